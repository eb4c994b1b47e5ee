"""The 4050-series generator driver against a pyvisa-sim instrument (tests/fg_sim.yaml) and
against the simulated testbed's SCPI server (pyvisa-py over a loopback socket): settings
and queries, refusals before sending, instrument errors, outputs off on abort / close /
drop / exit, binary arbitrary-waveform upload, and the simulated generator's output."""

from __future__ import annotations

import gc
import logging
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from groundstation.instruments import (InstrumentError, InstrumentLimitError, InstrumentLinkError,
                                       SafetyLimitError, list_resources,
                                       open_generator)
from groundstation.instruments import spec4050 as spec
from groundstation.sim.scpi_server import ScpiServer
from groundstation.sim.fg_instrument import SimulatedGenerator
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

ROOT = Path(__file__).resolve().parents[2]
YAML = str(Path(__file__).resolve().parents[1] / "fg_sim.yaml")
SIM_RESOURCE = "USB0::0xF4ED::0xEE3A::SIM4053B::INSTR"
INERTIAL = load_testbed(TESTBEDS_DIR / "inertial_2dof.toml")


class Tick:
    """A hand-driven device clock for the simulated generator."""

    def __init__(self):
        self.now = 0

    def __call__(self) -> int:
        return self.now


@pytest.fixture
def server():
    clock = Tick()
    srv = ScpiServer(SimulatedGenerator(tick_source=clock)).start()
    srv.clock = clock
    yield srv
    srv.stop()


def fresh_yaml(tmp_path) -> str:
    """pyvisa keeps one backend (and so one simulated instrument state) per definitions
    file for the whole process: a copy per test starts from the power-on state."""
    path = tmp_path / "fg_sim.yaml"
    shutil.copyfile(YAML, path)
    return str(path)


@pytest.fixture(params=["pyvisa-sim", "scpi-server"])
def target(request, tmp_path):
    """(driver, server or None) on both instruments, safety limits of the inertial testbed."""
    if request.param == "pyvisa-sim":
        fg = open_generator(SIM_RESOURCE, backend=fresh_yaml(tmp_path), testbed=INERTIAL)
        srv = None
    else:
        srv = ScpiServer(SimulatedGenerator()).start()
        fg = open_generator(srv.resource, testbed=INERTIAL, timeout_s=2.0)
    yield fg, srv
    fg.close()
    if srv is not None:
        srv.stop()


def _safe(fg, ch=1):
    """Settings inside every limit (the power-on 4 Vpp is not)."""
    return fg.configure(ch, waveform="SINE", frequency_hz=2.0, amplitude_vpp=0.5, offset_v=0.0,
                        phase_deg=0.0)


# ------------------------------------------------------------------ identity and listing


def test_identify_names_the_4053b(target):
    fg, _ = target
    ident = fg.identify()
    assert (ident.maker, ident.model) == ("B&K Precision", "4053B")
    assert ident.serial and ident.firmware


def test_a_non_generator_is_refused_on_open(tmp_path):
    with pytest.raises(InstrumentError, match="not a 4050-series generator"):
        open_generator("USB0::0x2A8D::0x0101::SIMDMM::INSTR", backend=fresh_yaml(tmp_path))


def test_an_unreachable_instrument_is_a_link_error():
    with socket.socket() as s:              # a port that nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(InstrumentLinkError, match=f"127.0.0.1::{port}"):
        open_generator(f"TCPIP0::127.0.0.1::{port}::SOCKET", timeout_s=0.5)


def test_listing_resources_never_fails():
    found = list_resources(YAML)
    assert any("SIM4053B" in r for r in found.resources) and not found.notes
    missing = list_resources("@no_such_backend")
    assert missing.resources == () and "not available" in missing.notes[0]


# ------------------------------------------------------------------ settings and queries


