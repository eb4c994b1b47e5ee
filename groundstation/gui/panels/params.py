"""The parameter panel: design file -> validated table -> verified on the device.

Three columns of values side by side (design or edited / last uploaded from here / what
the device reports), edit in place with range checks, validation with the closed loop of
the design's testbed, a Bode plot of the loop gain with its margins, upload (confirmed),
read back and roll back.  The widget does no link I/O: the Session runs uploads on worker
threads (the Station's verbs, which take the table through params/upload_path.py and its
upload gate) and answers with its sig_params_* signals.  Nor does it run the numerics on
the GUI thread: building a design's table, validating it and its Bode data run on the
panel's own pool thread (`_off_gui_thread`) while the GUI thread goes on serving events,
as it does while one of the panel's dialogs is open."""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QEventLoop, QObject, Qt, QThreadPool, Signal
from PySide6.QtWidgets import (QCheckBox, QFileDialog, QHBoxLayout, QInputDialog, QLabel,
                               QMessageBox, QProgressBar, QPushButton, QSplitter, QTextBrowser,
                               QTreeWidget, QTreeWidgetItem, QVBoxLayout, QWidget)

from ...core.dictionary import Dictionary, ParameterDef
from ...core.errors import GroundStationError
from ...core.kinds import LinkState
from ...params import table as ptable
from ...params.compare import three_way, wire_value
from ...params.design_file import ControllerDesign, load_design, table_values
from ...params.loop import ValidationReport, report_lines, validate
from ...params.loop_response import bode
from ...params.upload import ActiveTable, UploadRecord
from ..session.session import Session

COLUMNS = ("Parameter", "Design / edited", "Last uploaded", "Device", "Units", "Range")
COL_EDIT, COL_UPLOADED, COL_DEVICE = 1, 2, 3
DIFF_BRUSH = pg.mkBrush(255, 200, 0, 70)
BAD_STYLE = "color:#c62828; font-weight:bold;"


