"""A recorded log as `TelemetryBlock`s again, in the order they arrived: the part of
replay without threads or pacing (`iter_blocks`, and the core of `ReplaySource`).

The blocks are decoded again from the raw frames stored under `/frames/<PACKET>` with a
`FrameCodec` of the log's own protocol files (or of a dictionary given by the caller),
so they carry the same columns, `raw` records and `host_time` (the recorded arrival
times) as the blocks the link delivered live, and the same sequence gaps show up as the
same drops.

Order
    Frames of all packets are merged in recorded arrival order: host arrival time, ties
    broken by packet id (the order the deframer hands out the packets of one read),
    then row.  A block is a run of consecutive frames of one packet.  Each merged frame
    also carries a device-time timeline: the running maximum of device time along the
    merged order (a housekeeping frame that arrived late never moves time backwards),
    by which `ReplaySource` paces playback.

Reading
    The log is opened by `LogReader` (SWMR, no file lock: see opening.py), which also
    checks that it is a log, says what is damaged, and provides the datasets and the
    protocol files; nothing here opens the file itself.  It is read a few seconds at a
    time (an index of host and device times per packet, then the frame bytes of the
    merged window); seeking uses the logs package's one row search (rows.py) on the
    device-time column.  On reaching the end the datasets are refreshed, so a log that
    is still being written plays on as it grows, and only then is it finished.

Times given to `locate` and `iter_blocks(start=, stop=)` are device times in seconds
as recorded in `/telemetry/<PACKET>/device_time` (unwrapped device tick / tick rate).
"""

from __future__ import annotations

import contextlib
import logging
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import h5py
import numpy as np

from ..codec import FrameCodec, TelemetryBlock
from ..core.dictionary import CRC_SIZE, HEADER_SIZE, Dictionary, PacketDef, load_dictionary
from ..core.errors import GroundStationError
from .opening import H5_READ_ERRORS, LogDamagedError, LogError, first_unreadable, unreadable_text
from .reader import LogReader
from .rows import search_sorted

log = logging.getLogger(__name__)

MAIN_PACKET = "HIGH_RATE"


class ReplayError(LogError):
    """A log cannot be replayed (missing file, not a log, unreadable protocol, ...)."""


class ReplayDamagedError(LogDamagedError, ReplayError):
    """The log is damaged (truncated, overwritten, empty): both a ReplayError and a
    LogDamagedError, whose message says what is damaged and what to do."""


def _unreadable(ds: h5py.Dataset, start: int, stop: int, exc: BaseException) -> ReplayDamagedError:
    """The error for a failed read of rows [start, stop) of `ds`, naming the first
    unreadable row."""
    row, _ = first_unreadable(ds, start, stop)
    return ReplayDamagedError(Path(ds.file.filename), unreadable_text(ds, row, exc))


@contextlib.contextmanager
def _replay_errors(path: Path) -> Iterator[None]:
    """Errors of the log reader as replay's: damage as ReplayDamagedError (what and
    whether it is salvageable unchanged), anything else the reader refuses as ReplayError."""
    try:
        yield
    except ReplayError:
        raise
    except LogDamagedError as exc:
        raise ReplayDamagedError(path, exc.what, salvageable=exc.salvageable) from None
    except LogError as exc:
        raise ReplayError(str(exc)) from None


# ---------------------------------------------------------------------- opening
def _open_log(path: Path) -> LogReader:
    """The log opened for replay, through LogReader: the same checks and words as
    `log info` and export, with replay's own advice for a wrong path."""
    if not path.exists():
        raise ReplayError(f"{path}: no such log file - check the path")
    if path.is_dir():
        raise ReplayError(f"{path} is a folder, not a log file - choose one of the .h5 files in it")
    with _replay_errors(path):
        return LogReader(path)


def _log_dictionary(reader: LogReader) -> Dictionary:
    """The dictionary the log was recorded with, from its /protocol/*.toml texts."""
    texts = reader.protocol_files()
    try:
        with tempfile.TemporaryDirectory(prefix="gs-replay-") as tmp:
            for name, text in texts.items():
                (Path(tmp) / name).write_text(text, encoding="utf-8")
            d = load_dictionary(tmp)
    except GroundStationError as exc:
        raise ReplayError(f"{reader.path}: the protocol files stored in the log cannot be loaded "
                          f"({exc}); pass a dictionary to decode it with") from None
    recorded = reader.attrs.get("dictionary_hash")
    if recorded is not None and str(recorded) != f"{d.hash:08x}":
        log.warning("%s: stored protocol files hash to %08x, the log says %s", reader.path, d.hash,
                    recorded)
    return d


