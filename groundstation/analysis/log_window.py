"""What the log adapters of analysis/ share: the packet they read, their errors, the
testbed a log was recorded with, and the reading of a window of its frames.

frf_from_log (log_frf.py), hysteresis_from_log (log_hysteresis.py), step_from_log
(log_step.py) and friction_velocity_from_log (log_friction_velocity.py) read HIGH_RATE
frames through LogReader with these helpers: the channels checked (check_channel,
require_channels), the window turned into rows (window_rows), the frames playing a
profile found (profile_span), the longest stretch without missing frames (longest_run),
and the testbed's constants and model from the file the log recorded or the one given
(testbed_info).  find_logs lists the logs of a folder.

Errors are GroundStationError subclasses with the reason in the message:
MissingChannelError, WindowTooShortError, NoExcitationError (and the log's own LogError,
an AnalysisError for anything else).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from ..logs import LogReader
from ..plant.testbed import Testbed, TestbedConfigError, load_testbed
from . import AnalysisError
from .testbed_figures import log_testbed, no_testbed

PACKET = "HIGH_RATE"
#: the channels a missing-channel message lists when the log has them: the frequency
#: response's inputs and outputs (log_frf.FRF_INPUTS, FRF_OUTPUTS, in their order)
SIGNAL_CHANNELS = ("current_coarse", "torque_coarse_cmd", "current_fine", "torque_fine_cmd",
                   "encoder_outer", "encoder_inner", "gyro_rate", "autocollimator",
                   "los_estimate")


class LogIdentificationError(AnalysisError):
    """A frequency response or a hysteresis loop cannot be had from this log."""


class MissingChannelError(LogIdentificationError):
    """The log does not hold a channel the analysis needs (the message lists what it has)."""


class WindowTooShortError(LogIdentificationError):
    """The chosen window of the log holds too few frames for the analysis."""


class NoExcitationError(LogIdentificationError):
    """The input does not vary (or the axis does not move) in the window."""


# ======================================================================================
# the log's testbed
# ======================================================================================
@dataclass(frozen=True)
class TestbedInfo:
    """What the log adapters need of the testbed, and where it came from."""

    __test__ = False                # a name starting with "Test" that pytest must not collect

    model: Testbed | None           # the full record (for the model), None if not loadable
    doc: dict[str, Any]             # the TOML document (constants)
    source: str                     # '' when the log records none
    note: str = ""                  # why there is no model, if there is none

    def number(self, section: str, key: str) -> float | None:
        # the record's values first: a Testbed made with other values than its file's
        # (an identified plant, plant_fit.with_values) is what the caller means
        sec = getattr(self.model, section, None) if self.model is not None else None
        if not isinstance(sec, dict) or key not in sec:
            sec = self.doc.get(section)
        v = sec.get(key) if isinstance(sec, dict) else None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return None
        return float(v)

    @property
    def two_dof(self) -> bool:
        sec = self.doc.get("testbed")
        return isinstance(sec, dict) and sec.get("configuration") == "2dof"


def coarse_torque_constant(tbi: TestbedInfo, name: str) -> float:
    """K_t1 in in-oz/A from the testbed, for torques from the coarse motor's current."""
    kt1 = tbi.number("motor_coarse", "torque_constant")
    if kt1 is None:
        raise LogIdentificationError(f"{name}: the coarse motor's torque constant "
                                     f"([motor_coarse] torque_constant) is unknown "
                                     f"({tbi.source or tbi.note}): choose a testbed file")
    return kt1


