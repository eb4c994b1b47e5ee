"""pyvisa driver for the B&K Precision 4050-series function generator (4053B).

The generator drives the base stage (audio amplifier -> linear actuator -> rotary stage),
so the driver is first of all a safety layer:

* every setting is checked *before* it is sent, against the instrument's limits
  (`spec4050`) and against the testbed's safety limits (`SafetyLimits`, from the testbed
  file's [limits]); a refused setting raises `InstrumentLimitError` / `SafetyLimitError`
  naming the value, the limit and where the limit comes from, and nothing is sent;
* the full basic-wave state of a channel is sent in one `BSWV` command (read, modify,
  check, send), so what was checked is exactly what the instrument gets, and amplitude
  and offset are ordered so that no intermediate state leaves the envelope; a load
  change made together with the wave is checked with the new load and sent in the order
  whose state in between is allowed;
* any failure of the I/O itself (VISA error, timeout, dropped link, a reply that is not
  text, a backend that cannot take a message) raises `InstrumentLinkError` with one line
  naming the command and what to check - never a backend's own exception;
* after every setting the standard event status (`*ESR?`) is read and, on an error bit,
  the error queue (`SYST:ERR?`, where supported): an error raises `InstrumentError` with
  the instrument's own text;
* the outputs go off on `abort()`, on `close()`, when the driver is garbage-collected
  and at interpreter exit, whatever happened before.  If the session is dead, the
  resource is opened once more to switch them off; closing never raises.

This module is the driver: the SCPI commands, the channel state read back, and the checks
(the instrument's limits from the table in `spec4050`, the testbed's in `safety`).  The
VISA session it talks through - opening, locking, I/O errors in one line, outputs off on
failure - is `visa_link`; the records it reads are `records4050`; its exceptions are
`fg_errors`.  The names callers use are re-exported here and from the package.

Backends: any pyvisa backend - "@py" (pyvisa-py, the default), "@ivi" (a vendor VISA
where installed) or "file.yaml@sim" (pyvisa-sim, for tests; it has no binary transfers,
so arbitrary-waveform uploads through it are refused before anything is sent).
"""

from __future__ import annotations

import atexit
import logging
import math
import weakref
from typing import Iterable

import numpy as np

from ..core.errors import GroundStationError
from . import spec4050 as spec
# the records, errors and link are re-exported: callers import them from here or from
# the package, as they did when this module held everything
from .fg_errors import (InstrumentError, InstrumentLimitError, InstrumentLinkError,
                        SettingRefusedError)
from .records4050 import ArbSelection, ArbUpload, BasicWave, OutputState
from .safety import SafetyLimits
from .spec4050 import Identity
from .visa_link import VisaLink, io_failure, normalise_backend, resource_manager, shorten

log = logging.getLogger(__name__)

INSTRUMENT_SOURCE = f"the {spec.MODEL} specification (groundstation/instruments/spec4050.py)"
#: how a message names a derived quantity
_SPOKEN = {"envelope": "|offset| + amplitude/2 ="}


