"""The command line's consoles: `monitor --watch`, `record --watch` (a normal log that
`log check` and replay accept), `--publish` refused beyond loopback without keys, and
`fanout keys` with CURVE: only an authorised viewer hears the publisher."""

from __future__ import annotations

import threading

import pytest

from groundstation.cli.main import main
from groundstation.fanout.endpoints import FanoutError
from groundstation.fanout.publisher import Publisher
from groundstation.fanout.viewer import WatchClient
from groundstation.link import open_client
from groundstation.logs import LogReader
from groundstation.logs.check import check_log
from groundstation.sim import SimulatedDevice

from conftest import wait_for


@pytest.fixture
def rig(dictionary):
    """A real-time simulated device, a commander with a session, publishing."""
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=3).start()
    client = open_client(dictionary, f"127.0.0.1:{dev.tcp_port}")
    client.connect()
    pub = Publisher("tcp://127.0.0.1:*")
    pub.attach(client, f"127.0.0.1:{dev.tcp_port}")
    yield dev, client, pub
    pub.close()
    client.close()
    dev.stop()


def test_monitor_watch_prints_the_viewers_own_link_statistics(rig, capsys):
    _, _, pub = rig
    assert main(["monitor", "--watch", pub.endpoint, "--duration", "1.2", "--interval", "0.4"]) == 0
    out = capsys.readouterr().out
    assert f"watching {pub.endpoint} (read-only)" in out and "device tcp://127.0.0.1:" in out
    assert "HIGH_RATE" in out and "drop=0" in out and "commander: up" in out


def test_record_watch_writes_a_normal_log_with_the_commanders_journal(rig, tmp_path, capsys):
    dev, client, pub = rig

    done = threading.Event()

    def commander_works():                      # the commanding station goes on meanwhile
        while not done.wait(0.2):
            client.command("SET_MODE", mode="OPEN_LOOP")

    worker = threading.Thread(target=commander_works)
    worker.start()
    try:
        code = main(["record", "--watch", pub.endpoint, "--folder", str(tmp_path), "--name",
                     "watched", "--duration", "2.0"])
    finally:
        done.set()
        worker.join(10.0)
    assert code == 0
    out = capsys.readouterr().out
    assert "recording to" in out and "duration of 2 s reached" in out
    (path,) = sorted(tmp_path.glob("*.h5"))
    assert check_log(path).exit_code == 0
    with LogReader(path) as log:
        assert log.n_frames("HIGH_RATE") > 1000
        commands = [r.data["name"] for r in log.journal(["command"])]
        notes = [r.data.get("text", "") for r in log.journal(["note"])]
    assert any("(read-only)" in n for n in notes)
    # commands sent after the recording began are in the viewer's journal
    assert "SET_MODE" in commands and "HEARTBEAT" not in commands
    from groundstation.logs import ReplaySource
    src = ReplaySource(path, dictionary=None, speed=None)
    blocks = []
    src.subscribe(blocks.append)
    src.play()
    wait_for(lambda: sum(len(b) for b in blocks if b.name == "HIGH_RATE") > 1000, timeout=20.0)
    src.close()


def test_publish_beyond_loopback_needs_keys(capsys):
    code = main(["monitor", "--publish", "tcp://0.0.0.0:5999", "--device", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert code == 2
    assert "anyone on the network" in err and "--curve-keys DIR" in err
    assert "groundstation fanout keys DIR" in err
    with pytest.raises(FanoutError, match="tcp://127.0.0.1:PORT"):
        Publisher("tcp://*:5999")


def test_curve_keys_admit_only_the_labs_viewers(dictionary, tmp_path, capsys):
    lab, stranger = tmp_path / "lab", tmp_path / "stranger"
    assert main(["fanout", "keys", str(lab), "--name", "alice"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["fanout", "keys", str(stranger), "--name", "eve"]) == 0
    assert (lab / "authorized" / "alice.public").exists()
    assert oct((lab / "alice.secret").stat().st_mode)[-3:] == "600"
    with pytest.raises(FanoutError, match="exists"):
        from groundstation.fanout.keys import make_keys
        make_keys(lab, "alice")

    # the stranger's viewer trusts the right publisher key but is not authorised
    (stranger / "publisher.public").write_bytes((lab / "publisher.public").read_bytes())
    with Publisher("tcp://127.0.0.1:*", curve_keys=str(lab), hello_period_s=0.05) as pub:
        with WatchClient(dictionary, pub.endpoint, curve_keys=str(lab), key_name="alice") as ok:
            ok.wait_up(10.0)
        with WatchClient(dictionary, pub.endpoint, curve_keys=str(stranger), key_name="eve") as no:
            with pytest.raises(FanoutError, match="authorized/ folder"):
                no.wait_up(1.0)
        # nor does a plain (unencrypted) subscriber hear anything - and it is told why
        with WatchClient(dictionary, pub.endpoint) as plain:
            with pytest.raises(FanoutError, match="requires CURVE keys"):
                plain.wait_up(1.0)


def test_a_campaign_publishes_for_watching_consoles(dictionary, tmp_path, capsys):
    """`campaign run --publish`: a console watching the campaign's station sees its
    telemetry and its commands; a wider address without keys is refused before anything
    runs."""
    import socket
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    campaign = str(root / "profiles" / "campaigns" / "relative_steps.toml")
    code = main(["campaign", "run", campaign, "--fast", "--publish", "tcp://0.0.0.0:5998",
                 "--log-folder", str(tmp_path / "refused")])
    assert code == 2 and "--curve-keys DIR" in capsys.readouterr().err
    with socket.socket() as s:                  # a free loopback port for the publisher
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    endpoint = f"tcp://127.0.0.1:{port}"
    seen, commands, result = [], [], {}
    viewer = WatchClient(dictionary, endpoint).start()
    viewer.subscribe(lambda b: seen.append(len(b)) if b.name == "HIGH_RATE" else None)
    viewer.add_command_listener(lambda r: commands.append(r.name))
    runner = threading.Thread(target=lambda: result.setdefault("code", main(
        ["campaign", "run", campaign, "--fast", "--publish", endpoint, "--max-step-seconds", "2",
         "--log-folder", str(tmp_path / "logs"), "--no-analysis"])))
    runner.start()
    try:
        runner.join(300.0)
    finally:
        viewer.close()
    assert not runner.is_alive() and result["code"] == 0
    assert sum(seen) > 1000                       # the runs' telemetry, decoded by the viewer
    assert "UPLOAD_COMMIT" in commands or "ARM" in commands


def test_a_watch_says_when_the_commanders_session_ends_and_why_it_closes(rig, dictionary):
    """After the commander closes its device link, a watching console says so in words -
    not "commander's link closed: " with nothing after it, nor "commander: up" from a
    stale hello - and its own end has a reason ("watch closed: " was empty)."""
    from groundstation.fanout.commands import status_line

    _, client, pub = rig
    remote, own = [], []
    viewer = WatchClient(dictionary, pub.endpoint)
    viewer.add_remote_listener(lambda state, message: remote.append((state, message)))
    viewer.add_link_listener(lambda state, message: own.append((state, message)))
    viewer.start()
    try:
        viewer.wait_up(timeout=10)
        assert "commander: up" in status_line(viewer)
        client.close()                       # the commander's session ends
        wait_for(lambda: any(state == "closed" for state, _ in remote), timeout=10)
        assert all(message for _, message in remote), remote
        pub.detach()                         # and it publishes hellos with no device link
        wait_for(lambda: "no device link" in status_line(viewer), timeout=10)
    finally:
        viewer.close()
    assert own[-1] == ("closed", "this console stopped watching")
