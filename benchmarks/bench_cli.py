"""CLI start-up: how long an operator waits before a command does anything.

Side by side in one run, each as a fresh process (median of N):
- the floor: `python -c pass` (the interpreter alone - no command can start faster);
- ours: `groundstation --help`, `groundstation fg off` against a pyvisa-sim instrument
  (tests/fg_sim.yaml), `groundstation params validate` (numerics needed: scipy);
- the baseline: the same interpreter importing every heavy library the package uses
  (numpy, scipy.signal, h5py, PySide6, pyqtgraph, pyvisa, serial) - what each command
  paid when the CLI imported everything at start.

    python benchmarks/bench_cli.py [--repeats 7] [--before REV]

`--before REV` also times `--help` and `fg off` of that revision (a temporary git
worktree, run from inside it so that its package is the one imported; same interpreter
and libraries): before and after in one run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
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


def wall(cmd: list[str], tree: str | None = None) -> float:
    """Seconds for one fresh process of `cmd`, run in `tree` (default: this checkout)."""
    env = {"QT_QPA_PLATFORM": "offscreen", "PATH": "/usr/bin:/bin"}
    t0 = time.perf_counter()
    # the working directory comes first on sys.path: the tree timed is the one we stand in
    done = subprocess.run(cmd, cwd=tree or ROOT, stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, env=env)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: exit {done.returncode}: {done.stderr.decode()[-400:]}")
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--before", default=None, metavar="REV",
                    help="also time --help and fg off of this git revision")
    args = ap.parse_args()
    runs = [(name, cmd, None) for name, cmd in COMMANDS.items()]
    with tempfile.TemporaryDirectory() as tmp:
        if args.before:
            tree = os.path.join(tmp, "before")
            subprocess.run(["git", "worktree", "add", "--detach", tree, args.before], cwd=ROOT,
                           check=True, capture_output=True)
            for name in ("groundstation --help", "groundstation fg off (pyvisa-sim)"):
                runs.insert(-1, (f"{name} at {args.before}", COMMANDS[name], tree))
        try:
            for _name, cmd, path in runs:          # warm the page cache and .pyc files
                wall(cmd, path)
            results = {"machine": machine(), "repeats": args.repeats, "before": args.before,
                       "seconds": {}}
            for name, cmd, path in runs:
                times = [wall(cmd, path) for _ in range(args.repeats)]
                results["seconds"][name] = {"median": statistics.median(times), "min": min(times),
                                            "max": max(times)}
        finally:
            if args.before:
                subprocess.run(["git", "worktree", "remove", "--force", tree], cwd=ROOT,
                               capture_output=True)
    floor = results["seconds"]["python -c pass (floor)"]["median"]
    heavy = results["seconds"]["import every heavy library (baseline)"]["median"]
    print(f"CLI start-up, median of {args.repeats} fresh processes ({results['machine']}):")
    print(f"  {'':<48} {'s':>7} {'x floor':>8} {'/ baseline':>10}")
    for name, r in results["seconds"].items():
        print(f"  {name:<48} {r['median']:7.3f} {r['median'] / floor:8.1f} {r['median'] / heavy:10.2f}")
    print(f"results: {save('cli', results)}")


if __name__ == "__main__":
    main()
