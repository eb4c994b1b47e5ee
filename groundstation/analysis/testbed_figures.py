"""The testbed constants the log metrics need - the autocollimator's calibrated range,
the motor resistances, the set-up - from a testbed file or from the one a log recorded:
its testbed file (--testbed at recording), else the one the device named at connect
(logs/device_testbed.py; a log recorded from a tcp:// device without --testbed).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ..logs import LogReader
from ..logs.device_testbed import recorded_device
from ..plant.testbed import Testbed, TestbedConfigError, load_testbed
from . import AnalysisError

DEG = math.pi / 180.0


@dataclass(frozen=True)
class TestbedFigures:
    """The testbed constants the metrics need, and where they came from."""

    __test__ = False

    source: str                                  # '' when the log records no testbed
    autocollimator_range_rad: float | None
    resistance_coarse_ohm: float | None
    resistance_fine_ohm: float | None
    setup: str = ""                              # "relative" | "inertial" | '' unknown
    #: why there is no testbed, when `source` is '' (what the device said, if it did)
    missing: str = "the log records no testbed file"

    @classmethod
    def of(cls, tb: Testbed, source: str) -> "TestbedFigures":
        return cls(source, tb.sensors["autocollimator_range"] * DEG, tb.motor_coarse["resistance"],
                   tb.motor_fine["resistance"], tb.setup)


def _number(doc: dict, section: str, key: str) -> float | None:
    v = doc.get(section, {}).get(key) if isinstance(doc.get(section), dict) else None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v > 0 and math.isfinite(v)):
        return None
    return float(v)


def log_testbed(reader: LogReader) -> tuple[str, str, str, str]:
    """(name, path, text, label) of the testbed a log recorded: its testbed file, else
    the file the device named at connect; all '' when neither."""
    name, where, text = reader.testbed()
    if text:
        return name, where, text, f"the log's testbed '{name}'" if name else "the log's testbed"
    device = recorded_device(reader) or {}
    text = device.get("testbed_text")
    if isinstance(text, str) and text:
        name = str(device.get("testbed_name", ""))
        return (name, str(device.get("testbed_file", "")), text,
                f"the testbed '{name}' the device named at connect")
    return "", "", "", ""


def no_testbed(reader: LogReader) -> str:
    """Why a log has no testbed, in words: and what its device said it was, if it did."""
    device = recorded_device(reader)
    if device is None:
        return "the log records no testbed file"
    return (f"the log records no testbed file, and its device described itself at connect "
            f"as \"{device['description']}\", naming no testbed file known here")


def figures_from_testbed(reader: LogReader, testbed: str | Path | Testbed | None = None) -> TestbedFigures:
    """From `testbed` (a file or a loaded Testbed) if given, else from the log: the
    recorded file itself when it is still where it was and unchanged (then checked in
    full by load_testbed), else the recorded text - what was true when the log was made."""
    if testbed is not None:
        tb = testbed if isinstance(testbed, Testbed) else load_testbed(testbed)
        return TestbedFigures.of(tb, f"testbed file {tb.path}")
    name, where, text, label = log_testbed(reader)
    if not text:
        return TestbedFigures("", None, None, None, missing=no_testbed(reader))
    if where and Path(where).is_file():
        try:
            tb = load_testbed(where)
        except TestbedConfigError:
            tb = None
        if tb is not None and tb.text == text:
            return TestbedFigures.of(tb, f"{label} ({where})")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise AnalysisError(f"{reader.path}: the testbed file recorded in the log is not valid "
                            f"TOML ({exc}): give --testbed FILE") from None
    rng = _number(doc, "sensors", "autocollimator_range")
    return TestbedFigures(f"{label} (as recorded in the log)", None if rng is None else rng * DEG,
                          _number(doc, "motor_coarse", "resistance"),
                          _number(doc, "motor_fine", "resistance"),
                          str(doc.get("testbed", {}).get("setup", "")) if isinstance(doc.get("testbed"), dict) else "")


__all__ = ["DEG", "TestbedFigures", "figures_from_testbed", "log_testbed", "no_testbed"]