def test_every_setting_reads_back(target):
    fg, _ = target
    wave = fg.configure(1, waveform="SINE", frequency_hz=2.0, amplitude_vpp=0.5, offset_v=0.1,
                        phase_deg=90.0)
    assert (fg.get_waveform(1), fg.get_frequency(1), fg.get_amplitude(1), fg.get_offset(1),
            fg.get_phase(1)) == ("SINE", 2.0, 0.5, 0.1, 90.0) == (wave.waveform, wave.frequency_hz,
                                                                  wave.amplitude_vpp, wave.offset_v,
                                                                  wave.phase_deg)
    fg.set_frequency(1, 3.5)
    fg.set_amplitude(1, 1.2)
    fg.set_offset(1, -0.15)
    fg.set_phase(1, 45.0)
    for waveform in ("SQUARE", "RAMP", "SINE"):
        fg.set_waveform(1, waveform)
        assert fg.basic_wave(1) == type(wave)(waveform, 3.5, 1.2, -0.15, 45.0)
    fg.set_load(1, "HZ")
    assert fg.get_load(1) == "HZ" and fg.get_output(1) is False
    fg.configure(1, amplitude_vpp=0.6, offset_v=0.05)   # x2 at the amplifier into "50 ohm"
    fg.set_load(1, 50)
    assert fg.get_load(1) == "50"
    fg.set_load(1, "hz")
    fg.set_output(1, True)
    assert fg.get_output(1) is True
    fg.set_output(1, False)
    assert fg.get_output(1) is False
    # DC has an offset only; leaving it needs the values the instrument no longer reports
    fg.configure(1, waveform="DC", offset_v=0.05)
    assert fg.basic_wave(1).waveform == "DC" and fg.get_offset(1) == 0.05
    assert fg.get_frequency(1) is None and fg.get_amplitude(1) is None
    with pytest.raises(InstrumentLimitError, match="frequency is unknown for SINE"):
        fg.set_waveform(1, "SINE")
    fg.configure(1, waveform="SINE", frequency_hz=1.0, amplitude_vpp=0.4)
    assert fg.basic_wave(1).frequency_hz == 1.0
    # the other channel was never touched
    assert fg.basic_wave(2).amplitude_vpp == 4.0


def test_arbitrary_waveform_selection(target):
    fg, _ = target
    fg.select_arbitrary(1, index=3)
    assert fg.arb_selection(1).index == 3
    fg.select_arbitrary(2, name="Sinc")
    assert fg.arb_selection(2).name == "Sinc"
    assert fg.arb_selection(1).index == 3


def _state(fg, srv):
    """What the instrument holds, read behind the driver's back where possible."""
    if srv is not None:
        g = srv.generator
        return [(c.waveform, c.frequency_hz, c.amplitude_vpp, c.offset_v, c.on, c.load)
                for c in g.channels.values()]
    return [fg.query(f"C{ch}:BSWV?") + fg.query(f"C{ch}:OUTP?") for ch in (1, 2)]


@pytest.mark.parametrize("call, error, limit, source", [
    (lambda fg: fg.set_amplitude(1, 2.5), SafetyLimitError, 2.0, "inertial_2dof.toml [limits]"),
    (lambda fg: fg.set_offset(1, 0.3), SafetyLimitError, 0.2, "inertial_2dof.toml [limits]"),
    (lambda fg: fg.set_amplitude(1, 25.0), InstrumentLimitError, 20.0, "4053B specification"),
    (lambda fg: fg.set_frequency(1, 2e7), InstrumentLimitError, 1e7, "4053B specification"),
    (lambda fg: fg.set_phase(1, 400.0), InstrumentLimitError, 360.0, "4053B specification"),
])
def test_out_of_range_settings_are_refused_before_anything_is_sent(target, call, error, limit,
                                                                     source):
    fg, srv = target
    _safe(fg)
    before = _state(fg, srv)
    sent = len(srv.generator.command_log) if srv else None
    with pytest.raises(error) as err:
        call(fg)
    assert err.value.limit == limit and source in err.value.source
    assert source in str(err.value) and "nothing was sent" in str(err.value)
    assert _state(fg, srv) == before
    if srv is not None:              # only the read-back queries reached the instrument
        assert all(c.endswith("?") for c in list(srv.generator.command_log)[sent:])


