"""One BLAS thread in the ground station's processes, unless the user chose otherwise.

numpy's and scipy's BLAS (OpenBLAS in their wheels) starts a thread per core, and after
each call its threads spin for a while waiting for the next one.  The ground station's
matrices are small - a design's discretisation, a loop's margins, the plant's 6-state
model - so those threads never help, but their spinning took a core from the simulator
and the telemetry receiver: a fast `inertial_bm` campaign's own process used 3.2-3.4 s
of CPU with the default and 1.9-2.0 s with one thread (docs/campaigns.md, "Fifth
round").  The batch analysis already ran with one (Dask's workers, and the benchmarks'
serial loop: docs/scale.md).

The variables are read once, when the BLAS library loads (numpy's import), so this is
called first thing by the command line's entry points; the processes the ground station
starts (the simulator's child, log writers, the compressing process) inherit them.  A
value already in the environment stands."""

from __future__ import annotations

import os
from typing import MutableMapping

#: what OpenBLAS, an OpenMP build and MKL each read
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread(environ: MutableMapping[str, str] = os.environ) -> None:
    for name in BLAS_THREAD_VARIABLES:
        environ.setdefault(name, "1")
