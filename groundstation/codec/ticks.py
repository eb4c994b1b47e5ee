"""The device's tick as one continuing count.

The device stamps every frame with a u32 tick of its control clock (1200 Hz, SPEC §3),
which wraps after about 41 days; the host's timebase (link statistics, the display
store, the log writer, the generator journal) needs a count that keeps increasing.
The rule is the sequence tracker's (codec/sequence.py): a step backwards of more than
half the range is a wrap, anything smaller is the device's own doing and kept."""

from __future__ import annotations

import numpy as np

from .sequence import SEQ_MOD


class TickUnwrapper:
    """u32 device ticks -> monotonically continuing int64 (handles the 2^32 wrap)."""

    def __init__(self) -> None:
        self._last: int | None = None
        self._base = 0

    def unwrap(self, ticks: np.ndarray) -> np.ndarray:
        t = ticks.astype(np.int64)
        if not len(t):
            return t
        prev = np.concatenate(([self._last if self._last is not None else t[0]], t[:-1]))
        wraps = np.cumsum(((t - prev) < -(SEQ_MOD // 2)).astype(np.int64))
        out = t + (self._base + wraps * SEQ_MOD)
        self._base += int(wraps[-1]) * SEQ_MOD
        self._last = int(t[-1])
        return out

    def unwrap_scalar(self, tick: int) -> int:
        return int(self.unwrap(np.array([tick], dtype=np.int64))[0])
