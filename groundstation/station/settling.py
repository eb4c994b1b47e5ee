"""The Station's `settle` verb: wait until the rig is ready for a run's clock to start,
recentring it first if asked (start_state.py says what "ready" means).

    state = settle_rig(station, 30.0, StartCriteria(), progress, recentre=None)

A latched fault is acknowledged (DISARM) first, as after a failed run.  Then device time
passes (the session's clock, so a fast simulator is not waited for in real time) until
the monitor's window meets every criterion, or `max_seconds` have passed.

recentre: a RELATIVE-mode design for this testbed, validated on upload like any design.
When the rig is at rest and unfaulted but out of range, it is uploaded, armed (which
holds where the axis is), stepped to a zero reference, kept armed until the range
criteria hold (at most `recentre_seconds`), disarmed, and the rig is checked again.  The
table it leaves active is the recentring one: a run uploads its own next.

Every unmet criterion, with its measured value, ends in the ScriptError: the run must
not start.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable

from .start_state import RigLimits, StartCriteria, StartStateMonitor

if TYPE_CHECKING:
    from .station import Station


def settle_rig(st: "Station", max_seconds: float, criteria: StartCriteria,
               progress: Callable[[float], None] | None, recentre: Path | None,
               recentre_seconds: float) -> dict[str, float]:
    from .station import ScriptError

    if st.state.fault and not st.state.armed:
        st.client.command("DISARM")
    monitor = StartStateMonitor(RigLimits.from_testbed(st.testbed), st.d.control_rate_hz, criteria)
    st.client.subscribe(monitor)
    try:
        st.clock.advance(max_seconds, progress, until=lambda: not monitor.problems())
        problems = monitor.problems()
        if recentre is not None and problems and all(p.kind == "range" for p in problems):
            _recentre(st, recentre, monitor, problems, recentre_seconds)
            monitor.reset()
            st.clock.advance(max_seconds, progress, until=lambda: not monitor.problems())
            problems = monitor.problems()
    finally:
        st.client.unsubscribe(monitor)
    if problems:
        raise ScriptError(f"settle: the rig is not ready after {max_seconds:g} s: "
                          + "; ".join(map(str, problems)))
    state = monitor.summary()
    st._note("start state verified: " + ", ".join(f"{k} {v:.6g}" for k, v in state.items()))
    return state


def _recentre(st: "Station", design: Path, monitor: StartStateMonitor, problems,
              seconds: float) -> None:
    from .station import ScriptError

    st._note(f"recentring with {design.name} (RELATIVE, zero reference): "
             + "; ".join(map(str, problems)))
    st.upload_design(design)
    st.client.command("SET_MODE", mode="RELATIVE")
    st.client.command("ARM")                               # arming holds where the axis is ...
    st.client.command("SET_REFERENCE", reference=0.0)      # ... then the way back to zero
    monitor.reset()

    def centred() -> bool:
        return st.state.fault or (monitor.window() is not None and
                                  not any(p.kind == "range" for p in monitor.problems()))
    st.clock.advance(seconds, until=centred)
    if st.state.fault:
        raise ScriptError(f"settle: the device faulted while recentring with {design.name}")
    st.client.command("DISARM")
