"""Render the main window offscreen, live on the simulated testbed, to docs/screenshot.png.

    QT_QPA_PLATFORM=offscreen .venv/bin/python tools/screenshot.py [seconds]

The simulator runs the 2-DOF relative configuration.  The script uploads the thesis's
relative Design #2 through the Parameters panel (so the dock shows its Bode plot and
margins), arms in relative position control and steps the reference by +-0.5 mrad, so
the charts show the closed loop at work, not flat lines.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from PySide6.QtCore import QSettings, Qt, QTimer  # noqa: E402
from PySide6.QtWidgets import QApplication  # noqa: E402

from groundstation.core.dictionary import load_dictionary  # noqa: E402
from groundstation.gui.main_window import MainWindow  # noqa: E402
from groundstation.gui.session.session import Session  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 8.0
    app = QApplication(sys.argv[:1])
    session = Session(load_dictionary(), store_seconds=60.0,
                      param_history=ROOT / "build" / "screenshot-history")
    settings = QSettings(str(ROOT / "build" / "screenshot-settings.ini"), QSettings.Format.IniFormat)
    settings.clear()
    win = MainWindow(session, settings)
    win.resize(1680, 1150)
    win.show()
    win.commands.confirm_override = True
    win.parameters.confirm_override = True
    win.charts.set_layout([["HIGH_RATE.encoder_inner", "HIGH_RATE.reference"],
                           ["HIGH_RATE.encoder_outer"],
                           ["HIGH_RATE.error_angle"],
                           ["HIGH_RATE.torque_coarse_cmd", "HIGH_RATE.torque_fine_cmd"]])
    session.connect_sim(str(ROOT / "profiles" / "testbeds" / "relative_2dof.toml"))
    design = ROOT / "profiles" / "controllers" / "relative_design2.toml"

    def upload():
        win.docks["Parameters"].raise_()
        # room for the dock's Bode plot under its design summary (once the layout is settled)
        win.resizeDocks([win.docks["Parameters"]], [340], Qt.Orientation.Vertical)
        if win.parameters.load_design(design):
            win.parameters.upload()

    steps = iter([
        (1.0, upload),
        (4.5, lambda: win.commands.send("SET_MODE", mode="RELATIVE")),
        (5.0, lambda: win.commands.send("ARM")),
        (5.5, lambda: session.command("SET_REFERENCE", reference=0.5e-3)),
        (5.5 + seconds / 3, lambda: session.command("SET_REFERENCE", reference=-0.5e-3)),
        (5.5 + 2 * seconds / 3, lambda: session.command("SET_REFERENCE", reference=0.0)),
    ])
    start = None                  # the timeline starts when the link is up (a busy machine is slow)
    pending = [next(steps)]

    def tick():
        nonlocal start
        if start is None:
            if session.client is None or session.client.link_state != "up":
                return
            start = time.monotonic()
        now = time.monotonic() - start
        while pending and now >= pending[0][0]:
            pending.pop(0)[1]()
            nxt = next(steps, None)
            if nxt:
                pending.append(nxt)
        if now > 5.5 + seconds:
            win.charts.set_window_seconds(seconds + 2)
            win.charts.refresh()
            out = ROOT / "docs" / "screenshot.png"
            win.grab().save(str(out))
            print(f"wrote {out}")
            # once: a tick after close() would grab the closed window (charts hidden, no fps)
            timer.stop()
            win.close()
            app.quit()
    timer = QTimer()
    timer.timeout.connect(tick)
    timer.start(100)
    return app.exec()


if __name__ == "__main__":
    sys.exit(main())
