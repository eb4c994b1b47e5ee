"""Parameter work: validating a design, and uploading a table until it is verified.

Side by side, in one run, over TCP loopback to the simulated device (real time, 1200 Hz):

  ours       ParameterLoader.upload: read the active table (rollback point), BEGIN,
             WRITE blocks, COMMIT with CRC, read back and compare, wait for HOUSEKEEPING
             to report the new CRC
  baseline   the bare exchange a home-grown tool does: BEGIN, WRITE blocks, COMMIT,
             nothing read back, nothing confirmed
  limit      the table's bytes at the serial link's 2 Mbaud (10 bits per byte), the
             slowest transport the rig has, for both directions of ours

Design validation (load, discretise, closed loop, margins) is timed per thesis design.

Run: .venv/bin/python benchmarks/bench_params.py [--repeats 20]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from common import machine, save

from groundstation.core.dictionary import load_dictionary
from groundstation.link import open_client
from groundstation.params import table as ptable
from groundstation.params.clearance import clear_design
from groundstation.params.design_file import load_design, table_values
from groundstation.params.loop import validate
from groundstation.params.upload import ParameterLoader
from groundstation.sim import SimulatedDevice

CONTROLLERS = Path(__file__).resolve().parent.parent / "profiles" / "controllers"
SERIAL_BYTES_PER_S = 2_000_000 / 10


def bare_upload(client, d, blob: bytes) -> None:
    block = d.max_payload - 10
    client.command("PARAM_BEGIN", table_version=1, table_length=len(blob))
    for off in range(0, len(blob), block):
        client.command("PARAM_WRITE", offset=off, data=blob[off:off + block])
    client.command("PARAM_COMMIT", table_crc=ptable.table_crc(blob))


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=20)
    args = p.parse_args()
    d = load_dictionary()
    print(f"parameter benchmark - {machine()}")

    val = {}
    for f in sorted(CONTROLLERS.glob("*design?.toml")):
        t0 = time.perf_counter()
        design = load_design(f)
        report = validate(design, table_values(design, dictionary=d), d)
        val[f.stem] = {"seconds": time.perf_counter() - t0, "ok": report.ok}
    print("\nvalidate (load + discretise + closed loop + margins), s:")
    for k, v in val.items():
        print(f"  {k:<22} {v['seconds']:.3f}  {'OK' if v['ok'] else 'REFUSED'}")

    dev = SimulatedDevice(d, pacing="realtime").start()
    client = open_client(d, f"127.0.0.1:{dev.tcp_port}")
    client.connect()
    loader = ParameterLoader(client, d)
    designs = [load_design(CONTROLLERS / name) for name in ("relative_design1.toml", "relative_design2.toml")]
    values = [table_values(design, dictionary=d) for design in designs]
    # validated once, outside the timing: the figure is the transfer and its verification
    clearances = [clear_design(design, v, d)[0] for design, v in zip(designs, values)]
    ours, bare = [], []
    try:
        for i in range(args.repeats):
            v = values[i % 2]
            t0 = time.perf_counter()
            loader.upload(v, "bench", clearance=clearances[i % 2])
            ours.append(time.perf_counter() - t0)
            blob = ptable.pack(d, values[(i + 1) % 2])
            t0 = time.perf_counter()
            bare_upload(client, d, blob)
            bare.append(time.perf_counter() - t0)
    finally:
        client.close()
        dev.stop()
    size = ptable.table_size(d)
    limit = 3 * size / SERIAL_BYTES_PER_S          # previous read, write, read-back
    res = {
        "machine": machine(), "table_bytes": size, "repeats": args.repeats,
        "validate_s": val,
        "upload_verified_s": {"median": statistics.median(ours), "max": max(ours)},
        "upload_bare_s": {"median": statistics.median(bare), "max": max(bare)},
        "serial_limit_s": limit,
    }
    print(f"\nupload of a {size}-byte table over TCP loopback, {args.repeats} times:")
    print(f"  ours, verified (read-back + HOUSEKEEPING): median {res['upload_verified_s']['median'] * 1e3:7.1f} ms, "
          f"max {res['upload_verified_s']['max'] * 1e3:.1f} ms")
    print(f"  baseline, unverified BEGIN/WRITE/COMMIT:   median {res['upload_bare_s']['median'] * 1e3:7.1f} ms "
          f"(ours / baseline = {res['upload_verified_s']['median'] / res['upload_bare_s']['median']:.1f}x)")
    print(f"  serial 2 Mbaud byte time, 3 x {size} B:      {limit * 1e3:7.1f} ms "
          f"(ours / limit = {res['upload_verified_s']['median'] / limit:.1f}x)")
    print("  (ours waits for the next 10 Hz HOUSEKEEPING to confirm the CRC: 0-100 ms of it)")
    print(f"written to {save('params', res)}")


if __name__ == "__main__":
    main()
