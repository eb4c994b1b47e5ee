"""The journal record of the function generator: what the window did with the generator,
as a log's journal keeps it (kind "function_generator"), and what `fg check` reads back.

One record per action.  Every record has the action and the VISA resource; the other
fields are those its action carries (ACTION_FIELDS):

    open     identity, limits            the generator opened, and the limits applied
    close    device_time                 closed (outputs off)
    apply    channel, wave, load, device_time           a basic wave sent
    output   channel, on, device_time                   an output switched
    upload   channel, name, profile, psd_source, duration_s, seed, target_rms_rad,
             precompensated, band_hz, points, frequency_hz, amplitude_vpp, device_time
    abort    device_time                 both outputs off at once
    check    profile, target_rms_rad, achieved_rms_rad, window_s, missing_frames, ok

`device_time` is the newest telemetry time when the action was taken (s, the device's
clock; null when no telemetry had arrived).  A record read back must have its action's
fields and no others, of the right types; a field whose value may be null may also be
absent (a record written before it existed), and reads as None.  Anything else raises
GeneratorJournalError naming the action and the field, so a reader can skip the record
and say why.  No Qt here: the window writes these records and the command line reads
them.
"""

from __future__ import annotations

import numbers
import os
from dataclasses import dataclass
from typing import Any, Callable, Mapping, NamedTuple

from ..core.errors import GroundStationError

#: the journal kind these records are written under (logs/schema.py JOURNAL_KINDS)
JOURNAL_KIND = "function_generator"

#: the fields each action carries, besides `action` and `resource`
ACTION_FIELDS: dict[str, tuple[str, ...]] = {
    "open": ("identity", "limits"),
    "close": ("device_time",),
    "apply": ("channel", "wave", "load", "device_time"),
    "output": ("channel", "on", "device_time"),
    "upload": ("channel", "name", "profile", "psd_source", "duration_s", "seed",
               "target_rms_rad", "precompensated", "band_hz", "points", "frequency_hz",
               "amplitude_vpp", "device_time"),
    "abort": ("device_time",),
    "check": ("profile", "target_rms_rad", "achieved_rms_rad", "window_s", "missing_frames",
              "ok"),
}


class GeneratorJournalError(GroundStationError, ValueError):
    """A function-generator journal record that does not follow the schema (the message
    names the action and the field)."""


