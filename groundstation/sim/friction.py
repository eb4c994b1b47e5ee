"""Ball-bearing friction of the simulated testbed: the four Dahl-type models of reference §5.

Models (``FRICTION_MODELS``), all integrating the friction torque T [in-oz] from its slope
with respect to the relative angle φ [rad] across the bearing, dT = (dT/dθ)·dφ:

- ``SFM``     Dahl solid friction model:   dT/dθ = σ·(1 − (T/T_c)·sgn φ')^α
- ``DHM``     Dahl hysteresis model:       dT/dθ = σ·(2 − ((T − T_k)/T_c)·sgn φ')^α,
  T_k the torque at the last velocity reversal, kept on a stack of reversal torques
  (nonlocal memory: a closed minor loop is forgotten).
- ``DB-SFM``  SFM with (1 − (T/T_c)·sgn φ')^α replaced by a slope table f(x),
  x = 1 + (T/T_c)·sgn φ' (0 right after a full reversal, 2 at the Coulomb level).
- ``DB-DHM``  DHM with (2 − x)^α replaced by f(x), x = (T − T_k)/T_c·sgn φ' ∈ [0, 2]
  (negative velocity is the mirror image).  The simulator's default.

One variable for all four
-------------------------
Every model is the same scalar ODE in a normalised branch coordinate x ∈ [0, 2]:

    dx/dψ = (σ/T_c)·g(x),   ψ = |φ| travelled in the current direction s = sgn φ',
    g(x) = (2 − x)^α (analytic models) or f(x) (data-based models),
    T = s·(x − 1)·T_c            (SFM, DB-SFM)
    T = T_k + s·x·T_c            (DHM, DB-DHM)

x = 0 is "just reversed" (slope 2^α·σ, resp. σ·f(0)); x = 2 is the end of the branch
(T = ±T_c for the SFM, T_k ± 2·T_c for the DHM) where the slope vanishes.

Integration (why it cannot overshoot)
-------------------------------------
The slope is stiff: σ·f(0) = 12·5730 in-oz/rad with the shipped table, i.e. T_c is
reached after ~30 µrad, a distance one 1200 Hz substep can easily cover.  Forward Euler
would overshoot the asymptote (and, clamped, would still be step-size dependent).  So
``friction_step`` does not use Euler at all: the branch ODE has a closed-form solution —
y = 2 − x decays as y0·e^(−kψ) for α = 1 and as (y0^(1−α) − (1−α)·k·ψ)^(1/(1−α))
otherwise (k = σ/T_c); on each linear segment of the slope table f itself decays
exponentially, f = f0·e^(b·k·ψ) with b the segment's slope — and the step is advanced
exactly, segment by segment.  The result is independent of how a motion is split into
substeps, x can only move monotonically towards 2 (never past it: it is capped), and so
|T| ≤ T_c (SFM types) and T ∈ T_k + s·[0, 2·T_c] (DHM types) hold for any dφ, however
large.  The same closed form gives the exact travel at which a DHM minor loop closes,
so a step that crosses the closure point is split there: the first part finishes the
minor loop (T lands exactly on T_(k−1)), the rest continues on the restored branch.

Closure tolerance ε = T_c/400: with exact crossings, ε is only needed where a branch
*ends* (at the next velocity reversal) within ε short of its closure point — round-off,
or periodic motion that returns exactly to a reversal point.  Such a branch counts as
closed (its pair is popped) before the new reversal torque is pushed, so the stack does
not creep up under periodic motion.  It is deliberately not applied mid-branch: doing
so would pop a just-pushed reversal whenever a minor loop is narrower than ε (sub-µrad
dither) and replace the 2^α·σ (σ·f(0)) post-reversal slope by the outer branch's, i.e.
lose exactly the high small-amplitude stiffness the DHM exists to model.

Hot path: the ``numba.njit(cache=True)`` functions below take plain floats and float64
arrays only.  State layout (``state``, float64, length ``STATE_SIZE``):

    state[S_T]          friction torque T [in-oz]
    state[S_DIR]        direction of the current branch: +1, −1, or 0 (not moved yet)
    state[S_DEPTH]      number of valid entries in ``stack`` (≥ 2; DHM types only)
    state[S_OVERFLOW]   times the reversal stack overflowed and was reset (report it!)
    state[S_REVERSALS]  velocity reversals seen
    state[S_CLOSURES]   minor loops closed (pairs popped off the stack)

``stack`` (float64, length = stack capacity) holds reversal torques, top at
``stack[depth − 1]`` = T_k, below it T_(k−1).  The bottom two entries are the boundary
[s·T_c, −s·T_c] for a branch moving in direction s (top −s·T_c: the outer branch of
direction s starts at the opposite Coulomb level) and are never popped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from ..core.errors import GroundStationError
# the table is the testbed's fact (plant/); the models below integrate it
from ..plant.slope_table import DEFAULT_SLOPE_TABLE, load_slope_table, validate_slope_table

__all__ = ["FRICTION_MODELS", "MODEL_NAMES", "FrictionParams", "FrictionConfigError", "STATE_SIZE",
           "S_T", "S_DIR", "S_DEPTH", "S_OVERFLOW", "S_REVERSALS", "S_CLOSURES", "new_state",
           "init_state", "friction_step", "simulate_friction", "simulate_friction_kernel"]


class FrictionConfigError(GroundStationError, ValueError):
    """A friction parameter is out of its allowed range (the message names field and range)."""


FRICTION_MODELS = {"SFM": 0, "DHM": 1, "DB-SFM": 2, "DB-DHM": 3}
MODEL_NAMES = {v: k for k, v in FRICTION_MODELS.items()}
MODEL_SFM, MODEL_DHM, MODEL_DB_SFM, MODEL_DB_DHM = 0, 1, 2, 3

# state layout -------------------------------------------------------------------------
S_T, S_DIR, S_DEPTH, S_OVERFLOW, S_REVERSALS, S_CLOSURES = 0, 1, 2, 3, 4, 5
STATE_SIZE = 6

MIN_STACK_CAPACITY = 4
MAX_STACK_CAPACITY = 1_000_000
EPS_FRACTION = 1.0 / 400.0      # ε = T_c/400, the minor-loop closure tolerance of §5

# ======================================================================================
# parameters (plain Python, not in the hot path)
# ======================================================================================
def _check_positive(name: str, value, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise FrictionConfigError(f"FrictionParams.{name} = {value!r}: must be a number > 0 "
                                  f"({unit})") from None
    if not (math.isfinite(v) and v > 0.0):
        raise FrictionConfigError(f"FrictionParams.{name} = {value!r}: must be finite and > 0 "
                                  f"({unit})")
    return v


@dataclass(frozen=True, eq=False)
class FrictionParams:
    """Friction model selection and parameters (validated on construction).

    ``lut_x``/``lut_y`` is the slope table f(x); the data-based models need one, the
    analytic ones ignore it (a flat placeholder is stored so the njit arguments are
    always arrays).  Use ``FrictionParams.from_csv(path, ...)`` to load one.
    """

    model: str = "DB-DHM"
    sigma: float = 5730.0           # in-oz/rad, rest stiffness σ
    T_c: float = 2.25               # in-oz, Coulomb (running) torque
    alpha: float = 1.0              # shape factor α
    lut_x: np.ndarray | None = field(default=None, repr=False)
    lut_y: np.ndarray | None = field(default=None, repr=False)
    stack_capacity: int = 64

    def __post_init__(self):
        if self.model not in FRICTION_MODELS:
            raise FrictionConfigError(f"FrictionParams.model = {self.model!r}: use one of "
                                      f"{', '.join(FRICTION_MODELS)}")
        object.__setattr__(self, "sigma", _check_positive("sigma", self.sigma, "in-oz/rad"))
        object.__setattr__(self, "T_c", _check_positive("T_c", self.T_c, "in-oz"))
        object.__setattr__(self, "alpha", _check_positive("alpha", self.alpha, "dimensionless"))
        cap = self.stack_capacity
        if (isinstance(cap, bool) or not isinstance(cap, (int, np.integer))
                or not MIN_STACK_CAPACITY <= cap <= MAX_STACK_CAPACITY):
            raise FrictionConfigError(
                f"FrictionParams.stack_capacity = {cap!r}: must be an integer in "
                f"[{MIN_STACK_CAPACITY}, {MAX_STACK_CAPACITY}]")
        object.__setattr__(self, "stack_capacity", int(cap))
        if self.lut_x is None and self.lut_y is None:
            if self.data_based:
                raise FrictionConfigError(
                    f"FrictionParams: model {self.model} needs a slope table (lut_x, lut_y); "
                    f"use FrictionParams.from_csv(path, ...)")
            lx, ly = np.array([0.0, 2.0]), np.array([1.0, 1.0])   # unused placeholder
        elif self.lut_x is None or self.lut_y is None:
            raise FrictionConfigError("FrictionParams: give both lut_x and lut_y, or neither")
        else:
            lx, ly = validate_slope_table(self.lut_x, self.lut_y, "FrictionParams.lut_x/lut_y")
        object.__setattr__(self, "lut_x", lx)
        object.__setattr__(self, "lut_y", ly)

    @property
    def model_id(self) -> int:
        return FRICTION_MODELS[self.model]

    @property
    def data_based(self) -> bool:
        return self.model.startswith("DB-")

    @property
    def epsilon(self) -> float:
        """Minor-loop closure tolerance ε = T_c/400 [in-oz]."""
        return self.T_c * EPS_FRACTION

    @classmethod
    def from_csv(cls, path=DEFAULT_SLOPE_TABLE, **kwargs) -> "FrictionParams":
        """Parameters with the slope table read from ``path`` (other fields as keywords)."""
        lx, ly = load_slope_table(path)
        return cls(lut_x=lx, lut_y=ly, **kwargs)

    def step_args(self) -> tuple:
        """(model, sigma, T_c, alpha, lut_x, lut_y): the trailing arguments of friction_step."""
        return (self.model_id, self.sigma, self.T_c, self.alpha, self.lut_x, self.lut_y)


# ======================================================================================
# numba core
# ======================================================================================
@numba.njit(cache=True)
def _set_base(state, stack, direction, T_c):
    """Stack = the two boundary entries for a branch moving in ``direction`` (±1)."""
    stack[0] = direction * T_c
    stack[1] = -direction * T_c
    state[S_DEPTH] = 2.0


@numba.njit(cache=True)
def init_state(state, stack, direction, T0, T_c):
    """(Re)initialise in place: torque T0, branch direction +1/−1/0, fresh stack."""
    d = 1.0 if direction > 0 else (-1.0 if direction < 0 else 0.0)
    state[:] = 0.0
    state[S_T] = min(max(T0, -T_c), T_c)
    state[S_DIR] = d
    _set_base(state, stack, d if d != 0.0 else 1.0, T_c)


@numba.njit(cache=True)
def _pop_pair(state, stack, direction, T_c):
    """A minor loop closed: drop its two reversal torques (never the boundary pair)."""
    depth = int(state[S_DEPTH])
    if depth >= 4:
        state[S_DEPTH] = depth - 2.0
    else:
        # depth 3 = [boundary pair, T_k]: the branch merged into the outer loop, whose
        # branch in this direction starts from the opposite Coulomb level.
        _set_base(state, stack, direction, T_c)
    state[S_CLOSURES] += 1.0


@numba.njit(cache=True)
def _closure_x(state, stack, T_c):
    """Branch coordinate x at which the current branch closes its minor loop (2: never)."""
    depth = int(state[S_DEPTH])
    if depth <= 2:
        return 2.0
    return min(abs(stack[depth - 1] - stack[depth - 2]) / T_c, 2.0)


@numba.njit(cache=True)
def _advance_analytic(x0, psi, x_cap, alpha, k):
    """Advance dx/dψ = k·(2 − x)^α exactly by ψ, stopping at x_cap.

    Returns (dx, psi_left); psi_left > 0 only if x_cap was reached.
    """
    if x0 >= x_cap:                          # already at the cap (x_cap <= 2)
        return 0.0, psi
    y0 = 2.0 - x0
    y_cap = 2.0 - x_cap
    p = 1.0 - alpha
    if abs(p) < 1e-12:                       # α = 1: y = y0·exp(−kψ)
        psi_cap = math.log(y0 / y_cap) / k if y_cap > 0.0 else math.inf
    elif y_cap > 0.0:                        # y^p = y0^p − p·k·ψ
        psi_cap = (y0 ** p - y_cap ** p) / (p * k)
    elif p > 0.0:                            # α < 1 reaches y = 0 in finite travel
        psi_cap = y0 ** p / (p * k)
    else:
        psi_cap = math.inf
    if psi >= psi_cap:
        return x_cap - x0, psi - psi_cap
    if abs(p) < 1e-12:
        dx = -y0 * math.expm1(-k * psi)
    else:
        r = p * k * psi / (y0 ** p)          # y = y0·(1 − r)^(1/p)
        if r >= 1.0:                         # only for p > 0 (excluded by psi < psi_cap)
            dx = y0
        else:
            dx = -y0 * math.expm1(math.log1p(-r) / p)
    return min(max(dx, 0.0), x_cap - x0), 0.0


@numba.njit(cache=True)
def _advance_table(x0, psi, x_cap, k, lut_x, lut_y):
    """Advance dx/dψ = k·f(x) exactly by ψ (f piecewise linear), stopping at x_cap.

    On a segment f = fa + b·(x − xa), so f(ψ) = f0·exp(b·k·ψ): exact, no overshoot.
    Returns (dx, psi_left); psi_left > 0 only if x_cap was reached.
    """
    n = lut_x.shape[0]
    x = x0
    j = 0
    while j < n - 2 and lut_x[j + 1] <= x:
        j += 1
    while psi > 0.0 and x < x_cap:
        xa = lut_x[j]
        xb = lut_x[j + 1]
        fa = lut_y[j]
        b = (lut_y[j + 1] - fa) / (xb - xa)
        g0 = fa + b * (x - xa)
        if g0 <= 0.0:                        # zero slope: T cannot move on this branch
            psi = 0.0
            break
        x_end = min(xb, x_cap) if j < n - 2 else x_cap
        g_end = fa + b * (x_end - xa)
        if b == 0.0:
            psi_seg = (x_end - x) / (k * g0)
        elif g_end > 0.0:
            psi_seg = math.log(g_end / g0) / (b * k)
        else:
            psi_seg = math.inf               # f → 0 at x_end: approached asymptotically
        if psi >= psi_seg:
            psi -= psi_seg
            x = x_end
            if x_end >= xb and j < n - 2:
                j += 1
        else:
            if b == 0.0:
                dx = k * g0 * psi
            else:
                dx = g0 * math.expm1(b * k * psi) / b
            x = min(x + dx, x_end)
            psi = 0.0
    if x < x_cap:
        psi = 0.0
    return x - x0, psi


@numba.njit(cache=True)
def _advance(x0, psi, x_cap, table, alpha, k, lut_x, lut_y):
    if table:
        return _advance_table(x0, psi, x_cap, k, lut_x, lut_y)
    return _advance_analytic(x0, psi, x_cap, alpha, k)


@numba.njit(cache=True)
def friction_step(state, stack, dphi, velocity, model, sigma, T_c, alpha, lut_x, lut_y):
    """Advance the friction torque over one substep; returns the new T [in-oz].

    dphi      relative angle increment across the bearing over the substep [rad]
    velocity  relative velocity; only its sign is used (direction, reversal detection).
              0 → nothing changes (no reversal).  An increment whose sign disagrees with
              the velocity's is not integrated (pass velocity = dphi/h to avoid that).
    model     FRICTION_MODELS value; sigma [in-oz/rad], T_c [in-oz], alpha; lut_x/lut_y
              slope table (ignored by SFM/DHM but must be float64 arrays).
    state, stack are updated in place (see the module docstring for the layout).
    """
    T = state[S_T]
    if not (velocity > 0.0 or velocity < 0.0) or not math.isfinite(dphi):
        return T                             # zero / NaN velocity: no change, no reversal
    s = 1.0 if velocity > 0.0 else -1.0
    dhm = model == MODEL_DHM or model == MODEL_DB_DHM
    table = model == MODEL_DB_SFM or model == MODEL_DB_DHM
    d = state[S_DIR]
    eps_x = EPS_FRACTION                     # ε/T_c
    if d == 0.0:                             # first motion: choose the outer branch
        state[S_DIR] = s
        if dhm:
            _set_base(state, stack, s, T_c)
    elif d != s:                             # velocity reversal
        state[S_DIR] = s
        state[S_REVERSALS] += 1.0
        if dhm:
            # Closure tolerance: the branch being left ended within ε of its closure
            # point (T + ε·d − T_k reached |T_k − T_(k−1)|): treat its minor loop as
            # closed before remembering the new reversal.  Catches round-off and
            # periodic motion that returns exactly to a reversal point, so the stack
            # does not grow; crossings during motion are detected exactly below.
            while int(state[S_DEPTH]) > 2:
                depth = int(state[S_DEPTH])
                tk = stack[depth - 1]
                if d * (T - tk) / T_c + eps_x >= abs(tk - stack[depth - 2]) / T_c:
                    _pop_pair(state, stack, d, T_c)
                else:
                    break
            depth = int(state[S_DEPTH])
            if depth >= stack.shape[0]:
                # Overflow: forget all inner memory, keep the current branch's outer
                # context (boundary pair for the old direction) and the reversal
                # itself, so T and the post-reversal slope stay right.  Counted.
                state[S_OVERFLOW] += 1.0
                _set_base(state, stack, d, T_c)
                depth = 2
            stack[depth] = T
            state[S_DEPTH] = depth + 1.0
    psi = s * dphi
    if not psi > 0.0:
        return T
    k = sigma / T_c
    if not dhm:
        x0 = min(max(1.0 + s * T / T_c, 0.0), 2.0)
        dx, _ = _advance(x0, psi, 2.0, table, alpha, k, lut_x, lut_y)
        T = T + s * dx * T_c
        T = min(max(T, -T_c), T_c)          # round-off guard only
    else:
        for _ in range(stack.shape[0] + 2):  # each extra pass pops a pair: bounded
            depth = int(state[S_DEPTH])
            tk = stack[depth - 1]
            x0 = min(max(s * (T - tk) / T_c, 0.0), 2.0)
            x_cap = _closure_x(state, stack, T_c)
            dx, psi = _advance(x0, psi, x_cap, table, alpha, k, lut_x, lut_y)
            if depth > 2 and x0 + dx >= x_cap:
                # the branch reached the previous reversal point T_(k-1): the minor loop
                # closed exactly there; the rest of the travel continues on the restored
                # branch (nonlocal memory: as if the minor loop never happened).
                tk1 = stack[depth - 2]
                T = tk1 if abs(tk - tk1) <= 2.0 * T_c else tk + s * 2.0 * T_c
                _pop_pair(state, stack, s, T_c)
                if psi > 0.0:
                    continue
            else:
                T = T + s * dx * T_c
            break
    state[S_T] = T
    return T


@numba.njit(cache=True)
def simulate_friction_kernel(phi, state, stack, model, sigma, T_c, alpha, lut_x, lut_y, out):
    """out[0] = current T; out[i] = T after moving from phi[i−1] to phi[i]."""
    out[0] = state[S_T]
    for i in range(1, phi.shape[0]):
        dphi = phi[i] - phi[i - 1]
        out[i] = friction_step(state, stack, dphi, dphi, model, sigma, T_c, alpha, lut_x, lut_y)


# ======================================================================================
# convenience wrappers
# ======================================================================================
def new_state(params: FrictionParams, initial_direction: int = 0,
              T0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Fresh (state, stack) arrays: torque T0 (|T0| ≤ T_c), branch direction ±1 or 0.

    The stack starts as the boundary pair [−T_c, +T_c] ordered so that T_k is the
    Coulomb level the branch of ``initial_direction`` starts from (direction 0: chosen
    at the first motion).
    """
    if initial_direction not in (-1, 0, 1):
        raise FrictionConfigError(f"initial_direction = {initial_direction!r}: use -1, 0 or +1")
    T0 = float(T0)
    if not (math.isfinite(T0) and abs(T0) <= params.T_c):
        raise FrictionConfigError(f"T0 = {T0!r}: must lie in [-T_c, T_c] = "
                                  f"[{-params.T_c:g}, {params.T_c:g}] in-oz")
    state = np.zeros(STATE_SIZE)
    stack = np.zeros(params.stack_capacity)
    init_state(state, stack, float(initial_direction), T0, params.T_c)
    return state, stack


def simulate_friction(phi_trajectory, params: FrictionParams, *, initial_direction: int = 0,
                      T0: float = 0.0, state: np.ndarray | None = None,
                      stack: np.ndarray | None = None) -> np.ndarray:
    """Friction torque along an angle trajectory (one friction_step per increment).

    Returns T with T[0] the initial torque.  Pass ``state``/``stack`` (from new_state) to
    continue a run or to read counters (overflow, reversals, closures) afterwards.
    """
    phi = np.ascontiguousarray(phi_trajectory, dtype=np.float64)
    if phi.ndim != 1 or phi.size == 0:
        raise ValueError("phi_trajectory must be a non-empty 1-D array")
    if state is None or stack is None:
        state, stack = new_state(params, initial_direction, T0)
    out = np.empty_like(phi)
    simulate_friction_kernel(phi, state, stack, *params.step_args(), out)
    return out
