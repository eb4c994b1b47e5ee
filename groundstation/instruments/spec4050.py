"""What the B&K Precision 4050-series generator (4053B) accepts: the one place for its limits,
sample format and reply formats, shared by the pyvisa driver and the simulated instrument.

Sources: `reference/instruments.md` (command family, binary upload with a header of
name/value pairs, "14-bit values are common", "in the order of 16 k" points) and the
4050-series data sheet figures as we read them.  The reference asks for every figure to be
checked against the series programming manual before it is relied on; a correction made
here changes the driver's checks and the simulator's behaviour together.  Figures we could
not confirm are marked VERIFY.

Amplitude and load (the convention both sides implement)
--------------------------------------------------------
The generator has a 50 ohm source impedance.  The amplitude setting AMP is the
peak-to-peak voltage *across the load the instrument is told about* (`C1:OUTP LOAD,...`):

* LOAD = HZ (high impedance): AMP is the open-circuit voltage, i.e. what a high-impedance
  input really sees.
* LOAD = 50: AMP is the voltage across a 50 ohm load, half the open-circuit voltage.  Into
  a high-impedance input the real voltage is therefore 2 x AMP (and the offset doubles too).

The base-stage amplifier input is high impedance (instruments.md), so LOAD = HZ is the
correct setting; the driver's safety check and the simulated stage both use
`volts_at_high_z()` so that a wrongly set load cannot double the stage drive unnoticed.
Changing the load keeps the AMP/OFST *settings* (the simulator does; the real instrument
behaviour is VERIFY), so the driver checks a load change with the current settings.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

MAKER = "B&K Precision"
MODEL = "4053B"
SERIES_PREFIX = "405"                 # *IDN? model field of every 4050-series generator
CHANNELS = (1, 2)

# --- waveforms -----------------------------------------------------------------------------
#: basic waveforms this driver/simulator set (PULSE and NOISE exist on the instrument but
#: carry parameters the base stage has no use for; they are parsed on read, never set)
WAVEFORMS = ("SINE", "SQUARE", "RAMP", "ARB", "DC")
ALL_WAVEFORMS = WAVEFORMS + ("PULSE", "NOISE")
#: which BSWV parameters apply to each waveform (the instrument rejects or ignores others)
WAVE_PARAMETERS = {
    "SINE": ("FRQ", "AMP", "OFST", "PHSE"),
    "SQUARE": ("FRQ", "AMP", "OFST", "PHSE"),
    "RAMP": ("FRQ", "AMP", "OFST", "PHSE"),
    "ARB": ("FRQ", "AMP", "OFST", "PHSE"),
    "DC": ("OFST",),
}

# --- frequency (Hz) --------------------------------------------------------------------------
FREQUENCY_MIN_HZ = 1e-6
FREQUENCY_MAX_HZ = {"SINE": 10e6, "SQUARE": 5e6, "RAMP": 300e3, "ARB": 5e6}   # 4053B; VERIFY

# --- level (V), per load -----------------------------------------------------------------------
LOADS = ("HZ", "50")
AMPLITUDE_MIN_VPP = {"HZ": 0.002, "50": 0.001}
AMPLITUDE_MAX_VPP = {"HZ": 20.0, "50": 10.0}
OFFSET_MAX_V = {"HZ": 10.0, "50": 5.0}           # |offset|
ENVELOPE_MAX_V = {"HZ": 10.0, "50": 5.0}         # |offset| + amplitude / 2
PHASE_MIN_DEG, PHASE_MAX_DEG = 0.0, 360.0

# --- arbitrary waveforms -----------------------------------------------------------------------
ARB_POINTS_MAX = 16384          # user waveform length (16 kpts)
ARB_POINTS_MIN = 2
ARB_SAMPLE_FORMAT = "<h"        # one sample = 16-bit two's complement, little-endian (VERIFY)
ARB_CODE_MIN = -8192            # 14-bit values stored in the 16-bit words (VERIFY: the manual
ARB_CODE_MAX = 8191             # may use offset binary 0..16383; change these three then)
ARB_CODE_FULL_SCALE = 8191      # code that plays +AMP/2 (and -8191 plays -AMP/2)
ARB_NAME_PATTERN = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,15}$")
#: built-in waveforms selectable by `ARWV INDEX,n` (the simulator's small subset; the
#: real instrument has several dozen)
BUILTIN_ARB_NAMES = ("StairUp", "StairDn", "StairUD", "Trapezia", "ExpFal", "ExpRise",
                     "LogFall", "LogRise", "Sinc", "Gaussian")

# --- status -------------------------------------------------------------------------------------
#: IEEE 488.2 standard event status register bits that mean "something went wrong"
ESR_ERROR_BITS = {4: "query error", 8: "device-dependent error", 16: "execution error",
                  32: "command error"}


def volts_at_high_z(volts: float, load: str) -> float:
    """What a setting of `volts` (amplitude or offset) really puts on a high-impedance input."""
    return 2.0 * volts if load == "50" else volts


def normalise_load(text: str | int | float) -> str:
    """'HZ', 'hz', 'INF', 50, '50', '50OHM' -> 'HZ' or '50'; ValueError otherwise."""
    t = str(text).strip().upper().removesuffix("OHM").removesuffix("OHMS")
    if t in ("HZ", "HIGHZ", "HIGH_Z", "INF", "INFINITY"):
        return "HZ"
    try:
        if float(t) == 50.0:
            return "50"
    except ValueError:
        pass
    raise ValueError(f"load must be HZ (high impedance) or 50, not {text!r}")


# --- numbers and replies ---------------------------------------------------------------------------
_NUMBER = re.compile(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z]*)$")
_UNITS = {"": 1.0, "HZ": 1.0, "V": 1.0, "VPP": 1.0, "S": 1.0, "DEG": 1.0}


def parse_number(text: str) -> float:
    """'10HZ', '0.5V', '-1e-3', '90' -> float (units of the reply, no SI prefixes)."""
    m = _NUMBER.match(text.strip())
    if not m or m.group(2).upper() not in _UNITS:
        raise ValueError(f"not a number with a known unit: {text!r}")
    value = float(m.group(1))
    if not math.isfinite(value):
        raise ValueError(f"not a finite number: {text!r}")
    return value


def format_number(value: float) -> str:
    """Shortest text that round-trips a float (what the driver sends)."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def split_reply(reply: str, header: str) -> list[str]:
    """'C1:BSWV WVTP,SINE,FRQ,2HZ' (or without the 'C1:BSWV ' header, which the
    instrument omits when headers are off) -> ['WVTP', 'SINE', 'FRQ', '2HZ']."""
    text = reply.strip()
    m = re.match(r"^(?:C\d:)?" + re.escape(header) + r"\s+", text, re.IGNORECASE)
    if m:
        text = text[m.end():]
    return [p.strip() for p in text.split(",")] if text else []


def pairs(fields: list[str]) -> dict[str, str]:
    """['WVTP', 'SINE', 'FRQ', '2HZ'] -> {'WVTP': 'SINE', 'FRQ': '2HZ'} (names upper-cased)."""
    if len(fields) % 2:
        raise ValueError(f"expected name,value pairs, got {','.join(fields)!r}")
    return {fields[i].upper(): fields[i + 1] for i in range(0, len(fields), 2)}


@dataclass(frozen=True)
class Identity:
    maker: str
    model: str
    serial: str
    firmware: str

    @classmethod
    def parse(cls, reply: str) -> "Identity":
        text = reply.strip()
        if text.upper().startswith("*IDN "):
            text = text[5:]
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != 4:
            raise ValueError(f"*IDN? reply is not maker,model,serial,firmware: {reply!r}")
        return cls(*parts)

    def __str__(self) -> str:
        return f"{self.maker} {self.model} (serial {self.serial}, firmware {self.firmware})"
