"""Logging figures, side by side in one run:

  write     sustained recorder write rate (frames/s and x the 1200 Hz link), through the
            real Recorder (its writer process), for the chosen layout (gzip-1 + shuffle)
            and the alternatives: LZF + shuffle (h5py-only filter), no compression
  size      file size per hour of HIGH_RATE telemetry for each
  read      a one-hour log with the chosen layout: open + read one channel in full
            (target < 1 s), read a 10 s window from the middle (target < 50 ms)

The telemetry is the simulated 2-DOF inertial testbed in fast mode, with the base stage
driven by a two-tone generator signal so every sensor moves (idle data compresses
better than any real session would).

Run: .venv/bin/python benchmarks/bench_logs.py [--hours 1.0] [--compare-minutes 10]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from common import machine, save
from groundstation.codec import StreamDeframer
from groundstation.core.dictionary import load_dictionary
from groundstation.logs import Recorder
from groundstation.logs.reader import LogReader
from groundstation.sim import SimulatedDevice
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

RATE = 1200.0
LAYOUTS = {
    "gzip-1 + shuffle (chosen)": {"compression": "gzip", "compression_opts": 1, "shuffle": True},
    "lzf + shuffle": {"compression": "lzf", "shuffle": True},
    "no compression": {},
}


def telemetry(d, seconds: float, sink) -> int:
    """Decoded blocks of `seconds` of simulated telemetry, in 1 s batches, to sink."""
    dev = SimulatedDevice(d, pacing="manual", seed=9, testbed=load_testbed(TESTBEDS_DIR / "inertial_2dof.toml"))
    dev.base_drive = lambda t0, n: 0.3 * np.sin(2 * np.pi * 1.0 * (t0 + np.arange(n)) / RATE) \
        + 0.1 * np.sin(2 * np.pi * 7.0 * (t0 + np.arange(n)) / RATE)
    dfr = StreamDeframer(dev.codec)
    t_host = [time.time()]

    def consume(data: bytes) -> None:
        t_host[0] += 1.0
        sink(dfr.feed(data, t_host[0]))
    return dev.run_fast(seconds, consume)


def record(d, folder: Path, seconds: float, layout: dict) -> dict:
    blocks = []
    telemetry(d, seconds, blocks.extend)
    frames = sum(len(b) for b in blocks)
    rec = Recorder(d, folder, test_name="bench", queue_blocks=100000, compression=layout)
    path = rec.start()
    t = time.perf_counter()
    for b in blocks:
        rec(b)
    status = rec.stop(timeout=1800)
    elapsed = time.perf_counter() - t
    assert status.state == "stopped" and status.discarded_blocks == 0, status
    size = path.stat().st_size
    hr_frames = sum(len(b) for b in blocks if b.name == "HIGH_RATE")
    return {"path": str(path), "frames": frames, "seconds_simulated": seconds,
            "write_frames_per_s": frames / elapsed, "write_x_link": frames / elapsed / RATE,
            "bytes": size, "bytes_per_hour": size * 3600.0 / seconds,
            "bytes_per_high_rate_frame": size / hr_frames}


def read_timings(path: str) -> dict:
    t = time.perf_counter()
    with LogReader(path) as r:
        full = r.read("HIGH_RATE", ["encoder_inner"], with_time=False)["encoder_inner"]
        t_full = time.perf_counter() - t
        hr = r.summary().packets["HIGH_RATE"]
        mid = (hr.first_device_time + hr.last_device_time) / 2
        t = time.perf_counter()
        window = r.read("HIGH_RATE", ["encoder_inner"], start=mid, stop=mid + 10.0)
        t_window = time.perf_counter() - t
    assert len(window["encoder_inner"]) in (12000, 12001), len(window["encoder_inner"])
    return {"open_and_read_channel_s": t_full, "channel_samples": int(len(full)),
            "read_10s_window_ms": 1e3 * t_window}


def main() -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--compare-minutes", type=float, default=10.0)
    args = ap.parse_args()
    d = load_dictionary()
    res: dict = {"machine": machine(), "layouts": {}}
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_TMP")) as tmp:
        print(f"recorder, {args.compare_minutes:g} min of HIGH_RATE+HOUSEKEEPING per layout:")
        for name, layout in LAYOUTS.items():
            r = record(d, Path(tmp) / name.split()[0], args.compare_minutes * 60, layout)
            res["layouts"][name] = r
            print(f"  {name:<26} write {r['write_frames_per_s']:>9,.0f} frames/s "
                  f"({r['write_x_link']:5.0f}x link)   {r['bytes_per_hour'] / 1e9:5.2f} GB/hour "
                  f"({r['bytes_per_high_rate_frame']:.0f} B/frame)")
        print(f"one-hour log ({args.hours:g} h), chosen layout:")
        hour = record(d, Path(tmp) / "hour", args.hours * 3600, LAYOUTS["gzip-1 + shuffle (chosen)"])
        res["hour"] = hour
        res["hour"].update(read_timings(hour["path"]))
        print(f"  {hour['bytes'] / 1e9:.2f} GB; open + read one channel in full "
              f"({hour['channel_samples']:,} samples): {hour['open_and_read_channel_s']:.2f} s "
              f"(target < 1 s); 10 s window from the middle: {hour['read_10s_window_ms']:.1f} ms "
              f"(target < 50 ms); written at {hour['write_x_link']:.0f}x the link")
    save("logs", res)
    return res


if __name__ == "__main__":
    main()
