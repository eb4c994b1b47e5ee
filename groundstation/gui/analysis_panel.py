"""The Analysis dock: figures of merit and identification from recorded logs.

Left, the logs it acts on (analysis_runs.RunsTable): the log the window replays (added
when the Session opens it), files chosen with File…, the logs of a folder (a campaign's)
with Folder….  Then the options - the scored sensor, the integration period, a window
of the log (from/to in seconds from its start; empty: the whole log), the FRF's input
and output channels, segment length and testbed - and the three buttons:

* Metrics: jitter and energy of every ticked log (a table row each) and the PSD and CSP
  of the scored sensor (a curve each);
* FRF: the frequency response of the highlighted log, measured against the testbed
  model, and the coherence;
* Hysteresis: the friction torque against the outer encoder of the highlighted log.

The widget does no I/O and no computing: AnalysisJobs (analysis_jobs.py) runs the
analysis modules on worker threads and answers with signals; what fails is said in the
status line under the buttons, in the error's own words.
"""

from __future__ import annotations

import math
from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (QAbstractItemView, QComboBox, QDoubleSpinBox, QFileDialog,
                               QFormLayout, QGroupBox, QHBoxLayout, QHeaderView, QLabel,
                               QLineEdit, QPushButton, QTableWidget, QTableWidgetItem,
                               QTabWidget, QVBoxLayout, QWidget)

from ..analysis.jitter import DEFAULT_INTEGRATION_PERIOD_S
from ..analysis.log_identification import FRF_INPUTS, FRF_OUTPUTS
from ..analysis.log_metrics import DEFAULT_SENSOR, SENSORS
from ..plant.testbed import TESTBEDS_DIR
from .analysis_jobs import AnalysisJobs, MetricsBatch
from .analysis_plots import FrfPlots, HysteresisPlot, SpectraPlots
from .analysis_runs import RunsTable
from .dock_layout import controls_beside_plots

#: the metrics table: header, LogMetrics.row() key, format ('' : text as it is)
METRIC_COLUMNS = (("log", "log", ""), ("sensor", "sensor", ""), ("from s", "from_s", ".3f"),
                  ("to s", "to_s", ".3f"), ("RMS µrad", "rms_urad", ".4g"),
                  ("std µrad", "std_urad", ".4g"), ("high-pass µrad", "highpass_rms_urad", ".4g"),
                  ("smear µrad", "smear_rms_urad", ".4g"), ("energy J", "energy_total_j", ".4g"),
                  ("sat. coarse %", "saturated_coarse_pct", ".3g"),
                  ("sat. fine %", "saturated_fine_pct", ".3g"), ("note", "notes", ""))
VALUE_ROLE = Qt.ItemDataRole.UserRole
SEGMENTS = (256, 512, 1024, 2048, 4096, 8192)
BAD_STYLE = "color:#c62828;"
BUSY_STYLE = "color:#1565c0;"
TABS = ("Metrics", "PSD / CSP", "FRF", "Hysteresis")