class ParameterPanel(QWidget):
    def __init__(self, session: Session, dictionary: Dictionary, parent: QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.d = dictionary
        self.params = {p.name: p for p in dictionary.parameters}
        self.design: ControllerDesign | None = None
        self.values: dict[str, Any] | None = None          # the table that Upload would send
        self.source = ""
        self.device: dict[str, Any] | None = None
        self.device_crc: int | None = None
        self.uploaded: dict[str, Any] | None = None
        self._sent: dict[str, Any] | None = None             # the table of the upload under way
        self.report: ValidationReport | None = None
        #: tests answer the confirmation dialog through this (None: ask the operator)
        self.confirm_override: bool | None = None
        #: tests: the reason given for a table without a design (None: ask)
        self.override_reason: str | None = None
        self._filling = False
        self.workbench = None                                # opened on demand
        #: the numerics' thread: one job at a time, apart from the pool other jobs share
        self._pool = QThreadPool(self)
        self._pool.setMaxThreadCount(1)
        self._busy = False                                   # a check runs on the pool
        #: why the device's buttons are off (a replay, a read-only console), or None
        self._device_reason: str | None = None
        self._build()
        session.sig_params_active.connect(self._on_active)
        session.sig_params_uploaded.connect(self._on_uploaded)
        session.sig_params_progress.connect(self._on_progress)
        session.sig_params_failed.connect(self._on_failed)
        session.sig_link_state.connect(self._on_link)

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        lay = QVBoxLayout(self)
        row = QHBoxLayout()
        self.load_button = QPushButton("Load design…")
        self.validate_button = QPushButton("Validate")
        self.upload_button = QPushButton("Upload…")
        self.read_button = QPushButton("Read back")
        self.rollback_button = QPushButton("Roll back")
        self.only_diff = QCheckBox("differences only")
        self.workbench_button = QPushButton("Workbench…")
        self.workbench_button.setToolTip("the design workbench: PQ views, edit Q and c0, save, "
                                         "send back here")
        for w in (self.load_button, self.validate_button, self.upload_button, self.read_button,
                  self.rollback_button, self.only_diff, self.workbench_button):
            row.addWidget(w)
        row.addStretch(1)
        lay.addLayout(row)
        self.design_label = QLabel("no design loaded - Read back starts from the device's table")
        self.design_label.setWordWrap(True)
        self.result = QLabel("")
        self.result.setWordWrap(True)
        self.result.setTextFormat(Qt.TextFormat.PlainText)
        self.result.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.progress = QProgressBar()
        self.progress.setRange(0, 100)
        self.progress.setVisible(False)
        # the full validation report: scrollable, above the table and Bode plot in a
        # splitter that gives it little room at first, so a low dock still shows the plot
        self.report_view = QTextBrowser()
        self.report_view.setVisible(False)
        lay.addWidget(self.design_label)
        lay.addWidget(self.result)
        lay.addWidget(self.progress)
        # side by side: the panel usually lives in a wide, low bottom dock
        split = QSplitter(Qt.Orientation.Horizontal)
        self.tree = QTreeWidget()
        self.tree.setColumnCount(len(COLUMNS))
        self.tree.setHeaderLabels(list(COLUMNS))
        self.tree.setAlternatingRowColors(True)
        self.tree.itemChanged.connect(self._on_edit)
        split.addWidget(self.tree)
        self.bode_view = pg.GraphicsLayoutWidget()
        self.mag_plot = self.bode_view.addPlot(row=0, col=0)
        self.phase_plot = self.bode_view.addPlot(row=1, col=0)
        for plot, label, units in ((self.mag_plot, "|L|", "dB"), (self.phase_plot, "phase L", "deg")):
            plot.setLogMode(x=True, y=False)
            plot.showGrid(x=True, y=True, alpha=0.25)
            plot.setLabel("left", label, units=units)
        self.phase_plot.setLabel("bottom", "frequency", units="Hz")
        self.phase_plot.setXLink(self.mag_plot)
        split.addWidget(self.bode_view)
        split.setSizes([600, 500])
        rows = QSplitter(Qt.Orientation.Vertical)
        rows.addWidget(self.report_view)
        rows.addWidget(split)
        rows.setStretchFactor(0, 0)
        rows.setStretchFactor(1, 1)
        rows.setSizes([60, 400])
        lay.addWidget(rows, 1)
        self.load_button.clicked.connect(self.load_design_dialog)
        self.validate_button.clicked.connect(self.run_validation)
        self.upload_button.clicked.connect(self.upload)
        self.read_button.clicked.connect(self.session.params_read)
        self.rollback_button.clicked.connect(self.rollback)
        self.only_diff.toggled.connect(lambda _: self._fill())
        self.workbench_button.clicked.connect(self.open_workbench)
        self._fill()

    def open_workbench(self):
        """The design workbench window (workbench/workbench.py), with this dock's 2-DOF
        design in #1 the first time; its Send to Parameters calls load_design here."""
        from ..workbench.workbench import DesignWorkbench

        if self.workbench is None:
            self.workbench = DesignWorkbench(self.d, send=self.load_design, parent=self)
            if self.design is not None and self.design.testbed.is_2dof:
                self.workbench.open_design(0, self.design)
        self.workbench.show()
        self.workbench.raise_()
        return self.workbench

    # ------------------------------------------------------------------ design
    def load_design_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Load controller design", "profiles/controllers",
                                              "Controller designs (*.toml)")
        if path:
            self.load_design(path)

    def load_design(self, path: str | Path) -> bool:
        """Read a design, build its table over the device's (defaults if none read) and
        validate it (the numerics off the GUI thread; this returns when they are done)."""
        if self._busy:
            self._say("a validation is still running: try again when it has finished", bad=True)
            return False
        base = self.device
        try:
            design, values, report, curve, error = self._off_gui_thread(
                lambda: _prepared(path, self.d, base))
        except GroundStationError as exc:
            self._say(str(exc), bad=True)
            return False
        self.design, self.values, self.source = design, values, str(path)
        self.report = None
        self.design_label.setText(f"<b>{design.name}</b> ({design.mode}) for {design.testbed.name} "
                                  f"- {Path(path).name}" + (f"<br>{'; '.join(design.notes)}"
                                                            if design.notes else ""))
        self._fill()
        if error is not None:
            self._say(f"validation failed: {error}", bad=True)
        else:
            self._show_report(report, curve)
        return True

    def run_validation(self) -> ValidationReport | None:
        """Check the table Upload would send; with a design, the closed loop too (off the
        GUI thread; this returns when it is done)."""
        if self.values is None:
            self._say("nothing to validate: load a design or read the device's table", bad=True)
            return None
        if self.design is None:
            problems = ptable.problems(self.d, self.values)
            self._say("table OK (no design loaded: the closed loop is not checked)" if not problems
                      else "refused: " + "; ".join(problems), bad=bool(problems))
            return None
        if self._busy:
            self._say("a validation is still running: try again when it has finished", bad=True)
            return None
        design, values = self.design, self.values
        try:
            report, curve = self._off_gui_thread(lambda: _checked(design, dict(values), self.d))
        except GroundStationError as exc:
            self._say(f"validation failed: {exc}", bad=True)
            return None
        # an edit in the tree meanwhile makes a new table (set_value): this report is not its
        if design is not self.design or values is not self.values:
            return None
        return self._show_report(report, curve)

    def _show_report(self, report: ValidationReport, curve) -> ValidationReport:
        self.report = report
        m = report.margins
        if report.ok:
            head = "OK: the table may be sent"
        elif not report.problems:
            head = (f"MARGINAL: stable, but {'; '.join(report.marginal)} - sent only with these "
                    f"margins accepted (Upload asks why)")
        else:
            head = f"REFUSED: {'; '.join(report.problems)}"
        self._say(head + (f" - {m.text()}" if m is not None else ""), bad=not report.ok)
        self.report_view.setHtml(_report_html(self.design, report))
        self.report_view.setVisible(True)
        self._plot_bode(curve)
        return report

    def _off_gui_thread(self, work):
        """Run `work()` on the panel's pool thread and return what it returns (or raise
        what it raised).  Meanwhile the GUI thread serves its events in a local loop - the
        charts and the link go on, as under a dialog - with the panel's buttons disabled
        so that nothing of the panel starts twice."""
        done = _Relay()
        loop = QEventLoop()
        done.finished.connect(loop.quit)     # queued: emitted on the pool thread
        outcome: dict[str, Any] = {}

        def run() -> None:
            try:
                outcome["result"] = work()
            except BaseException as exc:     # handed to the GUI thread, raised there
                outcome["error"] = exc
            finally:
                done.finished.emit()

        buttons = (self.load_button, self.validate_button, self.upload_button, self.read_button,
                   self.rollback_button, self.workbench_button)
        enabled = [b.isEnabled() for b in buttons]
        for b in buttons:
            b.setEnabled(False)
        self._busy = True
        try:
            self._pool.start(run)
            loop.exec()
        finally:
            self._busy = False
            for b, on in zip(buttons, enabled):
                b.setEnabled(on)
            self._device_buttons()          # the source may have changed meanwhile
        if "error" in outcome:
            raise outcome["error"]
        return outcome["result"]

    def _plot_bode(self, b) -> None:
        """Draw the loop gain's Bode data (computed off the GUI thread; None: none)."""
        self.mag_plot.clear()
        self.phase_plot.clear()
        if b is None:
            return
        finite = np.isfinite(b.magnitude_db)
        f = np.log10(b.freqs_hz[finite])
        phase = b.phase_deg[finite]
        # the usual convention: the phase near crossover between -360 and 0 deg
        at = np.searchsorted(b.freqs_hz[finite], b.margins.crossover_hz or 1.0)
        phase = phase - 360.0 * math.ceil(phase[min(at, len(phase) - 1)] / 360.0)
        self.mag_plot.plot(b.freqs_hz[finite], b.magnitude_db[finite], pen=pg.mkPen("#4e9bff", width=2))
        self.phase_plot.plot(b.freqs_hz[finite], phase, pen=pg.mkPen("#ffa62b", width=2))
        self.mag_plot.addItem(pg.InfiniteLine(pos=0, angle=0, pen=pg.mkPen((200, 200, 200), style=Qt.PenStyle.DashLine)))
        m = b.margins
        # -180 deg lines at every odd multiple of 180 within the plotted phase range
        lo, hi = np.nanmin(phase), np.nanmax(phase)
        for k in range(int(math.floor((lo - 180) / 360)), int(math.ceil((hi + 180) / 360)) + 1):
            level = -180 + 360 * k
            if lo - 30 <= level <= hi + 30:
                self.phase_plot.addItem(pg.InfiniteLine(pos=level, angle=0,
                                                        pen=pg.mkPen((200, 200, 200), style=Qt.PenStyle.DashLine)))
        red = pg.mkPen("#ff5050", width=1)
        if m.crossover_hz:
            for plot in (self.mag_plot, self.phase_plot):
                plot.addItem(pg.InfiniteLine(pos=math.log10(m.crossover_hz), angle=90, pen=red,
                                             label=f"PM {m.phase_margin_deg:.1f}°",
                                             labelOpts={"position": 0.9, "color": "#ff5050"}))
        if m.gain_margin_hz:
            green = pg.mkPen("#8ac926", width=1)
            for plot in (self.mag_plot, self.phase_plot):
                plot.addItem(pg.InfiniteLine(pos=math.log10(m.gain_margin_hz), angle=90, pen=green,
                                             label=f"GM {m.gain_margin_db:.1f} dB",
                                             labelOpts={"position": 0.1, "color": "#8ac926"}))
        self.mag_plot.setXRange(f[0], f[-1], padding=0)

    # ------------------------------------------------------------------ device actions
    def upload(self, confirm: bool = True) -> bool:
        """Validate and send the table (worker thread, via the Session).  confirm=False
        skips the question: for the simulator's demo, which the operator asked for."""
        if self.values is None:
            self._say("nothing to upload: load a design or read the device's table", bad=True)
            return False
        problems = ptable.problems(self.d, self.values)
        reason = None
        if self.design is not None:
            # the report of this very table when there is one (it is dropped whenever the
            # table changes), else a fresh validation; the upload gate validates it again
            report = self.report or self.run_validation()
            if report is None or report.problems:
                return False
            if report.marginal:
                # stable but marginal: sent only on the operator's stated acceptance of
                # these margins, which the history and the recording keep
                reason = self._override_reason(
                    "Accept these margins",
                    "The closed loop is stable, but " + "; ".join(report.marginal) + ".\n"
                    "Why is it safe to run with these margins? (kept in the parameter history "
                    "and the recording)")
                if not reason:
                    self._say("upload cancelled: a marginal design is sent only with its margins "
                              "accepted and a reason")
                    return False
        elif problems:
            self._say("refused: " + "; ".join(problems), bad=True)
            return False
        else:
            # no design: the closed loop cannot be checked, so the table goes only on the
            # operator's stated reason, which the history and the recording keep
            reason = self._override_reason()
            if not reason:
                self._say("upload cancelled: a table without a design is sent only with a "
                          "reason (its closed loop is not checked)")
                return False
        crc = ptable.table_crc(ptable.pack(self.d, self.values))
        what = self.source or "the edited table"
        if confirm and not self._confirm(f"Upload parameter table {crc:08x} from {what} to the device?\n"
                                         "It becomes active at once (the device must be disarmed)."):
            self._say("upload cancelled")
            return False
        self._sent = dict(self.values)
        self.progress.setVisible(True)
        self.progress.setValue(0)
        self.session.params_upload(dict(self.values), what, design=self.design, accept_risk=reason)
        return True

    def rollback(self) -> None:
        if self._confirm("Roll the device back to the table that was active before the last upload?"):
            self.progress.setVisible(True)
            self.session.params_rollback()

    def _override_reason(self, title: str = "Upload without a design",
                         question: str = "No design is loaded, so this table's closed loop is not "
                                         "checked.\nWhy is it safe to send? (kept in the parameter "
                                         "history and the recording)") -> str:
        if self.override_reason is not None:
            return self.override_reason
        text, ok = QInputDialog.getText(self, title, question)
        return text.strip() if ok else ""

    def _confirm(self, text: str) -> bool:
        if self.confirm_override is not None:
            return self.confirm_override
        return QMessageBox.question(self, "Parameter upload", text) == QMessageBox.StandardButton.Yes

    def _on_progress(self, step: str, fraction: float) -> None:
        self.progress.setVisible(True)
        self.progress.setFormat(f"{step} %p%")
        self.progress.setValue(int(100 * fraction))

    def _on_active(self, table: ActiveTable) -> None:
        self.device, self.device_crc = table.values, table.crc
        if self.values is None:                   # start editing from what runs
            self.values, self.source = dict(table.values), "edited from the device's table"
        self.progress.setVisible(False)
        self._fill()

    def _on_uploaded(self, record: UploadRecord) -> None:
        self.uploaded = self._sent
        if record.validated:
            gate = ""
        elif record.accepted_risk == "marginal":
            gate = f"; stable but marginal, margins accepted: {record.override_reason}"
        else:
            gate = f"; NOT validated, sent on the reason: {record.override_reason}"
        self._say(f"table {record.crc:08x} verified on the device (v{record.version}, "
                  f"read back bit for bit, HOUSEKEEPING agrees){gate}")
        self._fill()

    def _on_failed(self, text: str) -> None:
        self.progress.setVisible(False)
        self._say(f"upload failed: {text}", bad=True)
        self._fill()

    def _on_link(self, state: str, _message: str) -> None:
        if state == LinkState.UP:
            self.session.params_read()

    # ------------------------------------------------------------------ the tree
    def _fill(self) -> None:
        """Rebuild the three-way tree (expansion kept)."""
        expanded = {self.tree.topLevelItem(i).text(0) for i in range(self.tree.topLevelItemCount())
                    if self.tree.topLevelItem(i).isExpanded()}
        self._filling = True
        self.tree.clear()
        rows = three_way(self.d, {"design": self.values, "uploaded": self.uploaded, "device": self.device})
        for row in rows:
            if self.only_diff.isChecked() and row.status != "differs":
                continue
            p = self.params[row.name]
            item = QTreeWidgetItem([row.name, row.texts["design"], row.texts["uploaded"],
                                    row.texts["device"], row.units, _range_text(p)])
            item.setToolTip(0, row.description)
            item.setData(0, Qt.ItemDataRole.UserRole, (row.name, None))
            if not p.shape and self.values is not None:
                item.setFlags(item.flags() | Qt.ItemFlag.ItemIsEditable)
            for src in row.differing:
                col = {"design": COL_EDIT, "uploaded": COL_UPLOADED, "device": COL_DEVICE}[src]
                item.setBackground(col, DIFF_BRUSH)
            if row.differing:
                item.setToolTip(COL_EDIT, "differs from the device: " + ", ".join(row.differing))
            self.tree.addTopLevelItem(item)
            if p.shape:
                self._add_elements(item, p)
            item.setExpanded(row.name in expanded)
        for i in range(len(COLUMNS)):
            self.tree.resizeColumnToContents(i)
        self._filling = False
        self._device_buttons()

    def set_device_reason(self, reason: str | None) -> None:
        """Upload, Read back and Roll back off with `reason` as their tooltip (a replay,
        a read-only console: nothing to send them to); None: on when they can act."""
        self._device_reason = reason
        self._device_buttons()

    def _device_buttons(self) -> None:
        if self._busy:
            return                           # a check runs: they come back after it
        why = self._device_reason
        self.rollback_button.setEnabled(self.device is not None and why is None)
        self.upload_button.setEnabled(self.values is not None and why is None)
        self.read_button.setEnabled(why is None)
        for b in (self.upload_button, self.read_button, self.rollback_button):
            b.setToolTip(why or "")

    def _add_elements(self, parent: QTreeWidgetItem, p: ParameterDef) -> None:
        """Children: one per SOS section (6 numbers) or per array element; editable."""
        tables = {"design": self.values, "uploaded": self.uploaded, "device": self.device}
        arrays = {s: wire_value(p, t[p.name]) for s, t in tables.items() if t is not None}
        n = p.shape[0]
        for i in range(n):
            label = f"section {i + 1}" if p.filter == "sos" else f"[{i}]"
            texts = {s: _element_text(a[i]) for s, a in arrays.items()}
            child = QTreeWidgetItem([label, texts.get("design", ""), texts.get("uploaded", ""),
                                     texts.get("device", ""), "", "b0 b1 b2 a0 a1 a2" if p.filter == "sos" else ""])
            child.setData(0, Qt.ItemDataRole.UserRole, (p.name, i))
            if "design" in arrays:
                child.setFlags(child.flags() | Qt.ItemFlag.ItemIsEditable)
                ref = arrays.get("device")
                if ref is not None and arrays["design"][i].tobytes() != ref[i].tobytes():
                    child.setBackground(COL_EDIT, DIFF_BRUSH)
            parent.addChild(child)

    def _on_edit(self, item: QTreeWidgetItem, column: int) -> None:
        """An edit in the design/edited column: parse, check, and take it or put it back."""
        if self._filling or column != COL_EDIT or self.values is None:
            return
        name, index = item.data(0, Qt.ItemDataRole.UserRole)
        error = self.set_value(name, item.text(COL_EDIT), index)
        if error:
            self._say(error, bad=True)
        else:
            self.source = "edited" if not self.source.startswith("edited") else self.source
            self._say(f"{name} edited: Validate, then Upload")
        self._fill()

    def set_value(self, name: str, text: str, index: int | None = None) -> str | None:
        """Change one entry (or one element / SOS section) of the edited table.  Returns
        the reason when the text is refused (and nothing changes)."""
        p = self.params[name]
        try:
            numbers = [float(t) for t in text.replace(",", " ").split()]
        except ValueError:
            return f"{name}: '{text}' is not a number"
        want = (6 if p.filter == "sos" else 1) if (index is not None or not p.shape) else None
        if want is None or len(numbers) != want:
            return f"{name}: expected {want} number(s), got '{text}'"
        if not all(math.isfinite(x) for x in numbers):
            return f"{name}: {text} is not finite"
        lo, hi = p.value_range
        bad = [x for x in numbers if not lo <= x <= hi]
        if bad and p.filter != "sos":
            return f"{name}: {bad[0]:g} is outside {lo:g} .. {hi:g} {p.units}".rstrip()
        if np.issubdtype(p.dtype, np.integer) and any(x != int(x) for x in numbers):
            return f"{name}: {text} is not a whole number"
        candidate = dict(self.values)
        if index is None:
            candidate[name] = int(numbers[0]) if np.issubdtype(p.dtype, np.integer) else numbers[0]
        else:
            arr = np.array(wire_value(p, self.values[name]), dtype=float)
            arr[index] = numbers if p.filter == "sos" else numbers[0]
            candidate[name] = arr.tolist()
        problems = [x for x in ptable.problems(self.d, candidate) if name in x]
        if problems:
            return "; ".join(problems)
        self.values = candidate
        self.report = None                   # it judged the table before this change
        return None

    def _say(self, text: str, bad: bool = False) -> None:
        self.result.setText(text)
        self.result.setStyleSheet(BAD_STYLE if bad else "")