# ---------------------------------------------------------------------------------- driver
class FunctionGenerator4050:
    """A 4050-series generator on a VISA resource; use `open_generator()` to make one.

    All methods are safe to call from several threads (one transaction at a time)."""

    def __init__(self, link: VisaLink, *, limits: SafetyLimits | None = None, check_model: bool = True):
        self._link = link
        self.limits = limits
        self.resource_name = link.resource_name
        self._finalizer = weakref.finalize(self, VisaLink.shutdown, link)
        self._finalizer.atexit = False          # the atexit handler below runs first instead
        # registered after pyvisa's own atexit handler for this resource manager, so it
        # runs before it (atexit is last-in, first-out) while the session still works
        atexit.register(link.shutdown)
        self._error_query: str | None = "SYST:ERR?"
        try:
            with link.lock:
                link.inst = link.open_session()
                link.inst.write("*CLS")          # old errors are not ours
            self.identity = self.identify()
            if check_model and not self.identity.model.upper().startswith(spec.SERIES_PREFIX):
                raise InstrumentError(f"{self.resource_name} is a {self.identity.maker} "
                                      f"{self.identity.model}, not a 4050-series generator")
            link.is_generator = True            # from now on, closing switches outputs off
        except BaseException:
            self._finalizer()
            raise

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Outputs off, link closed.  Never raises (a dead link is logged)."""
        self._finalizer()

    @property
    def closed(self) -> bool:
        return self._link.closed

    def __enter__(self) -> "FunctionGenerator4050":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def abort(self) -> None:
        """Both outputs off now (re-opening the resource if the session died); raises
        InstrumentLinkError only if the generator could not be reached at all."""
        self._require_open()
        self._link.outputs_off()

    # ------------------------------------------------------------------ low level
    def _require_open(self) -> None:
        self._link.require_open()

    def query(self, command: str) -> str:
        """Send a query and return the reply line (no error check: replies are data).

        Any failure of the exchange (VISA error, timeout, dropped link, a reply that is not
        text) raises InstrumentLinkError naming the query and what to check."""
        return self._link.query(command)

    def _write_checked(self, command: str, binary: np.ndarray | None = None) -> None:
        with self._link.lock:
            self._link.write(command, binary)
            self._check_errors(command)

    def _check_errors(self, command: str) -> None:
        """*ESR? after a setting; on an error bit, the error queue's text."""
        reply = self.query("*ESR?")
        try:
            esr = int(float(reply))
            if not 0 <= esr <= 255:
                raise ValueError("not an 8-bit register")
        except (ValueError, OverflowError):
            raise InstrumentError(f"{self.resource_name}: unexpected *ESR? reply {reply!r} "
                                  f"after {shorten(command)!r} (not a status register value); "
                                  f"the setting may or may not have been taken - read the "
                                  f"channel back before going on") from None
        bits = [name for bit, name in spec.ESR_ERROR_BITS.items() if esr & bit]
        if not bits:
            return
        texts = self._error_texts()
        text = "; ".join(texts) if texts else ", ".join(bits)
        raise InstrumentError(f"{self.resource_name} refused {shorten(command)!r}: {text}",
                              command, text)

    def _error_texts(self) -> list[str]:
        if self._error_query is None:
            return []
        texts: list[str] = []
        for _ in range(20):                   # bounded: a queue holds ~20 entries
            try:
                with self._link.lock:
                    reply = self._link.inst.query(self._error_query).strip()
            except UnicodeDecodeError as exc:   # an answer, but not text: say so, stop
                texts.append(f"(the {self._error_query} reply is not text: {exc.reason} at "
                             f"byte {exc.start})")
                break
            except Exception as exc:
                # no error query on this firmware: use the status bits from now on
                log.info("%s: %s not answered (%s); reporting status bits only",
                         self.resource_name, self._error_query, exc)
                self._error_query = None
                try:
                    self._link.inst.write("*CLS")
                except Exception:
                    pass
                break
            code = reply.split(",", 1)[0].strip()
            try:
                if int(float(code)) == 0:
                    break
            except ValueError:
                pass
            texts.append(reply)
        return texts

    # ------------------------------------------------------------------ identification
    def identify(self) -> Identity:
        reply = self.query("*IDN?")
        try:
            return Identity.parse(reply)
        except ValueError as exc:
            raise InstrumentError(f"{self.resource_name}: {exc}") from None

    # ------------------------------------------------------------------ queries
    def _read(self, parse, command: str):
        """Query and parse; a reply that cannot be parsed names the instrument and query."""
        reply = self.query(command)
        try:
            return parse(reply)
        except InstrumentError as exc:
            raise InstrumentError(f"{self.resource_name}: {command}: {exc}") from None

    def basic_wave(self, channel: int) -> BasicWave:
        return self._read(BasicWave.parse, f"C{_channel(channel)}:BSWV?")

    def output_state(self, channel: int) -> OutputState:
        return self._read(OutputState.parse, f"C{_channel(channel)}:OUTP?")

    def arb_selection(self, channel: int) -> ArbSelection:
        return self._read(ArbSelection.parse, f"C{_channel(channel)}:ARWV?")

    def get_waveform(self, channel: int) -> str:
        return self.basic_wave(channel).waveform

    def get_frequency(self, channel: int) -> float | None:
        return self.basic_wave(channel).frequency_hz

    def get_amplitude(self, channel: int) -> float | None:
        return self.basic_wave(channel).amplitude_vpp

    def get_offset(self, channel: int) -> float | None:
        return self.basic_wave(channel).offset_v

    def get_phase(self, channel: int) -> float | None:
        return self.basic_wave(channel).phase_deg

    def get_output(self, channel: int) -> bool:
        return self.output_state(channel).on

    def get_load(self, channel: int) -> str | None:
        return self.output_state(channel).load

    # ------------------------------------------------------------------ checks
    # ------------------------------------------------------------------ checks
    def check(self, channel: int, wave: BasicWave, load: str | None, *,
              safety: bool = True) -> None:
        """Raise InstrumentLimitError / SafetyLimitError if `wave` into `load` is not
        allowed; an unknown load is taken as 50 ohm (the one that doubles the real voltage).
        With safety=False only the instrument's own limits apply (a state in between two
        commands while the output is off: the instrument must take it, the stage never
        sees it)."""
        ch = _channel(channel)
        if wave.waveform not in spec.WAVEFORMS:
            raise InstrumentLimitError.on_channel(
                ch, f"waveform {wave.waveform!r} is not one this driver sets "
                f"({', '.join(spec.WAVEFORMS)})", setting="waveform", value=wave.waveform,
                limit=", ".join(spec.WAVEFORMS), source=INSTRUMENT_SOURCE)
        load_known = load if load is not None else "50"
        needed = spec.WAVE_PARAMETERS[wave.waveform]
        values = {"FRQ": wave.frequency_hz, "AMP": wave.amplitude_vpp,
                  "OFST": wave.offset_v, "PHSE": wave.phase_deg}
        for name in needed:
            v = values[name]
            if v is None or not math.isfinite(v):
                raise InstrumentLimitError.on_channel(
                    ch, f"{_LABEL[name]} is {'unknown' if v is None else v} for "
                    f"{wave.waveform} (give it explicitly: the driver sends only settings it "
                    f"has checked)", setting=_LABEL[name], value=str(v),
                    limit="a finite number", source=INSTRUMENT_SOURCE)
        violation = spec.first_violation(wave.waveform, load_known, spec.wave_quantities(
            wave.waveform, frequency_hz=wave.frequency_hz, amplitude_vpp=wave.amplitude_vpp,
            offset_v=wave.offset_v, phase_deg=wave.phase_deg))
        if violation is not None:
            raise instrument_refusal(ch, violation)
        if self.limits is None or not safety:
            return
        self.limits.check(ch, amplitude_vpp=wave.amplitude_vpp if "AMP" in needed else None,
                          offset_v=wave.offset_v, load=load)

    def configure(self, channel: int, *, waveform: str | None = None,
                  frequency_hz: float | None = None, amplitude_vpp: float | None = None,
                  offset_v: float | None = None, phase_deg: float | None = None,
                  load: str | int | None = None) -> BasicWave:
        """Change any of the basic-wave settings and, with `load`, the load they refer to:
        the resulting state is checked as a whole - the new values against the NEW load -
        and the wave is sent as one BSWV command; returns the wave state sent.

        When the load changes too, the two commands (BSWV and OUTP LOAD) go in the order
        whose state in between is one the instrument accepts (an amplitude valid only into
        high impedance needs the load first; one valid only at the old load, the wave
        first) and, if the output is on, one the testbed's limits allow: the smaller
        drive in between is preferred (to high impedance: load first; to 50 ohm: wave
        first).  If no order works, nothing is sent."""
        ch = _channel(channel)
        new_load = None if load is None else _load_setting(ch, load)
        wave_given = any(v is not None for v in (waveform, frequency_hz, amplitude_vpp,
                                                 offset_v, phase_deg))
        with self._link.lock:
            current = self.basic_wave(ch)
            out = self.output_state(ch)
            if wave_given or new_load is None:
                # a value the instrument does not report for the current waveform (DC has
                # no frequency or amplitude) stays None - "unknown", which check() refuses -
                # rather than letting the instrument fall back on a value nobody checked
                new = BasicWave(
                    (waveform or current.waveform).upper(),
                    float(frequency_hz) if frequency_hz is not None else current.frequency_hz,
                    float(amplitude_vpp) if amplitude_vpp is not None else current.amplitude_vpp,
                    float(offset_v) if offset_v is not None else (current.offset_v or 0.0),
                    float(phase_deg) if phase_deg is not None else (current.phase_deg or 0.0))
            else:
                new = current                   # a load change alone: what plays stays
            final_load = new_load if new_load is not None else out.load
            given = {"amplitude": amplitude_vpp, "offset": offset_v, "frequency": frequency_hz,
                     "phase": phase_deg}
            try:
                self.check(ch, new, final_load)
            except SettingRefusedError as exc:
                if given.get(exc.setting, 0) is not None:
                    raise
                # a value this call did not give: say it is the channel's present one
                raise type(exc)(str(exc).replace(
                    "; nothing was sent", f" (the channel's present {exc.setting}: give a new "
                    f"one in the same command); nothing was sent"), setting=exc.setting,
                    value=exc.value, limit=exc.limit, source=exc.source) from None
            commands: list[str] = []
            if wave_given or new_load is None:
                body = ",".join(f"{n},{v if isinstance(v, str) else spec.format_number(v)}"
                                for n, v in new.command_pairs(current))
                commands.append(f"C{ch}:BSWV {body}")
            if new_load is not None and new_load != out.load:
                load_cmd = f"C{ch}:OUTP {'ON' if out.on else 'OFF'},LOAD,{new_load}"
                if commands:
                    commands = self._order_with_load(ch, current, new, out, new_load,
                                                     commands[0], load_cmd)
                else:
                    commands = [load_cmd]
            for command in commands:
                self._write_checked(command)
            return new

    def _order_with_load(self, ch: int, current: BasicWave, new: BasicWave, out: "OutputState",
                         new_load: str, bswv: str, load_cmd: str) -> list[str]:
        """BSWV and the load command in an order whose in-between state is allowed."""
        load_first = ((current, new_load), [load_cmd, bswv])
        wave_first = ((new, out.load), [bswv, load_cmd])
        orders = [load_first, wave_first] if new_load == "HZ" else [wave_first, load_first]
        refusals: list[SettingRefusedError] = []
        for (wave, load), commands in orders:
            try:
                self.check(ch, wave, load, safety=out.on)
            except SettingRefusedError as exc:
                refusals.append(exc)
                continue
            return commands
        first = refusals[0]
        steps = ("load first", "wave first") if new_load == "HZ" else ("wave first", "load first")
        reason = "; ".join(f"{step}: " + str(r).removeprefix(f"channel {ch}: ")
                           .removesuffix("; nothing was sent")
                           for step, r in zip(steps, refusals))
        raise type(first)(
            f"channel {ch}: the wave and the load cannot be changed one after the other "
            f"without a state in between that is refused - {reason}"
            + ("; switch the output off first" if out.on else "") + "; nothing was sent",
            setting=first.setting, value=first.value, limit=first.limit, source=first.source)

    def set_waveform(self, channel: int, waveform: str) -> BasicWave:
        return self.configure(channel, waveform=waveform)

    def set_frequency(self, channel: int, frequency_hz: float) -> BasicWave:
        return self.configure(channel, frequency_hz=frequency_hz)

    def set_amplitude(self, channel: int, amplitude_vpp: float) -> BasicWave:
        return self.configure(channel, amplitude_vpp=amplitude_vpp)

    def set_offset(self, channel: int, offset_v: float) -> BasicWave:
        return self.configure(channel, offset_v=offset_v)

    def set_phase(self, channel: int, phase_deg: float) -> BasicWave:
        return self.configure(channel, phase_deg=phase_deg)

    def set_output(self, channel: int, on: bool) -> None:
        """Output on (after checking the channel's current settings, which the front
        panel may have changed) or off (always allowed, never checked)."""
        ch = _channel(channel)
        if not on:
            self._write_checked(f"C{ch}:OUTP OFF")
            return
        with self._link.lock:
            self.check(ch, self.basic_wave(ch), self.output_state(ch).load)
            self._write_checked(f"C{ch}:OUTP ON")

    def set_load(self, channel: int, load: str | int) -> None:
        """The load the amplitude refers to: 'HZ' (the base-stage amplifier) or 50.  The
        channel's wave is checked against the new load; to change the amplitude too, give
        both to `configure(..., load=...)` (checked together, sent in a safe order)."""
        ch = _channel(channel)
        self.configure(ch, load=_load_setting(ch, load))

    # ------------------------------------------------------------------ arbitrary waveforms
    def select_arbitrary(self, channel: int, *, name: str | None = None,
                         index: int | None = None) -> None:
        """Select a stored arbitrary waveform by name (user) or index (built-in)."""
        ch = _channel(channel)
        if (name is None) == (index is None):
            raise ValueError("give exactly one of name and index")
        if name is not None:
            _check_arb_name(ch, name)
            self._write_checked(f"C{ch}:ARWV NAME,{name}")
        else:
            if int(index) < 0:
                raise InstrumentLimitError(f"channel {ch}: arbitrary waveform index {index} is "
                                           f"negative; nothing was sent", setting="index",
                                           value=index, limit=0,
                                           source=f"the {spec.MODEL} specification")
            self._write_checked(f"C{ch}:ARWV INDEX,{int(index)}")

    def upload_arbitrary(self, channel: int, volts: Iterable[float], *, name: str,
                         frequency_hz: float, select: bool = True) -> ArbUpload:
        """Upload one period of a waveform given in volts (at a high-impedance load) and,
        with `select`, play it: ARB at `frequency_hz` (1 / period), amplitude 2*max|v|,
        offset 0.  The output state is left as it is.

        The samples are scaled symmetrically (0 V is code 0) so the waveform's mean stays
        exact and no offset is needed; the amplitude set is the symmetric span, never
        less than the waveform's real peak-to-peak, and that is what is checked."""
        ch = _channel(channel)
        _check_arb_name(ch, name)
        v = np.asarray(list(volts) if not isinstance(volts, np.ndarray) else volts, dtype=float)
        source = INSTRUMENT_SOURCE
        points = spec.limit_for("points", "ARB")
        # the point count does not depend on the load: either load reads the same range
        outside = spec.first_violation("ARB", "HZ", {"points": v.size}) if v.ndim == 1 else None
        if v.ndim != 1 or outside is not None:
            raise InstrumentLimitError.on_channel(
                ch, f"an arbitrary waveform has {points.range_text('HZ')}, not {v.size}",
                setting="points", value=int(v.size),
                limit=outside.bound if outside else points.high_z[1], source=source)
        if not np.all(np.isfinite(v)):
            raise InstrumentLimitError(f"channel {ch}: the waveform has non-finite samples; "
                                       f"nothing was sent", setting="samples", value="nan/inf",
                                       limit="finite", source=source)
        peak = float(np.max(np.abs(v)))
        if peak == 0.0:
            raise InstrumentLimitError(f"channel {ch}: the waveform is all zeros; nothing was sent",
                                       setting="amplitude", value=0.0,
                                       limit=spec.AMPLITUDE_MIN_VPP["HZ"], source=source)
        codes = np.clip(np.round(v / peak * spec.ARB_CODE_FULL_SCALE),
                        spec.ARB_CODE_MIN, spec.ARB_CODE_MAX).astype(np.int16)
        wave = BasicWave("ARB", float(frequency_hz), 2 * peak, 0.0, 0.0)
        if self._link.backend.endswith("@sim"):
            # pyvisa-sim decodes every message as text: a binary block would fail half-way
            raise InstrumentLinkError(
                f"{self.resource_name}: the pyvisa-sim backend ({self._link.backend}) cannot "
                f"carry the binary samples of an arbitrary waveform; nothing was sent - upload "
                f"to the simulated generator (--resource sim) or to a real instrument")
        with self._link.lock:
            load = self.output_state(ch).load
            self.check(ch, wave, load)
            header = (f"C{ch}:WVDT WVNM,{name},LENGTH,{2 * len(codes)}B,"
                      f"FREQ,{spec.format_number(wave.frequency_hz)},"
                      f"AMPL,{spec.format_number(wave.amplitude_vpp)},OFST,0,PHASE,0,WAVEDATA,")
            self._write_checked(header, binary=codes)
            if select:
                self.select_arbitrary(ch, name=name)
                self.configure(ch, waveform="ARB", frequency_hz=wave.frequency_hz,
                               amplitude_vpp=wave.amplitude_vpp, offset_v=0.0, phase_deg=0.0)
        return ArbUpload(ch, name, len(codes), wave.frequency_hz, wave.amplitude_vpp, 0.0, codes)

    # ------------------------------------------------------------------ summary
    def describe(self, channel: int) -> str:
        w, o = self.basic_wave(channel), self.output_state(channel)
        parts = [w.waveform]
        for label, value, unit in (("f", w.frequency_hz, "Hz"), ("amp", w.amplitude_vpp, "Vpp"),
                                   ("offset", w.offset_v, "V"), ("phase", w.phase_deg, "deg")):
            if value is not None:
                parts.append(f"{label} {value:g} {unit}")
        if w.waveform == "ARB":
            sel = self.arb_selection(channel)
            parts.append(f"arb {sel.name or sel.index}")
        load = {"HZ": "high-Z", "50": "50 ohm", None: "load ?"}[o.load]
        return f"C{channel}: {', '.join(parts)}; output {'ON' if o.on else 'off'} ({load})"


