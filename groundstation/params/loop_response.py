"""A controller design in its sampled loop: the loop's state-space model, its frequency
responses (loop gains broken at the error, the rate loop, the position loop), closed-loop
poles, stability margins and Bode data.  validate() in loop.py judges a table with them.

The loop is the discretised plant of the design's testbed with the device's loop structure
(protocol/SPEC.md §10.1):

- relative:  e = r - phi2;  v = C0(e), u1 = C1(v), u2 = C2(v)
- inertial:  e = K_p (r - theta_hat) - omega_g, with omega_g the gyro (second-order
  dynamics and a pure delay) and theta_hat the device's complementary filter of the
  integrated gyro and the autocollimator.

The plant is the testbed's linear model (plant/model.py, bearing friction linearised to
its viscous part b_f, base at rest) discretised exactly for a zero-order hold at the
control rate: the sensors are sampled at the start of a period and the torques computed
from them are held over that period, as the simulator and the rig do.  The gyro delay
T_d is not approximated (no Padé): with T_d = (d + f) T, the gyro reading at t_k is the
gyro state at t_(k-d-1) + (1 - f) T, which is the ZOH step from sample k-d-1 over
(1 - f) T, delayed by d + 1 whole samples.  That is exact for piecewise-constant torque.

Loop gains are broken at the error e, the controller's only input: every feedback path
(the rate loop and, in inertial mode, the position loop through K_p) passes through it.
Closed-loop stability is decided by the eigenvalues of the closed-loop state matrix,
not by the margins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from ..core.kinds import Setup
from ..core.dictionary import Dictionary, load_dictionary
from ..plant import model as plant_model
from .tf_algebra import CONTROL_RATE_HZ
from .design_file import ControllerDesign, table_values
from .discretise import sos_response

LOWEST_HZ = 1e-3                  # the frequency grid of the margins starts here
IDENTITY_ROW = np.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0])


# ======================================================================================
# margins
# ======================================================================================
@dataclass(frozen=True)
class Margins:
    """Stability margins of one loop gain L (loop broken at one point).

    gain_margin_db: how far |L| may grow before instability, at the phase crossover where
    it is smallest (inf: L never crosses the negative real axis with |L| < 1).
    lower_gain_margin_db: how far |L| may shrink, for loops that cross -180 deg with
    |L| > 1 (conditionally stable ones); None if there is no such crossing.
    phase_margin_deg: 180 deg + angle of L at the gain crossover where that is smallest
    (nan: |L| never crosses 1).  crossover_hz is that gain crossover."""

    gain_margin_db: float
    gain_margin_hz: float | None
    phase_margin_deg: float
    crossover_hz: float | None
    lower_gain_margin_db: float | None = None
    lower_gain_margin_hz: float | None = None
    gain_crossovers_hz: tuple[float, ...] = ()
    phase_crossovers_hz: tuple[float, ...] = ()

    def text(self) -> str:
        gm = ("gain margin inf (phase never reaches -180 deg below |L| = 1)"
              if math.isinf(self.gain_margin_db) else
              f"gain margin {self.gain_margin_db:.1f} dB at {self.gain_margin_hz:.3g} Hz")
        if self.lower_gain_margin_db is not None:
            gm += f" (lower {self.lower_gain_margin_db:.1f} dB at {self.lower_gain_margin_hz:.3g} Hz)"
        pm = ("no gain crossover" if self.crossover_hz is None else
              f"phase margin {self.phase_margin_deg:.1f} deg at {self.crossover_hz:.3g} Hz")
        if len(self.gain_crossovers_hz) > 1:
            pm += " (|L| = 1 at " + ", ".join(f"{f:.3g}" for f in self.gain_crossovers_hz) + " Hz)"
        return f"{gm}, {pm}"


def margins(loop: Callable[[np.ndarray], np.ndarray], nyquist_hz: float,
            lowest_hz: float = LOWEST_HZ, points: int = 4000) -> Margins:
    """Margins of a discrete-time loop gain given as a function of frequency (Hz).

    Crossings are bracketed on a log grid up to Nyquist and refined by root finding, every
    bracket at once: one vectorised evaluation of L per refinement step serves all the gain
    and phase crossings (a scalar root finder per crossing needs hundreds of single-point
    evaluations, which made the workbench's inertial margins miss 100 ms)."""
    f = np.logspace(math.log10(lowest_hz), math.log10(nyquist_hz * (1 - 1e-9)), points)
    L = loop(f)
    with np.errstate(divide="ignore"):              # a zero of L is just very small
        log_L = np.log(np.abs(L))
    gain_i = _sign_changes(log_L)
    phase_i = np.array([i for i in _sign_changes(L.imag) if L.real[i] < 0 or L.real[i + 1] < 0],
                       dtype=int)
    brackets = np.concatenate([gain_i, phase_i])
    is_gain = np.arange(len(brackets)) < len(gain_i)

    def crossing_function(x: np.ndarray, which: np.ndarray) -> np.ndarray:
        v = loop(x)
        with np.errstate(divide="ignore"):
            return np.where(is_gain[which], np.log(np.maximum(np.abs(v), 1e-300)), v.imag)

    start = np.where(is_gain, log_L[brackets], L.imag[brackets])
    end = np.where(is_gain, log_L[brackets + 1], L.imag[brackets + 1])
    roots = refine_roots(crossing_function, f[brackets], f[brackets + 1], start, end)
    at_roots = loop(np.append(roots, nyquist_hz)) if len(roots) else loop(np.array([nyquist_hz]))
    L_roots, at_nyquist = at_roots[:-1], complex(at_roots[-1])

    gain_x = [float(x) for x in roots[is_gain]]
    gain_v = L_roots[is_gain]
    phase_x, phase_v = [], []
    for x, v in zip(roots[~is_gain], L_roots[~is_gain]):
        if v.real < 0 and abs(v.imag) <= 1e-6 * abs(v):    # not a jump through infinity
            phase_x.append(float(x))
            phase_v.append(complex(v))
    if at_nyquist.real < 0 and not any(abs(x / nyquist_hz - 1) < 1e-3 for x in phase_x):
        phase_x.append(nyquist_hz)
        phase_v.append(at_nyquist)

    pm_deg, pm_hz = math.nan, None
    for x, v in zip(gain_x, gain_v):
        pm = (math.degrees(np.angle(v)) + 360.0) % 360.0 - 180.0
        if pm_hz is None or pm < pm_deg:
            pm_deg, pm_hz = pm, x
    upper = [(-20 * math.log10(abs(v)), x) for x, v in zip(phase_x, phase_v) if abs(v) < 1]
    lower = [(20 * math.log10(abs(v)), x) for x, v in zip(phase_x, phase_v) if abs(v) >= 1]
    gm_db, gm_hz = min(upper) if upper else (math.inf, None)
    lgm_db, lgm_hz = min(lower) if lower else (None, None)
    return Margins(gm_db, gm_hz, pm_deg, pm_hz, lgm_db, lgm_hz,
                   tuple(sorted(gain_x)), tuple(sorted(phase_x)))


def refine_roots(g: Callable[[np.ndarray, np.ndarray], np.ndarray], lo: np.ndarray,
                 hi: np.ndarray, g_lo: np.ndarray, g_hi: np.ndarray,
                 xtol: float = 1e-12, rtol: float = 1e-12, max_steps: int = 400) -> np.ndarray:
    """A zero of g in each bracket [lo_i, hi_i] across which g changes sign, all at once.

    g(x, which) gives g at the points x for the brackets `which` (indices), one call per
    step for every bracket still open.  Illinois regula falsi: the end that stays twice
    running has its value halved, so both ends converge, superlinearly for a simple root,
    until the bracket is within the tolerance scipy's brentq was given here before
    (xtol + rtol |x|).  After three steps running that did not halve a bracket it is
    bisected, so even a flat multiple root needs at most about four times bisection's
    steps.  (Bisecting after two made the steep brackets beside a resonance take twice
    the steps; ITP kept every bracket near bisection's count.)  scipy's root finders
    take one bracket per call, hence this small vectorised one."""
    lo, hi = np.array(lo, float), np.array(hi, float)
    g_lo, g_hi = np.array(g_lo, float), np.array(g_hi, float)
    kept = np.zeros(len(lo), dtype=int)            # +1: lo stayed last step, -1: hi stayed
    slow = np.zeros(len(lo), dtype=int)            # steps since the bracket last halved
    for _ in range(max_steps):
        open_ = (hi - lo) > xtol + rtol * np.abs(hi)
        if not open_.any():
            break
        w = np.nonzero(open_)[0]
        a, b, ga, gb = lo[w], hi[w], g_lo[w], g_hi[w]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = b - gb * (b - a) / (gb - ga)
        bisect = (slow[w] >= 3) | ~np.isfinite(x) | (x <= a) | (x >= b)
        x = np.where(bisect, 0.5 * (a + b), x)
        gx = np.asarray(g(x, w), dtype=float)
        width = b - a
        exact = gx == 0
        right_half = (np.sign(gx) == np.sign(ga)) & ~exact    # the root is in [x, b]
        left_half = ~right_half & ~exact                       # the root is in [a, x]
        # Illinois: halve the value at an end that stays for the second time running
        gb = np.where(right_half & (kept[w] == -1), 0.5 * gb, gb)
        ga = np.where(left_half & (kept[w] == +1), 0.5 * ga, ga)
        a, ga = np.where(right_half | exact, x, a), np.where(right_half, gx, ga)
        b, gb = np.where(left_half | exact, x, b), np.where(left_half, gx, gb)
        kept[w] = np.where(right_half, -1, np.where(left_half, +1, 0))
        slow[w] = np.where(b - a <= 0.5 * width, 0, slow[w] + 1)
        lo[w], hi[w], g_lo[w], g_hi[w] = a, b, ga, gb
    # the end with the smaller |g| (brentq, too, returns its best point, not the midpoint)
    return np.where(np.abs(g_lo) <= np.abs(g_hi), lo, hi)


def _sign_changes(y: np.ndarray) -> np.ndarray:
    s = np.sign(y)
    return np.nonzero((s[:-1] * s[1:]) < 0)[0]


# ======================================================================================
# the sampled loop
# ======================================================================================
def sos_state_space(sos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C, D) of a cascade in direct form II transposed, with the device's states.

    One section: y = b0 x + s1; s1' = b1 x - a1 y + s2; s2' = b2 x - a2 y.  Identity rows
    are left out (they only add states that stay zero)."""
    A = np.zeros((0, 0))
    B = np.zeros((0, 1))
    C = np.zeros((1, 0))
    D = np.ones((1, 1))
    for row in np.asarray(sos, dtype=float):
        if np.array_equal(row, IDENTITY_ROW):
            continue
        b0, b1, b2, _, a1, a2 = row
        Ai = np.array([[-a1, 1.0], [-a2, 0.0]])
        Bi = np.array([[b1 - a1 * b0], [b2 - a2 * b0]])
        Ci = np.array([[1.0, 0.0]])
        n = A.shape[0]
        # series connection: this section takes the previous output C x + D u
        A = np.block([[A, np.zeros((n, 2))], [Bi @ C, Ai]])
        B = np.vstack([B, Bi @ D])
        C = np.hstack([b0 * C, Ci])
        D = b0 * D
    return A, B, C, D


@dataclass(frozen=True, eq=False)
class SampledLoop:
    """The discretised plant and the device's feedback structure for one mode.

    Plant states x (angles rad, rates rad/s, gyro states), inputs u = [u1, u2] in-oz.
    `measurements(z)` gives the response of the angle and, in inertial mode, of the gyro
    reading and the LOS estimate to each input, at the points z."""

    mode: str
    rate_hz: float
    Ad: np.ndarray
    Bd: np.ndarray
    c_angle: np.ndarray              # (n,) LOS angle theta2 (encoder phi2 with the base at rest)
    outer_loop_gain: float = 0.0     # K_p, 1/s
    alpha: float = 0.0               # complementary filter: tau / (tau + T)
    gyro_state: np.ndarray | None = None   # w_k = gyro_state x_k + gyro_input u_k, read d+1 later
    gyro_input: np.ndarray | None = None
    gyro_delay_samples: int = 0      # d + 1

    @property
    def period(self) -> float:
        return 1.0 / self.rate_hz

    def measurements(self, z: np.ndarray) -> dict[str, np.ndarray]:
        """Each value has shape (len(z), 2): the response to u1 and to u2."""
        z = np.asarray(z, dtype=complex)
        n = self.Ad.shape[0]
        M = z[:, None, None] * np.eye(n) - self.Ad
        X = np.linalg.solve(M, np.broadcast_to(self.Bd, (len(z), n, 2)))
        out = {"angle": np.einsum("i,fij->fj", self.c_angle, X)}
        if self.mode == Setup.INERTIAL:
            w = np.einsum("i,fij->fj", self.gyro_state, X) + self.gyro_input
            gyro = w * z[:, None] ** (-self.gyro_delay_samples)
            a, T = self.alpha, self.period
            out["gyro"] = gyro
            out["estimate"] = (a * T * gyro + (1 - a) * out["angle"]) / (1 - a / z)[:, None]
        return out

    def error_feedback(self, z: np.ndarray, loop: str = "error") -> np.ndarray:
        """P such that e = -P u (reference zero), shape (len(z), 2).

        loop "error": the whole loop; "inner": the rate loop alone (K_p = 0)."""
        return self.error_feedback_from(self.measurements(z), loop)

    def error_feedback_from(self, m: Mapping[str, np.ndarray], loop: str = "error") -> np.ndarray:
        """error_feedback from measurements(z) already computed."""
        if self.mode == Setup.RELATIVE:
            return m["angle"]
        kp = self.outer_loop_gain if loop == "error" else 0.0
        return kp * m["estimate"] + m["gyro"]

    def closed_loop_matrix(self, c0: np.ndarray, c1: np.ndarray, c2: np.ndarray) -> np.ndarray:
        """State matrix of plant + sensors + controller with the reference at zero."""
        return self.closed_loop(c0, c1, c2)[0]

    def closed_loop(self, c0: np.ndarray, c1: np.ndarray, c2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M, m): X_(k+1) = M X_k + m r_k, X = [plant, gyro delay line, complementary
        filter, controller states]; the plant's states come first."""
        n = self.Ad.shape[0]
        inertial = self.mode == Setup.INERTIAL
        nq = self.gyro_delay_samples if inertial else 0
        nh = 1 if inertial else 0
        Ac, Bc, Cc, Dc = _controller(c0, c1, c2)
        nc = Ac.shape[0]
        N = n + nq + nh + nc
        ip, iq, ih, ic = 0, n, n + nq, n + nq + nh
        # the error as a function of the state
        E = np.zeros(N)
        if inertial:
            a, T, kp = self.alpha, self.period, self.outer_loop_gain
            estimate = np.zeros(N)
            estimate[ih] = a
            estimate[iq + nq - 1] += a * T                # the gyro reading is the last delay state
            estimate[ip:ip + n] += (1 - a) * self.c_angle
            E = -kp * estimate
            E[iq + nq - 1] -= 1.0
        else:
            E[ip:ip + n] = -self.c_angle
        U = np.zeros((2, N))
        U[:, ic:] = Cc
        U += Dc @ E[None, :]
        M = np.zeros((N, N))
        M[ip:ip + n, ip:ip + n] = self.Ad
        M[ip:ip + n] += self.Bd @ U
        if inertial:
            M[iq, ip:ip + n] = self.gyro_state
            M[iq] += self.gyro_input @ U
            for k in range(1, nq):
                M[iq + k, iq + k - 1] = 1.0
            M[ih] = estimate
        M[ic:, ic:] += Ac
        M[ic:] += Bc @ E[None, :]
        # the reference enters the error with gain 1 (relative) or K_p (inertial)
        e_r = self.outer_loop_gain if inertial else 1.0
        m = np.zeros(N)
        m[ip:ip + n] = (self.Bd @ Dc)[:, 0] * e_r
        if inertial:
            m[iq] = (self.gyro_input @ Dc)[0] * e_r
        m[ic:] = Bc[:, 0] * e_r
        return M, m


def _controller(c0, c1, c2):
    """(A, B, C, D) of e -> [u1, u2]: C0 feeding C1 and C2."""
    A0, B0, C0, D0 = sos_state_space(c0)
    A1, B1, C1, D1 = sos_state_space(c1)
    A2, B2, C2, D2 = sos_state_space(c2)
    n0, n1, n2 = A0.shape[0], A1.shape[0], A2.shape[0]
    A = np.zeros((n0 + n1 + n2,) * 2)
    A[:n0, :n0] = A0
    A[n0:n0 + n1, :n0] = B1 @ C0
    A[n0:n0 + n1, n0:n0 + n1] = A1
    A[n0 + n1:, :n0] = B2 @ C0
    A[n0 + n1:, n0 + n1:] = A2
    B = np.vstack([B0, B1 @ D0, B2 @ D0])
    C = np.zeros((2, n0 + n1 + n2))
    C[0, :n0], C[0, n0:n0 + n1] = (D1 @ C0)[0], C1[0]
    C[1, :n0], C[1, n0 + n1:] = (D2 @ C0)[0], C2[0]
    D = np.array([[D1[0, 0] * D0[0, 0]], [D2[0, 0] * D0[0, 0]]])
    return A, B, C, D


def sampled_loop(testbed, mode: str, rate_hz: float = CONTROL_RATE_HZ,
                 outer_loop_gain: float = 0.0, crossover_hz: float = 2.0) -> SampledLoop:
    """The ZOH-discretised plant of a testbed, with the sensors the mode feeds back."""
    M = plant_model
    states = [M.TH1, M.W1] + ([M.TH2, M.W2] if testbed.is_2dof else [])
    if mode == Setup.INERTIAL:
        states += [M.GY, M.GYD]
    A, B = M.continuous_model(testbed)
    A, B = A[np.ix_(states, states)], B[np.ix_(states, [0, 1])]
    T = 1.0 / rate_hz
    Ad, Bd = M.discretise(A, B, T)
    c_angle = np.zeros(len(states))
    c_angle[states.index(M.TH2 if testbed.is_2dof else M.TH1)] = 1.0
    if mode == Setup.RELATIVE:
        return SampledLoop(mode, rate_hz, Ad, Bd, c_angle)
    steps = testbed.sensors["gyro_delay"] * rate_hz
    whole = int(math.floor(steps + 1e-9))
    frac = max(steps - whole, 0.0)
    Af, Bf = M.discretise(A, B, (1.0 - frac) * T)
    c_gyro = np.zeros(len(states))
    c_gyro[states.index(M.GY)] = 1.0
    tau = 1.0 / (2 * math.pi * crossover_hz)
    return SampledLoop(mode, rate_hz, Ad, Bd, c_angle, outer_loop_gain=outer_loop_gain,
                       alpha=tau / (tau + T), gyro_state=c_gyro @ Af, gyro_input=c_gyro @ Bf,
                       gyro_delay_samples=whole + 1)


# ======================================================================================
# loop responses for a design and a table
# ======================================================================================
@dataclass(frozen=True, eq=False)
class LoopModel:
    """A design's sampled loop with the cascades of one table (padded rows as sent)."""

    design: ControllerDesign
    loop: SampledLoop
    c0: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    # the plant's and controller's responses on the last large grid: validation asks for
    # the loop broken at three points (error, inner, outer) on the same margin grid
    _grid: dict = field(default_factory=dict, repr=False)

    def controller(self, z: np.ndarray) -> np.ndarray:
        """[e -> u1, e -> u2] at the points z, shape (len(z), 2)."""
        v = sos_response(self.c0, z)
        return np.stack([v * sos_response(self.c1, z), v * sos_response(self.c2, z)], axis=1)

    def _parts(self, z: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """(plant measurements, controller) at z; remembered for one grid of >= 256 points
        (the refinement steps' few points are cheaper to compute than to look up)."""
        if len(z) < 256:
            return self.loop.measurements(z), self.controller(z)
        key = z.tobytes()
        if self._grid.get("key") != key:
            self._grid.clear()
            self._grid.update(key=key, parts=(self.loop.measurements(z), self.controller(z)))
        return self._grid["parts"]

    def response(self, freqs_hz: np.ndarray, loop: str = "error") -> np.ndarray:
        """Loop gain L at freqs_hz.  loop: "error" (broken at e), "inner" (inertial rate
        loop alone, K_p = 0) or "outer" (inertial: broken at the angle error, rate loop
        closed)."""
        z = np.exp(2j * np.pi * np.asarray(freqs_hz, dtype=float) / self.loop.rate_hz)
        if loop == "inner" and self.loop.mode != Setup.INERTIAL:
            raise ValueError("the inner loop exists in inertial mode only")
        if loop not in ("error", "inner") and (loop != "outer" or self.loop.mode != Setup.INERTIAL):
            raise ValueError(f"unknown loop {loop!r} for {self.loop.mode} mode")
        m, C = self._parts(z)
        if loop in ("error", "inner"):
            return np.sum(self.loop.error_feedback_from(m, loop) * C, axis=1)
        inner = np.sum(m["gyro"] * C, axis=1)
        return self.loop.outer_loop_gain * np.sum(m["estimate"] * C, axis=1) / (1 + inner)

    def closed_loop_poles(self) -> np.ndarray:
        return np.linalg.eigvals(self.loop.closed_loop_matrix(self.c0, self.c1, self.c2))


def loop_model(design: ControllerDesign, values: Mapping[str, Any] | None = None,
               dictionary: Dictionary | None = None) -> LoopModel:
    d = dictionary or load_dictionary()
    values = values if values is not None else table_values(design, dictionary=d)
    loop = sampled_loop(design.testbed, design.mode, d.control_rate_hz,
                        outer_loop_gain=float(np.float32(values["outer_loop_gain"])),
                        crossover_hz=float(np.float32(values["complementary_crossover"])))
    c0, c1, c2 = (np.asarray(values[f"{design.mode}_{k}"], dtype=float) for k in ("c0", "c1", "c2"))
    return LoopModel(design, loop, c0, c1, c2)


@dataclass(frozen=True, eq=False)
class Bode:
    freqs_hz: np.ndarray
    response: np.ndarray          # complex L
    margins: Margins

    @property
    def magnitude_db(self) -> np.ndarray:
        return 20 * np.log10(np.abs(self.response))

    @property
    def phase_deg(self) -> np.ndarray:
        return np.degrees(np.unwrap(np.angle(self.response)))


def bode(design: ControllerDesign, values: Mapping[str, Any] | None = None, loop: str = "error",
         points: int = 800) -> Bode:
    """Everything a Bode plot of the loop needs: grid up to Nyquist, L, and its margins."""
    lm = loop_model(design, values)
    nyquist = lm.loop.rate_hz / 2
    f = np.logspace(-2, math.log10(nyquist * 0.999), points)
    return Bode(f, lm.response(f, loop), margins(lambda x: lm.response(x, loop), nyquist))
