"""How a campaign was run - device, fast clock, seed, testbed, log folder - kept in its
report, so that `--resume` continues on the same rig as the same kind of run.

A resumed campaign's report holds runs from before and after the resume and compares
them; they are comparable only if both halves ran on the same device, clock, seed and
testbed.  So a resume takes the stored setup, refuses an option that contradicts it
unless the operator says so explicitly (`--allow-setup-change`, and the report then
records what changed), and the resume hint printed after a failure or Ctrl-C is the
whole command, one that works when pasted.  No I/O here.
"""

from __future__ import annotations

import shlex
from typing import Any

from ..core.kinds import FastSim
from .model import CampaignError

#: option -> its value when neither the command line nor a report gives one
SETUP_DEFAULTS: dict[str, Any] = {"device": "sim", "fast": False, "fast_sim": "process",
                                  "seed": 0, "testbed": None, "log_folder": None}
#: options whose change makes a resumed report compare runs of two different set-ups
MUST_MATCH = ("device", "fast", "fast_sim", "seed", "testbed")
_FLAGS = {"device": "--device", "fast": "--fast", "fast_sim": "--fast-sim", "seed": "--seed",
          "testbed": "--testbed", "log_folder": "--log-folder"}


def resolve_setup(given: dict[str, Any], stored: dict[str, Any] | None, *,
                  allow_change: bool = False, report_name: str = "the report") -> tuple[dict[str, Any], list[str]]:
    """(the setup to run with, notes for the operator).

    `given`: the options the operator typed (absent ones left out); `stored`: the setup
    of the report being resumed (None: not resuming; {}: a report from before set-ups
    were recorded).  Raises CampaignError naming each contradiction unless
    `allow_change`."""
    notes: list[str] = []
    if stored is None:
        return {k: given.get(k, d) for k, d in SETUP_DEFAULTS.items()}, notes
    if not stored:
        setup = {k: given.get(k, d) for k, d in SETUP_DEFAULTS.items()}
        notes.append(f"{report_name} does not record the set-up it ran with (written before "
                     f"set-ups were kept): resuming with {describe(setup)} - check it is the same rig")
        return setup, notes
    setup = {k: stored.get(k, d) for k, d in SETUP_DEFAULTS.items()}
    changed = {k: v for k, v in given.items() if k in SETUP_DEFAULTS and v != setup[k]}
    clashes = [k for k in changed if k in MUST_MATCH]
    if clashes and not allow_change:
        asked = ", ".join(f"{_FLAGS[k]} {_shown(changed[k])}" for k in clashes)
        ran = ", ".join(f"{_FLAGS[k]} {_shown(setup[k])}" for k in clashes)
        raise CampaignError(
            f"{report_name} ran with {ran}; this resume asks for {asked}.  Its runs would then "
            f"come from two different set-ups in one report.  Resume with the report's set-up "
            f"(leave those options out), or pass --allow-setup-change to mix them on purpose "
            f"(the report records the change)")
    if changed:
        notes.append("resuming with a changed set-up: " + ", ".join(
            f"{_FLAGS[k]} {_shown(setup[k])} -> {_shown(v)}" for k, v in changed.items()))
    setup.update(changed)
    notes.insert(0, f"resuming with the report's set-up: {describe(setup)}")
    return setup, notes


def describe(setup: dict[str, Any]) -> str:
    """'device sim, fast (simulator in its own process), seed 0, testbed FILE'."""
    parts = [f"device {setup['device']}"]
    if setup.get("fast"):
        parts.append(f"fast (simulator {'in its own process' if setup.get('fast_sim') == FastSim.PROCESS else 'inline'})")
    parts.append(f"seed {setup.get('seed', 0)}")
    if setup.get("testbed"):
        parts.append(f"testbed {setup['testbed']}")
    return ", ".join(parts)


def resume_command(campaign_file: str, report_file: str, setup: dict[str, Any]) -> str:
    """The whole command that continues this campaign, quoted for a POSIX shell: the
    report's set-up spelled out, so it reads as what it does (a resume would take the
    same values from the report anyway)."""
    words = ["groundstation", "campaign", "run", campaign_file, "--resume", report_file or "REPORT.json"]
    if setup:
        words += ["--device", str(setup.get("device", "sim"))]
        if setup.get("fast"):
            words.append("--fast")
            if setup.get("fast_sim", FastSim.PROCESS) != FastSim.PROCESS:
                words += ["--fast-sim", str(setup["fast_sim"])]
        words += ["--seed", str(setup.get("seed", 0))]
        for key in ("testbed", "log_folder"):
            if setup.get(key):
                words += [_FLAGS[key], str(setup[key])]
    return shlex.join(words)


def _shown(value: Any) -> str:
    if value is True:
        return "(on)"
    if value is False:
        return "(off)"
    return "(none)" if value is None else str(value)


__all__ = ["MUST_MATCH", "SETUP_DEFAULTS", "describe", "resolve_setup", "resume_command"]