def test_a_50_ohm_load_setting_counts_double_at_the_amplifier(target):
    fg, srv = target
    fg.configure(1, waveform="SINE", frequency_hz=2.0, amplitude_vpp=1.5, offset_v=0.0)
    with pytest.raises(SafetyLimitError, match="3 Vpp at the amplifier.*twice the setting"):
        fg.set_load(1, 50)
    assert fg.get_load(1) == "HZ"
    fg.set_amplitude(1, 0.9)
    fg.set_load(1, 50)
    with pytest.raises(SafetyLimitError, match="2.4 Vpp"):
        fg.set_amplitude(1, 1.2)


def test_turning_on_checks_what_the_instrument_holds(target):
    fg, srv = target                        # power-on state: 4 Vpp, above the 2 Vpp limit
    with pytest.raises(SafetyLimitError, match="amplitude 4 Vpp"):
        fg.set_output(1, True)
    assert fg.get_output(1) is False


def test_the_envelope_limit_without_testbed_limits(server):
    with open_generator(server.resource, timeout_s=2.0) as fg:
        fg.configure(1, amplitude_vpp=18.0)       # allowed into high impedance
        with pytest.raises(InstrumentLimitError, match=r"\|offset\| \+ amplitude/2 = 10.5 V"):
            fg.set_offset(1, 1.5)


def test_an_instrument_error_is_raised_with_the_instruments_text(target):
    fg, srv = target
    with pytest.raises(InstrumentError) as err:
        fg.select_arbitrary(1, index=42)          # the driver cannot know how many there are
    expected = '-222,"Data out of range; INDEX 42' if srv else '-224,"Illegal parameter value"'
    assert expected in str(err.value) and "ARWV INDEX,42" in str(err.value)
    assert err.value.instrument_text.startswith(expected)
    # the error was consumed: the next setting goes through cleanly
    _safe(fg)
    assert fg.query("*ESR?") == "0"


# ------------------------------------------------------------------ outputs off


def test_abort_switches_both_outputs_off(target):
    fg, _ = target
    for ch in (1, 2):
        _safe(fg, ch)
        fg.set_output(ch, True)
    fg.abort()
    assert fg.get_output(1) is False and fg.get_output(2) is False


def test_close_and_context_exit_switch_the_outputs_off(server):
    g = server.generator
    with open_generator(server.resource, testbed=INERTIAL) as fg:
        _safe(fg)
        fg.set_output(1, True)
        assert g.channels[1].on
    assert not g.channels[1].on
    fg.close()                              # twice is fine
    with pytest.raises(InstrumentLinkError, match="closed"):
        fg.get_output(1)


def test_a_dropped_connection_still_ends_with_the_outputs_off(server):
    g = server.generator
    fg = open_generator(server.resource, testbed=INERTIAL, timeout_s=0.3)
    _safe(fg)
    fg.set_output(1, True)
    server.drop_connections()
    with pytest.raises(InstrumentLinkError, match="C1:OUTP"):
        fg.get_output(1)
    assert g.channels[1].on                 # the instrument keeps its state, as a real one
    fg.abort()                              # re-opens the resource to switch off
    assert not g.channels[1].on
    fg.set_output(1, True)                  # and carries on with the new session
    server.drop_connections()
    fg.close()
    assert not g.channels[1].on


def test_closing_a_dead_link_does_not_raise(server, caplog):
    fg = open_generator(server.resource, timeout_s=0.3)
    server.stop()
    with caplog.at_level(logging.ERROR, logger="groundstation.instruments.fg4050"):
        fg.close()
    assert "outputs may still be ON" in caplog.text


def test_garbage_collection_switches_the_outputs_off(server):
    fg = open_generator(server.resource, testbed=INERTIAL)
    _safe(fg)
    fg.set_output(1, True)
    del fg
    gc.collect()
    assert not server.generator.channels[1].on


