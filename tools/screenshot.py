"""Render the main window offscreen, live on the simulated testbed, to docs/screenshot.png.

    QT_QPA_PLATFORM=offscreen .venv/bin/python tools/screenshot.py [seconds]

The simulator runs the inertial configuration with the base stage moving and the axis
in relative position control, so the charts show real motion, not flat lines.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from PySide6.QtCore import QSettings, QTimer  # noqa: E402
from PySide6.QtWidgets import QApplication  # noqa: E402

from groundstation.dictionary import load_dictionary  # noqa: E402
from groundstation.gui.main_window import MainWindow  # noqa: E402
from groundstation.gui.session import Session  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 8.0
    app = QApplication(sys.argv[:1])
    session = Session(load_dictionary(), store_seconds=60.0)
    settings = QSettings(str(ROOT / "build" / "screenshot-settings.ini"), QSettings.Format.IniFormat)
    settings.clear()
    win = MainWindow(session, settings)
    win.resize(1680, 1000)
    win.show()
    win.commands.confirm_override = True
    session.connect_sim(str(ROOT / "profiles" / "testbeds" / "rigid_1dof.toml"))
    steps = iter([
        (3.0, lambda: win.commands.send("SET_MODE", mode="OPEN_LOOP")),
        (3.5, lambda: win.commands.send("ARM")),
        (4.0, lambda: session.command("SET_CURRENTS", current_coarse=0.08, current_fine=0.0)),
        (4.0 + seconds / 2, lambda: session.command("SET_CURRENTS", current_coarse=-0.08, current_fine=0.0)),
    ])
    start = time.monotonic()
    pending = [next(steps)]

    def tick():
        now = time.monotonic() - start
        while pending and now >= pending[0][0]:
            pending.pop(0)[1]()
            nxt = next(steps, None)
            if nxt:
                pending.append(nxt)
        if now > 4.0 + seconds:
            win.charts.set_window_seconds(seconds + 2)
            win.charts.refresh()
            out = ROOT / "docs" / "screenshot.png"
            win.grab().save(str(out))
            print(f"wrote {out}")
            win.close()
    timer = QTimer()
    timer.timeout.connect(tick)
    timer.start(100)
    return app.exec()


if __name__ == "__main__":
    sys.exit(main())
