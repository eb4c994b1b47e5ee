"""§11.2 profiles: upload with CRC, sample-exact playback seen through HIGH_RATE
profile_index and reference, abort mid-profile.  All of it arms the rig."""

from __future__ import annotations

import zlib

import numpy as np

from .check import Check
from .context import Context, Verdict

PROFILE_ID = 0x5EC2          # an id the operator can recognise in HOUSEKEEPING
SHORT, LONG = 240, 2400      # samples: 0.2 s to play to the end, 2 s to abort inside
SAMPLES_PER_WRITE = 253      # §11.2: one frame carries up to 253 samples
STEP = 1e-4                  # rad: the reference ramps by this much, a tiny move


def _samples(ctx: Context, n: int) -> np.ndarray:
    """A small ramp from where the LOS axis is now, so RELATIVE holds almost still."""
    now = ctx.high_rate_after(ctx.host.mark(), lambda f: True, 2.0)
    start = now["encoder_inner"] if now else 0.0
    lo, hi = ctx.d.command("SET_REFERENCE").args[0].value_range
    ramp = start + STEP * np.arange(n) / n
    return np.clip(ramp, lo * 0.9, hi * 0.9).astype(">f4")


def _upload(ctx: Context, v: Verdict, samples: np.ndarray, *, check_bad_crc: bool):
    h = ctx.host
    target = ctx.d.command("PROFILE_BEGIN").args[1].states["REFERENCE"]
    raw = samples.tobytes()
    steps = [h.exchange("PROFILE_BEGIN", {"profile_id": PROFILE_ID, "target": target,
                                          "sample_count": len(samples)})]
    for first in range(0, len(samples), SAMPLES_PER_WRITE):
        steps.append(h.exchange("PROFILE_WRITE", {
            "offset": first, "samples": raw[4 * first:4 * (first + SAMPLES_PER_WRITE)]}))
    v.expect(all(ctx.is_ok(s) for s in steps), f"PROFILE_BEGIN and {len(steps) - 1} "
             f"PROFILE_WRITE blocks completed")
    if check_bad_crc:
        bad = h.exchange("PROFILE_COMMIT", {"profile_crc": zlib.crc32(raw) ^ 0x80000000})
        v.expect(ctx.stages(bad) == [("ACCEPTED", "OK"), ("FAILED", "CRC_MISMATCH")],
                 f"PROFILE_COMMIT with a wrong CRC: {ctx.outcome(bad)}, expected FAILED "
                 f"CRC_MISMATCH (staging kept)")
    commit = h.exchange("PROFILE_COMMIT", {"profile_crc": zlib.crc32(raw)})
    v.expect(ctx.is_ok(commit), f"PROFILE_COMMIT crc 0x{zlib.crc32(raw):08X}: {ctx.outcome(commit)}")
    return commit


def _armed_relative(ctx: Context, v: Verdict) -> bool:
    ctx.make_safe()
    modes = ctx.d.command("SET_MODE").args[0].states
    m = ctx.host.exchange("SET_MODE", {"mode": modes["RELATIVE"]})
    arm = ctx.host.exchange("ARM", {})
    return v.expect(ctx.is_ok(m) and ctx.is_ok(arm), f"SET_MODE RELATIVE {ctx.outcome(m)}; ARM "
                    f"{ctx.outcome(arm)}")


def upload(ctx: Context, v: Verdict) -> None:
    """§11.2 steps 1-3: upload with CRC, a wrong CRC refused, HOUSEKEEPING.active_profile."""
    ctx.require_motion()
    ctx.make_safe()
    commit = _upload(ctx, v, _samples(ctx, SHORT), check_bad_crc=True)
    if ctx.is_ok(commit):
        hk = ctx.housekeeping_after(commit.final.tick)
        v.expect(hk is not None and hk["active_profile"] == PROFILE_ID,
                 f"HOUSEKEEPING.active_profile {(hk or {}).get('active_profile')} = {PROFILE_ID}")


def _loaded_and_armed(ctx: Context, v: Verdict, length: int):
    """From the safe state: `length` samples uploaded and the device armed in RELATIVE;
    the samples, or None (the device made safe again) when either failed."""
    ctx.require_motion()
    ctx.make_safe()
    samples = _samples(ctx, length)
    if not ctx.is_ok(_upload(ctx, v, samples, check_bad_crc=False)) or not _armed_relative(ctx, v):
        ctx.make_safe()
        return None
    return samples


