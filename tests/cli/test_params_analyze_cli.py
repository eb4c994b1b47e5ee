"""`groundstation params analyze`: the PQ numbers printed, the figure written, errors named."""

from __future__ import annotations

from pathlib import Path

from groundstation.cli.main import main

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_analyze_prints_ti0_margins_alignment_and_saturation(capsys):
    code, out, err = run(capsys, "params", "analyze", str(CONTROLLERS / "relative_design1.toml"),
                         "--freqs", "1,14")
    assert code == 0, err
    assert "T_I(0):   [[1, 0], [13.9, 0]]" in out
    assert "margins:  sampled loop broken at e: gain margin" in out
    assert "PQ:       |PQ| = 1 at" in out
    assert "alignment phi (deg" in out and "Q = 1 on the same plant" in out
    assert "under a 2.25 in-oz step into u1:" in out
    fine = next(line for line in out.splitlines() if line.strip().startswith("u2 (fine, VCM)"))
    assert "SATURATES" in fine                     # 13.9 x 2.25 in-oz > 16.1 in-oz


def test_analyze_against_writes_a_png(capsys, tmp_path):
    png = tmp_path / "pq.png"
    code, out, err = run(capsys, "params", "analyze", str(CONTROLLERS / "inertial_design1.toml"),
                         "--against", str(CONTROLLERS / "inertial_design2.toml"),
                         "--plot", str(png), "--duration", "0.2",
                         "--disturbance", "sine:u1:1:14")
    assert code == 0, err
    assert "T_I(0):   [[1, 0], [27.5, 0]]" in out and "T_I(0):   [[1, 0], [0, 0]]" in out
    assert "#2 Inertial Design #2" in out
    assert "under a 1 in-oz sine at 14 Hz into u1:" in out
    assert "UNSTABLE" in out                       # the reference's inertial loop, as validate says
    assert f"figure:   {png}" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 50_000


def test_analyze_refuses_what_it_cannot_read(capsys, tmp_path):
    code, _, err = run(capsys, "params", "analyze", str(CONTROLLERS / "rigid_pid.toml"))
    assert code == 2 and "needs a 2-DOF testbed" in err
    code, _, err = run(capsys, "params", "analyze", str(CONTROLLERS / "relative_design2.toml"),
                       "--disturbance", "step:u3:1")
    assert code == 2 and "--disturbance" in err and "step:u1|u2:IN_OZ" in err
    code, _, err = run(capsys, "params", "analyze", str(CONTROLLERS / "relative_design2.toml"),
                       "--freqs", "1,x")
    assert code == 2 and "--freqs" in err
    code, _, err = run(capsys, "params", "analyze", str(tmp_path / "missing.toml"))
    assert code == 2 and "missing.toml" in err


def test_a_design_that_leaves_the_fine_motor_unused(capsys, tmp_path):
    """c2' = 0: Q is infinite; phi is the angle between G and u1 alone, no warnings."""
    design = tmp_path / "coarse_only.toml"
    design.write_text(f'''
[design]
name = "coarse only"
mode = "relative"
testbed = "{(CONTROLLERS.parent / 'testbeds' / 'relative_2dof.toml').as_posix()}"
[saturation]
coarse_in_oz = 81.3
fine_in_oz = 16.1
[friction_compensation]
enabled = false
[c0]
gain = 2000.0
numerator = [[3.0], [3.0]]
denominator = [[0], [60.0]]
[c1]
gain = 1.0
[c2]
gain = 0.0
''')
    png = tmp_path / "coarse.png"
    code, out, err = run(capsys, "params", "analyze", str(design), "--plot", str(png))
    assert code == 0, err
    assert "c2' = 0: the fine motor is not used" in out
    assert png.stat().st_size > 50_000
