"""The testbed's linear plant fitted to measured frequency responses.

Open-loop random excitation of a motor (reference §7) gives H1 estimates from motor
current to the encoders (and, on the inertial rig, to the gyro).  The testbed model
(plant.model, evaluated by analysis.frf.model_response) predicts each of them from the
physical parameters of the testbed file.  This module finds the parameters for which
the model matches the measurements best, with a confidence interval for each.

The fit
-------
Weighted complex least squares (scipy.optimize.least_squares) on the logarithm of the
ratio model/measured, bin by bin: ln|ratio| and arg(ratio) are the two residuals of a
bin.  Both have, for an H1 estimate from n averaged segments with coherence γ², a
standard deviation of about sqrt((1 − γ²) / (2·n·γ²)) (Bendat & Piersol's normalised
random error), so each residual is divided by it: bins the input explains well weigh
much, noisy or friction-dominated bins little, and a perfect model gives a reduced
chi-square near 1.  Only bins with γ² ≥ `min_coherence` inside `band_hz` count.

The parameters are fitted as logarithms of their ratio to the base value (so a factor
of two up or down is the same step, and no value can turn negative); the gyro's delay,
which may be zero, is fitted as an offset in milliseconds.

What the data can and cannot determine
--------------------------------------
- With current-driven motors the measured response is K_t·G(s; J1, J2, k, b, b_f):
  multiplying every torque-side parameter (J1, J2, k, b, b_f and both K_t) by one factor
  leaves every response unchanged.  One of them is therefore held at its datasheet
  value: the coarse motor's torque constant (a torque-motor datasheet value, checked on
  a bench with a torque cell independently of the rig); with no coarse-motor response
  measured, the fine motor's.  Everything else is measured relative to it, and an error
  in it scales J, k, b, b_f alike.
- A parameter no measured response depends on (the gyro's with no gyro response, K_t of
  a motor that was not excited) is held at the base value and said so.
- A parameter whose confidence interval comes out wider than a factor of
  `MAX_RELATIVE_SPREAD` is "not determined by the data": held at the base value, and
  the fit repeated without it.  Nothing is ever invented.

The covariance is (JᵀJ)⁻¹ from the Jacobian at the solution, multiplied by the reduced
chi-square when that is above 1 (the model explains the data less well than the noise
says: the friction the linear model leaves out, mostly), so the intervals widen with
the misfit instead of pretending.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import least_squares

from ..plant.testbed import Testbed
from . import AnalysisError
from .frf import model_response

#: z for a two-sided 95 % interval
Z95 = 1.959963984540054
#: a parameter whose 95 % interval spans more than this factor either way is not determined
MAX_RELATIVE_SPREAD = 2.0
#: coherence is capped below 1 so that a noise-free bin gets a large, finite weight
MAX_COHERENCE = 0.9999
#: how far the fit may move a parameter from its base value (factor either way)
MAX_FACTOR = 10.0
#: how far the gyro delay may move (s either way)
MAX_DELAY_SHIFT_S = 0.01


class PlantFitError(AnalysisError):
    """The measured responses cannot support a fit (the message says why)."""


@dataclass(frozen=True)
class PlantParameter:
    """One physical parameter of the testbed file that the fit may move."""
    section: str
    key: str
    units: str
    log_scale: bool = True           # fitted as ln(value/base); else as an offset (delay)

    @property
    def name(self) -> str:
        return f"{self.section}.{self.key}"


PLANT_PARAMETERS = (
    PlantParameter("mechanics", "J1", "in-oz-s^2"),
    PlantParameter("mechanics", "J2", "in-oz-s^2"),
    PlantParameter("mechanics", "flexure_stiffness", "in-oz/rad"),
    PlantParameter("mechanics", "flexure_damping", "in-oz-s/rad"),
    PlantParameter("mechanics", "bearing_viscous", "in-oz-s/rad"),
    PlantParameter("motor_coarse", "torque_constant", "in-oz/A"),
    PlantParameter("motor_fine", "torque_constant", "in-oz/A"),
    PlantParameter("sensors", "gyro_bandwidth", "Hz"),
    PlantParameter("sensors", "gyro_damping", ""),
    PlantParameter("sensors", "gyro_delay", "s", log_scale=False),
)
#: the bearing's friction, linearised as a spring from the outer axis to the base: not a
#: parameter of the testbed file (the Dahl model's effective stiffness depends on the
#: motion), fitted beside the plant so that it does not bend the plant's values
FRICTION_STIFFNESS = PlantParameter("friction", "linearised_stiffness", "in-oz/rad",
                                    log_scale=False)


@dataclass(frozen=True, eq=False)
class MeasuredResponse:
    """One measured frequency response, per ampere of motor current."""
    which: str                  # the model's 'INPUT->OUTPUT' (analysis.frf.model_response)
    freq_hz: np.ndarray
    response: np.ndarray        # complex H1, output units per ampere
    coherence: np.ndarray       # γ², 0..1
    segments: int               # Welch segments averaged
    source: str                 # where it came from (a log's file name)


@dataclass(frozen=True)
class ParameterEstimate:
    name: str                   # 'mechanics.J1'
    units: str
    base: float
    value: float
    ci95: tuple[float, float] | None     # None when held
    status: str                 # 'identified', 'held (scale)', 'held (no data)', 'held (not determined)'
    reason: str = ""
    sources: tuple[str, ...] = ()

    @property
    def change(self) -> float:
        """value / base - 1 (NaN for a zero base)."""
        return self.value / self.base - 1.0 if self.base else math.nan


@dataclass(frozen=True, eq=False)
class PlantFit:
    parameters: tuple[ParameterEstimate, ...]
    testbed: Testbed                    # the base testbed with the identified values
    base: Testbed
    bins_used: int
    reduced_chi_square: float
    rms_magnitude_db: float             # over the used bins, identified model vs measured
    rms_phase_deg: float
    base_rms_magnitude_db: float        # the same for the base model
    base_rms_phase_deg: float
    band_hz: tuple[float, float]
    min_coherence: float
    messages: tuple[str, ...] = field(default=())

    def estimate(self, name: str) -> ParameterEstimate:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)


ResponseModel = Callable[[Testbed, str, np.ndarray, float], np.ndarray]


def sampled_model(sample_rate_hz: float) -> ResponseModel:
    """The model as a record sampled at `sample_rate_hz` with the current held for a
    period measures it, per ampere, with a linearised friction stiffness
    (analysis.frf.model_response)."""
    def response(tb: Testbed, which: str, freq_hz: np.ndarray, kf: float) -> np.ndarray:
        return model_response(tb, which, freq_hz, sample_rate_hz=sample_rate_hz, per_amp=True,
                              friction_stiffness_in_oz_per_rad=kf)
    return response


def with_values(base: Testbed, values: dict[str, float]) -> Testbed:
    """`base` with the named 'section.key' values replaced (a new Testbed)."""
    sections: dict[str, dict] = {}
    for name, value in values.items():
        section, key = name.split(".", 1)
        sections.setdefault(section, dict(getattr(base, section)))[key] = float(value)
    return dataclasses.replace(base, **sections)


# ------------------------------------------------------------------------------ bins
@dataclass(frozen=True, eq=False)
class _Bins:
    """The used bins of every response, flattened: which response, frequency, measured
    value and the residual's standard deviation."""
    which: tuple[str, ...]
    slices: tuple[slice, ...]
    freq_hz: np.ndarray
    measured: np.ndarray
    sigma: np.ndarray


