"""The step response of a closed-loop log: analysis.step.step_metrics on what a log holds.

The response is ``reference - error_angle``, i.e. the angle the active mode controls
(whatever that mode is: the outer axis, the relative angle, the LOS), in the reference's
units.  The step is the reference's largest transition in the window: a raw step (one
frame) or a shaped one (the reference moving over consecutive frames, pauses under
STEP_MERGE_S merged), commanded at the first frame that carries a new value and scored
until the reference moves again (NoStepError when no transition exceeds MIN_STEP_RAD).
The effort is a channel of the same frames (current_coarse by default).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..logs import LogReader
from .log_window import (PACKET, LogIdentificationError, WindowTooShortError, longest_run,
                         require_channels, window_rows)
from .step import StepMetrics, step_metrics

#: the least net change of the reference that counts as a step [rad]
MIN_STEP_RAD = 1e-7


class NoStepError(LogIdentificationError):
    """The reference makes no step (no jump larger than MIN_STEP_RAD) in the window."""


@dataclass(frozen=True, eq=False)
class LogStep:
    """A step response's figures of merit and where in the log the step was."""

    path: Path
    window_from_s: float            # first frame used, s from the log's start
    window_to_s: float              # last frame used
    frames: int
    step_time_s: float              # first frame with the new reference, s from the log's start
    step_size: float                # the reference's jump (rad; sign = direction)
    reference_before: float
    effort_channel: str | None      # None: no effort
    effort_units: str
    metrics: StepMetrics
    notes: tuple[str, ...] = field(default_factory=tuple)


#: pauses shorter than this inside a moving reference belong to the same (shaped) step
STEP_MERGE_S = 0.05


def _reference_transitions(ref: np.ndarray, rate_hz: float) -> list[tuple[int, int]]:
    """(first, last) indices into diff(ref) of each stretch where the reference moves,
    stretches closer than STEP_MERGE_S joined."""
    moving = np.flatnonzero(np.isfinite(np.diff(ref)) & (np.diff(ref) != 0.0))
    if not moving.size:
        return []
    breaks = np.flatnonzero(np.diff(moving) > max(1, int(STEP_MERGE_S * rate_hz)))
    starts = np.concatenate(([moving[0]], moving[breaks + 1]))
    ends = np.concatenate((moving[breaks], [moving[-1]]))
    return list(zip(starts.tolist(), ends.tolist()))


def step_from_log(path: str | Path, start_s: float | None = None, stop_s: float | None = None,
                  effort_channel: str | None = "current_coarse") -> LogStep:
    """Step-response figures (analysis.step.step_metrics) of a closed-loop record.

    The response is ``reference - error_angle``: the controlled angle, whatever the mode
    in the log controls (outer axis, relative angle or LOS).  The step is the largest
    change of ``reference`` within the window [start_s, stop_s] (s from the log's start;
    None: open end): a raw step (one frame) or a shaped one (the reference moving over
    consecutive frames, pauses under STEP_MERGE_S merged), commanded at the first frame
    carrying a new value; step_metrics gets the net change as the step size and that
    frame's time as the start.  The effort is `effort_channel` (None: no effort figure).
    Raises NoStepError when no jump exceeds MIN_STEP_RAD, MissingChannelError,
    WindowTooShortError, StepMetricsError (e.g. too few samples after the step), LogError."""
    needed = ["reference", "error_angle"] + ([effort_channel] if effort_channel else [])
    with LogReader(path) as r:
        require_channels(r, needed, "a step response")
        chans = {c.name: c for c in r.channels(PACKET)}
        i0, i1 = window_rows(r, start_s, stop_s)
        d = r.read_rows(PACKET, needed, i0, i1)
        origin = r.origin("device")
        rate = r.tick_rate_hz
    name = Path(path).name
    notes: list[str] = []
    t = np.asarray(d["device_time"], dtype=np.float64) - origin
    ref = np.asarray(d["reference"], dtype=np.float64)
    response = ref - np.asarray(d["error_angle"], dtype=np.float64)
    effort = np.asarray(d[effort_channel], dtype=np.float64) if effort_channel else None
    if t.size < 2:
        raise WindowTooShortError(f"{name}: {t.size} frame(s) in the window: a step needs more")
    jumps = np.diff(ref)
    if not np.any(np.isfinite(jumps)):
        raise NoStepError(f"{name}: the reference has no finite samples in the window")
    transitions = _reference_transitions(ref, rate)
    if not transitions:
        raise NoStepError(f"{name}: the reference makes no step in the window {t[0]:.3f}.."
                          f"{t[-1]:.3f} s (it never changes)")
    # the transition with the largest net change: a raw step is one frame long, a shaped
    # (smoothed) step many - timed from its first change either way
    a, b = max(transitions, key=lambda ab: abs(ref[ab[1] + 1] - ref[ab[0]]))
    size = float(ref[b + 1] - ref[a])
    k = a
    if not abs(size) > MIN_STEP_RAD:
        raise NoStepError(f"{name}: the reference makes no step in the window {t[0]:.3f}.."
                          f"{t[-1]:.3f} s (largest change {abs(size):.3g} rad, a step must "
                          f"exceed {MIN_STEP_RAD:g} rad)")
    _, _, missing = longest_run(t, rate)
    if missing:
        notes.append(f"{missing} frame(s) missing in the window (not bridged)")
    if b > a:
        notes.append(f"a shaped step: the reference moves over {(t[b + 1] - t[a + 1]) * 1e3:.1f} ms; "
                     f"times are from its first change")
    others = sum(1 for x, y in transitions
                 if abs(ref[y + 1] - ref[x]) > max(MIN_STEP_RAD, 0.1 * abs(size)))
    if others > 1:
        notes.append(f"the reference steps {others} times in the window; the largest "
                     f"({size:.3g} rad at {t[k + 1]:.3f} s) is evaluated")
    # the step's response lasts until the reference moves again (a profile that steps up
    # and back down): scored to there, so the steady state is this step's
    later = [x for x, _ in transitions if x > b]
    end = later[0] + 1 if later else t.size
    if end < t.size:
        notes.append(f"scored until the reference changes again at {t[end]:.3f} s")
    metrics = step_metrics(t[:end], response[:end], size, float(t[k + 1]),
                           effort[:end] if effort is not None else None)
    return LogStep(path=Path(path), window_from_s=float(t[0]), window_to_s=float(t[-1]),
                   frames=int(t.size), step_time_s=float(t[k + 1]), step_size=size,
                   reference_before=float(ref[k]), effort_channel=effort_channel,
                   effort_units=chans[effort_channel].units if effort_channel else "",
                   metrics=metrics, notes=tuple(notes))


__all__ = ["LogStep", "MIN_STEP_RAD", "NoStepError", "STEP_MERGE_S", "step_from_log"]
