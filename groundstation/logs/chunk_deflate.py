"""Chunks deflated outside HDF5's filter pipeline, stored as HDF5's own filters store them.

Compressing a finished log (compress.py) through h5py costs a read of every value
through the library's type conversion, then the filter pipeline's shuffle and zlib's
deflate at level 1.  Deflate was about half of it, and zlib's encoder is not the
fastest one that writes deflate's format: ISA-L (Intel's storage acceleration library,
through the `isal` package) writes the same RFC 1950 zlib stream about 2.8 times
faster at its level 1, for a ratio 2 % lower on our logs (3.14 against 3.20 on a 60 s
log, measured: docs/campaigns.md, "Fifth round").

So the copy takes each stored chunk of an uncompressed dataset as bytes (sliced from
the file mapped in memory at the address HDF5 gives for it, or `read_direct_chunk`),
checks that it is a whole chunk's size, shuffles it as HDF5's shuffle filter does
(byte k of every element together, k = 0 .. size-1), deflates it, and stores the result
with `write_direct_chunk` in a dataset created with the same shuffle and deflate
filters.  A reader - h5py, h5dump, MATLAB, anything with HDF5's deflate filter, which
inflates with zlib - cannot tell the chunk from one HDF5 wrote itself.  compress.py
then reads each dataset's first and last chunk back through HDF5 and compares them
with the original byte for byte: a mistake in the encoding would be in every chunk, so
it fails the compression instead of changing a log.

Only the pipelines this module knows are taken this way: a source dataset stored with
no filter at all, a fixed-size numeric or byte type, and a target pipeline of deflate
alone or shuffle then deflate.  Anything else is copied through h5py as before.
"""

from __future__ import annotations

import zlib
from typing import Callable

import h5py
import numpy as np

try:                                   # the same stream, faster; zlib where no wheel exists
    from isal.isal_zlib import compress as _deflate_fast
except ImportError:                    # isal has wheels for Linux, macOS and Windows
    _deflate_fast = zlib.compress
#: ISA-L's level 1 (of 0-3); zlib's 1 where it stands in
_DEFLATE_LEVEL = 1

ChunkEncoder = Callable[[bytes], bytes]


def deflate(data: bytes) -> bytes:
    """One chunk in the zlib format HDF5's deflate filter reads."""
    return _deflate_fast(data, _DEFLATE_LEVEL)


def shuffle(data: bytes, element_size: int) -> bytes:
    """HDF5's shuffle filter: the first byte of every element, then every second byte,
    ...  (a chunk is always a whole number of elements here: whole stored chunks)."""
    if element_size <= 1:
        return data
    return np.frombuffer(data, np.uint8).reshape(-1, element_size).T.tobytes()


def chunk_encoder(source: h5py.Dataset, target: h5py.Dataset,
                  deflate_chunk: ChunkEncoder = deflate) -> ChunkEncoder | None:
    """How to turn `source`'s stored chunks into `target`'s, or None when that is not a
    pipeline this module reproduces exactly (the caller copies through h5py then)."""
    if not hasattr(source.id, "chunk_iter"):       # h5py built on HDF5 before 1.12.3
        return None
    if source.id.get_create_plist().get_nfilters() != 0:
        return None
    if source.dtype.kind not in "biufc" or source.dtype.hasobject or source.dtype.names:
        return None
    if source.chunks != target.chunks or source.dtype != target.dtype:
        return None
    element_size = source.dtype.itemsize
    pipeline = _filters(target)
    if pipeline == [h5py.h5z.FILTER_DEFLATE]:
        return deflate_chunk
    if pipeline == [h5py.h5z.FILTER_SHUFFLE, h5py.h5z.FILTER_DEFLATE]:
        return lambda data: deflate_chunk(shuffle(data, element_size))
    return None


def copy_chunks(source: h5py.Dataset, target: h5py.Dataset, encode: ChunkEncoder,
                file_bytes: memoryview | None = None) -> None:
    """Every chunk `source` has stored, encoded into `target` at the same place (chunks
    never written stay unwritten: both read as the fill value, which the caller set the
    same).  `file_bytes`: the source file mapped in memory (a file with no user block,
    where HDF5's chunk addresses are offsets in the file): each chunk is sliced from it
    instead of asked of HDF5 one call at a time, a fifth of the copy's time."""
    whole = source.dtype.itemsize * int(np.prod(source.chunks, dtype=np.int64))
    stored: list[tuple[tuple[int, ...], int, int]] = []
    source.id.chunk_iter(lambda c: stored.append((c.chunk_offset, c.byte_offset, c.size)))
    for offset, address, size in stored:
        if file_bytes is not None:
            data = file_bytes[address:address + size]
        else:
            data = source.id.read_direct_chunk(offset)[1]
        if size != whole or len(data) != whole:   # an index pointing past the file's end
            raise OSError(f"{source.name}: the chunk at {offset} is {len(data)} bytes where "
                          f"an uncompressed chunk has {whole}: the log is damaged")
        target.id.write_direct_chunk(offset, encode(data), 0)   # mask 0: every filter applied


def _filters(dataset: h5py.Dataset) -> list[int]:
    plist = dataset.id.get_create_plist()
    return [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