def _select_bins(measured: Sequence[MeasuredResponse], band_hz: tuple[float, float],
                 min_coherence: float) -> _Bins:
    which, slices, freqs, values, sigmas = [], [], [], [], []
    start = 0
    lo, hi = band_hz
    for m in measured:
        f = np.asarray(m.freq_hz, dtype=float)
        h = np.asarray(m.response, dtype=complex)
        g = np.asarray(m.coherence, dtype=float)
        use = (np.isfinite(h) & (np.abs(h) > 0) & np.isfinite(g) & (g >= min_coherence)
               & (f >= lo) & (f <= hi))
        n = int(np.count_nonzero(use))
        if n == 0:
            continue
        g2 = np.minimum(g[use], MAX_COHERENCE)
        which.append(m.which)
        slices.append(slice(start, start + n))
        start += n
        freqs.append(f[use])
        values.append(h[use])
        sigmas.append(np.sqrt((1.0 - g2) / (2.0 * max(m.segments, 1) * g2)))
    if not which:
        raise PlantFitError(f"no bin of any response has coherence >= {min_coherence:g} "
                            f"between {lo:g} and {hi:g} Hz: the excitation was too weak, or "
                            f"the band misses it (record longer, excite harder, or widen --band)")
    return _Bins(tuple(which), tuple(slices), np.concatenate(freqs), np.concatenate(values),
                 np.concatenate(sigmas))


def _log_ratio(model: ResponseModel, tb: Testbed, kf: float, bins: _Bins) -> np.ndarray:
    """ln(model / measured) on every used bin (complex: ln|ratio| + j·arg(ratio))."""
    out = np.empty(bins.measured.shape, dtype=complex)
    for which, s in zip(bins.which, bins.slices):
        h = model(tb, which, bins.freq_hz[s], kf)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[s] = np.log(h / bins.measured[s])
    return out


