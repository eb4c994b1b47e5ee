"""`groundstation params analyze`: one design's PQ numbers gathered, and as text.

`summarize(design)` collects what the command prints - the sampled loop's margins (the
validation's, loop.py), the PQ crossovers, T_I(0), the alignment at chosen frequencies
(with Q = 1 on the same plant for comparison), and the predicted saturation under a
stated input disturbance and a reference step - so tests and scripts read numbers, not
text.  `summary_lines` writes them; with two designs (--against) the alignment table
has a column per design.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..core.kinds import Setup
from .design_file import ControllerDesign
from .pq_design import (DCMatrix, PQAnalysis, analyze, dc_input_sensitivity, frequency_grid,
                        ratio_alignment_deg)
from .pq_response import (DEFAULT_DURATION_S, Disturbance, LinearResponses, SaturationPrediction,
                          friction_disturbance, linear_responses, predict_saturation)
from .tf_algebra import TransferFunction

if TYPE_CHECKING:
    from .loop import ValidationReport

DEFAULT_FREQS_HZ = (1.0, 5.0, 14.0, 22.0)
DEFAULT_STEP_RAD = 0.5e-3


@dataclass(frozen=True, eq=False)
class DesignSummary:
    design: ControllerDesign
    analysis: PQAnalysis                    # on the default grid (for plots)
    freqs_hz: np.ndarray                    # the chosen frequencies
    phi_deg: np.ndarray                     # at freqs_hz
    phi_pq_deg: np.ndarray
    phi_q_one_deg: np.ndarray               # Q = 1 (c1' = c2' = 1) on the same plant
    ti_over_bound: np.ndarray               # ||T_I|| / |T_O| = 1 / cos phi
    pq_crossovers: tuple[tuple[float, float], ...]   # (Hz, angle PQ deg) where |PQ| = 1
    dc: DCMatrix
    validation: ValidationReport            # the margins, as `params validate` finds them
    responses: LinearResponses
    disturbance: Disturbance
    saturation: SaturationPrediction        # under the disturbance
    step_saturation: SaturationPrediction   # under the reference step


def pq_crossovers(a: PQAnalysis) -> tuple[tuple[float, float], ...]:
    """Where |PQ| crosses 1 on the grid, interpolated in log |PQ| over log f."""
    with np.errstate(divide="ignore"):
        log_m = np.log(np.abs(a.pq))
    if not np.all(np.isfinite(log_m)):         # a path unused (c2' = 0) or |PQ| = 0
        return ()
    out = []
    for i in np.nonzero(np.sign(log_m[:-1]) * np.sign(log_m[1:]) < 0)[0]:
        x = log_m[i] / (log_m[i] - log_m[i + 1])
        f = math.exp(math.log(a.freqs_hz[i]) + x * math.log(a.freqs_hz[i + 1] / a.freqs_hz[i]))
        pq = complex(analyze(a.design, np.array([f]), a.sensor).pq[0])
        out.append((f, math.degrees(math.atan2(pq.imag, pq.real))))
    return tuple(out)


def summarize(design: ControllerDesign, freqs_hz=DEFAULT_FREQS_HZ,
              disturbance: Disturbance | None = None, step_rad: float = DEFAULT_STEP_RAD,
              duration_s: float = DEFAULT_DURATION_S, sensor: bool = True,
              dictionary=None) -> DesignSummary:
    """Everything `params analyze` prints for one design.  The margins and the time
    responses use the table the design would upload (over `dictionary`'s defaults)."""
    from ..core.dictionary import load_dictionary
    from .design_file import table_values
    from .loop import validate
    from .loop_response import loop_model

    f = np.asarray(freqs_hz, float)
    grid = analyze(design, frequency_grid(), sensor)
    at = analyze(design, f, sensor)
    one = TransferFunction.constant(1.0)
    dist = disturbance or friction_disturbance(design.testbed)
    d = dictionary or load_dictionary()
    values = table_values(design, dictionary=d)
    lm = loop_model(design, values, d)
    responses = linear_responses(design, dist, step_rad, duration_s, lm=lm)
    return DesignSummary(
        design=design, analysis=grid, freqs_hz=f, phi_deg=at.phi_deg, phi_pq_deg=at.phi_pq_deg,
        phi_q_one_deg=ratio_alignment_deg(design.testbed, one, one, f),
        ti_over_bound=at.functions.ti_norm / at.functions.ti_bound,
        pq_crossovers=pq_crossovers(grid), dc=dc_input_sensitivity(design),
        validation=validate(design, values, d),
        responses=responses, disturbance=dist,
        saturation=predict_saturation(design, responses.disturbance),
        step_saturation=predict_saturation(design, responses.step))


def _design_lines(s: DesignSummary) -> list[str]:
    d, v = s.design, s.validation
    plant = ("LOS rate seen through the gyro (second order, exact delay)" if d.mode == Setup.INERTIAL
             and s.analysis.sensor else "LOS rate" if d.mode == Setup.INERTIAL else "LOS angle")
    out = [f"design:   {d.name} ({d.path.name})",
           f"mode:     {d.mode} on {d.testbed.name}; G = [g1, g2] of the {plant}"]
    if v.margins is not None:
        out.append(f"margins:  sampled loop broken at e: {v.margins.text()}")
    if v.inner_margins is not None:
        out.append(f"          rate loop alone: {v.inner_margins.text()}")
        out.append(f"          position loop (K_p = {d.outer_loop_gain_per_s:g}, rate loop closed): "
                   f"{v.outer_margins.text()}")
    if v.max_pole_radius is not None:
        state = ("stable" if v.max_pole_radius < 1 else
                 "UNSTABLE (validation refuses it; the linear responses below grow)")
        out.append(f"          closed-loop max |z| = {v.max_pole_radius:.6f}: {state}")
    cross = ", ".join(f"{f:.3g} Hz (angle PQ {a:+.0f} deg)" for f, a in s.pq_crossovers)
    if not np.all(np.isfinite(s.analysis.q)):
        out.append("PQ:       c2' = 0: the fine motor is not used, Q = c1'/c2' is infinite")
    else:
        out.append(f"PQ:       |PQ| = 1 at {cross}" if cross else
                   "PQ:       |PQ| does not cross 1 on the grid (0.1 Hz to Nyquist)")
    out.append(f"T_I(0):   {s.dc.text()}  (rows u1, u2; columns d1, d2: from the input "
               f"disturbance d_j to the torque u_i, exact limit s -> 0)")
    return out


def _response_lines(s: DesignSummary) -> list[str]:
    periods = len(s.responses.disturbance.t)
    rate = 1.0 / (s.responses.disturbance.t[1] - s.responses.disturbance.t[0])
    out = [f"{s.design.name}: linear sampled loop from rest, {periods} periods "
           f"({periods / rate:.2f} s at {rate:.0f} Hz), no saturation applied:"]
    out.append(f"  under {s.disturbance.text()}:")
    out += ["    " + line for line in s.saturation.lines()]
    if s.disturbance.kind == "step":
        dc = s.dc.values[:, s.disturbance.input] * -s.disturbance.amplitude_in_oz + 0.0
        out.append(f"    steady state from T_I(0): u1 {dc[0]:+.3g}, u2 {dc[1]:+.3g} in-oz")
    out.append(f"  under {s.responses.step.label}:")
    out += ["    " + line for line in s.step_saturation.lines()]
    return out


def summary_lines(summaries: list[DesignSummary]) -> list[str]:
    """The report of one design, or of several side by side (the alignment table)."""
    out: list[str] = []
    for s in summaries:
        out += _design_lines(s) + [""]
    f = summaries[0].freqs_hz
    head = "".join(f"{x:>9.3g} Hz" for x in f)
    out.append(f"alignment phi (deg; 0 = aligned, 90 = the paths cancel) at {head}")
    rows: list[tuple[str, np.ndarray]] = []
    for i, s in enumerate(summaries):
        tag = f"#{i + 1} " if len(summaries) > 1 else ""
        rows += [(f"{tag}{s.design.name}", s.phi_deg),
                 (f"{tag}  phi_PQ (inputs scaled so |P| = |Q|)", s.phi_pq_deg),
                 (f"{tag}  ||T_I|| / |T_O| = 1 / cos phi", s.ti_over_bound)]
    rows.append(("Q = 1 on the same plant", summaries[0].phi_q_one_deg))
    for label, values in rows:
        out.append(f"  {label:<52.52}" + "".join(f"{x:>12.3g}" for x in values))
    out.append("")
    for s in summaries:
        out += _response_lines(s)
    return out
