"""Deflate a finished log in place: the same file, every per-frame dataset compressed.

A fast campaign's writer records without compression (deflate was the writer's whole
cost, and the stop of every run waited for it: docs/campaigns.md, "Fourth round"), and
its logs are compressed behind the campaign (compress_behind.py).  The compressed log
is written beside the original as a hidden temporary file, checked against it, flushed
to the disk and renamed over it: at every moment the name holds a whole log, the
uncompressed one or the compressed one.  A crash, a full disk or a damaged original
leaves the original as it was and removes the temporary file (a SIGKILL leaves it: a
hidden `.NAME.<8 hex digits>.part` beside the log (atomic.leftovers finds it), safe
to delete).

What is copied: every group, dataset and attribute, in the layout and with the chunk
shape they had; the chunked datasets (the per-frame columns, the byte streams, the
journal) get `schema.COMPRESSION`, the others (the protocol and testbed texts) are
copied as they are.  The chunks are deflated as stored, by ISA-L, outside HDF5's
filter pipeline (chunk_deflate.py); a layout it does not reproduce goes through h5py.
The root's `compression` attribute says what the file now has.

HDF5 after a failed write is not to be trusted (a full disk can end in a crash of the
library rather than an error): this runs in a process of its own, the compressing
process of compress_behind.py, for the command line as for a session.

Only a log closed cleanly is compressed: a log whose writer failed or was killed is
evidence, and stays exactly as it was recorded (`groundstation log check` reads it).
Why not h5repack: it is a separate tool a pip installation does not have, and it would
rewrite the file's format bounds (schema.LIBVER); h5py does the same copy here.
"""

from __future__ import annotations

import contextlib
import json
import mmap
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from ..core.errors import GroundStationError
from . import schema
from .atomic import atomic_output
from .chunk_deflate import chunk_encoder, copy_chunks
from .opening import H5_READ_ERRORS

#: bytes read and written per step of a dataset's copy (whole chunks): bounds the memory
#: a one-hour log's compression takes
COPY_BYTES = 16 << 20

COMPRESSED, SKIPPED, FAILED = "compressed", "skipped", "failed"


class LogCompressError(GroundStationError):
    """The compressed copy could not be written or did not match its original."""


@dataclass(frozen=True)
class CompressOutcome:
    path: Path
    state: str                   # compressed, skipped (with why), failed (with why)
    bytes_before: int = 0
    bytes_after: int = 0
    note: str = ""

    def text(self) -> str:
        if self.state == COMPRESSED:
            return (f"{self.path.name}: compressed, {self.bytes_before / 1e6:.1f} MB -> "
                    f"{self.bytes_after / 1e6:.1f} MB")
        return f"{self.path.name}: {self.state}, {self.note}"


def compress_log(path: str | Path, compression: dict | None = None) -> CompressOutcome:
    """Compress the log at `path` in place (see the module's text); never raises for a
    log it cannot or need not compress: the outcome says so, and the file is as it was."""
    path = Path(path)
    compression = dict(schema.COMPRESSION if compression is None else compression)
    try:
        size = path.stat().st_size
        why_not = _why_not(path, compression)
    except H5_READ_ERRORS as exc:                # OSError among them
        return CompressOutcome(path, FAILED, note=f"cannot read it as a log: {_describe(exc)}")
    if why_not:
        return CompressOutcome(path, SKIPPED, size, size, why_not)
    free = shutil.disk_usage(path.parent).free
    if free < size:              # the copy is at most about the original's size
        return CompressOutcome(path, FAILED, size, size, (
            f"left as recorded: {free / 1e6:.0f} MB free in {path.parent}, the compressed "
            f"copy may need up to {size / 1e6:.0f} MB"))
    try:
        with atomic_output(path, LogCompressError) as tmp:
            _copy(path, tmp, compression)
            _check_copy(path, tmp)
            _flush_to_disk(tmp)
        _flush_to_disk(path.parent)
        return CompressOutcome(path, COMPRESSED, size, path.stat().st_size)
    except (GroundStationError, *H5_READ_ERRORS) as exc:
        return CompressOutcome(path, FAILED, note=f"left as recorded: {_describe(exc)}")


