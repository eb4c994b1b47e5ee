"""The testbed's own limits on the generator: what the base stage tolerates.

These are the testbed's fact (its file's [limits]: fg_max_amplitude, fg_max_offset), not
the instrument's - the instrument's limits are the table in `spec4050`.  They are volts
at the stage amplifier's high-impedance input, so a setting made into a 50 ohm load
(which puts twice the setting on a high-impedance input) counts double here.
"""

from __future__ import annotations

from dataclasses import dataclass

from . import spec4050 as spec
from .fg_errors import SafetyLimitError


@dataclass(frozen=True)
class SafetyLimits:
    """What the stage tolerates, in volts at the high-impedance amplifier input."""

    max_amplitude_vpp: float
    max_offset_v: float
    source: str                  # where the numbers come from, quoted in every refusal

    @classmethod
    def from_testbed(cls, testbed) -> "SafetyLimits":
        lim = testbed.limits
        return cls(float(lim["fg_max_amplitude"]), float(lim["fg_max_offset"]),
                   f"{testbed.path} [limits]")

    def check(self, channel: int, *, amplitude_vpp: float | None, offset_v: float,
              load: str | None) -> None:
        """Raise SafetyLimitError if the setting puts more on the amplifier than the
        testbed allows.  `amplitude_vpp` is None for a waveform without one (DC); an
        unknown `load` is taken as 50 ohm, the one that doubles the real voltage."""
        load_known = load if load is not None else "50"
        note = ("" if load_known == "HZ" else
                f" (with the load at {'50 ohm' if load else 'an unknown value, taken as 50 ohm'}: "
                f"into the high-impedance amplifier input the real voltage is twice the setting)")
        if amplitude_vpp is not None:
            real = spec.volts_at_high_z(amplitude_vpp, load_known)
            if real > self.max_amplitude_vpp:
                raise SafetyLimitError.on_channel(
                    channel, f"amplitude {real:g} Vpp at the amplifier is above the testbed's "
                    f"safety limit of {self.max_amplitude_vpp:g} Vpp (fg_max_amplitude in "
                    f"{self.source}){note}", setting="amplitude", value=real,
                    limit=self.max_amplitude_vpp, source=self.source)
        real_offset = spec.volts_at_high_z(offset_v, load_known)
        if abs(real_offset) > self.max_offset_v:
            raise SafetyLimitError.on_channel(
                channel, f"offset {real_offset:g} V at the amplifier is beyond the testbed's "
                f"safety limit of +-{self.max_offset_v:g} V (fg_max_offset in {self.source}){note}",
                setting="offset", value=real_offset, limit=self.max_offset_v, source=self.source)


__all__ = ["SafetyLimits"]
