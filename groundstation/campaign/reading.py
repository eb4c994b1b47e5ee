"""Reading a campaign file: its structure, the matrix expanded into steps with their
placeholders filled and files resolved, then every step's values checked by its
action's handler (`actions.ACTIONS`).  Nothing here connects or sends anything."""

from __future__ import annotations

import itertools
import re
from pathlib import Path
from typing import Any

from ..errors import GroundStationError
from ..tomlfile import read_toml
from .actions import ACTIONS, PATH_KEYS, known_actions
from .checks import CampaignChecker
from .model import Campaign, CampaignError, Step


def load_campaign(path: str | Path, dictionary=None) -> Campaign:
    """Read a campaign file and check every step of every run before anything runs:
    the file's structure, then every value against the protocol dictionary, the
    testbed's limits and the function generator's (`check_campaign`).  Raises
    CampaignError listing every problem found."""
    campaign, problems = read_campaign(path, dictionary)
    if problems:
        raise CampaignError(_problems_text(Path(path), problems), problems)
    return campaign


def read_campaign(path: str | Path, dictionary=None) -> tuple[Campaign | None, list[str]]:
    """The campaign and every problem found in it (an empty list: it may run).  The
    campaign is None when the file is too broken to list its steps."""
    path = Path(path)
    doc, _text = read_toml(path, CampaignError, "campaign file not found (see profiles/campaigns/)")
    head = doc.get("campaign")
    if not isinstance(head, dict):
        raise CampaignError(f"{path}: needs a [campaign] table with name and testbed")
    name = _text_field(head, "name", path, "[campaign]")
    testbed = (path.parent / _text_field(head, "testbed", path, "[campaign]")).resolve()
    if not testbed.is_file():
        raise CampaignError(f"{path}: [campaign] testbed: no file {testbed}")
    unknown = set(doc) - {"campaign", "matrix", "setup", "run", "teardown"}
    if unknown:
        raise CampaignError(f"{path}: unknown table(s) {sorted(unknown)} (known: campaign, matrix, "
                            f"setup, run, teardown)")
    matrix = doc.get("matrix", {})
    if not isinstance(matrix, dict) or any(not isinstance(v, list) or not v for v in matrix.values()):
        raise CampaignError(f"{path}: [matrix] values must be non-empty lists")
    combos = [dict(zip(matrix, values)) for values in itertools.product(*matrix.values())] or [{}]
    steps: list[Step] = []
    problems: list[str] = []
    raw = {ph: doc.get(ph, []) for ph in ("setup", "run", "teardown")}
    for ph, items in raw.items():
        if not isinstance(items, list) or any(not isinstance(i, dict) for i in items):
            raise CampaignError(f"{path}: [[{ph}]] must be an array of tables")
    if not raw["run"] and not raw["setup"]:
        raise CampaignError(f"{path}: no steps ([[setup]] or [[run]])")
    policy = head.get("on_run_failure", "stop")
    if policy not in ("stop", "next_run"):
        raise CampaignError(f"{path}: [campaign] on_run_failure must be \"stop\" or \"next_run\", "
                            f"not {policy!r}")

    def add(phase: str, run: int, items: list[dict], variables: dict[str, Any]) -> None:
        for position, item in enumerate(items, 1):
            step = _step(item, problems, len(steps), phase, run, position, variables, path, name)
            if step is not None:
                steps.append(step)
    add("setup", 0, raw["setup"], {})
    for run, combo in enumerate(combos, 1):
        if raw["run"]:
            add("run", run, raw["run"], combo)
    add("teardown", 0, raw["teardown"], {})
    campaign = Campaign(path, name, str(head.get("description", "")), testbed, matrix, steps,
                        len(combos) if raw["run"] else 0, policy)
    problems += check_campaign(campaign, dictionary)
    return campaign, problems


def _problems_text(path: Path, problems: list[str]) -> str:
    if len(problems) == 1:
        return problems[0]
    return (f"{path.name}: {len(problems)} problems, nothing was run:\n  " + "\n  ".join(problems))


