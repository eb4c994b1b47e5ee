"""Which loop a log's run closed, for the mode check (loop_mode.py): its design file
and the parameter table it uploaded, as the log records them.

A log's journal holds every verified upload as a `parameter_table` record: its source
(the design file, then notes in parentheses) and the table's bytes.  The check uses the
table the device ran - the recorded bytes - with the design file that made it (the
loop's structure and testbed), so a design edited since the run does not change the
verdict on it.

    find_design(reader, "auto")                   # the last design uploaded in the log
    find_design(reader, "profiles/controllers/inertial_design1.toml")   # that design; its
                                                  # recorded table if the log has one

A design whose file is gone, or a table this dictionary cannot read, leaves the check
out with the reason (`DesignSource.reason`), never an exception: the jitter and energy
figures do not depend on it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.errors import GroundStationError
from .loop_mode import LoopMode, design_mode

log = logging.getLogger(__name__)

AUTO = "auto"
#: the device's closed-loop modes (telemetry `mode` states) by design mode
CLOSED_LOOP_STATES = {"relative": "RELATIVE", "inertial": "INERTIAL"}

# (resolved design path, its modification time, table bytes) -> its mode: a campaign's
# twelve logs share four designs, and a loop model costs ~0.1 s
_MODES: dict[tuple[str, int, bytes], tuple[LoopMode | None, str]] = {}


@dataclass(frozen=True)
class DesignSource:
    """The loop a run closed: its mode (None: none found, or no lightly damped one),
    how it was found, and why there is no check when there is none."""

    mode: LoopMode | None
    design_mode: str = ""              # "relative" | "inertial" ('' : no design)
    source: str = ""                   # the design file and where its table came from
    reason: str = ""                   # why no mode check ('' : there is one, or no loop at all)


def _uploads(reader) -> list[tuple[str, bytes]]:
    """(design file as recorded, table bytes) of every upload from a .toml file, in order."""
    out = []
    for rec in reader.journal("parameter_table"):
        d = rec.data if isinstance(rec.data, dict) else {}
        source = str(d.get("source", "")).split(" (")[0]
        if source.endswith(".toml") and rec.blob:
            out.append((source, bytes(rec.blob)))
    return out


def _mode_of(path: Path, blob: bytes | None) -> tuple[LoopMode | None, str]:
    """(the design's lightly damped mode, its design mode) with the table `blob` (None:
    the design's own table); raises GroundStationError for a file or table unusable."""
    from ..core.dictionary import load_dictionary
    from ..params.design_file import load_design
    from ..params.table import unpack

    # the same design and table recur in log after log of a batch: reading and checking
    # the design file was a fifth of a 60 s log's analysis, so it is done once per key
    key = (str(path.resolve()), path.stat().st_mtime_ns, blob or b"")
    if key not in _MODES:
        design = load_design(path)
        values: dict[str, Any] | None = unpack(load_dictionary(), blob) if blob else None
        _MODES[key] = (design_mode(design, values), design.mode)
    return _MODES[key]


def find_design(reader, design: str | Path) -> DesignSource:
    """The loop of the log `reader` (a LogReader): `design` AUTO (the last design the log
    records uploading) or a design file (its recorded table if the log has an upload of a
    file of that name, else the design's own table)."""
    uploads = _uploads(reader)
    if str(design) == AUTO:
        if not uploads:
            return DesignSource(None)          # nothing uploaded: an open-loop run, nothing to say
        where, blob = uploads[-1]
        path = Path(where)
        table = "the table the log recorded"
    else:
        path = Path(design)
        mine = [(w, b) for w, b in uploads if Path(w).name == path.name]
        blob = mine[-1][1] if mine else None
        if not path.is_file() and mine and Path(mine[-1][0]).is_file():
            path = Path(mine[-1][0])             # named relative to elsewhere: the log knows where
        table = "the table the log recorded" if mine else "the design's own table (the log records no upload of it)"
    if not path.is_file():
        return DesignSource(None, reason=f"the design file {path} is not there: no mode check")
    try:
        mode, kind = _mode_of(path, blob)
    except GroundStationError as exc:
        return DesignSource(None, reason=f"the design {path.name} cannot be analysed ({exc}): no mode check")
    source = f"{path.name} with {table}"
    if mode is None:
        return DesignSource(None, kind, source, f"{path.name}'s closed loop has no lightly damped mode")
    return DesignSource(mode, kind, source)


__all__ = ["AUTO", "CLOSED_LOOP_STATES", "DesignSource", "find_design"]
