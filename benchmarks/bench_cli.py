"""CLI start-up: how long an operator waits before a command does anything.

Side by side in one run, each as a fresh process (median of N):
- the floor: `python -c pass` (the interpreter alone - no command can start faster);
- ours: `groundstation --help`, `groundstation fg off` against a pyvisa-sim instrument
  (tests/fg_sim.yaml), `groundstation params validate` (numerics needed: scipy);
- the baseline: the same interpreter importing every heavy library the package uses
  (numpy, scipy.signal, h5py, PySide6, pyqtgraph, pyvisa, serial) - what each command
  paid when the CLI imported everything at start.

    python benchmarks/bench_cli.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

from common import machine, save

ROOT = Path(__file__).resolve().parent.parent
YAML = ROOT / "tests" / "fg_sim.yaml"
RESOURCE = "USB0::0xF4ED::0xEE3A::SIM4053B::INSTR"
HEAVY = "import numpy, scipy.signal, h5py, PySide6.QtWidgets, pyqtgraph, pyvisa, serial"

COMMANDS = {
    "python -c pass (floor)": [sys.executable, "-c", "pass"],
    "groundstation --help": [sys.executable, "-m", "groundstation", "--help"],
    "groundstation fg off (pyvisa-sim)": [sys.executable, "-m", "groundstation", "fg", "off",
                                          "--resource", RESOURCE, "--backend", str(YAML)],
    "groundstation params validate": [sys.executable, "-m", "groundstation", "params", "validate",
                                      str(ROOT / "profiles/controllers/relative_design2.toml")],
    "import every heavy library (baseline)": [sys.executable, "-c", HEAVY],
}


def wall(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          env={"QT_QPA_PLATFORM": "offscreen", "PATH": "/usr/bin:/bin"})
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: exit {done.returncode}: {done.stderr.decode()[-400:]}")
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    for cmd in COMMANDS.values():              # warm the page cache and .pyc files
        wall(cmd)
    results = {"machine": machine(), "repeats": args.repeats, "seconds": {}}
    for name, cmd in COMMANDS.items():
        times = [wall(cmd) for _ in range(args.repeats)]
        results["seconds"][name] = {"median": statistics.median(times), "min": min(times),
                                    "max": max(times)}
    floor = results["seconds"]["python -c pass (floor)"]["median"]
    heavy = results["seconds"]["import every heavy library (baseline)"]["median"]
    print(f"CLI start-up, median of {args.repeats} fresh processes ({results['machine']}):")
    print(f"  {'':<40} {'s':>7} {'x floor':>8} {'/ baseline':>10}")
    for name, r in results["seconds"].items():
        print(f"  {name:<40} {r['median']:7.3f} {r['median'] / floor:8.1f} {r['median'] / heavy:10.2f}")
    print(f"results: {save('cli', results)}")


if __name__ == "__main__":
    main()
