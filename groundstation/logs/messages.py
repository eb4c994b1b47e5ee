"""What the recorder and its writer process say to each other (through two queues).

Small frozen dataclasses rather than tuples of strings: each side matches on the class,
a misspelt kind is an error at import instead of a message nobody handles, and the
fields say what they are.  They are pickled through multiprocessing queues, so they
hold only plain values (bytes, floats, numpy arrays, str)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


# ------------------------------------------------------------------ recorder -> writer
@dataclass(frozen=True)
class Frames:
    """One telemetry block as received: the frame bytes and their host arrival times."""
    packet_id: int
    data: Any                  # bytes (fixed-size packets) or a list of frame bytes
    host_time: np.ndarray      # s since the epoch, one per frame


@dataclass(frozen=True)
class JournalEntry:
    at: float                  # host time, s since the epoch
    kind: str                  # one of schema.JOURNAL_KINDS
    record: dict
    blob: bytes = b""


@dataclass(frozen=True)
class Stop:
    """Write what is queued, close the file; `reason` goes into its closing record."""
    reason: str = ""


# ------------------------------------------------------------------ writer -> recorder
@dataclass(frozen=True)
class Started:
    path: str


@dataclass(frozen=True)
class StartFailed:
    message: str


@dataclass(frozen=True)
class Flushed:
    frames: int                # frames in the current file
    size_bytes: int
    last_host_time: float | None
    path: str


@dataclass(frozen=True)
class Closed:
    """A file was closed at a rollover (a new one follows with Started)."""
    frames: int
    path: str


@dataclass(frozen=True)
class Stopped:
    frames: int
    path: str


@dataclass(frozen=True)
class Failed:
    message: str
    last_host_time: float | None
    frames: int = field(default=0)
