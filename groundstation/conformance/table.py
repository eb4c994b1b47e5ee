"""§11.1 parameter table: staged upload, read-back, and every refusal leaving the active
table as it was.  The tables sent are built from the table found on the device, with
one value changed; nothing here arms the rig."""

from __future__ import annotations

import math
import zlib

import numpy as np

from ..params import table as ptable
from .check import Check
from .context import Context, Verdict


def _values(ctx: Context) -> dict:
    return ptable.unpack(ctx.d, ctx.found_table)


def _packed(ctx: Context, values: dict) -> bytes:
    """Pack without the ground station's own validation: the device must refuse."""
    rec = np.zeros(1, ptable.table_dtype(ctx.d))
    for p in ctx.d.parameters:
        rec[p.name] = values[p.name]
    return rec.tobytes()


def read_back(ctx: Context, v: Verdict) -> None:
    """§11.1 step 4 / §5.2: PARAM_READ of the whole table, its CRC as HOUSEKEEPING says."""
    blob = ctx.read_table()
    hk = ctx.housekeeping_after(ctx.latest_tick())
    v.note(f"read {len(blob)} bytes with PARAM_READ in blocks of 1000")
    v.expect(len(blob) == ctx.table_size(), f"table of {len(blob)} bytes, the dictionary's "
             f"is {ctx.table_size()}")
    v.expect(hk is not None and hk["param_table_crc"] == zlib.crc32(blob),
             f"HOUSEKEEPING.param_table_crc 0x{(hk or {}).get('param_table_crc', 0):08X} = CRC-32 "
             f"of the read-back 0x{zlib.crc32(blob):08X}")
    over = ctx.host.exchange("PARAM_READ", {"offset": len(blob) - 10, "count": 20})
    v.expect(ctx.refused(over, 2, "OUT_OF_RANGE"), f"PARAM_READ past the end: {ctx.outcome(over)}, "
             "expected REJECTED OUT_OF_RANGE")


def staged_upload(ctx: Context, v: Verdict) -> None:
    """§11.1: BEGIN, WRITE blocks, COMMIT with the CRC activates the table; read-back
    equal; HOUSEKEEPING shows its CRC and version; a second COMMIT finds nothing staged."""
    values = _values(ctx)
    lo, hi = next(p.value_range for p in ctx.d.parameters if p.name == "watchdog_timeout")
    # a quarter second longer (shorter at the top of the range): a change the read-back
    # shows and that moves nothing while disarmed
    step = 0.25 if values["watchdog_timeout"] + 0.25 <= hi else -0.25
    new = float(np.float32(values["watchdog_timeout"] + step))
    values["watchdog_timeout"] = new
    blob = _packed(ctx, values)
    version = ((ctx.found_version or 0) + 1) & 0xFFFF
    steps, commit = ctx.upload_table(blob, version)
    v.note(f"uploaded the found table with watchdog_timeout {new:g} s as version {version}: "
           f"{len(steps) - 1} PARAM_WRITE blocks, PARAM_COMMIT crc 0x{zlib.crc32(blob):08X}")
    v.expect(all(ctx.is_ok(s) for s in steps), "PARAM_BEGIN and every PARAM_WRITE completed")
    v.note(f"PARAM_COMMIT: {ctx.outcome(commit)}")
    if not v.expect(ctx.is_ok(commit), "PARAM_COMMIT ACCEPTED then COMPLETED"):
        return
    reply = ctx.host.reply(commit, "PARAM_COMMIT")
    v.expect(reply["table_crc"] == zlib.crc32(blob), f"reply table_crc 0x{reply['table_crc']:08X}")
    hk = ctx.housekeeping_after(reply["tick"])
    v.expect(hk is not None and hk["param_table_crc"] == zlib.crc32(blob)
             and hk["param_table_version"] == version,
             f"HOUSEKEEPING after tick {reply['tick']}: crc 0x{(hk or {}).get('param_table_crc', 0):08X}"
             f" version {(hk or {}).get('param_table_version')}")
    v.expect(ctx.read_table() == blob, "read-back equals what was sent")
    again = ctx.host.exchange("PARAM_COMMIT", {"table_crc": zlib.crc32(blob)})
    v.expect(ctx.refused(again, 2, "NOTHING_STAGED"), f"a second PARAM_COMMIT: "
             f"{ctx.outcome(again)}, expected REJECTED NOTHING_STAGED (staging consumed)")
    # back to the table found, so the refusals below compare with it
    _, restore = ctx.upload_table(ctx.found_table, ctx.found_version or 0)
    v.expect(ctx.is_ok(restore), f"the found table committed again: {ctx.outcome(restore)}")


