"""The identified testbed file (identification/testbed_file.py): the base text with the
values put in and an [identification] block; it loads; a second identification replaces
the block; a value the base file has no line for is refused with nothing written; and
`params analyze --testbed` shows what the identified plant does to a shipped design."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from groundstation.cli.main import main
from groundstation.identification.testbed_file import (Provenance, TestbedWriteError,
                                                       write_identified)
from groundstation.plant.testbed import load_testbed

ROOT = Path(__file__).resolve().parents[2]
BASE = load_testbed(ROOT / "profiles/testbeds/relative_2dof.toml")
SOFTER = {"mechanics.flexure_stiffness": 23144.0, "mechanics.J1": 0.5702}
PROVENANCE = [Provenance("mechanics.flexure_stiffness", "in-oz/rad", 26300.0, 23144.0,
                         (23100.0, 23190.0), "identified", "", ("a.h5",)),
              Provenance("mechanics.J1", "in-oz-s^2", 0.528, 0.5702, (0.5699, 0.5705),
                         "identified", "", ("a.h5",))]


def test_the_file_keeps_the_base_text_and_says_where_each_value_came_from(tmp_path):
    out = tmp_path / "sub" / "rig.toml"
    out.parent.mkdir()
    tb = write_identified(BASE, SOFTER, PROVENANCE, out, name="lab rig", logs=["a.h5"])
    assert tb.name == "lab rig" and tb.mechanics["flexure_stiffness"] == 23144.0
    assert tb.mechanics["J2"] == BASE.mechanics["J2"]                # untouched values stay
    assert tb.slope_table_path == BASE.slope_table_path              # re-aimed from sub/
    text = out.read_text()
    assert "flexure_stiffness = 23144.0" in text and "# identified (base 26300.0)" in text
    assert "[assumed]" in text                                       # the base's own sections
    doc = tomllib.loads(text)["identification"]
    assert doc["logs"] == ["a.h5"]
    assert doc["parameter"][0]["ci95"] == [23100.0, 23190.0]
    # identified again from this file: one [identification] block, the new one
    again = write_identified(tb, {"mechanics.J2": 0.7}, PROVENANCE[:1], tmp_path / "rig2.toml",
                             name="lab rig, again")
    doc2 = tomllib.loads((tmp_path / "rig2.toml").read_text())
    assert again.mechanics["flexure_stiffness"] == 23144.0 and again.mechanics["J2"] == 0.7
    assert len(doc2["identification"]["parameter"]) == 1


def test_a_value_without_a_line_is_refused_and_nothing_is_written(tmp_path):
    out = tmp_path / "rig.toml"
    with pytest.raises(TestbedWriteError, match="no line for mechanics.J3"):
        write_identified(BASE, {"mechanics.J3": 1.0}, [], out, name="x")
    assert not out.exists() and not list(tmp_path.iterdir())


def test_params_analyze_shows_a_design_on_the_identified_plant(tmp_path, capsys):
    rig = tmp_path / "rig.toml"
    write_identified(BASE, SOFTER, PROVENANCE, rig, name="lab rig")
    design = ROOT / "profiles/controllers/relative_design2.toml"
    assert main(["params", "analyze", str(design), "--testbed", str(rig)]) == 0
    out = capsys.readouterr().out
    margins = [line for line in out.splitlines() if line.startswith("margins:")]
    assert len(margins) == 2 and margins[0] != margins[1]
    assert "Relative Design #2 on lab rig" in out
    assert main(["params", "analyze", str(design), "--testbed", str(tmp_path / "nope.toml")]) == 2
    assert "--testbed" in capsys.readouterr().err
