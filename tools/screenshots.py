"""Screenshots of the window in each of its sources, to docs/screenshots/:

    live-simulator.png     live on the simulated testbed (`make run`)
    read-only-console.png  a read-only console (`--watch`) watching it during the demo
    demo-after.png         after "Demo: step response on the simulator" ran
    replay.png             a replay of the log recorded during the demo

    make screenshots                      # installs xvfb when missing (root), runs this
    xvfb-run -a -s "-screen 0 1920x1080x24" .venv/bin/python tools/screenshots.py [folder]

Run it on a virtual X server (xvfb-run): the offscreen platform's screen is 800 x 800
and the window fits itself to its screen.  Each window has its own settings and
parameter history in a temporary folder, so neither the operator's saved layout nor
their history is read or changed.  Not part of `make test`.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

from PySide6.QtCore import QEventLoop, QSettings
from PySide6.QtWidgets import QApplication

from groundstation.core.dictionary import load_dictionary
from groundstation.core.kinds import LinkState
from groundstation.gui.main_window import MainWindow
from groundstation.gui.session.session import Session

ROOT = Path(__file__).resolve().parent.parent
#: the size of every window shot (a 1080p screen less a desktop's bars)
SIZE = (1600, 950)
#: generous: a loaded machine runs the real-time simulator and its compile slowly
STEP_TIMEOUT_S = 180.0


class Shots:
    def __init__(self, folder: Path, scratch: Path):
        self.app = QApplication.instance() or QApplication(sys.argv[:1])
        self.d = load_dictionary()
        self.folder, self.scratch = folder, scratch
        self.windows: list[MainWindow] = []

    def window(self, name: str) -> MainWindow:
        session = Session(self.d, store_seconds=60.0, param_history=self.scratch / f"{name}-history")
        settings = QSettings(str(self.scratch / f"{name}.ini"), QSettings.Format.IniFormat)
        win = MainWindow(session, settings)
        win.resize(*SIZE)
        win.show()
        win.commands.confirm_override = True
        win.parameters.confirm_override = True
        self.windows.append(win)
        return win

    def spin(self, what: str, done, timeout: float = STEP_TIMEOUT_S) -> None:
        """Serve the windows' events until done() (or give up saying what was awaited)."""
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                raise SystemExit(f"screenshots: gave up waiting for {what} ({timeout:g} s)")
            self.app.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 50)
            time.sleep(0.01)

    def settle(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        self.spin(f"{seconds:g} s", lambda: time.monotonic() >= end, seconds + 5)

    def shoot(self, win: MainWindow, name: str) -> None:
        win.charts.refresh()
        self.app.processEvents()
        out = self.folder / name
        win.grab().save(str(out))
        print(f"wrote {out.relative_to(ROOT) if out.is_relative_to(ROOT) else out}", flush=True)

    def close(self) -> None:
        for win in self.windows:
            win.close()
        self.app.processEvents()


def frames(win: MainWindow) -> int:
    return win.session.store.ring("HIGH_RATE").total_frames


def run(shots: Shots) -> None:
    # 1. live on the simulator, publishing for a console
    live = shots.window("live")
    live.session.start_publishing("tcp://127.0.0.1:*")
    live.session.connect_sim()
    shots.spin("the simulator's link", lambda: live.session.client is not None
               and live.session.client.link_state == LinkState.UP and frames(live) > 3 * 1200)
    shots.settle(2.0)
    shots.shoot(live, "live-simulator.png")

    # 2. a read-only console on it, shot while the demo runs (its charts move); the
    #    demo recorded for the replay
    console = shots.window("console")
    console.session.watch(live.session.consoles.publisher.endpoint)
    shots.spin("the console's first frames", lambda: frames(console) > 1200)
    log = live.session.start_recording(str(shots.scratch / "logs"), "demo")
    if log is None:
        raise SystemExit("screenshots: the demo's recording did not start")
    live.demo_action.trigger()
    shots.spin("the demo to play", lambda: live.demo.state in ("playing", "completed", "failed", "aborted"))
    shots.settle(4.0)
    shots.spin("the console's device address", lambda: bool(console.session.client.device))
    shots.settle(1.0)                              # the bar's next refresh names it
    shots.shoot(console, "read-only-console.png")
    shots.spin("the demo to end", lambda: live.demo.state in ("completed", "failed", "aborted"))
    if live.demo.state != "completed":
        raise SystemExit(f"screenshots: the demo {live.demo.state}: {live.demo.text}")
    shots.settle(1.5)
    shots.shoot(live, "demo-after.png")
    live.session.stop_recording()
    console.close()

    # 3. the demo's log replayed to its end
    replay = shots.window("replay")
    replay.session.open_log(str(log))
    replay.replay_bar.speed.setCurrentText("max")      # as fast as it reads, as the bar says
    replay.session.replay.play()
    shots.spin("the replay's end", lambda: replay.session.replay.finished)
    shots.settle(1.0)
    shots.shoot(replay, "replay.png")


def main() -> int:
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "screenshots"
    folder.mkdir(parents=True, exist_ok=True)
    if not os.environ.get("DISPLAY") and not os.environ.get("QT_QPA_PLATFORM"):
        print("screenshots: no X display: run it under xvfb-run (make screenshots); "
              "using the offscreen platform, whose 800 x 800 screen makes small windows",
              file=sys.stderr)
        os.environ["QT_QPA_PLATFORM"] = "offscreen"
    with tempfile.TemporaryDirectory(prefix="gs-screenshots-") as scratch:
        shots = Shots(folder, Path(scratch))
        try:
            run(shots)
        finally:
            shots.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
