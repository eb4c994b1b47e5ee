"""Opening a log for reading, and telling a damaged log from one that is not a log.

This is the one place that opens a log file for reading: `LogReader`, `log check`,
export, redecode and replay all come through `open_log_file()`, so they accept and
refuse the same files with the same words.  The errors of the logs package live here
too, because opening is where most of them are first raised.

How a reader opens the file (`open_h5`)
    swmr=True: the recorder writes in SWMR mode and HDF5 marks such a file as open for
    writing until its recorder stops; only a SWMR reader accepts it, and only a SWMR
    reader can `refresh()` to follow it while it grows.  HDF5 >= 1.10 opens every
    superblock version this way, so a SWMR open also covers a log that was written or
    converted without SWMR; a plain (non-SWMR) open would add nothing but refuse the
    live file.  (Replay used to fall back to a plain open when the SWMR open failed.
    That open fails as well on every file that reaches it - empty, superblock gone,
    truncated - so the fallback was removed rather than kept as a second way in.)

    locking=False: with HDF5's file lock a reader holds a shared lock for as long as
    it has the file open, and the recorder's final reopen, which marks the log
    `clean_close`, then fails in the writing process.  A reader changes nothing, so it
    needs no lock.  HDF5 refuses to open a file twice in one process with different
    locking flags; when this process already has it open with the lock (a `LogFile`
    written in-process, as tests and scripts do) the reader opens it with the lock too.

    metadata read attempts = SWMR_METADATA_READ_ATTEMPTS: in SWMR read mode HDF5 takes
    a metadata block whose checksum does not match for one a writer is rewriting at
    that moment, and reads it again, sleeping 1, 2, 4, ... ns between attempts - by
    default 100 attempts, 2^100 ns: for ever, inside one C call, deaf to Ctrl-C.  A
    truncated or overwritten log has such blocks for good (past the cut HDF5 reads
    zeros), so `log check`, `log info` or `export --salvage` hung on the first one they
    touched (issue 29).  The attempts are bounded here, on the file-access property list
    (H5Pset_metadata_read_attempts, which h5py does not wrap: it is called from the
    HDF5 library h5py itself is linked to).  The bound still rides out a writer's
    rewrite (a few ms); a block that stays wrong then fails as any unreadable block
    does, and the callers say what is damaged.  Where the call is not available (a
    platform whose loader cannot find it), a log no writer has open is opened without
    SWMR (one read attempt, as HDF5 does outside SWMR; a truncated file is then refused
    at opening, which HDF5 checks only outside SWMR).
"""

from __future__ import annotations

import ctypes
import functools
import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from h5py import h5f, h5p

from ..core.errors import GroundStationError
from . import schema


class LogError(GroundStationError):
    """A log cannot be opened or a request to it cannot be answered (message says why)."""


class LogFormatError(LogError):
    """The file is not a ground-station log this version can read (not HDF5, another
    schema, a newer schema version, or a damaged layout)."""


class LogQueryError(LogError):
    """A request names a packet, channel, timebase or journal kind the log does not have."""


class EmptyRangeError(LogQueryError):
    """A time or tick range holds no frames of the packet."""


class LogDamagedError(LogFormatError):
    """The file is (or was) a log but part of it cannot be read: empty, superblock
    destroyed, truncated, or a dataset / attribute that HDF5 cannot read any more.

    `what` names the damage; the message adds the file and what to do about it
    (`groundstation log check`, and `log export --salvage` when something is readable;
    `advice` replaces that where the caller knows better)."""

    def __init__(self, path: str | Path, what: str, *, salvageable: bool = True,
                 advice: str | None = None):
        self.path = Path(path)
        self.what = what
        self.salvageable = salvageable
        if advice is None and salvageable:
            advice = (f"run `groundstation log check {self.path}` to see what is readable, and "
                      f"`groundstation log export {self.path} --salvage` to export it")
        elif advice is None:
            advice = (f"nothing in it can be read (`groundstation log check {self.path}` "
                      f"says what was found)")
        self.advice = advice
        super().__init__(f"{self.path}: damaged log, {what}; {advice}")


#: what h5py raises when the bytes under a read are not what HDF5 wrote (a filter fails,
#: a signature or checksum does not match, an address lies past the end of the file)
H5_READ_ERRORS = (OSError, RuntimeError)
#: signatures of HDF5 structures (object header, B-trees, heaps, chunk index) that show
#: a file without a valid superblock once was an HDF5 file
_HDF5_SIGNATURES = (b"OHDR", b"TREE", b"GCOL", b"FRHP", b"BTHD", b"EAHD", b"FAHD")


def attr_text(value: Any) -> str:
    """An attribute (or scalar dataset) value as str, whichever way h5py returns it."""
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.shape == ():
        return attr_text(value[()])
    return "" if value is None else str(value)


# ---------------------------------------------------------------------- damage
def truncation_text(actual: int, expected: int) -> str:
    return f"truncated: file ends at byte {actual}, HDF5 expects {expected}"


