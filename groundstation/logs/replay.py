"""Replay of a recorded log through the same interface as the live link.

`ReplaySource` looks to its consumers like a `DeviceClient`: `subscribe(cb)` receives
`TelemetryBlock`s in a worker thread, `add_link_listener(cb(state, message))`,
`stats` (a `LinkStatistics` fed with every block before the subscribers see it),
`link_state`, `close()` and use as a context manager.  The blocks are decoded again
from the raw frames stored under `/frames/<PACKET>` with a `FrameCodec` of the log's
own protocol files (or of a dictionary given by the caller), so they carry the same
columns, `raw` records and `host_time` (the recorded arrival times) as the blocks the
link delivered live, and the same sequence gaps show up as the same drops.

Order and timing
    Frames of all packets are merged in recorded arrival order: host arrival time, ties
    broken by packet id (the order the deframer hands out the packets of one read),
    then row.  A block is a run of consecutive frames of one packet.  Playback is paced
    by *device* time: at speed s, a frame is delivered at wall time
    t0 + (T - T0) / s, where T is the running maximum of the device time along the
    merged order (a housekeeping frame that arrived late never moves time backwards).
    The worker wakes at most ~60 times a second and delivers what is due, in blocks of
    at most 1/60 s of device time; with speed None ("max") it delivers whole runs as
    fast as the subscribers take them.

Reading
    The file is opened read-only in SWMR mode and read a few seconds at a time (an index
    of host and device times per packet, then the frame bytes of the merged window);
    seeking bisects the device-time column.  On reaching the end the datasets are
    refreshed, so a log that is still being written plays on as it grows, and only then
    is the replay finished.

Times given to `seek`, `iter_blocks(start=, stop=)` and reported by `position`,
`start_time` and `end_time` are device times in seconds as recorded in
`/telemetry/<PACKET>/device_time` (unwrapped device tick / tick rate).
"""

from __future__ import annotations

import bisect
import logging
import math
import tempfile
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import h5py
import numpy as np

from ..codec import FrameCodec, TelemetryBlock
from ..dictionary import CRC_SIZE, HEADER_SIZE, Dictionary, PacketDef, load_dictionary
from ..errors import GroundStationError
from .reader import (H5_READ_ERRORS, LogDamagedError, LogError, LogFormatError, first_unreadable,
                     open_log_file)
from ..link.stats import LinkStatistics
from . import schema

log = logging.getLogger(__name__)

MIN_SPEED = 0.1
MAX_SPEED = 50.0
DELIVERY_PERIOD_S = 1.0 / 60.0     # worker wake-up period and device time per paced block
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
    where = f"after frame {row}" if row else "from its first frame"
    return ReplayDamagedError(Path(ds.file.filename),
                              f"dataset {ds.name} unreadable {where} (of {ds.shape[0]}; {exc})")


# ---------------------------------------------------------------------- opening
def _open_log(path: Path) -> h5py.File:
    if not path.exists():
        raise ReplayError(f"{path}: no such log file - check the path")
    if path.is_dir():
        raise ReplayError(f"{path} is a folder, not a log file - choose one of the .h5 files in it")
    try:
        f, _ = open_log_file(path)
    except LogDamagedError as exc:
        try:          # not written in the SWMR format (e.g. converted): read it plainly
            f = h5py.File(path, "r")
        except OSError:
            raise ReplayDamagedError(path, exc.what, salvageable=exc.salvageable) from None
    except LogFormatError as exc:        # not HDF5 at all
        raise ReplayError(str(exc)) from None
    except LogError as exc:
        raise ReplayError(str(exc)) from None
    try:
        found = f.attrs.get("schema")
        if isinstance(found, bytes):
            found = found.decode("utf-8", "replace")
        if found != schema.SCHEMA:
            raise ReplayError(f"{path} is an HDF5 file but not a ground-station log "
                              f"(its 'schema' attribute is {found!r}, expected {schema.SCHEMA!r})")
        version = int(f.attrs.get("schema_version", 0))
        if version > schema.SCHEMA_VERSION:
            raise ReplayError(f"{path} uses log schema version {version}; this ground station "
                              f"reads up to version {schema.SCHEMA_VERSION} - update it")
        for group in ("frames", "telemetry", "protocol"):
            if group not in f:
                raise ReplayError(f"{path}: the log has no /{group} group - the file is "
                                  f"incomplete or not a ground-station log")
    except BaseException:
        f.close()
        raise
    return f


