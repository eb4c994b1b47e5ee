"""Linear time responses of a design in the loop the rig runs: u1, u2 and y.

The loop is the validation's sampled loop (loop_response.py): the testbed's plant
discretised for a zero-order hold at the control rate, the discretised cascades of the
table that would be uploaded, and in inertial mode the gyro with its exact 2.6 ms delay,
the complementary filter and K_p.  Here it gets two more inputs, the input disturbances
d1, d2 (torques added to u1, u2 and held over each period like them), and the outputs
y (LOS angle, rad) and u1, u2 (the controller's torques, in-oz).  The responses are
linear: no saturation, no friction beyond b_f.  Comparing their peaks with the motor
limits is the prediction of saturation; the simulator shows what saturation then does.

The input and output rows are derived from the loop's own closed-loop matrix (the plant
rows of M are Ad + Bd U, so U, the torques as a function of the loop state, is the exact
solution of Bd U = M_plant - Ad), so this module cannot drift from validation's loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.kinds import Setup
from .design_file import ControllerDesign

INPUTS = ("d1", "d2")
DEFAULT_DURATION_S = 0.5


class DisturbanceError(ValueError):
    """A disturbance text that cannot be read (names the text and the form expected)."""


@dataclass(frozen=True)
class Disturbance:
    """A torque added to one motor's command: a step, or a sine from t = 0."""

    kind: str                       # "step" | "sine"
    input: int                      # 0: u1 (coarse, where the bearing friction acts), 1: u2
    amplitude_in_oz: float
    frequency_hz: float = 0.0

    def text(self) -> str:
        where = f"u{self.input + 1}"
        if self.kind == "step":
            return f"a {self.amplitude_in_oz:g} in-oz step into {where}"
        return f"a {self.amplitude_in_oz:g} in-oz sine at {self.frequency_hz:g} Hz into {where}"

    def samples(self, t: np.ndarray) -> np.ndarray:
        if self.kind == "step":
            return np.full(t.shape, self.amplitude_in_oz)
        return self.amplitude_in_oz * np.sin(2 * math.pi * self.frequency_hz * t)


_FORM = "step:u1|u2:IN_OZ or sine:u1|u2:IN_OZ:HZ (e.g. step:u1:2.25, sine:u1:2.25:14)"


def parse_disturbance(text: str) -> Disturbance:
    parts = [p.strip() for p in text.split(":")]
    kind = parts[0].lower()
    count = {"step": 3, "sine": 4}.get(kind)
    if count is None or len(parts) != count or parts[1].lower() not in ("u1", "u2"):
        raise DisturbanceError(f"disturbance {text!r}: expected {_FORM}")
    try:
        numbers = [float(p) for p in parts[2:]]
    except ValueError:
        raise DisturbanceError(f"disturbance {text!r}: amplitude and frequency must be numbers; "
                               f"expected {_FORM}") from None
    if not all(math.isfinite(x) for x in numbers) or (kind == "sine" and numbers[1] <= 0):
        raise DisturbanceError(f"disturbance {text!r}: amplitude must be finite and the "
                               f"frequency > 0 Hz")
    return Disturbance(kind, int(parts[1][1]) - 1, numbers[0], numbers[1] if kind == "sine" else 0.0)


def friction_disturbance(testbed) -> Disturbance:
    """The default: the bearing's Coulomb torque T_c as a step into u1, where the friction
    torque enters the outer axis (reference §4)."""
    return Disturbance("step", 0, float(testbed.friction["coulomb_torque"]))


# ======================================================================================
# the sampled loop with disturbance inputs and torque outputs
# ======================================================================================
@dataclass(frozen=True, eq=False)
class LoopSystem:
    """X_(k+1) = M X_k + B w_k,  [y, u1, u2]_k = C X_k + D w_k,  w = [r, d1, d2]."""

    M: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    rate_hz: float

    @property
    def max_pole_radius(self) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(self.M))))


def loop_system(design: ControllerDesign, lm=None, dictionary=None) -> LoopSystem:
    """The design's sampled closed loop (lm: a loop_response.LoopModel, default the
    design's own table over `dictionary`'s defaults) with inputs [r, d1, d2] and outputs
    [y, u1, u2]."""
    from .loop_response import loop_model

    lm = lm if lm is not None else loop_model(design, dictionary=dictionary)
    loop = lm.loop
    M, m = loop.closed_loop(lm.c0, lm.c1, lm.c2)
    n, N = loop.Ad.shape[0], M.shape[0]
    rest = M[:n].copy()
    rest[:, :n] -= loop.Ad
    U = np.linalg.lstsq(loop.Bd, rest, rcond=None)[0]
    u_r = np.linalg.lstsq(loop.Bd, m[:n], rcond=None)[0]
    scale = max(float(np.max(np.abs(rest))), 1e-300)
    if np.max(np.abs(loop.Bd @ U - rest)) > 1e-9 * scale:
        raise ValueError("the loop's plant rows are not Ad + Bd U; loop_response changed shape")
    B = np.zeros((N, 3))
    B[:, 0] = m
    B[:n, 1:] = loop.Bd
    if loop.mode == Setup.INERTIAL:
        B[n, 1:] = loop.gyro_input          # the gyro's first delay state sees u + d too
    C = np.zeros((3, N))
    C[0, :n] = loop.c_angle
    C[1:] = U
    D = np.zeros((3, 3))
    D[1:, 0] = u_r
    return LoopSystem(M, B, C, D, loop.rate_hz)