def truncated_advice(actual: int, expected: int) -> str:
    """What to do with a truncated log of which nothing can be read: only its source
    has the rest."""
    return (f"nothing in it can be read, and only {actual} of its {expected} bytes "
            f"({100 * actual // max(1, expected)} %) are there: copy the log again from "
            f"where it came from")


def file_truncation(f: h5py.File, path: Path) -> tuple[int, int] | None:
    """(bytes on disk, bytes HDF5 expects) if the file is shorter than its superblock's
    end-of-file address says, else None.  HDF5 itself refuses such a file in normal read
    mode ("truncated file: eof = ..."), but not in the SWMR read mode we use (a writer
    may be extending it), so we ask: H5Fget_filesize is max(end of allocated space,
    end of file), larger than the size on disk exactly when the file was cut short."""
    try:
        expected = int(f.id.get_filesize())
        actual = os.stat(path).st_size
    except (OSError, RuntimeError):
        return None
    return (actual, expected) if expected > actual else None


def superblock_eof(path: Path) -> int | None:
    """End-of-file address from a version 2/3 superblock at offset 0 (the format our
    logs use), for when HDF5 cannot open the file to say it: signature (8 bytes),
    version, sizes of offsets and lengths, flags, then base, extension and EOF addresses."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(48)
    except OSError:
        return None
    if len(head) < 12 or head[:8] != b"\x89HDF\r\n\x1a\n" or head[8] not in (2, 3):
        return None
    size = head[9]
    at = 12 + 2 * size
    if size not in (4, 8) or len(head) < at + size:
        return None
    return int.from_bytes(head[at:at + size], "little")


def _looks_like_hdf5_body(path: Path, limit: int = 4 << 20) -> bool:
    try:
        with open(path, "rb") as fh:
            body = fh.read(limit)
    except OSError:
        return False
    return any(sig in body for sig in _HDF5_SIGNATURES)


def first_unreadable(ds: h5py.Dataset, start: int, stop: int) -> tuple[int, str]:
    """(k, error) for rows [start, stop) of `ds`: rows start..k-1 read, row k's chunk does
    not (k == stop and error '' when all read).  Reads many chunks at a time and narrows
    down to one chunk only where a read fails."""
    step = ds.chunks[0] if ds.chunks else max(1, stop - start)
    block = step * 256
    a = start
    while a < stop:
        b = min(stop, a + block)
        try:
            ds[a:b]
        except H5_READ_ERRORS as exc:
            first_error = str(exc)
            c = a
            while c < b:
                d = min(b, (c // step + 1) * step)
                try:
                    ds[c:d]
                except H5_READ_ERRORS as exc2:
                    return c, str(exc2)
                c = d
            return a, first_error          # only the large read fails: be conservative
        a = b
    return stop, ""


def unreadable_text(ds: h5py.Dataset, row: int, exc: BaseException) -> str:
    """The `what` of a LogDamagedError for a dataset that stops reading at `row`: the
    same words whether the reader or replay found it."""
    where = f"after frame {row}" if row else "from its first frame"
    n = ds.shape[0] if ds.shape else 0
    return f"dataset {ds.name} unreadable {where} (of {n}; {exc})"


# ---------------------------------------------------------------------- opening
#: SWMR read: reads of a metadata block whose checksum does not match before HDF5 gives
#: up on it (module docstring).  The sleeps between them double from 1 ns, so 24
#: attempts wait up to 2^24 ns = 17 ms in all (measured: 20 ms) - far longer than a
#: writer takes to rewrite a block, and a damaged log with a few hundred bad blocks
#: still answers in seconds.
SWMR_METADATA_READ_ATTEMPTS = 24


@functools.lru_cache(maxsize=1)
def _set_metadata_read_attempts():
    """HDF5's H5Pset_metadata_read_attempts from the library h5py is linked to, or None.

    It is looked up through h5py's own extension module: the dynamic loader then
    searches that module's dependencies, so the function found belongs to the very
    HDF5 library (and the same property-list ids) h5py uses - never another copy of
    HDF5 that happens to be installed."""
    try:
        from h5py import defs
        fn = ctypes.CDLL(defs.__file__).H5Pset_metadata_read_attempts
    except (OSError, AttributeError, ImportError):
        return None
    fn.argtypes = [ctypes.c_int64, ctypes.c_uint]       # hid_t is 64-bit since HDF5 1.10
    fn.restype = ctypes.c_int
    return fn


def _writer_flags(path: Path) -> int | None:
    """The file-consistency flags of a version 3 superblock (byte 11): bit 0 a writer
    has the file open, bit 2 for SWMR writing; None for another superblock."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(12)
    except OSError:
        return None
    if len(head) < 12 or head[:8] != b"\x89HDF\r\n\x1a\n" or head[8] != 3:
        return None
    return head[11]


def _fapl(locking: bool) -> tuple[h5p.PropFAID, bool]:
    """File-access properties of a read: latest format, HDF5's file lock or not, and
    the bounded metadata read attempts; and whether the bound could be set."""
    fapl = h5p.create(h5p.FILE_ACCESS)
    fapl.set_libver_bounds(h5f.LIBVER_LATEST, h5f.LIBVER_LATEST)
    if not locking:
        fapl.set_file_locking(False, ignore_when_disabled=False)
    setter = _set_metadata_read_attempts()
    bounded = setter is not None and setter(fapl.id, SWMR_METADATA_READ_ATTEMPTS) >= 0
    return fapl, bounded


