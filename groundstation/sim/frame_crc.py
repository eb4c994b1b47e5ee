"""The frame CRC (CRC-32/ISO-HDLC, zlib's) of every row of a byte array, compiled.

Written here because no library computes many CRCs in one call: zlib takes one buffer
at a time, and a Python loop of zlib calls (~1 us a frame) was a quarter of the fast
simulator's time per frame once everything else is vectorised; a numpy table lookup
over (frames x bytes) is slower still (it materialises the whole index array).  This is
the textbook byte-at-a-time table algorithm; `tests/sim/test_sim_frame_batches.py`
checks it against zlib on random rows of many lengths.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_POLY_REFLECTED = 0xEDB88320


def _table() -> np.ndarray:
    table = np.zeros(256, dtype=np.uint32)
    for byte in range(256):
        reg = byte
        for _ in range(8):
            reg = (reg >> 1) ^ _POLY_REFLECTED if reg & 1 else reg >> 1
        table[byte] = reg
    return table


_TABLE = _table()


@njit(cache=True)
def _crc_rows(rows, table, out):
    # four rows at a time: each register's update waits on its previous byte, so four
    # independent chains keep the core busy where one would leave it waiting
    n, length = rows.shape
    full = n - n % 4
    for i in range(0, full, 4):
        r0 = r1 = r2 = r3 = np.uint32(0xFFFFFFFF)
        for j in range(length):
            r0 = table[(r0 ^ rows[i, j]) & 0xFF] ^ (r0 >> 8)
            r1 = table[(r1 ^ rows[i + 1, j]) & 0xFF] ^ (r1 >> 8)
            r2 = table[(r2 ^ rows[i + 2, j]) & 0xFF] ^ (r2 >> 8)
            r3 = table[(r3 ^ rows[i + 3, j]) & 0xFF] ^ (r3 >> 8)
        out[i] = ~r0
        out[i + 1] = ~r1
        out[i + 2] = ~r2
        out[i + 3] = ~r3
    for i in range(full, n):
        reg = np.uint32(0xFFFFFFFF)
        for j in range(length):
            reg = table[(reg ^ rows[i, j]) & 0xFF] ^ (reg >> 8)
        out[i] = ~reg


def crc_rows(rows: np.ndarray) -> np.ndarray:
    """(N, L) uint8 (any strides) -> (N,) uint32: zlib.crc32 of each row."""
    out = np.empty(rows.shape[0], dtype=np.uint32)
    _crc_rows(rows, _TABLE, out)
    return out