def _log_dictionary(f: h5py.File, path: Path) -> Dictionary:
    """The dictionary the log was recorded with, from its /protocol/*.toml texts."""
    try:
        with tempfile.TemporaryDirectory(prefix="gs-replay-") as tmp:
            for name, ds in f["protocol"].items():
                value = ds[()]
                text = value.decode("utf-8") if isinstance(value, bytes) else str(value)
                (Path(tmp) / name).write_text(text, encoding="utf-8")
            d = load_dictionary(tmp)
    except GroundStationError as exc:
        raise ReplayError(f"{path}: the protocol files stored in the log cannot be loaded "
                          f"({exc}); pass a dictionary to decode it with") from None
    recorded = f.attrs.get("dictionary_hash")
    if recorded is not None and str(recorded) != f"{d.hash:08x}":
        log.warning("%s: stored protocol files hash to %08x, the log says %s", path, d.hash, recorded)
    return d


# ---------------------------------------------------------------------- one packet's frames
class _Track:
    """The recorded frames of one packet, read through a cursor a chunk at a time."""

    def __init__(self, f: h5py.File, pkt: PacketDef, index: int, chunk_rows: int):
        self.pkt = pkt
        self.index = index
        self.rank = pkt.id
        self.chunk_rows = chunk_rows
        g = f["frames"][pkt.name]
        self.host_ds = g["host_time"]
        self.dev_ds = f["telemetry"][pkt.name]["device_time"]
        self.fixed = pkt.variable_item is None
        if self.fixed:
            self.data_ds = g["data"]
            width = pkt.fixed_payload_size + HEADER_SIZE + CRC_SIZE
            if self.data_ds.shape[1] != width:
                raise ReplayError(
                    f"{pkt.name} frames in the log are {self.data_ds.shape[1]} bytes long, the "
                    f"dictionary's are {width}: decode it with the protocol it was recorded with")
            self.datasets = [self.data_ds, self.host_ds, self.dev_ds]
        else:
            s = g["stream"]
            self.data_ds, self.off_ds, self.len_ds = s["data"], s["offset"], s["length"]
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


def _bisect_ds(ds: h5py.Dataset, n: int, value: float, right: bool = False) -> int:
    """First row of ds[:n] (ascending) with ds >= value (> value with right=True)."""

    class _View:
        def __getitem__(self, i: int) -> float:
            return float(ds[i])

        def __len__(self) -> int:
            return n

    fn = bisect.bisect_right if right else bisect.bisect_left
    try:
        return fn(_View(), value)  # type: ignore[arg-type]
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


class _LogReader:
    """Non-threaded core: opens a log, merges its packets, decodes windows into blocks."""

    def __init__(self, path: str | Path, dictionary: Dictionary | None = None,
                 main_packet: str | None = None, chunk_seconds: float = 4.0):
        self.path = Path(path)
        self.f = _open_log(self.path)
        try:
            self.swmr = bool(self.f.swmr_mode)
            self.attrs = {k: (v.item() if isinstance(v, np.generic) else v)
                          for k, v in self.f.attrs.items()}
            self.dictionary = dictionary if dictionary is not None else _log_dictionary(self.f, self.path)
            self.codec = FrameCodec(self.dictionary)
            self.tracks: list[_Track] = []
            for pkt in sorted(self.dictionary.packets, key=lambda p: p.id):
                if pkt.name not in self.f["frames"] or pkt.name not in self.f["telemetry"]:
                    continue
                rows = max(256, int((pkt.rate_hz or 0) * chunk_seconds))
                self.tracks.append(_Track(self.f, pkt, len(self.tracks), rows))
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
        except BaseException:
            self.f.close()
            raise

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
        """Look for rows appended since the last look (a log still being written)."""
        if not self.swmr:
            return False
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
        r = _bisect_ds(main.dev_ds, main.n_rows, device_time)
        if r >= main.n_rows:
            return [t.n_rows for t in self.tracks], None
        key = float(main._rows(main.host_ds, r, r + 1)[0])
        rows = []
        for t in self.tracks:
            if t is main:
                rows.append(r)
            else:   # frames of t that sort before (key, main rank, r) in the merge
                rows.append(_bisect_ds(t.host_ds, t.n_rows, key, right=t.rank < main.rank))
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
        self.f.close()


