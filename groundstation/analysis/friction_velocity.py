"""Steady-state (running) friction against velocity: the reference's constant-velocity
ramps (§7, "constant-velocity ramps from 0.01 to 50 deg/s -> steady-state friction vs
velocity").  Arrays in, figures out; no I/O and no Qt (the log adapter is
log_friction_velocity.py).

At constant velocity the bearing's friction torque is what the motors push with: no
inertia torque, and the controller holds the axis on its ramp.  So the record (the
bearing's angle and the torque across it, e.g. the coarse torque command) is searched
for its constant-velocity stretches, and each gives one point: its velocity and the mean
torque over its settled part.

How
---
1. **Blocks.**  The record is cut into blocks of ``block_s`` (50 ms) of time.  Each block
   keeps its sample count and sums taken relative to its first sample, from which come
   its mean time, mean angle, mean torque (and spread) and its velocity: the
   least-squares slope of angle against time over the block (so encoder noise averages
   out; 5 nrad of noise gives ~0.5 urad/s over 50 ms, against 175 urad/s at the
   reference's slowest ramp, 0.01 deg/s).  `BlockAccumulator` builds the blocks from
   pieces of a record (a log read in chunks) with the same result as one array.
2. **Runs of one direction.**  Consecutive blocks moving faster than the floor
   (``min_speed_rad_s``) in the same direction.  A stop or a reversal ends a run.
3. **The plateau of a run.**  The run's median velocity is its plateau; the blocks
   within ``tolerance`` (10 %) of it are steady, and the segment is the longest stretch
   of steady blocks, bridging up to ``MAX_GAP_BLOCKS`` unsteady blocks (a servo that
   rings around its ramp), less ``EDGE_BLOCKS`` at either end.  The velocity blends at
   either end of a pass are left out: there the motors also accelerate the axis.  A
   pass without such a stretch of at least ``min_segment_s`` is left out (a note says
   so); a run shorter than that is not a pass (a servo flickering through the floor).  One segment
   per run: a profile that changes speed without stopping gives its longest plateau.
4. **The settled part.**  A friction torque needs travel to reach its running value
   after a reversal (presliding: several T_c/sigma, ~0.4 mrad each on the rig; on the
   DB-DHM slope table the last percent takes longest), so only the last
   ``settled_fraction`` (half) of each segment is averaged.  Its two halves are compared
   (``torque_drift_in_oz``): a segment whose torque still moves by more than
   ``settle_tolerance`` (2 %) of its mean between them is flagged unsettled - its mean
   is then a bound, not the running friction.
5. **The point.**  velocity = the angle travelled over the settled part / its duration
   (signed); torque = its mean (signed), with its standard deviation.

Per direction, the running friction of a record is the mean of its settled segments;
(T+ - T-)/2 is the friction, (T+ + T-)/2 an offset that is the same both ways (a cable,
an unbalance, a torque-constant error does not cancel that way, but a bias does).
Across records (one velocity each, as a campaign runs them) `coulomb_viscous_fit` fits
T = T0 + T_c sgn(v) + b v.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import AnalysisError

#: block length [s]: velocity and torque are summarised per block
DEFAULT_BLOCK_S = 0.05
#: a block is on the plateau when its velocity is within this fraction of the plateau's
DEFAULT_TOLERANCE = 0.1
#: slower than this counts as standing still [rad/s] (0.00057 deg/s; the reference's
#: slowest friction test moves at 0.001 deg/s = 1.7e-5 rad/s)
DEFAULT_MIN_SPEED_RAD_S = 1.0e-5
#: the torque is averaged over this last fraction of each segment
DEFAULT_SETTLED_FRACTION = 0.5
#: the settled part's halves may differ by this fraction of its mean torque
DEFAULT_SETTLE_TOLERANCE = 0.02
#: ... or by this much [in-oz], whichever is larger (a torque near zero)
SETTLE_FLOOR_IN_OZ = 0.01
#: a shorter plateau is not a segment [s]
DEFAULT_MIN_SEGMENT_S = 0.2
#: unsteady blocks bridged inside a plateau
MAX_GAP_BLOCKS = 2
#: blocks dropped at either end of a plateau: they may reach into a velocity blend,
#: where the inertia torque (J·dw/dt) is not friction
EDGE_BLOCKS = 1
#: a block needs this many samples for a slope
MIN_BLOCK_SAMPLES = 3


class FrictionVelocityError(AnalysisError, ValueError):
    """A record cannot give friction against velocity (the message says why)."""


# ======================================================================================
# blocks
# ======================================================================================
@dataclass(frozen=True, eq=False)
class VelocityBlocks:
    """Per-block summaries of a record (see the module docstring, step 1)."""

    block_s: float
    time_s: np.ndarray              # mean time of each block
    angle_rad: np.ndarray           # mean angle
    velocity_rad_s: np.ndarray      # least-squares slope (nan: too few samples)
    torque_in_oz: np.ndarray        # mean torque
    torque_var: np.ndarray          # variance of the torque within the block
    samples: np.ndarray             # samples per block (int)
    saturated: np.ndarray | None    # saturated samples per block (None: not given)

    def __len__(self) -> int:
        return int(self.time_s.size)


_SUMS = ("n", "t", "a", "tt", "ta", "q", "qq", "sat")


class BlockAccumulator:
    """Blocks from a record given in pieces, in time order (a log read in chunks): the
    same blocks as one call with the whole record.  Each block's sums are taken relative
    to its first sample, so an angle of 0.3 rad does not eat a 1 nrad step."""

    def __init__(self, block_s: float = DEFAULT_BLOCK_S, origin_s: float | None = None):
        if not (isinstance(block_s, (int, float)) and math.isfinite(block_s) and block_s > 0):
            raise FrictionVelocityError(f"block_s = {block_s!r}: must be a finite number > 0")
        self.block_s = float(block_s)
        self.origin_s = origin_s
        self._closed: dict[str, list[np.ndarray]] = {k: [] for k in ("id", "rt", "ra", "rq", *_SUMS)}
        self._open: dict[str, float] | None = None      # the last block, still growing
        self._last_t = -math.inf
        self._flags = None                              # saturated given: True/False once known

    def add(self, time_s, angle_rad, torque_in_oz, saturated=None) -> None:
        t = _array("time_s", time_s)
        a = _array("angle_rad", angle_rad, t.size)
        q = _array("torque_in_oz", torque_in_oz, t.size)
        if not t.size:
            return
        flags = saturated is not None
        if self._flags is None:
            self._flags = flags
        elif self._flags != flags:
            raise FrictionVelocityError("saturated must be given with every piece or with none")
        s = (np.asarray(saturated, dtype=bool).astype(np.float64) if flags else np.zeros(t.size))
        if s.size != t.size:
            raise FrictionVelocityError(f"saturated has {s.size} samples, time_s {t.size}")
        if np.any(np.diff(t) <= 0) or t[0] <= self._last_t:
            raise FrictionVelocityError("time_s must increase strictly, also from piece to piece")
        self._last_t = float(t[-1])
        if self.origin_s is None:
            self.origin_s = float(t[0])
        ids = np.floor((t - self.origin_s) / self.block_s).astype(np.int64)
        starts = np.concatenate(([0], np.flatnonzero(np.diff(ids)) + 1))
        counts = np.diff(np.concatenate((starts, [t.size])))
        rt, ra, rq = t[starts].copy(), a[starts].copy(), q[starts].copy()
        merge = self._open is not None and ids[0] == self._open["id"]
        if merge:                                       # the first group continues the open block
            rt[0], ra[0], rq[0] = self._open["rt"], self._open["ra"], self._open["rq"]
        dt = t - np.repeat(rt, counts)
        da = a - np.repeat(ra, counts)
        dq = q - np.repeat(rq, counts)
        sums = {"n": counts.astype(np.float64), "t": np.add.reduceat(dt, starts),
                "a": np.add.reduceat(da, starts), "tt": np.add.reduceat(dt * dt, starts),
                "ta": np.add.reduceat(dt * da, starts), "q": np.add.reduceat(dq, starts),
                "qq": np.add.reduceat(dq * dq, starts), "sat": np.add.reduceat(s, starts)}
        if merge:
            for k in _SUMS:
                sums[k][0] += self._open[k]
        elif self._open is not None:
            self._close(self._open)
        n = len(starts)
        for i in range(n - 1):
            self._close({"id": ids[starts[i]], "rt": rt[i], "ra": ra[i], "rq": rq[i],
                         **{k: sums[k][i] for k in _SUMS}})
        self._open = {"id": ids[starts[-1]], "rt": rt[-1], "ra": ra[-1], "rq": rq[-1],
                      **{k: sums[k][-1] for k in _SUMS}}

    def _close(self, block: dict[str, float]) -> None:
        for k, v in block.items():
            self._closed[k].append(v)

    def result(self) -> VelocityBlocks:
        """The blocks so far (the growing last one included)."""
        cols = {k: np.array(v, dtype=np.float64) for k, v in self._closed.items()}
        if self._open is not None:
            for k, v in self._open.items():
                cols[k] = np.append(cols[k], v)
        n = cols["n"]
        with np.errstate(invalid="ignore", divide="ignore"):
            den = n * cols["tt"] - cols["t"] ** 2
            slope = (n * cols["ta"] - cols["t"] * cols["a"]) / den
            slope = np.where((n >= MIN_BLOCK_SAMPLES) & (den > 0), slope, np.nan)
            mq = cols["q"] / n
            var = np.maximum(cols["qq"] / n - mq ** 2, 0.0)
            return VelocityBlocks(
                block_s=self.block_s, time_s=cols["rt"] + cols["t"] / n,
                angle_rad=cols["ra"] + cols["a"] / n, velocity_rad_s=slope,
                torque_in_oz=cols["rq"] + mq, torque_var=var, samples=n.astype(np.int64),
                saturated=cols["sat"].astype(np.int64) if self._flags else None)


def _array(name: str, values, size: int | None = None) -> np.ndarray:
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise FrictionVelocityError(f"{name} must be a 1-D array of numbers") from None
    if a.ndim != 1:
        raise FrictionVelocityError(f"{name} must be 1-D, got shape {a.shape}")
    if size is not None and a.size != size:
        raise FrictionVelocityError(f"{name} has {a.size} samples, time_s {size}")
    if not np.all(np.isfinite(a)):
        i = int(np.argmax(~np.isfinite(a)))
        raise FrictionVelocityError(f"{name} has a non-finite value at sample {i} ({a[i]})")
    return a


def velocity_blocks(time_s, angle_rad, torque_in_oz, saturated=None, *,
                    block_s: float = DEFAULT_BLOCK_S) -> VelocityBlocks:
    """The blocks of a record held in memory."""
    acc = BlockAccumulator(block_s)
    acc.add(time_s, angle_rad, torque_in_oz, saturated)
    return acc.result()


# ======================================================================================
# segments
# ======================================================================================
@dataclass(frozen=True)
class VelocitySegment:
    """One constant-velocity stretch and its running-friction point."""

    direction: int                  # +1: the angle increases, -1: it decreases
    start_s: float                  # the plateau found (block mean times)
    stop_s: float
    settled_from_s: float           # the part averaged: settled_from_s .. stop_s
    velocity_rad_s: float           # over the settled part, signed
    torque_in_oz: float             # mean over the settled part, signed
    torque_std_in_oz: float
    torque_drift_in_oz: float       # second half minus first half of the settled part
    velocity_spread: float          # std of the plateau's block velocities / |velocity|
    samples: int                    # samples averaged
    saturated_fraction: float | None
    settled: bool                   # |drift| within the settle tolerance

    @property
    def speed_deg_s(self) -> float:
        return abs(self.velocity_rad_s) * 180.0 / math.pi


@dataclass(frozen=True, eq=False)
class FrictionVelocity:
    """The constant-velocity segments of a record, and the running friction per direction."""

    segments: tuple[VelocitySegment, ...]
    blocks: VelocityBlocks
    min_speed_rad_s: float
    tolerance: float
    settled_fraction: float
    notes: tuple[str, ...] = field(default_factory=tuple)

    def direction(self, sign: int, *, settled_only: bool = True) -> list[VelocitySegment]:
        return [s for s in self.segments if s.direction == sign and (s.settled or not settled_only)]

    def mean(self, sign: int) -> tuple[float, float] | None:
        """(velocity, torque) of one direction: the sample-weighted mean of its settled
        segments (None: none)."""
        segs = self.direction(sign)
        if not segs:
            return None
        w = np.array([s.samples for s in segs], dtype=np.float64)
        return (float(np.average([s.velocity_rad_s for s in segs], weights=w)),
                float(np.average([s.torque_in_oz for s in segs], weights=w)))

    @property
    def running_torque_in_oz(self) -> float | None:
        """(T+ - T-)/2 of the directions' means (None: not both directions settled)."""
        p, m = self.mean(+1), self.mean(-1)
        return None if p is None or m is None else (p[1] - m[1]) / 2.0

    @property
    def offset_in_oz(self) -> float | None:
        """(T+ + T-)/2: a torque the same both ways (None: not both directions settled)."""
        p, m = self.mean(+1), self.mean(-1)
        return None if p is None or m is None else (p[1] + m[1]) / 2.0

    def summary(self) -> dict[str, float | int | None]:
        """The record's figures, flat: segments, settled ones, their mean speed (deg/s,
        sample-weighted), each direction's mean torque, the friction ((T+ - T-)/2 with both
        directions settled, else |T| of the one) and the offset ((T+ + T-)/2)."""
        settled = [s for s in self.segments if s.settled]
        pos, neg = self.mean(+1), self.mean(-1)
        friction = self.running_torque_in_oz
        if friction is None and (pos or neg):
            friction = abs((pos or neg)[1])
        speed = (sum(s.speed_deg_s * s.samples for s in settled) / sum(s.samples for s in settled)
                 if settled else None)
        return {"segments": len(self.segments), "settled_segments": len(settled),
                "speed_deg_s": speed, "torque_pos_in_oz": pos[1] if pos else None,
                "torque_neg_in_oz": neg[1] if neg else None, "friction_in_oz": friction,
                "offset_in_oz": self.offset_in_oz}

    def text(self) -> str:
        lines = [f"{len(self.segments)} constant-velocity segment(s)"]
        for s in self.segments:
            lines.append(f"  {'+' if s.direction > 0 else '-'} {s.speed_deg_s:.4g} deg/s "
                         f"({s.velocity_rad_s:+.4g} rad/s): torque {s.torque_in_oz:+.4g} in-oz "
                         f"(std {s.torque_std_in_oz:.3g}, drift {s.torque_drift_in_oz:+.3g})"
                         + ("" if s.settled else " NOT SETTLED"))
        rt = self.running_torque_in_oz
        if rt is not None:
            lines.append(f"  running friction (T+ - T-)/2 = {rt:.4g} in-oz, offset "
                         f"{self.offset_in_oz:+.3g} in-oz")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


