"""The allowed range of each function-generator setting as the panel shows it next to the
field, from the instrument's limits table and the testbed's safety limits (no Qt, no I/O).
"""

from __future__ import annotations

from pathlib import Path

from ...instruments import SafetyLimits
from ...instruments import spec4050 as spec


def limit_texts(waveform: str, load: str | None, limits: SafetyLimits | None) -> dict[str, str]:
    """The allowed range of each setting, short enough to sit next to its field: the
    instrument's range for the load from its limits table (`spec4050.LIMITS`, the rows the
    driver checks), then the testbed's safety limit (volts at the amplifier, expressed as
    the setting that gives them).  Keys: frequency, amplitude, offset (with the envelope
    |offset| + amplitude/2 where it applies), phase, points (uploads)."""
    load_known = load if load in spec.LOADS else "50"     # unknown: the one that doubles
    lname = "high-Z" if load_known == "HZ" else "50 ohm"
    unused = "not used by " + waveform

    def where(row: spec.Limit) -> str:
        return f" ({spec.MODEL}, {lname})" if row.depends_on_load else f" ({spec.MODEL})"

    out = {}
    for key in ("frequency", "amplitude", "phase", "points", "offset"):
        row = spec.limit_for(key, waveform)
        out[key] = row.range_text(load_known) + where(row) if row else unused
    envelope = spec.limit_for("envelope", waveform)
    if envelope is not None:                 # amplitude and offset share the output swing
        offset = spec.limit_for("offset", waveform)
        out["offset"] = (f"{offset.range_text(load_known)}; |offset| + amplitude/2 "
                         f"{envelope.range_text(load_known)}{where(envelope)}")
    if limits is not None:
        # a 50 ohm setting puts twice the setting on the amplifier: the setting may be half
        k = 0.5 if load_known == "50" else 1.0
        if spec.limit_for("amplitude", waveform):
            out["amplitude"] += f"\ntestbed: ≤ {limits.max_amplitude_vpp * k:g} Vpp"
        out["offset"] += f"\ntestbed: ±{limits.max_offset_v * k:g} V"
    return out


def limits_source(limits: SafetyLimits | None) -> str:
    """'inertial_2dof.toml' from a SafetyLimits' source ('<path> [limits]')."""
    if limits is None:
        return "no testbed"
    return Path(limits.source.split(" [")[0]).name