def _open(path: Path, locking: bool) -> h5py.File:
    fapl, bounded = _fapl(locking)
    flags = h5f.ACC_RDONLY | h5f.ACC_SWMR_READ
    if not bounded and not (_writer_flags(path) or 0) & 0x5:
        # no bound on SWMR's retries, and no writer that needs SWMR: a plain read tries
        # every metadata block once (module docstring)
        flags = h5f.ACC_RDONLY
    return h5py.File(h5f.open(os.fsencode(path), flags, fapl=fapl))


def open_h5(path: Path) -> h5py.File:
    """The file opened for reading: SWMR, without HDF5's file lock, with bounded
    metadata read attempts (module docstring)."""
    try:
        return _open(path, locking=False)
    except OSError as exc:
        if "locking" not in str(exc):
            raise
    return _open(path, locking=True)


def open_log_file(path: Path, *, salvage: bool = False) -> tuple[h5py.File, tuple[int, int] | None]:
    """Open `path` for SWMR reading, or say precisely why it cannot be read: no such
    file, empty, not HDF5, HDF5 structures without a superblock, unopenable, truncated.
    Returns the file and (bytes on disk, bytes expected) when it is truncated - which
    raises LogDamagedError unless `salvage` (then the caller reads what it can)."""
    if not path.exists():
        raise LogError(f"{path}: no such file")
    if not path.is_file():
        raise LogFormatError(f"{path} is not a file")
    try:
        size = path.stat().st_size
        is_hdf5 = h5py.is_hdf5(str(path))
    except OSError as exc:
        raise LogError(f"{path}: cannot read ({exc})") from None
    if size == 0:
        raise LogDamagedError(path, "not an HDF5 file: it is empty (0 bytes)", salvageable=False)
    if not is_hdf5:
        if _looks_like_hdf5_body(path):
            raise LogDamagedError(
                path, "not an HDF5 file any more: the HDF5 superblock at its start is destroyed "
                      "(HDF5 structures follow it, but no HDF5 reader can find them)",
                salvageable=False)
        try:
            with open(path, "rb") as fh:
                head = fh.read(16)
        except OSError:
            head = b""
        raise LogFormatError(
            f"{path} is not an HDF5 file (it starts with {head!r}); a ground-station "
            f"log is the .h5 file `groundstation record` writes")
    try:
        f = open_h5(path)
    except H5_READ_ERRORS as exc:
        expected = superblock_eof(path)
        if expected is not None and expected > size:
            raise LogDamagedError(path, truncation_text(size, expected) + " and what is left "
                                  f"cannot be opened ({exc})", salvageable=False,
                                  advice=truncated_advice(size, expected)) from None
        raise LogDamagedError(path, f"the HDF5 file cannot be opened ({exc})",
                              salvageable=False) from None
    cut = file_truncation(f, path)
    if cut is not None and not salvage:
        f.close()
        # a recorder may be between writing the superblock and extending the file at a
        # flush: a file it is still writing is looked at once more before it is called cut
        f = open_h5(path)
        cut = file_truncation(f, path)
        if cut is not None:
            f.close()
            raise LogDamagedError(path, truncation_text(*cut))
    return f, cut


def check_layout(f: h5py.File, path: Path) -> int:
    """The schema version of an opened file, or LogFormatError saying why it is not a
    log this version reads (no or another schema, newer version, groups missing)."""
    a = f.attrs
    if "schema" not in a:
        top = ", ".join(list(f.keys())[:10]) or "nothing"
        raise LogFormatError(f"{path} is an HDF5 file but not a ground-station log: no "
                             f"'schema' attribute (top level holds: {top})")
    found = attr_text(a["schema"])
    if found != schema.SCHEMA:
        raise LogFormatError(f"{path}: schema '{found}', not a ground-station log "
                             f"('{schema.SCHEMA}')")
    try:
        version = int(a["schema_version"])
    except (KeyError, TypeError, ValueError):
        raise LogFormatError(f"{path}: no valid 'schema_version' attribute "
                             f"(found {a.get('schema_version')!r})") from None
    if version > schema.SCHEMA_VERSION:
        raise LogFormatError(
            f"{path}: log schema_version {version} is newer than this ground station "
            f"reads (up to {schema.SCHEMA_VERSION}); update the ground station to open it")
    if version < 1:
        raise LogFormatError(f"{path}: invalid schema_version {version}")
    missing = [g for g in ("telemetry", "frames", "journal", "protocol") if g not in f]
    if missing:
        raise LogFormatError(f"{path}: damaged log, group(s) {', '.join(missing)} missing")
    return version


__all__ = ["EmptyRangeError", "H5_READ_ERRORS", "LogDamagedError", "LogError", "LogFormatError",
           "LogQueryError", "attr_text", "check_layout", "file_truncation", "first_unreadable",
           "open_h5", "open_log_file", "superblock_eof", "truncated_advice", "truncation_text", "unreadable_text"]