def _check_fraction(name: str, v: float, *, upper: float = 1.0) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0.0 < v <= upper):
        raise FrictionVelocityError(f"{name} = {v!r}: must be a number in (0, {upper:g}]")
    return float(v)


def _runs(v: np.ndarray, floor: float) -> list[tuple[int, int]]:
    """[a, b) of each stretch of blocks moving one way faster than `floor`."""
    sign = np.where(np.isfinite(v) & (np.abs(v) > floor), np.sign(np.nan_to_num(v)), 0.0)
    out: list[tuple[int, int]] = []
    i, n = 0, sign.size
    while i < n:
        if sign[i] == 0:
            i += 1
            continue
        j = i
        while j < n and sign[j] == sign[i]:
            j += 1
        out.append((i, j))
        i = j
    return out


def _plateau(v: np.ndarray, tolerance: float) -> tuple[int, int] | None:
    """[a, b) (within the run) of the longest stretch of blocks within `tolerance` of
    the run's median velocity, gaps of up to MAX_GAP_BLOCKS bridged."""
    target = float(np.median(v))
    steady = np.abs(v - target) <= tolerance * abs(target)
    idx = np.flatnonzero(steady)
    if not idx.size:
        return None
    best, start, prev = None, idx[0], idx[0]
    for i in idx[1:]:
        if i - prev - 1 > MAX_GAP_BLOCKS:
            if best is None or prev + 1 - start > best[1] - best[0]:
                best = (int(start), int(prev) + 1)
            start = i
        prev = i
    if best is None or prev + 1 - start > best[1] - best[0]:
        best = (int(start), int(prev) + 1)
    return best


