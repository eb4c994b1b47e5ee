"""Decode throughput on the same bytes, side by side in one run:

  ours      StreamDeframer.feed: sync search, header checks, CRC check of every frame,
            columns in engineering units (the path live telemetry takes)
  baseline  struct.iter_unpack over the same frames + zlib CRC per frame + per-field
            scaling in Python (what a hand-written host program does), with the benefit
            of assuming perfectly aligned frames (no sync search)
  limit     numpy copy of the same bytes (memory bandwidth: no decoder can beat it)

Run: .venv/bin/python benchmarks/bench_codec.py [--frames N]
"""

from __future__ import annotations

import argparse
import struct
import time
import zlib

import numpy as np

from common import machine, save
from groundstation.codec import StreamDeframer, FrameCodec
from groundstation.codec.crc import RESIDUE
from groundstation.core.dictionary import load_dictionary

LINK_RATE_HZ = 1200.0
STRUCT_CODES = {"u8": "B", "u16": "H", "u32": "I", "i8": "b", "i16": "h", "i32": "i",
                "f32": "f", "f64": "d"}


def make_frames(codec: FrameCodec, n: int, seed: int = 1) -> bytes:
    pkt = codec.packet("HIGH_RATE")
    rng = np.random.default_rng(seed)
    raw = {}
    for item in pkt.items:
        dt = item.wire_dtype
        if dt.kind == "f":
            raw[item.name] = rng.standard_normal(n).astype(dt)
        else:
            info = np.iinfo(dt)
            raw[item.name] = rng.integers(info.min, info.max, n, endpoint=True)
    return codec.encode(pkt, raw, np.arange(n), np.arange(n), engineering=False)


def ours(codec: FrameCodec, data: bytes) -> int:
    blocks = StreamDeframer(codec).feed(data, 0.0)
    return sum(len(b) for b in blocks)


def baseline(codec: FrameCodec, data: bytes) -> int:
    pkt = codec.packet("HIGH_RATE")
    fmt = ">HBBHII" + "".join(STRUCT_CODES[i.type] for i in pkt.items) + "4s"
    st = struct.Struct(fmt)
    size = st.size
    scales = [1.0] * 6 + [i.scale if i.scale is not None else 1.0 for i in pkt.items] + [None]
    mv = memoryview(data)
    rows = []
    append = rows.append
    for k, rec in enumerate(st.iter_unpack(data)):
        if zlib.crc32(mv[k * size:(k + 1) * size]) != RESIDUE:
            continue
        append([v * s for v, s in zip(rec[:-1], scales)])
    return len(rows)


def limit(data: bytes) -> int:
    return np.frombuffer(data, np.uint8).copy().nbytes


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    codec = FrameCodec(load_dictionary())
    data = make_frames(codec, args.frames)
    n, mb = args.frames, len(data) / 1e6
    assert ours(codec, data) == n and baseline(codec, data) == n
    t_ours = best_of(lambda: ours(codec, data), args.repeats)
    t_base = best_of(lambda: baseline(codec, data), max(1, args.repeats - 1))
    t_lim = best_of(lambda: limit(data), args.repeats)
    res = {
        "frames": n, "bytes": len(data), "frame_bytes": len(data) // n,
        "ours_frames_per_s": n / t_ours, "ours_MB_per_s": mb / t_ours,
        "baseline_frames_per_s": n / t_base, "baseline_MB_per_s": mb / t_base,
        "limit_frames_per_s": n / t_lim, "limit_MB_per_s": mb / t_lim,
        "ours_vs_baseline": t_base / t_ours, "ours_vs_limit": t_lim / t_ours,
        "ours_vs_link_rate": n / t_ours / LINK_RATE_HZ,
        "machine": f"{machine()}, numpy {np.__version__}",
    }
    print(f"decode of {n:,} HIGH_RATE frames ({res['frame_bytes']} B each, {mb:.1f} MB), CRC checked")
    print(f"  ours      {res['ours_frames_per_s']:>12,.0f} frames/s  {res['ours_MB_per_s']:8.1f} MB/s")
    print(f"  baseline  {res['baseline_frames_per_s']:>12,.0f} frames/s  {res['baseline_MB_per_s']:8.1f} MB/s  (struct.iter_unpack + zlib + scaling)")
    print(f"  limit     {res['limit_frames_per_s']:>12,.0f} frames/s  {res['limit_MB_per_s']:8.1f} MB/s  (numpy copy)")
    print(f"  ours / baseline = {res['ours_vs_baseline']:.1f}x   ours / limit = {res['ours_vs_limit']:.3f}   "
          f"ours / link rate (1200 Hz) = {res['ours_vs_link_rate']:,.0f}x")
    save("codec", res)
    return res


if __name__ == "__main__":
    main()
