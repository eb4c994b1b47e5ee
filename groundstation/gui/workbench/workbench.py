"""The design workbench: a window, opened from the Parameters dock ("Workbench…"), that
shows the PQ method's views of one design or of two side by side (#1 blue, #2 orange),
lets the operator edit Q's and c0's gain and factors and see every view follow, saves
the result as a design file and hands it to the Parameters dock (Send to Parameters),
whose load_design -> validate -> upload path then applies as to any file.

Why a window and not another dock: nine plots and two columns of numbers need most of a
screen, the Parameters dock lives in the low bottom dock area tabbed with six others,
and the workbench is used beside it (validate, upload) - a window can be maximised or
put on a second screen while the dock stays where it is, and the main window's saved
dock layout does not change.  It is a child of the Parameters dock, so it closes with
the main window and is disabled with the dock while a campaign runs.

`open_on_testbed` opens it on another testbed file of a design's kind - an identified
rig, from the Analysis dock's Identify tab: #1 the design on the testbed it names, #2
the same design on that file (judged on it as the upload gate judges it,
params/upload_path.judged_on), so every view compares the two plants under one
controller.

Each edit recomputes on the GUI thread what takes milliseconds - the frequency views,
T_I(0), the alignment at the report's frequencies, the PQ crossovers - and asks the
worker (design_workbench_jobs) for what takes tens: the validation's margins and
verdict and the linear responses.  Until those arrive the slot's responses are drawn
faint and its rows in the table say "(stale)".  `edit_ms` holds the GUI-thread time of
each edit (model + numbers + plots), `slow_ms` the worker's time per slot.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (QFileDialog, QHBoxLayout, QLabel, QPushButton, QSplitter,
                               QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget)

from ...core.dictionary import Dictionary
from ...core.errors import GroundStationError
from ...params.design_file import ControllerDesign, load_design
from ...params.tf_algebra import DesignError
from ...params.upload_path import judged_on
from ...plant.testbed import PROFILES_DIR, Testbed, load_testbed
from .editor import FactorEditor
from .jobs import SlowJobs
from .model import SLOTS, WorkbenchModel, fast_views
from .plots import DESIGN_COLOURS, WorkbenchPlots

STALE = QBrush(QColor(150, 150, 150))
ROWS = (("design", "design"), ("file", "file"), ("testbed", "testbed"), ("state", "state"),
        ("c0", "c0"),
        ("dc", "T_I(0) [[u1 ← d1, u1 ← d2], [u2 ← d1, u2 ← d2]]"),
        ("phi_1", "φ at 1 Hz"), ("phi_5", "φ at 5 Hz"), ("phi_14", "φ at 14 Hz"),
        ("phi_22", "φ at 22 Hz"), ("pq_cross", "|PQ| = 1 at (∠PQ)"),
        ("verdict", "validation"), ("margins", "margins, loop broken at e"),
        ("inner", "rate loop alone"), ("outer", "position loop (K_p)"),
        ("dist", "peak |u1|, |u2| under the disturbance"), ("step", "peak |u1|, |u2| under the step"),
        ("times", "recompute: views / margins+responses"))
SLOW_ROWS = ("verdict", "margins", "inner", "outer", "dist", "step")
ROW = {key: i for i, (key, _) in enumerate(ROWS)}
CONTROLLERS_DIR = PROFILES_DIR / "controllers"


def _kind(testbed: Testbed) -> tuple[str, str]:
    return testbed.configuration, str(testbed.setup)


def shipped_design_for(testbed: Testbed) -> ControllerDesign:
    """The first shipped 2-DOF design (by file name) made for a testbed of `testbed`'s
    kind; DesignError when there is none (a 1-DOF rig has no PQ views)."""
    for path in sorted(CONTROLLERS_DIR.glob("*.toml")):
        try:
            design = load_design(path)
        except GroundStationError:
            continue                              # a file the workbench could not open anyway
        if design.testbed.is_2dof and _kind(design.testbed) == _kind(testbed):
            return design
    raise DesignError(f"no shipped 2-DOF design for a {testbed.configuration} {testbed.setup} "
                      f"testbed ({testbed.path.name}): the workbench's PQ views need two inputs")


def margins_text(m) -> str:
    if m is None:
        return "–"
    gm = "GM ∞" if m.gain_margin_db == float("inf") else f"GM {m.gain_margin_db:.1f} dB @ {m.gain_margin_hz:.3g} Hz"
    if m.lower_gain_margin_db is not None:
        gm += f" (lower {m.lower_gain_margin_db:.1f} dB @ {m.lower_gain_margin_hz:.3g} Hz)"
    pm = "no crossover" if m.crossover_hz is None else f"PM {m.phase_margin_deg:.1f}° @ {m.crossover_hz:.3g} Hz"
    return f"{gm}; {pm}"


def peaks_text(s) -> str:
    (p1, p2), (l1, l2) = s.peaks_in_oz, s.limits_in_oz
    words = [f"{p:.3g}{' SATURATES' if p > lim else ''}" for p, lim in ((p1, l1), (p2, l2))]
    return f"{words[0]}, {words[1]} in-oz (limits {l1:g}, {l2:g})"


class DesignWorkbench(QWidget):
    sig_fresh = Signal()            # every view of every open design is up to date

    def __init__(self, dictionary: Dictionary | None = None,
                 send: Callable[[Path], bool] | None = None, parent: QWidget | None = None,
                 processes: bool = True):
        super().__init__(parent)
        self.setWindowFlag(Qt.WindowType.Window)
        self.setWindowTitle("Design workbench - PQ views")
        self.model = WorkbenchModel(dictionary)
        self._send = send
        self.fast: list = [None] * SLOTS
        self.slow: list = [None] * SLOTS
        self.slow_generation = [-1] * SLOTS
        self.current = 0
        self._refs: list = []
        self._last_ms = [0.0] * SLOTS
        self.edit_ms: list[float] = []
        self.slow_ms: list[list[float]] = [[] for _ in range(SLOTS)]
        self.jobs = SlowJobs(self.model.dictionary, self, processes=processes)
        self.jobs.sig_done.connect(self._on_slow)
        self.jobs.sig_failed.connect(self._on_slow_failed)
        self._build()
        self.resize(1800, 1050)

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        lay = QVBoxLayout(self)
        bar = QHBoxLayout()
        self.open_buttons = [QPushButton("Open #1…"), QPushButton("Open #2…")]
        self.close_second = QPushButton("Close #2")
        self.save_button = QPushButton("Save as design file…")
        self.send_button = QPushButton("Send to Parameters")
        self.send_button.setToolTip("save (if needed), then load the file in the Parameters dock, "
                                    "which validates it; upload from there")
        for i, b in enumerate(self.open_buttons):
            b.clicked.connect(lambda _=False, i=i: self.open_dialog(i))
            b.setStyleSheet(f"color:{DESIGN_COLOURS[i]}; font-weight:bold;")
            bar.addWidget(b)
        bar.addWidget(self.close_second)
        bar.addStretch(1)
        bar.addWidget(self.save_button)
        bar.addWidget(self.send_button)
        lay.addLayout(bar)
        split = QSplitter(Qt.Orientation.Horizontal)
        left = QSplitter(Qt.Orientation.Vertical)
        self.editor = FactorEditor()
        self.numbers = QTableWidget(len(ROWS), SLOTS + 1)
        self.numbers.setHorizontalHeaderLabels(["", "#1", "#2"])
        self.numbers.verticalHeader().setVisible(False)
        self.numbers.setWordWrap(True)
        self.numbers.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        for key, label in ROWS:
            self.numbers.setItem(ROW[key], 0, QTableWidgetItem(label))
            for c in range(1, SLOTS + 1):
                self.numbers.setItem(ROW[key], c, QTableWidgetItem(""))
        self.numbers.setColumnWidth(0, 190)
        for c in (1, 2):
            self.numbers.setColumnWidth(c, 215)
        left.addWidget(self.editor)
        left.addWidget(self.numbers)
        left.setSizes([380, 620])
        self.plots = WorkbenchPlots()
        split.addWidget(left)
        split.addWidget(self.plots)
        split.setSizes([640, 1160])
        lay.addWidget(split, 1)
        self.message = QLabel("Open a 2-DOF design (#1), and optionally a second one (#2) to compare.")
        self.message.setWordWrap(True)
        lay.addWidget(self.message)
        self.close_second.clicked.connect(lambda: self.close_design(1))
        self.save_button.clicked.connect(lambda: self.save())
        self.send_button.clicked.connect(self.send_to_parameters)
        e = self.editor
        e.sig_slot.connect(self.select)
        e.sig_edit.connect(lambda k, p, i, t: self._change(lambda: self.model.edit(self.current, k, p, i, t)))
        e.sig_add.connect(lambda k, side: self._change(lambda: self.model.add_factor(self.current, k, side)))
        e.sig_remove.connect(lambda k, side, i: self._change(
            lambda: self.model.remove_factor(self.current, k, side, i)))
        e.sig_scale.connect(lambda k, f: self._change(lambda: self.model.scale_gain(self.current, k, f)))
        e.sig_reference.connect(self._on_reference)
        e.sig_reset.connect(lambda: self._change(lambda: self.model.reset(self.current)))
        e.sig_rename.connect(self._on_rename)
        self._show_editor()

    # ------------------------------------------------------------------ designs
    def open_dialog(self, index: int) -> None:
        path, _ = QFileDialog.getOpenFileName(self, f"Open design #{index + 1}", "profiles/controllers",
                                              "Controller designs (*.toml)")
        if path:
            self.open_design(index, path)

    def open_design(self, index: int, source: str | Path | ControllerDesign) -> bool:
        """Load a design file (or take a loaded design) into slot `index` and show it."""
        try:
            if isinstance(source, ControllerDesign):
                slot = self.model.set_design(index, source)
            else:
                slot = self.model.open(index, source)
        except GroundStationError as exc:
            self._say(str(exc), bad=True)
            return False
        self.slow[index], self.slow_generation[index] = None, -1
        self.plots.show_slow(index, None)
        self._say(f"#{index + 1}: {slot.original.name} loaded"
                  + (f" - c0 kept output-equivalent to {slot.reference.name}" if slot.reference else ""))
        self.select(index)
        self._refresh(index)
        return True

    def open_on_testbed(self, testbed: str | Path, design: ControllerDesign | None = None) -> bool:
        """#1 `design` on the testbed it names, #2 the same design on the testbed file
        `testbed` (an identified rig).  `design` None, or one for another kind of rig: the
        first shipped design for the file's kind."""
        try:
            rig = load_testbed(testbed)
            if design is None or not design.testbed.is_2dof or _kind(design.testbed) != _kind(rig):
                design = shipped_design_for(rig)
            on_rig = judged_on(design, rig)
        except GroundStationError as exc:
            self._say(f"cannot open on {Path(testbed).name}: {exc}", bad=True)
            return False
        if not (self.open_design(0, design) and self.open_design(1, on_rig)):
            return False
        self._say(f"{design.name}: #1 on {design.testbed.path.name} (the testbed it names), "
                  f"#2 on {rig.path.name}")
        return True

    def close_design(self, index: int) -> None:
        self.model.clear(index)
        self.jobs.forget(index)
        self.fast[index] = self.slow[index] = None
        self.plots.show_fast(index, None)
        self.plots.show_slow(index, None)
        for key, _ in ROWS:
            self._cell(key, index, "")
        if self.current == index:
            self.select(0)
        self._show_editor()

    def select(self, index: int) -> None:
        """The slot the editor edits."""
        self.current = index
        self.editor.slot_combo.blockSignals(True)
        self.editor.slot_combo.setCurrentIndex(index)
        self.editor.slot_combo.blockSignals(False)
        self._show_editor()

    def _show_editor(self) -> None:
        slot = self.model.slots[self.current]
        if slot is None:
            self.editor.show_slot(None, [], None)
            return
        refs = self.model.references(self.current)
        chosen = next((i for i, (_, d) in enumerate(refs) if d is slot.reference), None)
        if slot.reference is not None and chosen is None:       # a design no longer offered
            refs.append((slot.reference.name, slot.reference))
            chosen = len(refs) - 1
        self._refs = refs
        self.editor.show_slot(slot, [label for label, _ in refs], chosen)

    # ------------------------------------------------------------------ edits
    def _change(self, change: Callable) -> bool:
        t0 = time.perf_counter()
        if self.model.slots[self.current] is None:
            return False
        try:
            change()
        except GroundStationError as exc:
            self._say(f"not changed: {exc}", bad=True)
            self._show_editor()
            return False
        self._refresh(self.current, t0)
        self._show_editor()
        return True

    def _on_reference(self, choice: int) -> None:
        ref = self._refs[choice][1] if choice >= 0 else None
        if self._change(lambda: self.model.set_reference(self.current, ref)):
            self._say("c0 kept output-equivalent to " + ref.name if ref else
                      "c0 is no longer recomputed: it stays as it is and may be edited")

    def _on_rename(self, name: str) -> None:
        if self.model.slots[self.current] is not None:
            try:
                self.model.rename(self.current, name)
            except GroundStationError as exc:
                self._say(str(exc), bad=True)
            self._fill_state(self.current)

    def _refresh(self, index: int, t0: float | None = None) -> None:
        """Every view of slot `index`: the fast ones now, the slow ones asked for."""
        t0 = time.perf_counter() if t0 is None else t0
        slot = self.model.slot(index)
        fast = fast_views(slot.design)
        self.fast[index] = fast
        self.plots.show_fast(index, fast, self.model.q_one(0, fast.analysis.freqs_hz)
                             if index == 0 else None)
        self._fill_fast(index, fast)
        self.plots.set_stale(index, True)
        self._mark_stale(index, True)
        self.jobs.request(index, slot.generation, slot.design)
        ms = 1e3 * (time.perf_counter() - t0)
        self.edit_ms.append(ms)
        self._last_ms[index] = ms
        self._fill_times(index, ms)

    def _on_slow(self, index: int, generation: int, summary, seconds: float) -> None:
        slot = self.model.slots[index]
        self.slow_ms[index].append(1e3 * seconds)
        if slot is None or generation != slot.generation:
            return                                  # an older edit's; the latest is coming
        self.slow[index], self.slow_generation[index] = summary, generation
        self.plots.show_slow(index, summary, stale=False)
        self._fill_slow(index, summary)
        self._mark_stale(index, False)
        self._fill_times(index, self._last_ms[index])
        if not self.stale():
            self.sig_fresh.emit()

    def _on_slow_failed(self, index: int, generation: int, message: str) -> None:
        slot = self.model.slots[index]
        if slot is None or generation != slot.generation:
            return
        self.slow_generation[index] = generation
        for key in SLOW_ROWS:
            self._cell(key, index, "–")
        self._cell("verdict", index, f"could not be computed: {message}", bad=True)
        self._mark_stale(index, False)
        self._say(f"#{index + 1}: margins and responses: {message}", bad=True)
        if not self.stale():
            self.sig_fresh.emit()

    def stale(self, index: int | None = None) -> bool:
        """Are the margins and responses of slot `index` (or of any slot) out of date?"""
        idx = range(SLOTS) if index is None else (index,)
        return any(self.model.slots[i] is not None
                   and self.slow_generation[i] != self.model.slots[i].generation for i in idx)

    # ------------------------------------------------------------------ saving
    def save(self, path: str | Path | None = None) -> ControllerDesign | None:
        """Save the edited design (#1 or #2, the one in the editor) as a design file."""
        slot = self.model.slots[self.current]
        if slot is None:
            self._say("nothing to save: open a design", bad=True)
            return None
        if path is None:
            path, _ = QFileDialog.getSaveFileName(self, "Save design", str(slot.original.path.parent),
                                                  "Controller designs (*.toml)")
            if not path:
                return None
        try:
            back = self.model.save(self.current, path)
        except GroundStationError as exc:
            self._say(f"not saved: {exc}", bad=True)
            return None
        self._say(f"#{self.current + 1} saved as {back.path} (read back: the same transfer functions)")
        self._fill_state(self.current)
        return back

    def send_to_parameters(self) -> bool:
        """Hand the saved file to the Parameters dock (its load_design validates it)."""
        slot = self.model.slots[self.current]
        if slot is None or self._send is None:
            self._say("nothing to send" if slot is None else "no Parameters dock to send to", bad=True)
            return False
        if not slot.saved and self.save() is None:
            return False
        ok = bool(self._send(slot.saved_path))
        self._say(f"sent {slot.saved_path.name} to the Parameters dock: see its validation there"
                  if ok else f"the Parameters dock could not load {slot.saved_path.name}", bad=not ok)
        return ok

    # ------------------------------------------------------------------ the numbers
    def _cell(self, key: str, index: int, text: str, bad: bool = False, tip: str = "") -> None:
        item = self.numbers.item(ROW[key], index + 1)
        item.setText(text)
        item.setToolTip(tip or text)
        item.setForeground(QBrush(QColor("#c62828")) if bad else QBrush())

    def value(self, key: str, index: int) -> str:
        """The text of a row of the numbers table for slot `index` (tests read this)."""
        return self.numbers.item(ROW[key], index + 1).text()

    def _fill_state(self, index: int) -> None:
        slot = self.model.slots[index]
        if slot is None:
            return
        state = ("as loaded" if not slot.edited else "edited, not saved")
        if slot.saved:
            state = f"saved as {slot.saved_path.name}"
        self._cell("design", index, slot.name)
        self._cell("file", index, slot.original.path.name, tip=str(slot.original.path))
        testbed = slot.original.testbed.path
        self._cell("testbed", index, testbed.name, tip=str(testbed))
        self._cell("state", index, state)

    def _fill_fast(self, index: int, fast) -> None:
        d = fast.design
        self._fill_state(index)
        eq = f", equivalent to {Path(d.c0_equivalent_to).name}" if d.c0_equivalent_to else ""
        self._cell("c0", index, f"order {d.c0.order}{eq}", tip=d.c0.text())
        self._cell("dc", index, fast.dc.text() if fast.dc is not None else fast.dc_problem)
        for f, phi in zip(fast.freqs_hz, fast.phi_at_deg):
            key = f"phi_{f:g}"
            if key in ROW:
                self._cell(key, index, f"{phi:.1f}°")
        cross = ", ".join(f"{f:.3g} Hz ({a:+.0f}°)" for f, a in fast.crossovers)
        self._cell("pq_cross", index, cross or "none on the grid")

    def _fill_slow(self, index: int, s) -> None:
        v = s.validation
        verdict = ("OK" if v.ok else "MARGINAL" if not v.problems else "REFUSED")
        radius = f", max |z| {v.max_pole_radius:.6f}" if v.max_pole_radius is not None else ""
        self._cell("verdict", index, verdict + radius, bad=not v.ok,
                   tip="; ".join(v.problems + v.marginal) or "the table may be sent")
        self._cell("margins", index, margins_text(v.margins), tip=v.margins.text() if v.margins else "")
        self._cell("inner", index, margins_text(v.inner_margins) if v.inner_margins else "–")
        self._cell("outer", index, margins_text(v.outer_margins) if v.outer_margins else "–")
        self._cell("dist", index, peaks_text(s.saturation), bad=any(s.saturation.saturates),
                   tip=f"under {s.disturbance.text()} (linear loop)")
        self._cell("step", index, peaks_text(s.step_saturation), bad=any(s.step_saturation.saturates),
                   tip=f"under {s.responses.step.label} (linear loop)")

    def _fill_times(self, index: int, edit_ms: float) -> None:
        slow = self.slow_ms[index]
        self._cell("times", index, f"{edit_ms:.0f} ms / " + (f"{slow[-1]:.0f} ms" if slow else "…"))

    def _mark_stale(self, index: int, stale: bool) -> None:
        for key in SLOW_ROWS:
            item = self.numbers.item(ROW[key], index + 1)
            text = item.text().removesuffix(" (stale)")
            if stale and text:
                text += " (stale)"
            item.setText(text)
            if stale:
                item.setForeground(STALE)
        self.numbers.resizeRowsToContents()

    def _say(self, text: str, bad: bool = False) -> None:
        self.message.setText(text)
        self.message.setStyleSheet("color:#c62828; font-weight:bold;" if bad else "")

    def shutdown(self) -> None:
        """Wait for the job under way (the window's owner calls this before it goes)."""
        self.jobs.shutdown()