def segments_from_blocks(blocks: VelocityBlocks, *, tolerance: float = DEFAULT_TOLERANCE,
                         min_speed_rad_s: float = DEFAULT_MIN_SPEED_RAD_S,
                         settled_fraction: float = DEFAULT_SETTLED_FRACTION,
                         settle_tolerance: float = DEFAULT_SETTLE_TOLERANCE,
                         min_segment_s: float = DEFAULT_MIN_SEGMENT_S) -> FrictionVelocity:
    """The constant-velocity segments of a record's blocks (module docstring, steps 2-5)."""
    tolerance = _check_fraction("tolerance", tolerance)
    settled_fraction = _check_fraction("settled_fraction", settled_fraction)
    settle_tolerance = _check_fraction("settle_tolerance", settle_tolerance)
    for name, value in (("min_speed_rad_s", min_speed_rad_s), ("min_segment_s", min_segment_s)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                math.isfinite(value) and value > 0):
            raise FrictionVelocityError(f"{name} = {value!r}: must be a finite number > 0")
    v = blocks.velocity_rad_s
    notes: list[str] = []
    segments: list[VelocitySegment] = []
    min_blocks = max(2, int(math.ceil(min_segment_s / blocks.block_s - 1e-9)))
    short = 0
    for a, b in _runs(v, float(min_speed_rad_s)):
        if b - a < min_blocks:           # a flicker through the floor, not a pass
            continue
        span = _plateau(v[a:b], tolerance)
        if span is None or span[1] - span[0] - 2 * EDGE_BLOCKS < min_blocks:
            short += 1
            continue
        p0, p1 = a + span[0] + EDGE_BLOCKS, a + span[1] - EDGE_BLOCKS
        k = max(2, int(round((p1 - p0) * settled_fraction)))
        s0 = p1 - k
        segments.append(_segment(blocks, p0, p1, s0, settle_tolerance))
    if short:
        notes.append(f"{short} pass(es) without a constant-velocity stretch of at least "
                     f"{min_segment_s:g} s (within {tolerance * 100:g} % of their speed) left out")
    unsettled = sum(not s.settled for s in segments)
    if unsettled:
        notes.append(f"{unsettled} segment(s) whose torque still drifts by more than "
                     f"{settle_tolerance * 100:g} % over the settled part (the friction not yet "
                     f"at its running value - too short a stroke - or the loop still ringing): "
                     f"not in the direction means")
    return FrictionVelocity(segments=tuple(segments), blocks=blocks,
                            min_speed_rad_s=float(min_speed_rad_s), tolerance=tolerance,
                            settled_fraction=settled_fraction, notes=tuple(notes))


