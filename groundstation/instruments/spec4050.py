"""What the B&K Precision 4050-series generator (4053B) accepts: the one place for its limits,
sample format and reply formats, shared by the pyvisa driver, the simulated instrument and
the GUI.

The limits are one declarative table, `LIMITS`: a row per quantity and range (key, unit,
range with the load at high impedance and at 50 ohm, the waveforms it applies to, the
field the instrument's command calls it).  `first_violation()` applies it for the driver
and the simulator alike, `Limit.range_text()` words it for messages and the GUI.  The
testbed's own safety limits are not here: they are the testbed's fact (its file's
[limits], `instruments.safety`).

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
_PERIODIC = ("SINE", "SQUARE", "RAMP", "ARB")       # the waveforms with an amplitude

LOADS = ("HZ", "50")
LOAD_NAMES = {"HZ": "high-impedance", "50": "50 ohm"}


# --- the limits table ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Limit:
    """One row of what the instrument accepts: a quantity, its unit, its range with the load
    set to high impedance and to 50 ohm, and the waveforms whose setting it limits.

    `form` says how the range reads (and so how every consumer words it): "between" is
    low .. high, "plus_minus" is a magnitude range +-high (low = -high), "at_most" is a
    ceiling on a quantity that cannot be negative (low = 0)."""

    key: str                         # the setting's name in messages and in the GUI
    unit: str
    high_z: tuple[float, float]      # (lowest, highest) accepted with LOAD HZ
    fifty_ohm: tuple[float, float]   # ... with LOAD 50
    waveforms: tuple[str, ...]
    field: str                       # what the instrument's command calls it
    form: str = "between"
    note: str = ""                   # where the figure comes from / what is unconfirmed

    def bounds(self, load: str) -> tuple[float, float]:
        return self.high_z if load == "HZ" else self.fifty_ohm

    @property
    def depends_on_load(self) -> bool:
        return self.high_z != self.fifty_ohm

    def range_text(self, load: str, *, between: str = " .. ", plus_minus: str = "±",
                   at_most: str = "≤ ") -> str:
        """The one wording of a range - '0.002 .. 20 Vpp', '±10 V', '≤ 10 V' - with the
        symbols each consumer uses (the driver's messages stay ASCII, the GUI does not)."""
        low, high = self.bounds(load)
        if self.form == "plus_minus":
            return f"{plus_minus}{high:g} {self.unit}"
        if self.form == "at_most":
            return f"{at_most}{high:g} {self.unit}"
        return f"{low:g}{between}{high:g} {self.unit}"


_BOTH = lambda low, high: dict(high_z=(low, high), fifty_ohm=(low, high))   # noqa: E731

#: The 4053B's limits, one row per (quantity, range): every check of the driver, every
#: refusal of the simulated instrument and every limit text of the GUI is derived from
#: these rows (tests/instruments/test_fg_limits_table.py holds the three to it).  The order is the
#: order of the checks, so the first refusal named is the same everywhere.
LIMITS: tuple[Limit, ...] = (
    Limit("frequency", "Hz", waveforms=("SINE",), field="FRQ", **_BOTH(1e-6, 10e6),
          note="4053B data sheet; VERIFY"),
    Limit("frequency", "Hz", waveforms=("SQUARE",), field="FRQ", **_BOTH(1e-6, 5e6),
          note="4053B data sheet; VERIFY"),
    Limit("frequency", "Hz", waveforms=("RAMP",), field="FRQ", **_BOTH(1e-6, 300e3),
          note="4053B data sheet; VERIFY"),
    Limit("frequency", "Hz", waveforms=("ARB",), field="FRQ", **_BOTH(1e-6, 5e6),
          note="4053B data sheet; VERIFY"),
    Limit("phase", "deg", waveforms=_PERIODIC, field="PHSE", **_BOTH(0.0, 360.0)),
    # amplitude and offset are settings into the load the instrument is told about: into
    # 50 ohm the 50 ohm source halves what it can put across the load
    Limit("amplitude", "Vpp", waveforms=_PERIODIC, field="AMP",
          high_z=(0.002, 20.0), fifty_ohm=(0.001, 10.0)),
    Limit("offset", "V", waveforms=WAVEFORMS, field="OFST", form="plus_minus",
          high_z=(-10.0, 10.0), fifty_ohm=(-5.0, 5.0)),
    # the output swing as a whole: |offset| + amplitude/2 (HLEV/LLEV) stays inside the rail
    Limit("envelope", "V", waveforms=_PERIODIC, field="|OFST|+AMP/2", form="at_most",
          high_z=(0.0, 10.0), fifty_ohm=(0.0, 5.0)),
    # one period of a user arbitrary waveform (16 kpts; reference: "in the order of 16 k")
    Limit("points", "points", waveforms=("ARB",), field="LENGTH", **_BOTH(2, 16384),
          note="VERIFY against the programming manual"),
)

#: the basic-wave settings: the BSWV fields a waveform takes, in the instrument's order
_BSWV_FIELDS = ("FRQ", "AMP", "OFST", "PHSE")
#: which BSWV parameters apply to each waveform (the instrument rejects or ignores others)
WAVE_PARAMETERS = {w: tuple(f for f in _BSWV_FIELDS
                            if any(row.field == f and w in row.waveforms for row in LIMITS))
                   for w in WAVEFORMS}


def limit_for(key: str, waveform: str) -> Limit | None:
    """The row limiting `key` for `waveform` (None: the setting does not apply to it)."""
    return next((row for row in LIMITS if row.key == key and waveform in row.waveforms), None)


def varies_by_waveform(key: str) -> bool:
    """True when `key` has different ranges for different waveforms (so a message names
    the waveform)."""
    return len({(row.high_z, row.fifty_ohm) for row in LIMITS if row.key == key}) > 1


@dataclass(frozen=True)
class Violation:
    """A value outside its row: what the driver and the simulator each put into words."""

    limit: Limit
    value: float
    load: str
    waveform: str

    @property
    def bound(self) -> float:
        """The end of the range that was passed (the magnitude for plus_minus rows)."""
        low, high = self.limit.bounds(self.load)
        if self.limit.form == "plus_minus":
            return high
        return high if self.value > high else low


def wave_quantities(waveform: str, *, frequency_hz: float | None, amplitude_vpp: float | None,
                    offset_v: float | None, phase_deg: float | None) -> dict[str, float]:
    """The quantities the table limits for one basic-wave state (those that apply to the
    waveform; the envelope computed from amplitude and offset)."""
    given = {"frequency": frequency_hz, "amplitude": amplitude_vpp, "offset": offset_v,
             "phase": phase_deg}
    out = {k: v for k, v in given.items() if v is not None and limit_for(k, waveform)}
    if limit_for("envelope", waveform) and "offset" in out:
        out["envelope"] = abs(out["offset"]) + out.get("amplitude", 0.0) / 2
    return out


def first_violation(waveform: str, load: str, quantities: dict[str, float]) -> Violation | None:
    """The first row (in table order) that a value in `quantities` falls outside, for
    `waveform` into `load`; None when every value is accepted.  A NaN is outside every
    range.  Quantities without a row for the waveform are not the table's business."""
    for row in LIMITS:
        if row.key not in quantities or waveform not in row.waveforms:
            continue
        value = quantities[row.key]
        low, high = row.bounds(load)
        if not low <= value <= high:
            return Violation(row, value, load, waveform)
    return None


def _row(key: str, waveform: str) -> Limit:
    row = limit_for(key, waveform)
    assert row is not None, (key, waveform)
    return row


# The figures by name, derived from the table (for callers that need one number: campaign
# file checks, profile synthesis); the table stays the one place they are written.
FREQUENCY_MIN_HZ = _row("frequency", "SINE").high_z[0]
FREQUENCY_MAX_HZ = {w: _row("frequency", w).high_z[1] for w in WAVEFORMS if limit_for("frequency", w)}
AMPLITUDE_MIN_VPP = {load: _row("amplitude", "SINE").bounds(load)[0] for load in LOADS}
AMPLITUDE_MAX_VPP = {load: _row("amplitude", "SINE").bounds(load)[1] for load in LOADS}
OFFSET_MAX_V = {load: _row("offset", "DC").bounds(load)[1] for load in LOADS}          # |offset|
ENVELOPE_MAX_V = {load: _row("envelope", "SINE").bounds(load)[1] for load in LOADS}
PHASE_MIN_DEG, PHASE_MAX_DEG = _row("phase", "SINE").high_z
ARB_POINTS_MIN, ARB_POINTS_MAX = (int(b) for b in _row("points", "ARB").high_z)

# --- arbitrary waveforms -----------------------------------------------------------------------
ARB_SAMPLE_FORMAT = "<h"        # one sample = 16-bit two's complement, little-endian (VERIFY)
ARB_CODE_MIN = -8192            # 14-bit values stored in the 16-bit words (VERIFY: the manual
ARB_CODE_MAX = 8191             # may use offset binary 0..16383; change these three then)
ARB_CODE_FULL_SCALE = 8191      # code that plays +AMP/2 (and -8191 plays -AMP/2)
ARB_NAME_PATTERN = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,15}$")


def arb_name_for(text: str) -> str:
    """A stored-waveform name the instrument takes, made from any text (a profile's name):
    other characters become '_', a name not starting with a letter gets 'BM_' before it,
    and it is cut to 16 characters (ARB_NAME_PATTERN)."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", text)
    if not name or not name[0].isalpha():
        name = "BM_" + name
    return name[:16]
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