_LABEL = {"FRQ": "frequency", "AMP": "amplitude", "OFST": "offset", "PHSE": "phase"}


def _channel(channel: int) -> int:
    if channel not in spec.CHANNELS:
        raise ValueError(f"channel must be one of {spec.CHANNELS}, not {channel!r}")
    return int(channel)


def _load_setting(ch: int, load: str | int) -> str:
    try:
        return spec.normalise_load(load)
    except ValueError as exc:
        raise InstrumentLimitError(f"channel {ch}: {exc}; nothing was sent", setting="load",
                                   value=str(load), limit="HZ or 50",
                                   source=f"the {spec.MODEL} specification") from None


def _check_arb_name(ch: int, name: str) -> None:
    if not spec.ARB_NAME_PATTERN.match(name):
        raise InstrumentLimitError(
            f"channel {ch}: arbitrary waveform name {name!r} must be a letter then up to 15 "
            f"letters, digits or '_'; nothing was sent", setting="name", value=name,
            limit=spec.ARB_NAME_PATTERN.pattern, source=f"the {spec.MODEL} specification")


def instrument_refusal(channel: int, violation: spec.Violation) -> InstrumentLimitError:
    """A row of the limits table that a setting fell outside, in words: the setting, its
    value, the range, the waveform where the range depends on it, the load where it
    depends on that, and where the figures come from."""
    row, load = violation.limit, violation.load
    if row.form == "between":
        text = f"{row.key} {violation.value:g} {row.unit} is outside {row.range_text(load)}"
    else:
        spoken = _SPOKEN.get(row.key, row.key)
        text = (f"{spoken} {violation.value:g} {row.unit} is beyond "
                f"{row.range_text(load, plus_minus='+-', at_most='')}")
    if spec.varies_by_waveform(row.key):
        text += f" for {violation.waveform}"
    if row.depends_on_load:
        text += f" into a {spec.LOAD_NAMES[load]} load"
    return InstrumentLimitError.on_channel(channel, f"{text} ({INSTRUMENT_SOURCE})",
                                           setting=row.key, value=violation.value,
                                           limit=violation.bound, source=INSTRUMENT_SOURCE)


