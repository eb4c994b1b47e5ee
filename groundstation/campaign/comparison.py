"""The comparison a campaign asks for: per group (a base motion), each value compared (a
design) with the baseline's log of the same group - the figures, their ratio and their
change in % - and what keeps a cell out of the ranking (no log, not valid, a baseline
without figures, unequal windows).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .metrics_words import (finite, invalid_reason, label, mode_text, num, pct, row_valid,
                            window_seconds)
from .model import AnalysisSpec

#: the figures compared: key in LogMetrics.row() -> (what it is, unit)
COMPARED = {"std_urad": ("jitter (std)", "urad"),
            "highpass_rms_urad": ("jitter (high-pass RMS)", "urad"),
            "energy_total_j": ("control energy", "J")}
#: a window this much shorter than the baseline's makes energies incomparable (said so)
WINDOW_TOLERANCE = 0.05


def compare(rows: list[dict[str, Any]], spec: AnalysisSpec,
            matrix: dict[str, list[Any]]) -> tuple[list[dict[str, Any]], list[str]]:
    """One cell per (group value, compared value): the figures of its log and, relative
    to the baseline's cell of the same group, their ratio and change in %."""
    notes: list[str] = []
    tagged = [r for r in rows if r["run"]]

    def values(key: str) -> list[Any]:
        if key in matrix:
            return list(matrix[key])
        return list(dict.fromkeys(r["variables"].get(key) for r in tagged if key in r["variables"]))

    groups = values(spec.group_by) if spec.group_by else [None]
    compared = values(spec.compare)
    cells: list[dict[str, Any]] = []
    for g in groups:
        members = [r for r in tagged if g is None or r["variables"].get(spec.group_by) == g]
        chosen: dict[int, dict[str, Any] | None] = {}
        for i, c in enumerate(compared):
            mine = [r for r in members if r["variables"].get(spec.compare) == c]
            good = [r for r in mine if not r["error"]]
            # a valid log first: a repeat that clipped must not hide one that measured
            good.sort(key=lambda r: not row_valid(r))
            chosen[i] = good[0] if good else (mine[0] if mine else None)
            if len(mine) > 1:
                notes.append(f"{len(mine)} logs for {spec.compare} = {label(c)}"
                             + (f", {spec.group_by} = {label(g)}" if g is not None else "")
                             + f": the first {'readable ' if good else ''}one is compared")
        base_i = next((i for i, c in enumerate(compared) if c == spec.baseline), None)
        base = chosen.get(base_i) if base_i is not None else None
        for i, c in enumerate(compared):
            cells.append(_cell(chosen[i], base, g, c, i == base_i))
    return cells, notes


def _cell(row: dict[str, Any] | None, base: dict[str, Any] | None, group: Any, value: Any,
          is_baseline: bool) -> dict[str, Any]:
    cell: dict[str, Any] = {"group": label(group) if group is not None else "all",
                            "group_value": group, "compare": label(value), "compare_value": value,
                            "baseline": is_baseline, "run": None, "run_status": "", "log": "",
                            "window_s": None, "error": "", "valid": False, "invalid_reason": "",
                            "excluded_fraction": None, "baseline_valid": None,
                            "baseline_invalid_reason": ""}
    notes: list[str] = []
    if row is None:
        notes.append("no log")
        cell["invalid_reason"] = "no log"
    else:
        cell.update(run=row["run"], run_status=row["run_status"], log=Path(row["file"]).name,
                    window_s=window_seconds(row), error=row["error"], valid=row_valid(row),
                    invalid_reason=invalid_reason(row),
                    excluded_fraction=finite(row["metrics"].get("excluded_fraction")))
    if base is not None:
        cell.update(baseline_valid=row_valid(base), baseline_invalid_reason=invalid_reason(base))
    figures = row["metrics"] if row is not None and not row["error"] else {}
    basefig = base["metrics"] if base is not None and not base["error"] else {}
    # ratios only between two measurements: an invalid run (or baseline) is named, not ranked
    comparable = cell["valid"] and (is_baseline or bool(cell["baseline_valid"]))
    for key in COMPARED:
        v, b = finite(figures.get(key)), finite(basefig.get(key))
        cell[key] = v
        ratio = None
        if comparable and is_baseline and v is not None and v != 0:
            ratio = 1.0
        elif comparable and v is not None and b is not None and b != 0:
            ratio = v / b
        cell[f"{key}_ratio"] = ratio
        cell[f"{key}_change_pct"] = None if ratio is None else (ratio - 1.0) * 100.0
    missing = [what for key, (what, _) in COMPARED.items() if row is not None and not row["error"]
               and cell[key] is None]
    if missing:
        notes.append(f"no {', '.join(missing)} (the log's row says why)")
    if row is not None and not row["error"] and not cell["valid"]:
        notes.append(f"not valid: {cell['invalid_reason']} - not compared")
    elif not is_baseline and row is not None and not row["error"] and base is not None \
            and not base["error"] and not cell["baseline_valid"]:
        notes.append(f"the baseline's run is not valid ({cell['baseline_invalid_reason']}): "
                     f"no ratio")
    if not is_baseline and row is not None and not row["error"]:
        if base is None or base["error"]:
            notes.append("no baseline figures in this group: " + ("the baseline's log could not be "
                                                                   "scored" if base else "no baseline log"))
        else:
            lacking = [what for key, (what, _) in COMPARED.items()
                       if cell[key] is not None and finite(basefig.get(key)) in (None, 0.0)]
            if lacking:
                notes.append(f"the baseline has no (or a zero) {', '.join(lacking)}")
            w, wb = window_seconds(row), window_seconds(base)
            if w is not None and wb is not None and abs(w - wb) > WINDOW_TOLERANCE * max(w, wb):
                notes.append(f"windows differ ({w:.3g} s vs the baseline's {wb:.3g} s): energies "
                             f"are totals over unequal times")
    cell["mode_share"] = finite(figures.get("mode_share"))
    cell["mode_band_hz"] = figures.get("mode_band_hz")
    cell["mode_frequency_hz"] = finite(figures.get("mode_frequency_hz"))
    cell["mode_dominates"] = bool(figures.get("mode_dominates"))
    if cell["mode_dominates"]:
        notes.append(mode_text(cell))
    if row is not None and row["run_status"] not in ("completed", ""):
        notes.append(f"run {row['run']} {row['run_status'].split(':')[0]}")
    cell["note"] = "; ".join(notes)
    return cell


def cell_text(cell: dict[str, Any]) -> str:
    if cell["error"]:
        return f"ERROR {cell['error']}"
    if cell["note"] == "no log":
        return "no log"
    parts = []
    for key, (what, unit) in COMPARED.items():
        s = f"{what} {num(cell[key])}" + (f" {unit}" if cell[key] is not None else "")
        if not cell["baseline"] and cell[f"{key}_change_pct"] is not None:
            s += f" ({pct(cell[f'{key}_change_pct'])})"
        parts.append(s)
    text = ", ".join(parts) + (" (baseline)" if cell["baseline"] else "")
    return text + (f" - {cell['note']}" if cell["note"] else "")


__all__ = ["COMPARED", "WINDOW_TOLERANCE", "cell_text", "compare"]
