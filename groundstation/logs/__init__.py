"""HDF5 recording, reading, export and replay of testbed sessions."""

from .h5file import LogFile
from .recorder import Recorder, RecorderError, RecorderStatus, log_path

__all__ = ["LogFile", "Recorder", "RecorderError", "RecorderStatus", "log_path"]