def _describe(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror + (f" ({exc.filename})" if exc.filename else "")
    return str(exc) or type(exc).__name__


def _why_not(path: Path, compression: dict) -> str:
    """Why this log is left as it is ("" when it is to be compressed)."""
    with h5py.File(path, "r") as f:
        if f.attrs.get("schema") != schema.SCHEMA:
            return "not a ground-station log"
        if not f.attrs.get("clean_close", False):
            return ("it was not closed cleanly (a failed or killed recording): kept exactly "
                    "as recorded; `groundstation log check` says what of it is readable")
        try:
            recorded = json.loads(f.attrs.get("compression", "{}"))
        except ValueError:
            recorded = None
        if recorded == compression:
            return "already compressed"
    return ""


def _copy(source: Path, target: Path, compression: dict) -> None:
    with h5py.File(source, "r") as src, h5py.File(target, "w", libver=schema.LIBVER) as dst, \
            _mapped(source, src) as file_bytes:
        _copy_attrs(src, dst)
        dst.attrs["compression"] = json.dumps(compression)

        def visit(name: str, obj) -> None:
            if isinstance(obj, h5py.Group):
                _copy_attrs(obj, dst.create_group(name))
            elif obj.chunks is None:
                src.copy(obj, dst, name)            # a text: as it is, attributes and all
            else:
                _copy_dataset(obj, dst, name, compression, file_bytes)

        src.visititems(visit)


@contextlib.contextmanager
def _mapped(path: Path, opened: h5py.File):
    """The file's bytes mapped read-only, where HDF5's addresses are offsets in it (no
    user block), else None."""
    if opened.userblock_size != 0 or path.stat().st_size == 0:
        yield None
        return
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mapped:
        view = memoryview(mapped)
        try:
            yield view
        finally:
            view.release()


def _copy_attrs(src, dst) -> None:
    for name in src.attrs:
        dst.attrs.create(name, src.attrs[name], dtype=src.attrs.get_id(name).dtype)


def _copy_dataset(ds: h5py.Dataset, dst: h5py.File, name: str, compression: dict,
                  file_bytes: memoryview | None) -> None:
    out = dst.create_dataset(name, shape=ds.shape, maxshape=ds.maxshape, dtype=ds.dtype,
                             chunks=ds.chunks, fillvalue=ds.fillvalue, **compression)
    _copy_attrs(ds, out)
    encode = chunk_encoder(ds, out)
    if encode is not None:                  # stored chunks deflated as they are: chunk_deflate.py
        copy_chunks(ds, out, encode, file_bytes)
        return
    for rows in _steps(ds):
        out[rows] = ds[rows]


def _check_copy(source: Path, target: Path) -> None:
    """The copy has every object of the original, with its type, shape and attributes
    (the root's compression apart), and each chunked dataset's ends read back through
    HDF5 as the original's do: a mistake here would otherwise replace a log with less
    than it had."""
    with h5py.File(source, "r") as src, h5py.File(target, "r") as dst:
        def compare(name: str, obj) -> None:
            other = dst.get(name)
            if other is None or type(other) is not type(obj):
                raise LogCompressError(f"the compressed copy lacks /{name}")
            if isinstance(obj, h5py.Dataset) and (other.shape != obj.shape or other.dtype != obj.dtype):
                raise LogCompressError(f"the compressed copy of /{name} differs in shape or type")
            if sorted(other.attrs) != sorted(obj.attrs):
                raise LogCompressError(f"the compressed copy of /{name} differs in its attributes")
            if isinstance(obj, h5py.Dataset) and obj.chunks is not None and not _same_values(obj, other):
                raise LogCompressError(f"the compressed copy of /{name} reads back different values")

        src.visititems(compare)
        if sorted(dst.attrs) != sorted(src.attrs) or len(dst) != len(src):
            raise LogCompressError("the compressed copy differs at its root")


def _same_values(original: h5py.Dataset, copy: h5py.Dataset) -> bool:
    """The first and the last chunk's rows read back byte for byte (NaN included).  A
    mistake in how a chunk is encoded or stored (chunk_deflate.py) would be the same in
    every chunk, so the two ends find it without inflating the whole log again."""
    n, rows = original.shape[0], original.chunks[0]
    last = (max(n - 1, 0) // rows) * rows
    ends = [slice(0, min(rows, n))] + ([slice(last, n)] if last > 0 else [])
    return all(original[s].tobytes() == copy[s].tobytes() for s in ends)


def _steps(ds: h5py.Dataset):
    row_bytes = max(1, ds.dtype.itemsize * int(np.prod(ds.shape[1:], dtype=np.int64)))
    step = max(1, COPY_BYTES // (row_bytes * ds.chunks[0])) * ds.chunks[0]
    for start in range(0, ds.shape[0], step):
        yield slice(start, min(start + step, ds.shape[0]))


def _flush_to_disk(path: Path) -> None:
    """fsync: the rename that follows must not leave the name on a file whose data a
    power cut could still lose (the same for the folder's entry, afterwards)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
