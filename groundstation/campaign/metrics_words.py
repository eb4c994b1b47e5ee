"""The campaign metrics in words: matrix values as the tables show them, numbers with
their units, and the sentences that say whether a run is valid, dominated by the loop's
mode, or better or worse than the baseline.  Rows and comparison cells are the dicts
scoring.py and comparison.py make.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from .model import AnalysisSpec


def label(value: Any) -> str:
    """A matrix value as the tables show it: a file by its name without extension."""
    if isinstance(value, str):
        return Path(value).stem or value
    if isinstance(value, float) and value.is_integer():
        return f"{value:g}"
    return str(value)


def describe(variables: dict[str, Any]) -> str:
    shown = {k: v for k, v in variables.items() if not k.endswith("_stem")}
    return ", ".join(f"{k}={label(v)}" for k, v in shown.items())


def group_text(spec: AnalysisSpec, group: str, *, under: bool = False) -> str:
    if not spec.group_by:
        return "" if under else "all runs"
    return f"{'under ' if under else ''}{spec.group_by} {group}"


def csv_variable(key: str, fixed: set[str]) -> str:
    return f"matrix_{key}" if key in fixed else key


def finite(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def num(v: Any) -> str:
    return "n/a" if finite(v) is None else f"{v:.4g}"


def unit(v: Any, name: str) -> str:
    return "n/a" if finite(v) is None else f"{v:.4g} {name}"


def pct(v: Any) -> str:
    return "n/a" if finite(v) is None else f"{v:+.0f} %"


def window_seconds(row: dict[str, Any]) -> float | None:
    m = row["metrics"]
    a, b = finite(m.get("from_s")), finite(m.get("to_s"))
    return None if a is None or b is None else b - a


def seconds(row: dict[str, Any]) -> str:
    w = window_seconds(row)
    return "n/a" if w is None else f"{w:.3g}"


def row_valid(row: dict[str, Any]) -> bool:
    """A row whose window is a measurement: scored without error and `valid` (its
    excluded fraction within the limit)."""
    return not row["error"] and row["metrics"].get("valid") is True


def invalid_reason(row: dict[str, Any]) -> str:
    """Why a row is not valid ('' if it is)."""
    if row["error"]:
        return f"not scored: {row['error']}"
    if row["metrics"].get("valid") is True:
        return ""
    return str(row["metrics"].get("invalid_reason") or "no validity figure")


def mode_text(figures: dict[str, Any]) -> str:
    """'jitter dominated by the loop's mode at 22.8 Hz (82 % of its variance in
    21.7-23.9 Hz)' from a row's figures or a cell ('' without a mode check)."""
    share, band, f = (finite(figures.get("mode_share")), figures.get("mode_band_hz"),
                      finite(figures.get("mode_frequency_hz")))
    if share is None or not band or f is None:
        return ""
    where = f"{share * 100:.0f} % of its variance in {band[0]:.3g}-{band[1]:.3g} Hz"
    if figures.get("mode_dominates"):
        return f"jitter dominated by the loop's lightly damped mode at {f:.3g} Hz ({where})"
    return f"mode check: {where} (the loop's mode at {f:.3g} Hz)"


def mode_sentence(cell: dict[str, Any], where: str) -> str:
    """'inertial_design1 under base_motion BM2: jitter dominated by ... - a limit cycle of
    the loop, not base-motion rejection' ('' when the mode does not dominate)."""
    if not cell.get("mode_dominates"):
        return ""
    return (f"{cell['compare']}" + (f" {where}" if where else "")
            + f": {mode_text(cell)} - a limit cycle of the loop, not base-motion rejection")


def validity_sentence(cell: dict[str, Any], baseline: str, where: str) -> str:
    """'open_loop under base_motion BM2: not valid, 52 % of the window off the
    autocollimator's range ...' for a cell left out of the comparison ('' otherwise)."""
    head = f"{cell['compare']}" + (f" {where}" if where else "")
    if cell["note"] == "no log" or cell["error"]:
        return ""
    if not cell["valid"]:
        return f"{head}: not valid, {cell['invalid_reason']} - not ranked"
    if not cell["baseline"] and cell["baseline_valid"] is False:
        return (f"{head}: no comparison, the baseline {baseline} is not valid "
                f"({cell['baseline_invalid_reason']})")
    return ""


def verdict(cell: dict[str, Any], baseline: str, where: str) -> str:
    """'relative_design2 cuts jitter by 80 % and energy by 97 % vs relative_design1 under
    ref 0.0001' ('' when a figure is missing, or either run is not valid).  Jitter is the
    reference's metric, the high-pass RMS over the integration period; the standard
    deviation (said so) only where the window has no settled high-pass figure."""
    j, e = cell.get("highpass_rms_urad_change_pct"), cell["energy_total_j_change_pct"]
    jitter = "jitter"
    if j is None:
        j, jitter = cell["std_urad_change_pct"], "jitter (std)"
    if j is None or e is None:
        return ""

    def verb(change: float) -> str:
        return "leaves" if round(change) == 0 else "cuts" if change < 0 else "raises"

    def what(change: float, name: str) -> str:
        return f"{name} unchanged (within 1 %)" if round(change) == 0 else f"{name} by {abs(change):.0f} %"
    if verb(j) == verb(e):              # "cuts jitter by 60 % and energy by 95 %"
        words = f"{verb(j)} {what(j, jitter)} and {what(e, 'energy')}"
    else:
        words = f"{verb(j)} {what(j, jitter)} and {verb(e)} {what(e, 'energy')}"
    return f"{cell['compare']} {words} vs {baseline}" + (f" {where}" if where else "")


__all__ = ["csv_variable", "describe", "finite", "group_text", "invalid_reason", "label",
           "mode_sentence", "mode_text", "num", "pct", "row_valid", "seconds", "unit",
           "validity_sentence", "verdict", "window_seconds"]
