"""The simulated B&K 4053B function generator as an instrument: its channels, settings
checked against `groundstation.instruments.spec4050.LIMITS`, error queue, arbitrary-waveform
upload and the output voltage that drives the simulated base stage (`base_drive`).  No I/O:
`scpi_server.ScpiServer` serves it on TCP.

SCPI subset (channel prefix C1: or C2:, case-insensitive, several commands per line
separated by ';'):

    *IDN?  *CLS  *RST  *OPC  *OPC?  *ESR?  SYST:ERR? (SYSTEM:ERROR?)
    Cn:BSWV WVTP,<SINE|SQUARE|RAMP|ARB|DC>,FRQ,<Hz>,PERI,<s>,AMP,<Vpp>,OFST,<V>,PHSE,<deg>
    Cn:BSWV?      -> Cn:BSWV WVTP,SINE,FRQ,2HZ,PERI,0.5S,AMP,0.5V,OFST,0V,HLEV,0.25V,LLEV,-0.25V,PHSE,0
    Cn:OUTP ON|OFF[,LOAD,<HZ|50>]   (or LOAD,<HZ|50> alone)
    Cn:OUTP?      -> Cn:OUTP ON,LOAD,HZ,PLRT,NOR
    Cn:ARWV INDEX,<n> | NAME,<name>
    Cn:ARWV?      -> Cn:ARWV INDEX,2,NAME,StairUD   (built-in) | Cn:ARWV NAME,BM1 (user)
    Cn:WVDT WVNM,<name>,LENGTH,<bytes>B,FREQ,<Hz>,AMPL,<Vpp>,OFST,<V>,PHASE,<deg>,WAVEDATA,<raw>
                  raw = LENGTH bytes of int16 little-endian samples (framed by LENGTH, so
                  the data may contain the terminator byte); LENGTH also accepts <n>KB

Errors go to the error queue (SCPI numbers and texts, 20 deep, -350 on overflow) and set
the standard event status bits (-1xx CME 32, -2xx EXE 16, -3xx DDE 8, -4xx QYE 4); a
command in error changes nothing (a BSWV's pairs are checked together, then applied).
Limits and formats come from `groundstation.instruments.spec4050`: its limits table is
the one the driver checks against, so both refuse the same values with the same numbers.

Output model (deterministic: time is the device's tick, never the wall clock):
* phase accumulates from a reference tick; a frequency change keeps the phase
  continuous; a waveform change, an arbitrary-waveform selection and switching the
  output on restart the waveform at PHSE on the next control period (so an uploaded
  base-motion profile plays from its first sample when the output goes on);
* SINE; SQUARE (50 % duty); RAMP as a symmetric triangle (the instrument's default 50 %
  symmetry), in phase with SINE; DC = offset; ARB = sample-and-hold of the stored codes
  (code 8191 plays +AMP/2), one period per 1/FRQ;
* amplitude and offset are settings *into the set load*; the base-stage amplifier input
  is high impedance, so with LOAD 50 the stage sees twice the setting
  (`spec4050.volts_at_high_z`); output off -> 0 V.
"""

from __future__ import annotations

import logging
import math
import re
import threading
from collections import deque
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ..core.dictionary import default_control_rate_hz
from ..instruments import spec4050 as spec

log = logging.getLogger(__name__)

ERROR_QUEUE_DEPTH = 20

_ALIASES = {"BSWV": "BSWV", "BASIC_WAVE": "BSWV", "OUTP": "OUTP", "OUTPUT": "OUTP",
            "ARWV": "ARWV", "ARBWAVE": "ARWV", "WVDT": "WVDT", "WAVEDATA": "WVDT"}


class ScpiError(Exception):
    def __init__(self, code: int, text: str):
        super().__init__(f"{code},\"{text}\"")
        self.code = code
        self.text = text


