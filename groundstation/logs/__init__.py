"""HDF5 recording, reading, export and replay of testbed sessions.

The names below are imported on first use (PEP 562): a log writer process imports
`groundstation.logs.writer`, which runs this file first, and needs only the file layout
and the codec - not the reader, export, replay and the link they bring (about 0.2 s of
CPU at every writer's start, one writer per recording: docs/campaigns.md).
"""

from __future__ import annotations

from ..core.lazy_names import lazy_dir, lazy_getattr

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


__getattr__ = lazy_getattr(__name__, _LAZY, globals())
__dir__ = lazy_dir(_LAZY, globals())


__all__ = sorted(_LAZY)
