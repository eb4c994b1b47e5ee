"""The Station's parts: the grouped options (fast simulator, console publishing) and the
GeneratorDesk that its generator verbs hand their work to."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from groundstation import ScriptError, Testbed
from groundstation.core.kinds import BetweenSteps, FastSim
from groundstation.plant.testbed import load_testbed
from groundstation.station.clock import FastPacing, SteppedClock
from groundstation.station.generator_desk import GeneratorDesk
from groundstation.station.options import ConsolePublishing, FastSimOptions
from groundstation.station.recording import RecordingSlot

ROOT = Path(__file__).resolve().parents[2]
TESTBEDS = ROOT / "profiles" / "testbeds"


def test_fast_sim_options_take_words_and_check_them():
    options = FastSimOptions(where="process", between_steps="realtime")
    assert options.where is FastSim.PROCESS and options.between_steps is BetweenSteps.REALTIME
    assert options.where == "process"                       # a member is its word
    assert FastSimOptions() == FastSimOptions(FastSim.INLINE, None, BetweenSteps.HELD)
    with pytest.raises(ValueError, match="FastSimOptions.where must be one of inline, process, not 'thread'"):
        FastSimOptions(where="thread")
    with pytest.raises(ValueError, match="between_steps must be one of held, realtime"):
        FastSimOptions(between_steps="paused")
    with pytest.raises(TypeError, match="FastPacing"):
        FastSimOptions(pacing=4)
    with pytest.raises(ValueError, match="needs an endpoint"):
        ConsolePublishing("")


def test_the_station_refuses_what_is_not_an_option():
    with pytest.raises(TypeError, match="FastSimOptions"):
        Testbed("sim", fast="process")
    with pytest.raises(TypeError, match="ConsolePublishing"):
        Testbed("sim", publishing="tcp://127.0.0.1:*")


def test_the_fast_options_reach_the_clock(tmp_path):
    pacing = FastPacing(in_flight=2, datagram_bytes=0)
    with Testbed("sim", testbed=TESTBEDS / "relative_2dof.toml", generator=None, log_folder=tmp_path,
                 fast=FastSimOptions(pacing=pacing, between_steps="realtime")) as tb:
        assert isinstance(tb.clock, SteppedClock)
        assert tb.clock.pacing is pacing and tb.clock.between_steps == BetweenSteps.REALTIME
        tb.dwell(0.1)
        assert tb.state.tick >= 100


def test_a_published_session_serves_its_link_to_consoles(tmp_path):
    with Testbed("sim", testbed=TESTBEDS / "relative_2dof.toml", fast=True, generator=None,
                 log_folder=tmp_path, publishing=ConsolePublishing("tcp://127.0.0.1:*")) as tb:
        assert tb.publisher is not None and tb.publisher.endpoint.startswith("tcp://127.0.0.1:")
    assert tb.publisher is None                              # closed with the session


class _Generator:
    """Notes what the desk asks of an instrument."""

    def __init__(self):
        self.calls: list[tuple] = []

    def configure(self, channel, **settings):
        self.calls.append(("configure", channel, settings))

    def set_output(self, channel, on):
        self.calls.append(("output", channel, on))

    def describe(self, channel):
        return f"channel {channel}"

    def abort(self):
        self.calls.append(("abort",))


def test_the_generator_desk_acts_on_the_generator_its_owner_holds_now():
    held: list = [None]
    said: list[str] = []
    desk = GeneratorDesk(lambda: held[0], load_testbed(TESTBEDS / "inertial_2dof.toml"),
                         RecordingSlot(said.append), said.append)
    with pytest.raises(ScriptError, match="generator_set: no function generator"):
        desk.set(1, waveform="SINE", frequency_hz=1.0, amplitude_vpp=0.1)
    desk.off()                                               # nothing to switch off: no error
    held[0] = gen = _Generator()                             # the owner opened one since
    desk.set(2, waveform="SQUARE", frequency_hz=3.0, amplitude_vpp=0.2, output=False)
    desk.off()
    assert gen.calls == [("configure", 2, {"waveform": "SQUARE", "frequency_hz": 3.0,
                                           "amplitude_vpp": 0.2, "offset_v": 0.0, "phase_deg": 0.0}),
                         ("output", 2, False), ("abort",)]
    assert said == ["generator: channel 2"]


def test_closing_a_session_with_a_generator_closes_it_without_an_error(tmp_path, caplog):
    with caplog.at_level(logging.ERROR, logger="groundstation.station.station"):
        with Testbed("sim", testbed=TESTBEDS / "inertial_2dof.toml", fast=True, generator="sim",
                     log_folder=tmp_path) as tb:
            gen = tb.generator
            tb.generator_set(1, waveform="SINE", frequency_hz=2.0, amplitude_vpp=0.3)
            assert gen.get_output(1)
    assert gen.closed and tb.generator is None
    assert not [r for r in caplog.records if "closing the session" in r.getMessage()]
