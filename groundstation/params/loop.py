"""Checks of a controller design in its loop, before the table is sent to the device.

`validate(design)` analyses exactly the coefficients that would be uploaded (the table
`design.table_values(design)` builds, or any complete table) with the discretised plant of
the design's testbed and the device's loop structure (protocol/SPEC.md §10.1; the loop
model, its responses and margins are in loop_response.py): the table's own problems, the
controller's poles, the saturation limits, closed-loop stability, the margins and how far
the discretisation changes the closed loop.  `report_lines` is its report as text.

Closed-loop stability is decided by the eigenvalues of the closed-loop state matrix,
not by the margins.  The responses themselves (Bode, the sampled loop) are in loop_response.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from ..core.kinds import Setup
from ..core.dictionary import Dictionary, load_dictionary
from . import table as ptable
from .tf_algebra import CONTROL_RATE_HZ
from .discretise import (MATCH_BAND_HZ, DiscretisationMatch, discretisation_match,
                         match_frequencies, response_error)
from .design_file import ControllerDesign, table_values
from .loop_response import IDENTITY_ROW, LoopModel, Margins, loop_model, margins

__all__ = ["INSIDE_TOLERANCE", "INTEGRATOR_TOLERANCE", "MATCH_LIMIT_DEG", "MATCH_LIMIT_PCT",
           "MIN_GAIN_MARGIN_DB", "MIN_PHASE_MARGIN_DEG", "STABILITY_MARGIN", "ValidationReport",
           "report_lines", "validate"]

MATCH_LIMIT_PCT = 1.0             # closed-loop discretisation match tolerated without a warning
MATCH_LIMIT_DEG = 1.0
MIN_GAIN_MARGIN_DB = 6.0          # below these the loop is accepted with a warning
MIN_PHASE_MARGIN_DEG = 30.0
STABILITY_MARGIN = 1e-9           # a closed-loop pole must lie within |z| <= 1 - this
INSIDE_TOLERANCE = ptable.POLE_TOLERANCE    # the device's rule for filter poles (SPEC §11.1)
INTEGRATOR_TOLERANCE = 1e-6


# ======================================================================================
# validation
# ======================================================================================
@dataclass
class ValidationReport:
    """What `validate` found.  ok: nothing in `problems` and nothing in `marginal` (the
    table may be sent).  `marginal`: the closed loop is stable but its margins are below
    MIN_GAIN_MARGIN_DB / MIN_PHASE_MARGIN_DEG - refused unless the operator accepts those
    stated margins (clearance.clear_design's accept_risk, recorded); warnings do not refuse.  Figures are None when the analysis could not run (a table
    with non-finite coefficients)."""

    design: str
    mode: str
    testbed: str
    ok: bool
    problems: list[str]
    warnings: list[str] = field(default_factory=list)
    marginal: list[str] = field(default_factory=list)   # stable, margins below the limits
    margins: Margins | None = None                 # loop broken at the error e
    inner_margins: Margins | None = None           # inertial: rate loop alone
    outer_margins: Margins | None = None           # inertial: position loop, rate loop closed
    max_pole_radius: float | None = None           # closed loop
    unstable_poles: list[complex] = field(default_factory=list)
    controller_pole_radius: float | None = None    # largest |z| of a non-integrator controller pole
    match: DiscretisationMatch | None = None
    orders: dict[str, int] = field(default_factory=dict)       # continuous order per cascade
    sections: dict[str, int] = field(default_factory=dict)     # rows used per cascade
    integrators: dict[str, int] = field(default_factory=dict)
    values: dict[str, Any] = field(default_factory=dict)       # the table that was checked


def validate(design: ControllerDesign, values: Mapping[str, Any] | None = None,
             dictionary: Dictionary | None = None) -> ValidationReport:
    """Everything that must hold before the table `values` (default: the design's own,
    over the dictionary defaults) is sent for `design`."""
    d = dictionary or load_dictionary()
    values = dict(values) if values is not None else table_values(design, dictionary=d)
    tb = design.testbed
    report = ValidationReport(design.name, design.mode, tb.name, ok=False, problems=[],
                              values=values,
                              orders={k: tf.order for k, tf in design.cascades.items()},
                              integrators={k: tf.integrators for k, tf in design.cascades.items()})
    problems = report.problems
    problems += [f"table: {p}" for p in ptable.problems(d, values)]
    keys = [f"{design.mode}_{k}" for k in ("c0", "c1", "c2")]
    used = keys + ["outer_loop_gain", "complementary_crossover", "saturation_coarse", "saturation_fine"]
    shapes = {p.name: p.shape for p in d.parameters}
    unusable = [k for k in used if k not in values or np.shape(values[k]) != shapes[k]]
    bad = [k for k in used if k not in unusable and not _all_finite(values[k])]
    for k in bad:
        if not any(p.startswith(f"table: '{k}'") and "not finite" in p for p in problems):
            problems.append(f"{k} has a non-finite value (NaN or infinity)")
    if bad or unusable:           # the table's own problems say what; nothing to analyse
        return report
    cascades = {k[-2:]: np.asarray(values[k], dtype=float) for k in keys}
    report.sections = {k: int(sum(not np.array_equal(r, IDENTITY_ROW) for r in s))
                       for k, s in cascades.items()}
    own = _controller_pole_problems(design, cascades, report)
    for k in keys:                # say it once, in the more specific words below
        if any(p.startswith(f"{k} ") for p in own):
            problems[:] = [p for p in problems if not p.startswith(f"table: '{k}' section")]
    problems += own
    problems += _saturation_problems(values, tb, report.warnings)

    lm = loop_model(design, values, d)
    poles = lm.closed_loop_poles()
    radius = np.abs(poles)
    report.max_pole_radius = float(np.max(radius)) if len(radius) else 0.0
    report.unstable_poles = [complex(p) for p in poles[radius > 1 - STABILITY_MARGIN]]
    if report.unstable_poles:
        problems.append(_instability_text(report.unstable_poles, lm.loop.rate_hz, design))
    nyquist = lm.loop.rate_hz / 2
    report.margins = margins(lambda f: lm.response(f, "error"), nyquist)
    if design.mode == Setup.INERTIAL:
        report.inner_margins = margins(lambda f: lm.response(f, "inner"), nyquist)
        report.outer_margins = margins(lambda f: lm.response(f, "outer"), nyquist)
    if not report.unstable_poles:
        report.marginal += _margin_shortfalls(report.margins)
    report.match = _match(design, lm, cascades)
    cl = report.match.closed_loop
    if not report.unstable_poles and not cl.within(MATCH_LIMIT_PCT, MATCH_LIMIT_DEG):
        report.warnings.append(
            f"the discretised controller changes the closed loop (sensitivity) by up to "
            f"{cl.magnitude_pct:.2f} % at {cl.magnitude_at_hz:.1f} Hz / {cl.phase_deg:.2f} deg at "
            f"{cl.phase_at_hz:.1f} Hz below {MATCH_BAND_HZ:g} Hz (limit {MATCH_LIMIT_PCT:g} % / "
            f"{MATCH_LIMIT_DEG:g} deg): set design.prewarp_hz to the frequency of a lightly damped "
            f"pole or zero of the controller near there")
    report.ok = not problems and not report.marginal
    return report


def _all_finite(v) -> bool:
    try:
        return bool(np.all(np.isfinite(np.asarray(v, dtype=float))))
    except (TypeError, ValueError):
        return False


def _controller_pole_problems(design, cascades: dict[str, np.ndarray], report) -> list[str]:
    """Each pole inside the unit circle, or on z = 1 where the design has an integrator."""
    out, worst = [], 0.0
    for name, sos in cascades.items():
        at_one = 0
        for i, row in enumerate(sos):
            if not np.any(row[4:]):
                continue
            for p in np.roots(row[3:]):
                if abs(p - 1) <= INTEGRATOR_TOLERANCE and abs(p) <= 1 + INSIDE_TOLERANCE:
                    at_one += 1
                elif abs(p) <= 1 - INSIDE_TOLERANCE:
                    worst = max(worst, abs(p))
                else:
                    out.append(f"{design.mode}_{name} section {i}: pole at z = {complex(p):.6g} "
                               f"(|z| = {abs(p):.6f}) is not inside the unit circle: the "
                               f"controller itself is unstable "
                               f"({_continuous_pole_text(p, prewarp_hz=design.prewarp_hz)}) "
                               f"and the device refuses such a table; move that pole of "
                               f"{name} into the left half-plane")
        marked = report.integrators.get(name, 0)
        if at_one > marked:
            out.append(f"{design.mode}_{name} has {at_one} pole(s) at z = 1 but the design marks "
                       f"{marked} integrator(s) (poles at s = 0) in {name}")
    report.controller_pole_radius = worst
    return out


def _continuous_pole_text(p: complex, rate_hz: float = CONTROL_RATE_HZ,
                          prewarp_hz: float | None = None) -> str:
    """The design's own s for a discrete pole: the inverse of the (pre-warped) bilinear
    map the discretisation used, s = 2 fs' (z - 1)/(z + 1), so it reads as the factor in
    the design file."""
    from .discretise import bilinear_rate_hz

    z = complex(p)
    if abs(z + 1) < 1e-12:
        return "s = infinity"
    s = 2 * bilinear_rate_hz(rate_hz, prewarp_hz) * (z - 1) / (z + 1)
    if abs(s.imag) <= 1e-9 * abs(s):
        return f"s = {s.real:+.6g} rad/s"
    return f"s = {s.real:+.6g}{s.imag:+.6g}j rad/s"


def _saturation_problems(values, tb, warnings: list[str]) -> list[str]:
    out = []
    for key, motor, label in (("saturation_coarse", tb.motor_coarse, "coarse (BLDC)"),
                              ("saturation_fine", tb.motor_fine, "fine (VCM)")):
        limit = np.float32(values[key])
        peak = motor["peak_torque"]
        if limit > np.float32(peak):
            out.append(f"{key} = {float(limit):.6g} in-oz exceeds the {label} motor's peak torque "
                       f"{peak:g} in-oz on {tb.name}; lower it to at most {peak:g}")
        elif limit <= 0:
            warnings.append(f"{key} = 0 in-oz: the {label} motor will give no torque")
    return out


def _instability_text(poles: list[complex], rate_hz: float, design) -> str:
    p = max(poles, key=abs)
    head = f"the closed loop is unstable: {len(poles)} pole(s) on or outside the unit circle"
    if abs(p - 1) < 1e-6:
        hint = ("outer_loop_gain = 0 leaves the LOS angle free" if design.mode == Setup.INERTIAL
                else "is the controller's gain zero?")
        return (f"{head}, the largest at z = 1 (0 Hz): an integrator the feedback does not "
                f"act on (the axis' free rotation or a controller integrator); {hint}")
    s = np.log(p) * rate_hz
    f = abs(s.imag) / (2 * math.pi)
    grow = (f"grows by e every {1 / s.real:.3g} s" if s.real > 1e-9 * rate_hz else "does not decay")
    return (f"{head}, the largest |z| = {abs(p):.6f} at {f:.1f} Hz ({grow}); lower the loop "
            f"gain or add phase near {f:.0f} Hz")


def _margin_shortfalls(m: Margins) -> list[str]:
    """The margins of a stable loop below the limits, each as the risk it is."""
    out = []
    if m.gain_margin_db < MIN_GAIN_MARGIN_DB:
        out.append(f"gain margin {m.gain_margin_db:.1f} dB at {m.gain_margin_hz:.1f} Hz is below "
                   f"{MIN_GAIN_MARGIN_DB:g} dB")
    if m.lower_gain_margin_db is not None and m.lower_gain_margin_db < MIN_GAIN_MARGIN_DB:
        out.append(f"lower gain margin {m.lower_gain_margin_db:.1f} dB at {m.lower_gain_margin_hz:.1f} Hz "
                   f"is below {MIN_GAIN_MARGIN_DB:g} dB (the loop goes unstable if its gain drops "
                   f"that much, e.g. in saturation)")
    if m.crossover_hz is not None and m.phase_margin_deg < MIN_PHASE_MARGIN_DEG:
        out.append(f"phase margin {m.phase_margin_deg:.1f} deg at {m.crossover_hz:.1f} Hz is below "
                   f"{MIN_PHASE_MARGIN_DEG:g} deg")
    return out


def _match(design, lm: LoopModel, cascades) -> DiscretisationMatch:
    """Controller match, plus the closed-loop figure: sensitivity 1/(1 + P C) with the
    discrete controller against the same with the continuous one, P the sampled plant as
    the error sees it.  Where |L| is far from 1 a controller error barely reaches the
    closed loop; where the loop is sensitive it does fully."""
    m = discretisation_match(design, cascades, lm.loop.rate_hz)
    f = match_frequencies(m.band_hz)
    z = np.exp(2j * np.pi * f / lm.loop.rate_hz)
    P = lm.loop.error_feedback(z, "error")
    w = 2j * np.pi * f
    c0 = design.c0.response(w)
    C_cont = np.stack([c0 * design.c1.response(w), c0 * design.c2.response(w)], axis=1)
    L_d = np.sum(P * lm.controller(z), axis=1)
    L_c = np.sum(P * C_cont, axis=1)
    return DiscretisationMatch(m.band_hz, m.rate_hz, m.prewarp_hz, m.warp_pct, m.cascades, m.paths,
                               closed_loop=response_error((1 + L_c) / (1 + L_d), f))


def report_lines(design, report) -> list[str]:
    """The validation report as text (also what a log or a dialog can show)."""
    tb = design.testbed
    out = [f"design:   {design.name} ({design.path})",
           f"mode:     {design.mode} on {tb.name} ({tb.path.name})"]
    for note in design.notes:
        out.append(f"note:     {note}")
    for name, tf in design.cascades.items():
        integ = f", {report.integrators[name]} integrator(s)" if report.integrators.get(name) else ""
        rows = report.sections.get(name)
        out.append(f"{name}:       order {tf.order}{integ}, {rows} section(s): {tf.text()}")
    m = report.match
    if m is not None:
        prewarp = f", pre-warped at {m.prewarp_hz:g} Hz" if m.prewarp_hz else ""
        out.append(f"discrete: bilinear at {m.rate_hz:g} Hz{prewarp} (frequency warp "
                   f"{m.warp_pct:.2f} % at {m.band_hz:g} Hz); worst below {m.band_hz:g} Hz:")
        for name, r in {**m.cascades, **m.paths}.items():
            out.append(f"          {name:<6} {r.text()}")
        if m.closed_loop is not None:
            out.append(f"          closed loop (sensitivity) {m.closed_loop.text()}")
    if report.margins is not None:
        out.append(f"margins:  loop broken at e: {report.margins.text()}")
    if report.inner_margins is not None:
        out.append(f"          rate loop alone: {report.inner_margins.text()}")
    if report.outer_margins is not None:
        out.append(f"          position loop (rate loop closed): {report.outer_margins.text()}")
    if report.max_pole_radius is not None:
        out.append(f"poles:    closed-loop max |z| = {report.max_pole_radius:.6f}; controller "
                   f"max |z| = {report.controller_pole_radius:.6f} (integrators at z = 1 aside)")
    for w in report.warnings:
        out.append(f"warning:  {w}")
    if report.ok:
        out.append("OK: the table may be sent")
    elif not report.problems:
        out.append(f"MARGINAL: the closed loop is stable, but {'; '.join(report.marginal)}: refused "
                   f"unless the risk of these margins is accepted with a reason (recorded)")
    else:
        out.append(f"REFUSED: {len(report.problems)} problem(s)")
        out += [f"problem:  {p}" for p in report.problems]
    return out
