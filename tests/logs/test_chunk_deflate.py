"""Chunks deflated outside HDF5 (chunk_deflate.py) are the chunks HDF5's own shuffle and
deflate filters make: inflated, every stored chunk holds the same bytes as the one HDF5
wrote for the same values, and every value reads back, for each element size, NaN,
a partial last chunk and chunks never written; pipelines it does not reproduce are
left to h5py's copy."""

from __future__ import annotations

import zlib

import h5py
import numpy as np
import pytest

from groundstation.logs import schema
from groundstation.logs.chunk_deflate import chunk_encoder, copy_chunks, deflate, shuffle

CHUNK = 64


def _columns():
    rng = np.random.default_rng(7)
    n = 5 * CHUNK + 17                                         # a partial last chunk
    floats = rng.standard_normal(n)
    floats[[3, 200]] = np.nan
    return {
        "f8": floats,
        "f4": floats.astype(np.float32),
        "i2": rng.integers(-3000, 3000, n).astype(np.int16),
        "u4": np.arange(n, dtype=np.uint32) * 7,
        "b1": rng.random(n) > 0.5,
        "frames": rng.integers(0, 255, (n, 78)).astype(np.uint8),
    }


def _write(path, compression: dict, *, skip_chunk: bool = False) -> None:
    with h5py.File(path, "w", libver=schema.LIBVER) as f:
        for name, values in _columns().items():
            ds = f.create_dataset(name, shape=values.shape, maxshape=(None, *values.shape[1:]),
                                  dtype=values.dtype, chunks=(CHUNK, *values.shape[1:]),
                                  fillvalue=np.zeros((), values.dtype), **compression)
            if skip_chunk:                       # chunk 1 never written: reads as the fill value
                ds[:CHUNK] = values[:CHUNK]
                ds[2 * CHUNK:] = values[2 * CHUNK:]
            else:
                ds[...] = values


def _copy_into(source_path, target_path, compression: dict, deflate_chunk=deflate, mapped=False):
    with h5py.File(source_path, "r") as src, h5py.File(target_path, "w", libver=schema.LIBVER) as dst:
        view = memoryview(source_path.read_bytes()) if mapped else None
        for name, ds in src.items():
            out = dst.create_dataset(name, shape=ds.shape, maxshape=ds.maxshape, dtype=ds.dtype,
                                     chunks=ds.chunks, fillvalue=ds.fillvalue, **compression)
            encode = chunk_encoder(ds, out, deflate_chunk)
            assert encode is not None, name
            copy_chunks(ds, out, encode, view)


def _stored(path, name):
    with h5py.File(path, "r") as f:
        ds = f[name]
        offsets = []
        ds.id.chunk_iter(lambda c: offsets.append(c.chunk_offset))
        return {o: zlib.decompress(ds.id.read_direct_chunk(o)[1]) for o in offsets}


@pytest.mark.parametrize("skip_chunk", [False, True])
@pytest.mark.parametrize("mapped", [False, True])
def test_chunks_are_the_ones_hdf5_makes_and_every_value_reads_back(tmp_path, skip_chunk, mapped):
    raw, ours, theirs = tmp_path / "raw.h5", tmp_path / "ours.h5", tmp_path / "theirs.h5"
    _write(raw, {}, skip_chunk=skip_chunk)
    _write(theirs, schema.COMPRESSION, skip_chunk=skip_chunk)    # HDF5's own filters
    _copy_into(raw, ours, schema.COMPRESSION, mapped=mapped)
    with h5py.File(ours, "r") as o, h5py.File(raw, "r") as r:
        for name, values in _columns().items():
            assert o[name].compression == "gzip" and o[name].shuffle
            expected = r[name][()]
            assert o[name][()].tobytes() == expected.tobytes(), name          # NaN included
            if skip_chunk:
                assert not o[name][CHUNK:2 * CHUNK].any(), name
            assert _stored(ours, name) == _stored(theirs, name), name


def test_deflate_alone_and_zlibs_own_encoder_give_the_same_values(tmp_path):
    raw, ours = tmp_path / "raw.h5", tmp_path / "ours.h5"
    _write(raw, {})
    _copy_into(raw, ours, {"compression": "gzip", "compression_opts": 1},
               deflate_chunk=lambda data: zlib.compress(data, 1))
    with h5py.File(ours, "r") as o:
        for name, values in _columns().items():
            assert not o[name].shuffle
            assert o[name][()].tobytes() == values.tobytes(), name


def test_shuffle_groups_each_byte_of_every_element():
    data = np.array([0x0102, 0x0304, 0x0506], dtype="<u2").tobytes()
    assert shuffle(data, 2) == bytes([0x02, 0x04, 0x06, 0x01, 0x03, 0x05])
    assert shuffle(data, 1) == data


def test_pipelines_it_does_not_reproduce_are_left_to_h5py(tmp_path):
    raw, packed = tmp_path / "raw.h5", tmp_path / "packed.h5"
    _write(raw, {})
    _write(packed, schema.COMPRESSION)
    with h5py.File(raw, "r") as r, h5py.File(packed, "r") as p, h5py.File(tmp_path / "t.h5", "w") as t:
        lzf = t.create_dataset("lzf", shape=(10,), maxshape=(None,), dtype="f8", chunks=(CHUNK,), compression="lzf")
        other_chunks = t.create_dataset("c", shape=(10,), maxshape=(None,), dtype="f8", chunks=(2 * CHUNK,),
                                        **schema.COMPRESSION)
        same = t.create_dataset("s", shape=(10,), maxshape=(None,), dtype="f8", chunks=(CHUNK,), **schema.COMPRESSION)
        assert chunk_encoder(r["f8"], lzf) is None                # a filter it does not write
        assert chunk_encoder(r["f8"], other_chunks) is None       # chunks of another shape
        assert chunk_encoder(p["f8"], same) is None               # a source already filtered
        assert chunk_encoder(r["f8"], same) is not None


def test_a_chunk_that_is_not_whole_is_refused_not_written(tmp_path):
    """A chunk address past the end of the file (a damaged index) would slice a short
    chunk: it is refused with the dataset's name, before anything of it is written."""
    raw = tmp_path / "raw.h5"
    _write(raw, {})
    with h5py.File(raw, "r") as src, h5py.File(tmp_path / "t.h5", "w") as dst:
        ds = src["f8"]
        out = dst.create_dataset("f8", shape=ds.shape, maxshape=ds.maxshape, dtype=ds.dtype,
                                 chunks=ds.chunks, **schema.COMPRESSION)
        short = memoryview(raw.read_bytes())[:2048]          # the file cut short
        with pytest.raises(OSError, match="f8: the chunk at .* bytes where an uncompressed"):
            copy_chunks(ds, out, chunk_encoder(ds, out), short)
        assert out.id.get_num_chunks() == 0