def _segment(blocks: VelocityBlocks, p0: int, p1: int, s0: int,
             settle_tolerance: float) -> VelocitySegment:
    t, ang, q = blocks.time_s, blocks.angle_rad, blocks.torque_in_oz
    n = blocks.samples.astype(np.float64)
    sel = slice(s0, p1)
    w = n[sel]
    mean_q = float(np.average(q[sel], weights=w))
    var = float(np.average(blocks.torque_var[sel] + (q[sel] - mean_q) ** 2, weights=w))
    velocity = float((ang[p1 - 1] - ang[s0]) / (t[p1 - 1] - t[s0]))
    half = s0 + (p1 - s0) // 2
    first = float(np.average(q[s0:half], weights=n[s0:half]))
    second = float(np.average(q[half:p1], weights=n[half:p1]))
    drift = second - first
    pv = blocks.velocity_rad_s[p0:p1]
    spread = float(np.std(pv) / abs(np.mean(pv)))
    sat = None
    if blocks.saturated is not None:
        sat = float(blocks.saturated[sel].sum() / w.sum())
    return VelocitySegment(
        direction=1 if velocity > 0 else -1, start_s=float(t[p0]), stop_s=float(t[p1 - 1]),
        settled_from_s=float(t[s0]), velocity_rad_s=velocity, torque_in_oz=mean_q,
        torque_std_in_oz=math.sqrt(var), torque_drift_in_oz=drift, velocity_spread=spread,
        samples=int(w.sum()), saturated_fraction=sat,
        settled=abs(drift) <= max(settle_tolerance * abs(mean_q), SETTLE_FLOOR_IN_OZ))


