"""Faults of the generator link and settings that change together (issue 13).

* Any I/O failure - a backend that cannot take a message (pyvisa-sim and the binary block
  of an arbitrary waveform), a reply that is not text, a reply that is not a number, no
  reply at all - reaches the caller as one GroundStationError line naming the command and
  what to check; the CLI prints `error: ...`, exits 2, and the outputs end up off.
* A change of load and amplitude in one command is checked against the NEW load, and the
  two SCPI commands go in the order the instrument (and, with the output on, the stage)
  accepts.

Instruments: pyvisa-sim (tests/fg_sim.yaml, a fresh copy per test) and the simulated
generator's SCPI server, whose replies a test can replace (`ScpiServer.inject_reply`).
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from groundstation.cli.main import main
from groundstation.core.errors import GroundStationError
from groundstation.instruments import (InstrumentError, InstrumentLimitError,
                                       InstrumentLinkError, SafetyLimitError, open_generator)
from groundstation.sim.scpi_server import ScpiServer
from groundstation.sim.fg_instrument import SimulatedGenerator
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

ROOT = Path(__file__).resolve().parents[2]
YAML = Path(__file__).resolve().parents[1] / "fg_sim.yaml"
SIM_RESOURCE = "USB0::0xF4ED::0xEE3A::SIM4053B::INSTR"
GARBLED_RESOURCE = "USB0::0xF4ED::0xEE3A::SIMGARBLED::INSTR"
BM1 = str(ROOT / "profiles" / "base_motion" / "BM1.csv")
INERTIAL = load_testbed(TESTBEDS_DIR / "inertial_2dof.toml")


@pytest.fixture
def yaml_copy(tmp_path) -> str:
    """A definitions file of its own: pyvisa-sim keeps one instrument state per file and
    process, so the CLI and the test see the same simulated instrument through it."""
    path = tmp_path / "fg_sim.yaml"
    shutil.copyfile(YAML, path)
    return str(path)


@pytest.fixture
def server():
    srv = ScpiServer(SimulatedGenerator()).start()
    yield srv
    srv.stop()


def _set_channel(srv, ch=1, **state):
    """Put the simulated instrument in a state (as from its front panel)."""
    g = srv.generator
    with g.lock:
        g.channels[ch] = replace(g.channels[ch], **state)


def _one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    return lines[0]


def _sent(srv, since: int) -> list[str]:
    return list(srv.generator.command_log)[since:]


# ------------------------------------------------------------------ I/O failures


def test_upload_through_pyvisa_sim_is_one_error_line_with_the_outputs_off(yaml_copy, capsys):
    """pyvisa-sim decodes every message as UTF-8, so the binary samples of WVDT used to
    end in a UnicodeDecodeError traceback.  Now: refused before sending, one line, exit 2,
    and a channel that was left on (front panel) is off afterwards."""
    import pyvisa

    rm = pyvisa.ResourceManager(yaml_copy + "@sim")
    inst = rm.open_resource(SIM_RESOURCE, read_termination="\n", write_termination="\n")
    try:
        inst.write("C1:BSWV WVTP,SINE,FRQ,2,AMP,0.5,OFST,0,PHSE,0")
        inst.write("C1:OUTP ON,LOAD,HZ")
        assert inst.query("C1:OUTP?").startswith("ON")
        rc = main(["fg", "upload", "--resource", SIM_RESOURCE, "--backend", yaml_copy,
                   "--profile", BM1, "--duration", "10"])
        line = _one_error_line(capsys.readouterr().err)
        assert rc == 2
        assert "pyvisa-sim" in line and "nothing was sent" in line and "--resource sim" in line
        assert inst.query("C1:OUTP?").startswith("OFF")
        assert inst.query("C2:OUTP?").startswith("OFF")
    finally:
        inst.close()


def test_the_driver_refuses_a_pyvisa_sim_upload_before_sending(yaml_copy):
    with open_generator(SIM_RESOURCE, backend=yaml_copy, testbed=INERTIAL) as fg:
        before = fg.query("C1:ARWV?"), fg.query("C1:BSWV?")
        with pytest.raises(InstrumentLinkError, match="cannot carry the binary samples"):
            fg.upload_arbitrary(1, [0.1, -0.1, 0.05], name="W1", frequency_hz=1.0)
        assert (fg.query("C1:ARWV?"), fg.query("C1:BSWV?")) == before
        assert fg.query("*ESR?") == "0"              # nothing half-sent reached it


def test_a_reply_that_is_not_text_is_a_link_error_and_the_session_goes_on(server):
    server.inject_reply("C1:BSWV?", b"C1:BSWV WVTP,SINE,AMP,\xff\xfeV\n")
    with open_generator(server.resource, testbed=INERTIAL, timeout_s=2.0) as fg:
        since = len(server.generator.command_log)
        with pytest.raises(InstrumentLinkError) as err:
            fg.configure(1, amplitude_vpp=0.5)
        text = str(err.value)
        assert "query 'C1:BSWV?' failed: the reply is not text" in text
        assert "\n" not in text and "check the cable" in text
        assert not any(c.startswith("C1:BSWV ") for c in _sent(server, since))
        assert fg.get_output(1) is False            # the next exchange is in step
        server.clear_faults()
        assert fg.configure(1, frequency_hz=2.0, amplitude_vpp=0.5).amplitude_vpp == 0.5


def test_pyvisa_sim_replies_that_cannot_be_read(yaml_copy):
    """Channel 1 answers OUTP? with a non-ASCII byte, channel 2 a frequency of 1e999."""
    with open_generator(GARBLED_RESOURCE, backend=yaml_copy, testbed=INERTIAL) as fg:
        with pytest.raises(InstrumentLinkError, match=r"C1:OUTP\?' failed: the reply is not text"):
            fg.get_load(1)
        with pytest.raises(InstrumentLinkError, match="not text"):
            fg.set_output(1, True)
        with pytest.raises(InstrumentError, match=r"C2:BSWV\?.*not a finite number"):
            fg.get_frequency(2)


def test_cli_on_a_reply_that_is_not_text_exits_2_with_the_outputs_off(server, capsys):
    _set_channel(server, 1, frequency_hz=2.0, amplitude_vpp=0.5, on=True)
    server.inject_reply("C1:BSWV?", b"\x80\x81\x82\n")
    rc = main(["fg", "set", "--resource", server.resource, "--amplitude", "0.4",
               "--timeout", "2"])
    line = _one_error_line(capsys.readouterr().err)
    assert rc == 2 and "C1:BSWV?" in line and "not text" in line
    assert not server.generator.channels[1].on and not server.generator.channels[2].on


def test_cli_identify_on_garbled_pyvisa_sim_replies_exits_2(yaml_copy, capsys):
    rc = main(["fg", "identify", "--resource", GARBLED_RESOURCE, "--backend", yaml_copy])
    capsys.readouterr()
    assert rc == 2


def test_an_unanswered_query_is_a_timeout_line_and_nothing_is_switched_on(server):
    _set_channel(server, 1, frequency_hz=2.0, amplitude_vpp=0.5)
    server.inject_reply("C1:OUTP?", None)               # hangs on this query only
    with open_generator(server.resource, testbed=INERTIAL, timeout_s=0.3) as fg:
        with pytest.raises(InstrumentLinkError) as err:
            fg.set_output(1, True)
        assert "query 'C1:OUTP?' failed: no answer within 0.3 s" in str(err.value)
        assert "--timeout" in str(err.value)
        assert not server.generator.channels[1].on
        assert not any(c.startswith("C1:OUTP ON") for c in server.generator.command_log)


def test_a_status_reply_that_is_not_a_number_is_an_instrument_error(server):
    with open_generator(server.resource, testbed=INERTIAL, timeout_s=2.0) as fg:
        server.inject_reply("*ESR?", b"inf\n")
        with pytest.raises(InstrumentError, match=r"unexpected \*ESR\? reply 'inf'.*read the "
                                                  r"channel back"):
            fg.configure(1, frequency_hz=2.0, amplitude_vpp=0.5)
        server.inject_reply("*ESR?", b"\xfe\n")
        with pytest.raises(InstrumentLinkError, match=r"\*ESR\?' failed: the reply is not text"):
            fg.configure(1, frequency_hz=2.0, amplitude_vpp=0.5)


def test_an_error_queue_reply_that_is_not_text_still_reports_the_refusal(server):
    with open_generator(server.resource, testbed=INERTIAL, timeout_s=2.0) as fg:
        server.inject_reply("SYST:ERR?", b"-222,\"\xb5\"\n")
        with pytest.raises(InstrumentError) as err:
            fg.select_arbitrary(1, index=42)         # out of range: the instrument refuses
        assert "ARWV INDEX,42" in str(err.value) and "reply is not text" in str(err.value)


@pytest.mark.parametrize("timeout", [float("nan"), 0.0, -1.0, float("inf")])
def test_an_unusable_timeout_is_refused_before_opening(server, timeout):
    with pytest.raises(InstrumentLinkError, match="timeout must be a number of seconds"):
        open_generator(server.resource, timeout_s=timeout)
    assert not server.generator.command_log


def test_every_driver_error_is_a_groundstation_error():
    for cls in (InstrumentError, InstrumentLinkError, InstrumentLimitError, SafetyLimitError):
        assert issubclass(cls, GroundStationError)


# ------------------------------------------------------------------ load and amplitude together


@pytest.mark.parametrize("instrument", ["pyvisa-sim", "scpi-server"])
def test_cli_amplitude_and_load_from_power_on(instrument, yaml_copy, server, capsys):
    """Power-on: 4 Vpp (above the testbed's 2 Vpp).  `--amplitude 1 --load HZ` asks for
    1 Vpp at the amplifier: allowed (it used to be refused: the load step was checked
    with the old 4 Vpp)."""
    where = (["--resource", SIM_RESOURCE, "--backend", yaml_copy] if instrument == "pyvisa-sim"
             else ["--resource", server.resource])
    rc = main(["fg", "set", *where, "--amplitude", "1", "--load", "HZ"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "amp 1 Vpp" in out and "(high-Z)" in out


def test_cli_from_a_50_ohm_state_to_high_impedance_sends_the_load_first(server, capsys):
    """4 Vpp into '50 ohm' (8 V at the amplifier, output off) -> 1 Vpp into high Z: the
    new amplitude is checked with the new load, the load goes first (4 Vpp into high Z is a
    state the instrument takes, and the output is off)."""
    _set_channel(server, 1, load="50")
    since = len(server.generator.command_log)
    rc = main(["fg", "set", "--resource", server.resource, "--amplitude", "1", "--load", "HZ"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    c = server.generator.channels[1]
    assert (c.amplitude_vpp, c.load) == (1.0, "HZ")
    settings = [x for x in _sent(server, since) if not x.endswith("?") and x.startswith("C1:")]
    assert settings[0] == "C1:OUTP OFF,LOAD,HZ" and settings[1].startswith("C1:BSWV ")


def test_cli_a_new_amplitude_is_checked_against_the_new_load(server, capsys):
    """1.5 Vpp is fine into high Z, but into '50 ohm' it is 3 V at the amplifier."""
    _set_channel(server, 1, frequency_hz=2.0, amplitude_vpp=0.5)
    rc = main(["fg", "set", "--resource", server.resource, "--amplitude", "1.5", "--load", "50"])
    line = _one_error_line(capsys.readouterr().err)
    assert rc == 2 and "3 Vpp at the amplifier" in line and "nothing was sent" in line
    c = server.generator.channels[1]
    assert (c.amplitude_vpp, c.load) == (0.5, "HZ")     # the amplitude was not sent either


def _settings_sent(srv, since):
    return [c.split()[0] + " " + ("LOAD" if "LOAD" in c else "BSWV") for c in _sent(srv, since)
            if c.startswith("C1:") and not c.endswith("?")]


@pytest.mark.parametrize("start, change, order", [
    # only valid into high Z: the instrument refuses 15 Vpp at 50 ohm, so the load goes first
    (dict(amplitude_vpp=8.0, load="50"), dict(amplitude_vpp=15.0, load="HZ"), ["LOAD", "BSWV"]),
    # only valid at the old amplitude: 15 Vpp cannot go to 50 ohm, so the wave goes first
    (dict(amplitude_vpp=15.0, load="HZ"), dict(amplitude_vpp=8.0, load=50), ["BSWV", "LOAD"]),
])
def test_the_order_is_one_the_instrument_accepts(server, start, change, order):
    """Without testbed limits: the simulated instrument refuses a BSWV outside the set
    load's range and a load change that leaves the amplitude outside it."""
    _set_channel(server, 1, frequency_hz=2.0, **start)
    with open_generator(server.resource, timeout_s=2.0) as fg:
        since = len(server.generator.command_log)
        fg.configure(1, **change)
        assert [s.split()[1] for s in _settings_sent(server, since)] == order
        assert fg.get_amplitude(1) == change["amplitude_vpp"]
        assert fg.get_load(1) == str(change["load"])
        assert fg.query("*ESR?") == "0"


@pytest.mark.parametrize("start, change, order", [
    # output on, 0.9 Vpp into 50 ohm (1.8 V at the amplifier) -> 1.8 Vpp into high Z:
    # wave first would pass through 1.8 Vpp into 50 ohm = 3.6 V; load first passes 0.9 V
    (dict(amplitude_vpp=0.9, load="50"), dict(amplitude_vpp=1.8, load="HZ"), ["LOAD", "BSWV"]),
    # and back: load first would pass through 1.8 Vpp into 50 ohm
    (dict(amplitude_vpp=1.8, load="HZ"), dict(amplitude_vpp=0.9, load="50"), ["BSWV", "LOAD"]),
])
def test_with_the_output_on_the_state_in_between_stays_within_the_testbed_limits(server, start,
                                                                                  change, order):
    _set_channel(server, 1, frequency_hz=2.0, on=True, **start)
    with open_generator(server.resource, testbed=INERTIAL, timeout_s=2.0) as fg:
        since = len(server.generator.command_log)
        fg.configure(1, **change)
        assert [s.split()[1] for s in _settings_sent(server, since)] == order
        c = server.generator.channels[1]
        assert c.on and (c.amplitude_vpp, c.load) == (change["amplitude_vpp"], change["load"])


def test_no_safe_order_with_the_output_on_is_refused(server):
    """Front panel left 5 Vpp into 50 ohm ON (10 V at the amplifier): to 1.5 Vpp into high
    Z, either order passes through a state beyond the 2 Vpp limit."""
    _set_channel(server, 1, frequency_hz=2.0, amplitude_vpp=5.0, load="50", on=True)
    with open_generator(server.resource, testbed=INERTIAL, timeout_s=2.0) as fg:
        since = len(server.generator.command_log)
        with pytest.raises(SafetyLimitError, match="switch the output off first; nothing was sent"):
            fg.configure(1, amplitude_vpp=1.5, load="HZ")
        assert _settings_sent(server, since) == []
        fg.set_output(1, False)
        fg.configure(1, amplitude_vpp=1.5, load="HZ")       # output off: allowed
        assert (server.generator.channels[1].amplitude_vpp, server.generator.channels[1].load) \
            == (1.5, "HZ")


def test_a_load_change_alone_is_checked_with_the_present_wave(server):
    """Power-on 4 Vpp into high Z: `--load HZ` alone keeps 4 Vpp, which the testbed does
    not allow; the refusal says that the amplitude is the channel's present one."""
    with open_generator(server.resource, testbed=INERTIAL, timeout_s=2.0) as fg:
        with pytest.raises(SafetyLimitError, match="present amplitude: give a new one"):
            fg.set_load(1, "50")
        fg.configure(1, amplitude_vpp=0.5, offset_v=0.05, load=50)
        c = server.generator.channels[1]
        assert (c.amplitude_vpp, c.offset_v, c.load) == (0.5, 0.05, "50")
        # offset and amplitude together are checked against the new load as well:
        # 0.15 V into 50 ohm is 0.3 V at the amplifier, beyond the 0.2 V limit
        with pytest.raises(SafetyLimitError, match="offset 0.3 V"):
            fg.configure(1, amplitude_vpp=0.3, offset_v=0.15)
        fg.configure(1, amplitude_vpp=0.3, offset_v=0.15, load="HZ")
        assert (c := server.generator.channels[1]).offset_v == 0.15 and c.load == "HZ"
