"""HDF5 recording, reading, export and replay of testbed sessions.

The names below are imported on first use (PEP 562): a log writer process imports
`groundstation.logs.writer`, which runs this file first, and needs only the file layout
and the codec - not the reader, export, replay and the link they bring (about 0.2 s of
CPU at every writer's start, one writer per recording: docs/campaigns.md).
"""

from __future__ import annotations

from importlib import import_module

_LAZY = {
    "export_csv": "export", "export_mat": "export",
    "LogFile": "h5file",
    "check_log": "check",
    "LogReader": "reader",
    "LogDamagedError": "opening", "LogFormatError": "opening", "LogQueryError": "opening",
    "LogError": "opening",
    "Recorder": "recorder", "RecorderError": "recorder", "RecorderStatus": "recorder",
    "log_path": "recorder",
    "ReplaySource": "replay",
    "ReplayDamagedError": "blocks", "ReplayError": "blocks", "iter_blocks": "blocks",
}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value          # looked up once
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = sorted(_LAZY)
