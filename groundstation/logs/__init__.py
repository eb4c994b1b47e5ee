"""HDF5 recording, reading, export and replay of testbed sessions."""

from .export import export_csv, export_mat
from .h5file import LogFile
from .check import check_log
from .reader import LogDamagedError, LogError, LogFormatError, LogQueryError, LogReader
from .recorder import Recorder, RecorderError, RecorderStatus, log_path
from .replay import ReplayDamagedError, ReplayError, ReplaySource, iter_blocks

__all__ = ["LogDamagedError", "LogError", "LogFile", "LogFormatError", "LogQueryError", "LogReader", "Recorder",
           "RecorderError", "RecorderStatus", "ReplayDamagedError", "ReplayError", "ReplaySource", "export_csv",
           "check_log", "export_mat", "iter_blocks", "log_path"]
