"""The identification in words and as JSON: every parameter with its base value, the
identified value, the 95 % interval and what it came from; the logs and what each was
used for; how well the base and the identified model match the measurements."""

from __future__ import annotations

from typing import Any

from .pipeline import Identification, LogUse


def _value(x: float) -> str:
    return f"{x:.6g}"


def parameter_rows(result: Identification) -> list[dict[str, Any]]:
    return [{"name": p.name, "units": p.units, "base": p.base, "value": p.value,
             "change_pct": (100.0 * (p.value / p.base - 1.0)) if p.base else None,
             "ci95": list(p.ci95) if p.ci95 is not None else None, "status": p.status,
             "reason": p.reason, "sources": list(p.sources)} for p in result.provenance]


def as_json(result: Identification, written_to: str = "") -> dict[str, Any]:
    fit = result.fit
    return {
        "base": str(result.base.path), "written": written_to,
        "band_hz": list(fit.band_hz), "min_coherence": fit.min_coherence,
        "bins_used": fit.bins_used, "reduced_chi_square": fit.reduced_chi_square,
        "rms_magnitude_db": {"identified": fit.rms_magnitude_db, "base": fit.base_rms_magnitude_db},
        "rms_phase_deg": {"identified": fit.rms_phase_deg, "base": fit.base_rms_phase_deg},
        "parameters": parameter_rows(result),
        "logs": [{"path": str(u.path), "used": u.used, "input": u.input_channel,
                  "current_rms_a": u.current_rms_a, "note": u.note,
                  "purpose": u.purpose} for u in result.logs],
        "notes": list(result.notes)}


def log_line(u: LogUse) -> str:
    """What one log was used for, in a line (the text report and the window's notes)."""
    what = ("friction: a position profile" if u.purpose == "friction"
            else f"{u.input_channel}, {u.current_rms_a:.3g} A RMS" if u.input_channel else "")
    return (f"{'used' if u.used else 'not used'}: {u.path.name}" + (f" ({what})" if what else "")
            + (f" - {u.note}" if u.note else ""))


def as_text(result: Identification, written_to: str = "") -> str:
    fit = result.fit
    lines = [f"identified from {sum(u.used for u in result.logs)} of {len(result.logs)} log(s), "
             f"base {result.base.path.name}; {fit.bins_used} bins with coherence >= "
             f"{fit.min_coherence:g} in {fit.band_hz[0]:g}-{fit.band_hz[1]:g} Hz"]
    lines += [f"  {log_line(u)}" for u in result.logs]
    lines.append(f"{'parameter':32s} {'base':>11s} {'identified':>11s} {'change':>8s}  "
                 f"95 % interval")
    for p in result.provenance:
        change = f"{100 * (p.value / p.base - 1):+.2f} %" if p.base else ""
        ci = (f"[{_value(p.ci95[0])}, {_value(p.ci95[1])}]" if p.ci95 is not None else p.status)
        lines.append(f"{p.name:32s} {_value(p.base):>11s} {_value(p.value):>11s} "
                     f"{change:>8s}  {ci} {p.units}")
    lines.append(f"model vs measured, RMS over the used bins: base {fit.base_rms_magnitude_db:.2f} dB"
                 f" / {fit.base_rms_phase_deg:.1f} deg, identified {fit.rms_magnitude_db:.2f} dB / "
                 f"{fit.rms_phase_deg:.1f} deg (reduced chi-square "
                 f"{fit.reduced_chi_square:.2f})")
    lines += [f"note: {n}" for n in result.notes]
    if written_to:
        lines.append(f"written: {written_to}")
    return "\n".join(lines)
