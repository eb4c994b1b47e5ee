"""The README's five-minute tour, run as a newcomer runs it: every command of its code
blocks, in order, in a fresh folder, against the simulated testbed.

The terminal commands run as one bash script (`set -euo pipefail`, so shell variables such
as `LOG=$(...)` carry from one block to the next, as they do in the reader's terminal).
The window commands (`make run`, `groundstation gui ...`) run offscreen in a process of
their own through `readme_tour_gui.py`, which drives the real window the way the tour
tells the reader to (the Demo button) and checks what the tour says they will see.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
TOUR_HEADING = "## A five-minute tour"
GUI_RUNNER = Path(__file__).with_name("readme_tour_gui.py")


def tour_section(text: str) -> str:
    start = text.index(TOUR_HEADING)
    end = text.find("\n## ", start + len(TOUR_HEADING))
    return text[start:] if end < 0 else text[start:end]


def tour_commands(section: str) -> list[str]:
    """The command lines of the section's ```sh blocks, continuations joined, comments kept
    (bash ignores them)."""
    commands: list[str] = []
    for block in re.findall(r"```sh\n(.*?)```", section, flags=re.S):
        pending = ""
        for line in block.splitlines():
            if line.rstrip().endswith("\\"):
                pending += line.rstrip()[:-1] + " "
                continue
            line = (pending + line).strip()
            pending = ""
            if line:
                commands.append(line)
    return commands


def makefile_run_recipe() -> list[str]:
    text = (ROOT / "Makefile").read_text()
    match = re.search(r"^run:.*\n((?:\t.*\n)+)", text, flags=re.M)
    assert match, "the Makefile has no run target"
    return [line.strip() for line in match.group(1).splitlines()]


def as_script_line(command: str) -> str:
    """The line bash runs for one tour command: window commands go through the runner."""
    runner = f'"$TOUR_PYTHON" {shlex.quote(str(GUI_RUNNER))}'
    if command.split("#")[0].strip() == "make run":
        # `make run` = set-up (done: this suite runs in it) + `groundstation run`
        assert makefile_run_recipe() == ["$(VENV)/bin/groundstation run"], (
            "the Makefile's run target changed: teach this test what it now does")
        return f"{runner} run"
    if command.startswith("groundstation gui "):
        return f"{runner} {command[len('groundstation '):]}"
    return command


def test_the_tour_section_is_there_and_has_its_steps():
    section = tour_section(README.read_text())
    commands = tour_commands(section)
    verbs = " ".join(commands)
    for expected in ("make run", "groundstation record", "groundstation campaign run",
                     "groundstation gui --replay", "groundstation analyze", "groundstation log export"):
        assert expected in verbs, f"the tour lost its '{expected}' step"


def test_readme_links_point_at_files_that_exist():
    text = README.read_text()
    missing = [target for target in re.findall(r"\]\(([^)#][^)]*)\)", text)
               if "://" not in target and not (ROOT / target).exists()]
    assert missing == []


def test_every_tour_command_works_on_the_simulator(tmp_path):
    venv = Path(sys.prefix)
    for needed in ("bin/activate", "bin/groundstation"):
        if not (venv / needed).exists():
            pytest.fail(f"the tour needs the project's virtual environment ({venv / needed} is "
                        "missing): run the suite with `make test`")
    (tmp_path / ".venv").symlink_to(venv)
    (tmp_path / "profiles").symlink_to(ROOT / "profiles")
    commands = tour_commands(tour_section(README.read_text()))
    script = ["set -euo pipefail", "set -x"] + [as_script_line(c) for c in commands]
    env = dict(os.environ, TOUR_PYTHON=sys.executable, QT_QPA_PLATFORM="offscreen",
               PYTHONPATH=str(ROOT))
    done = subprocess.run(["bash", "-c", "\n".join(script)], cwd=tmp_path, env=env,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=1500)    # a hang guard only: the tour takes about a minute
    assert done.returncode == 0, (
        f"a tour command failed (status {done.returncode}):\n--- stderr (the commands are "
        f"echoed here) ---\n{done.stderr[-6000:]}\n--- stdout ---\n{done.stdout[-3000:]}")
    # what the tour promised to leave behind
    logs = tmp_path / "logs"
    assert len(list(logs.glob("*_first-look_*.h5"))) == 1
    assert (logs / "relative_steps" / "report.html").exists()
    assert len(list((logs / "relative_steps").glob("*_relative_design2_*.mat"))) == 1
    assert done.stderr.count("readme_tour_gui: saw") == 0     # the runner reports on stdout
    assert done.stdout.count("readme_tour_gui: saw") == 2     # the demo and the replay were seen
