"""The parallel limit for bench_batch.py: the serial loop in N independent processes at
once, process k taking logs k, k+N, k+2N, ... - no scheduler, no tasks, no rows sent
anywhere.  What two cores give this work at best; Dask's two workers are measured
against it.

Each process does its imports, says "ready", and starts when its stdin gets a line, so
the clock (the parent's, from the go to the last process's answer) holds the loops only.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")       # as the serial loop and the workers have it

HERE = Path(__file__).resolve().parent


def parallel_loops(cache: Path, logs: int, processes: int = 2) -> float:
    """Wall seconds of `processes` serial loops over the first `logs` logs in `cache`."""
    procs = [subprocess.Popen([sys.executable, __file__, str(cache), str(logs), str(k), str(processes)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": str(HERE.parent)})
             for k in range(processes)]
    for p in procs:
        if p.stdout.readline().strip() != "ready":
            raise SystemExit("a serial loop process did not start")
    t0 = time.perf_counter()
    for p in procs:
        p.stdin.write("go\n")
        p.stdin.flush()
    for p in procs:
        p.stdout.readline()
    wall = time.perf_counter() - t0
    for p in procs:
        p.wait()
    return wall


def _loop(cache: Path, logs: int, k: int, n: int) -> None:
    from groundstation.analysis.batch import BatchOptions, analyze_one, campaign_index, find_logs, run_serial

    paths = find_logs([cache])[:logs]
    known = campaign_index(paths)
    mine = paths[k::n]
    analyze_one(mine[0], BatchOptions(), known.get(str(mine[0])))       # imports paid
    print("ready", flush=True)
    sys.stdin.readline()
    run_serial(mine, BatchOptions(), known)
    print("done", flush=True)


if __name__ == "__main__":
    _loop(Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))
