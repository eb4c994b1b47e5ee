"""The bearing's friction slope table f(x): a fact about the testbed, read from CSV.

The data-based friction models (DB-SFM, DB-DHM, reference §5) replace the analytic
branch shape by a measured slope ratio f(x) over the normalised branch coordinate
x in [0, 2].  The table is part of the testbed's description: the simulator integrates
it (sim/friction.py), the controller design linearises it (params/design_file.py, params/discretise.py), and the
analysis compares measured hysteresis with it - so it lives here, not in the simulator.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import GroundStationError


class SlopeTableError(GroundStationError, ValueError):
    """A friction slope table is malformed (the message names the file and the problem)."""


DEFAULT_SLOPE_TABLE = Path(__file__).resolve().parents[2] / "profiles" / "friction_slope_lut.csv"
SLOPE_TABLE_HEADER = ("x", "slope_ratio")


def validate_slope_table(x, y, source: str = "<slope table>") -> tuple[np.ndarray, np.ndarray]:
    """Check a slope table f(x) and return it as contiguous float64 arrays.

    Requirements: at least 2 points, finite values, x strictly increasing and covering
    [0, 2], slope ratios ≥ 0, non-increasing in x (steep after a reversal, then
    shallower), and f(0) > 0 (otherwise the bearing would have no friction stiffness).
    Raises SlopeTableError naming ``source``.
    """
    try:
        xa = np.ascontiguousarray(x, dtype=np.float64)
        ya = np.ascontiguousarray(y, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SlopeTableError(f"{source}: slope table is not numeric ({exc})") from None
    if xa.ndim != 1 or ya.ndim != 1 or xa.shape != ya.shape:
        raise SlopeTableError(f"{source}: x and slope_ratio must be 1-D and of equal length "
                              f"(got shapes {xa.shape} and {ya.shape})")
    if xa.size < 2:
        raise SlopeTableError(f"{source}: slope table needs at least 2 rows, has {xa.size}")
    if not (np.all(np.isfinite(xa)) and np.all(np.isfinite(ya))):
        raise SlopeTableError(f"{source}: slope table contains non-finite values")
    dx = np.diff(xa)
    if np.any(dx <= 0.0):
        i = int(np.argmax(dx <= 0.0))
        raise SlopeTableError(f"{source}: x must be strictly increasing "
                              f"(row {i + 2}: x = {xa[i + 1]:g} after x = {xa[i]:g})")
    if xa[0] > 0.0 or xa[-1] < 2.0:
        raise SlopeTableError(f"{source}: x must cover [0, 2] (table spans "
                              f"[{xa[0]:g}, {xa[-1]:g}])")
    if np.any(ya < 0.0):
        i = int(np.argmax(ya < 0.0))
        raise SlopeTableError(f"{source}: slope_ratio must be >= 0 "
                              f"(row {i + 1}: x = {xa[i]:g}, slope_ratio = {ya[i]:g})")
    dy = np.diff(ya)
    if np.any(dy > 0.0):
        i = int(np.argmax(dy > 0.0))
        raise SlopeTableError(
            f"{source}: slope_ratio must be monotone non-increasing in x (steep right after "
            f"a reversal, then shallower); it rises from {ya[i]:g} at x = {xa[i]:g} to "
            f"{ya[i + 1]:g} at x = {xa[i + 1]:g}")
    if np.interp(0.0, xa, ya) <= 0.0:
        raise SlopeTableError(f"{source}: slope_ratio at x = 0 must be > 0")
    return xa, ya


def load_slope_table(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a slope table CSV: '#' comment lines, header ``x,slope_ratio``, then rows.

    Returns (x, slope_ratio) as float64 arrays; raises SlopeTableError naming the file.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SlopeTableError(f"{path}: cannot read slope table ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise SlopeTableError(f"{path}: slope table is not UTF-8 text") from None
    header_seen = False
    xs: list[float] = []
    ys: list[float] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if not header_seen:
            if tuple(c.lower() for c in cells) != SLOPE_TABLE_HEADER:
                raise SlopeTableError(f"{path}:{lineno}: header must be "
                                      f"'{','.join(SLOPE_TABLE_HEADER)}', got '{line}'")
            header_seen = True
            continue
        if len(cells) != 2:
            raise SlopeTableError(f"{path}:{lineno}: expected 2 columns (x,slope_ratio), "
                                  f"got {len(cells)}: '{line}'")
        try:
            xs.append(float(cells[0]))
            ys.append(float(cells[1]))
        except ValueError:
            raise SlopeTableError(f"{path}:{lineno}: not a number: '{line}'") from None
    if not header_seen:
        raise SlopeTableError(f"{path}: no header line '{','.join(SLOPE_TABLE_HEADER)}' found")
    return validate_slope_table(xs, ys, str(path))
