"""One log's figures as one flat row: the metrics of `analyze_log` and the extra metrics
asked for by name (step, frf, hysteresis, friction_velocity), flattened to the keys of
`groundstation analyze --json/--csv` (ROW_KEYS).

It lives here, not in cli/analysis.py, because the batch task (batch.py) builds the very
same row inside a Dask worker, and the analysis package must not import the CLI (the
package graph has no cycles: tests/test_architecture.py).  The CLI calls these too, so a
row from `analyze LOG --csv` and a row of `analyze FOLDER --table OUT` are one code path.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import GroundStationError
from .log_frf import DEFAULT_MIN_COHERENCE
from .validity import MAX_EXCLUDED_FRACTION

#: every key of a row, in the order of the CSV columns (cli_analysis.ROW_KEYS is this list)
ROW_KEYS = ["log", "path", "test_name", "from_s", "to_s", "frames", "missing_frames", "sensor",
            "samples_used", "samples_excluded", "segments", "integration_period_s", "mean_urad",
            "rms_urad", "std_urad", "highpass_rms_urad", "smear_rms_urad", "energy_coarse_j",
            "energy_fine_j", "energy_total_j", "rms_current_coarse_a", "rms_current_fine_a",
            "saturated_coarse_pct", "saturated_fine_pct", "psd_rms_urad", "psd_resolution_hz",
            "psd_segments", "highpass_samples_used", "highpass_samples_settling",
            "excluded_fraction", "valid", "invalid_reason", "max_excluded_fraction",
            "mode_share", "mode_band_hz", "mode_frequency_hz", "mode_damping", "mode_dominates",
            "mode_band_rule",
            "step_time_s", "step_size_urad", "step_rise_s", "step_overshoot_pct",
            "step_settling_s", "step_steady_state_error_urad", "step_peak_effort",
            "step_effort_channel",
            "frf_input", "frf_output", "frf_coherent_from_hz", "frf_coherent_to_hz",
            "frf_coherent_bins", "frf_rms_db",
            "hyst_branches", "hyst_complete_branches", "hyst_coulomb_in_oz",
            "hyst_turnaround_slope_in_oz_per_rad", "hyst_slope_table", "hyst_slope_table_file",
            "fv_segments", "fv_settled_segments", "fv_speed_deg_s", "fv_torque_pos_in_oz",
            "fv_torque_neg_in_oz", "fv_friction_in_oz", "fv_offset_in_oz", "fv_torque_formula",
            "notes", "error"]

EXTRA_METRICS = ("step", "frf", "hysteresis", "friction_velocity")


def extra_results(path: str | Path, extras: tuple[str, ...], *, start_s: float | None,
                  stop_s: float | None, frf_input: str, frf_output: str, testbed,
                  min_coherence: float = DEFAULT_MIN_COHERENCE) -> dict[str, Any]:
    """{metric: result, or the error message} of the extra metrics of one log."""
    from .log_friction_velocity import friction_velocity_from_log
    from .log_frf import frf_from_log
    from .log_hysteresis import hysteresis_from_log
    from .log_step import step_from_log

    out: dict[str, Any] = {}
    for metric in extras:
        try:
            if metric == "step":
                out[metric] = step_from_log(path, start_s, stop_s)
            elif metric == "frf":
                out[metric] = frf_from_log(path, frf_input, frf_output, start_s, stop_s,
                                           testbed=testbed, min_coherence=min_coherence)
            elif metric == "friction_velocity":
                out[metric] = friction_velocity_from_log(path, start_s, stop_s, testbed=testbed)
            else:
                out[metric] = hysteresis_from_log(path, start_s, stop_s, testbed=testbed)
        except GroundStationError as exc:
            out[metric] = str(exc)
    return out


def finite(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def extra_figures(ex: dict[str, Any], min_coherence: float = DEFAULT_MIN_COHERENCE
                  ) -> tuple[dict[str, Any], list[str], list[str]]:
    """(figures, notes, errors) of a log's extra metrics for its row."""
    row: dict[str, Any] = {}
    notes: list[str] = []
    errors: list[str] = []
    for metric, res in ex.items():
        if metric == "hysteresis_file":
            continue
        if isinstance(res, str):
            errors.append(f"{metric}: {res}")
            continue
        notes += [f"{metric}: {n}" for n in res.notes]
        if metric == "step":
            s = res.metrics
            row.update(step_time_s=res.step_time_s, step_size_urad=res.step_size * 1e6,
                       step_rise_s=finite(s.rise_time_s),
                       step_overshoot_pct=finite(s.overshoot_percent),
                       step_settling_s=finite(s.settling_time_s),
                       step_steady_state_error_urad=finite(s.steady_state_error * 1e6),
                       step_peak_effort=finite(s.peak_effort),
                       step_effort_channel=res.effort_channel or "")
        elif metric == "frf":
            m = res.measured
            coherent = (m.freq_hz > 0) & (np.nan_to_num(m.coherence) >= min_coherence)
            f = m.freq_hz[coherent]
            c = res.comparison
            row.update(frf_input=res.input_channel, frf_output=res.output_channel,
                       frf_coherent_from_hz=float(f.min()) if f.size else None,
                       frf_coherent_to_hz=float(f.max()) if f.size else None,
                       frf_coherent_bins=int(f.size),
                       frf_rms_db=finite(c.rms_magnitude_ratio_db)
                       if c is not None and c.bins_used else None)
        elif metric == "friction_velocity":
            row.update({f"fv_{k}": v for k, v in res.result.summary().items()},
                       fv_torque_formula=res.torque_formula)
        else:
            ident = res.identification
            slopes = np.array([b.turnaround_slope_in_oz_per_rad for b in res.loop.branches])
            slopes = slopes[np.isfinite(slopes)]
            row.update(hyst_branches=len(res.loop.branches),
                       hyst_complete_branches=sum(b.complete for b in res.loop.branches),
                       hyst_coulomb_in_oz=ident.coulomb_torque_in_oz if ident else None,
                       hyst_turnaround_slope_in_oz_per_rad=float(np.median(slopes))
                       if slopes.size else None,
                       hyst_slope_table=ident is not None,
                       hyst_slope_table_file=ex.get("hysteresis_file", ""))
    return row, notes, errors


def log_row(path: str | Path, m, error: str, ex: dict[str, Any],
            min_coherence: float = DEFAULT_MIN_COHERENCE,
            max_excluded_fraction: float = MAX_EXCLUDED_FRACTION) -> dict[str, Any]:
    """The flat row of one log: `m` its LogMetrics (None if not computed), `error` why
    the log could not be analysed, `ex` its extra results; every key of ROW_KEYS.  A
    window with more than `max_excluded_fraction` excluded is `valid` False."""
    if m is None:
        row = dict.fromkeys(ROW_KEYS)
        row.update(log=Path(path).name, path=str(path), error=error, notes="", valid=False,
                   invalid_reason="not analysed: " + (error or "no figures"),
                   max_excluded_fraction=max_excluded_fraction)
    else:
        row = {"path": str(path), **m.row(max_excluded_fraction)}
    figures, notes, errors = extra_figures(ex, min_coherence)
    row.update(figures)
    row["notes"] = "; ".join(([row["notes"]] if row.get("notes") else []) + notes)
    row["error"] = "; ".join(([row["error"]] if row.get("error") else []) + errors)
    return {k: row.get(k) for k in ROW_KEYS}


__all__ = ["EXTRA_METRICS", "ROW_KEYS", "extra_figures", "extra_results", "finite", "log_row"]
