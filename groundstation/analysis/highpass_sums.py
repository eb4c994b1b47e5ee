"""The running sums of the high-pass jitter over a series with holes, fed whole or in
pieces: where the filter H(s) = s/(s + 1/dT_i) is bridged across a hole, where it
restarts, and which of its outputs count.

Why not simply restart at every hole.  A restart initialises the filter in steady state
on the stretch's first sample: its low-pass state (the "DC" the high-pass removes) is
pinned at that one value and reaches the signal's own slow level only after a few time
constants dT_i.  On a log whose sensor clips, every stretch starts at the range's edge,
so each restart adds a transient as large as the excursion, and a campaign log with many
short stretches gave a high-pass RMS above the run's own standard deviation - which a
filter of gain <= 1 cannot produce from the signal itself (issue 28).  Three rules:

* **bridge short holes.**  A hole of at most `bridge_samples` (missing frames and
  excluded samples together) does not restart the filter: it runs on through the hole
  with its input held at the last usable value, and its outputs there are not counted.
  The hold is wrong by at most the signal's change over the hole, which the low-pass
  state follows only at the rate 1/dT_i: over a hole of 1 % of dT_i the state moves by
  at most 1 % of that change - far less than a restart's transient, and the stretch's
  filter keeps its settled state.
* **discard the settling.**  After a restart, the first `settle_samples` outputs (a
  stated number of time constants dT_i) are counted apart (`settling`), not in the sums:
  the restart's error in the low-pass state decays as exp(-t/dT_i); after 3 dT_i the
  residual is 5 % of the initial error in amplitude (e^-6 = 0.25 % of its power).
* **a stretch shorter than the settling contributes nothing** - it has no settled output.

The state carried from one piece to the next (filter state, the value held, the time
since the restart and the hole still open) makes the pieces give the same sums as the
whole, so `los_jitter` and `JitterAccumulator` agree.  No I/O here.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from . import AnalysisError


class HighpassSums:
    """Sum of squares of the settled high-pass output, over a series fed in order.

    `b`, `a`: the discrete filter; `bridge_samples`: the longest hole bridged (samples
    of device time); `settle_samples`: outputs discarded after each restart."""

    def __init__(self, b: np.ndarray, a: np.ndarray, *, bridge_samples: int, settle_samples: int):
        if bridge_samples < 0 or settle_samples < 0:
            raise AnalysisError("the bridge and the settling must be >= 0 samples")
        self._b, self._a = b, a
        self._zi = signal.lfilter_zi(b, a)
        self.bridge_samples = int(bridge_samples)
        self.settle_samples = int(settle_samples)
        self.sum_squares = 0.0
        self.used = 0                 # outputs counted (settled)
        self.settling = 0             # outputs discarded while settling after a restart
        self.restarts = 0             # filter starts (the first included)
        self.bridged = 0              # holes bridged without a restart
        self._zf: np.ndarray | None = None    # None: no filter running (the next sample restarts)
        self._last = 0.0              # the last usable sample: the input held through a hole
        self._elapsed = 0             # samples of device time since the running filter started
        self._pending = 0             # samples of the hole after the last usable sample so far

    def feed(self, x: np.ndarray, ok: np.ndarray, missing_before: np.ndarray | None = None) -> None:
        """The next piece: its samples `x`, `ok` (usable), `missing_before` (frames
        missing just before each sample; -1: a break of unknown length, which always
        restarts; None: none missing)."""
        n = len(x)
        if not n:
            return
        if missing_before is None:
            miss = np.zeros(n, dtype=np.int64)
        else:
            miss = np.asarray(missing_before, dtype=np.int64)
            if miss.shape != (n,):
                raise AnalysisError(f"missing_before must have one entry per sample ({n})")
        # cumulative missing frames and hard breaks up to and including each sample
        cm = np.concatenate([[0], np.cumsum(np.maximum(miss, 0))])
        ch = np.concatenate([[0], np.cumsum(miss < 0)])
        idx = np.flatnonzero(ok)
        if not len(idx):
            self._grow_hole(n + int(cm[-1]), bool(ch[-1]))
            return
        nxt = idx + 1
        # hole before each usable sample: excluded samples and missing frames since the
        # previous usable one (for the first: since the last one of the previous piece)
        hole = np.empty(len(idx), dtype=np.int64)
        hard = np.empty(len(idx), dtype=bool)
        hole[0] = self._pending + idx[0] + cm[nxt[0]]
        hard[0] = self._zf is None or bool(ch[nxt[0]])
        hole[1:] = (idx[1:] - idx[:-1] - 1) + (cm[nxt[1:]] - cm[nxt[:-1]])
        hard[1:] = ch[nxt[1:]] > ch[nxt[:-1]]
        restart = hard | (hole > self.bridge_samples)
        starts = np.flatnonzero(restart[1:]) + 1
        bounds = np.concatenate([[0], starts, [len(idx)]])
        for j0, j1 in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
            self._segment(x[idx[j0:j1]], hole[j0:j1], bool(restart[j0]))
        self._pending = 0
        tail = n - nxt[-1]
        self._grow_hole(int(tail + cm[n] - cm[nxt[-1]]), bool(ch[n] > ch[nxt[-1]]))

    def _grow_hole(self, samples: int, hard: bool) -> None:
        if self._zf is None:
            return
        self._pending += samples
        if hard or self._pending > self.bridge_samples:
            self._zf = None          # too long: the next usable sample restarts

    def _segment(self, v: np.ndarray, hole: np.ndarray, restart: bool) -> None:
        """Usable samples `v` joined by bridged holes (`hole[k]`: the hole before v[k])."""
        if restart:
            zi, elapsed0, prefix = self._zi * v[0], 0, 0
            self.restarts += 1
        else:
            zi, elapsed0, prefix = self._zf, self._elapsed, int(hole[0])
        inner = hole[1:]
        self.bridged += int(np.count_nonzero(inner)) + (1 if prefix else 0)
        # each value is held through the hole after it; the held copies are filtered, not counted
        rep = np.concatenate([1 + inner, [1]])
        inputs = np.repeat(v, rep)
        if prefix:
            inputs = np.concatenate([np.full(prefix, self._last), inputs])
        pos = prefix + np.concatenate([[0], np.cumsum(rep[:-1])])
        y, self._zf = signal.lfilter(self._b, self._a, inputs, zi=zi)
        settled = elapsed0 + pos >= self.settle_samples
        ys = y[pos[settled]]
        self.sum_squares += float(np.dot(ys, ys))
        k = int(np.count_nonzero(settled))
        self.used += k
        self.settling += len(pos) - k
        self._last = float(v[-1])
        self._elapsed = elapsed0 + len(inputs)


__all__ = ["HighpassSums"]
