"""Starting the window: `groundstation run` / `groundstation gui`."""

from __future__ import annotations

import os
import signal
import sys

from ..core.dictionary import Dictionary
from ..core.kinds import SIMULATED_DEVICE


def display_available() -> bool:
    """A screen to show a window on (X11 or Wayland), or an explicit Qt platform."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                or os.environ.get("QT_QPA_PLATFORM"))


def run_gui(dictionary: Dictionary, *, connect: str | None = SIMULATED_DEVICE, testbed: str | None = None,
            replay: str | None = None, watch: str | None = None, publish: str | None = None,
            curve_keys: str | None = None, key_name: str = "viewer") -> int:
    """`watch`: a read-only console on the station publishing there (connect is then not
    used); `publish`: this window's link published for such consoles (docs/consoles.md)."""
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from .main_window import MainWindow
    from .session.session import Session

    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName("groundstation")
    app.setOrganizationName("groundstation")
    session = Session(dictionary)
    window = MainWindow(session)
    window.show()
    if publish and not watch:
        session.start_publishing(publish, curve_keys)
    if watch:
        session.testbed = testbed
        session.watch(watch, curve_keys, key_name)
    elif replay:
        session.open_log(replay)
    elif connect == SIMULATED_DEVICE:
        session.connect_sim(testbed)
    elif connect:
        session.connect_address(connect)
    # Ctrl-C in the terminal closes the window cleanly (Qt would otherwise swallow it)
    signal.signal(signal.SIGINT, lambda *_: window.close())
    tick = QTimer()
    tick.timeout.connect(lambda: None)     # lets Python see the signal while Qt runs
    tick.start(200)
    return app.exec()