def friction_vs_velocity(time_s, angle_rad, torque_in_oz, saturated=None, *,
                         block_s: float = DEFAULT_BLOCK_S, tolerance: float = DEFAULT_TOLERANCE,
                         min_speed_rad_s: float = DEFAULT_MIN_SPEED_RAD_S,
                         settled_fraction: float = DEFAULT_SETTLED_FRACTION,
                         settle_tolerance: float = DEFAULT_SETTLE_TOLERANCE,
                         min_segment_s: float = DEFAULT_MIN_SEGMENT_S) -> FrictionVelocity:
    """Running friction against velocity of a record in memory (module docstring).

    time_s        sample times [s], strictly increasing (holes allowed)
    angle_rad     the bearing's angle (the outer encoder, phi1)
    torque_in_oz  the torque across the bearing (e.g. the coarse torque command)
    saturated     optional flags (a motor saturated): each segment reports its share
    Raises FrictionVelocityError on bad input."""
    return segments_from_blocks(velocity_blocks(time_s, angle_rad, torque_in_oz, saturated,
                                                block_s=block_s),
                                tolerance=tolerance, min_speed_rad_s=min_speed_rad_s,
                                settled_fraction=settled_fraction,
                                settle_tolerance=settle_tolerance, min_segment_s=min_segment_s)