@dataclass
class _Channel:
    waveform: str = "SINE"                 # power-on defaults of the series: 1 kHz, 4 Vpp
    frequency_hz: float = 1000.0
    amplitude_vpp: float = 4.0
    offset_v: float = 0.0
    phase_deg: float = 0.0
    on: bool = False
    load: str = "HZ"
    arb_index: int | None = 0              # built-in index, or None for a user waveform
    arb_name: str = spec.BUILTIN_ARB_NAMES[0]
    ref_tick: int = 0                      # the phase is ref_cycles at ref_tick
    ref_cycles: float = 0.0

    def cycles_at(self, tick: int, rate_hz: float) -> float:
        return self.ref_cycles + self.frequency_hz * (tick - self.ref_tick) / rate_hz


@dataclass(frozen=True)
class UserWave:
    name: str
    codes: np.ndarray                     # int16
    frequency_hz: float | None
    amplitude_vpp: float | None
    offset_v: float | None
    phase_deg: float | None


def _builtin_shape(index: int, n: int = 1024) -> np.ndarray:
    """A few of the instrument's built-in arbitrary shapes, normalised to [-1, 1]."""
    x = np.arange(n) / n
    name = spec.BUILTIN_ARB_NAMES[index]
    shapes = {
        "StairUp": np.floor(x * 8) / 7 * 2 - 1,
        "StairDn": 1 - np.floor(x * 8) / 7 * 2,
        "StairUD": 1 - np.abs(np.floor(x * 8) / 3.5 - 1) * 2 + 0.0,
        "Trapezia": np.clip(3 - np.abs(x - 0.5) * 8, -1, 1),
        "ExpFal": np.exp(-5 * x) * 2 - 1,
        "ExpRise": (1 - np.exp(-5 * x)) * 2 - 1,
        "LogFall": 1 - np.log1p(x * 9) / math.log(10) * 2,
        "LogRise": np.log1p(x * 9) / math.log(10) * 2 - 1,
        "Sinc": np.sinc((x - 0.5) * 20),
        "Gaussian": np.exp(-((x - 0.5) / 0.1) ** 2) * 2 - 1,
    }
    shape = np.clip(shapes[name], -1.0, 1.0)
    return np.round(shape * spec.ARB_CODE_FULL_SCALE).astype(np.int16)