def open_generator(resource: str, *, backend: str | None = None, limits: SafetyLimits | None = None,
                   testbed=None, timeout_s: float = 5.0,
                   check_model: bool = True) -> FunctionGenerator4050:
    """Open a 4050-series generator: `resource` is a VISA address (USB0::...::INSTR,
    TCPIP0::host::port::SOCKET, ...); `backend` '@py' (default), '@ivi' or 'x.yaml@sim';
    safety limits from `limits` or from `testbed` (a Testbed record)."""
    if limits is None and testbed is not None:
        limits = SafetyLimits.from_testbed(testbed)
    try:
        timeout_ok = math.isfinite(float(timeout_s)) and float(timeout_s) > 0
    except (TypeError, ValueError):
        timeout_ok = False
    if not timeout_ok or int(float(timeout_s) * 1000) < 1:
        raise InstrumentLinkError(f"cannot open {resource}: the VISA timeout must be a number "
                                  f"of seconds of at least 0.001, not {timeout_s!r}")
    backend = normalise_backend(backend)
    rm = resource_manager(backend)
    link = VisaLink(rm, resource, backend, int(timeout_s * 1000))
    try:
        return FunctionGenerator4050(link, limits=limits, check_model=check_model)
    except GroundStationError:
        raise
    except Exception as exc:       # VISA errors; ValueError etc. for malformed addresses
        link.shutdown()
        log.debug("opening %s on %s failed", resource, backend, exc_info=exc)
        why = io_failure(exc, reading=True, timeout_ms=link.timeout_ms, backend=backend)
        raise InstrumentLinkError(f"cannot open {resource} on {backend}: {why}") from None


__all__ = ["FunctionGenerator4050", "open_generator"]
