"""§6 command exchange: stages, refusals with their reason codes, duplicates, and the
device's own range checks (raw COMMAND frames that our client would never send)."""

from __future__ import annotations

import struct

from .check import Check
from .context import Context, Verdict


def stages_in_order(ctx: Context, v: Verdict) -> None:
    """§6.3: ACCEPTED then COMPLETED, echoing the command's sequence and opcode."""
    for name in ("GET_INFO", "HEARTBEAT"):
        ex = ctx.host.exchange(name, {})
        v.note(f"sent {name} seq {ex.sequence}; got {ctx.outcome(ex)}")
        v.expect(ctx.is_ok(ex) and all(s.reason == 0 for s in ex.stages),
                 f"{name}: ACCEPTED then COMPLETED, reason 0 (OK)")
        if ctx.is_ok(ex):
            v.expect(len(ex.final.data) >= sum(i.wire_dtype.itemsize for i in
                                               ctx.d.command(name).reply if not i.is_variable),
                     f"{name}: COMPLETED carries the reply ({len(ex.final.data)} bytes)")
    ex = ctx.host.exchange(0x7FEE, arguments=b"")
    echoed = [f for f in ctx.host.since(0, ctx.ids["RESPONSE"])
              if int.from_bytes(f.payload[:4], "big") == ex.sequence]
    v.expect(bool(echoed) and all(int.from_bytes(f.payload[4:6], "big") == 0x7FEE for f in echoed),
             "§6.2: the opcode is echoed even when it is unknown")


# (what to send, expected reason, what the SPEC says); arguments packed raw, so values
# outside a range reach the device exactly as written
def _refusals(ctx: Context):
    h = ctx.host
    nan = struct.pack(">f", float("nan"))
    return [
        ("unknown opcode 0x7FEE", dict(command=0x7FEE, arguments=b""), "UNKNOWN_COMMAND",
         "§6.3 check 1: the opcode is in commands.toml"),
        ("HEARTBEAT with one argument byte too many", dict(command="HEARTBEAT", arguments=b"\x00"),
         "BAD_LENGTH", "§6.3 check 2: exactly the size of args"),
        ("SET_CURRENTS with 7 of its 8 argument bytes", dict(command="SET_CURRENTS",
                                                            arguments=bytes(7)),
         "BAD_LENGTH", "§6.3 check 2"),
        ("PROFILE_WRITE with 5 sample bytes", dict(command="PROFILE_WRITE",
                                                   arguments=bytes(4) + bytes(5)),
         "BAD_LENGTH", "§11.2: samples a multiple of 4, checked as length"),
        ("HEARTBEAT with a wrong token", dict(command="HEARTBEAT", arguments=b"",
                                              token=h.token ^ 0x0F0F0F0F),
         "NOT_SESSION_OWNER", "§6.3 check 3 / §7"),
        ("SET_MODE mode 9 (no such state)", dict(command="SET_MODE", arguments=b"\x09"),
         "OUT_OF_RANGE", "§6.3 check 4: one of its states"),
        ("SET_REFERENCE 0.5 rad (range ±0.349)", dict(command="SET_REFERENCE",
                                                      arguments=struct.pack(">f", 0.5)),
         "OUT_OF_RANGE", "§6.3 check 4, before the state rules"),
        ("SET_REFERENCE NaN", dict(command="SET_REFERENCE", arguments=nan),
         "OUT_OF_RANGE", "§3.2: NaN is out of every range"),
        ("SET_CURRENTS 3.0 A coarse (range ±2.53)", dict(command="SET_CURRENTS",
                                                        arguments=struct.pack(">ff", 3.0, 0.0)),
         "OUT_OF_RANGE", "§6.3 check 4, before INVALID_STATE"),
        ("FRICTION_COMP enable 2 (range 0..1)", dict(command="FRICTION_COMP", arguments=b"\x02"),
         "OUT_OF_RANGE", "§6.3 check 4"),
        ("PARAM_READ count 0 (range 1..1000)", dict(command="PARAM_READ",
                                                    arguments=struct.pack(">IH", 0, 0)),
         "OUT_OF_RANGE", "§6.3 check 4"),
        ("PARAM_BEGIN with a table_length that is not the table's",
         dict(command="PARAM_BEGIN", arguments=struct.pack(">HI", 1, ctx.table_size() + 1)),
         "OUT_OF_RANGE", "§11.1: table_length must equal the device's table"),
        ("PROFILE_BEGIN profile_id 0 (range 1..65535)",
         dict(command="PROFILE_BEGIN", arguments=struct.pack(">HBI", 0, 0, 10)),
         "OUT_OF_RANGE", "§11.2"),
    ]