# ---------------------------------------------------------------------- iterator
def iter_blocks(path: str | Path, start: float | None = None, stop: float | None = None,
                dictionary: Dictionary | None = None) -> Iterator[TelemetryBlock]:
    """All recorded telemetry of a log as blocks, in arrival order, without threads.

    `start`/`stop` are device times (s): the range begins at the first frame of the main
    packet at or after `start` and ends before the first one at or after `stop` (frames
    of other packets go with the main-packet frames they arrived among).  Raises
    ReplayError (on the first next()) if the file cannot be replayed."""
    reader = _LogReader(path, dictionary)
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


# ---------------------------------------------------------------------- threaded source
def _check_speed(speed: Any) -> float | None:
    if speed is None or (isinstance(speed, str) and speed.lower() == "max"):
        return None
    if isinstance(speed, bool) or not isinstance(speed, (int, float, np.integer, np.floating)):
        raise ValueError(f"replay speed must be a number from {MIN_SPEED} to {MAX_SPEED} "
                         f"or None/'max', not {speed!r}")
    s = float(speed)
    if not MIN_SPEED <= s <= MAX_SPEED:     # NaN fails this too
        raise ValueError(f"replay speed {speed} is outside {MIN_SPEED}..{MAX_SPEED} "
                         f"(use None or 'max' for as fast as possible)")
    return s


