"""The fast simulated testbed in a child process (sim/stepped_process.py): its control
channel, and what the parent hears when the child fails to start, dies or is left
behind.  That a session run through it writes the same log as the in-process device is
tests/campaign/test_campaign_speed.py's."""

from __future__ import annotations

import os
import select
import subprocess
import sys

import pytest

from groundstation import Testbed
from groundstation.station.options import FastSimOptions
from groundstation.core.errors import LinkError, LinkLostError
from groundstation.plant.testbed import TESTBEDS_DIR
from groundstation.sim.stepped_process import SteppedSimulatorProcess

TESTBED = TESTBEDS_DIR / "relative_2dof.toml"


@pytest.fixture
def child(dictionary):
    sim = SteppedSimulatorProcess(dictionary, testbed=TESTBED).start()
    yield sim
    sim.stop()


def test_the_child_steps_and_reports_the_ticks_it_ran(child):
    assert child.tcp_port and child.fg_resource is None
    assert child.step(10) == 10
    assert child.step(900, datagram_bytes=32768) == 910
    # nothing plays: a step that runs only while a profile plays runs nothing
    assert child.step(900, only_while_playing=True) is None
    child.run_ticks(5)
    assert child.step(1) == 916
    child.sync()
    assert not child.faulted
    proc = child.proc
    child.stop()                     # asked to end, it ends at once and says all is well
    assert proc.returncode == 0


def test_a_confirmation_period_is_reported_before_the_next_reply(child, dictionary):
    """Held between steps, a command that needs device time runs its period in the
    child, which reports it on the channel before it answers anything else."""
    from groundstation.link import open_client

    ran: list[int] = []
    child.hold_between_steps(ran.append, datagram_bytes=32768)
    client = open_client(dictionary, f"127.0.0.1:{child.tcp_port}", heartbeat=False)
    try:
        client.connect()
        before = child.step(1)
        seen = len(ran)
        client.command("SET_MODE", mode="OPEN_LOOP")      # raises unless COMPLETED
        child.sync()
        assert len(ran) == seen + 1 and ran[-1] == before + 1
    finally:
        client.close()
        child.hold_between_steps(None)


def test_a_testbed_the_child_cannot_load_is_named(dictionary, tmp_path):
    bad = tmp_path / "broken.toml"
    bad.write_text("[mechanics\n")
    with pytest.raises(LinkError, match="did not start.*broken.toml"):
        SteppedSimulatorProcess(dictionary, testbed=bad, start_timeout=60).start()


def test_a_child_that_died_is_reported_not_waited_for(child):
    child.proc.kill()
    child.proc.wait(timeout=10)
    with pytest.raises(LinkLostError, match="fast simulated testbed"):
        child.step(10)


def test_the_child_ends_when_the_ground_station_goes(tmp_path):
    """A ground station that dies without stopping it leaves no simulator running: the
    child ends when its control channel closes, which the kernel does for the dead."""
    script = tmp_path / "dies.py"
    script.write_text(
        "import os, sys\n"
        "from groundstation.core.dictionary import load_dictionary\n"
        "from groundstation.sim.stepped_process import SteppedSimulatorProcess\n"
        f"sim = SteppedSimulatorProcess(load_dictionary(), testbed={str(TESTBED)!r}).start()\n"
        "print(sim.proc.pid, flush=True)\n"
        "os._exit(3)\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 3, out.stderr
    pid = int(out.stdout.split()[0])
    # the orphan is no longer ours to wait for; a pidfd becomes readable when it exits
    try:
        pidfd = os.pidfd_open(pid)
    except ProcessLookupError:            # already gone and reaped
        return
    try:
        readable, _, _ = select.select([pidfd], [], [], 60)
        assert readable, "the orphaned simulator still runs a minute after its parent died"
    finally:
        os.close(pidfd)


def test_where_the_fast_simulator_runs_is_checked():
    with pytest.raises(ValueError, match="where must be one of inline, process"):
        Testbed("sim", testbed=TESTBED, fast=FastSimOptions(where="thread"))


def test_a_session_with_the_process_simulator_and_its_generator(tmp_path):
    """An inertial testbed gets the simulated generator in the child too: the session
    talks SCPI to it and the base stage moves the telemetry's base encoder."""
    with Testbed("sim", testbed=TESTBEDS_DIR / "inertial_2dof.toml", fast=FastSimOptions(where="process"),
                 log_folder=tmp_path) as tb:
        assert tb.generator is not None and tb.simulator.fg_resource
        tb.dwell(0.5)
        assert tb.state.tick >= 600


def test_the_log_names_the_simulators_seed(tmp_path):
    """A log of the simulated testbed says what it takes to run it again: its seed and
    its clock."""
    from groundstation.logs.reader import LogReader

    with Testbed("sim", testbed=TESTBED, fast=FastSimOptions(where="process"), seed=7,
                 log_folder=tmp_path) as tb:
        tb.start_recording("seeded")
        tb.dwell(0.1)
        path = tb.stop_recording()["files"][0]
    with LogReader(path) as log:
        records = [r.data for r in log.journal("testbed")]
    assert records == [{"device": "simulated testbed", "seed": 7, "clock": "script (fast)"}]
