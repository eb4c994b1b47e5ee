"""design_writer: a design written as a design file and read back by load_design gives the
same transfer functions; factors from roots; what is refused and left untouched."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from groundstation.params.design_file import load_design
from groundstation.params.design_writer import (Factored, controller_problems, design_text,
                                                factor_text, factored,
                                                transfer_function_mismatch, write_design)
from groundstation.params.loop import validate
from groundstation.params.tf_algebra import DesignError, TransferFunction

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"
SHIPPED = sorted(CONTROLLERS.glob("*.toml"))


def same_roots(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.sort_complex(np.asarray(a, complex)), np.sort_complex(np.asarray(b, complex))
    return len(a) == len(b) and bool(np.all(np.abs(a - b) <= 1e-9 * np.maximum(np.abs(a), 1.0)))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_every_shipped_design_round_trips(path, tmp_path):
    design = load_design(path)
    out = tmp_path / "sub" / path.name
    out.parent.mkdir()
    back = write_design(design, out)
    assert back.path == out.resolve()
    assert transfer_function_mismatch(design, back) < 1e-12
    for key in ("c0", "c1", "c2"):
        assert same_roots(design.cascades[key].zeros, back.cascades[key].zeros)
        assert same_roots(design.cascades[key].poles, back.cascades[key].poles)
        assert back.cascades[key].gain == pytest.approx(design.cascades[key].gain, rel=1e-14)
        assert back.cascades[key].integrators == design.cascades[key].integrators
    assert (back.q is None) == (design.q is None)
    for field in ("name", "description", "mode", "saturation_coarse_in_oz", "saturation_fine_in_oz",
                  "anti_windup", "outer_loop_gain_per_s", "prewarp_hz", "friction"):
        assert getattr(back, field) == getattr(design, field), field
    assert back.testbed.path == design.testbed.path


def test_an_output_equivalent_c0_is_written_as_equivalent_to(tmp_path):
    design = load_design(CONTROLLERS / "relative_design1.toml")
    assert design.c0_equivalent_to is not None
    back = write_design(design, tmp_path / "eq.toml", c0_equivalent_to=design.c0_equivalent_to)
    assert "equivalent_to =" in (tmp_path / "eq.toml").read_text()
    assert back.c0_equivalent_to == design.c0_equivalent_to
    assert transfer_function_mismatch(design, back) == 0.0
    with pytest.raises(DesignError, match="itself"):
        design_text(design, design.c0_equivalent_to, c0_equivalent_to=design.c0_equivalent_to)


def test_paths_are_relative_beside_the_shipped_files(tmp_path):
    design = load_design(CONTROLLERS / "relative_design1_friction_comp.toml")
    text = design_text(design, CONTROLLERS / "not_written.toml")
    assert 'testbed = "../testbeds/relative_2dof.toml"' in text
    assert 'slope_table = "../friction_slope_lut.csv"' in text
    # elsewhere the file names the testbed so that it loads from where it is written,
    # wherever this checkout and the temporary folder are
    elsewhere = tmp_path / "x.toml"
    elsewhere.write_text(design_text(design, elsewhere))
    assert load_design(elsewhere).testbed.path == design.testbed.path


def test_a_path_sharing_only_the_root_is_written_absolute():
    from groundstation.core.tomlfile import relative_path
    assert relative_path(Path("/srv/lab/testbeds/a.toml"), Path("/home/op/designs")) == "/srv/lab/testbeds/a.toml"
    assert relative_path(Path("/srv/lab/testbeds/a.toml"), Path("/srv/lab/designs")) == "../testbeds/a.toml"


def test_factors_from_roots():
    tf = TransferFunction(np.array([-1 + 2j, -5, -1 - 2j, 0]), np.array([-3 - 4j, -3 + 4j, 0, -7]), 2.5)
    f = factored(tf)
    assert f.gain == 2.5
    assert f.numerator == ((2.0, 5.0), (5.0,), (0.0,))
    assert f.denominator == ((6.0, 25.0), (0.0,), (7.0,))
    back = f.transfer_function()
    assert back.integrators == 1 and same_roots(back.zeros, tf.zeros) and same_roots(back.poles, tf.poles)
    assert factor_text((60.27,)) == "(s+60.27)" and factor_text((0.0,)) == "s"
    assert factor_text((25.92, 86100.0)) == "(s^2+25.92s+86100)"
    with pytest.raises(DesignError, match="conjugate"):
        factored(TransferFunction(np.array([-1 + 2j]), np.zeros(0, complex), 1.0))


def test_an_edited_design_round_trips_and_validates(tmp_path):
    design = load_design(CONTROLLERS / "relative_design2.toml")
    q = factored(design.q)
    edited_q = Factored(q.gain * 1.3, q.numerator, q.denominator).transfer_function()
    edited = replace(design, c1=edited_q, q=edited_q)
    back = write_design(edited, tmp_path / "edited.toml", name="Relative Design #2, Q x 1.3")
    assert back.name == "Relative Design #2, Q x 1.3"
    assert transfer_function_mismatch(edited, back) < 1e-12
    assert transfer_function_mismatch(design, back) > 0.2
    assert validate(back).ok


def test_what_load_design_refuses_is_not_written(tmp_path):
    design = load_design(CONTROLLERS / "relative_design2.toml")
    improper = Factored(1.0, ((10.0,), (20.0,)), ((30.0,),)).transfer_function()
    bad = replace(design, c1=improper, q=improper)
    assert any("proper" in p for p in controller_problems(bad))
    out = tmp_path / "kept.toml"
    out.write_text("what was there\n")
    with pytest.raises(DesignError, match="proper"):
        write_design(bad, out)
    assert out.read_text() == "what was there\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.toml"]   # no temporary left
    with pytest.raises(DesignError, match="finite"):
        design_text(replace(design, saturation_fine_in_oz=float("nan")), out)
