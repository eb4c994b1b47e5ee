"""Missing and repeated frames of a recording, found in the frames' device ticks.

The tick counts control periods and wraps with its u32 type; a step of k ticks between
consecutive frames means k - 1 frames missing, a step of 0 or backwards a repeated or
out-of-order frame.
"""

from __future__ import annotations

import numpy as np

TICK_MODULUS = 1 << 32                      # the header's tick is a u32 that wraps (41 days)


def frame_steps(tick, previous_tick: int | None = None) -> tuple[np.ndarray, int, int]:
    """(gap_before, missing frames, non-advancing frames) of consecutive frames' device
    ticks: gap_before[k] is True when frame k is not one tick after the frame before it
    (`previous_tick`: the frame before the first; None: none).  A step of k > 1 ticks
    means k - 1 frames missing; a step of 0 or backwards (a repeated or out-of-order
    frame) is counted apart and breaks the stretch too."""
    t = np.asarray(tick).astype(np.uint32, copy=False)
    if not len(t):
        return np.zeros(0, dtype=bool), 0, 0
    steps = np.empty(len(t), dtype=np.uint32)
    steps[0] = 1 if previous_tick is None else (int(t[0]) - int(previous_tick)) % TICK_MODULUS
    np.subtract(t[1:], t[:-1], out=steps[1:])          # uint32 arithmetic wraps with the tick
    gap = steps != 1
    if not gap.any():
        return gap, 0, 0
    odd = steps[gap].astype(np.int64)
    back = (odd == 0) | (odd >= TICK_MODULUS // 2)     # no advance, or a step backwards
    return gap, int((odd[~back] - 1).sum()), int(back.sum())


def missing_before(tick, previous_tick: int | None = None) -> np.ndarray:
    """Frames missing just before each frame, from the device ticks (as frame_steps
    counts them): k - 1 for a step of k > 1 ticks, -1 for a step of 0 or backwards (a
    repeated or out-of-order frame: a break of no known length), else 0.  The jitter's
    high-pass bridges a short hole with it (jitter.BRIDGE_MAX_PERIODS)."""
    t = np.asarray(tick).astype(np.uint32, copy=False)
    if not len(t):
        return np.zeros(0, dtype=np.int64)
    steps = np.empty(len(t), dtype=np.int64)
    steps[0] = 1 if previous_tick is None else (int(t[0]) - int(previous_tick)) % TICK_MODULUS
    steps[1:] = np.subtract(t[1:], t[:-1])             # uint32 arithmetic wraps with the tick
    back = (steps == 0) | (steps >= TICK_MODULUS // 2)
    return np.where(back, -1, steps - 1)


__all__ = ["TICK_MODULUS", "frame_steps", "missing_before"]