class AnalysisPanel(QWidget):
    def __init__(self, session, parent: QWidget | None = None):
        """`session`: the window's Session (sig_source tells which log it replays)."""
        super().__init__(parent)
        self.session = session
        self.jobs = AnalysisJobs(self)
        self._build()
        j = self.jobs
        j.sig_progress.connect(self._on_progress)
        j.sig_metrics_done.connect(self._on_metrics)
        j.sig_frf_done.connect(self._on_frf)
        j.sig_hysteresis_done.connect(self._on_hysteresis)
        j.sig_logs_found.connect(self._on_logs_found)
        j.sig_failed.connect(self._on_failed)
        session.sig_source.connect(self._on_source)
        replay = getattr(session, "replay", None)
        if replay is not None:
            self.runs.add(replay.path, "replay", make_current=True)

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        runs_box = QGroupBox("Logs")
        col = QVBoxLayout(runs_box)
        self.runs = RunsTable()
        self.runs.setMinimumHeight(90)
        col.addWidget(self.runs, 1)
        row = QHBoxLayout()
        self.file_button = QPushButton("File…")
        self.file_button.setToolTip("add one or more log files")
        self.folder_button = QPushButton("Folder…")
        self.folder_button.setToolTip("add every log in a folder and below (a campaign's logs)")
        self.remove_button = QPushButton("Remove")
        for b in (self.file_button, self.folder_button, self.remove_button):
            row.addWidget(b)
        col.addLayout(row)

        opts = QGroupBox("Options")
        form = QFormLayout(opts)
        form.setContentsMargins(6, 4, 6, 4)
        form.setVerticalSpacing(2)
        self.sensor = QComboBox()
        self.sensor.addItems(list(SENSORS))
        self.sensor.setCurrentText(DEFAULT_SENSOR)
        self.period = QDoubleSpinBox()
        self.period.setRange(0.001, 3600.0)
        self.period.setDecimals(3)
        self.period.setValue(DEFAULT_INTEGRATION_PERIOD_S)
        self.period.setSuffix(" s")
        self.period.setToolTip("integration period of the jitter's high-pass and windowed smear")
        window = QHBoxLayout()
        self.window_from = QLineEdit()
        self.window_from.setPlaceholderText("start")
        self.window_to = QLineEdit()
        self.window_to.setPlaceholderText("end")
        for w in (self.window_from, self.window_to):
            w.setToolTip("seconds from the log's start (empty: open end)")
            w.setMaximumWidth(70)
            window.addWidget(w)
        self.frf_input = QComboBox()
        self.frf_input.addItems(list(FRF_INPUTS))
        self.frf_output = QComboBox()
        self.frf_output.addItems(list(FRF_OUTPUTS))
        self.segments = QComboBox()
        self.segments.addItem("auto", None)
        for n in SEGMENTS:
            self.segments.addItem(str(n), n)
        self.segments.setToolTip("Welch segment length in samples (resolution = rate / length)")
        self.testbed = QComboBox()
        self.testbed.addItem("the log's", None)
        for path in sorted(TESTBEDS_DIR.glob("*.toml")):
            self.testbed.addItem(path.stem, str(path))
        self.testbed.setToolTip("the testbed whose model and constants are used (default: the "
                                "file the log recorded)")
        form.addRow("sensor", self.sensor)
        form.addRow("integration", self.period)
        form.addRow("window s", window)
        form.addRow("FRF input", self.frf_input)
        form.addRow("FRF output", self.frf_output)
        form.addRow("segments", self.segments)
        form.addRow("testbed", self.testbed)

        actions = QWidget()
        acol = QVBoxLayout(actions)
        acol.setContentsMargins(0, 0, 0, 0)
        self.metrics_button = QPushButton("Metrics")
        self.metrics_button.setToolTip("jitter, energy and spectra of every ticked log")
        self.frf_button = QPushButton("FRF")
        self.frf_button.setToolTip("frequency response of the highlighted log against the model")
        self.hysteresis_button = QPushButton("Hysteresis")
        self.hysteresis_button.setToolTip("friction torque against angle of the highlighted log")
        for b in (self.metrics_button, self.frf_button, self.hysteresis_button):
            acol.addWidget(b)
        self.status = QLabel("tick logs, then Metrics; highlight one for FRF or Hysteresis")
        self.status.setWordWrap(True)
        self.status.setTextFormat(Qt.TextFormat.PlainText)
        self.status.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.status.setMinimumWidth(160)
        acol.addWidget(self.status, 1)

        self.tabs = QTabWidget()
        self.metrics_table = QTableWidget(0, len(METRIC_COLUMNS))
        self.metrics_table.setHorizontalHeaderLabels([c[0] for c in METRIC_COLUMNS])
        self.metrics_table.verticalHeader().setVisible(False)
        self.metrics_table.verticalHeader().setDefaultSectionSize(20)
        self.metrics_table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.metrics_table.horizontalHeader().setSectionResizeMode(
            QHeaderView.ResizeMode.ResizeToContents)
        self.spectra = SpectraPlots()
        self.frf_plots = FrfPlots()
        self.hysteresis_plot = HysteresisPlot()
        for name, w in zip(TABS, (self.metrics_table, self.spectra, self.frf_plots,
                                  self.hysteresis_plot)):
            self.tabs.addTab(w, name)

        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 2, 4, 2)
        lay.addWidget(controls_beside_plots([runs_box, opts, actions], self.tabs, min_width=240,
                                            plots_width=700, pad=20))

        self.file_button.clicked.connect(self.files_dialog)
        self.folder_button.clicked.connect(self.folder_dialog)
        self.remove_button.clicked.connect(self.runs.remove_selected)
        self.metrics_button.clicked.connect(self.run_metrics)
        self.frf_button.clicked.connect(self.run_frf)
        self.hysteresis_button.clicked.connect(self.run_hysteresis)

    # ------------------------------------------------------------------ logs
    def add_log(self, path: str | Path, origin: str = "file") -> None:
        """List a log file (ticked and highlighted)."""
        self.runs.add(path, origin, make_current=True)

    def add_folder(self, folder: str | Path) -> bool:
        """List every log of a folder (found on a worker thread)."""
        started = self.jobs.folder(Path(folder))
        if started:
            self._say(f"looking for logs in {folder}…", BUSY_STYLE)
        return started

    def files_dialog(self) -> None:
        paths, _ = QFileDialog.getOpenFileNames(self, "Logs to analyse", "", "Logs (*.h5)")
        for p in paths:
            self.add_log(p)

    def folder_dialog(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "A folder of logs (a campaign's)", "logs")
        if folder:
            self.add_folder(folder)

    def _on_source(self, kind: str, text: str) -> None:
        if kind == "replay" and text:
            self.runs.add(text, "replay", make_current=True)

    def _on_logs_found(self, folder: str, paths: list) -> None:
        for p in paths:
            self.runs.add(p, Path(folder).name)
        self._say(f"{len(paths)} log(s) in {folder}" if paths else f"no logs (*.h5) in {folder}",
                  "" if paths else BAD_STYLE)

    # ------------------------------------------------------------------ options
    def _window(self) -> tuple[float | None, float | None] | None:
        out = []
        for name, edit in (("from", self.window_from), ("to", self.window_to)):
            text = edit.text().strip()
            if not text:
                out.append(None)
                continue
            try:
                value = float(text)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                self._say(f"window {name}: {text!r} is not a number of seconds", BAD_STYLE)
                return None
            out.append(value)
        return out[0], out[1]

    def _testbed(self) -> str | None:
        return self.testbed.currentData()

    # ------------------------------------------------------------------ the jobs
    def run_metrics(self) -> bool:
        paths = self.runs.checked_paths()
        if not paths:
            self._say("Metrics: tick at least one log", BAD_STYLE)
            return False
        window = self._window()
        if window is None:
            return False
        options = dict(sensor=self.sensor.currentText(), integration_period_s=self.period.value(),
                       start_s=window[0], stop_s=window[1])
        if self._testbed():
            options["testbed"] = self._testbed()
        return self._started("metrics", self.metrics_button, self.jobs.metrics(paths, **options))

    def run_frf(self) -> bool:
        path, window = self._one("FRF")
        if path is None:
            return False
        options = dict(input_channel=self.frf_input.currentText(),
                       output_channel=self.frf_output.currentText(), start_s=window[0],
                       stop_s=window[1], nperseg=self.segments.currentData(),
                       testbed=self._testbed())
        return self._started("frf", self.frf_button, self.jobs.frf(path, **options))

    def run_hysteresis(self) -> bool:
        path, window = self._one("Hysteresis")
        if path is None:
            return False
        return self._started("hysteresis", self.hysteresis_button, self.jobs.hysteresis(
            path, start_s=window[0], stop_s=window[1], testbed=self._testbed()))

    def _one(self, what: str):
        path = self.runs.current_path()
        if path is None:
            self._say(f"{what}: highlight a log in the list (or add one)", BAD_STYLE)
            return None, None
        window = self._window()
        return (path, window) if window is not None else (None, None)

    def _started(self, job: str, button: QPushButton, started: bool) -> bool:
        if started:
            button.setEnabled(False)
            self._say(f"{_label(job)}: working…", BUSY_STYLE)
        else:
            self._say(f"{_label(job)}: still working on the last one", BAD_STYLE)
        return started

    def _button(self, job: str) -> QPushButton | None:
        return {"metrics": self.metrics_button, "frf": self.frf_button,
                "hysteresis": self.hysteresis_button}.get(job)

    # ------------------------------------------------------------------ results
    def _on_progress(self, job: str, text: str) -> None:
        self._say(f"{_label(job)}: {text}…", BUSY_STYLE)

    def _on_failed(self, job: str, message: str) -> None:
        button = self._button(job)
        if button is not None:
            button.setEnabled(True)
        self._say(f"{_label(job)} failed: {message}", BAD_STYLE)

    def _on_metrics(self, batch: MetricsBatch) -> None:
        self.metrics_button.setEnabled(True)
        table = self.metrics_table
        table.setRowCount(0)
        for m in batch.results:
            self._metrics_row(m.row())
        for path, reason in batch.failures:
            self._metrics_row({"log": path.name, "notes": reason}, bad=True)
        self.spectra.show_metrics(batch.results)
        self.tabs.setCurrentIndex(TABS.index("PSD / CSP" if batch.results else "Metrics"))
        if batch.failures:
            self.tabs.setCurrentIndex(TABS.index("Metrics"))
            self._say(f"Metrics of {len(batch.results)} of {len(batch.requested)} log(s); "
                      + "; ".join(f"{p.name}: {r}" for p, r in batch.failures), BAD_STYLE)
        else:
            self._say(f"Metrics of {len(batch.results)} log(s)", "")

    def _metrics_row(self, values: dict, bad: bool = False) -> None:
        table = self.metrics_table
        row = table.rowCount()
        table.insertRow(row)
        for col, (_, key, fmt) in enumerate(METRIC_COLUMNS):
            value = values.get(key)
            if value is None or value == "":
                text = ""
            elif fmt and isinstance(value, (int, float)):
                text = format(value, fmt)
            else:
                text = str(value)
            item = QTableWidgetItem(text)
            item.setData(VALUE_ROLE, value)
            if fmt:
                item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            if key == "notes" and text:
                item.setToolTip(text)
                if bad:
                    item.setForeground(Qt.GlobalColor.red)
            table.setItem(row, col, item)

    def _on_frf(self, res) -> None:
        self.frf_button.setEnabled(True)
        self.frf_plots.show_frf(res)
        self.tabs.setCurrentIndex(TABS.index("FRF"))
        self._say(f"FRF of {res.path.name}: {res.input_channel} → {res.output_channel}, "
                  f"{res.measured.segments} segments"
                  + ("" if res.model is not None else " (no model: see the notes)"), "")

    def _on_hysteresis(self, res) -> None:
        self.hysteresis_button.setEnabled(True)
        self.hysteresis_plot.show_loop(res)
        self.tabs.setCurrentIndex(TABS.index("Hysteresis"))
        self._say(f"Hysteresis of {res.path.name}: {len(res.loop.branches)} branches"
                  + ("" if res.identification is None else
                     f", T_c {res.identification.coulomb_torque_in_oz:.3f} in-oz"), "")

    def _say(self, text: str, style: str = "") -> None:
        self.status.setStyleSheet(style)
        self.status.setText(text)

    # ------------------------------------------------------------------ closing
    def shutdown(self) -> None:
        self.jobs.shutdown()


def _label(job: str) -> str:
    return {"metrics": "Metrics", "frf": "FRF", "hysteresis": "Hysteresis",
            "folder": "Folder"}.get(job, job)


__all__ = ["AnalysisPanel", "METRIC_COLUMNS"]
