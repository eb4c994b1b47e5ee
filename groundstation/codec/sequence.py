"""Sequence numbers -> dropped frames, duplicates and wild values (one rule for all).

Every frame header carries a per-packet sequence number that counts up by one and wraps
at 2^32 (SPEC.md §2).  A jump forward means frames were lost; a repeat or a step back
means a duplicate or a late frame.  Taken at face value, one frame with a wild sequence
number (a forged frame that got through, a corrupted header with a matching CRC, a
device bug) would report up to four billion lost frames, and every good frame after it
would count as "late".  So a jump is not believed on its own: the frame after it must
continue from it.  If the next frame continues the old line instead, the jumping frame
was an outlier, counted as such and otherwise ignored.

The same tracker is used by the live link statistics, the display buffers and the log
reader, so a log's `log info` and the live view agree on what was dropped.

Cost: numpy for the common case (every step is +1); a Python loop runs only over the
frames where the step is not +1, which are rare on a healthy link.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SEQ_MOD = 1 << 32
HALF = SEQ_MOD // 2
#: A forward jump still waiting for its confirmation when the data end is believed
#: (counted as a gap) up to this size: about 55 s of HIGH_RATE, or a whole session of
#: the slower packets.  Beyond it, an unconfirmed last frame counts as an outlier.
UNCONFIRMED_GAP_LIMIT = 1 << 16


@dataclass
class SequenceReport:
    """What one call of SequenceTracker.feed found.

    gap_index: absolute index (frames fed since the tracker was made, from 0) of the
    first frame after each gap; missing: frames lost in each gap."""

    gap_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    missing: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    duplicates: int = 0       # repeated or late frames (a step of 0 or backwards)
    outliers: int = 0         # single frames off the sequence line, not believed
    restarts: int = 0         # the sequence started again elsewhere (device reboot)

    @property
    def dropped(self) -> int:
        return int(self.missing.sum()) if len(self.missing) else 0


class SequenceTracker:
    """Feed it the sequence column of each block of one packet, in arrival order."""

    def __init__(self) -> None:
        self.last: int | None = None        # last sequence number on the believed line
        self._suspect: tuple[int, int] | None = None   # (sequence, absolute index) awaiting its successor
        self.fed = 0

    def feed(self, sequence: np.ndarray) -> SequenceReport:
        seq = np.asarray(sequence).astype(np.int64) % SEQ_MOD
        n = len(seq)
        base = self.fed
        self.fed += n
        report = SequenceReport()
        if not n:
            return report
        if self.last is None and self._suspect is None:
            self.last = int(seq[0]) - 1 & (SEQ_MOD - 1)
        # fast path: find where the step from the previous frame is not +1
        prev0 = self._suspect[0] if self._suspect is not None else self.last
        prev = np.concatenate(([prev0], seq[:-1]))
        odd = np.flatnonzero((seq - prev) % SEQ_MOD != 1)
        if not len(odd) and self._suspect is None:
            self.last = int(seq[-1])
            return report
        gaps_at: list[int] = []
        gaps_n: list[int] = []
        i = 0 if self._suspect is not None else int(odd[0])
        if self._suspect is None:
            self.last = int(seq[i - 1]) if i > 0 else self.last
        # slow path from the first odd frame on, one frame at a time
        for k in range(i, n):
            s = int(seq[k])
            if self._suspect is not None:
                sus, sus_at = self._suspect
                if (s - sus) % SEQ_MOD == 1:           # the jump is confirmed
                    self._suspect = None
                    self._believe_jump(sus, sus_at, report, gaps_at, gaps_n)
                    self.last = s
                    continue
                self._suspect = None
                report.outliers += 1                  # the jumping frame was wild
            step = (s - self.last) % SEQ_MOD
            if step == 1:
                self.last = s
            elif step == 0:
                report.duplicates += 1
            else:
                self._suspect = (s, base + k)         # wait for the next frame
        report.gap_index = np.asarray(gaps_at, dtype=np.int64)
        report.missing = np.asarray(gaps_n, dtype=np.int64)
        return report

    def _believe_jump(self, sus: int, sus_at: int, report: SequenceReport,
                      gaps_at: list[int], gaps_n: list[int]) -> None:
        step = (sus - self.last) % SEQ_MOD
        if step < HALF:
            gaps_at.append(sus_at)
            gaps_n.append(step - 1)
        else:                                         # a new line behind the old one
            report.restarts += 1

    def finish(self) -> SequenceReport:
        """End of data: decide a jump that had no successor (believed if it is a
        modest forward gap, else counted as an outlier)."""
        report = SequenceReport()
        if self._suspect is None:
            return report
        sus, sus_at = self._suspect
        self._suspect = None
        step = (sus - self.last) % SEQ_MOD
        if 1 < step <= UNCONFIRMED_GAP_LIMIT:
            report.gap_index = np.array([sus_at], np.int64)
            report.missing = np.array([step - 1], np.int64)
            self.last = sus
        else:
            report.outliers += 1
        return report

    @property
    def pending(self) -> bool:
        """A jump is waiting for the next frame to confirm it."""
        return self._suspect is not None