def simulate(system: LoopSystem, w: np.ndarray) -> np.ndarray:
    """Outputs (len(w), 3, m) for m input sequences w (len(w), 3, m) at once, from rest."""
    M, B, C, D = system.M, system.B, system.C, system.D
    x = np.zeros((M.shape[0], w.shape[2]))
    states = np.empty((len(w), M.shape[0], w.shape[2]))
    Bw = np.einsum("ni,kim->knm", B, w)
    for k in range(len(w)):
        states[k] = x
        x = M @ x + Bw[k]
    return np.einsum("on,knm->kom", C, states) + np.einsum("oi,kim->kom", D, w)


@dataclass(frozen=True, eq=False)
class TimeResponse:
    label: str
    t: np.ndarray                   # s
    y: np.ndarray                   # rad
    u: np.ndarray                   # (n, 2) in-oz

    def peaks(self) -> tuple[float, float]:
        return float(np.max(np.abs(self.u[:, 0]))), float(np.max(np.abs(self.u[:, 1])))


@dataclass(frozen=True)
class SaturationPrediction:
    """Peak |u1|, |u2| of a linear response against the design's saturation limits."""

    label: str
    peaks_in_oz: tuple[float, float]
    limits_in_oz: tuple[float, float]
    first_over_s: tuple[float | None, float | None]    # when each first exceeds its limit
    final_in_oz: tuple[float, float]                   # u1, u2 at the end of the window

    @property
    def saturates(self) -> tuple[bool, bool]:
        return tuple(p > lim for p, lim in zip(self.peaks_in_oz, self.limits_in_oz))

    def lines(self) -> list[str]:
        out = []
        for i, name in enumerate(("u1 (coarse, BLDC)", "u2 (fine, VCM)")):
            peak, lim = self.peaks_in_oz[i], self.limits_in_oz[i]
            verdict = (f"SATURATES (x{peak / lim:.2f}, first at {1e3 * self.first_over_s[i]:.1f} ms)"
                       if self.saturates[i] else f"within ({100 * peak / lim:.0f} % of the limit)")
            out.append(f"{name:<18} peak {peak:8.3g} in-oz, limit {lim:g}: {verdict}; "
                       f"at the end {self.final_in_oz[i]:+.3g}")
        return out


def predict_saturation(design: ControllerDesign, response: TimeResponse) -> SaturationPrediction:
    limits = (design.saturation_coarse_in_oz, design.saturation_fine_in_oz)
    first = []
    for i in range(2):
        over = np.nonzero(np.abs(response.u[:, i]) > limits[i])[0]
        first.append(float(response.t[over[0]]) if len(over) else None)
    return SaturationPrediction(response.label, response.peaks(), limits, tuple(first),
                                (float(response.u[-1, 0]), float(response.u[-1, 1])))


@dataclass(frozen=True, eq=False)
class LinearResponses:
    disturbance: TimeResponse
    step: TimeResponse
    max_pole_radius: float          # > 1: the linear loop grows (the responses show it)


def linear_responses(design: ControllerDesign, disturbance: Disturbance | None = None,
                     step_rad: float = 0.5e-3, duration_s: float = DEFAULT_DURATION_S,
                     lm=None, dictionary=None) -> LinearResponses:
    """The response to `disturbance` (default friction_disturbance) and to a reference
    step of step_rad, each over duration_s from rest (both in one pass)."""
    system = loop_system(design, lm, dictionary)
    dist = disturbance or friction_disturbance(design.testbed)
    t = np.arange(int(round(duration_s * system.rate_hz))) / system.rate_hz
    w = np.zeros((len(t), 3, 2))
    w[:, 1 + dist.input, 0] = dist.samples(t)
    w[:, 0, 1] = step_rad
    out = simulate(system, w)
    out_d, out_r = out[..., 0], out[..., 1]
    return LinearResponses(
        TimeResponse(dist.text(), t, out_d[:, 0], out_d[:, 1:]),
        TimeResponse(f"a {1e3 * step_rad:g} mrad reference step", t, out_r[:, 0], out_r[:, 1:]),
        system.max_pole_radius)
