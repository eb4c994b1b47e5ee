"""The campaign panel: a test procedure file, its steps, run it, watch it, abort it.

Top, the campaign (profiles/campaigns/ or any file), Run and Abort, where the logs go,
and a trial-run cap on every dwell.  Below, what the file says (testbed, runs over the
matrix) and whether it can run here; the steps as the runner will do them, the current
one highlighted and each one's result as it happens; a progress bar for the step and
one for the campaign; what the campaign says as it goes; and at the end the report's
summary with where the report and the logs were written.

The widget does no I/O: the CampaignController (session.campaign) runs the campaign on
its worker thread, on the Session's own link, and answers with signals.  Esc, the
window's ABORT and this panel's Abort all stop it (MainWindow.abort -> Session.abort).
"""

from __future__ import annotations

import time
from datetime import datetime
from pathlib import Path

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor, QFont
from PySide6.QtWidgets import (QAbstractItemView, QComboBox, QDoubleSpinBox, QFileDialog,
                               QHBoxLayout, QHeaderView, QLabel, QLineEdit, QMessageBox,
                               QPlainTextEdit, QProgressBar, QPushButton, QSizePolicy,
                               QSplitter, QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget)

from ...campaign import Campaign, StepResult, load_campaign
from ...core.errors import GroundStationError
from ...core.kinds import SIMULATED_DEVICE
from ...plant.testbed import PROFILES_DIR
from ..session.campaign_runner import CampaignOutcome
from ..common.file_combo import FilePicker
from ..session.session import Session

CAMPAIGNS_DIR = PROFILES_DIR / "campaigns"
COLUMNS = ("#", "where", "action", "arguments", "result", "time")
COL_ARGS, COL_RESULT, COL_TIME = 3, 4, 5
BAD_STYLE = "color:#c62828; font-weight:bold;"
WARN_STYLE = "color:#b26a00;"
OK_STYLE = "color:#2e7d32; font-weight:bold;"
SMALL_STYLE = "color:#707070; font-size:8pt;"
RUN_STYLE = ("QPushButton { background:#2e7d32; color:white; font-weight:bold; padding:5px 14px; "
             "border-radius:4px; } QPushButton:disabled { background:#9e9e9e; color:#eeeeee; }")
ABORT_STYLE = ("QPushButton { background:#c62828; color:white; font-weight:bold; padding:5px 14px; "
               "border-radius:4px; } QPushButton:disabled { background:#9e9e9e; color:#eeeeee; }")
CURRENT_BRUSH = QBrush(QColor("#fff59d"))
NO_BRUSH = QBrush()
RESULT_COLOURS = {"done": "#2e7d32", "failed": "#c62828", "aborted": "#c62828",
                  "skipped": "#757575", "running": "#1565c0"}
REPORT_STYLES = {"completed": OK_STYLE, "completed_with_failures": WARN_STYLE + " font-weight:bold;",
                 "failed": BAD_STYLE, "aborted": BAD_STYLE}


