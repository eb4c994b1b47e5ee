"""`groundstation identify --report DIR`: the identification as files - the text, the
JSON, the figures as PNG and one self-contained HTML page (identification/figures.py,
identification/html.py) - written only when the identification succeeds.

The logs are short open-loop excitations recorded on the simulated reference rig (as
test_identify_round_trip.py records them, shorter: the report's files are checked here,
not the fit's accuracy).  One log is copied to a name with HTML's special characters, so
the page must escape what it shows.  The hysteresis figure is drawn from loops made here
as plain data in the shape the friction fit's `loop_curves()` gives."""

from __future__ import annotations

import base64
import contextlib
import io
import json
import re
import shutil
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from groundstation.cli.main import main
from identification_helpers import record_sysid_logs
from groundstation.identification.figures import (friction_loops, hysteresis_figure,
                                                  png_bytes)
from groundstation.identification.html import write_report
from groundstation.identification.pipeline import identify

ROOT = Path(__file__).resolve().parents[2]
BASE = ROOT / "profiles/testbeds/relative_2dof.toml"
RECORD_S = 4.0
#: a log's name with the characters HTML gives a meaning to: shown, never interpreted
AWKWARD_NAME = "fine <run&1>.h5"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: a drawn figure, not an empty canvas: every figure here holds several panels of data
MIN_PNG_BYTES = 20_000


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("identify_report_logs")
    recorded = record_sysid_logs(BASE, folder, RECORD_S)
    awkward = folder / AWKWARD_NAME
    shutil.copyfile(recorded[1], awkward)
    return [Path(recorded[0]), awkward]


def run(argv: list[str]) -> tuple[int, str, str]:
    """The command's exit status, standard output and standard error."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(argv)
    return status, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def report(logs, tmp_path_factory):
    """The report folder of one identification without --out."""
    folder = tmp_path_factory.mktemp("identify_report") / "report"
    status, out, err = run(["identify", *map(str, logs), "--testbed", str(BASE),
                            "--report", str(folder)])
    assert status == 0, out + err
    return {"folder": folder, "out": out}


def check_png(data: bytes) -> None:
    """A whole PNG: signature, a header of a sizeable image, the end chunk."""
    assert data[:8] == PNG_SIGNATURE
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    assert width >= 300 and height >= 300, (width, height)
    assert data[-8:-4] == b"IEND"
    assert len(data) > MIN_PNG_BYTES, len(data)


def test_the_report_folder_holds_the_text_the_json_the_figures_and_the_page(report):
    folder = report["folder"]
    names = {p.name for p in folder.iterdir()}
    assert {"identification.txt", "identification.json", "identification.html",
            "identification.responses.png", "identification.residuals.png"} <= names
    assert f"report: {(folder / 'identification.html').resolve()}" in report["out"]
    text = (folder / "identification.txt").read_text(encoding="utf-8")
    assert text.startswith("identified from 2 of 2 log(s), base relative_2dof.toml")
    assert text.strip() in report["out"]                  # the text printed, word for word
    doc = json.loads((folder / "identification.json").read_text(encoding="utf-8"))
    assert doc["written"] == "" and doc["parameters"]
    for png in folder.glob("*.png"):
        check_png(png.read_bytes())


def test_the_page_is_self_contained_and_shows_every_parameter(report):
    folder = report["folder"]
    page = (folder / "identification.html").read_text(encoding="utf-8")
    doc = json.loads((folder / "identification.json").read_text(encoding="utf-8"))
    # nothing is fetched from anywhere: no script, no style sheet, every image inline
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:|//)""", page, re.I)
    assert "<script" not in page.lower() and "<link" not in page.lower()
    assert "url(" not in page.lower()
    sources = re.findall(r'<img[^>]*\ssrc="([^"]*)"', page)
    pngs = {p.read_bytes() for p in folder.glob("*.png")}
    assert len(sources) == len(pngs) >= 2
    for src in sources:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1]) in pngs    # the files' own drawing
    # the figures of the JSON, in the page
    assert BASE.name in page
    for p in doc["parameters"]:
        row = re.search(rf'<tr( class="held")?><td class="text">{re.escape(p["name"])}</td>', page)
        assert row, p["name"]
        assert (row.group(1) is not None) == p["status"].startswith("held"), p
    assert any(p["status"].startswith("held") for p in doc["parameters"])
    assert f"{doc['reduced_chi_square']:.3g}" in page
    for u in doc["logs"]:
        assert Path(u["path"]).name.replace("&", "&amp;").replace("<", "&lt;").replace(
            ">", "&gt;") in page
    # what the page shows is escaped, never markup
    assert "fine &lt;run&amp;1&gt;.h5" in page and AWKWARD_NAME not in page


