"""`make bench`: every benchmark, one after the other, printing its figures.

Results are also written to benchmarks/results/*.json (not committed); the README's
performance section quotes them with the machine they came from.
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

HERE = Path(__file__).parent
BENCHES = ["bench_cli.py", "bench_codec.py", "bench_sim.py", "bench_logs.py", "bench_params.py", "bench_campaign.py", "bench_faults.py", "bench_gui.py", "bench_analysis.py", "bench_pq.py", "bench_workbench.py", "bench_fanout.py", "bench_batch.py", "bench_identify.py", "bench_conformance.py"]

if __name__ == "__main__":
    sys.path.insert(0, str(HERE))           # the benchmarks import common.py beside them
    for name in BENCHES:
        print(f"== {name}", flush=True)
        sys.argv = [str(HERE / name)]
        runpy.run_path(str(HERE / name), run_name="__main__")