def bad_crc(ctx: Context, v: Verdict) -> None:
    """§11.1 step 3: a CRC that differs gives FAILED CRC_MISMATCH; the table stays."""
    values = _values(ctx)
    values["watchdog_timeout"] = float(np.float32(values["watchdog_timeout"] + 0.125))
    blob = _packed(ctx, values)
    wrong = zlib.crc32(blob) ^ 0x00000001
    _, commit = ctx.upload_table(blob, 0x7777, crc=wrong)
    v.note(f"staged a valid table, PARAM_COMMIT with table_crc 0x{wrong:08X} (true "
           f"0x{zlib.crc32(blob):08X}): {ctx.outcome(commit)}")
    v.expect(ctx.stages(commit) == [("ACCEPTED", "OK"), ("FAILED", "CRC_MISMATCH")],
             "ACCEPTED then FAILED CRC_MISMATCH (9)")
    ctx.table_unchanged(v, "the bad CRC")


def _bad_tables(ctx: Context):
    """(what, values) of tables §11.1's validation must refuse."""
    out = []
    vals = _values(ctx)
    nan = dict(vals, saturation_coarse=float("nan"))
    out.append(("saturation_coarse = NaN (rule 1, finite)", nan))
    inf = dict(vals)
    cascade = np.array(inf["relative_c1"], dtype=np.float64)
    cascade[-1, 1] = math.inf
    inf["relative_c1"] = cascade.tolist()
    out.append(("relative_c1 last row b1 = +inf (rule 1, every element, used or not)", inf))
    unstable = dict(vals)
    cascade = np.array(unstable["relative_c1"], dtype=np.float64)
    cascade[0] = [1.0, 0.0, 0.0, 1.0, -2.5, 1.5]          # poles 1 and 1.5: outside the circle
    unstable["relative_c1"] = cascade.tolist()
    out.append(("relative_c1 row 0 with a pole at z = 1.5 (rule 3, unstable section)", unstable))
    on_circle = dict(vals)
    cascade = np.array(on_circle["inertial_c2"], dtype=np.float64)
    cascade[0] = [1.0, 0.0, 0.0, 1.0, 0.0, 1.0]           # poles ±j: on the unit circle
    on_circle["inertial_c2"] = cascade.tolist()
    out.append(("inertial_c2 row 0 with poles at ±j (rule 3, on the circle)", on_circle))
    a0 = dict(vals)
    cascade = np.array(a0["relative_c0"], dtype=np.float64)
    cascade[0, 3] = 2.0
    a0["relative_c0"] = cascade.tolist()
    out.append(("relative_c0 row 0 a0 = 2 (rule 3, a0 must be 1)", a0))
    out.append(("saturation_coarse = 100 in-oz, above its rating 81.3 (rule 2)",
                dict(vals, saturation_coarse=100.0)))
    out.append(("saturation_fine = 20 in-oz, above its rating 16.1 (rule 2)",
                dict(vals, saturation_fine=20.0)))
    slope = dict(vals)
    x = list(slope["friction_comp_table_x"])
    x[1] = x[0]
    slope["friction_comp_table_x"] = x
    out.append(("friction_comp_table_x not strictly increasing (rule 4)", slope))
    return out


def bad_tables(ctx: Context, v: Verdict) -> None:
    """§11.1 validation: each bad table FAILED VALIDATION_FAILED, the active one unchanged."""
    for what, values in _bad_tables(ctx):
        blob = _packed(ctx, values)
        _, commit = ctx.upload_table(blob, 0x7778)
        v.expect(ctx.stages(commit) == [("ACCEPTED", "OK"), ("FAILED", "VALIDATION_FAILED")],
                 f"{what}: {ctx.outcome(commit)}, expected ACCEPTED, FAILED VALIDATION_FAILED (10)")
    ctx.table_unchanged(v, "the refused tables")


CHECKS = [
    Check("§11.1", "read-back equals HOUSEKEEPING's CRC", read_back),
    Check("§11.1", "staged upload, read-back equal", staged_upload),
    Check("§11.1", "refusal of a bad CRC, table unchanged", bad_crc),
    Check("§11.1", "refusal of bad tables, table unchanged", bad_tables),
]