def play_sample_exact(ctx: Context, v: Verdict) -> None:
    """§11.2 step 4: in the k-th period after the start HIGH_RATE shows profile_index k and
    uses sample k-1; index 0 again after the last sample."""
    samples = _loaded_and_armed(ctx, v, SHORT)
    if samples is None:
        return
    h = ctx.host
    try:
        mark = h.mark()
        start = h.exchange("PROFILE_START", {})
        v.note(f"PROFILE_START: {ctx.outcome(start)}")
        if not v.expect(ctx.is_ok(start), "PROFILE_START completed"):
            return
        t0 = start.final.tick
        n = len(samples)
        end = ctx.high_rate_after(mark, lambda f: f["tick"] > t0 + n + 1, 3.0 + 4 * n / ctx.rate)
        if not v.expect(end is not None, f"HIGH_RATE beyond tick {t0 + n + 1}"):
            return
        frames = [ctx.decode(f, "HIGH_RATE") for f in h.since(mark, ctx.ids["HIGH_RATE"])]
        played = [f for f in frames if f["profile_index"] != 0]
        if not v.expect(bool(played), "some HIGH_RATE frames show a profile_index"):
            return
        first, last = played[0], played[-1]
        v.note(f"COMPLETED at tick {t0}; index 1 first at tick {first['tick']}, index "
               f"{last['profile_index']} last at tick {last['tick']}")
        v.expect(first["profile_index"] == 1 and first["tick"] - t0 in (0, 1),
                 f"sample 1 in the first period after the start: index "
                 f"{first['profile_index']} at tick {first['tick']} (start {t0})")
        v.expect(last["profile_index"] == n and last["tick"] - first["tick"] == n - 1,
                 f"last sample (index {n}) {n - 1} periods after the first: index "
                 f"{last['profile_index']} at tick {last['tick']}")
        bad_index = [f for f in played if f["profile_index"] != f["tick"] - first["tick"] + 1]
        v.expect(not bad_index, f"index = ticks since the first + 1 in every frame "
                 f"({len(bad_index)} frames differ)")
        idle_active = [f for f in frames if f["profile_index"] == 0 and f["profile_active"]]
        v.expect(not idle_active, f"profile_active clear whenever the index is 0 "
                 f"({len(idle_active)} frames differ)")
        scale = ctx.hr.item_by_name["reference"].scale or 0.0
        wrong = [f for f in played if 1 <= f["profile_index"] <= n and
                 abs(f["reference"] - float(samples[f["profile_index"] - 1])) > 1.5 * scale]
        v.expect(not wrong, f"reference = sample index-1 within one count in every frame "
                 f"({len(wrong)} differ)")
        v.expect(ctx.wait_event(mark, "PROFILE_FINISHED") is not None, "EVENT PROFILE_FINISHED")
    finally:
        ctx.make_safe()


def abort_mid_profile(ctx: Context, v: Verdict) -> None:
    """§9.2/§11.2: ABORT during playback stops it within one control period and disarms."""
    samples = _loaded_and_armed(ctx, v, LONG)
    if samples is None:
        return
    h = ctx.host
    try:
        mark = h.mark()
        start = h.exchange("PROFILE_START", {})
        playing = ctx.high_rate_after(mark, lambda f: f["profile_index"] >= 60, 5.0)
        if not v.expect(ctx.is_ok(start) and playing is not None, "the profile plays"):
            return
        abort = h.exchange("ABORT", {})
        v.note(f"ABORT at profile_index >= 60: {ctx.outcome(abort)}")
        if not v.expect(ctx.is_ok(abort), "ABORT completed"):
            return
        ta = abort.final.tick
        after = ctx.high_rate_after(mark, lambda f: f["tick"] > ta + 1, 3.0)
        frames = [ctx.decode(f, "HIGH_RATE") for f in h.since(mark, ctx.ids["HIGH_RATE"])]
        later = [f for f in frames if f["tick"] > ta + 1]
        v.expect(after is not None and all(f["profile_index"] == 0 and not f["armed"]
                                           and not f["profile_active"] and f["mode"] == 0
                                           for f in later),
                 f"from tick {ta + 2} on (ABORT at {ta}): index 0, disarmed, IDLE "
                 f"({len(later)} frames)")
        stopped = [f for f in frames if f["profile_index"]]
        v.expect(bool(stopped) and stopped[-1]["profile_index"] < len(samples),
                 f"playback stopped mid-profile at index {stopped[-1]['profile_index'] if stopped else None}")
        v.expect(ctx.wait_event(mark, "ABORTED") is not None, "EVENT ABORTED")
    finally:
        ctx.make_safe()


CHECKS = [
    Check("§11.2", "profile upload with CRC", upload),
    Check("§11.2", "profile plays sample-exact", play_sample_exact),
    Check("§11.2", "abort mid-profile", abort_mid_profile),
]
