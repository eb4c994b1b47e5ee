"""HDF5 recording, reading, export and replay of testbed sessions."""

from .export import export_csv, export_mat
from .h5file import LogFile
from .reader import LogError, LogFormatError, LogQueryError, LogReader
from .recorder import Recorder, RecorderError, RecorderStatus, log_path
from .replay import ReplayError, ReplaySource, iter_blocks

__all__ = ["LogError", "LogFile", "LogFormatError", "LogQueryError", "LogReader", "Recorder",
           "RecorderError", "RecorderStatus", "ReplayError", "ReplaySource", "export_csv",
           "export_mat", "iter_blocks", "log_path"]
