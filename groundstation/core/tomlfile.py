"""TOML files: reading one with errors a user can act on (shared by every config loader),
and the few pieces the writers of designs and testbed files spell alike."""

from __future__ import annotations

import json
import math
import os
import tomllib
from pathlib import Path

from .errors import GroundStationError


def read_toml(path: Path, error: type[GroundStationError], missing: str = "file not found") -> tuple[dict, str]:
    """(parsed document, text) of `path`; `error` (naming the file) if it cannot be."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{path}: {missing}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: malformed TOML: {exc}") from None


def toml_number(x: float, error: type[Exception] = ValueError) -> str:
    """A float as TOML writes it: shortest exact-enough text, always with a '.' or an
    exponent (so it reads back as a float); `error` for NaN or infinity."""
    x = float(x)
    if not math.isfinite(x):
        raise error(f"cannot write the number {x!r}: the file holds finite numbers")
    text = f"{x + 0.0:.15g}"
    return text if any(c in text for c in ".en") else text + ".0"


def toml_string(text: str) -> str:
    """A TOML basic string (JSON's escaping is TOML's)."""
    return json.dumps(text, ensure_ascii=False)


def relative_path(target: Path, folder: Path) -> str:
    """`target` relative to `folder` when they share more than the file system's root
    (../testbeds/x.toml, as the shipped files write it), otherwise absolute."""
    target, folder = Path(target).resolve(), Path(folder).resolve()
    try:
        common = Path(os.path.commonpath([target, folder]))
    except ValueError:                                 # another drive
        return target.as_posix()
    if common == Path(common.anchor):
        return target.as_posix()
    return Path(os.path.relpath(target, folder)).as_posix()