class CampaignPanel(QWidget):
    #: the panel's Abort button: the window's Abort (device ABORT, generator off, campaign stopped)
    sig_abort = Signal()

    def __init__(self, session: Session, parent: QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.ctl = session.campaign
        self.campaign: Campaign | None = None
        self.path: Path | None = None
        self.results: dict[int, StepResult] = {}
        self.current: int | None = None
        self.outcome: CampaignOutcome | None = None
        self.running = False
        #: tests answer the confirmation dialogs (Run, pause steps) through this
        self.confirm_override: bool | None = None
        #: the folder the panel last proposed: while the field still shows it, it follows
        #: the campaign loaded (logs/NAME); a folder typed or set by hand is kept
        self._proposed_folder = "logs"
        self._started = 0.0
        self._build()
        c = self.ctl
        c.sig_started.connect(self._on_started)
        c.sig_progress.connect(self._on_progress)
        c.sig_step_result.connect(self._on_result)
        c.sig_log.connect(self._log)
        c.sig_pause.connect(self._on_pause)
        c.sig_finished.connect(self._on_finished)
        c.sig_failed.connect(self._on_failed)
        session.sig_link_state.connect(lambda *_: self._update_readiness())
        session.sig_source.connect(lambda *_: self._update_readiness())
        session.profiles.sig_done.connect(lambda _outcome: self._update_readiness())
        self._update_readiness()

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        """Top to bottom: the campaign and how to run it, what it is, the progress bars,
        then its steps beside what it says."""
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 2, 4, 2)
        lay.setSpacing(3)
        lay.addLayout(self._run_bar())
        lay.addLayout(self._about_line())
        lay.addLayout(self._progress_bars())
        lay.addWidget(self._steps_and_log(), 1)
        self._connect_controls()

    def _run_bar(self) -> QHBoxLayout:
        """The campaign file, where its logs go, the trial-run cap, Run and Abort."""
        self.file = QComboBox()
        self.file.addItem("choose a campaign…", "")
        for path in sorted(CAMPAIGNS_DIR.glob("*.toml")):
            self.file.addItem(path.stem, str(path))
        self.file.setMinimumContentsLength(22)
        self.file.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.file.setToolTip("a campaign file (docs/campaigns.md)")
        self.browse_button = QPushButton("File…")
        self.run_button = QPushButton("▶  Run")
        self.run_button.setStyleSheet(RUN_STYLE)
        self.run_button.setToolTip("run every step on the connected device (the charts show it)")
        self.abort_button = QPushButton("■  Abort (Esc)")
        self.abort_button.setStyleSheet(ABORT_STYLE)
        self.abort_button.setToolTip("stop the campaign now: device ABORT, generator off, "
                                     "recording closed; the report says where it stopped")
        self.cap = QDoubleSpinBox()
        self.cap.setRange(0.0, 3600.0)
        self.cap.setDecimals(1)
        self.cap.setSingleStep(1.0)
        self.cap.setSuffix(" s")
        self.cap.setSpecialValueText("off")
        self.cap.setToolTip("trial run: cap every dwell, base-motion duration and profile at "
                            "this many seconds (off: the campaign as written)")
        self.folder = QLineEdit("logs")
        self.folder.setToolTip("where the logs and report.json / report.txt go")
        self.folder_button = QPushButton("…")
        self.folder_button.setFixedWidth(28)
        top = QHBoxLayout()
        top.addWidget(QLabel("Campaign"))
        top.addWidget(self.file, 2)
        top.addWidget(self.browse_button)
        top.addSpacing(12)
        top.addWidget(QLabel("Logs to"))
        top.addWidget(self.folder, 2)
        top.addWidget(self.folder_button)
        top.addSpacing(12)
        top.addWidget(QLabel("Trial run: cap dwells at"))
        top.addWidget(self.cap)
        top.addSpacing(12)
        top.addWidget(self.run_button)
        top.addWidget(self.abort_button)
        return top

    def _about_line(self) -> QHBoxLayout:
        """What the file says and whether it can run here, on one line."""
        self.info = QLabel("no campaign loaded")
        self.info.setTextFormat(Qt.TextFormat.RichText)
        self.info.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.readiness = QLabel("")
        self.readiness.setWordWrap(True)
        self.readiness.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        self.readiness.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.connect_button = QPushButton("Connect the simulator")
        self.connect_button.setToolTip("start the simulated testbed with the campaign's testbed file")
        self.connect_button.setVisible(False)
        about = QHBoxLayout()
        about.addWidget(self.info, 3)
        about.addWidget(self.readiness, 2)
        about.addWidget(self.connect_button)
        return about

    def _progress_bars(self) -> QHBoxLayout:
        """The current step's progress beside the whole campaign's."""
        self.step_bar = QProgressBar()
        self.step_bar.setFormat("step")
        self.campaign_bar = QProgressBar()
        self.campaign_bar.setFormat("campaign")
        bars = QHBoxLayout()
        for bar in (self.step_bar, self.campaign_bar):
            bar.setRange(0, 1000)
            bar.setValue(0)
            bar.setTextVisible(True)
            bars.addWidget(bar, 1)
        return bars

    def _steps_and_log(self) -> QSplitter:
        """The steps beside what the campaign says: side by side, a low dock keeps the
        table's height."""
        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(self._steps_table())
        split.addWidget(self._log_column())
        split.setStretchFactor(0, 3)
        split.setStretchFactor(1, 2)
        split.setSizes([900, 600])
        return split

    def _steps_table(self) -> QTableWidget:
        """One row per step as the runner will do it (filled by load)."""
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(list(COLUMNS))
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.NoSelection)
        self.table.setAlternatingRowColors(True)
        self.table.setWordWrap(False)
        self.table.verticalHeader().setDefaultSectionSize(20)
        header = self.table.horizontalHeader()
        for col in range(len(COLUMNS)):
            header.setSectionResizeMode(col, QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(COL_ARGS, QHeaderView.ResizeMode.Stretch)
        return self.table

    def _log_column(self) -> QWidget:
        """What the campaign says as it runs, and below it the outcome."""
        right = QWidget()
        col = QVBoxLayout(right)
        col.setContentsMargins(0, 0, 0, 0)
        col.setSpacing(2)
        self.log_view = QPlainTextEdit()
        self.log_view.setReadOnly(True)
        self.log_view.setMaximumBlockCount(5000)
        mono = QFont("monospace")
        mono.setStyleHint(QFont.StyleHint.TypeWriter)
        mono.setPointSize(8)
        self.log_view.setFont(mono)
        self.log_view.setPlaceholderText("what the campaign says as it runs")
        self.log_view.setLineWrapMode(QPlainTextEdit.LineWrapMode.NoWrap)
        col.addWidget(self.log_view, 1)
        self.result = QLabel("")
        self.result.setWordWrap(True)
        self.result.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.result.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        col.addWidget(self.result)
        return right

    def _connect_controls(self) -> None:
        # a campaign chosen in the combo while one runs is not loaded
        self.file_picker = FilePicker(
            self, self.file, self.browse_button, self.load, title="Campaign",
            folder=CAMPAIGNS_DIR, file_filter="Campaigns (*.toml);;All files (*)",
            loaded=lambda path: self.campaign is not None and self.path == path,
            may_load=lambda: not self.running)
        self.folder_button.clicked.connect(self._choose_folder)
        self.run_button.clicked.connect(self.run)
        self.abort_button.clicked.connect(self.sig_abort.emit)
        self.connect_button.clicked.connect(self._connect_sim)

    # ------------------------------------------------------------------ loading
    def load_dialog(self) -> None:
        self.file_picker.dialog()

    def set_file(self, path: str | Path) -> bool:
        """Choose a campaign file (added to the list if needed) and load it."""
        return self.file_picker.set_file(path)

    def _choose_folder(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Log folder", self.folder.text())
        if folder:
            self.folder.setText(folder)

    def load(self, path: str | Path) -> bool:
        """Read a campaign (every step checked, nothing run) and list its steps."""
        if self.running:
            self._say("a campaign is running: load another when it has ended", bad=True)
            return False
        path = Path(path)
        try:
            campaign = load_campaign(path)
        except GroundStationError as exc:
            self.campaign, self.path = None, None
            self.table.setRowCount(0)
            self.info.setText(f"<span style='color:#c62828'><b>cannot use this file:</b> "
                              f"{_html(str(exc))}</span>")
            self._update_readiness()
            return False
        self.campaign, self.path = campaign, path
        self.results.clear()
        self.current = None
        self.outcome = None
        if self.folder.text().strip() in (self._proposed_folder, ""):
            self._proposed_folder = str(Path("logs") / campaign.name)
            self.folder.setText(self._proposed_folder)
        matrix = ", ".join(f"{k} ({len(v)})" for k, v in campaign.matrix.items()) or "no matrix"
        self.info.setText(
            f"<b>{_html(campaign.name)}</b> - {_html(campaign.description or '(no description)')}"
            f"<br><span style='color:#606060'>testbed <b>{_html(campaign.testbed.name)}</b> · "
            f"{campaign.runs} run(s) over {_html(matrix)} · {len(campaign.steps)} steps · "
            f"on a failed run: {campaign.on_run_failure.replace('_', ' ')}</span>")
        self.info.setToolTip(str(path))
        self._fill(campaign)
        self.step_bar.setValue(0)
        self.step_bar.setFormat("step")
        self.campaign_bar.setValue(0)
        self.campaign_bar.setFormat(f"campaign: {len(campaign.steps)} steps")
        self._say("")
        self._update_readiness()
        return True

    def _fill(self, campaign: Campaign) -> None:
        self.table.setRowCount(len(campaign.steps))
        for row, step in enumerate(campaign.steps):
            where = f"run {step.run}" if step.run else step.phase
            args = ", ".join(f"{k}={_short(v)}" for k, v in step.args.items())
            cells = (str(step.index + 1), where, step.action, args, "", "")
            for col, text in enumerate(cells):
                item = QTableWidgetItem(text)
                if col == COL_ARGS:
                    item.setToolTip("\n".join(f"{k} = {v}" for k, v in step.args.items()))
                if col in (0, COL_TIME):
                    item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
                self.table.setItem(row, col, item)

    # ------------------------------------------------------------------ readiness
    def _update_readiness(self) -> None:
        c = self.campaign
        self.abort_button.setEnabled(self.running)
        for w in (self.file, self.browse_button, self.folder, self.folder_button, self.cap):
            w.setEnabled(not self.running)
        if self.running:
            self.run_button.setEnabled(False)
            self.connect_button.setVisible(False)
            self.readiness.setText("running on the connected device - Esc or Abort stops it")
            self.readiness.setStyleSheet(WARN_STYLE + " font-weight:bold;")
            return
        if c is None:
            self.run_button.setEnabled(False)
            self.connect_button.setVisible(False)
            self.readiness.setText("")
            return
        reason, note = self.ctl.readiness(c)
        self.run_button.setEnabled(reason is None)
        self.run_button.setToolTip(reason or "run every step on the connected device")
        self.readiness.setText(f"cannot run: {reason}" if reason else
                               f"ready: {note}" if note else "ready to run on the connected device")
        self.readiness.setStyleSheet(BAD_STYLE if reason else WARN_STYLE if note else OK_STYLE)
        # the simulator can be (re)started with the campaign's testbed from here
        s = self.session
        offer = bool(reason) and s.replay is None and (
            s.client is None or (s.address == SIMULATED_DEVICE and self.ctl.session_testbed()
                                 != c.testbed.resolve()))
        self.connect_button.setText(f"Connect the simulator ({c.testbed.name})")
        self.connect_button.setVisible(offer)

    def _connect_sim(self) -> None:
        if self.campaign is not None:
            self.session.connect_sim(str(self.campaign.testbed))
            self.readiness.setText("connecting the simulated testbed…")
            self.readiness.setStyleSheet(WARN_STYLE)
            self.connect_button.setVisible(False)

    # ------------------------------------------------------------------ run
    def run(self) -> str | None:
        """Run the loaded campaign (the file read again: it may have been edited);
        returns why not, else None (the run goes on in the background)."""
        if self.path is None:
            return self._refuse("load a campaign first")
        if not self.load(self.path):
            return self._refuse("the campaign file cannot be used (see above)")
        c = self.campaign
        reason, note = self.ctl.readiness(c)
        if reason:
            return self._refuse(reason)
        cap = self.cap.value() or None
        folder = self.folder.text().strip() or str(Path("logs") / c.name)
        text = (f"Run campaign {c.name} on the device?\n\n{len(c.steps)} steps, {c.runs} run(s), "
                f"testbed {c.testbed.name}" + (f", every dwell capped at {cap:g} s" if cap else "")
                + f".\nLogs and report to {folder}.\nEsc aborts at any time.")
        if note:
            text += f"\n\nNote: {note}."
        if not self._confirm("Run campaign", text):
            self._say("not started (cancelled)")
            return "cancelled"
        reason = self.ctl.run(c, folder, cap)
        if reason:
            return self._refuse(reason)
        return None

    def _refuse(self, reason: str) -> str:
        self._say(f"not started: {reason}", bad=True)
        return reason

    def _confirm(self, title: str, text: str) -> bool:
        if self.confirm_override is not None:
            return self.confirm_override
        return QMessageBox.question(self, title, text) == QMessageBox.StandardButton.Yes

    # ------------------------------------------------------------------ the run, as it happens
    def _on_started(self, campaign: Campaign, folder: str) -> None:
        self.running = True
        self._started = time.monotonic()
        self.results.clear()
        self.outcome = None
        self._highlight(None)
        for row in range(self.table.rowCount()):
            for col in (COL_RESULT, COL_TIME):
                self.table.item(row, col).setText("")
        self.log_view.appendPlainText(f"--- {datetime.now():%Y-%m-%d %H:%M:%S} campaign "
                                      f"{campaign.name}: logs to {folder}")
        self._say(f"running {campaign.name}…", style=WARN_STYLE + " font-weight:bold;")
        self._update_readiness()

    def _on_progress(self, index: int, fraction: float) -> None:
        if self.campaign is None or not self.running:
            return
        n = len(self.campaign.steps)
        if index != self.current:
            self._highlight(index)
            item = self.table.item(index, COL_RESULT)
            if item is not None and index not in self.results:
                item.setText("running")
                item.setForeground(QColor(RESULT_COLOURS["running"]))
        step = self.campaign.steps[index]
        self.step_bar.setValue(int(1000 * max(0.0, min(1.0, fraction))))
        self.step_bar.setFormat(f"step {index + 1}/{n} {step.action}: %p%")
        whole = (index + max(0.0, min(1.0, fraction))) / max(n, 1)
        self.campaign_bar.setValue(int(1000 * whole))
        self.campaign_bar.setFormat(f"campaign: step {index + 1} of {n} - %p% - "
                                    f"{time.monotonic() - self._started:.0f} s")

    def _on_result(self, result: StepResult) -> None:
        self.results[result.index] = result
        self._show_result(result)

    def _show_result(self, r: StepResult) -> None:
        item = self.table.item(r.index, COL_RESULT)
        if item is None:
            return
        first = r.error.splitlines()[0] if r.error else ""
        if first == r.status:                      # "aborted: aborted" says nothing more
            first = ""
        if len(first) > 70:                        # the whole reason is the tooltip
            first = first[:69] + "…"
        item.setText(first if first.startswith(r.status) else
                     r.status + (f": {first}" if first else ""))
        item.setToolTip(r.error)
        item.setForeground(QColor(RESULT_COLOURS.get(r.status, "#000000")))
        font = item.font()
        font.setBold(r.status in ("failed", "aborted"))
        item.setFont(font)
        self.table.item(r.index, COL_TIME).setText(f"{r.seconds:.1f} s" if r.seconds else "")

    def _highlight(self, index: int | None) -> None:
        if self.current is not None and self.current < self.table.rowCount():
            for col in range(len(COLUMNS)):
                self.table.item(self.current, col).setBackground(NO_BRUSH)
        self.current = index
        if index is not None and index < self.table.rowCount():
            for col in range(len(COLUMNS)):
                self.table.item(index, col).setBackground(CURRENT_BRUSH)
            self.table.scrollToItem(self.table.item(index, 0),
                                    QAbstractItemView.ScrollHint.EnsureVisible)

    def _log(self, text: str) -> None:
        self.log_view.appendPlainText(f"{datetime.now():%H:%M:%S}  {text}")

    def _on_pause(self, prompt: str) -> None:
        go_on = self._confirm("Campaign paused", f"{prompt}\n\nContinue the campaign? "
                                                 f"(No aborts it and makes the rig safe.)")
        self._log(f"pause '{prompt}': {'continue' if go_on else 'stop'}")
        self.ctl.answer(go_on)

    def _on_finished(self, outcome: CampaignOutcome) -> None:
        self.running = False
        self.outcome = outcome
        report = outcome.report
        for r in report.steps:                     # the report is the record: it wins
            self.results[r.index] = r
            self._show_result(r)
        stopped = report.failed_step
        self._highlight(stopped)                   # where it stopped stays marked
        if stopped is None:
            self.step_bar.setValue(1000 if report.status.startswith("completed") else self.step_bar.value())
        if report.status.startswith("completed"):
            self.campaign_bar.setValue(1000)
        self.campaign_bar.setFormat(f"campaign: {report.status.replace('_', ' ')} - "
                                    f"{report.finished - report.started:.0f} s")
        summary = report.summary()
        self.log_view.appendPlainText(summary)
        where = (f"report {outcome.report_path} (and report.txt)" if outcome.report_path
                 else "the report could not be saved")
        self.log_view.appendPlainText(f"{where}; logs in {outcome.log_folder}")
        head = summary.splitlines()[0]
        if report.reason and report.status not in ("completed", "completed_with_failures"):
            head += f" - {report.reason.splitlines()[0]}"
        logs = sum(len(rec.get("files", [])) for rec in report.recordings)
        self._say(f"{head}\n{logs} log(s) in {outcome.log_folder}; {where}",
                  style=REPORT_STYLES.get(report.status, ""))
        self._update_readiness()

    def _on_failed(self, text: str) -> None:
        self.running = False
        self._log(text)
        self._say(text, bad=True)
        self._update_readiness()

    def _say(self, text: str, bad: bool = False, style: str | None = None) -> None:
        self.result.setText(text)
        self.result.setToolTip(text)
        self.result.setStyleSheet(style if style is not None else (BAD_STYLE if bad else ""))


def _short(v) -> str:
    """A path shown by its file name (the tooltip has it whole)."""
    text = str(v)
    return Path(text).name if "/" in text else text


def _html(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


__all__ = ["CampaignPanel"]