# ------------------------------------------------------------------------------ the fit
#: the step of one unit of x for the parameters fitted as offsets (not logarithms)
OFFSET_UNITS = {"sensors.gyro_delay": 1e-3, FRICTION_STIFFNESS.name: 100.0}
#: how far an offset parameter may move, in its own units
OFFSET_LIMITS = {"sensors.gyro_delay": MAX_DELAY_SHIFT_S, FRICTION_STIFFNESS.name: 1e5}


def base_value(base: Testbed, p: PlantParameter) -> float:
    if p is FRICTION_STIFFNESS:
        return 0.0                 # the model's own plant is friction-free (viscous b_f only)
    return float(getattr(base, p.section)[p.key])


class _Problem:
    """The residual function over the free parameters."""

    def __init__(self, base: Testbed, free: list[PlantParameter], bins: _Bins,
                 model: ResponseModel):
        self.base, self.free, self.bins, self.model = base, free, bins, model
        self.base_values = [base_value(base, p) for p in free]

    def values(self, x: np.ndarray) -> dict[str, float]:
        return {p.name: b * math.exp(xi) if p.log_scale else b + xi * OFFSET_UNITS[p.name]
                for p, b, xi in zip(self.free, self.base_values, x)}

    def testbed_and_kf(self, x: np.ndarray) -> tuple[Testbed, float]:
        values = self.values(x)
        kf = values.pop(FRICTION_STIFFNESS.name, 0.0)
        return with_values(self.base, values), kf

    def residuals(self, x: np.ndarray) -> np.ndarray:
        r = _log_ratio(self.model, *self.testbed_and_kf(x), self.bins) / self.bins.sigma
        out = np.concatenate([r.real, r.imag])
        return np.where(np.isfinite(out), out, 1e6)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = [], []
        for p, b in zip(self.free, self.base_values):
            if p.log_scale:
                lo.append(-math.log(MAX_FACTOR))
                hi.append(math.log(MAX_FACTOR))
            else:                  # an offset that cannot take the value below zero
                unit, limit = OFFSET_UNITS[p.name], OFFSET_LIMITS[p.name]
                lo.append(max(-limit, -b) / unit)
                hi.append(limit / unit)
        return np.array(lo), np.array(hi)


def _scale_anchor(bins: _Bins) -> PlantParameter:
    inputs = {w.split("->")[0].strip() for w in bins.which}
    key = "motor_coarse" if "T1" in inputs else "motor_fine"
    return next(p for p in PLANT_PARAMETERS if p.section == key and p.key == "torque_constant")


def _informed(base: Testbed, bins: _Bins, model: ResponseModel,
              candidates: list[PlantParameter]) -> tuple[list[PlantParameter], list[PlantParameter]]:
    """Split `candidates` into those some measured bin depends on, and the rest."""
    probe = _Problem(base, candidates, bins, model)
    r0 = probe.residuals(np.zeros(len(candidates)))
    informed, idle = [], []
    for i, p in enumerate(candidates):
        x = np.zeros(len(candidates))
        x[i] = 0.01 if p.log_scale else 1.0
        change = np.max(np.abs(probe.residuals(x) - r0))
        (informed if change > 1e-6 else idle).append(p)
    return informed, idle


def _solve(problem: _Problem) -> tuple[np.ndarray, np.ndarray, float, bool, str]:
    """(x, covariance, reduced chi-square, converged, message)."""
    lo, hi = problem.bounds()
    # strictly inside the bounds: started on one (a friction stiffness of zero), the
    # trust region takes no step and the solver stops where it began
    margin = 1e-3 * (hi - lo)
    x0 = np.clip(np.zeros(len(problem.free)), lo + margin, hi - margin)
    sol = least_squares(problem.residuals, x0, bounds=(lo, hi), x_scale="jac", method="trf",
                        max_nfev=200 * (len(problem.free) + 1))
    dof = max(sol.fun.size - len(problem.free), 1)
    chi2 = float(np.sum(sol.fun ** 2) / dof)
    cov = np.linalg.pinv(sol.jac.T @ sol.jac) * max(chi2, 1.0)
    return sol.x, cov, chi2, bool(sol.success), str(sol.message)


def _interval(p: PlantParameter, base: float, x: float, sd: float) -> tuple[float, float]:
    if p.log_scale:
        return base * math.exp(x - Z95 * sd), base * math.exp(x + Z95 * sd)
    unit = OFFSET_UNITS[p.name]
    return base + (x - Z95 * sd) * unit, base + (x + Z95 * sd) * unit


