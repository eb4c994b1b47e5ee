"""What runs in the design workbench's worker process (or thread): no Qt, so that the
spawned process imports only the numerics.  design_workbench_jobs drives it."""

from __future__ import annotations

import logging
import time
from typing import Any

from ...core.errors import GroundStationError
from .model import slow_views

log = logging.getLogger(__name__)

_dictionary = None                       # in the worker process: the GUI's dictionary


def start(dictionary) -> None:
    """The process's initializer: keep the dictionary the jobs use."""
    global _dictionary
    _dictionary = dictionary


def ready() -> bool:
    """A job that does nothing: submitted first, so the process starts (and imports) early."""
    return True


def compute(design, dictionary=None) -> tuple[Any, str, float]:
    """(result, message, seconds) of one job: slow_views, or why it could not be had."""
    t0 = time.perf_counter()
    try:
        return slow_views(design, dictionary or _dictionary), "", time.perf_counter() - t0
    except GroundStationError as exc:
        return None, str(exc), time.perf_counter() - t0
    except Exception as exc:                 # a bug: logged, reported in one line
        log.exception("workbench: the slow views failed")
        return None, f"internal error: {type(exc).__name__}: {exc}", time.perf_counter() - t0
