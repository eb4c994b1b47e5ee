"""The conformance suite: how long it takes to judge a device, and what a device costs.

Side by side in one run:
- `groundstation conformance --allow-motion` (every check) as a fresh process against
  - the simulated device it starts itself (`--device sim`: the start is included),
  - a simulated device already running (`groundstation sim`),
  - the C reference device (firmware/reference_device, built by `make firmware`);
- split: the time inside the checks (each check prints its own duration) and the rest
  (interpreter, imports, starting a simulator, connecting, restoring the table);
- each device idle with no client: the CPU it burns (a rig waits for hours between
  sessions).

    python benchmarks/bench_conformance.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

from common import machine, save

ROOT = Path(__file__).resolve().parent.parent
BINARY = ROOT / "firmware" / "reference_device" / "build" / "hfb_reference_device"
SUMMARY = re.compile(r"(\d+) checks: (\d+) passed, (\d+) failed, (\d+) skipped")
CHECK_TIME = re.compile(r"^(?:PASS|FAIL|SKIP) .*\(([0-9.]+) s\)$", re.M)
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def start(args: list[str], prefix: str) -> tuple[subprocess.Popen, str]:
    """A device process and its address, from the first stdout line starting `prefix`."""
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            env=ENV, cwd=ROOT)
    for line in proc.stdout:                       # bounded: the device prints it at start
        if prefix in line:
            return proc, "tcp://" + line.split("tcp://", 1)[1].split()[0]
    raise RuntimeError(f"{args[0]} ended without printing {prefix!r}")


def stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def suite(address: str) -> tuple[float, float, str]:
    """Wall seconds of one whole run, the seconds inside its checks, its summary line."""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "groundstation", "conformance", "--device",
                          address, "--allow-motion"], capture_output=True, text=True, env=ENV,
                         cwd=ROOT, timeout=600)
    wall = time.perf_counter() - t0
    m = SUMMARY.search(out.stdout)
    if out.returncode != 0 or m is None:
        raise RuntimeError(f"conformance against {address} exited {out.returncode}:\n"
                           f"{out.stdout[-2000:]}\n{out.stderr[-2000:]}")
    return wall, sum(float(t) for t in CHECK_TIME.findall(out.stdout)), m.group(0)


def idle_cpu(proc: subprocess.Popen, seconds: float = 10.0) -> float:
    """Fraction of one core `proc` used over `seconds` with no client."""
    tick = os.sysconf("SC_CLK_TCK")

    def used() -> float:
        fields = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / tick        # utime + stime

    a = used()
    time.sleep(seconds)              # a measurement interval, not a wait for a condition
    return (used() - a) / seconds


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    subprocess.run(["make", "-C", str(ROOT), "firmware"], check=True, capture_output=True)
    sim, sim_address = start([sys.executable, "-m", "groundstation", "sim", "--tcp-port", "0"],
                             "tcp://")
    c_dev, c_address = start([str(BINARY), "--port", "0"], "listening tcp://")
    try:
        time.sleep(2.0)                            # both settled before the idle figures
        idle = {"simulated device (Python)": idle_cpu(sim), "C reference device": idle_cpu(c_dev)}
        runs: dict[str, list[float]] = {"--device sim (starts its own)": [],
                                        "simulated device, running": [],
                                        "C reference device": []}
        summary, inside = {}, {}
        for _ in range(args.repeats):             # interleaved: the load falls on all alike
            for name, address in (("--device sim (starts its own)", "sim"),
                                  ("simulated device, running", sim_address),
                                  ("C reference device", c_address)):
                wall, checks_s, line = suite(address)
                runs[name].append(wall)
                inside.setdefault(name, []).append(checks_s)
                summary[name] = line
    finally:
        stop(sim)
        stop(c_dev)
    medians = {k: statistics.median(v) for k, v in runs.items()}
    fastest = min(medians.values())
    print(f"machine: {machine()}, load {os.getloadavg()[0]:.1f}")
    print(f"conformance --allow-motion, median of {args.repeats} (fresh process each):")
    for name, m in medians.items():
        checks_s = statistics.median(inside[name])
        print(f"  {name:32s} {m:6.2f} s  ({m / fastest:.2f}x the fastest; in the checks "
              f"{checks_s:.2f} s, the rest {m - checks_s:.2f} s)  {summary[name]}")
    print("idle, no client (fraction of one core):")
    for name, f in idle.items():
        print(f"  {name:32s} {f:6.3f}")
    save("bench_conformance", {"machine": machine(), "load": os.getloadavg()[0],
                               "suite_wall_s": runs, "suite_median_s": medians,
                               "summary": summary, "inside_checks_s": inside,
                               "idle_core_fraction": idle})


if __name__ == "__main__":
    main()
