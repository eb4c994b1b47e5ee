"""Issue 13: a controller root at the bilinear map's singular point is refused with a
message (no scipy traceback), and `params show` and `params rollback` give the same
account of where the device's active table came from."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from groundstation.cli.main import main
from groundstation.params.tf_algebra import DesignError, TransferFunction
from groundstation.params.discretise import bilinear_singular_point, discretise
from groundstation.params.design_file import load_design
from groundstation.params.upload import ParameterHistory
from groundstation.sim import SimulatedDevice
from groundstation.sim.firmware import Firmware
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

ROOT = Path(__file__).resolve().parents[2]
CONTROLLERS = ROOT / "profiles" / "controllers"
TESTBED = TESTBEDS_DIR / "relative_2dof.toml"


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def design_file(tmp_path, *, c0_num="[[36.28]]", c0_den="[[108.8], [300.0]]", prewarp=None,
                q=None, name="singular.toml") -> Path:
    ratio = (f"[Q]\ngain = 1.0\nnumerator = {q[0]}\ndenominator = {q[1]}\n" if q else
             "[c1]\ngain = 1.0\n\n[c2]\ngain = 1.0\n")
    path = tmp_path / name
    path.write_text(f'''[design]
name = "singular"
mode = "relative"
testbed = "{TESTBED}"
{f"prewarp_hz = {prewarp!r}" if prewarp else ""}

[saturation]
coarse_in_oz = 81.3
fine_in_oz = 16.1

[friction_compensation]
enabled = false

[c0]
gain = 3000.0
numerator = {c0_num}
denominator = {c0_den}

{ratio}''')
    return path


# ------------------------------------------------------------------- singular point
def test_the_singular_point_is_the_one_the_map_uses():
    assert bilinear_singular_point(1200.0) == 2400.0
    wp = 2 * np.pi * 46.70
    assert bilinear_singular_point(1200.0, 46.70) == pytest.approx(wp / np.tan(wp / 2400.0), rel=1e-15)
    assert bilinear_singular_point(1200.0, 46.70) < 2400.0            # 2388.03 rad/s


def test_a_pole_at_2fs_is_refused_with_the_factor_named(tmp_path, capsys):
    path = design_file(tmp_path, c0_den="[[108.8], [-2400.0]]")
    code, out, err = run(capsys, "params", "validate", path)
    assert code == 2 and "Traceback" not in err
    assert err.startswith(f"error: {path}: cannot be discretised: [c0]: the denominator factor "
                          f"(s-2400) puts a pole at s = 2400 rad/s"), err
    assert "s = 2/T = 2 fs' = 2400 rad/s (plain Tustin at fs = 1200 Hz)" in err
    assert "z = infinity" in err


def test_an_all_pass_factor_at_2fs_is_refused(tmp_path, capsys):
    path = design_file(tmp_path, c0_num="[[-2400.0]]", c0_den="[[2400.0]]")
    code, out, err = run(capsys, "params", "validate", path)
    assert code == 2 and "Traceback" not in err
    assert "[c0]: the numerator factor (s-2400) puts a zero at s = 2400 rad/s" in err
    assert "gain becomes zero" in err


def test_prewarping_moves_the_singular_point(tmp_path, capsys):
    point = bilinear_singular_point(1200.0, 46.70)
    # in Q (c1'), pre-warped: the point the map really uses is refused ...
    path = design_file(tmp_path, prewarp=46.70, q=("[[10.0]]", f"[[100.0], [{-point!r}]]"))
    with pytest.raises(DesignError, match=re.escape("[Q] (c1' = Q): the denominator factor (s-2388.03)")):
        load_design(path)
    code, out, err = run(capsys, "params", "validate", path)
    assert code == 2 and f"2 fs' = {point:.10g} rad/s (pre-warped at 46.7 Hz" in err
    # ... and 2400 rad/s is not singular there: validated (and refused as an unstable
    # controller pole, which it is), no crash
    path = design_file(tmp_path, prewarp=46.70, c0_den="[[108.8], [-2400.0]]", name="b.toml")
    code, out, err = run(capsys, "params", "validate", path)
    assert code == 1 and "controller itself is unstable (s = +2400 rad/s)" in out and err == ""


def test_discretise_itself_refuses_the_singular_point():
    tf = TransferFunction.from_factors(1.0, [[10.0]], [[-2400.0], [5.0]])
    with pytest.raises(DesignError, match=r"c0: the denominator factor \(s-2400\)"):
        discretise(tf, 1200.0, None, "c0")
    sos = discretise(TransferFunction.from_factors(1.0, [[10.0]], [[-2399.0], [5.0]]), 1200.0)
    assert np.all(np.isfinite(sos))                   # near it, but not on it: a (bad) filter


def test_the_shipped_designs_are_not_affected(capsys):
    for path in sorted(CONTROLLERS.glob("*.toml")):
        load_design(path)


# ------------------------------------------------------------------- show vs rollback
@pytest.fixture
def rig(dictionary):
    fw = Firmware(dictionary, seed=4, testbed=load_testbed(TESTBED))
    dev = SimulatedDevice(dictionary, pacing="realtime", speed=4.0, firmware=fw).start()
    yield dev
    dev.stop()


def show(capsys, address, hist):
    code, out, err = run(capsys, "params", "show", "--device", address, "--history", hist)
    assert code == 0, err
    active = re.search(r"^active (table \w+: .*)$", out, re.M).group(1)
    target = re.search(r"^rollback would re-activate (\w+)$", out, re.M)
    return out, active, target.group(1) if target else None


def test_show_and_rollback_agree_to_the_end_of_the_history(rig, tmp_path, capsys):
    address = f"tcp://127.0.0.1:{rig.tcp_port}"
    hist = tmp_path / "history"
    original = rig.firmware.param_crc
    crcs = []
    for name in ("relative_design1.toml", "relative_design2.toml"):
        code, out, err = run(capsys, "params", "upload", CONTROLLERS / name, "--device", address,
                             "--history", hist)
        assert code == 0, err
        crcs.append(rig.firmware.param_crc)
    d1, d2 = crcs
    out, active, target = show(capsys, address, hist)
    assert f"last uploaded from here: {d2:08x}" in out and "the device's active table" in out
    assert target == f"{d1:08x}"
    # every rollback does what show said it would
    for expected in (d1, original):
        code, _, err = run(capsys, "params", "rollback", "--device", address, "--history", hist)
        assert code == 0, err
        assert f"{rig.firmware.param_crc:08x}" == target == f"{expected:08x}"
        out, active, target = show(capsys, address, hist)
    # the original table: show says a rollback from here put it there, and that nothing is
    # left to roll back to; rollback says the same thing, not "not uploaded from here"
    assert target is None and "rollback: nothing to roll back to" in out
    assert active.startswith(f"table {original:08x}: put there from here at ")
    assert f"by rollback from {d1:08x} to {original:08x}" in active
    assert f"last uploaded from here: {original:08x}" in out
    code, _, err = run(capsys, "params", "rollback", "--device", address, "--history", hist)
    assert code == 1 and rig.firmware.param_crc == original
    assert "not uploaded from here" not in err
    assert err.startswith("error: nothing further to roll back to: ")
    assert active in err                              # the very account show gave
    assert len(ParameterHistory(hist).records()) == 4    # the refused rollback recorded nothing


def test_uploading_the_active_table_again_does_not_block_rollback(rig, tmp_path, capsys):
    address = f"tcp://127.0.0.1:{rig.tcp_port}"
    hist = tmp_path / "history"
    original = rig.firmware.param_crc
    for _ in range(2):                               # the second upload changes nothing
        code, _, err = run(capsys, "params", "upload", CONTROLLERS / "relative_design2.toml",
                           "--device", address, "--history", hist)
        assert code == 0, err
    out, _, target = show(capsys, address, hist)
    assert target == f"{original:08x}"
    code, _, err = run(capsys, "params", "rollback", "--device", address, "--history", hist)
    assert code == 0, err
    assert rig.firmware.param_crc == original


def test_device_sim_says_that_each_command_gets_a_new_simulator(tmp_path, capsys):
    """`--device sim` starts a simulated testbed per command: each is another device, so
    show does not compare it with the upload that went to the previous one (histories are
    per device), and rollback says why there is nothing to roll back."""
    hist = tmp_path / "history"
    code, out, err = run(capsys, "params", "upload", CONTROLLERS / "relative_design2.toml",
                         "--device", "sim", "--history", hist)
    assert code == 0, err
    uploaded = ParameterHistory(hist).records()[-1]
    code, out, err = run(capsys, "params", "show", "--device", "sim", "--history", hist)
    assert code == 0, err
    assert f"{uploaded.crc:08x}" not in out.split("parameter ")[0]    # not claimed for this one
    assert ("no upload from here to this device yet: nothing to compare with (the history "
            "holds 1 upload(s) to 1 other device(s), not compared)") in out
    assert "new simulated testbed for this command" in out
    code, out, err = run(capsys, "params", "rollback", "--device", "sim", "--history", hist)
    assert code == 1
    assert "was not uploaded from here, and no upload from here replaced it" in err
    assert "new simulated testbed for this command" in err
