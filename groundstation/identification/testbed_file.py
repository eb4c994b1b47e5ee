"""An identified testbed file: the base file's text with the identified values put in,
its relative paths re-aimed at the new folder, and an [identification] block saying what
each value came from.

The base file's text is edited rather than the file written anew, so that its comments,
its [assumed] list and everything the fit did not touch read exactly as before; a value
the fit changed gets a comment with the base value.  The new text is written to a
temporary file beside the target, loaded as any testbed file is, and only then put in
place: a file that would not load is never left behind.  An identified slope table is
written beside it (RIG_slope_table.csv) and the file points at it; a table that was not
there before is removed again when the file is not written.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Sequence

from ..analysis.friction_id import write_slope_table
from ..core.errors import GroundStationError
from ..core.tomlfile import relative_path, toml_number, toml_string
from ..plant.testbed import Testbed, load_testbed

SECTION = re.compile(r"^\s*\[([A-Za-z0-9_.]+)\]\s*(#.*)?$")
ARRAY_SECTION = re.compile(r"^\s*\[\[([A-Za-z0-9_.]+)\]\]\s*(#.*)?$")
ASSIGNMENT = re.compile(r"^(\s*)([A-Za-z0-9_]+)(\s*=\s*)([^#\n]*?)(\s*)(#.*)?$")


class TestbedWriteError(GroundStationError):
    """The identified testbed file could not be written (the message says why)."""

    __test__ = False


@dataclass(frozen=True)
class Provenance:
    """What one parameter of the written file came from."""
    name: str                       # 'mechanics.J1'
    units: str
    base: float
    value: float
    ci95: tuple[float, float] | None
    status: str                     # 'identified', 'held (...)'
    reason: str = ""
    sources: tuple[str, ...] = ()


def _strip_identification(lines: list[str]) -> list[str]:
    """The base file's own [identification] block (a file identified before) is dropped:
    the new one replaces it."""
    out, skipping = [], False
    for line in lines:
        header = SECTION.match(line) or ARRAY_SECTION.match(line)
        if header:
            skipping = header.group(1).split(".")[0] == "identification"
        if not skipping:
            out.append(line)
    while out and not out[-1].strip():
        out.pop()
    return out


def _replace_values(lines: list[str], values: dict[str, str], comments: dict[str, str]) -> list[str]:
    """Put `values` ('section.key' -> TOML text) into the assignment lines of `lines`."""
    section, done, out = "", set(), []
    for line in lines:
        header = SECTION.match(line)
        if header:
            section = header.group(1)
        m = ASSIGNMENT.match(line)
        name = f"{section}.{m.group(2)}" if m else ""
        if m and name in values:
            indent, key, eq = m.group(1), m.group(2), m.group(3)
            comment = comments.get(name) or (m.group(6) or "")
            pad = " " * max(1, 34 - len(f"{indent}{key}{eq}{values[name]}"))
            line = f"{indent}{key}{eq}{values[name]}" + (f"{pad}{comment}" if comment else "")
            done.add(name)
        out.append(line)
    missing = sorted(set(values) - done)
    if missing:
        raise TestbedWriteError(f"the base file has no line for {', '.join(missing)}: "
                                f"write it in the base file first")
    return out


def _identification_block(base: Testbed, provenance: Sequence[Provenance], logs: Sequence[str],
                          folder: Path, note: str) -> list[str]:
    when = datetime.now(timezone.utc).replace(microsecond=0).isoformat()
    lines = ["", "[identification]",
             "# Written by `groundstation identify`: the values marked \"identified\" above",
             "# were fitted to the logs below; every other value is the base file's.",
             f"base = {toml_string(relative_path(base.path, folder))}",
             f"written = {toml_string(when)}",
             "logs = [" + ", ".join(toml_string(s) for s in logs) + "]"]
    if note:
        lines.append(f"note = {toml_string(note)}")
    for p in provenance:
        lines += ["", "[[identification.parameter]]", f"name = {toml_string(p.name)}",
                  f"units = {toml_string(p.units)}", f"base = {toml_number(p.base)}",
                  f"value = {toml_number(p.value)}", f"status = {toml_string(p.status)}"]
        if p.ci95 is not None:
            lines.append(f"ci95 = [{toml_number(p.ci95[0])}, {toml_number(p.ci95[1])}]")
        if p.reason:
            lines.append(f"reason = {toml_string(p.reason)}")
        if p.sources:
            lines.append("sources = [" + ", ".join(toml_string(s) for s in p.sources) + "]")
    return lines


def slope_table_path(out: str | Path) -> Path:
    """Where the identified slope table of the file `out` is written."""
    out = Path(out)
    return out.with_name(f"{out.stem}_slope_table.csv")


def identified_text(base: Testbed, values: dict[str, float], provenance: Sequence[Provenance],
                    out: Path, *, name: str, logs: Sequence[str] = (), note: str = "",
                    own_table: bool = False) -> str:
    """The text of the identified file that will live at `out`."""
    folder = Path(out).resolve().parent
    texts = {k: toml_number(v, TestbedWriteError) for k, v in values.items()}
    comments = {}
    for k in values:
        section, key = k.split(".", 1)
        section_values = getattr(base, section, None)
        was = section_values.get(key) if isinstance(section_values, dict) else None
        if isinstance(was, (int, float)):
            comments[k] = f"# identified (base {toml_number(float(was))})"
    texts["testbed.name"] = toml_string(name)
    if own_table:
        texts["friction.slope_table"] = toml_string(slope_table_path(out).name)
        comments["friction.slope_table"] = "# identified (beside this file)"
    elif base.friction.get("slope_table"):
        texts["friction.slope_table"] = toml_string(relative_path(base.slope_table_path, folder))
    lines = _replace_values(_strip_identification(base.text.splitlines()), texts, comments)
    return "\n".join(lines + _identification_block(base, provenance, logs, folder, note)) + "\n"


def _write_table(out: Path, table, logs: Sequence[str]) -> bool:
    """Write the slope table beside `out`; True if the file was not there before."""
    path = slope_table_path(out)
    new = not path.exists()
    try:
        write_slope_table(path, table[0], table[1],
                          comment=f"identified by `groundstation identify` from "
                                  f"{', '.join(logs) or 'the logs'} (for {out.name})")
    except GroundStationError as exc:
        raise TestbedWriteError(f"{out}: not written: {exc}") from None
    return new


def write_identified(base: Testbed, values: dict[str, float], provenance: Sequence[Provenance],
                     out: str | Path, *, name: str, logs: Sequence[str] = (),
                     note: str = "", slope_table=None) -> Testbed:
    """Write the identified testbed file to `out` (and `slope_table` (x, f) beside it)
    and return it as load_testbed reads it; TestbedWriteError (and `out` untouched) if it
    cannot be written or would not load."""
    out = Path(out)
    text = identified_text(base, values, provenance, out, name=name, logs=logs, note=note,
                           own_table=slope_table is not None)
    tmp = out.with_name(f".{out.name}.writing")
    new_table = False
    try:
        if slope_table is not None:
            new_table = _write_table(out, slope_table, logs)
        tmp.write_text(text, encoding="utf-8")
        try:
            load_testbed(tmp)
        except GroundStationError as exc:
            raise TestbedWriteError(f"{out}: not written: the identified file would not load "
                                    f"({exc})") from None
        os.replace(tmp, out)
        new_table = False
    except OSError as exc:
        raise TestbedWriteError(f"{out}: cannot write ({exc.strerror or exc})") from None
    finally:
        tmp.unlink(missing_ok=True)
        if new_table:
            slope_table_path(out).unlink(missing_ok=True)
    return load_testbed(out)
