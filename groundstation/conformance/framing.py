"""§1.1, §2, §2.1, §5: the bytes of every frame the device sent during the run, its
sequence numbers and ticks, its rates in device time, and HOUSEKEEPING's contents."""

from __future__ import annotations

import zlib

from .check import Check
from .context import Context, Skip, Verdict

MIN_TICKS = 360              # judge at least this much telemetry (three HOUSEKEEPING periods)


def _enough(ctx: Context) -> None:
    """Wait until the run has at least MIN_TICKS of HIGH_RATE (device time)."""
    pid = ctx.ids["HIGH_RATE"]
    first = ctx.host.wait_frame(lambda f: f.packet_id == pid, 0, 3.0)
    if first is None:
        return
    ctx.host.wait_frame(lambda f: f.packet_id == pid and f.tick - first.tick >= MIN_TICKS, 0,
                        3.0 + 4 * MIN_TICKS / ctx.rate)


def crc_of_every_packet(ctx: Context, v: Verdict) -> None:
    """§2/§2.1/§4: every frame received in this run, by every host, judged from its bytes."""
    _enough(ctx)
    hosts = ctx.all_hosts
    total = {k: sum(getattr(h.report, k) for h in hosts) for k in
             ("frames", "crc_errors", "version_errors", "unknown_packet_errors",
              "length_errors", "split_frames", "junk_bytes")}
    by_id: dict[str, int] = {}
    for f in ctx.host.since(0):
        name = next((p.name for p in ctx.d.packets if p.id == f.packet_id), hex(f.packet_id))
        by_id[name] = by_id.get(name, 0) + 1
    v.note(f"frames accepted: {total['frames']} ({', '.join(f'{k} {n}' for k, n in by_id.items())})")
    for kind in ("crc_errors", "version_errors", "unknown_packet_errors", "length_errors",
                 "split_frames"):
        example = next((h.report.examples[kind] for h in hosts if kind in h.report.examples), "")
        v.expect(total[kind] == 0, f"{kind.replace('_', ' ')}: {total[kind]}"
                 + (f" - e.g. {example}" if example else ""))
    v.expect(total["junk_bytes"] == 0, f"bytes outside any good frame: {total['junk_bytes']}")
    v.expect(total["frames"] > 0 and "HIGH_RATE" in by_id, "telemetry was received")
    v.note("§2.1: CRC-32/ISO-HDLC over bytes 0 .. 13+length, sent least significant byte first")


def _within_sessions(ctx: Context, frames):
    """Consecutive pairs of frames that no session change lies between: telemetry pauses
    with no session open (§1.3), and a pause is not a rate."""
    breaks = ctx.host.session_breaks
    for a, b in zip(frames, frames[1:]):
        if not any(a.arrival <= m < b.arrival for m in breaks):
            yield a, b


def sequence_numbers(ctx: Context, v: Verdict) -> None:
    """§2: one counter per packet, +1 per frame sent, wrapping; a gap only for frames lost
    in transit (and never more than the ticks elapsed for HIGH_RATE)."""
    _enough(ctx)
    frames = ctx.host.since(0)
    for name in ("HIGH_RATE", "HOUSEKEEPING", "EVENT", "RESPONSE"):
        mine = [f for f in frames if f.packet_id == ctx.ids[name]]
        backward = gaps = 0
        bad_tick = 0
        within = set(id(a) for a, _ in _within_sessions(ctx, mine))
        for a, b in zip(mine, mine[1:]):
            step = (b.sequence - a.sequence) & 0xFFFFFFFF
            if step == 0 or step >= 0x80000000:
                backward += 1
            elif step > 1 and id(a) in within:   # across a session change: not judged
                gaps += step - 1
            if name == "HIGH_RATE" and 0 < step < 0x80000000:
                dt = (b.tick - a.tick) & 0xFFFFFFFF
                if dt < step:          # more frames numbered than periods elapsed
                    bad_tick += 1
        v.expect(backward == 0, f"{name}: {len(mine)} frames, {backward} repeated or backward "
                 f"sequence numbers")
        # one serial host sees every frame the device sends; over TCP/UDP another host's
        # RESPONSEs and the telemetry sent to a host that took the session over use
        # numbers this host never sees, and UDP may lose datagrams
        if ctx.address.kind == "serial":
            v.expect(gaps == 0, f"{name}: {gaps} numbers skipped on a stream that loses nothing")
        elif gaps:
            v.note(f"{name}: {gaps} numbers skipped (frames lost in transit or sent to another "
                   f"host during the take-over)")
        if name == "HIGH_RATE":
            v.expect(bad_tick == 0, f"HIGH_RATE: sequence advances no faster than the tick "
                     f"({bad_tick} pairs differ)")


