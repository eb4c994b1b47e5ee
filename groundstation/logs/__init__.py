"""HDF5 recording, reading, export and replay of testbed sessions."""

from .export import export_csv, export_mat
from .h5file import LogFile
from .check import check_log
from .reader import LogReader
from .opening import LogDamagedError, LogFormatError, LogQueryError
from .opening import LogError
from .recorder import Recorder, RecorderError, RecorderStatus, log_path
from .replay import ReplaySource
from .blocks import ReplayDamagedError, ReplayError, iter_blocks

__all__ = ["LogDamagedError", "LogError", "LogFile", "LogFormatError", "LogQueryError", "LogReader", "Recorder",
           "RecorderError", "RecorderStatus", "ReplayDamagedError", "ReplayError", "ReplaySource", "export_csv",
           "check_log", "export_mat", "iter_blocks", "log_path"]
