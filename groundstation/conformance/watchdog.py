"""§9.1 heartbeat and watchdog, judged in device ticks from telemetry, never by the
wall clock: a simulated device may run faster than real time."""

from __future__ import annotations

import math

from .check import Check
from .context import Context, Verdict
from ..params import table as ptable


def heartbeat_age(ctx: Context, v: Verdict) -> None:
    """§9.1: while the host sends HEARTBEAT, HOUSEKEEPING says OK and a small age."""
    tick = ctx.latest_tick()
    hk = ctx.housekeeping_after(tick)
    if not v.expect(hk is not None, "a HOUSEKEEPING frame arrives"):
        return
    states = ctx.hk.item_by_name["watchdog"].states
    limit_ms = _timeout_s(ctx) * 1000.0
    v.expect(hk["watchdog"] in (states["OK"], states["EXPIRED"]),
             f"watchdog = {hk['watchdog']} while a session is open (OK {states['OK']})")
    v.expect(hk["heartbeat_age"] < limit_ms, f"heartbeat_age {hk['heartbeat_age']} ms while "
             f"heartbeats flow, below the timeout {limit_ms:g} ms")


def _timeout_s(ctx: Context) -> float:
    """The active table's watchdog_timeout, read back now (not the one found at the
    start: a device that activated a table it should have refused runs on that one)."""
    return float(ptable.unpack(ctx.d, ctx.read_table())["watchdog_timeout"])


def silent_host_disarms(ctx: Context, v: Verdict) -> None:
    """§9.1: armed and silent for watchdog_timeout, the device disarms in the first period
    with more than timeout x rate ticks since the last reset, and latches WATCHDOG."""
    ctx.require_motion()
    h = ctx.host
    ctx.make_safe()
    timeout = _timeout_s(ctx)        # read before ARM: every command resets the watchdog
    modes = ctx.d.command("SET_MODE").args[0].states
    m = h.exchange("SET_MODE", {"mode": modes["RELATIVE"]})
    v.note(f"SET_MODE RELATIVE: {ctx.outcome(m)} (a closed loop holding where it is)")
    h.pause_heartbeat()
    try:
        mark = h.mark()
        arm = h.exchange("ARM", {})
        v.note(f"heartbeat stopped, then ARM: {ctx.outcome(arm)}")
        if not v.expect(ctx.is_ok(arm), "ARM accepted and completed"):
            return
        reset = arm.stages[0].tick       # ARM passes checks 1-4: it resets the watchdog
        expected = reset + math.floor(timeout * ctx.rate) + 1
        trip = ctx.high_rate_after(mark, lambda f: not f["armed"] and f["tick"] > reset,
                                   timeout=4 * timeout + 5.0)
        if not v.expect(trip is not None, "the device disarms by itself (HIGH_RATE armed clear)"):
            return
        late = trip["tick"] - expected
        v.note(f"last reset at tick {reset} (ARM), watchdog_timeout {timeout:g} s; "
               f"HIGH_RATE shows armed clear first at tick {trip['tick']}")
        v.expect(abs(late) <= 2, f"trip tick {trip['tick']} vs SPEC {expected} (first period with "
                 f"more than {timeout:g} x {ctx.rate:g} ticks since the reset): "
                 f"{late:+d} ticks")
        v.expect(trip["torque_coarse_cmd"] == 0 and trip["torque_fine_cmd"] == 0,
                 "both motor commands zero in the period that trips")
        v.expect(trip["mode"] == modes["IDLE"], f"mode IDLE in that period (got {trip['mode']})")
        hk = ctx.housekeeping_after(trip["tick"])
        faults = ctx.hk.item_by_name["fault_code"].states
        wd = ctx.hk.item_by_name["watchdog"].states
        v.expect(hk is not None and hk["fault_code"] == faults["WATCHDOG"]
                 and hk["watchdog"] == wd["EXPIRED"],
                 f"HOUSEKEEPING fault_code WATCHDOG and watchdog EXPIRED (got "
                 f"{hk and hk['fault_code']}, {hk and hk['watchdog']})")
        v.expect(ctx.wait_event(mark, "WATCHDOG_EXPIRED") is not None, "EVENT WATCHDOG_EXPIRED")
    finally:
        h.pause_heartbeat(False)
        ctx.make_safe()              # DISARM acknowledges the latched fault (§9.2)


CHECKS = [
    Check("§9.1", "heartbeat keeps the watchdog OK", heartbeat_age),
    Check("§9.1", "silent host disarmed within watchdog_timeout (device ticks)", silent_host_disarms),
]
