"""A batch of control periods run and its telemetry encoded in one pass.

The device runs the firmware in pieces cut at housekeeping boundaries (each
HOUSEKEEPING frame carries the state of its own tick), but encodes the batch's
HIGH_RATE frames in one call of the vectorised encoder, and its HOUSEKEEPING frames in
another, with the CRCs compiled (`frame_crc.py`).  Frames are kept as one bytes object
(`FrameRun`), not a list of frames: the fast path hands them on joined, and a datagram
is a slice of it.  Batch sizes never change a byte of what is sent
(`tests/sim/test_sim_frame_batches.py`).
"""

from __future__ import annotations

from typing import Callable, Iterator, MutableMapping

import numpy as np

from ..codec import FrameCodec
from . import core
from .engine import Engine
from .frame_crc import crc_rows
from .firmware import Firmware


class FrameRun:
    """Back-to-back frames of one size in one bytes object; iterates as frames."""

    __slots__ = ("data", "size")

    def __init__(self, data: bytes = b"", size: int = 0):
        self.data = data
        self.size = size

    def __len__(self) -> int:
        return len(self.data) // self.size if self.size else 0

    def __iter__(self) -> Iterator[bytes]:
        return self.groups(1)

    def groups(self, frames: int) -> Iterator[bytes]:
        """Consecutive runs of `frames` frames (the last one shorter), as bytes."""
        step = self.size * max(1, frames)
        data = self.data
        if not step:
            return iter(())
        return (data[off:off + step] for off in range(0, len(data), step))

    def frames(self) -> list[bytes]:
        return list(self.groups(1))


class TelemetryBatcher:
    """Runs n control periods of a firmware and encodes their frames."""

    def __init__(self, codec: FrameCodec, housekeeping_every: int):
        self.every = housekeeping_every
        self.high_rate = codec.encoder("HIGH_RATE", crc_rows)
        self.housekeeping = codec.encoder("HOUSEKEEPING", crc_rows)

    def run(self, fw: Firmware, n: int, sequence: MutableMapping[str, int], *, encode: bool,
            base_drive: Callable[[int, int], np.ndarray] | None = None,
            truth_sink: Callable[[int, np.ndarray], None] | None = None) -> tuple[FrameRun, FrameRun]:
        """(HIGH_RATE frames, HOUSEKEEPING frames) of the next n periods; `sequence`
        holds the next sequence number per packet and is advanced.  With `encode`
        False nothing is encoded and no sequence number is used up (SPEC §2)."""
        out = np.empty((n, core.N_OUT)) if encode else None
        first_tick = fw.tick + 1
        hk_rows: list[dict] = []
        hk_ticks: list[int] = []
        done = 0
        # the generator's output for the whole batch at once: a pure function of its
        # settings and the tick, and evaluating it per piece cost the simulator's child
        # 7 % of its CPU in a campaign (docs/campaigns.md, "Fifth round")
        drive = base_drive(first_tick, n) if base_drive is not None else None
        while done < n:
            step = min(n - done, self.every - fw.tick % self.every)
            piece_tick = fw.tick + 1
            v_fg = drive[done:done + step] if drive is not None else None
            _, truth = fw.run(step, v_fg, out=None if out is None else out[done:done + step])
            if truth_sink is not None:
                truth_sink(piece_tick, truth)
            done += step
            if encode and fw.tick % self.every == 0:
                hk_rows.append(fw.housekeeping())
                hk_ticks.append(fw.tick)
        if out is None or n == 0:
            return FrameRun(), FrameRun()
        high_rate = self._encode(self.high_rate, "HIGH_RATE", sequence, Engine.columns(out),
                                 np.arange(first_tick, first_tick + n))
        if not hk_rows:
            return high_rate, FrameRun()
        columns = {name: [row[name] for row in hk_rows] for name in hk_rows[0]}
        return high_rate, self._encode(self.housekeeping, "HOUSEKEEPING", sequence, columns,
                                       np.asarray(hk_ticks, dtype=np.int64))

    @staticmethod
    def _encode(encoder, packet: str, sequence: MutableMapping[str, int], columns,
                ticks: np.ndarray) -> FrameRun:
        seq = sequence[packet]
        sequence[packet] = (seq + len(ticks)) & 0xFFFFFFFF
        data = encoder.encode(columns, np.arange(seq, seq + len(ticks)), ticks)
        return FrameRun(data, encoder.frame_size)
