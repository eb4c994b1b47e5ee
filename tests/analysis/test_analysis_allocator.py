"""The batch analysis sets glibc's allocator so that large numpy temporaries are reused
from the heap (analysis/allocator.py): a fresh process allocating and freeing a 4 MB
array over and over then faults its pages in once, not on every round; a value the user
exported stands."""

from __future__ import annotations

import subprocess
import sys
import textwrap

ROUNDS = """
    import resource, sys
    import numpy as np
    from groundstation.analysis.allocator import tune_for_batch
    tuned = tune_for_batch() if sys.argv[1] == "tuned" else None
    def one_round():                             # three 4 MB temporaries, touched, freed
        a, b, c = np.ones(1 << 19), np.ones(1 << 19), np.ones(1 << 19)
        return float(a.sum() + b.sum() + c.sum())
    one_round()
    one_round()                                  # glibc's own thresholds have adapted
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(50):
        one_round()
    print(tuned, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str, env: dict | None = None) -> tuple[str, int]:
    run = subprocess.run([sys.executable, "-c", textwrap.dedent(ROUNDS), mode],
                         capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 0, run.stderr
    tuned, faults = run.stdout.split()
    return tuned, int(faults)


def test_tuned_the_temporaries_pages_are_faulted_in_once_not_every_round():
    _, plain = _faults("plain")
    tuned, reused = _faults("tuned")
    assert tuned == "True"
    # glibc's defaults, adapted: the 12 MB freed each round exceed its trim threshold
    # (twice the largest block it freed), go back to the system and fault in again
    assert plain > 50 * 1000
    assert reused < plain / 10


def test_a_threshold_the_user_exported_stands(monkeypatch):
    import os
    tuned, _ = _faults("tuned", env={**os.environ, "MALLOC_MMAP_THRESHOLD_": "131072"})
    assert tuned == "False"
