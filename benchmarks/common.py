"""What every benchmark shares: the machine line and where its results go."""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path

RESULTS = Path(__file__).parent / "results"


def machine() -> str:
    return (f"{platform.machine()}, {os.cpu_count()} cores, {platform.system()} "
            f"{platform.release()}, Python {platform.python_version()}")


def save(name: str, results: dict) -> Path:
    """Write results/<name>.json (not committed; the README quotes the figures)."""
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(results, indent=2) + "\n")
    return path


def stat_cpu_seconds(stat: Path) -> float | None:
    """utime + stime of a /proc/.../stat file (a process's or a thread's), s; None when it
    cannot be read (the process has ended)."""
    try:
        fields = Path(stat).read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def proc_cpu_seconds(pid: int) -> float | None:
    """CPU seconds a process has used so far (Linux /proc); None when it has ended."""
    return stat_cpu_seconds(Path(f"/proc/{pid}/stat"))
