"""Finding the row of a time in a sorted column of a log: the one bisect over datasets.

The reader's time and tick ranges and replay's seek both come here.  A chunked,
compressed column is never read whole for this: the bisection probes one value per
chunk (the chunk's first row) until it knows which chunk holds the answer, then reads
that chunk once.  A plain bisect over rows would decompress a chunk for every probe.
"""

from __future__ import annotations

import h5py
import numpy as np

_UNCHUNKED_STEP = 8192          # probe spacing for a contiguous dataset


def search_sorted(ds: h5py.Dataset, n: int, value: float, side: str = "left") -> int:
    """First row i of the ascending rows [0, n) of `ds` with ds[i] >= value ("left") or
    ds[i] > value ("right"); n if there is none - numpy.searchsorted's answer.  HDF5
    read errors pass through for the caller to name the damage its own way."""
    if n <= 0:
        return 0
    step = ds.chunks[0] if ds.chunks else _UNCHUNKED_STEP
    lo, hi = 0, (n - 1) // step + 1
    while lo < hi:
        mid = (lo + hi) // 2
        x = ds[mid * step]
        if (x < value) if side == "left" else (x <= value):
            lo = mid + 1
        else:
            hi = mid
    if lo == 0:                       # the first row already qualifies
        return 0
    c0 = (lo - 1) * step
    block = ds[c0:min(n, c0 + step)]
    return c0 + int(np.searchsorted(block, value, side=side))


__all__ = ["search_sorted"]