class ReplaySource:
    """A recorded log played back through the live link's consumer interface.

    Starts paused at the beginning; `play()`, `pause()`, `step(n)`, `seek(t)`,
    `seek_fraction(x)` and `speed` may be used from any thread (they only post a request
    to the worker, which does all the file I/O and calls the subscribers).  Listeners
    get ('finished', '') at the end, ('up', '') when a seek or play leaves the end, ('lost',
    message) if the file fails while playing, and ('closed', '') on close().

    `stats` is fed every block before the subscribers, so the sequence gaps recorded
    live count as the same drops and gap events (with their recorded arrival times).  A
    seek resets it (a jump is not a drop).  play() at the end looks
    for rows a recorder appended since; to play again from the start, seek first.
    """

    def __init__(self, path: str | Path, *, dictionary: Dictionary | None = None,
                 speed: float | str | None = 1.0, main_packet: str | None = None,
                 chunk_seconds: float = 4.0):
        self._speed = _check_speed(speed)
        self._reader = _LogReader(path, dictionary, main_packet, chunk_seconds)
        self.path = self._reader.path
        self.dictionary = self._reader.dictionary
        self.codec = self._reader.codec
        self.attrs = self._reader.attrs
        self.main_packet = self._reader.main_track.pkt.name
        self.stats = LinkStatistics(self.dictionary.control_rate_hz)
        self.link_state = "up"
        self.link_error = ""
        self.error: Exception | None = None     # what stopped the replay ('lost'), if anything
        self.subscriber_errors = 0
        self.frames_delivered = 0
        self._subscribers: list[Callable[[TelemetryBlock], None]] = []
        self._listeners: list[Callable[[str, str], None]] = []
        rng = self._reader.time_range()
        self._start_time, self._end_time = rng if rng else (0.0, 0.0)
        self._position: float | None = None
        self._cv = threading.Condition()
        self._ops: deque[tuple[str, Any]] = deque()
        self._playing = False
        self._closed = False
        self._idle = True
        self._reanchor = True
        self._finished = threading.Event()
        self._window: _Window | None = None
        self._thread = threading.Thread(target=self._run, name="gs-replay", daemon=True)
        self._thread.start()

    # --------------------------------------------------------------- consumer interface
    def subscribe(self, callback: Callable[[TelemetryBlock], None]) -> None:
        """Call `callback(block)` for every replayed block (in the replay thread)."""
        self._subscribers.append(callback)

    def add_link_listener(self, callback: Callable[[str, str], None]) -> None:
        """Call `callback(state, message)`: 'finished', 'up', 'lost', 'closed'."""
        self._listeners.append(callback)

    def _notify(self, state: str, message: str = "") -> None:
        for cb in list(self._listeners):
            try:
                cb(state, message)
            except Exception:
                log.exception("replay listener failed")

    # --------------------------------------------------------------- controls
    def play(self) -> None:
        """Play from the current position at `speed` (at the end: look for new rows)."""
        with self._cv:
            if self._finished.is_set():
                self._ops.append(("resume", None))
            self._playing = True
            self._reanchor = True
            self._idle = False
            self._cv.notify_all()

    def pause(self) -> None:
        """Stop after the block being delivered; the position is kept."""
        with self._cv:
            self._playing = False
            self._cv.notify_all()

    def step(self, n: int = 1) -> None:
        """Pause, then deliver the next n frames of the main packet together with the
        other packets' frames that arrived before them."""
        n = int(n)
        if n < 1:
            raise ValueError(f"step count must be at least 1, not {n}")
        with self._cv:
            self._playing = False
            self._ops.append(("step", n))
            self._cv.notify_all()

    def seek(self, device_time_s: float) -> None:
        """Continue (playing or paused) from the first main-packet frame at or after
        `device_time_s`; sequence statistics start afresh (see `stats`)."""
        t = float(device_time_s)
        if math.isnan(t):
            raise ValueError("cannot seek to NaN")
        with self._cv:
            self._ops.append(("seek", t))
            self._reanchor = True
            self._cv.notify_all()

    def seek_fraction(self, fraction: float) -> None:
        """Seek to a fraction 0..1 of the duration."""
        x = float(fraction)
        if not 0.0 <= x <= 1.0:
            raise ValueError(f"seek fraction {fraction} is outside 0..1")
        self.seek(self._start_time + x * (self._end_time - self._start_time))

    @property
    def speed(self) -> float | None:
        """Playback speed 0.1..50, or None for as fast as possible."""
        return self._speed

    @speed.setter
    def speed(self, value: float | str | None) -> None:
        s = _check_speed(value)
        with self._cv:
            self._speed = s
            self._reanchor = True
            self._cv.notify_all()

    @property
    def playing(self) -> bool:
        return self._playing and not self._finished.is_set()

    @property
    def position(self) -> float | None:
        """Device time (s) of the last delivered frame; after a seek, of the frame it
        landed on until the next delivery; None before anything was delivered."""
        return self._position

    @property
    def start_time(self) -> float:
        """Device time (s) of the first main-packet frame."""
        return self._start_time

    @property
    def end_time(self) -> float:
        return self._end_time

    @property
    def duration(self) -> float:
        """Device time (s) from the first to the last main-packet frame known so far."""
        return self._end_time - self._start_time

    @property
    def finished(self) -> bool:
        return self._finished.is_set()

    @property
    def finished_event(self) -> threading.Event:
        return self._finished

    def wait_finished(self, timeout: float | None = None) -> bool:
        return self._finished.wait(timeout)

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Wait until every posted step/seek is done and nothing is playing (paused or at
        the end); True if so within the timeout."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cv:
            while not self._closed and not (self._idle and not self._ops):
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self._cv.wait(left)
            return True

    def close(self) -> None:
        """Stop the worker and close the file; safe to call twice, from any thread."""
        with self._cv:
            if self._closed:
                return
            self._closed = True
            self._cv.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)
        self.link_state = "closed"
        self._notify("closed", "")

    def __enter__(self) -> "ReplaySource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --------------------------------------------------------------- worker
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # a damaged or vanished file: say so, keep the app running
            self.error = exc
            if isinstance(exc, GroundStationError):
                # says what and where, and the consumer gets it (`error`, the 'lost'
                # listener): no traceback, and nothing on a terminal beside its report
                msg = f"replay of {self.path.name} stopped: {exc}"
                log.info(msg)
            else:
                msg = f"replay of {self.path.name} stopped: {type(exc).__name__}: {exc}"
                log.exception(msg)
            self.link_error = msg
            self.link_state = "lost"
            with self._cv:
                self._idle = True
                self._ops.clear()
                self._cv.notify_all()
            self._finished.set()
            self._notify("lost", msg)
        finally:
            self._reader.close()

    def _loop(self) -> None:
        anchor_wall = anchor_t = 0.0
        last_wake = -math.inf
        while True:
            with self._cv:
                while not self._closed and not self._ops and not (
                        self._playing and not self._finished.is_set()):
                    self._idle = True
                    self._cv.notify_all()
                    self._cv.wait()
                if self._closed:
                    return
                self._idle = False
                op = self._ops.popleft() if self._ops else None
                speed = self._speed
                reanchor = False
                if op is None:          # a seek's re-anchoring waits for the seek to be done
                    reanchor, self._reanchor = self._reanchor, False
            if op is not None:
                self._operation(*op)
                continue
            w = self._current()
            if w is None:
                continue
            if speed is None:
                self._deliver(w, len(w), self._interrupted)
                continue
            now = time.monotonic()
            if reanchor:
                anchor_wall = now
                anchor_t = self._position if self._position is not None else float(w.timeline[w.k])
                anchor_t = min(anchor_t, float(w.timeline[w.k]))
            limit = anchor_t + (now - anchor_wall) * speed
            due = int(np.searchsorted(w.timeline, limit, side="right"))
            k = w.k
            while k < due:      # blocks of at most DELIVERY_PERIOD_S of device time
                k_end = max(k + 1, int(np.searchsorted(w.timeline, w.timeline[k] + DELIVERY_PERIOD_S,
                                                       side="left")))
                k = self._deliver(w, min(k_end, due), self._interrupted)
                if self._interrupted():
                    break
            if k < len(w) and k >= due:
                last_wake = now
                next_due = anchor_wall + (float(w.timeline[k]) - anchor_t) / speed
                wake = max(next_due, last_wake + DELIVERY_PERIOD_S)
                with self._cv:
                    if not self._closed and not self._ops and not self._reanchor and self._playing:
                        self._cv.wait(max(0.0, wake - time.monotonic()))

    def _closing(self) -> bool:
        return self._closed

    def _interrupted(self) -> bool:
        with self._cv:
            return self._closed or bool(self._ops) or self._reanchor or not self._playing

    def _current(self) -> _Window | None:
        """The window being delivered; the next one when it is used up; None at the end."""
        w = self._window
        if w is not None and w.k < len(w):
            return w
        w = self._window = self._reader.next_window()
        if w is None:
            self._set_finished()
        else:
            rng = self._reader.time_range()
            if rng:
                self._start_time, self._end_time = rng
        return w

    def _set_finished(self) -> None:
        rng = self._reader.time_range()
        if rng:
            self._start_time, self._end_time = rng
        if not self._finished.is_set():
            self._finished.set()
            self._notify("finished", "")

    def _clear_finished(self) -> None:
        if self._finished.is_set():
            self._finished.clear()
            self._notify("up", "")

    def _deliver(self, w: _Window, k_end: int, stop: Callable[[], bool] | None = None) -> int:
        """Deliver merged frames w.k .. k_end block by block: stats first, then the
        subscribers; `stop()` is asked after each block.  Returns the index reached."""
        for k, block in self._reader.runs(w, w.k, k_end):
            self.stats.update(block)
            for cb in list(self._subscribers):
                try:
                    cb(block)
                except Exception:
                    self.subscriber_errors += 1
                    log.exception("replay subscriber %r failed", cb)
            self.frames_delivered += k - w.k
            self._position = float(w.timeline[k - 1])
            w.k = k
            if stop is not None and k < k_end and stop():
                break
        return w.k

    def _operation(self, kind: str, arg: Any) -> None:
        if kind == "seek":
            rows, landed = self._reader.locate(arg)
            self._reader.reset(rows)
            self._window = None
            self.stats.reset()
            rng = self._reader.time_range()
            if rng:
                self._start_time, self._end_time = rng
            if landed is not None:
                self._position = landed
                self._clear_finished()
            else:
                self._position = self._end_time if rng else None
                self._set_finished()
        elif kind == "resume":
            w = self._window
            if (w is not None and w.k < len(w)) or self._reader.refresh():
                self._clear_finished()
        elif kind == "step":
            remaining = arg
            while remaining > 0:
                with self._cv:
                    if self._closed:
                        return
                w = self._current()
                if w is None:
                    return
                main = np.flatnonzero(w.track[w.k:] == self._reader.main)[:remaining]
                if len(main) == remaining:
                    self._deliver(w, w.k + int(main[-1]) + 1, self._closing)
                    return
                remaining -= len(main)
                self._deliver(w, len(w), self._closing)
