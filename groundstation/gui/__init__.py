"""The operator's window (PySide6 + pyqtgraph).  Only this package imports Qt."""