class _Relay(QObject):
    """Tells the GUI thread that a job on the panel's pool has ended."""

    finished = Signal()


def _prepared(path, dictionary: Dictionary, base):
    """Pool thread: a design file read and its table built over `base`, then its validation
    and Bode data - or the error that stopped the validation, for a design still loaded."""
    design = load_design(path)
    values = table_values(design, base=base, dictionary=dictionary)
    try:
        report, curve = _checked(design, values, dictionary)
    except GroundStationError as exc:
        return design, values, None, None, exc
    return design, values, report, curve, None


def _checked(design: ControllerDesign, values: dict, dictionary: Dictionary):
    """Pool thread: a table's validation against its design, and its Bode data."""
    return validate(design, values, dictionary), _bode_or_none(design, values)


def _bode_or_none(design: ControllerDesign, values: dict):
    try:
        return bode(design, values)
    except GroundStationError:               # no curve to draw; the report says why
        return None


def _range_text(p: ParameterDef) -> str:
    lo, hi = p.value_range
    return f"{lo:g} .. {hi:g}"


def _element_text(v) -> str:
    a = np.atleast_1d(np.asarray(v, dtype=float))
    return " ".join(f"{x:.6g}" for x in a)


def _report_html(design: ControllerDesign, r: ValidationReport) -> str:
    """The CLI's report (params.loop.report_lines), coloured by what each line says."""
    colours = {"problem:": "#c62828", "REFUSED:": "#c62828", "warning:": "#b26a00", "OK:": "#2e7d32"}
    out = []
    for line in report_lines(design, r):
        text = html.escape(line)
        colour = next((c for k, c in colours.items() if line.startswith(k)), None)
        out.append(f"<span style='color:{colour}'><b>{text}</b></span>" if colour else text)
    return "<pre style='margin:0'>" + "\n".join(out) + "</pre>"
