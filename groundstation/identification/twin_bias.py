"""The linear fit's bias, measured on a twin of the identified rig and taken out.

The plant fit is a linear model, and the bearing is not linear: under a 1 A random
current its Dahl friction sticks near every velocity reversal, which the fit can only
absorb into the flexure, the inertias and an effective damping.  On the twin that
biased J2, k, b and the fine motor's K_t by 0.6-0.7 %, several times the fit's own
95 % interval (which measures the noise, not the model's structure).

The bias is a property of the estimator at the rig's parameters, so it is measured
where it arises: a twin with the identified values (and, when the friction was
identified, the identified friction; else the base file's) is driven in open loop by
the very current each plant log recorded, its responses are estimated on the same grid
and fitted the same way, and what the fit returns on the twin minus what the twin was
made of is the bias.  Taken out of the rig's fit:

    log-scale parameters   p = p_rig · p_twin_made / p_twin_fitted
    offsets (gyro delay)   p = p_rig − (p_twin_fitted − p_twin_made)

The twin's fit has noise of its own (its sensors are as noisy as the rig's), so the
interval widens: the two standard deviations add in quadrature.  This is indirect
inference in its simplest form, one step; it assumes the twin's friction model is
right in kind (the reference's DB-DHM), which is what a lab accepts in using the twin.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from pathlib import Path
from typing import Sequence

import numpy as np

from ..analysis.frf import h1_estimate
from ..analysis.friction_id import write_slope_table
from ..analysis.log_window import profile_span
from ..analysis.plant_fit import (OFFSET_UNITS, PLANT_PARAMETERS, MeasuredResponse,
                                  ParameterEstimate, PlantFit, PlantFitError, fit_plant,
                                  with_values)
from ..core.dictionary import load_dictionary
from ..logs.reader import LogReader
from ..params.table import default_values
from ..plant.testbed import Testbed
from ..sim import core
from ..sim.engine import Engine

Z95 = 1.959964
#: PROFILE_BEGIN targets of the current profiles (protocol/commands.toml)
TARGETS = {"current_coarse": 2, "current_fine": 3}
LOG_SCALE = {p.name for p in PLANT_PARAMETERS if p.log_scale}


def _recorded_current(path: Path, channel: str) -> tuple[np.ndarray, float]:
    """The current the log's profile played (A per control period) and the rate."""
    with LogReader(path) as r:
        d = r.read("HIGH_RATE", [channel, "profile_index"])
        rate = r.tick_rate_hz
    current = np.asarray(d[channel], dtype=np.float64)
    span = profile_span(np.asarray(d["profile_index"]))
    return (current if span is None else current[span[0]:span[1]]), float(rate)


def twin_responses(path: Path, channel: str, outputs: Sequence[tuple[str, str]],
                   twin: Testbed, rate_hz: float, seed: int) -> list[MeasuredResponse]:
    """The twin's responses to the current the log recorded, estimated as the log's.
    `outputs`: (output channel, the model's path) of each response the log gave."""
    current, _ = _recorded_current(path, channel)
    engine = Engine(twin, dict(default_values(load_dictionary())), seed=seed,
                    control_rate_hz=rate_hz)
    engine.fw[core.FW_MODE] = core.MODE_OPEN_LOOP
    engine.fw[core.FW_ARMED] = 1.0
    engine.reset_controllers()
    engine.load_profile(current, TARGETS[channel])
    engine.fw[core.FW_PROF_POS] = 0.0
    engine.fw[core.FW_PROF_ACTIVE] = 1.0
    cols, _, _ = engine.run(current.size + 2)
    span = profile_span(np.asarray(cols["profile_index"]))
    if span is None:
        raise PlantFitError(f"{path.name}: the twin did not play the recorded current")
    x = np.asarray(cols[channel][span[0]:span[1]], dtype=np.float64)
    out = []
    for output, which in outputs:
        y = np.asarray(cols[output][span[0]:span[1]], dtype=np.float64)
        fr = h1_estimate(x, y, rate_hz)
        out.append(MeasuredResponse(which, fr.freq_hz, fr.response, fr.coherence,
                                    fr.segments, f"twin of {path.name}"))
    return out