def testbed_info(reader: LogReader, testbed: str | Path | Testbed | None) -> TestbedInfo:
    """From `testbed` if given; else the file the log recorded, loaded in full when it is
    still where it was and unchanged, else its recorded text for the constants only (what
    was true when the log was made; the model needs the checked file)."""
    if testbed is not None:
        tb = testbed if isinstance(testbed, Testbed) else load_testbed(testbed)
        return TestbedInfo(tb, tomllib.loads(tb.text), f"testbed file {tb.path}")
    name, where, text, label = log_testbed(reader)
    if not text:
        return TestbedInfo(None, {}, "", f"{no_testbed(reader)}: choose one")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        return TestbedInfo(None, {}, "", f"the testbed file recorded in the log is not valid "
                                          f"TOML ({exc}): choose a testbed file")
    if where and Path(where).is_file():
        try:
            tb = load_testbed(where)
        except TestbedConfigError as exc:
            return TestbedInfo(None, doc, f"{label} (as recorded in the log)",
                                f"no model: the recorded testbed file does not load now ({exc})")
        if tb.text == text:
            return TestbedInfo(tb, doc, f"{label} ({where})")
        return TestbedInfo(None, doc, f"{label} (as recorded in the log)",
                            f"no model: {where} has changed since the log was recorded; "
                            f"choose a testbed file")
    return TestbedInfo(None, doc, f"{label} (as recorded in the log)",
                        f"no model: the recorded testbed file {where or '(no path)'} is not "
                        f"there any more; choose a testbed file")


# ======================================================================================
# reading
# ======================================================================================
def check_channel(role: str, channel: str, choices: Iterable[str], which: str) -> None:
    """LogIdentificationError "<role> channel '<channel>': <which>" unless `channel` is
    one of `choices` (`which` says what may be chosen)."""
    if channel not in choices:
        raise LogIdentificationError(f"{role} channel {channel!r}: {which}")


def require_channels(reader: LogReader, names: list[str], what: str) -> None:
    have = {c.name for c in reader.channels(PACKET)}
    missing = [n for n in names if n not in have]
    if missing:
        known = [c for c in SIGNAL_CHANNELS if c in have]
        raise MissingChannelError(
            f"{reader.path.name}: the log has no {PACKET} channel "
            f"{', '.join(repr(m) for m in missing)} for {what}"
            + (f" (it has {', '.join(known)})" if known else ""))


def window_rows(reader: LogReader, start_s, stop_s) -> tuple[int, int]:
    if start_s is not None and stop_s is not None and float(start_s) >= float(stop_s):
        raise WindowTooShortError(f"window {start_s}..{stop_s} s: 'from' must be before 'to'")
    i0, i1 = reader.index_range(PACKET, start_s, stop_s, relative=True)
    if i1 <= i0:
        raise WindowTooShortError(f"{reader.path.name}: no {PACKET} frames in the window "
                                  f"{reader.describe_range(PACKET, start_s, stop_s, relative=True)}")
    return i0, i1


def longest_run(device_time: np.ndarray, rate_hz: float) -> tuple[int, int, int]:
    """(a, b, missing) of the longest stretch [a, b) whose frames follow one tick apart,
    and the frames missing anywhere in the record."""
    if device_time.size < 2:
        return 0, device_time.size, 0
    ticks = np.rint(np.diff(device_time) * rate_hz)
    missing = int(np.maximum(ticks - 1, 0).sum())
    breaks = np.flatnonzero(ticks != 1) + 1
    if not breaks.size:
        return 0, device_time.size, 0
    edges = np.concatenate(([0], breaks, [device_time.size]))
    k = int(np.argmax(np.diff(edges)))
    return int(edges[k]), int(edges[k + 1]), missing


def profile_span(index: np.ndarray) -> tuple[int, int] | None:
    playing = np.flatnonzero(index > 0)
    if not playing.size:
        return None
    return int(playing[0]), int(playing[-1]) + 1


# ======================================================================================
# logs of a folder
# ======================================================================================
def find_logs(folder: str | Path) -> list[Path]:
    """The logs (*.h5) in `folder` and below, sorted by path (a campaign's folder holds
    one per recorded step).  AnalysisError if the folder cannot be listed."""
    root = Path(folder)
    if not root.is_dir():
        raise AnalysisError(f"{root}: not a folder")
    try:
        return sorted(p for p in root.rglob("*.h5") if p.is_file())
    except OSError as exc:
        raise AnalysisError(f"{root}: cannot list the logs ({exc.strerror or exc})") from None


__all__ = ["LogIdentificationError", "MissingChannelError", "NoExcitationError", "PACKET",
           "SIGNAL_CHANNELS", "TestbedInfo", "WindowTooShortError", "check_channel",
           "coarse_torque_constant", "find_logs", "longest_run", "profile_span",
           "require_channels", "testbed_info", "window_rows"]