def refusals(ctx: Context, v: Verdict) -> None:
    """§6.3: each failed check gives REJECTED with its documented reason, nothing executed."""
    for what, kw, reason, spec in _refusals(ctx):
        ex = ctx.host.exchange(**kw)
        v.expect(ctx.refused(ex, 2, reason) and len(ex.stages) == 1,
                 f"{what}: got {ctx.outcome(ex)}, expected REJECTED {reason} "
                 f"({ctx.d.error_codes[reason]}) - {spec}")


def state_refusals(ctx: Context, v: Verdict) -> None:
    """§10: state rules, with the device disarmed and in IDLE (nothing can move)."""
    ctx.make_safe()
    mode = ctx.host.exchange("SET_MODE", {"mode": 0})
    v.note(f"SET_MODE IDLE: {ctx.outcome(mode)}")
    for what, cmd, values, reason in (
            ("SET_CURRENTS 0 A in IDLE", "SET_CURRENTS", {"current_coarse": 0.0, "current_fine": 0.0},
             "INVALID_STATE"),
            ("SET_REFERENCE 0 rad in IDLE", "SET_REFERENCE", {"reference": 0.0}, "INVALID_STATE"),
            ("ARM in IDLE", "ARM", {}, "INVALID_STATE")):
        ex = ctx.host.exchange(cmd, values)
        v.expect(ctx.refused(ex, 2, reason), f"{what}: got {ctx.outcome(ex)}, expected "
                 f"REJECTED {reason} (§10)")
    ctx.make_safe()


def duplicate_executed_once(ctx: Context, v: Verdict) -> None:
    """§6.4: a resent COMMAND (same sequence, same bytes) is answered again but executed
    once.  ABORT shows it: each execution sends EVENT ABORTED, and a replay is not
    counted in HOUSEKEEPING.commands_accepted."""
    h = ctx.host
    h.pause_heartbeat()            # the counters must move only by what we send here
    try:
        # a heartbeat sent just before the pause is executed before this answer (one
        # ordered stream): the counters read after it include it
        settled = h.exchange("GET_INFO", {})
        base_tick = max([ctx.latest_tick()] + [s.tick for s in settled.stages])
        before = ctx.housekeeping_after(base_tick)
        mark = h.mark()
        frame = h.build("ABORT", {})
        first = h.exchange("ABORT", frame=frame, resend=False)
        again = h.exchange("ABORT", frame=frame, resend=False)
        v.note(f"sent ABORT seq {frame[1]}: {ctx.outcome(first)}; the identical frame again: "
               f"{ctx.outcome(again)}")
        v.expect(ctx.is_ok(first) and ctx.is_ok(again),
                 "both answered ACCEPTED, COMPLETED (the replay repeats the recorded stages)")
        last_tick = max([s.tick for s in first.stages + again.stages] or [base_tick])
        after = ctx.housekeeping_after(last_tick)
        # events of this ABORT arrive with or before the HOUSEKEEPING after it
        aborted = ctx.events_since(mark, "ABORTED")
        v.expect(len(aborted) == 1, f"exactly one EVENT ABORTED (saw {len(aborted)})")
        if before is None or after is None:
            v.expect(False, "HOUSEKEEPING before and after the commands")
            return
        delta = after["commands_accepted"] - before["commands_accepted"]
        v.expect(delta == 1, f"HOUSEKEEPING.commands_accepted rose by {delta} "
                 f"({before['commands_accepted']} -> {after['commands_accepted']}), "
                 f"expected 1: replays are not counted (§5.2, §6.4)")
    finally:
        h.pause_heartbeat(False)


CHECKS = [
    Check("§6.3", "stages ACCEPTED then COMPLETED", stages_in_order),
    Check("§6.3", "refusals with the documented reason codes, ranges checked by the device",
          refusals),
    Check("§10", "state rules refuse commands in IDLE", state_refusals),
    Check("§6.4", "resent command executed once", duplicate_executed_once),
]
