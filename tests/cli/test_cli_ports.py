"""Ports the user chooses: the `[HOST:]PORT` argument type (loopback unless a host is
given), the local Dask cluster's scheduler and dashboard ports, and a taken port
refused with a specific message and exit status 2 (docs/exit_statuses.md) - the Dask
scheduler's, the simulator child's."""

from __future__ import annotations

import argparse
import socket

import pytest

from groundstation.cli.arguments import listen_address
from groundstation.cli.station import EXIT_CANNOT_START, status_for
from groundstation.core.errors import GroundStationError, PortInUseError


@pytest.fixture
def taken_port():
    """A loopback TCP port another program listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("text, want", [
    ("8786", ("127.0.0.1", 8786)),            # a port alone: this host only
    ("0", ("127.0.0.1", 0)),                  # any free port
    ("0.0.0.0:8786", ("0.0.0.0", 8786)),
    ("lab-head:9000", ("lab-head", 9000)),
    ("[::1]:8786", ("::1", 8786)),
])
def test_a_listen_address_is_port_or_host_and_port(text, want):
    assert listen_address(text) == want


@pytest.mark.parametrize("text, message", [
    ("abc", "must be PORT or HOST:PORT (e.g. 8786 or 0.0.0.0:8786), not 'abc'"),
    ("host:", "must be PORT or HOST:PORT"),
    ("70000", "the port must be 0 (any free port) .. 65535, not 70000"),
    ("-1", "the port must be 0 (any free port) .. 65535, not -1"),
    (":8786", "no host before the ':' in ':8786'"),
])
def test_a_bad_listen_address_says_what_it_must_be(text, message):
    with pytest.raises(argparse.ArgumentTypeError, match="^" + message.replace("(", r"\(")
                       .replace(")", r"\)").replace(".", r"\.").replace("[", r"\[")):
        listen_address(text)


def test_argparse_refuses_it_with_status_2(capsys):
    p = argparse.ArgumentParser(prog="groundstation analyze")
    p.add_argument("--scheduler-port", type=listen_address)
    with pytest.raises(SystemExit) as exit_:
        p.parse_args(["--scheduler-port", "99999"])
    assert exit_.value.code == 2
    assert "--scheduler-port: the port must be 0 (any free port) .. 65535, not 99999" in capsys.readouterr().err


def test_a_taken_port_is_status_2():
    assert status_for(PortInUseError("TCP port 5020 on 127.0.0.1 is already in use")) == EXIT_CANNOT_START


def test_a_taken_scheduler_port_is_refused_before_any_process_starts(taken_port):
    from groundstation.analysis.batch_dask import dask_client

    with pytest.raises(PortInUseError, match=f"TCP port {taken_port} on 127.0.0.1 is already in use "
                                             f"- choose another port for the local Dask scheduler"):
        with dask_client("local", 1, listen=("127.0.0.1", taken_port)):
            pytest.fail("a cluster was started on a taken port")


def test_ports_for_another_cluster_are_refused():
    from groundstation.analysis.batch_dask import dask_client

    with pytest.raises(GroundStationError, match="the cluster at tcp://head:8786 has its own"):
        with dask_client("tcp://head:8786", listen=("127.0.0.1", 9000)):
            pytest.fail("connected")


def test_the_dashboard_and_the_scheduler_need_two_ports(monkeypatch):
    import sys
    import types

    from groundstation.analysis.batch_dask import dask_client

    monkeypatch.setitem(sys.modules, "bokeh", types.ModuleType("bokeh"))   # as if installed
    with pytest.raises(GroundStationError, match="both given port 9000 on 127.0.0.1: give them two ports"):
        with dask_client("local", 1, listen=("127.0.0.1", 9000), dashboard=("127.0.0.1", 9000)):
            pytest.fail("started")


def test_the_local_cluster_listens_where_asked():
    from groundstation.analysis.batch_dask import dask_client

    port = free_port()
    with dask_client("local", 1, listen=("127.0.0.1", port)) as client:
        assert client.scheduler.address == f"tcp://127.0.0.1:{port}"
        assert client.submit(sum, [1, 2]).result(timeout=60) == 3
        # no dashboard: the scheduler's few HTTP routes on a port the system chose, not
        # on distributed's 8787 that another cluster on this host may hold
        assert client.scheduler_info()["services"].get("dashboard") not in (8787, port)
    with socket.socket() as s:         # given back when the cluster closed (a server may
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)    # bind past TIME_WAIT)
        s.bind(("127.0.0.1", port))
        s.listen()


def test_the_simulator_child_on_a_taken_port_says_so(taken_port):
    from groundstation.sim.process import SimulatorProcess

    with pytest.raises(PortInUseError) as err:
        SimulatorProcess(tcp_port=taken_port, start_timeout=60).start()
    assert str(err.value).startswith(f"the simulated testbed cannot listen on 127.0.0.1:{taken_port}: "
                                     "the port (TCP, or the UDP port of the same number its telemetry "
                                     "leaves from) is in use by another program - choose another port")


# ---------------------------------------------------------------- through the commands
def test_monitor_starts_the_simulator_on_the_chosen_port(capsys):
    from groundstation.cli.main import main
    port = free_port()
    assert main(["monitor", "--device", "sim", "--sim-port", str(port), "--duration", "0.5"]) == 0
    assert f"started the simulated testbed on tcp://127.0.0.1:{port}" in capsys.readouterr().out


def test_a_command_on_a_taken_simulator_port_exits_2_naming_it(taken_port, capsys):
    from groundstation.cli.main import main
    code = main(["params", "show", "--device", "sim", "--sim-port", str(taken_port)])
    err = capsys.readouterr().err
    assert code == EXIT_CANNOT_START and str(taken_port) in err


def test_a_chosen_port_with_the_fast_simulator_is_refused(tmp_path, capsys):
    """The fast simulator is the campaign's own, on a private link: a port for it would be
    a promise nobody keeps."""
    from pathlib import Path
    from groundstation.cli.main import main
    campaign = Path(__file__).resolve().parents[2] / "profiles/campaigns/relative_steps.toml"
    code = main(["campaign", "run", str(campaign), "--device", "sim", "--fast", "--sim-port",
                 str(free_port()), "--log-folder", str(tmp_path), "--no-analysis"])
    assert code == EXIT_CANNOT_START
    assert "--sim-port" in capsys.readouterr().err


def test_cluster_ports_with_the_serial_loop_are_refused(tmp_path, capsys):
    from groundstation.cli.main import main
    code = main(["analyze", str(tmp_path), "--serial", "--scheduler-port", "0"])
    assert code == 2 and "for the local cluster" in capsys.readouterr().err
