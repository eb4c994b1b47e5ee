"""`groundstation params upload|show|rollback` against a simulated device on loopback."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation.cli.main import main
from groundstation.params import table as ptable
from groundstation.params.design_file import load_design, table_values
from groundstation.params.upload import ParameterHistory
from groundstation.sim import SimulatedDevice
from groundstation.sim.firmware import Firmware
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"


@pytest.fixture
def rig(dictionary):
    fw = Firmware(dictionary, seed=4, testbed=load_testbed(TESTBEDS_DIR / "relative_2dof.toml"))
    dev = SimulatedDevice(dictionary, pacing="realtime", speed=4.0, firmware=fw).start()
    yield dev
    dev.stop()


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_upload_show_rollback(rig, dictionary, tmp_path, capsys):
    address = f"tcp://127.0.0.1:{rig.tcp_port}"
    hist = str(tmp_path / "history")
    original = rig.firmware.param_crc
    design_file = CONTROLLERS / "relative_design2.toml"
    code, out, err = run(capsys, "params", "upload", str(design_file), "--device", address,
                         "--history", hist)
    assert code == 0, err
    assert "verified: table" in out and "OK: the table may be sent" in out
    expected = table_values(load_design(design_file), base=ptable.default_values(dictionary),
                            dictionary=dictionary)
    assert rig.firmware.param_blob == ptable.pack(dictionary, expected)
    assert [r.crc for r in ParameterHistory(hist).records()] == [rig.firmware.param_crc]

    code, out, err = run(capsys, "params", "show", "--device", address, "--history", hist,
                         "--against", str(CONTROLLERS / "relative_design1.toml"), "--differences")
    assert code == 0, err
    assert f"active table {rig.firmware.param_crc:08x}" in out
    assert "relative_c0" in out and "DIFFERS: design" in out
    assert "outer_loop_gain" not in out                       # equal everywhere: not listed

    code, out, err = run(capsys, "params", "rollback", "--device", address, "--history", hist)
    assert code == 0, err
    assert rig.firmware.param_crc == original


def test_refused_design_sends_nothing(rig, dictionary, tmp_path, capsys):
    """The thesis's inertial designs are marginally unstable on the reference's model
    with K_p = 25 (see docs/controllers.md): refused before anything is sent."""
    address = f"tcp://127.0.0.1:{rig.tcp_port}"
    before = rig.firmware.param_blob
    code, out, err = run(capsys, "params", "upload", str(CONTROLLERS / "inertial_design2.toml"),
                         "--device", address, "--history", str(tmp_path))
    assert code == 1
    assert "closed loop is unstable" in out and "nothing was sent" in err
    assert rig.firmware.param_blob == before
    bad = tmp_path / "broken.toml"
    bad.write_text("[design]\nname = 'x'\n")
    code, out, err = run(capsys, "params", "upload", str(bad), "--device", address)
    assert code == 2 and "broken.toml" in err
    code, out, err = run(capsys, "params", "rollback", "--device", address, "--history", str(tmp_path / "none"))
    assert code == 1 and "nothing to roll back to" in err
