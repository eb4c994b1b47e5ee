"""Reading a TOML file with errors a user can act on (shared by every config loader)."""

from __future__ import annotations

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
