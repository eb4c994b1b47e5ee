"""`campaign run --testbed FILE`: the same campaign on another testbed file (issue 28: the
inertial campaign bracketed by the section 6.2 and the appendix inertias), checked
against that file before anything runs, and recorded in every log."""

from __future__ import annotations

import tomllib
from pathlib import Path

from groundstation.cli.main import main
from groundstation.logs import LogReader

ROOT = Path(__file__).resolve().parents[2]
TESTBEDS = ROOT / "profiles" / "testbeds"
CAMPAIGNS = ROOT / "profiles" / "campaigns"


def short_inertial_campaign(tmp_path: Path) -> Path:
    path = tmp_path / "short.toml"
    path.write_text(f'''
[campaign]
name = "short"
testbed = "{TESTBEDS / 'inertial_2dof.toml'}"

[[setup]]
action = "connect"

[[run]]
action = "start_recording"
name = "short"

[[run]]
action = "dwell"
seconds = 0.2

[[run]]
action = "stop_recording"
''')
    return path


def test_the_run_uses_and_records_the_testbed_given(tmp_path, capsys):
    variant = TESTBEDS / "inertial_2dof_appendix_inertia.toml"
    code = main(["campaign", "run", str(short_inertial_campaign(tmp_path)), "--fast", "--no-analysis",
                 "--fast-sim", "inline", "--testbed", str(variant), "--log-folder", str(tmp_path / "logs")])
    out = capsys.readouterr().out
    assert code == 0, out
    (log_path,) = sorted((tmp_path / "logs").glob("*.h5"))
    with LogReader(log_path) as log:
        _name, _path, text = log.testbed()
        recorded = tomllib.loads(text)
    assert recorded["mechanics"]["J1"] == 2.7206 and recorded["mechanics"]["J2"] == 1.7878


def test_a_testbed_the_campaign_cannot_run_on_is_refused_before_anything_runs(tmp_path, capsys):
    folder = tmp_path / "logs"
    code = main(["campaign", "run", str(CAMPAIGNS / "inertial_bm.toml"), "--fast", "--log-folder",
                 str(folder), "--testbed", str(TESTBEDS / "relative_2dof.toml")])
    err = capsys.readouterr().err
    assert code == 2
    assert "relative_2dof.toml" in err and "use an inertial testbed" in err and "play_base_motion" in err
    assert not folder.exists()
    code = main(["campaign", "run", str(CAMPAIGNS / "inertial_bm.toml"), "--fast",
                 "--testbed", str(tmp_path / "nope.toml")])
    assert code == 2
    assert "--testbed: no file" in capsys.readouterr().err