def _text_field(table: dict, key: str, path: Path, where: str) -> str:
    v = table.get(key)
    if not isinstance(v, str) or not v:
        raise CampaignError(f"{path}: {where} {key} must be a non-empty string")
    return v


_WHOLE_PLACEHOLDER = re.compile(r"^\{(\w+)\}$")


def _step(item: dict, problems: list[str], index: int, phase: str, run: int, position: int,
          variables: dict[str, Any], path: Path, campaign: str) -> Step | None:
    """One step with its placeholders filled and its files resolved, or None (the
    problems found appended to `problems`)."""
    action = item.get("action")
    head = f"{path.name}: {f'run {run}' if run else phase} step {position}"
    handler = ACTIONS.get(action) if isinstance(action, str) else None
    if handler is None:
        problems.append(f"{head}: action {action!r} is not one of {known_actions()}")
        return None
    where = f"{head} ({action})"
    required, allowed = handler.required, handler.keys
    keys = set(item) - {"action"}
    ok = True
    if required - keys:
        problems.append(f"{where}: missing {', '.join(sorted(required - keys))}")
        ok = False
    if keys - allowed:
        problems.append(f"{where}: unknown key(s) {', '.join(sorted(keys - allowed))}"
                        f" (allowed: {', '.join(sorted(allowed)) or 'none'})")
        ok = False
    names = {"campaign": campaign, "run": run, **variables}
    for k, v in variables.items():
        if isinstance(v, str):
            names[f"{k}_stem"] = Path(v).stem
    args = {}
    for k, v in item.items():
        if k == "action":
            continue
        if isinstance(v, str):
            whole = _WHOLE_PLACEHOLDER.match(v)
            if whole and whole.group(1) in variables and not isinstance(variables[whole.group(1)], str):
                args[k] = variables[whole.group(1)]     # a number or flag from the matrix keeps its type
                continue
            try:
                v = v.format(**names)
            except (KeyError, IndexError, ValueError) as exc:
                problems.append(f"{where}: {k} = {v!r}: unknown or bad placeholder {exc} "
                                f"(known: {', '.join(sorted(names))})")
                ok = False
                continue
            # any file key is resolved (and must exist), whatever the action: a file key
            # given to the wrong action is then refused for the file as well as the key
            if k in PATH_KEYS:
                resolved = (path.parent / v).resolve()
                if not resolved.is_file():
                    problems.append(f"{where}: {k}: no file {resolved}")
                    ok = False
                    continue
                v = str(resolved)
        elif k in PATH_KEYS:
            problems.append(f"{where}: {k} = {v!r} - must be the path of a file (text)")
            ok = False
            continue
        args[k] = v
    if not ok:
        return None
    return Step(index, phase, run, action, args, dict(variables), position)


def check_campaign(campaign: Campaign, dictionary=None) -> list[str]:
    """Every value of every step (of every run) against what the rig accepts: the
    protocol dictionary's ranges and mode names, the testbed file's limits (travel,
    motor peak currents, the generator's [limits]), the 4053B generator's own limits;
    every referenced design, profile and PSD file must load.  Returns the problems,
    each naming file, step and field; nothing is sent anywhere."""
    from ..dictionary import load_dictionary
    from ..plant.testbed import load_testbed

    d = dictionary if dictionary is not None else load_dictionary()
    problems: list[str] = []
    try:
        testbed = load_testbed(campaign.testbed)
    except GroundStationError as exc:
        problems.append(f"{campaign.path.name}: [campaign] testbed: {exc}")
        testbed = None
    checker = CampaignChecker(campaign.path, d, testbed)
    for step in campaign.steps:
        handler = ACTIONS.get(step.action)
        if handler is None:                 # a Campaign built by hand, not read from a file
            problems.append(f"{campaign.path.name}: {step.where()}: action {step.action!r} "
                            f"is not one of {known_actions()}")
            continue
        check = checker.step(step)
        handler.check(check)
        problems += check.problems
    return problems