# ---------------------------------------------------------------------- one packet's frames
class _Track:
    """The recorded frames of one packet, read through a cursor a chunk at a time."""

    def __init__(self, reader: LogReader, pkt: PacketDef, index: int, chunk_rows: int):
        self.pkt = pkt
        self.index = index
        self.rank = pkt.id
        self.chunk_rows = chunk_rows
        frames = f"frames/{pkt.name}"
        self.host_ds = reader.dataset(f"{frames}/host_time")
        self.dev_ds = reader.dataset(f"telemetry/{pkt.name}/device_time")
        self.fixed = pkt.variable_item is None
        if self.fixed:
            self.data_ds = reader.dataset(f"{frames}/data")
            width = pkt.fixed_payload_size + HEADER_SIZE + CRC_SIZE
            if self.data_ds.shape[1] != width:
                raise ReplayError(
                    f"{pkt.name} frames in the log are {self.data_ds.shape[1]} bytes long, the "
                    f"dictionary's are {width}: decode it with the protocol it was recorded with")
            self.datasets = [self.data_ds, self.host_ds, self.dev_ds]
        else:
            self.data_ds, self.off_ds, self.len_ds = (reader.dataset(f"{frames}/stream/{c}")
                                                      for c in ("data", "offset", "length"))
            self.datasets = [self.data_ds, self.off_ds, self.len_ds, self.host_ds, self.dev_ds]
        self.n_rows = 0
        self.update_rows()
        self.reset(0, None)

    def update_rows(self) -> None:
        """Rows complete in every dataset (a growing log may show them one by one)."""
        try:
            self._update_rows()
        except H5_READ_ERRORS as exc:
            ds = self.data_ds if self.fixed else self.off_ds
            raise _unreadable(ds, max(0, ds.shape[0] - 1), ds.shape[0], exc) from None

    def _update_rows(self) -> None:
        if self.fixed:
            n = min(self.data_ds.shape[0], self.host_ds.shape[0], self.dev_ds.shape[0])
        else:
            n = min(self.off_ds.shape[0], self.len_ds.shape[0], self.host_ds.shape[0],
                    self.dev_ds.shape[0])
            size = self.data_ds.shape[0]
            while n and int(self.off_ds[n - 1]) + int(self.len_ds[n - 1]) > size:
                n -= 1
        self.n_rows = max(self.n_rows, n)

    def refresh(self) -> None:
        for ds in self.datasets:
            ds.refresh()
        self.update_rows()

    def reset(self, row: int, stop: int | None) -> None:
        self.loaded = row                    # next row not yet in the index buffer
        self.stop = stop
        self.buf_row = row                   # row of buf_keys[0]
        self.buf_keys = np.zeros(0)
        self.buf_dev = np.zeros(0)
        self.buf_host = np.zeros(0)
        self.key_carry = -math.inf

    @property
    def limit(self) -> int:
        return self.n_rows if self.stop is None else min(self.n_rows, self.stop)

    @property
    def more(self) -> bool:
        """Rows beyond the index buffer (known now)."""
        return self.loaded < self.limit

    def fill(self) -> bool:
        """Index the next chunk of rows: host time (merge key) and device time."""
        start, stop = self.loaded, min(self.limit, self.loaded + self.chunk_rows)
        if stop <= start:
            return False
        host = self._rows(self.host_ds, start, stop)
        dev = self._rows(self.dev_ds, start, stop)
        keys = np.maximum.accumulate(np.maximum(host, self.key_carry))
        self.key_carry = float(keys[-1])
        self.buf_keys = np.concatenate((self.buf_keys, keys))
        self.buf_dev = np.concatenate((self.buf_dev, dev))
        self.buf_host = np.concatenate((self.buf_host, host))
        self.loaded = stop
        return True

    def take(self, count: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        row = self.buf_row
        keys, dev, host = self.buf_keys[:count], self.buf_dev[:count], self.buf_host[:count]
        self.buf_keys, self.buf_dev, self.buf_host = (self.buf_keys[count:], self.buf_dev[count:],
                                                      self.buf_host[count:])
        self.buf_row += count
        return row, keys, dev, host

    @staticmethod
    def _rows(ds: h5py.Dataset, start: int, stop: int) -> np.ndarray:
        try:
            return ds[start:stop]
        except H5_READ_ERRORS as exc:
            raise _unreadable(ds, start, stop, exc) from None

    def read(self, row: int, count: int) -> np.ndarray | list[bytes]:
        """The raw frames of rows [row, row + count)."""
        if self.fixed:
            return self._rows(self.data_ds, row, row + count)
        off = self._rows(self.off_ds, row, row + count).astype(np.int64)
        ln = self._rows(self.len_ds, row, row + count).astype(np.int64)
        base = int(off[0])
        blob = self._rows(self.data_ds, base, int(off[-1] + ln[-1])).tobytes()
        return [blob[o - base:o - base + n] for o, n in zip(off.tolist(), ln.tolist())]


def _search(ds: h5py.Dataset, n: int, value: float, side: str = "left") -> int:
    """The logs package's row search (rows.py), its read errors named as replay's."""
    try:
        return search_sorted(ds, n, value, side)
    except H5_READ_ERRORS as exc:
        raise _unreadable(ds, 0, n, exc) from None


# ---------------------------------------------------------------------- merged windows
@dataclass
class _Window:
    """A few seconds of merged frames: which track, which row, device-time timeline."""

    track: np.ndarray          # track index per merged frame
    row: np.ndarray            # row in that track
    timeline: np.ndarray       # running maximum of device time along the merged order
    first_row: dict[int, int]  # track index -> first row held in `frames`
    frames: dict[int, Any]     # track index -> raw frames of the window
    host: dict[int, np.ndarray]
    k: int = 0                 # next merged frame to deliver

    def __len__(self) -> int:
        return len(self.track)


class BlockMerger:
    """Non-threaded core of replay: the log's packets merged in arrival order, decoded a
    window at a time into blocks."""

    def __init__(self, path: str | Path, dictionary: Dictionary | None = None,
                 main_packet: str | None = None, chunk_seconds: float = 4.0):
        self.path = Path(path)
        self.log = _open_log(self.path)
        try:
            with _replay_errors(self.path):
                self._setup(dictionary, main_packet, chunk_seconds)
        except BaseException:
            self.log.close()
            raise

    def _setup(self, dictionary: Dictionary | None, main_packet: str | None,
               chunk_seconds: float) -> None:
        self.attrs = self.log.attrs
        self.dictionary = dictionary if dictionary is not None else _log_dictionary(self.log)
        self.codec = FrameCodec(self.dictionary)
        recorded = set(self.log.packets()) & set(self.log.h5["frames"].keys())
        self.tracks: list[_Track] = []
        for pkt in sorted(self.dictionary.packets, key=lambda p: p.id):
            if pkt.name not in recorded:
                continue
            rows = max(256, int((pkt.rate_hz or 0) * chunk_seconds))
            self.tracks.append(_Track(self.log, pkt, len(self.tracks), rows))
        if not self.tracks:
            raise ReplayError(f"{self.path}: no recorded packet is known to the dictionary")
        names = [t.pkt.name for t in self.tracks]
        if main_packet is None:
            main_packet = MAIN_PACKET if MAIN_PACKET in names else max(
                self.tracks, key=lambda t: t.pkt.rate_hz or 0).pkt.name
        if main_packet not in names:
            raise ReplayError(f"{self.path}: no packet {main_packet!r} in the log "
                              f"(recorded: {', '.join(names)})")
        self.main = names.index(main_packet)
        self._timeline_carry = -math.inf

    # --------------------------------------------------------------- extent
    @property
    def main_track(self) -> _Track:
        return self.tracks[self.main]

    def time_range(self) -> tuple[float, float] | None:
        t = self.main_track
        if not t.n_rows:
            return None
        ends = t._rows(t.dev_ds, 0, 1), t._rows(t.dev_ds, t.n_rows - 1, t.n_rows)
        return float(ends[0][0]), float(ends[1][0])

    def refresh(self) -> bool:
        """Look for rows appended since the last look (a log still being written; the
        file is always open in SWMR read mode, so this works for every log)."""
        before = [t.n_rows for t in self.tracks]
        for t in self.tracks:
            t.refresh()
        return any(t.n_rows > b for t, b in zip(self.tracks, before))

    # --------------------------------------------------------------- positioning
    def locate(self, device_time: float) -> tuple[list[int], float | None]:
        """Rows per track where the merged order reaches the first main-packet frame at or
        after `device_time`, and that frame's device time (None beyond the end)."""
        self.refresh()                      # a growing log: seek into what is there now
        main = self.main_track
        r = _search(main.dev_ds, main.n_rows, device_time)
        if r >= main.n_rows:
            return [t.n_rows for t in self.tracks], None
        key = float(main._rows(main.host_ds, r, r + 1)[0])
        rows = []
        for t in self.tracks:
            if t is main:
                rows.append(r)
            else:   # frames of t that sort before (key, main rank, r) in the merge
                side = "right" if t.rank < main.rank else "left"
                rows.append(_search(t.host_ds, t.n_rows, key, side))
        return rows, float(main._rows(main.dev_ds, r, r + 1)[0])

    def reset(self, rows: list[int] | None = None, stops: list[int] | None = None) -> None:
        for i, t in enumerate(self.tracks):
            t.reset(rows[i] if rows else 0, stops[i] if stops else None)
        self._timeline_carry = -math.inf

    # --------------------------------------------------------------- merging
    def next_window(self) -> _Window | None:
        """The next merged window, or None at the end (after a refresh found nothing new)."""
        while True:
            for t in self.tracks:
                if not len(t.buf_keys):
                    t.fill()
            # frames may be merged up to the smallest last key of the tracks with more rows;
            # frames at exactly that key wait (more of them may follow in the unread rows)
            pending = [t for t in self.tracks if t.more]
            horizon = min((float(t.buf_keys[-1]) for t in pending), default=math.inf)
            counts = [len(t.buf_keys) if horizon == math.inf else
                      int(np.searchsorted(t.buf_keys, horizon, side="left")) for t in self.tracks]
            if sum(counts):
                return self._build(counts)
            if horizon == math.inf:
                if self.refresh():
                    continue
                return None
            for t in pending:
                if float(t.buf_keys[-1]) == horizon:
                    t.fill()

    def _build(self, counts: list[int]) -> _Window:
        parts = []
        frames: dict[int, Any] = {}
        host: dict[int, np.ndarray] = {}
        first: dict[int, int] = {}
        for t, c in zip(self.tracks, counts):
            if not c:
                continue
            row, keys, dev, h = t.take(c)
            frames[t.index] = t.read(row, c)
            host[t.index] = np.ascontiguousarray(h)
            first[t.index] = row
            parts.append((keys, np.full(c, t.rank), np.arange(row, row + c),
                          np.full(c, t.index), dev))
        keys, ranks, rows, idx, dev = (np.concatenate(x) for x in zip(*parts))
        order = np.lexsort((rows, ranks, keys))
        dev = dev[order]
        timeline = np.maximum.accumulate(np.maximum(dev, self._timeline_carry))
        self._timeline_carry = float(timeline[-1])
        return _Window(idx[order], rows[order], timeline, first, frames, host)

    # --------------------------------------------------------------- decoding
    def runs(self, w: _Window, k0: int, k1: int) -> Iterator[tuple[int, TelemetryBlock]]:
        """Merged frames [k0, k1) of a window as blocks of consecutive frames of one
        packet, each with the merged index just after its last frame (decoded lazily)."""
        if k1 <= k0:
            return
        trk = w.track[k0:k1]
        cuts = np.concatenate(([0], np.flatnonzero(np.diff(trk)) + 1, [len(trk)]))
        for a, b in zip(cuts[:-1].tolist(), cuts[1:].tolist()):
            ti = int(trk[a])
            t = self.tracks[ti]
            lo = int(w.row[k0 + a]) - w.first_row[ti]
            hi = lo + (b - a)
            host = w.host[ti][lo:hi].copy()
            if t.fixed:   # a copy: a block kept by a consumer does not pin the whole window
                yield k0 + b, self.codec.decode_fixed(t.pkt, w.frames[ti][lo:hi].copy(), host)
            else:
                yield k0 + b, self.codec.decode_variable(t.pkt, w.frames[ti][lo:hi], host)

    def close(self) -> None:
        self.log.close()


# ---------------------------------------------------------------------- iterator
def iter_blocks(path: str | Path, start: float | None = None, stop: float | None = None,
                dictionary: Dictionary | None = None) -> Iterator[TelemetryBlock]:
    """All recorded telemetry of a log as blocks, in arrival order, without threads.

    `start`/`stop` are device times (s): the range begins at the first frame of the main
    packet at or after `start` and ends before the first one at or after `stop` (frames
    of other packets go with the main-packet frames they arrived among).  Raises
    ReplayError (on the first next()) if the file cannot be replayed."""
    reader = BlockMerger(path, dictionary)
    try:
        rows = reader.locate(start)[0] if start is not None else None
        stops = None
        if stop is not None:
            stop_rows, found = reader.locate(stop)
            stops = stop_rows if found is not None else None
        reader.reset(rows, stops)
        while (w := reader.next_window()) is not None:
            for _, block in reader.runs(w, 0, len(w)):
                yield block
    finally:
        reader.close()


__all__ = ["BlockMerger", "MAIN_PACKET", "ReplayDamagedError", "ReplayError", "iter_blocks"]
