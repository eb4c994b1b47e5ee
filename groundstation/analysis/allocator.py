"""glibc's allocator set for the batch analysis: large numpy temporaries kept in the heap.

A log's analysis allocates and frees temporaries of up to a few MB, many times per log.
glibc serves a block above its mmap threshold (128 KiB at start, raised by itself only
after a large block is freed) with a fresh mapping, each page of which faults on first
touch, and gives the heap's top back to the system above its trim threshold.  Measured
on 200 logs of 60 s, the serial loop in a fresh process (docs/scale.md, "Third round"):
5.07-5.30 s with glibc's defaults, 4.59-4.74 s with the thresholds below - the same
10 % that a process gets by chance when it happened to free large blocks first (which
is how the benchmark's serial loop had it, and its Dask workers had not).

The thresholds: blocks up to 16 MiB from the heap (a 60 s log's columns are 0.6 MB,
an hour's 35 MB: those still get their own mapping), and up to 128 MiB of freed heap
kept for the next log instead of returned.  That is memory a batch process holds on
to while it runs (a worker: 128 MiB at most above what it uses), chosen for speed.

Set in the process running the serial loop (`tune_for_batch`, mallopt) and in each
local Dask worker (`WORKER_ENVIRONMENT`, which glibc reads when the worker starts); a
value the user exported wins.  Elsewhere than glibc, nothing is changed.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

MMAP_THRESHOLD_BYTES = 16 << 20
TRIM_THRESHOLD_BYTES = 128 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3        # glibc's malloc.h

#: the environment a local Dask worker starts with (glibc reads it at start)
WORKER_ENVIRONMENT = {"MALLOC_MMAP_THRESHOLD_": str(MMAP_THRESHOLD_BYTES),
                      "MALLOC_TRIM_THRESHOLD_": str(TRIM_THRESHOLD_BYTES)}

_tuned = False


def tune_for_batch() -> bool:
    """Set the thresholds in this process (once); False where it is not glibc, or where
    the user set them in the environment (theirs stand)."""
    global _tuned
    if _tuned:
        return True
    if any(name in os.environ for name in WORKER_ENVIRONMENT):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    _tuned = bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and \
        bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
    return _tuned
