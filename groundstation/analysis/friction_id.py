"""Bearing friction from hysteresis-triangle records: the loop, its slopes, and the
data-based slope table f(x) of the DB-DHM.

The record
----------
The friction test (reference §7) moves the axis with a triangle-wave position profile at
a constant, very low rate (0.001 deg/s) and several amplitudes.  At that rate inertia and
viscous torque are negligible (b_f·ω ≈ 20 in-oz-s/rad · 1.7e-5 rad/s ≈ 3e-4 in-oz against
T_c = 2.25 in-oz), so the motor torque balances the bearing's friction torque.  This module
therefore takes two arrays of equal length:

    angle_rad       displacement across the bearing (the outer encoder, phi1)
    torque_in_oz    friction torque = K_t · motor current (in-oz/A · A); the caller does
                    the product, e.g. ``current_coarse * testbed.motor_coarse["torque_constant"]``
                    (use the measured current, or the commanded one if that is all there is)

Branches
--------
The loop is split at velocity reversals of the angle.  A reversal is an extremum of the
angle that the motion then leaves by more than ``min_reversal_travel_rad`` (default 1 % of
the record's peak-to-peak angle): encoder noise and quantisation make the sign of single
differences useless at this speed, a travel threshold does not care.  A *branch* runs from
one reversal to the next (the last one to the end of the record); the samples before the
first reversal (the lead-in) start from an unknown friction state and are only plotted.

On a branch moving in direction s = ±1, starting at the reversal (θ_k, T_k):

    ψ = s·(θ − θ_k)           travel since the reversal, ≥ 0        [rad]
    x = s·(T − T_k) / T_c     normalised branch coordinate, 0 … 2
    dT/dθ = σ·f(x)            the DB-DHM (the analytic DHM is f(x) = (2 − x)^α)

so dψ/dx = T_c / (σ·f(x)).  Two slopes per branch are reported in in-oz/rad:
*turnaround* (right after the reversal: a quadratic fit of T against ψ over the first
``turnaround_fraction`` of the branch's torque swing, its derivative at ψ = 0 — σ·f(0),
2^α·σ for the DHM) and *late* (a straight-line fit over the last ``late_fraction`` of the
travel: ≈ 0 once the branch has reached the running torque).

The slope table
---------------
For each grid point x_g and each branch that passes through the window
[x_g − w, x_g + w] (at the ends of [0, 2]: [0, 2w] and [2 − 2w, 2]), the slope dT/dθ at
x_g is a quadratic fit of the branch's torque against its travel ψ over the samples in
the window, differentiated where the branch crosses x_g; f(x_g) = slope / σ.  Which
samples lie in the window is decided on a denoised x (a short moving average, then its
running maximum, since x cannot fall on a branch), so the window is a contiguous stretch
of travel: selecting samples by their own noisy torque, or regressing ψ on the noisy x,
would bias the slope (upwards, by several % near x = 0 at the rig's current resolution).
The branches are combined by averaging their compliances 1/slope (travel per torque: one
nearly flat stretch cannot dominate) and inverting the mean.  With the rig's rate and
noise (tests/analysis/test_analysis_friction.py) f comes out within ~8 % over the first 2 % of
the swing, where a branch has only a few dozen samples, and within ~3 % beyond.

Then, documented choices, so that the result is a table plant/slope_table.py accepts:

- f ≥ 0: a branch's slope ≤ 0 at a grid point is dropped as noise (friction torque
  does not run backwards while the motion continues);
- ``monotone=True`` (default) fits the closest non-increasing sequence (weighted
  pool-adjacent-violators, weights = branches per grid point).  The DHM family is
  non-increasing by construction (steepest at the reversal) and validate_slope_table
  requires it.  ``monotone_violation`` tells whether the data themselves agreed: the
  largest rise of the raw f between neighbouring grid points, relative to f's maximum;
  ``monotone=False`` keeps the raw shape (such a table may then not be writable);
- grid points no branch covered (typically near x = 2, where the branch approaches the
  running torque only asymptotically) are filled: interior gaps linearly, the tail
  linearly down to f(2) = 0 (where the DHM branch ends, its slope vanishes); the
  ``identified`` mask says which points are data.

σ is not identifiable separately from f (only σ·f is measured), so the rest stiffness the
table multiplies is an argument (the testbed's friction.sigma).  T_c is estimated from
the loop unless given: half the torque swing of the branches that reach the running
torque (late slope below ``plateau_slope_ratio`` × turnaround slope), median over them,
each swing extrapolated to its plateau (the branch approaches it only asymptotically;
see _running_swing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..plant.slope_table import SLOPE_TABLE_HEADER, validate_slope_table
from . import AnalysisError

__all__ = [
    "FrictionIdError", "Branch", "HysteresisLoop", "FrictionIdentification", "DEFAULT_X_GRID",
    "split_branches", "identify_friction", "combine_tables", "write_slope_table",
]


class FrictionIdError(AnalysisError, ValueError):
    """A hysteresis record cannot be analysed (the message says what is missing)."""


# dense near 0, where the slope changes fastest (σ·f falls by an order of magnitude over
# the first few % of the swing in the rig's bearing), coarser further on
DEFAULT_X_GRID = np.array([0.0, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5,
                           0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7, 1.8, 1.85,
                           1.9, 1.95, 2.0])
MIN_FIT_SAMPLES = 5
SMOOTH_HALF_WIDTH = 5      # samples each side for the denoised x that picks the windows


@dataclass(frozen=True)
class Branch:
    """One branch of the loop: samples ``start`` … ``stop`` inclusive (both reversals)."""

    start: int                               # index of the reversal that begins it
    stop: int                                # index of the next reversal (or the last sample)
    direction: int                           # +1 angle increasing, −1 decreasing
    complete: bool                           # ends at a reversal (False: the record ended)
    reversal_angle_rad: float                # θ_k
    reversal_torque_in_oz: float             # T_k
    travel_rad: float                        # ψ at the end of the branch
    torque_swing_in_oz: float                # s·(T_end − T_k), T_end: mean of the last 1 % of samples
    running_swing_in_oz: float               # s·(T_∞ − T_k): the end extrapolated to the plateau
    turnaround_slope_in_oz_per_rad: float    # dT/dθ right after the reversal (nan: too few samples)
    late_slope_in_oz_per_rad: float          # dT/dθ over the last part of the travel


@dataclass(frozen=True, eq=False)
class HysteresisLoop:
    """The record split at its velocity reversals (for plotting and for identification)."""

    angle_rad: np.ndarray
    torque_in_oz: np.ndarray
    reversal_indices: np.ndarray             # sample indices of the reversals, in order
    branches: tuple[Branch, ...]
    min_reversal_travel_rad: float           # the threshold that was used

    @property
    def lead_in(self) -> slice:
        """Samples before the first reversal (friction state unknown: plot only)."""
        return slice(0, int(self.reversal_indices[0]) + 1)

    def branch_arrays(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(angle_rad, torque_in_oz) of branch i, for a loop plot."""
        b = self.branches[i]
        return self.angle_rad[b.start:b.stop + 1], self.torque_in_oz[b.start:b.stop + 1]


