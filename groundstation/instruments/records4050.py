"""What the generator holds, as records: one channel's basic wave, its output state, the
arbitrary waveform selected, and what an upload sent.  Each parses the instrument's reply
(through `spec4050`'s reply formats) and says what cannot be read as an InstrumentError."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import spec4050 as spec
from .fg_errors import InstrumentError


@dataclass(frozen=True)
class BasicWave:
    """One channel's basic-wave settings (None: not applicable to this waveform / unknown)."""

    waveform: str
    frequency_hz: float | None = None
    amplitude_vpp: float | None = None
    offset_v: float | None = None
    phase_deg: float | None = None

    @classmethod
    def parse(cls, reply: str) -> "BasicWave":
        try:
            p = spec.pairs(spec.split_reply(reply, "BSWV"))
            num = {k: spec.parse_number(p[k]) if k in p else None
                   for k in ("FRQ", "AMP", "OFST", "PHSE")}
            return cls(p["WVTP"].upper(), num["FRQ"], num["AMP"], num["OFST"], num["PHSE"])
        except (KeyError, ValueError) as exc:
            raise InstrumentError(f"cannot read the basic-wave reply {reply!r}: {exc}") from None

    def command_pairs(self, previous: "BasicWave | None" = None) -> list[tuple[str, float | str]]:
        """BSWV name,value pairs for this state; AMP before OFST when the amplitude
        shrinks, after it when it grows, so every intermediate state stays in the envelope."""
        values = {"FRQ": self.frequency_hz, "AMP": self.amplitude_vpp,
                  "OFST": self.offset_v, "PHSE": self.phase_deg}
        names = list(spec.WAVE_PARAMETERS[self.waveform])
        grows = (previous is not None and previous.amplitude_vpp is not None
                 and self.amplitude_vpp is not None
                 and self.amplitude_vpp > previous.amplitude_vpp)
        if grows and "AMP" in names and "OFST" in names:
            names.remove("OFST")
            names.insert(names.index("AMP"), "OFST")
        return [("WVTP", self.waveform)] + [(n, values[n]) for n in names]


@dataclass(frozen=True)
class OutputState:
    on: bool
    load: str | None             # "HZ" or "50"; None when the instrument did not say

    @classmethod
    def parse(cls, reply: str) -> "OutputState":
        fields = spec.split_reply(reply, "OUTP")
        try:
            state = fields[0].upper()
            if state not in ("ON", "OFF"):
                raise ValueError(f"state {fields[0]!r}")
            extra = spec.pairs(fields[1:])
            load = spec.normalise_load(extra["LOAD"]) if "LOAD" in extra else None
        except (IndexError, ValueError) as exc:
            raise InstrumentError(f"cannot read the output reply {reply!r}: {exc}") from None
        return cls(state == "ON", load)


@dataclass(frozen=True)
class ArbSelection:
    index: int | None            # built-in waveform index, None for a user waveform
    name: str | None

    @classmethod
    def parse(cls, reply: str) -> "ArbSelection":
        try:
            p = spec.pairs(spec.split_reply(reply, "ARWV"))
            index = int(p["INDEX"]) if "INDEX" in p else None
        except ValueError as exc:
            raise InstrumentError(f"cannot read the arbitrary-wave reply {reply!r}: {exc}") from None
        return cls(index, p.get("NAME"))


@dataclass(frozen=True)
class ArbUpload:
    """What `upload_arbitrary` sent: the waveform plays at `frequency_hz` = 1/period."""

    channel: int
    name: str
    points: int
    frequency_hz: float
    amplitude_vpp: float
    offset_v: float
    codes: np.ndarray            # the int16 samples as sent


__all__ = ["ArbSelection", "ArbUpload", "BasicWave", "OutputState"]