def _tick_steps(ctx: Context, frames, packet: str) -> dict[int, int]:
    """{tick step: count} between frames of `packet` numbered one after the other within
    a session (a sequence gap is §2's business, not a rate)."""
    mine = [f for f in frames if f.packet_id == ctx.ids[packet]]
    steps: dict[int, int] = {}
    for a, b in _within_sessions(ctx, mine):
        if (b.sequence - a.sequence) & 0xFFFFFFFF == 1:
            d = (b.tick - a.tick) & 0xFFFFFFFF
            steps[d] = steps.get(d, 0) + 1
    return steps


def rates(ctx: Context, v: Verdict) -> None:
    """§5: HIGH_RATE every control period, HOUSEKEEPING every rate/rate_hz periods, in
    device ticks (a device may run faster than the wall clock)."""
    _enough(ctx)
    frames = ctx.host.since(0)
    per = _tick_steps(ctx, frames, "HIGH_RATE")
    v.expect(set(per) <= {1}, f"HIGH_RATE: tick step between consecutive frames {per} "
             f"(expected 1: one frame per period at {ctx.rate:g} Hz)")
    every = round(ctx.rate / ctx.hk.rate_hz)
    steps = _tick_steps(ctx, frames, "HOUSEKEEPING")
    v.expect(bool(steps) and set(steps) <= {every}, f"HOUSEKEEPING: tick step {steps} (expected "
             f"{every} = {ctx.rate:g} / {ctx.hk.rate_hz:g} Hz)")


def housekeeping_contents(ctx: Context, v: Verdict) -> None:
    """§5.2: the items the SPEC relies on agree with what the device says elsewhere."""
    hk = ctx.housekeeping_after(ctx.latest_tick())
    if not v.expect(hk is not None, "a HOUSEKEEPING frame arrives"):
        return
    for item in ctx.hk.items:
        if item.states:
            v.expect(hk[item.name] in item.states.values(),
                     f"{item.name} = {hk[item.name]} is one of its states")
    info = ctx.host.exchange("GET_INFO", {})
    if ctx.is_ok(info):
        fw = ctx.host.reply(info, "GET_INFO")["firmware_version"]
        v.expect(hk["firmware_version"] == fw, f"firmware_version {hk['firmware_version']:#x} "
                 f"= GET_INFO's {fw:#x}")
    active = ctx.read_table()
    hk = ctx.housekeeping_after(ctx.latest_tick()) or hk
    v.expect(hk["param_table_crc"] == zlib.crc32(active),
             f"param_table_crc 0x{hk['param_table_crc']:08X} = CRC of the table read back "
             f"0x{zlib.crc32(active):08X}")
    v.expect(hk["watchdog"] == ctx.hk.item_by_name["watchdog"].states["OK"] or
             hk["watchdog"] == ctx.hk.item_by_name["watchdog"].states["EXPIRED"],
             f"watchdog {hk['watchdog']} with a session open (OK or EXPIRED)")
    # the counters: two commands accepted and one rejected move them by exactly that
    h = ctx.host
    h.pause_heartbeat()
    try:
        before = ctx.housekeeping_after(ctx.latest_tick())
        sent = [h.exchange("GET_INFO", {}), h.exchange("GET_INFO", {}), h.exchange(0x7FEE)]
        after = ctx.housekeeping_after(max(s.tick for e in sent for s in e.stages))
        if v.expect(before is not None and after is not None, "HOUSEKEEPING before and after"):
            acc = after["commands_accepted"] - before["commands_accepted"]
            rej = after["commands_rejected"] - before["commands_rejected"]
            v.expect((acc, rej) == (2, 1), f"commands_accepted +{acc}, commands_rejected +{rej} "
                     f"after 2 accepted and 1 rejected commands")
    finally:
        h.pause_heartbeat(False)


def telemetry_source(ctx: Context, v: Verdict) -> None:
    """§1.1: UDP telemetry comes from the device's address and command port number."""
    if ctx.address.kind != "tcp" or ctx.host.udp is None:
        raise Skip("telemetry is on the stream here (serial or ?telemetry=stream)")
    _enough(ctx)
    sources = ctx.host.datagram_sources
    v.note(f"datagrams came from {sorted(sources)}; command connection to {ctx.host.peer}")
    v.expect(sources == {tuple(ctx.host.peer)}, "every datagram from the command port's number "
             "on the address the host connected to")


CHECKS = [
    Check("§1.1", "telemetry from the command port", telemetry_source),
    Check("§2.1", "CRC of every packet", crc_of_every_packet),
    Check("§2", "sequence numbers", sequence_numbers),
    Check("§5", "rates against the dictionary (device ticks)", rates),
    Check("§5.2", "HOUSEKEEPING contents", housekeeping_contents),
]