def test_the_report_names_the_testbed_file_written_beside_it(logs, tmp_path):
    rig = tmp_path / "my_rig.toml"
    status, out, err = run(["identify", *map(str, logs), "--testbed", str(BASE),
                            "--out", str(rig), "--report", str(tmp_path / "report")])
    assert status == 0, out + err
    assert rig.is_file()
    page = (tmp_path / "report" / "identification.html").read_text(encoding="utf-8")
    assert f"written: {rig.resolve()}" in page
    text = (tmp_path / "report" / "identification.txt").read_text(encoding="utf-8")
    assert f"written: {rig.resolve()}" in text


def test_a_failing_identification_writes_no_report(logs, tmp_path):
    """Logs of another kind of rig: exit 1, and the report folder is neither made nor
    filled."""
    other = ROOT / "profiles/testbeds/inertial_2dof.toml"
    status, _, err = run(["identify", *map(str, logs), "--testbed", str(other),
                          "--report", str(tmp_path / "new")])
    assert status == 1 and "nothing written" in err
    assert not (tmp_path / "new").exists()
    (tmp_path / "kept").mkdir()
    status, _, _ = run(["identify", *map(str, logs), "--testbed", str(other),
                        "--report", str(tmp_path / "kept")])
    assert status == 1 and not list((tmp_path / "kept").iterdir())


def test_a_report_folder_that_cannot_be_made_is_refused_before_the_fit(logs, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder\n")
    status, out, err = run(["identify", *map(str, logs), "--testbed", str(BASE),
                            "--report", str(blocker / "report")])
    assert status == 2
    assert "cannot make the report folder" in err and "a_file is not a folder" in err
    assert out == ""                                      # refused before identifying


# ---------------------------------------------------------------------- friction loops
@dataclass(frozen=True)
class Loop:
    """One loop in the shape of the friction fit's loop_curves() items."""
    source: str
    angle_rad: np.ndarray
    measured_in_oz: np.ndarray
    base_in_oz: np.ndarray
    identified_in_oz: np.ndarray


@dataclass(frozen=True)
class Loops:
    loops: tuple

    def loop_curves(self) -> list:
        return list(self.loops)


@dataclass(frozen=True)
class WithFriction:
    """An identification result that carries a friction fit."""
    plain: object
    friction: Loops | None

    def __getattr__(self, name):
        return getattr(self.plain, name)


def presliding_loop(source: str, amplitude_rad: float, coulomb_in_oz: float) -> Loop:
    """A Dahl-like loop: torque rising from the last reversal toward +-coulomb."""
    t = np.linspace(0.0, 2.0 * np.pi, 400)
    angle = amplitude_rad * np.sin(t)
    rising = np.cos(t) > 0
    since = np.where(rising, angle + amplitude_rad, amplitude_rad - angle)
    shape = np.where(rising, 1.0, -1.0) * (1.0 - 2.0 * np.exp(-since / (0.3 * amplitude_rad)))
    return Loop(source, angle, coulomb_in_oz * shape + 0.05 * np.cos(7 * t),
                0.8 * coulomb_in_oz * shape, coulomb_in_oz * shape)


LOOPS = (presliding_loop("hyst_a.h5", 40e-6, 2.0), presliding_loop("hyst_b.h5", 80e-6, 2.5))


def test_the_hysteresis_figure_draws_each_loop_with_both_models():
    fig = hysteresis_figure(list(LOOPS))
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in shown] == ["hyst_a.h5", "hyst_b.h5"]
    for ax, loop in zip(shown, LOOPS):
        assert [ln.get_label() for ln in ax.get_lines()] == ["measured", "base model",
                                                             "identified model"]
        assert ax.get_xlabel() == "bearing angle (µrad)"     # a presliding loop's scale
        assert ax.get_ylabel() == "friction torque (in-oz)"
        np.testing.assert_allclose(ax.get_lines()[2].get_xdata(), loop.angle_rad * 1e6)
        np.testing.assert_allclose(ax.get_lines()[2].get_ydata(), loop.identified_in_oz)
    check_png(png_bytes(fig))


def test_the_loops_come_from_the_friction_fit_when_there_is_one():
    assert friction_loops(WithFriction(None, Loops(LOOPS))) == list(LOOPS)
    assert friction_loops(WithFriction(None, None)) == []
    assert friction_loops(object()) == []            # an identification before friction


def test_a_report_with_a_friction_fit_adds_the_hysteresis_figure(logs, tmp_path):
    result = WithFriction(identify(logs, BASE), Loops(LOOPS))
    paths = write_report(result, tmp_path / "report")
    assert tmp_path / "report" / "identification.hysteresis.png" in paths
    check_png((tmp_path / "report" / "identification.hysteresis.png").read_bytes())
    page = paths[-1].read_text(encoding="utf-8")
    assert page.count('src="data:image/png;base64,') == 3
    assert "Friction loops and both friction models" in page
