"""`groundstation params show|rollback` keep each device's upload history apart: an upload
to one simulated device is never compared with another device's table (a new user saw
"NOT the device's active table" for a table that was sent to another simulator)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from groundstation.cli.main import main
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed
from groundstation.sim import SimulatedDevice
from groundstation.sim.firmware import Firmware

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"


def _device(dictionary, seed: int) -> SimulatedDevice:
    fw = Firmware(dictionary, seed=seed, testbed=load_testbed(TESTBEDS_DIR / "relative_2dof.toml"))
    return SimulatedDevice(dictionary, pacing="realtime", speed=4.0, firmware=fw).start()


@pytest.fixture
def two_rigs(dictionary):
    """Two simulators of the same testbed file: alike in GET_INFO, apart by address."""
    a = _device(dictionary, 4)
    try:
        b = _device(dictionary, 5)
    except BaseException:
        a.stop()
        raise
    yield a, b
    b.stop()
    a.stop()


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_show_compares_only_the_uploads_to_the_device_shown(two_rigs, tmp_path, capsys):
    a, b = two_rigs
    at_a, at_b = f"tcp://127.0.0.1:{a.tcp_port}", f"tcp://127.0.0.1:{b.tcp_port}"
    hist = str(tmp_path / "history")
    code, out, err = run(capsys, "params", "upload", str(CONTROLLERS / "relative_design2.toml"),
                         "--device", at_a, "--history", hist)
    assert code == 0, err
    uploaded = a.firmware.param_crc
    assert uploaded != b.firmware.param_crc

    # device B never got a table from here: its history is empty, A's upload not compared
    code, out, err = run(capsys, "params", "show", "--device", at_b, "--history", hist)
    assert code == 0, err
    assert "NOT the device's active table" not in out
    assert f"history of this device: {at_b} (simulated testbed:" in out
    assert "no upload from here to this device yet" in out
    assert "1 upload(s) to 1 other device(s), not compared" in out
    assert "rollback: nothing to roll back to" in out

    # device A: its own upload, which is its active table
    code, out, err = run(capsys, "params", "show", "--device", at_a, "--history", hist)
    assert code == 0, err
    assert f"last uploaded from here: {uploaded:08x}" in out
    assert "the device's active table" in out and "NOT the device's" not in out

    # the record says which device it went to
    record = json.loads((Path(hist) / "history.jsonl").read_text().splitlines()[0])
    assert record["device_address"] == at_a and record["device"].startswith("simulated testbed:")

    # rollback on B finds nothing of A's to roll back to; A's table stays on A
    code, out, err = run(capsys, "params", "rollback", "--device", at_b, "--history", hist)
    assert code == 1 and "nothing to roll back to" in err
    assert a.firmware.param_crc == uploaded


def test_records_from_before_the_per_device_history_are_not_compared(two_rigs, tmp_path, capsys):
    a, _ = two_rigs
    hist = tmp_path / "history"
    hist.mkdir()
    # a record as written before the history named its device (no device_address)
    old = {"time": 0.0, "source": "old.toml", "version": 1, "crc": 0x12345678,
           "previous_crc": a.firmware.param_crc, "activated_tick": 0, "device": "",
           "notes": [], "validated": True, "override_reason": "", "validation_problems": [],
           "accepted_risk": ""}
    (hist / "history.jsonl").write_text(json.dumps(old) + "\n")
    code, out, err = run(capsys, "params", "show", "--device", f"tcp://127.0.0.1:{a.tcp_port}",
                         "--history", str(hist))
    assert code == 0, err
    assert "NOT the device's active table" not in out
    assert "1 older upload(s) name no device and are not compared" in out