def _twin(fit: PlantFit, friction_values: dict[str, float],
          slope_table: tuple[np.ndarray, np.ndarray] | None, folder: Path) -> Testbed:
    """The identified rig as a Testbed the engine runs (its table written to `folder`)."""
    tb = with_values(fit.testbed, friction_values)
    if slope_table is not None:
        csv = write_slope_table(folder / "twin_slope_table.csv", *slope_table)
        tb = dataclasses.replace(tb, friction=dict(tb.friction, slope_table=str(csv.resolve())))
    return tb


def _sd(e: ParameterEstimate) -> float:
    """The estimate's standard deviation in the fit's own coordinate (ln, or offset)."""
    lo, hi = e.ci95
    if e.name in LOG_SCALE:
        return math.log(hi / lo) / (2 * Z95)
    return (hi - lo) / (2 * Z95)


def _corrected(rig: ParameterEstimate, made: float, fitted: ParameterEstimate) -> ParameterEstimate:
    sd = math.hypot(_sd(rig), _sd(fitted))
    if rig.name in LOG_SCALE:
        value = rig.value * made / fitted.value
        ci = (value * math.exp(-Z95 * sd), value * math.exp(Z95 * sd))
        bias = f"{100 * (fitted.value / made - 1):+.2f} %"
    else:
        shift = fitted.value - made
        value = rig.value - shift
        ci = (value - Z95 * sd, value + Z95 * sd)
        bias = f"{shift / OFFSET_UNITS.get(rig.name, 1.0):+.3g} ms" if rig.units == "s" \
            else f"{shift:+.3g} {rig.units}"
    return dataclasses.replace(rig, value=value, ci95=ci,
                               reason=f"corrected for the fit's bias on a twin of the "
                                      f"identified rig ({bias})")


def corrected_fit(fit: PlantFit, responses: Sequence, plant_logs: Sequence[tuple[Path, str]],
                  friction_values: dict[str, float],
                  slope_table: tuple[np.ndarray, np.ndarray] | None,
                  seed: int = 1) -> tuple[PlantFit, list[str]]:
    """`fit` with each identified parameter corrected for the bias the same fit shows on
    a twin of the identified rig, and notes saying by how much.  `responses`: the
    log_frf.LogFrf the fit was made from; `plant_logs`: (log, input channel) of each."""
    rate = float(responses[0].measured.rate_hz)
    with tempfile.TemporaryDirectory(prefix="identify-twin-") as tmp:
        twin = _twin(fit, friction_values, slope_table, Path(tmp))
        measured = []
        for i, (path, channel) in enumerate(plant_logs):
            outputs = [(lf.output_channel, lf.model_path) for lf in responses
                       if lf.path == path and lf.input_channel == channel]
            measured += twin_responses(path, channel, outputs, twin, rate, seed + i)
    on_twin = fit_plant(fit.base, measured, sample_rate_hz=rate, band_hz=fit.band_hz,
                        min_coherence=fit.min_coherence)
    params, notes = [], []
    for e in fit.parameters:
        t = on_twin.estimate(e.name)
        made = (float(getattr(twin, e.name.split(".")[0])[e.name.split(".")[1]])
                if e.name in {p.name for p in PLANT_PARAMETERS} else None)
        if e.status == "identified" and t.status == "identified" and made and e.ci95 and t.ci95:
            c = _corrected(e, made, t)
            params.append(c)
            notes.append(f"{e.name}: {c.reason.split('(')[-1].rstrip(')')} bias taken out "
                         f"({e.value:.6g} -> {c.value:.6g} {e.units})")
        else:
            params.append(e)
    tb = with_values(fit.base, {p.name: p.value for p in params
                                if p.status == "identified" and p.name in
                                {q.name for q in PLANT_PARAMETERS}})
    return dataclasses.replace(fit, parameters=tuple(params), testbed=tb), notes


__all__ = ["corrected_fit", "twin_responses"]