class SimulatedGenerator:
    """The instrument: state, SCPI interpreter and output voltages.  No I/O; thread-safe
    (the SCPI server thread and the device's tick loop share one lock)."""

    def __init__(self, *, tick_source: Callable[[], int] | None = None,
                 control_rate_hz: float | None = None, base_channel: int = 1,
                 serial: str = "SIM0000001", firmware: str = "sim-1.0"):
        if base_channel not in spec.CHANNELS:
            raise ValueError(f"base_channel must be one of {spec.CHANNELS}")
        self._tick_source = tick_source or (lambda: 0)
        #: the device's tick rate (None given: the protocol dictionary's)
        self.rate_hz = float(control_rate_hz if control_rate_hz is not None
                             else default_control_rate_hz())
        self.base_channel = base_channel
        self.identity = f"{spec.MAKER},{spec.MODEL},{serial},{firmware}"
        self.lock = threading.Lock()
        self.channels = {ch: _Channel() for ch in spec.CHANNELS}
        self.user_waves: dict[str, UserWave] = {}
        self.esr = 0
        self.errors: deque[tuple[int, str]] = deque()
        #: every command received (a WVDT as its header and byte count), newest last:
        #: lets a test prove that a refused setting never reached the instrument
        self.command_log: deque[str] = deque(maxlen=5000)

    # ------------------------------------------------------------------ errors
    def _push_error(self, code: int, text: str) -> None:
        # the SCPI error class sets its standard event status bit
        bit = {1: 32, 2: 16, 3: 8, 4: 4}.get(-code // 100, 0)
        self.esr |= bit
        if len(self.errors) >= ERROR_QUEUE_DEPTH:
            self.errors[-1] = (-350, "Queue overflow")
            return
        self.errors.append((code, text))
        log.info("simulated generator: error %d %s", code, text)

    # ------------------------------------------------------------------ commands
    def handle_line(self, line: str) -> list[str]:
        """Execute a text line (commands separated by ';'); return the reply lines."""
        replies: list[str] = []
        for command in line.split(";"):
            command = command.strip()
            if not command:
                continue
            with self.lock:
                self.command_log.append(command)
                try:
                    reply = self._execute(command)
                except ScpiError as exc:
                    self._push_error(exc.code, exc.text)
                    reply = None
            if reply is not None:
                replies.append(reply)
        return replies

    def _execute(self, command: str) -> str | None:
        upper = command.upper()
        common = upper.split(None, 1)[0]
        if common == "*IDN?":
            return self.identity
        if common == "*CLS":
            self.esr = 0
            self.errors.clear()
            return None
        if common == "*RST":
            self._reset()
            return None
        if common == "*OPC":
            self.esr |= 1
            return None
        if common == "*OPC?":
            return "1"
        if common == "*ESR?":
            value, self.esr = self.esr, 0
            return str(value)
        if common in ("SYST:ERR?", "SYSTEM:ERROR?", "SYST:ERR:NEXT?"):
            if not self.errors:
                return '0,"No error"'
            code, text = self.errors.popleft()
            return f'{code},"{text}"'
        m = re.match(r"^C([0-9]+):([A-Z_]+)(\?)?(?:\s+(.*))?$", command.strip(), re.IGNORECASE)
        if not m or m.group(2).upper() not in _ALIASES:
            raise ScpiError(-113, f"Undefined header; {command[:40]}")
        ch = int(m.group(1))
        if ch not in spec.CHANNELS:
            raise ScpiError(-114, f"Header suffix out of range; channel {ch}")
        what, query, args = _ALIASES[m.group(2).upper()], bool(m.group(3)), (m.group(4) or "").strip()
        if query:
            if args:
                raise ScpiError(-108, "Parameter not allowed")
            return {"BSWV": self._bswv_reply, "OUTP": self._outp_reply,
                    "ARWV": self._arwv_reply}.get(what, self._no_query)(ch)
        if what == "BSWV":
            self._set_bswv(ch, args)
        elif what == "OUTP":
            self._set_outp(ch, args)
        elif what == "ARWV":
            self._set_arwv(ch, args)
        else:
            raise ScpiError(-109, "Missing parameter; WVDT needs LENGTH and WAVEDATA")
        return None

    @staticmethod
    def _no_query(ch: int) -> str:
        raise ScpiError(-113, "Undefined header; no such query")

    def _reset(self) -> None:
        now = self._next_tick()
        self.channels = {ch: _Channel(ref_tick=now) for ch in spec.CHANNELS}
        self.esr = 0

    def _next_tick(self) -> int:
        """The first control period a change made now affects."""
        return int(self._tick_source()) + 1

    # ------------------------------------------------------------------ BSWV
    def _set_bswv(self, ch: int, args: str) -> None:
        p = _pairs(args)
        c = self.channels[ch]
        new = replace(c)
        for key, value in p.items():
            if key == "WVTP":
                wv = value.upper()
                if wv not in spec.ALL_WAVEFORMS:
                    raise ScpiError(-224, f"Illegal parameter value; WVTP {value}")
                if wv not in spec.WAVEFORMS:
                    raise ScpiError(-224, f"Illegal parameter value; {wv} is not simulated")
                new.waveform = wv
            elif key == "FRQ":
                new.frequency_hz = _number(value, key)
            elif key == "PERI":
                period = _number(value, key)
                if period <= 0:
                    raise ScpiError(-222, f"Data out of range; PERI {value}")
                new.frequency_hz = 1.0 / period
            elif key == "AMP":
                new.amplitude_vpp = _number(value, key)
            elif key == "OFST":
                new.offset_v = _number(value, key)
            elif key == "PHSE":
                new.phase_deg = _number(value, key)
            else:
                raise ScpiError(-108, f"Parameter not allowed; {key}")
        _check_levels(new)
        now = self._next_tick()
        if new.waveform != c.waveform:
            new.ref_tick, new.ref_cycles = now, new.phase_deg / 360.0
        else:
            # continuous phase through a frequency change; a phase change shifts it
            new.ref_cycles = (c.cycles_at(now, self.rate_hz)
                              + (new.phase_deg - c.phase_deg) / 360.0)
            new.ref_tick = now
        self.channels[ch] = new

    def _bswv_reply(self, ch: int) -> str:
        c = self.channels[ch]
        f = spec.format_number
        if c.waveform == "DC":
            return f"C{ch}:BSWV WVTP,DC,OFST,{f(c.offset_v)}V"
        return (f"C{ch}:BSWV WVTP,{c.waveform},FRQ,{f(c.frequency_hz)}HZ,"
                f"PERI,{f(1.0 / c.frequency_hz)}S,AMP,{f(c.amplitude_vpp)}V,"
                f"OFST,{f(c.offset_v)}V,HLEV,{f(c.offset_v + c.amplitude_vpp / 2)}V,"
                f"LLEV,{f(c.offset_v - c.amplitude_vpp / 2)}V,PHSE,{f(c.phase_deg)}")

    # ------------------------------------------------------------------ OUTP
    def _set_outp(self, ch: int, args: str) -> None:
        fields = [a.strip() for a in args.split(",")] if args else []
        if not fields:
            raise ScpiError(-109, "Missing parameter")
        c = self.channels[ch]
        new = replace(c)
        if fields[0].upper() in ("ON", "OFF"):
            new.on = fields[0].upper() == "ON"
            fields = fields[1:]
        for key, value in (_pairs(",".join(fields)).items() if fields else ()):
            if key == "LOAD":
                try:
                    new.load = spec.normalise_load(value)
                except ValueError:
                    raise ScpiError(-224, f"Illegal parameter value; LOAD {value}") from None
            elif key == "PLRT":
                if value.upper() != "NOR":
                    raise ScpiError(-224, f"Illegal parameter value; PLRT {value} (only NOR)")
            else:
                raise ScpiError(-108, f"Parameter not allowed; {key}")
        if new.load != c.load:
            try:
                _check_levels(new)
            except ScpiError as exc:
                raise ScpiError(-221, f"Settings conflict; {exc.text}") from None
        if new.on and not c.on:           # the waveform starts (again) at PHSE
            new.ref_tick, new.ref_cycles = self._next_tick(), new.phase_deg / 360.0
        self.channels[ch] = new

    def _outp_reply(self, ch: int) -> str:
        c = self.channels[ch]
        return f"C{ch}:OUTP {'ON' if c.on else 'OFF'},LOAD,{c.load},PLRT,NOR"

    # ------------------------------------------------------------------ ARWV / WVDT
    def _set_arwv(self, ch: int, args: str) -> None:
        p = _pairs(args)
        c = self.channels[ch]
        new = replace(c)
        if set(p) == {"INDEX"}:
            try:
                index = int(p["INDEX"])
            except ValueError:
                raise ScpiError(-104, f"Data type error; INDEX {p['INDEX']}") from None
            if not 0 <= index < len(spec.BUILTIN_ARB_NAMES):
                raise ScpiError(-222, f"Data out of range; INDEX {index} "
                                      f"(0..{len(spec.BUILTIN_ARB_NAMES) - 1})")
            new.arb_index, new.arb_name = index, spec.BUILTIN_ARB_NAMES[index]
        elif set(p) == {"NAME"}:
            name = p["NAME"]
            if name in self.user_waves:
                new.arb_index, new.arb_name = None, name
            elif name in spec.BUILTIN_ARB_NAMES:
                new.arb_index, new.arb_name = spec.BUILTIN_ARB_NAMES.index(name), name
            else:
                raise ScpiError(-224, f"Illegal parameter value; no waveform named {name}")
        else:
            raise ScpiError(-108, "Parameter not allowed; use INDEX,<n> or NAME,<name>")
        new.ref_tick, new.ref_cycles = self._next_tick(), new.phase_deg / 360.0
        self.channels[ch] = new

    def _arwv_reply(self, ch: int) -> str:
        c = self.channels[ch]
        if c.arb_index is None:
            return f"C{ch}:ARWV NAME,{c.arb_name}"
        return f"C{ch}:ARWV INDEX,{c.arb_index},NAME,{c.arb_name}"

    def handle_upload(self, header: str, data: bytes) -> None:
        """A WVDT message: `header` is the text before 'WAVEDATA,', `data` the raw samples."""
        with self.lock:
            self.command_log.append(f"{header.strip()}WAVEDATA,<{len(data)} bytes>")
            try:
                self._store_upload(header, data)
            except ScpiError as exc:
                self._push_error(exc.code, exc.text)

    def _store_upload(self, header: str, data: bytes) -> None:
        m = re.match(r"^\s*C([0-9]+):(WVDT|WAVEDATA)\s+(.*?),?\s*$", header, re.IGNORECASE)
        if not m:
            raise ScpiError(-113, "Undefined header; expected Cn:WVDT")
        if int(m.group(1)) not in spec.CHANNELS:
            raise ScpiError(-114, "Header suffix out of range")
        p = _pairs(m.group(3))
        name = p.get("WVNM", "")
        if not spec.ARB_NAME_PATTERN.match(name):
            raise ScpiError(-224, f"Illegal parameter value; WVNM {name!r}")
        if "LENGTH" not in p:
            raise ScpiError(-109, "Missing parameter; LENGTH")
        n_bytes = parse_length(p["LENGTH"])
        if n_bytes != len(data):
            raise ScpiError(-223, f"Too much or too little data; LENGTH {n_bytes}, got {len(data)}")
        load = self.channels[int(m.group(1))].load
        points = spec.first_violation("ARB", load, {"points": n_bytes / 2})
        if n_bytes % 2 or points is not None:
            row = spec.limit_for("points", "ARB")
            raise ScpiError(-222, f"Data out of range; {row.field} {n_bytes}B is "
                                  f"{n_bytes / 2:g} 16-bit samples "
                                  f"({row.range_text(load, between='..')})")
        codes = np.frombuffer(data, dtype=np.dtype(spec.ARB_SAMPLE_FORMAT)).astype(np.int16)
        if codes.min() < spec.ARB_CODE_MIN or codes.max() > spec.ARB_CODE_MAX:
            raise ScpiError(-222, f"Data out of range; samples must be {spec.ARB_CODE_MIN}.."
                                  f"{spec.ARB_CODE_MAX}")
        opt = {k: _number(p[k], k) if k in p else None for k in ("FREQ", "AMPL", "OFST", "PHASE")}
        # the header's frequency and amplitude are what the waveform plays at: the same
        # rows as a basic wave's, into the channel's load
        header_values = {"frequency": opt["FREQ"], "amplitude": opt["AMPL"]}
        violation = spec.first_violation("ARB", load, {k: v for k, v in header_values.items()
                                                       if v is not None})
        if violation is not None:
            raise _out_of_range(violation, {"frequency": "FREQ", "amplitude": "AMPL"}
                                [violation.limit.key])
        self.user_waves[name] = UserWave(name, codes.copy(), opt["FREQ"], opt["AMPL"],
                                         opt["OFST"], opt["PHASE"])
        now = self._next_tick()
        for c in self.channels.values():       # a channel playing this name plays the new data
            if c.arb_index is None and c.arb_name == name:
                c.ref_tick, c.ref_cycles = now, c.phase_deg / 360.0

    # ------------------------------------------------------------------ output
    def output_volts(self, channel: int, first_tick: int, n: int) -> np.ndarray:
        """Volts at a high-impedance input for ticks first_tick .. first_tick+n-1."""
        with self.lock:
            c = replace(self.channels[channel])
            codes = (self.user_waves[c.arb_name].codes if c.arb_index is None
                     else _builtin_shape(c.arb_index)) if c.waveform == "ARB" else None
        if not c.on:
            return np.zeros(n)
        if c.waveform == "DC":
            return np.full(n, spec.volts_at_high_z(c.offset_v, c.load))
        ticks = first_tick + np.arange(n, dtype=np.int64)
        cycles = c.ref_cycles + c.frequency_hz * (ticks - c.ref_tick) / self.rate_hz
        frac = cycles - np.floor(cycles)
        if c.waveform == "SINE":
            shape = np.sin(2 * np.pi * frac)
        elif c.waveform == "SQUARE":
            shape = np.where(frac < 0.5, 1.0, -1.0)
        elif c.waveform == "RAMP":
            shape = np.where(frac < 0.25, 4 * frac, np.where(frac < 0.75, 2 - 4 * frac, 4 * frac - 4))
        else:   # ARB
            # the tiny offset keeps a sample boundary that falls exactly on a tick (k/N of a
            # period) from rounding down to the previous sample
            idx = np.minimum(np.floor(frac * len(codes) + 1e-9).astype(np.int64), len(codes) - 1)
            shape = codes[idx] / spec.ARB_CODE_FULL_SCALE
        volts = c.offset_v + c.amplitude_vpp / 2 * shape
        return spec.volts_at_high_z(1.0, c.load) * volts

    def base_drive(self, first_tick: int, n: int) -> np.ndarray:
        """`SimulatedDevice.base_drive`: the base-stage channel's output."""
        return self.output_volts(self.base_channel, first_tick, n)


def _pairs(args: str) -> dict[str, str]:
    fields = [a.strip() for a in args.split(",")] if args.strip() else []
    if not fields or len(fields) % 2:
        raise ScpiError(-109, f"Missing parameter; expected name,value pairs in {args[:60]!r}")
    out: dict[str, str] = {}
    for i in range(0, len(fields), 2):
        out[fields[i].upper()] = fields[i + 1]
    return out


def _number(text: str, key: str) -> float:
    try:
        return spec.parse_number(text)
    except ValueError:
        raise ScpiError(-104, f"Data type error; {key} {text}") from None


def parse_length(text: str) -> int:
    m = re.match(r"^\s*(\d+)\s*(B|KB)?\s*$", text, re.IGNORECASE)
    if not m:
        raise ScpiError(-104, f"Data type error; LENGTH {text}")
    return int(m.group(1)) * (1024 if (m.group(2) or "").upper() == "KB" else 1)


def _out_of_range(violation: spec.Violation, field: str | None = None) -> ScpiError:
    """-222 naming the field as the command calls it (BSWV's name unless `field` says
    otherwise), its value and the range from the limits table (the driver words the same
    row for the user)."""
    row = violation.limit
    bounds = row.range_text(violation.load, between="..", plus_minus="+-", at_most="max ")
    where = f" for {violation.waveform}" if spec.varies_by_waveform(row.key) else ""
    return ScpiError(-222, f"Data out of range; {field or row.field} {violation.value:g} "
                          f"({bounds}{where})")


def _check_levels(c: _Channel) -> None:
    """The instrument's own limits for a channel state (ScpiError -222 naming the value)."""
    violation = spec.first_violation(c.waveform, c.load, spec.wave_quantities(
        c.waveform, frequency_hz=c.frequency_hz, amplitude_vpp=c.amplitude_vpp,
        offset_v=c.offset_v, phase_deg=c.phase_deg))
    if violation is not None:
        raise _out_of_range(violation)