def test_interpreter_exit_switches_the_outputs_off(server):
    script = (
        "from groundstation.instruments import open_generator\n"
        f"fg = open_generator({server.resource!r})\n"
        "fg.configure(1, frequency_hz=2.0, amplitude_vpp=0.5)\n"
        "fg.set_output(1, True)\n"
        "print(fg.get_output(1), flush=True)\n"
        "import sys; sys.exit(3)\n")               # no close(): exit must do it
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=60, cwd=ROOT, env={**os.environ, "PYTHONWARNINGS": "error"})
    assert out.returncode == 3, out.stderr
    assert out.stdout.strip() == "True"
    assert not server.generator.channels[1].on
    assert "OUTP OFF" in " ".join(server.generator.command_log)


# ------------------------------------------------------------------ arbitrary waveform upload


def test_upload_sends_a_binary_block_the_instrument_stores_and_plays(server):
    g, clock = server.generator, server.clock
    n = 1200
    volts = 0.6 * np.sin(2 * np.pi * np.arange(n) / n)
    volts[5] = 10 / spec.ARB_CODE_FULL_SCALE * 0.6    # code 10 = 0x000A: the terminator byte
    with open_generator(server.resource, testbed=INERTIAL) as fg:
        up = fg.upload_arbitrary(1, volts, name="TEST1", frequency_hz=1.0)
        assert up.points == n and up.amplitude_vpp == pytest.approx(1.2) and up.offset_v == 0
        assert np.array_equal(g.user_waves["TEST1"].codes, up.codes)
        assert up.codes[5] == 10 and up.codes.max() == spec.ARB_CODE_FULL_SCALE
        assert fg.arb_selection(1).name == "TEST1"
        wave = fg.basic_wave(1)
        assert (wave.waveform, wave.frequency_hz, wave.amplitude_vpp) == ("ARB", 1.0, pytest.approx(1.2))
        clock.now = 500
        fg.set_output(1, True)              # the waveform starts on the next period
        played = g.output_volts(1, 501, n)
        assert np.allclose(played, up.codes / spec.ARB_CODE_FULL_SCALE * 0.6)
        assert np.allclose(played, volts, atol=0.6 / 8191)
        assert "LENGTH,2400B" in " ".join(g.command_log)


def test_uploads_beyond_the_limits_are_refused_before_sending(server):
    g = server.generator
    with open_generator(server.resource, testbed=INERTIAL) as fg:
        sent = len(g.command_log)
        with pytest.raises(SafetyLimitError, match="2.4 Vpp"):
            fg.upload_arbitrary(1, [1.2, -1.2, 0.5], name="BIG", frequency_hz=1)
        with pytest.raises(InstrumentLimitError, match="16384"):
            fg.upload_arbitrary(1, np.zeros(16385) + 0.1, name="LONG", frequency_hz=1)
        with pytest.raises(InstrumentLimitError, match="name"):
            fg.upload_arbitrary(1, [0.1, -0.1], name="no spaces", frequency_hz=1)
        with pytest.raises(InstrumentLimitError, match="frequency 6e\\+06 Hz"):
            fg.upload_arbitrary(1, [0.1, -0.1], name="FAST", frequency_hz=6e6)
        assert not any("WVDT" in c for c in list(g.command_log)[sent:])
        assert g.user_waves == {}


def test_the_simulator_checks_uploads_itself():
    g = SimulatedGenerator()
    with ScpiServer(g) as srv, socket.create_connection(("127.0.0.1", srv.port), timeout=5) as s, \
            s.makefile("rb") as replies:
        def ask(text):
            s.sendall(text.encode() + b"\n")
            return replies.readline().decode().strip()
        good = np.array([0, 8191, 10, -8191], "<i2").tobytes()
        bad = np.array([0, 9000], "<i2").tobytes()
        s.sendall(b"C2:WVDT WVNM,W1,LENGTH,8B,WAVEDATA," + good + b"\n")
        s.sendall(b"C2:WVDT WVNM,W2,LENGTH,4B,WAVEDATA," + bad + b"\n")
        assert ask("*ESR?") == "16"
        assert ask("SYST:ERR?").startswith('-222,"Data out of range; samples')
        assert ask("SYST:ERR?") == '0,"No error"'
        assert list(g.user_waves) == ["W1"] and list(g.user_waves["W1"].codes) == [0, 8191, 10, -8191]
        assert ask("C2:ARWV NAME,W1;C2:ARWV?") == "C2:ARWV NAME,W1"
        assert ask("C3:BSWV?;*ESR?") == "32"          # no channel 3: command error