#: an offset parameter known no better than this (95 %, either way) is not determined
OFFSET_RESOLUTION = {"sensors.gyro_delay": 0.5e-3, FRICTION_STIFFNESS.name: math.inf}


def _undetermined(p: PlantParameter, sd: float) -> bool:
    if not math.isfinite(sd):
        return True
    if p.log_scale:
        return Z95 * sd > math.log(MAX_RELATIVE_SPREAD)
    return Z95 * sd * OFFSET_UNITS[p.name] > OFFSET_RESOLUTION[p.name]


def _rms(log_ratio: np.ndarray) -> tuple[float, float]:
    ok = np.isfinite(log_ratio)
    if not np.any(ok):
        return math.nan, math.nan
    mag_db = 20.0 / math.log(10.0) * log_ratio.real[ok]
    return (float(np.sqrt(np.mean(mag_db ** 2))),
            float(np.degrees(np.sqrt(np.mean(log_ratio.imag[ok] ** 2)))))


@dataclass
class _Held:
    """Why each parameter that is not fitted is held at its base value."""
    status: dict[str, tuple[str, str]] = field(default_factory=dict)
    messages: list[str] = field(default_factory=list)


def _fit_determined(base: Testbed, free: list[PlantParameter], bins: _Bins,
                    model: ResponseModel, held: _Held):
    """Fit, drop the least determined parameter, fit again, until every one left is
    determined.  Returns (problem, x, standard deviations, reduced chi-square)."""
    while True:
        problem = _Problem(base, free, bins, model)
        x, cov, chi2, converged, message = _solve(problem)
        if not converged:
            raise PlantFitError(f"the fit did not converge ({message}); parameters "
                                f"{', '.join(p.name for p in free)}")
        sds = np.sqrt(np.maximum(np.diag(cov), 0.0))
        loose = [i for i, p in enumerate(free) if _undetermined(p, sds[i])]
        if not loose:
            return problem, x, sds, chi2
        p = free.pop(max(loose, key=lambda i: sds[i]))
        held.status[p.name] = ("held (not determined)",
                               f"the data leave it uncertain by more than a factor "
                               f"{MAX_RELATIVE_SPREAD:g}: held at the base value")
        held.messages.append(f"{p.name}: not determined by these responses, held at the "
                             f"base value")
        if not free:
            raise PlantFitError("no parameter is determined by these responses")


def fit_plant(base: Testbed, measured: Sequence[MeasuredResponse], *,
              sample_rate_hz: float, band_hz: tuple[float, float] = (5.0, 300.0),
              min_coherence: float = 0.9, model: ResponseModel | None = None) -> PlantFit:
    """Fit the plant parameters of `base` to `measured` (see the module docstring)."""
    if not base.is_2dof:
        raise PlantFitError(f"{base.path.name}: the plant fit is written for the 2-DOF testbed "
                            f"(J1, J2, flexure); a 1-DOF rig has J and b_f only")
    model = model or sampled_model(sample_rate_hz)
    bins = _select_bins(measured, band_hz, min_coherence)
    anchor = _scale_anchor(bins)
    held = _Held({anchor.name: ("held (scale)", "every torque-side parameter scales with "
                                                "the motor's torque constant: held at its "
                                                "datasheet value")})
    candidates = [p for p in PLANT_PARAMETERS if p is not anchor] + [FRICTION_STIFFNESS]
    free, idle = _informed(base, bins, model, candidates)
    for p in idle:
        held.status[p.name] = ("held (no data)", "no measured response depends on it")
    problem, x, sds, chi2 = _fit_determined(base, free, bins, model, held)
    identified, kf = problem.testbed_and_kf(x)
    sources = tuple(sorted({m.source for m in measured if m.which in bins.which}))
    estimates = []
    for p in PLANT_PARAMETERS + (FRICTION_STIFFNESS,):
        b = base_value(base, p)
        if p in free:
            i = free.index(p)
            value = kf if p is FRICTION_STIFFNESS else float(getattr(identified, p.section)[p.key])
            estimates.append(ParameterEstimate(p.name, p.units, b, value,
                                               _interval(p, b, x[i], sds[i]), "identified",
                                               "", sources))
        else:
            status, reason = held.status[p.name]
            estimates.append(ParameterEstimate(p.name, p.units, b, b, None, status, reason))
    fit_mag, fit_phase = _rms(_log_ratio(model, identified, kf, bins))
    base_mag, base_phase = _rms(_log_ratio(model, base, 0.0, bins))
    return PlantFit(tuple(estimates), identified, base, int(bins.measured.size), chi2,
                    fit_mag, fit_phase, base_mag, base_phase, tuple(band_hz),
                    float(min_coherence), tuple(held.messages))