@dataclass(frozen=True, eq=False)
class FrictionIdentification:
    """The identified DB-DHM slope table and what it was made from."""

    loop: HysteresisLoop
    sigma_in_oz_per_rad: float               # the rest stiffness f multiplies (given)
    coulomb_torque_in_oz: float              # T_c used for x (estimated or given)
    coulomb_torque_estimated: bool
    x: np.ndarray                            # grid over [0, 2]
    f: np.ndarray                            # the table: ≥ 0, filled, monotone if asked
    f_raw: np.ndarray                        # data only (nan where no branch covered x)
    f_per_branch: np.ndarray                 # (branches, grid) per-branch f, nan if not covered
    branches_per_point: np.ndarray           # how many branches each raw point averages
    identified: np.ndarray                   # bool: f[i] comes from data (not filled)
    monotone: bool                           # f was made non-increasing
    monotone_violation: float                # largest rise of f_raw between neighbours / max f_raw

    @property
    def turnaround_slopes_in_oz_per_rad(self) -> np.ndarray:
        return np.array([b.turnaround_slope_in_oz_per_rad for b in self.loop.branches])

    @property
    def late_slopes_in_oz_per_rad(self) -> np.ndarray:
        return np.array([b.late_slope_in_oz_per_rad for b in self.loop.branches])


