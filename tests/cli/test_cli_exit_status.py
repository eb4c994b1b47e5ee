"""One exit status for a device that cannot be reached, whatever the command: 2 (it could
not start; nothing was sent), with the reason on stderr - `monitor` and `record` said 2,
`params`, `profile` and `campaign` said 1."""

import socket

import pytest

from groundstation.cli.main import main

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
PROFILES = ROOT / "profiles"


@pytest.fixture
def refusing_address():
    """tcp://127.0.0.1:PORT where a socket is bound but not listening: every connect is
    refused at once, and no other program can take the port meanwhile."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        yield f"tcp://127.0.0.1:{s.getsockname()[1]}"


COMMANDS = {
    "monitor": ["monitor", "--duration", "1"],
    "record": ["record", "--duration", "1"],
    "params show": ["params", "show"],
    "params upload": ["params", "upload", str(PROFILES / "controllers" / "relative_design1.toml")],
    "params rollback": ["params", "rollback"],
    "profile play": ["profile", "play", str(PROFILES / "waveforms" / "friction_triangle_0p01deg.toml")],
    "campaign run": ["campaign", "run", str(PROFILES / "campaigns" / "relative_steps.toml")],
}


@pytest.mark.parametrize("name", list(COMMANDS))
def test_an_unreachable_device_is_exit_status_2_with_the_reason(name, refusing_address, tmp_path,
                                                                 monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)           # whatever a command would write lands here
    args = COMMANDS[name] + ["--device", refusing_address]
    if name == "record":
        args += ["--folder", str(tmp_path / "logs")]
    if name == "campaign run":
        args += ["--log-folder", str(tmp_path / "logs")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "connection refused" in err and "Traceback" not in err
    assert not list(tmp_path.rglob("*.h5"))          # and no empty log left behind
