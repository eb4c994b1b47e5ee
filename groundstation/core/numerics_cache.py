"""Results of a few pure numerical calls, kept on disk under a key made of their inputs.

Why: a session makes a few calls before anything moves that need a heavy import for a
few microseconds of arithmetic.  A design's sections (scipy.signal's bilinear map and
section pairing, at its upload) and the base stage's held response (cont2discrete, when
a campaign's check synthesises a base motion) cost an import of about 0.3 s of CPU -
scipy.signal brings scipy.stats, scipy.interpolate and scipy.optimize along - and the
plant's zero-order hold (a matrix exponential, in the upload's closed-loop check) costs
scipy.linalg's, about 0.1 s, half of it numpy.f2py, which scipy's array-API layer
imports.  The results are a pure function of the inputs and of scipy's version, so they
are kept under a key made of exactly those, bit for bit (numba keeps its compiled
kernels the same way), and the import happens only when a key is new.

The cache can only save time, never change a result or stop a command: a file that is
missing, unreadable, damaged or not what its kind expects is computed again (and
written again if the folder allows), and a folder that cannot be written is not used.
A file is written whole or not at all (a temporary file renamed over it).  Where it
lives: `GROUNDSTATION_CACHE_DIR` if set (the tests set it), else the user's cache folder
(platformdirs; ~/.cache/groundstation on Linux), one folder per kind.  Deleting it is
always safe.
"""

from __future__ import annotations

import hashlib
import io
import logging
import os
import struct
import tempfile
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

log = logging.getLogger(__name__)

CACHE_ENV = "GROUNDSTATION_CACHE_DIR"
FORMAT = b"numerics-v1"      # bump when what is stored, or how a key is made, changes

Arrays = tuple[np.ndarray, ...]


def cache_root() -> Path | None:
    """The folder of all kinds (not created here); None when the user's cache folder
    cannot be named (no home directory): then nothing is kept."""
    root = os.environ.get(CACHE_ENV)
    if not root:
        import platformdirs

        try:
            root = platformdirs.user_cache_dir("groundstation", appauthor=False)
        except Exception as exc:        # whatever it is, the result is computed all the same
            log.debug("numerics cache: no cache folder (%s)", exc)
            return None
    return Path(root)


def scipy_version() -> str:
    import scipy          # the package alone, about 10 ms: none of its subpackages

    return scipy.__version__


def input_key(kind: str, version: str, inputs: Sequence) -> str:
    """Every input bit for bit, in order, with its type and shape, and the version of
    the library that computes the result (a new version may compute it differently)."""
    h = hashlib.sha256(FORMAT + b"\0" + kind.encode() + b"\0" + version.encode())
    for value in inputs:
        a = np.ascontiguousarray(value)
        if a.dtype == object:
            raise TypeError(f"{kind}: an input of type {type(value).__name__} cannot be keyed")
        h.update(struct.pack("<B", a.ndim) + struct.pack(f"<{a.ndim}q", *a.shape))
        h.update(a.dtype.str.encode() + b"\0" + a.tobytes())
    return h.hexdigest()


def _read(path: Path) -> Arrays | None:
    try:
        # the bytes first, then parsed: a damaged file must not leave a handle open
        with np.load(io.BytesIO(path.read_bytes()), allow_pickle=False) as f:
            return tuple(f[f"a{i}"] for i in range(len(f.files)))
    except Exception:       # missing, truncated, not an archive, a member missing: a miss
        return None


def _write(path: Path, arrays: Arrays) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".", suffix=".npz")
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez(f, **{f"a{i}": a for i, a in enumerate(arrays)})
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError as exc:      # a read-only folder or a full disk: computed all the same
        log.debug("numerics cache: %s not kept (%s)", path.name, exc)


def _finite_floats(arrays: Arrays) -> bool:
    return all(a.dtype == np.float64 and bool(np.all(np.isfinite(a))) for a in arrays)


def cached_arrays(kind: str, version: str, inputs: Sequence, compute: Callable[[], Arrays],
                  valid: Callable[[Arrays], bool]) -> Arrays:
    """compute() - or what it returned for these exact inputs before, if that is still
    on disk.  Every array kept is finite float64; `valid` is the kind's own check of how
    many arrays there are and their shapes.  A result either check refuses is never
    written, and one read back that either refuses is computed again."""

    def kept(arrays: Arrays) -> bool:
        return _finite_floats(arrays) and valid(arrays)

    root = cache_root()
    path = None if root is None else root / kind / f"{input_key(kind, version, inputs)}.npz"
    arrays = None if path is None else _read(path)
    if arrays is not None and kept(arrays):
        return arrays
    arrays = tuple(np.asarray(a) for a in compute())
    if path is not None and kept(arrays):
        _write(path, arrays)
    return arrays