# ------------------------------------------------------------------ the simulated output


def test_simulated_waveforms_follow_the_device_clock():
    clock = Tick()
    g = SimulatedGenerator(tick_source=clock)
    g.handle_line("C1:BSWV WVTP,SINE,FRQ,10,AMP,1,OFST,0.1,PHSE,90;C1:OUTP ON")
    k = np.arange(240)
    v = g.output_volts(1, 1, 240)                       # starts at PHSE on tick 1
    assert np.allclose(v, 0.1 + 0.5 * np.sin(2 * np.pi * (10 * k / 1200 + 0.25)))
    assert np.array_equal(v, g.output_volts(1, 1, 240))  # same ticks, same volts
    clock.now = 240                                      # a frequency change keeps the phase
    g.handle_line("C1:BSWV FRQ,20")
    assert g.output_volts(1, 241, 1)[0] == pytest.approx(v[0], abs=1e-9)
    g.handle_line("C1:BSWV WVTP,SQUARE,PHSE,0")
    sq = g.output_volts(1, 241, 60)
    assert np.allclose(sq[:30], 0.6) and np.allclose(sq[30:], -0.4)
    g.handle_line("C1:BSWV WVTP,RAMP")
    ramp = g.output_volts(1, 241, 60)
    assert ramp[0] == pytest.approx(0.1) and ramp[15] == pytest.approx(0.6)
    assert ramp[45] == pytest.approx(-0.4)
    g.handle_line("C1:BSWV WVTP,DC,OFST,0.2;C1:OUTP LOAD,50")
    assert np.allclose(g.output_volts(1, 241, 5), 0.4)  # 50 ohm setting into high Z: x2
    g.handle_line("C1:OUTP OFF")
    assert not g.output_volts(1, 241, 5).any()
    assert g.base_drive(241, 3).shape == (3,)


def test_the_simulator_refuses_what_the_instrument_refuses():
    g = SimulatedGenerator()
    assert g.handle_line("C1:BSWV AMP,25;*ESR?;SYST:ERR?") == [
        "16", '-222,"Data out of range; AMP 25 (0.002..20 Vpp)"']
    reply = g.handle_line("C1:BSWV AMP,12;C1:OUTP LOAD,50;SYST:ERR?")
    assert reply[0].startswith('-221,"Settings conflict')
    assert g.handle_line("C1:BSWV WVTP,NOISE;SYST:ERR?")[0].startswith("-224")
    assert g.handle_line("C1:FOO 1;SYST:ERR?")[0].startswith("-113")
    assert g.handle_line("C1:BSWV?")[0].startswith("C1:BSWV WVTP,SINE,FRQ,1000HZ,PERI,0.001S,AMP,12V")
    for _ in range(25):
        g.handle_line("C1:FOO")
    errors = [g.handle_line("SYST:ERR?")[0] for _ in range(21)]
    assert errors[19] == '-350,"Queue overflow"' and errors[20] == '0,"No error"'


def test_a_socket_generator_sends_small_writes_at_once(server):
    """A checked setting is two small writes (the command, then *ESR?): with Nagle's
    algorithm on, the second waited for the instrument's delayed acknowledgement of the
    first (44 ms each, 0.18 s per base-motion upload).  The link's socket has it off."""
    with open_generator(server.resource, timeout_s=2.0) as fg:
        inst = fg._link.inst
        sock = inst.visalib.sessions[inst.session].interface
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
        fg.set_output(1, False)                    # and the link works as before
