"""Run one of the README tour's window commands the way a newcomer would, and check it did
what the tour promises - offscreen, in a process of its own.

    python readme_tour_gui.py run                 # `make run`, then the Demo button
    python readme_tour_gui.py gui --replay LOG    # the window replaying a log

The command goes through the real CLI (`groundstation.cli.main.main`), so the window,
its session and the simulator are the product's own.  A Qt timer in the window's event
loop watches for what the tour says the reader will see, then closes the window; the
exit status is 0 when it was seen, 1 otherwise (with what was missing on stderr).

The watch is bounded by a number of polls, not by a time to meet: the poll interval only
decides how often we look.
"""

from __future__ import annotations

import os
import sys

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

POLL_MS = 100
MAX_POLLS = 3000          # 300 s of polling at most: a busy 2-core machine runs the demo in < 30 s


class TourWatch:
    """Looks at the window each poll; `steps` are (what the reader should see, predicate,
    action once seen).  A predicate returning a string is a failure with that reason."""

    def __init__(self, app, steps):
        self.app, self.steps, self.polls = app, list(steps), 0
        self.failure: str | None = None
        self.seen: list[str] = []

    def window(self):
        from groundstation.gui.main_window import MainWindow
        for widget in self.app.topLevelWidgets():
            if isinstance(widget, MainWindow):
                return widget
        return None

    def poll(self) -> None:
        self.polls += 1
        win = self.window()
        if win is not None and self.steps:
            what, predicate, action = self.steps[0]
            verdict = predicate(win)
            if isinstance(verdict, str):
                self.failure = f"{what}: {verdict}"
            elif verdict:
                self.seen.append(what)
                self.steps.pop(0)
                if action is not None:
                    action(win)
        if self.failure is None and self.polls >= MAX_POLLS:
            self.failure = f"{self.steps[0][0] if self.steps else 'the window'}: not seen after {MAX_POLLS} polls"
        if self.failure is not None or not self.steps:
            self.timer.stop()
            if win is not None:
                win.close()
            else:
                self.app.quit()


def demo_steps():
    def demo_outcome(win):
        state = win.demo.state
        if state == "completed":
            return True
        if state in ("refused", "failed", "aborted"):
            return f"the demo ended '{state}': {win.demo.text}"
        return False

    return [
        ("the link to the simulated testbed is up and the Demo button is enabled",
         lambda win: win.demo_action.isEnabled(), lambda win: win.demo_action.trigger()),
        ("the demo played its step response to the end", demo_outcome, None),
        ("the charts received the step's telemetry",
         lambda win: win.session.store.ring("HIGH_RATE").total_frames > 1200, None),
    ]


def replay_steps():
    return [
        ("the log opened for replay", lambda win: win.session.replay is not None, None),
        ("the charts show the log's telemetry",
         lambda win: win.session.store.ring("HIGH_RATE").total_frames > 0, None),
    ]


def main(argv: list[str]) -> int:
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from groundstation.cli.main import main as groundstation_main

    if argv[:1] == ["run"]:
        steps = demo_steps()
    elif argv[:1] == ["gui"] and "--replay" in argv:
        steps = replay_steps()
    else:
        print(f"readme_tour_gui: no check written for 'groundstation {' '.join(argv)}'", file=sys.stderr)
        return 2
    app = QApplication.instance() or QApplication(sys.argv[:1])
    watch = TourWatch(app, steps)
    watch.timer = QTimer()
    watch.timer.timeout.connect(watch.poll)
    watch.timer.start(POLL_MS)
    status = groundstation_main(argv)
    if watch.failure is not None:
        print(f"readme_tour_gui: {watch.failure} (seen: {watch.seen or 'nothing'})", file=sys.stderr)
        return 1
    if watch.steps:
        print(f"readme_tour_gui: the window closed before '{watch.steps[0][0]}'", file=sys.stderr)
        return 1
    print(f"readme_tour_gui: saw {'; '.join(watch.seen)}")
    return status or 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