# ======================================================================================
# across records
# ======================================================================================
@dataclass(frozen=True)
class CoulombViscousFit:
    """T = offset + coulomb·sgn(v) + viscous·v, least squares over the points given."""

    coulomb_in_oz: float
    viscous_in_oz_s_per_rad: float | None      # None: one speed only (no slope)
    offset_in_oz: float | None                 # None: one direction only
    residual_rms_in_oz: float
    points: int
    #: standard deviations of coulomb and viscous from the residuals (None: no residual
    #: degree of freedom, or no slope fitted)
    coulomb_sd_in_oz: float | None = None
    viscous_sd_in_oz_s_per_rad: float | None = None
    dof: int = 0                               # residual degrees of freedom

    def torque(self, velocity_rad_s) -> np.ndarray:
        v = np.asarray(velocity_rad_s, dtype=np.float64)
        return ((self.offset_in_oz or 0.0) + self.coulomb_in_oz * np.sign(v)
                + (self.viscous_in_oz_s_per_rad or 0.0) * v)


def coulomb_viscous_fit(velocity_rad_s, torque_in_oz) -> CoulombViscousFit:
    """Fit the running-friction points of one or more records.  The offset is fitted
    only with both directions present, the viscous slope only with two speeds or more.
    FrictionVelocityError with no point."""
    v = _array("velocity_rad_s", velocity_rad_s)
    q = _array("torque_in_oz", torque_in_oz, v.size)
    keep = v != 0
    v, q = v[keep], q[keep]
    if not v.size:
        raise FrictionVelocityError("no moving point to fit")
    sign = np.sign(v)
    columns = [sign]
    both = bool(np.any(sign > 0) and np.any(sign < 0))
    speeds = np.unique(np.round(np.abs(v), 12))
    slope = speeds.size >= 2
    if both:
        columns.insert(0, np.ones_like(v))
    if slope:
        columns.append(v)
    A = np.column_stack(columns)
    if A.shape[0] < A.shape[1]:                  # fewer points than unknowns: drop the slope
        A, slope = A[:, :-1], False
    coef, *_ = np.linalg.lstsq(A, q, rcond=None)
    resid = q - A @ coef
    i = 0
    offset = None
    if both:
        offset, i = float(coef[0]), 1
    coulomb = float(coef[i])
    viscous = float(coef[i + 1]) if slope else None
    sds: list[float | None] = [None] * A.shape[1]
    dof = A.shape[0] - A.shape[1]
    if dof > 0:
        # the usual least-squares covariance: residual variance x (A'A)^-1
        cov = float(resid @ resid) / dof * np.linalg.pinv(A.T @ A)
        sds = [float(np.sqrt(max(c, 0.0))) for c in np.diag(cov)]
    return CoulombViscousFit(coulomb_in_oz=coulomb, viscous_in_oz_s_per_rad=viscous,
                             offset_in_oz=offset,
                             residual_rms_in_oz=float(np.sqrt(np.mean(resid ** 2))),
                             points=int(v.size), coulomb_sd_in_oz=sds[i],
                             viscous_sd_in_oz_s_per_rad=sds[i + 1] if slope else None,
                             dof=max(dof, 0))


__all__ = ["BlockAccumulator", "CoulombViscousFit", "DEFAULT_BLOCK_S", "DEFAULT_MIN_SPEED_RAD_S",
           "DEFAULT_SETTLED_FRACTION", "DEFAULT_TOLERANCE", "FrictionVelocity",
           "FrictionVelocityError", "VelocityBlocks", "VelocitySegment", "coulomb_viscous_fit",
           "friction_vs_velocity", "segments_from_blocks", "velocity_blocks"]
