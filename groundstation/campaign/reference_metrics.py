"""Each campaign's own reference metric, per log, beside jitter and energy: what the
reference's procedure (§7) measures with that campaign.  The [analysis] table names them
(`metrics = ["step"]`, the names of `groundstation analyze --metrics`):

    step               step_from_log: rise time, overshoot, settling, steady-state error,
                       peak control effort (relative_steps)
    frf                frf_from_log: H1 and coherence against the testbed model's g1/g2
                       (open_loop_sysid).  The input is the motor current the run excited:
                       current_coarse or current_fine, whichever varies more over the
                       frames the profile plays; the output is encoder_inner, the LOS
                       angle of the relative rig (theta2 = phi2 on a fixed base), so the
                       model is g1 = T1->phi2 or g2 = T2->phi2, per ampere
    hysteresis         hysteresis_from_log: the loop, its turnaround and late slopes, T_c
                       and the DB-DHM slope table (friction_hysteresis_*); the table is
                       written beside the report per log (write_slope_tables)
    friction_velocity  friction_velocity_from_log: running friction per constant-velocity
                       pass (steady_state_friction); across the runs a Coulomb + viscous
                       fit (campaign_summary)

`reference_figures(path, names, start_s, stop_s)` computes them over the row's window
(the one jitter is scored over) and returns flat scalar figures (prefixed step_, frf_,
hyst_, fv_: the CSV's columns), details for the JSON, the results for the figures
(reference_figures.py), and one error text per metric that could not be had - never an
exception.  `row_lines` and `summary_lines` are the text report's words.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import GroundStationError

log = logging.getLogger(__name__)

PACKET = "HIGH_RATE"
#: a frequency-response bin counts at or above this coherence (as `analyze` counts it)
MIN_COHERENCE = 0.9
#: the frequency response's output: the LOS angle of the relative rig (g1, g2 of §4)
FRF_OUTPUT = "encoder_inner"
FRF_CANDIDATES = ("current_coarse", "current_fine")
#: the step trace kept for the figure: from this long before the step ...
STEP_BEFORE_S = 0.05
#: ... to at least this long after it (longer for a slow settling, up to STEP_AFTER_MAX_S)
STEP_AFTER_S = 0.5
STEP_AFTER_MAX_S = 2.0
#: points of a hysteresis loop kept for its figure
LOOP_POINTS = 20000
CHUNK_ROWS = 1 << 16


def _finite(v: Any) -> float | None:
    if v is None or isinstance(v, bool):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


# ---------------------------------------------------------------------- per log
def reference_figures(path: str | Path, names: tuple[str, ...], start_s: float | None = None,
                      stop_s: float | None = None) -> tuple[dict[str, Any], dict[str, Any],
                                                            dict[str, Any], list[str], list[str]]:
    """(flat figures, details for the JSON, results for the figures, notes, errors) of the
    reference metrics `names` of one log over [start_s, stop_s] (s from the log's start)."""
    figures: dict[str, Any] = {}
    details: dict[str, Any] = {}
    data: dict[str, Any] = {}
    notes: list[str] = []
    errors: list[str] = []
    for name in names:
        try:
            fig, det, dat, said = _COMPUTE[name](path, start_s, stop_s)
        except GroundStationError as exc:
            errors.append(f"{name}: {str(exc).strip() or type(exc).__name__}")
            continue
        except Exception as exc:        # a log this code did not foresee: an error, not a crash
            log.exception("%s of %s", name, path)
            errors.append(f"{name}: {type(exc).__name__}: {exc}")
            continue
        figures.update(fig)
        details[name] = det
        data[name] = dat
        notes += [f"{name}: {n}" for n in said]
    return figures, details, data, notes, errors


def add_to_row(row: dict[str, Any], path: str | Path, names: tuple[str, ...]) -> dict[str, Any]:
    """The reference metrics of a campaign-metrics row's log, over its window, added to
    the row (figures, `reference` details, notes, `reference_error`); their results for
    the figures returned."""
    w = row["window"]
    figures, details, data, notes, errors = reference_figures(path, names, w["start_s"], w["stop_s"])
    row["metrics"].update(figures)
    row["reference"] = details
    row["reference_error"] = "; ".join(errors)
    row["notes"] = "; ".join(n for n in [row["notes"], *notes] if n)
    return data


def _step(path, start_s, stop_s):
    from ..analysis.log_step import step_from_log

    st = step_from_log(path, start_s, stop_s)
    m = st.metrics
    settle = _finite(m.settling_time_s)
    after = min(STEP_AFTER_MAX_S, max(STEP_AFTER_S, 1.5 * settle if settle else STEP_AFTER_S))
    trace = _step_trace(path, st.step_time_s - STEP_BEFORE_S, st.step_time_s + after,
                        st.effort_channel)
    figures = {"step_time_s": st.step_time_s, "step_size_urad": st.step_size * 1e6,
               "step_rise_time_s": _finite(m.rise_time_s),
               "step_overshoot_pct": _finite(m.overshoot_percent),
               "step_settling_time_s": settle,
               "step_steady_state_error_urad": _finite(m.steady_state_error * 1e6),
               "step_steady_state_error_pct": _finite(m.steady_state_error_percent),
               "step_peak_effort": _finite(m.peak_effort),
               "step_effort_channel": st.effort_channel or "",
               "step_effort_units": st.effort_units}
    return figures, {"settled": m.settled}, {"result": st, "trace": trace}, list(st.notes)


def _step_trace(path, t0: float, t1: float, effort: str | None) -> dict[str, np.ndarray]:
    """Time (s from the log's start), reference, response (reference - error_angle) and
    effort over [t0, t1], for the overlay."""
    from ..logs import LogReader

    with LogReader(path) as r:
        i0, i1 = r.index_range(PACKET, t0, t1, relative=True)
        cols = ["reference", "error_angle"] + ([effort] if effort else [])
        d = r.read_rows(PACKET, cols, i0, i1)
        origin = r.origin("device")
    ref = np.asarray(d["reference"], dtype=np.float64)
    return {"time_s": np.asarray(d["device_time"], dtype=np.float64) - origin, "reference": ref,
            "response": ref - np.asarray(d["error_angle"], dtype=np.float64),
            "effort": np.asarray(d[effort], dtype=np.float64) if effort else None}


def excited_current(path, start_s, stop_s) -> tuple[str, dict[str, float], str]:
    """(the current channel that varies most, {channel: its RMS about its mean, A}, how
    it was chosen) over the frames that play a profile in the window (all of the window
    if none does); read in chunks."""
    from ..analysis.log_window import MissingChannelError

    from ..logs import LogReader

    with LogReader(path) as r:
        have = {c.name for c in r.channels(PACKET)}
        present = [c for c in FRF_CANDIDATES if c in have]
        if not present:
            raise MissingChannelError(f"{Path(path).name}: the log has neither "
                                      f"{' nor '.join(FRF_CANDIDATES)}: no input for a frequency "
                                      f"response")
        i0, i1 = r.index_range(PACKET, start_s, stop_s, relative=True)
        cols = present + (["profile_index"] if "profile_index" in have else [])
        sums = {c: [0, 0.0, 0.0, None] for c in present}      # n, sum, sum of squares, reference
        everything = {c: [0, 0.0, 0.0, None] for c in present}
        for c0 in range(i0, i1, CHUNK_ROWS):
            d = r.read_rows(PACKET, cols, c0, min(i1, c0 + CHUNK_ROWS), with_time=False)
            playing = d["profile_index"] > 0 if "profile_index" in d else None
            for c in present:
                x = np.asarray(d[c], dtype=np.float64)
                _accumulate(everything[c], x)
                if playing is not None:
                    _accumulate(sums[c], x[playing])
    if not any(s[0] for s in sums.values()):
        sums, where = everything, "the window (no profile plays in it)"
    else:
        where = "the frames that play the profile"
    rms = {c: math.sqrt(max(s[2] / s[0] - (s[1] / s[0]) ** 2, 0.0)) if s[0] else 0.0
           for c, s in sums.items()}
    chosen = max(present, key=lambda c: rms[c])
    others = ", ".join(f"{c} {rms[c]:.3g} A" for c in present if c != chosen)
    how = (f"input {chosen}: it varies most over {where} (RMS {rms[chosen]:.3g} A"
           + (f"; {others}" if others else "") + ")")
    return chosen, rms, how


def _accumulate(acc: list, x: np.ndarray) -> None:
    if not x.size:
        return
    if acc[3] is None:
        acc[3] = float(x[0])
    y = x - acc[3]                      # about the first sample: a large mean does not eat the variance
    acc[0] += x.size
    acc[1] += float(y.sum())
    acc[2] += float((y * y).sum())


def _frf(path, start_s, stop_s):
    from ..analysis.log_frf import frf_from_log

    channel, rms, how = excited_current(path, start_s, stop_s)
    res = frf_from_log(path, channel, FRF_OUTPUT, start_s, stop_s, min_coherence=MIN_COHERENCE)
    m = res.measured
    coh = np.nan_to_num(m.coherence)
    positive = m.freq_hz > 0
    coherent = positive & (coh >= MIN_COHERENCE)
    f = m.freq_hz[coherent]
    band = positive & (m.freq_hz >= f.min()) & (m.freq_hz <= f.max()) if f.size else positive & False
    c = res.comparison
    usable = c is not None and c.bins_used > 0
    figures = {"frf_input": channel, "frf_input_rms_a": rms[channel], "frf_output": FRF_OUTPUT,
               "frf_model": res.model_path, "frf_segments": m.segments,
               "frf_resolution_hz": m.resolution_hz,
               "frf_coherent_from_hz": float(f.min()) if f.size else None,
               "frf_coherent_to_hz": float(f.max()) if f.size else None,
               "frf_coherent_bins": int(f.size),
               # inside the band the coherent bins span: how many of its bins hold
               "frf_band_median_coherence": float(np.median(coh[band])) if band.any() else None,
               "frf_rms_db": _finite(c.rms_magnitude_ratio_db) if usable else None,
               "frf_max_abs_db": _finite(c.max_abs_magnitude_ratio_db) if usable else None,
               "frf_max_abs_phase_deg": _finite(c.max_abs_phase_difference_deg) if usable else None}
    details = {"input_choice": how, "input_rms_a": rms, "model": res.model_description,
               "testbed": res.testbed_source}
    return figures, details, {"result": res}, [how, *res.notes]


def _hysteresis(path, start_s, stop_s):
    from ..analysis.log_hysteresis import hysteresis_from_log

    h = hysteresis_from_log(path, start_s, stop_s)
    loop, ident = h.loop, h.identification
    turn = np.array([b.turnaround_slope_in_oz_per_rad for b in loop.branches])
    late = np.array([b.late_slope_in_oz_per_rad for b in loop.branches])
    turn, late = turn[np.isfinite(turn)], late[np.isfinite(late)]
    figures = {"hyst_branches": len(loop.branches),
               "hyst_complete_branches": sum(b.complete for b in loop.branches),
               "hyst_travel_urad": float(np.ptp(loop.angle_rad)) * 1e6,
               "hyst_torque_swing_in_oz": float(np.ptp(loop.torque_in_oz)),
               "hyst_turnaround_slope_in_oz_per_rad": float(np.median(turn)) if turn.size else None,
               "hyst_late_slope_in_oz_per_rad": float(np.median(late)) if late.size else None,
               "hyst_coulomb_in_oz": ident.coulomb_torque_in_oz if ident else None,
               "hyst_slope_table": ident is not None,
               "hyst_slope_f0": float(ident.f[0]) if ident else None,
               "hyst_slope_identified_points": int(np.count_nonzero(ident.identified)) if ident else None,
               "hyst_slope_grid_points": int(ident.x.size) if ident else None,
               "hyst_slope_monotone_violation": _finite(ident.monotone_violation) if ident else None,
               "hyst_slope_table_file": ""}
    details = {"torque": h.torque_formula, "testbed": h.testbed_source,
               "branches": [{"direction": b.direction, "complete": b.complete,
                             "travel_urad": b.travel_rad * 1e6,
                             "reversal_torque_in_oz": b.reversal_torque_in_oz,
                             "torque_swing_in_oz": b.torque_swing_in_oz,
                             "turnaround_slope_in_oz_per_rad": _finite(b.turnaround_slope_in_oz_per_rad),
                             "late_slope_in_oz_per_rad": _finite(b.late_slope_in_oz_per_rad)}
                            for b in loop.branches]}
    if ident is not None:
        details["slope_table"] = {"sigma_in_oz_per_rad": ident.sigma_in_oz_per_rad,
                                  "coulomb_in_oz": ident.coulomb_torque_in_oz,
                                  "x": ident.x.tolist(), "f": ident.f.tolist(),
                                  "identified": ident.identified.tolist()}
    step = max(1, loop.angle_rad.size // LOOP_POINTS)
    data = {"result": h, "angle_rad": loop.angle_rad[::step], "torque_in_oz": loop.torque_in_oz[::step],
            "testbed_table": _testbed_table(path)}
    return figures, details, data, list(h.notes)


def _log_testbed(path):
    from ..analysis.log_window import testbed_info
    from ..logs import LogReader

    with LogReader(path) as r:
        return testbed_info(r, None)


def _testbed_table(path) -> tuple[np.ndarray, np.ndarray, str] | None:
    """The slope table the log's testbed file names (what the simulator ran), for the
    figure; None when the testbed cannot be loaded or uses no table."""
    from ..plant.slope_table import load_slope_table

    try:
        tb = _log_testbed(path).model
        if tb is None or str(tb.friction.get("model", "")).lower() == "viscous":
            return None
        x, f = load_slope_table(tb.slope_table_path)
    except (GroundStationError, OSError, KeyError):
        return None
    return x, f, tb.slope_table_path.name


def _friction_velocity(path, start_s, stop_s):
    from ..analysis.log_friction_velocity import friction_velocity_from_log

    r = friction_velocity_from_log(path, start_s, stop_s)
    figures = {f"fv_{k}": v for k, v in r.result.summary().items()}
    figures["fv_torque_formula"] = r.torque_formula
    details = {"torque": r.torque_formula,
               "segments": [{"direction": s.direction, "start_s": s.start_s, "stop_s": s.stop_s,
                             "settled_from_s": s.settled_from_s,
                             "velocity_rad_s": s.velocity_rad_s, "speed_deg_s": s.speed_deg_s,
                             "torque_in_oz": s.torque_in_oz, "torque_std_in_oz": s.torque_std_in_oz,
                             "torque_drift_in_oz": s.torque_drift_in_oz,
                             "velocity_spread": s.velocity_spread, "samples": s.samples,
                             "saturated_fraction": s.saturated_fraction, "settled": s.settled}
                            for s in r.result.segments]}
    tbi = _log_testbed(path)
    testbed = None
    tc, bf = tbi.number("friction", "coulomb_torque"), tbi.number("mechanics", "bearing_viscous")
    if tc is not None:
        testbed = {"coulomb_in_oz": tc, "viscous_in_oz_s_per_rad": bf or 0.0, "source": tbi.source}
        details["testbed"] = testbed
    return figures, details, {"result": r, "testbed": testbed}, [*r.notes, *r.result.notes]


_COMPUTE = {"step": _step, "frf": _frf, "hysteresis": _hysteresis,
            "friction_velocity": _friction_velocity}


# ---------------------------------------------------------------------- across logs
def campaign_summary(rows: list[dict[str, Any]], names: tuple[str, ...]) -> dict[str, Any]:
    """What the reference metrics say across the logs: for friction_velocity the
    Coulomb + viscous fit T = T0 + T_c sgn(v) + b v over every settled segment."""
    out: dict[str, Any] = {}
    if "friction_velocity" in names:
        from ..analysis.friction_velocity import FrictionVelocityError, coulomb_viscous_fit

        v, q, logs = [], [], set()
        for r in rows:
            for s in r.get("reference", {}).get("friction_velocity", {}).get("segments", []):
                if s["settled"]:
                    v.append(s["velocity_rad_s"])
                    q.append(s["torque_in_oz"])
                    logs.add(r["file"])
        try:
            fit = coulomb_viscous_fit(v, q)
        except FrictionVelocityError as exc:
            out["friction_velocity"] = {"error": str(exc), "points": 0, "logs": 0}
        else:
            out["friction_velocity"] = {
                "coulomb_in_oz": fit.coulomb_in_oz,
                "viscous_in_oz_s_per_rad": fit.viscous_in_oz_s_per_rad,
                "offset_in_oz": fit.offset_in_oz, "residual_rms_in_oz": fit.residual_rms_in_oz,
                "points": fit.points, "logs": len(logs),
                "speeds_deg_s": sorted({float(f"{abs(x) * 180 / math.pi:.2g}") for x in v})}
            testbeds = [r["reference"]["friction_velocity"]["testbed"] for r in rows
                        if "testbed" in r.get("reference", {}).get("friction_velocity", {})]
            if testbeds:
                out["friction_velocity"]["testbed"] = testbeds[0]
    return out


# ---------------------------------------------------------------------- words
def _ms(v: Any) -> str:
    return "n/a" if _finite(v) is None else f"{v * 1e3:.1f} ms"


def _g(v: Any, unit: str = "", fmt: str = ".4g") -> str:
    return "n/a" if _finite(v) is None else f"{v:{fmt}}" + (f" {unit}" if unit else "")


def row_lines(row: dict[str, Any], names: tuple[str, ...]) -> list[str]:
    """The reference metrics of one row in words (indented for the text report)."""
    m = row["metrics"]
    ref = row.get("reference", {})
    lines = []
    if "step" in ref:
        lines.append(f"    step: {_g(m.get('step_size_urad'), 'urad')} at {_g(m.get('step_time_s'), 's', '.3f')}: "
                     f"rise {_ms(m.get('step_rise_time_s'))}, overshoot {_g(m.get('step_overshoot_pct'), '%', '.1f')}, "
                     f"settling (2 %) " + (_ms(m.get('step_settling_time_s')) if ref['step']['settled']
                                          else "not settled")
                     + f", steady-state error {_g(m.get('step_steady_state_error_urad'), 'urad', '.3g')}"
                     f", peak effort {_g(m.get('step_peak_effort'), m.get('step_effort_units', ''))}"
                     f" ({m.get('step_effort_channel')})")
    if "frf" in ref:
        band = ("no bin" if not m.get("frf_coherent_bins") else
                f"{_g(m.get('frf_coherent_from_hz'), '', '.3g')}-{_g(m.get('frf_coherent_to_hz'), 'Hz', '.3g')} "
                f"({m.get('frf_coherent_bins')} bins)")
        lines.append(f"    frf: {m.get('frf_input')} -> {m.get('frf_output')} (RMS "
                     f"{_g(m.get('frf_input_rms_a'), 'A', '.3g')}): coherence >= {MIN_COHERENCE:g} over "
                     f"{band}, median coherence there {_g(m.get('frf_band_median_coherence'), '', '.3f')}; vs model "
                     f"{m.get('frf_model') or 'n/a'}: RMS {_g(m.get('frf_rms_db'), 'dB', '.2f')}, max "
                     f"{_g(m.get('frf_max_abs_db'), 'dB', '.2f')}, phase max "
                     f"{_g(m.get('frf_max_abs_phase_deg'), 'deg', '.1f')}")
    if "hysteresis" in ref:
        table = ("slope table identified, f(0) " + _g(m.get("hyst_slope_f0"), "", ".3g")
                 + (f", written to {Path(m['hyst_slope_table_file']).name}"
                    if m.get("hyst_slope_table_file") else "")
                 if m.get("hyst_slope_table") else "no slope table")
        lines.append(f"    hysteresis: {m.get('hyst_branches')} branches ({m.get('hyst_complete_branches')} "
                     f"complete) over {_g(m.get('hyst_travel_urad'), 'urad', '.4g')}, torque swing "
                     f"{_g(m.get('hyst_torque_swing_in_oz'), 'in-oz', '.3f')}; T_c "
                     f"{_g(m.get('hyst_coulomb_in_oz'), 'in-oz', '.3f')}; turnaround slope (median) "
                     f"{_g(m.get('hyst_turnaround_slope_in_oz_per_rad'), 'in-oz/rad')}, late "
                     f"{_g(m.get('hyst_late_slope_in_oz_per_rad'), 'in-oz/rad')}; {table}")
    if "friction_velocity" in ref:
        for s in ref["friction_velocity"]["segments"]:
            lines.append(f"    friction_velocity: {'+' if s['direction'] > 0 else '-'}"
                         f"{s['speed_deg_s']:.4g} deg/s: torque {s['torque_in_oz']:+.4g} in-oz "
                         f"(std {s['torque_std_in_oz']:.3g}, drift {s['torque_drift_in_oz']:+.3g})"
                         + ("" if s["settled"] else " not settled"))
        if not m.get("fv_settled_segments"):
            lines.append(f"    friction_velocity: none of the {m.get('fv_segments')} segments settled: "
                         f"no running friction from this log")
        else:
            lines.append(f"    friction_velocity: friction {_g(m.get('fv_friction_in_oz'), 'in-oz')} at "
                         f"{_g(m.get('fv_speed_deg_s'), 'deg/s')} ({m.get('fv_settled_segments')} of "
                         f"{m.get('fv_segments')} segments settled)"
                         + ("" if m.get("fv_offset_in_oz") is None
                            else f", offset {m['fv_offset_in_oz']:+.3g} in-oz"))
    if row.get("reference_error"):
        lines.append(f"    reference metric error: {row['reference_error']}")
    return lines


def summary_lines(summary: dict[str, Any]) -> list[str]:
    lines = []
    fv = summary.get("friction_velocity")
    if fv is not None:
        if fv.get("error"):
            lines.append(f"friction against velocity: no fit ({fv['error']})")
        else:
            viscous = fv["viscous_in_oz_s_per_rad"]
            lines.append(
                f"friction against velocity, {fv['points']} settled segment(s) of {fv['logs']} log(s) "
                f"at {', '.join(f'{s:g}' for s in fv['speeds_deg_s'])} deg/s: T = T0 + T_c sgn(v) + b v "
                f"with T_c {fv['coulomb_in_oz']:.4g} in-oz, b "
                + ("n/a (one speed)" if viscous is None else f"{viscous:.4g} in-oz-s/rad")
                + ("" if fv["offset_in_oz"] is None else f", T0 {fv['offset_in_oz']:+.3g} in-oz")
                + f" (residual RMS {fv['residual_rms_in_oz']:.3g} in-oz)")
            tb = fv.get("testbed")
            if tb:
                lines.append(f"  the testbed file gives T_c {tb['coulomb_in_oz']:.4g} in-oz and a bearing "
                             f"viscous b_f {tb['viscous_in_oz_s_per_rad']:.4g} in-oz-s/rad "
                             f"({tb['source']})")
    return lines


__all__ = ["FRF_OUTPUT", "MIN_COHERENCE", "add_to_row", "campaign_summary", "excited_current",
           "reference_figures", "row_lines", "summary_lines"]
