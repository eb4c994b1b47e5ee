"""The suite and the program leave processes they did not start alone (docs/testing.md):
what a make or a CI runner above them waits for is never reaped or signalled here."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted(p for folder in ("groundstation", "tests", "benchmarks", "tools")
                 for p in (ROOT / folder).rglob("*.py") if p.name != Path(__file__).name)

#: calls that reap or signal processes beyond our own children, or change how the
#: process above us is told of its children
FORBIDDEN = {
    r"\bos\.wait\(": "os.wait() reaps any child, also one another part is waiting for",
    r"waitpid\(\s*-1": "waitpid(-1) reaps any child",
    r"waitpid\(\s*0\b": "waitpid(0) reaps any child of the group",
    r"\bprctl\b": "a subreaper would take orphans from the runner above",
    r"SIGCHLD": "changing SIGCHLD changes how children are reaped",
    r"killpg\(\s*0\b|killpg\(\s*os\.getpgrp|killpg\(\s*os\.getpgid\(\s*0": "signals our own group (and make's)",
    r"os\.kill\(\s*0\b|os\.kill\(\s*-": "signals a whole group we may belong to",
}


def test_sources_exist():
    assert len(SOURCES) > 100


def test_nothing_reaps_or_signals_processes_it_did_not_start():
    found = []
    for path in SOURCES:
        text = path.read_text(encoding="utf-8")
        for pattern, why in FORBIDDEN.items():
            for m in re.finditer(pattern, text):
                line = text.count("\n", 0, m.start()) + 1
                found.append(f"{path.relative_to(ROOT)}:{line}: {why}")
    assert not found, "\n".join(found)


def test_every_group_signalled_was_created_as_a_session_of_its_own():
    """killpg(proc.pid) reaches only that child's group when the child leads a session of
    its own; otherwise its group is ours - and make's."""
    found = []
    for path in SOURCES:
        text = path.read_text(encoding="utf-8")
        if "killpg(" in text and "start_new_session=True" not in text:
            found.append(str(path.relative_to(ROOT)))
    assert not found, f"killpg without start_new_session=True in: {found}"