# ----------------------------------------------------------------------------- field checks
# Each check returns the value as the record holds it, or raises TypeError.  Numbers
# from numpy (the check's RMS, the upload's point count) are taken as plain numbers.
def _number(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError
    return float(v)


def _integer(v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, numbers.Integral):
        raise TypeError
    return int(v)


def _flag(v: Any) -> bool:
    # numpy's bool is neither a bool nor a number; its dtype says what it is
    if isinstance(v, bool) or getattr(getattr(v, "dtype", None), "kind", "") == "b":
        return bool(v)
    raise TypeError


def _text(v: Any) -> str:
    if not isinstance(v, str):
        raise TypeError
    return v


def _path_text(v: Any) -> str:
    if not isinstance(v, (str, os.PathLike)):
        raise TypeError
    return os.fspath(v)


def _table(v: Any) -> dict:
    if not isinstance(v, Mapping):
        raise TypeError
    return dict(v)


def _pair(v: Any) -> tuple[float, float]:
    if isinstance(v, (str, bytes)) or not hasattr(v, "__len__") or len(v) != 2:
        raise TypeError
    return _number(v[0]), _number(v[1])


def _load(v: Any) -> str | int:
    if isinstance(v, str):
        return v
    return _integer(v)


class _Field(NamedTuple):
    check: Callable[[Any], Any]
    wanted: str                 # what the value must be, for the message
    nullable: bool = False      # None allowed (and the field may be absent when read)

    def value(self, v: Any) -> Any:
        return None if v is None and self.nullable else self.check(v)


_FIELDS: dict[str, _Field] = {
    "device_time": _Field(_number, "a number of seconds or null", nullable=True),
    "channel": _Field(_integer, "an integer channel number"),
    "on": _Field(_flag, "true or false"),
    "identity": _Field(_text, "text"),
    "limits": _Field(_table, "a table"),
    "wave": _Field(_table, "a table"),
    "load": _Field(_load, "text, an integer or null", nullable=True),
    "name": _Field(_text, "text"),
    "profile": _Field(_text, "text"),
    "psd_source": _Field(_path_text, "text (a file's path)"),
    "duration_s": _Field(_number, "a number of seconds"),
    "seed": _Field(_integer, "an integer"),
    "target_rms_rad": _Field(_number, "a number (rad)"),
    "precompensated": _Field(_flag, "true or false"),
    "band_hz": _Field(_pair, "two numbers (Hz)"),
    "points": _Field(_integer, "an integer"),
    "frequency_hz": _Field(_number, "a number (Hz)"),
    "amplitude_vpp": _Field(_number, "a number (Vpp)"),
    "achieved_rms_rad": _Field(_number, "a number (rad)"),
    "window_s": _Field(_pair, "two numbers (s)"),
    "missing_frames": _Field(_integer, "an integer"),
    "ok": _Field(_flag, "true or false"),
}


@dataclass(frozen=True)
class GeneratorJournalRecord:
    """One function-generator journal record.  Fields the action does not carry are
    None; constructing a record checks (and makes plain) the ones it does."""

    action: str
    resource: str
    device_time: float | None = None
    channel: int | None = None
    on: bool | None = None
    identity: str | None = None
    limits: dict | None = None
    wave: dict | None = None
    load: str | int | None = None
    name: str | None = None
    profile: str | None = None
    psd_source: str | None = None
    duration_s: float | None = None
    seed: int | None = None
    target_rms_rad: float | None = None
    precompensated: bool | None = None
    band_hz: tuple[float, float] | None = None
    points: int | None = None
    frequency_hz: float | None = None
    amplitude_vpp: float | None = None
    achieved_rms_rad: float | None = None
    window_s: tuple[float, float] | None = None
    missing_frames: int | None = None
    ok: bool | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.action, str) or self.action not in ACTION_FIELDS:
            raise GeneratorJournalError(f"{JOURNAL_KIND} record: action {self.action!r} is not "
                                        f"one of {', '.join(ACTION_FIELDS)}")
        where = f"{JOURNAL_KIND} record '{self.action}'"
        if not isinstance(self.resource, str):
            raise GeneratorJournalError(f"{where}: resource = {self.resource!r} must be text")
        carried = ACTION_FIELDS[self.action]
        for name, spec in _FIELDS.items():
            value = getattr(self, name)
            if name not in carried:
                if value is not None:
                    raise GeneratorJournalError(f"{where}: has {name} = {value!r}, which this "
                                                f"action does not carry (it carries "
                                                f"{', '.join(carried)})")
                continue
            try:
                # frozen: the checked, plain value replaces the one given
                object.__setattr__(self, name, spec.value(value))
            except (TypeError, ValueError):
                raise GeneratorJournalError(f"{where}: {name} = {value!r} must be "
                                            f"{spec.wanted}") from None

    def carried(self) -> dict[str, Any]:
        """The fields this record's action carries, by name."""
        return {name: getattr(self, name) for name in ACTION_FIELDS[self.action]}

    def to_record(self) -> dict[str, Any]:
        """The JSON-able dict the journal keeps: action, resource, the action's fields."""
        record: dict[str, Any] = {"action": self.action, "resource": self.resource}
        for name, value in self.carried().items():
            record[name] = list(value) if isinstance(value, tuple) else value
        return record

    @classmethod
    def from_record(cls, data: Any) -> GeneratorJournalRecord:
        """The record a journal entry holds; GeneratorJournalError if it does not follow
        the schema (module docstring)."""
        if not isinstance(data, Mapping):
            raise GeneratorJournalError(f"{JOURNAL_KIND} record: {type(data).__name__} "
                                        f"instead of a table of fields")
        action = data.get("action")
        if not isinstance(action, str) or action not in ACTION_FIELDS:
            raise GeneratorJournalError(f"{JOURNAL_KIND} record: action {action!r} is not one "
                                        f"of {', '.join(ACTION_FIELDS)}")
        where = f"{JOURNAL_KIND} record '{action}'"
        if "resource" not in data:
            raise GeneratorJournalError(f"{where}: no resource")
        carried = ACTION_FIELDS[action]
        unknown = sorted(str(k) for k in data if k not in ("action", "resource", *carried))
        if unknown:
            raise GeneratorJournalError(f"{where}: unknown field(s) {', '.join(unknown)} (it "
                                        f"carries {', '.join(carried)})")
        missing = [name for name in carried if name not in data and not _FIELDS[name].nullable]
        if missing:
            raise GeneratorJournalError(f"{where}: no {', '.join(missing)}")
        return cls(action=action, resource=data["resource"],
                   **{name: data.get(name) for name in carried})

__all__ = ["ACTION_FIELDS", "JOURNAL_KIND", "GeneratorJournalError", "GeneratorJournalRecord"]
