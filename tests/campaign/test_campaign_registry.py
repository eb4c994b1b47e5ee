"""The campaign actions live in one registry (groundstation/campaign/actions.py): every
action the documentation names and every action a shipped campaign uses has a handler
there, with the keys the documentation gives it; an action that is not registered is
refused, naming the known ones, before anything connects or runs."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from groundstation.station.station import Station
from groundstation.campaign import (ACTIONS, Action, CampaignError, CampaignRunner, Step, StepRun,
                                    load_campaign, read_campaign, register)
from groundstation.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGNS = ROOT / "profiles" / "campaigns"
DOC = ROOT / "docs" / "campaigns.md"
RELATIVE = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"


def documented_actions() -> dict[str, set[str]]:
    """The "Actions and their keys" table of docs/campaigns.md: action -> its keys."""
    lines = DOC.read_text().splitlines()
    start = lines.index("| action | keys |")
    table: dict[str, set[str]] = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        _, names, keys, _ = line.split("|")
        for name in re.findall(r"`(\w+)`", names):
            table[name] = set(re.findall(r"`(\w+)`", keys))
    return table


def shipped_actions() -> dict[str, set[str]]:
    """Action -> the campaign files in profiles/campaigns/ that use it."""
    used: dict[str, set[str]] = {}
    for path in sorted(CAMPAIGNS.glob("*.toml")):
        doc = tomllib.loads(path.read_text())
        for phase in ("setup", "run", "teardown"):
            for item in doc.get(phase, []):
                used.setdefault(item["action"], set()).add(path.name)
    return used


def test_the_documentation_table_is_read():
    table = documented_actions()
    assert len(table) >= 15 and {"arm", "disarm", "dwell", "generator_set"} <= set(table)


def test_every_documented_action_has_a_handler_with_the_documented_keys():
    table = documented_actions()
    assert set(table) == set(ACTIONS), (
        f"documented, not registered: {sorted(set(table) - set(ACTIONS))}; "
        f"registered, not documented: {sorted(set(ACTIONS) - set(table))}")
    for name, keys in table.items():
        assert keys == set(ACTIONS[name].keys), f"{name}: docs {sorted(keys)}, " \
                                                f"registry {sorted(ACTIONS[name].keys)}"


def test_every_action_of_the_shipped_campaigns_has_a_handler():
    used = shipped_actions()
    assert used, "no campaign files found"
    missing = {name: sorted(files) for name, files in used.items() if name not in ACTIONS}
    assert not missing, f"actions with no handler: {missing}"


def test_every_handler_checks_and_runs_under_its_own_name():
    for name, handler in ACTIONS.items():
        assert isinstance(handler, Action) and handler.name == name
        assert type(handler).run is not Action.run, f"{name} does not say how it runs"
        assert handler.required <= handler.keys
        assert handler.paths <= handler.keys and handler.durations <= handler.keys


def test_an_action_cannot_be_registered_twice_or_without_running():
    with pytest.raises(ValueError, match="'dwell' is registered twice"):
        @register
        class AnotherDwell(Action):
            name = "dwell"

            def run(self, r: StepRun) -> None:
                pass

    with pytest.raises(TypeError, match="does not say how it runs"):
        @register
        class Idle(Action):
            name = "idle_for_test"

    assert "idle_for_test" not in ACTIONS and type(ACTIONS["dwell"]).__name__ == "Dwell"


def write(tmp_path, body: str) -> Path:
    path = tmp_path / "unknown.toml"
    path.write_text(f'[campaign]\nname = "unknown"\ntestbed = "{RELATIVE}"\n\n'
                    f'[[setup]]\naction = "connect"\n\n{body}')
    return path


def test_an_unknown_action_is_refused_naming_the_known_ones(tmp_path):
    path = write(tmp_path, '[[run]]\naction = "dwell"\nseconds = 1.0\n\n'
                           '[[run]]\naction = "jump"\nheight = 2\n')
    known = ", ".join(sorted(ACTIONS))
    _, problems = read_campaign(path)
    assert problems == [f"unknown.toml: run 1 step 2: action 'jump' is not one of {known}"]
    with pytest.raises(CampaignError) as err:
        load_campaign(path)
    assert err.value.problems == problems


def test_a_step_without_an_action_or_with_a_non_text_one_is_refused(tmp_path):
    path = write(tmp_path, '[[run]]\nseconds = 1.0\n\n[[run]]\naction = ["dwell"]\n')
    _, problems = read_campaign(path)
    known = ", ".join(sorted(ACTIONS))
    assert problems == [f"unknown.toml: run 1 step 1: action None is not one of {known}",
                        f"unknown.toml: run 1 step 2: action ['dwell'] is not one of {known}"]


def test_the_cli_refuses_an_unknown_action_before_connecting(tmp_path, capsys, monkeypatch):
    path = write(tmp_path, '[[run]]\naction = "start_recording"\nname = "r"\n\n'
                           '[[run]]\naction = "jump"\n')

    def no_session(*args, **kwargs):
        raise AssertionError("a session was opened for a refused campaign")

    monkeypatch.setattr(Station, "__init__", no_session)
    logs = tmp_path / "logs"
    code = main(["campaign", "run", str(path), "--fast", "--log-folder", str(logs)])
    err = capsys.readouterr().err
    assert code == 2
    assert (f"error: unknown.toml: run 1 step 2: action 'jump' is not one of "
            f"{', '.join(sorted(ACTIONS))}") in err
    assert not logs.exists()


class _BareTestbed:
    """Stands in for a Testbed: notes make_safe, and any other verb fails the test."""

    def __init__(self):
        self.recordings: list = []
        self.made_safe: list[str] = []

    def make_safe(self, reason: str) -> None:
        self.made_safe.append(reason)

    def __getattr__(self, name):
        raise AssertionError(f"the Testbed was asked to {name}")


def test_the_runner_refuses_a_step_it_has_no_handler_for(tmp_path):
    # load_campaign admits no such step; a Campaign assembled in code could hold one
    campaign = load_campaign(write(tmp_path, ""))
    campaign.steps = [Step(0, "run", 1, "jump", {}, {}, 1)]
    tb = _BareTestbed()
    report = CampaignRunner(campaign, tb).run()
    assert report.status == "failed" and report.failed_step == 0
    assert report.reason == (f"step 1 (run 1): jump: no handler for action 'jump' "
                             f"(known: {', '.join(sorted(ACTIONS))})")
    assert tb.made_safe == [report.reason]