# ======================================================================================
# branches
# ======================================================================================
def _as_record(angle_rad, torque_in_oz) -> tuple[np.ndarray, np.ndarray]:
    arrays = []
    for name, values in (("angle_rad", angle_rad), ("torque_in_oz", torque_in_oz)):
        try:
            a = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            raise FrictionIdError(f"{name} must be a 1-D array of numbers") from None
        if a.ndim != 1:
            raise FrictionIdError(f"{name} must be 1-D, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            i = int(np.argmax(~np.isfinite(a)))
            raise FrictionIdError(f"{name} contains a non-finite value at sample {i} ({a[i]})")
        arrays.append(a)
    th, tq = arrays
    if th.size != tq.size:
        raise FrictionIdError(f"angle_rad and torque_in_oz must have the same length (same "
                              f"samples): {th.size} vs {tq.size}")
    if th.size < 3 * MIN_FIT_SAMPLES:
        raise FrictionIdError(f"hysteresis record too short: {th.size} samples (need at least "
                              f"{3 * MIN_FIT_SAMPLES}; a triangle profile gives thousands)")
    return th, tq


def _moving_average(v: np.ndarray, half_width: int) -> np.ndarray:
    """Centred moving average over 2·half_width + 1 samples, the window truncated (not
    zero-padded) at the ends so the first samples after a reversal are not pulled to 0."""
    c = np.concatenate(([0.0], np.cumsum(v)))
    i = np.arange(v.size)
    lo = np.maximum(i - half_width, 0)
    hi = np.minimum(i + half_width + 1, v.size)
    return (c[hi] - c[lo]) / (hi - lo)


def _reversals(angle: np.ndarray, threshold: float) -> list[int]:
    """Indices of the angle's extrema that the motion then leaves by ≥ threshold.

    A plain loop over Python floats: it has state (the direction and the running extremum),
    and it runs once per record (a few million samples take well under a second).
    """
    vals = angle.tolist()
    rev: list[int] = []
    direction = 0
    lo_i = hi_i = 0
    lo_v = hi_v = vals[0]
    for i, v in enumerate(vals):
        if direction == 0:
            # before the first significant motion: the start is not a reversal
            if v > hi_v:
                hi_i, hi_v = i, v
            if v < lo_v:
                lo_i, lo_v = i, v
            if v - lo_v >= threshold:
                direction, hi_i, hi_v = 1, i, v
            elif hi_v - v >= threshold:
                direction, lo_i, lo_v = -1, i, v
        elif direction > 0:
            if v >= hi_v:
                hi_i, hi_v = i, v
            elif hi_v - v >= threshold:
                rev.append(hi_i)
                direction, lo_i, lo_v = -1, i, v
        else:
            if v <= lo_v:
                lo_i, lo_v = i, v
            elif v - lo_v >= threshold:
                rev.append(lo_i)
                direction, hi_i, hi_v = 1, i, v
    return rev


def _turnaround_slope(psi: np.ndarray, dT: np.ndarray, swing: float, fraction: float) -> float:
    """d(s·T)/dψ at ψ = 0 from a quadratic fit over the first ``fraction`` of the swing."""
    if not swing > 0.0:
        return math.nan
    sel = dT <= fraction * swing
    # the window ends where the torque first leaves it (later noise re-entries excluded)
    last = int(np.argmax(~sel)) if not np.all(sel) else sel.size
    if last < MIN_FIT_SAMPLES:
        return math.nan
    p, q = psi[:last], dT[:last]
    scale = float(np.max(np.abs(p)))
    if not scale > 0.0:
        return math.nan
    u = p / scale                             # conditioning: u in [0, 1]
    coef = np.polynomial.polynomial.polyfit(u, q, 2)
    return float(coef[1] / scale)


def _late_slope(psi: np.ndarray, dT: np.ndarray, travel: float, fraction: float) -> float:
    sel = psi >= (1.0 - fraction) * travel
    if np.count_nonzero(sel) < MIN_FIT_SAMPLES or not travel > 0.0:
        return math.nan
    p = psi[sel]
    if np.ptp(p) <= 0.0:
        return math.nan
    coef = np.polynomial.polynomial.polyfit(p - p.mean(), dT[sel], 1)
    return float(coef[1])


def _running_swing(psi: np.ndarray, dT: np.ndarray, travel: float, fraction: float,
                   end_swing: float) -> float:
    """The swing the branch is heading for, s·(T_∞ − T_k).

    Near the running torque the torque approaches its plateau exponentially in ψ (exactly
    so for the DHM with α = 1 and on a table segment that falls linearly to 0), so the
    means m1, m2, m3 of three equal thirds of the late travel form a geometric sequence
    and Aitken's extrapolation m3 + d2·r/(1 − r) (d1 = m2 − m1, d2 = m3 − m2, r = d2/d1)
    gives the plateau.  Used only when the late part decelerates (0 < d2 < d1), and the
    correction is capped at the late part's own rise d1 + d2, so that noise on a plateau
    that has already been reached cannot run the extrapolation away; otherwise the
    branch's end value is the answer.
    """
    edges = travel * (1.0 - fraction * np.array([1.0, 2.0 / 3.0, 1.0 / 3.0, 0.0]))
    means = []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (psi >= a) & (psi <= b)
        if np.count_nonzero(sel) < MIN_FIT_SAMPLES:
            return end_swing
        means.append(float(np.mean(dT[sel])))
    m1, m2, m3 = means
    d1, d2 = m2 - m1, m3 - m2
    if not (0.0 < d2 < d1):
        return end_swing
    r = d2 / d1
    correction = min(d2 * r / (1.0 - r), d1 + d2)
    # the plateau lies beyond the mean of the last third, and beyond the end value
    return max(m3 + correction, end_swing)


def split_branches(angle_rad, torque_in_oz, *, min_reversal_travel_rad: float | None = None,
                   turnaround_fraction: float = 0.01,
                   late_fraction: float = 0.2) -> HysteresisLoop:
    """Split a hysteresis record into branches at its velocity reversals.

    min_reversal_travel_rad  how far the angle must come back from an extremum for it to
                             count as a reversal (default 1 % of the peak-to-peak angle).
    turnaround_fraction      part of each branch's torque swing used for the turnaround
                             slope (small: the slope falls fast after a reversal).
    late_fraction            part of each branch's travel used for the late slope.
    Raises FrictionIdError for unusable arrays, an angle that does not move, or a record
    without a velocity reversal.
    """
    th, tq = _as_record(angle_rad, torque_in_oz)
    span = float(np.ptp(th))
    if not span > 0.0:
        raise FrictionIdError("angle_rad does not move: a hysteresis record needs the "
                              "triangle position profile (no excitation)")
    if min_reversal_travel_rad is None:
        threshold = 0.01 * span
    else:
        threshold = float(min_reversal_travel_rad)
        if not (math.isfinite(threshold) and 0.0 < threshold < span):
            raise FrictionIdError(f"min_reversal_travel_rad = {min_reversal_travel_rad!r}: must "
                                  f"be > 0 and below the record's peak-to-peak angle {span:g} rad")
    for name, v in (("turnaround_fraction", turnaround_fraction), ("late_fraction", late_fraction)):
        if not 0.0 < float(v) <= 1.0:
            raise FrictionIdError(f"{name} = {v!r}: must be in (0, 1]")
    rev = _reversals(th, threshold)
    if not rev:
        raise FrictionIdError(f"no velocity reversal in the record (the angle never comes back "
                              f"by {threshold:g} rad): a hysteresis loop needs at least one "
                              f"turn of the triangle profile")
    ends = rev[1:] + [th.size - 1]
    branches = []
    for k, (a, b) in enumerate(zip(rev, ends)):
        complete = k + 1 < len(rev)
        if b - a < MIN_FIT_SAMPLES:
            continue                              # the record stopped right at a reversal
        direction = 1 if th[b] > th[a] else -1
        psi = direction * (th[a:b + 1] - th[a])
        dT = direction * (tq[a:b + 1] - tq[a])
        travel = float(psi[-1])
        if not complete and travel < threshold:
            continue                              # a stub after the last reversal
        swing = float(np.mean(dT[-max(MIN_FIT_SAMPLES, dT.size // 100):]))
        running = _running_swing(psi, dT, travel, float(late_fraction), swing)
        branches.append(Branch(
            start=int(a), stop=int(b), direction=direction, complete=complete,
            reversal_angle_rad=float(th[a]), reversal_torque_in_oz=float(tq[a]),
            travel_rad=travel, torque_swing_in_oz=swing, running_swing_in_oz=running,
            turnaround_slope_in_oz_per_rad=_turnaround_slope(psi, dT, swing,
                                                             float(turnaround_fraction)),
            late_slope_in_oz_per_rad=_late_slope(psi, dT, travel, float(late_fraction))))
    if not branches:
        raise FrictionIdError("the record has a reversal but no branch after it long enough to "
                              "analyse")
    return HysteresisLoop(angle_rad=th, torque_in_oz=tq, reversal_indices=np.asarray(rev),
                          branches=tuple(branches), min_reversal_travel_rad=threshold)


# ======================================================================================
# the slope table
# ======================================================================================
def _pava_nonincreasing(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares non-increasing fit (pool adjacent violators)."""
    # run PAVA for a non-decreasing fit on −y
    vals: list[float] = []
    wts: list[float] = []
    sizes: list[int] = []
    for yi, wi in zip((-y).tolist(), w.tolist()):
        vals.append(yi)
        wts.append(wi)
        sizes.append(1)
        while len(vals) > 1 and vals[-2] > vals[-1]:
            wsum = wts[-2] + wts[-1]
            merged = (vals[-2] * wts[-2] + vals[-1] * wts[-1]) / wsum
            vals[-2:] = [merged]
            wts[-2:] = [wsum]
            sizes[-2:] = [sizes[-2] + sizes[-1]]
    return -np.repeat(np.array(vals), sizes)


def _fill(x: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Fill nan points: interior linearly, leading with the first value, the tail linearly
    to 0 at the grid's end (x = 2: the DHM branch's end, where its slope vanishes)."""
    ok = np.isfinite(f)
    out = f.copy()
    xs, fs = x[ok], f[ok]
    if not ok[-1]:
        xs, fs = np.append(xs, x[-1]), np.append(fs, 0.0)
    gaps = ~ok
    out[gaps] = np.interp(x[gaps], xs, fs)      # np.interp holds the first value before xs[0]
    return out


def _checked_arguments(sigma_in_oz_per_rad, x_grid, window_halfwidth_x,
                       plateau_slope_ratio) -> tuple[float, np.ndarray, float]:
    """(sigma, x grid, window half-width) of identify_friction's arguments, checked."""
    sigma = float(sigma_in_oz_per_rad)
    if not (math.isfinite(sigma) and sigma > 0.0):
        raise FrictionIdError(f"sigma_in_oz_per_rad = {sigma_in_oz_per_rad!r}: must be > 0")
    grid = DEFAULT_X_GRID if x_grid is None else np.asarray(x_grid, dtype=np.float64)
    if (grid.ndim != 1 or grid.size < 2 or not np.all(np.isfinite(grid))
            or np.any(np.diff(grid) <= 0) or grid[0] != 0.0 or grid[-1] != 2.0):
        raise FrictionIdError("x_grid must be strictly increasing from 0 to 2 (the branch "
                              "coordinate's range)")
    w = float(window_halfwidth_x)
    if not 0.0 < w <= 0.5:
        raise FrictionIdError(f"window_halfwidth_x = {window_halfwidth_x!r}: must be in (0, 0.5]")
    if not 0.0 < float(plateau_slope_ratio) < 1.0:
        raise FrictionIdError(f"plateau_slope_ratio = {plateau_slope_ratio!r}: must be in (0, 1)")
    return sigma, grid, w


def _coulomb_torque(loop: HysteresisLoop, coulomb_torque_in_oz: float | None,
                    plateau_slope_ratio: float) -> tuple[float, bool]:
    """(T_c, whether it was estimated from the loop): the one given, or half the median
    running swing of the complete branches that reach a plateau."""
    if coulomb_torque_in_oz is None:
        plateau = [b for b in loop.branches
                   if b.complete and b.turnaround_slope_in_oz_per_rad > 0.0
                   and abs(b.late_slope_in_oz_per_rad)
                   <= plateau_slope_ratio * b.turnaround_slope_in_oz_per_rad]
        if not plateau:
            raise FrictionIdError(
                "no complete branch reaches the running torque (its late slope stays above "
                f"{plateau_slope_ratio:g} × its turnaround slope), so T_c cannot be read off "
                "the loop: record a larger triangle amplitude or give coulomb_torque_in_oz")
        t_c = float(np.median([0.5 * b.running_swing_in_oz for b in plateau]))
        estimated = True
    else:
        t_c = float(coulomb_torque_in_oz)
        estimated = False
    if not (math.isfinite(t_c) and t_c > 0.0):
        raise FrictionIdError(f"Coulomb torque T_c = {t_c!r} in-oz: must be > 0")
    return t_c, estimated


def _branch_slopes(loop: HysteresisLoop, b: Branch, grid: np.ndarray, w: float,
                   t_c: float) -> np.ndarray:
    """dT/dθ of one branch at each grid point (NaN where the branch gives none)."""
    th, tq = loop.angle_rad, loop.torque_in_oz
    slopes = np.full(grid.size, np.nan)
    s = b.direction
    psi = s * (th[b.start:b.stop + 1] - b.reversal_angle_rad)
    dT = s * (tq[b.start:b.stop + 1] - b.reversal_torque_in_oz)
    x_mono = np.maximum.accumulate(_moving_average(dT / t_c, SMOOTH_HALF_WIDTH))
    for i, xg in enumerate(grid):
        # at the ends of [0, 2] the window is one-sided but keeps its full width 2w:
        # the first samples of a branch carry the reversal's timing jitter (the noisy
        # angle's extremum is a few samples off), which a narrower fit would feel most
        lo = min(max(xg - w, 0.0), 2.0 - 2.0 * w)
        hi = max(min(xg + w, 2.0), 2.0 * w)
        if x_mono[-1] < hi:
            continue                           # the branch does not get through the window
        a = 0 if lo <= 0.0 else int(np.searchsorted(x_mono, lo, side="left"))
        e = int(np.searchsorted(x_mono, hi, side="right"))
        if e - a < MIN_FIT_SAMPLES:
            continue
        g = min(int(np.searchsorted(x_mono, xg, side="left")), psi.size - 1)
        p = psi[a:e] - psi[g]
        scale = float(np.max(np.abs(p)))
        if not scale > 0.0:
            continue
        coef = np.polynomial.polynomial.polyfit(p / scale, dT[a:e], 2)
        slopes[i] = coef[1] / scale
    return slopes


def identify_friction(angle_rad, torque_in_oz, *, sigma_in_oz_per_rad: float,
                      coulomb_torque_in_oz: float | None = None, x_grid=None,
                      window_halfwidth_x: float = 0.01, monotone: bool = True,
                      min_reversal_travel_rad: float | None = None,
                      turnaround_fraction: float = 0.01, late_fraction: float = 0.2,
                      plateau_slope_ratio: float = 0.05) -> FrictionIdentification:
    """Identify the DB-DHM slope table f(x) from a hysteresis-triangle record.

    sigma_in_oz_per_rad   rest stiffness σ the table multiplies (testbed friction.sigma).
    coulomb_torque_in_oz  T_c; None: estimated from the branches that reach the running
                          torque (see the module docstring).
    x_grid                table abscissae, strictly increasing from 0 to 2 (default
                          DEFAULT_X_GRID, dense near 0).
    window_halfwidth_x    half-width w of each grid point's fitting window in x.
    monotone              make f non-increasing (needed for a valid table); see
                          ``monotone_violation`` for whether the data agreed.
    Other arguments: see split_branches.  Raises FrictionIdError.
    """
    sigma, grid, w = _checked_arguments(sigma_in_oz_per_rad, x_grid, window_halfwidth_x,
                                        plateau_slope_ratio)
    loop = split_branches(angle_rad, torque_in_oz, min_reversal_travel_rad=min_reversal_travel_rad,
                          turnaround_fraction=turnaround_fraction, late_fraction=late_fraction)
    t_c, estimated = _coulomb_torque(loop, coulomb_torque_in_oz, plateau_slope_ratio)
    ng = grid.size
    slopes = np.full((len(loop.branches), ng), np.nan)   # dT/dθ per branch and grid point
    for j, b in enumerate(loop.branches):
        slopes[j] = _branch_slopes(loop, b, grid, w, t_c)
    valid = slopes > 0.0                            # a falling torque on a branch is noise
    counts = np.sum(valid, axis=0)
    with np.errstate(divide="ignore"):
        compliance = np.where(valid, 1.0 / np.where(valid, slopes, 1.0), np.nan)
    f_per_branch = np.where(valid, slopes / sigma, np.nan)
    f_raw = np.full(ng, np.nan)
    has = counts > 0
    f_raw[has] = 1.0 / (sigma * np.nanmean(compliance[:, has], axis=0))
    identified = np.isfinite(f_raw)
    if not np.any(identified):
        raise FrictionIdError("no branch covers any grid point of the table: the branches are "
                              "too short or too sparsely sampled")
    fr = f_raw[identified]
    violation = float(np.max(np.diff(fr), initial=0.0) / np.max(fr)) if np.max(fr) > 0 else 0.0
    f = np.clip(f_raw, 0.0, None)
    if monotone:
        f[identified] = _pava_nonincreasing(f[identified], counts[identified].astype(float))
    f = _fill(grid, f)
    return FrictionIdentification(
        loop=loop, sigma_in_oz_per_rad=sigma, coulomb_torque_in_oz=t_c,
        coulomb_torque_estimated=estimated, x=grid.copy(), f=f, f_raw=f_raw,
        f_per_branch=f_per_branch, branches_per_point=counts, identified=identified,
        monotone=bool(monotone), monotone_violation=max(violation, 0.0))


def combine_tables(identifications, *, monotone: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One slope table from several records' (same grid, same σ and T_c): at each grid
    point the compliance-mean of every record's branches that covered it, as
    identify_friction combines the branches of one record; then made non-increasing and
    filled as there.  Returns (x, f, points identified by data).  A record that did not
    reach a point (a small triangle stays in the presliding range, x < 2) does not
    dilute it with its filled value."""
    idents = list(identifications)
    if not idents:
        raise FrictionIdError("no record to combine")
    grid = idents[0].x
    for i in idents[1:]:
        if i.x.shape != grid.shape or np.any(i.x != grid):
            raise FrictionIdError("the records' slope tables are on different grids")
        if i.sigma_in_oz_per_rad != idents[0].sigma_in_oz_per_rad:
            raise FrictionIdError("the records' slope tables use different rest stiffnesses")
    counts = np.sum([i.branches_per_point for i in idents], axis=0).astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        # a record's compliance mean x its branch count = the sum of its compliances
        compliance = np.nansum([np.where(i.identified, i.branches_per_point / i.f_raw, 0.0)
                                for i in idents], axis=0)
        f_raw = np.where(counts > 0, counts / compliance, np.nan)
    identified = np.isfinite(f_raw) & (f_raw > 0)
    if not np.any(identified):
        raise FrictionIdError("no record covers any grid point of the table")
    f = np.where(identified, f_raw, np.nan)
    if monotone:
        f[identified] = _pava_nonincreasing(f[identified], counts[identified])
    return grid.copy(), _fill(grid, f), identified


def write_slope_table(path, x, f, *, comment: str | None = None) -> Path:
    """Write f(x) as a slope-table CSV that plant/slope_table.load_slope_table reads back
    unchanged: '#' comment lines, the header ``x,slope_ratio``, one row per point with
    round-trip precision.  The table is validated first (SlopeTableError, naming the
    problem, if it is not a valid DB-DHM table: e.g. not monotone, or not covering [0, 2]);
    FrictionIdError if the file cannot be written.  Returns the path.
    """
    path = Path(path)
    xa, ya = validate_slope_table(x, f, str(path))
    lines = [f"# {line}".rstrip() for line in (comment or "").splitlines()]
    lines += ["# x = (T - T_k) / T_c for positive velocity, from 0 (at the reversal) to 2;",
              "# slope_ratio multiplies the rest stiffness sigma (negative velocity: mirror image).",
              ",".join(SLOPE_TABLE_HEADER)]
    # repr of a Python float is the shortest text that parses back to the same double
    lines += [f"{float(a)!r},{float(b)!r}" for a, b in zip(xa, ya)]
    try:
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as exc:
        raise FrictionIdError(f"{path}: cannot write the slope table "
                              f"({exc.strerror or exc})") from None
    return path
