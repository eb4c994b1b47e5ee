"""The Analysis dock: figures of merit and identification from recorded logs and from
what the window shows.

Left, the logs it acts on (analysis_runs.RunsTable): the log the window replays (added
when the Session opens it), files chosen with File…, the logs of a folder (a campaign's)
with Folder…, each recording the Session finishes (origin "recorded", not ticked), and
the "Live window" row while a live link or a replay feeds the charts: the telemetry the
window holds, Metrics only (analysis/live.py: a copy of the store taken here when
Metrics is pressed, computed on the worker like a log).  Then the options
(analysis_controls.OptionsBox) - the scored sensor, the integration period, a window of
the log (from/to in seconds from its start; empty: the whole log), the live window's
span (its last N seconds), the FRF's input and output channels, segment length and
testbed - and the buttons (ActionsBox).  Each acts on every ticked log (when none is
ticked, on the highlighted one), one colour per log in every plot:

* Metrics: jitter and energy (a table row each) and the PSD and CSP of the scored sensor;
* FRF: the frequency responses overlaid, the testbed model once, and the coherences;
* Hysteresis: the friction torque against the outer encoder, the loops overlaid;
* Step: response and reference against the time from the step, and a table of rise,
  overshoot, settling, steady-state error and peak effort;
* Identify: the rig's testbed fitted to the ticked open-loop identification logs
  together (identification.pipeline), from a base testbed that is always named: the
  one chosen under Options, else the session's testbed file, else one asked for - never
  the file a log recorded (on the simulated rig that is the hidden truth the fit is to
  find).  The Identify tab (analysis/identify.py) shows the parameters, the fit and the
  overlays; Save testbed file… writes the identified file, and Open in design workbench
  asks the main window (sig_open_workbench) to open the workbench on the saved file.

Cancel stops the jobs under way (what they computed is dropped); the status line says
how far a job is (logs done / in all).  Export writes the metrics or step table as CSV
or JSON (analysis_export.write_rows: the values the table holds) and the plots of the
tab shown as one PNG.

The widget does no I/O and no computing: AnalysisJobs (analysis/jobs.py) runs the
analysis modules on worker threads and answers with signals; analysis_export writes the
files; what fails is said in the status line in the error's own words.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (QFileDialog, QGroupBox, QHBoxLayout, QPushButton, QTabWidget,
                               QVBoxLayout, QWidget)

from .controls import BAD_STYLE, BUSY_STYLE, ActionsBox, OptionsBox
from ...core.errors import GroundStationError
from .export import write_bytes, write_rows
from .identify import IdentifyView
from .jobs import BATCH_JOBS, AnalysisJobs, Batch, IdentifyResult
from .live import live_available, take_snapshot
from .plots import FrfPlots, HysteresisPlot, SpectraPlots, StepPlots, render_png
from .runs import LIVE, RunsTable
from .tables import METRIC_COLUMNS, ResultTable
from ..common.dock_layout import controls_beside_plots
from ...plant.testbed import TESTBEDS_DIR

TABS = ("Metrics", "PSD / CSP", "FRF", "Hysteresis", "Step", "Identify")
LABELS = {"metrics": "Metrics", "frf": "FRF", "hysteresis": "Hysteresis", "step": "Step",
          "identify": "Identify", "folder": "Folder"}


class AnalysisPanel(QWidget):
    #: the identified testbed file saved from the Identify tab, to open in the design
    #: workbench (the main window owns the workbench, through the Parameters dock)
    sig_open_workbench = Signal(str)

    def __init__(self, session, parent: QWidget | None = None):
        """`session`: the window's Session (sig_source tells which log it replays, its
        link state and source whether the Live window row is shown, its recording
        signals what it has just recorded; `session.store` is the live window)."""
        super().__init__(parent)
        self.session = session
        self._recording: tuple[Path, object] | None = None    # (first file, its Recorder)
        self.jobs = AnalysisJobs(self)
        self._build()
        j = self.jobs
        j.sig_progress.connect(self._on_progress)
        j.sig_metrics_done.connect(self._on_metrics)
        j.sig_frf_done.connect(self._on_frf)
        j.sig_hysteresis_done.connect(self._on_hysteresis)
        j.sig_step_done.connect(self._on_step)
        j.sig_identify_done.connect(self._on_identify)
        j.sig_logs_found.connect(self._on_logs_found)
        j.sig_failed.connect(self._on_failed)
        j.sig_cancelled.connect(self._on_cancelled)
        session.sig_source.connect(self._on_source)
        for name, slot in (("sig_link_state", self._update_live),
                           ("sig_recording_started", self._on_recording_started),
                           ("sig_recording_stopped", self._on_recording_stopped)):
            if hasattr(session, name):
                getattr(session, name).connect(slot)
        self.runs.itemChanged.connect(self._on_run_ticked)
        replay = getattr(session, "replay", None)
        if replay is not None:
            self.runs.add(replay.path, "replay", make_current=True)
        self._update_live()

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

        self.options = o = OptionsBox()
        # the options and buttons under the names the panel has always had
        self.sensor, self.period = o.sensor, o.period
        self.window_from, self.window_to = o.window_from, o.window_to
        self.frf_input, self.frf_output = o.frf_input, o.frf_output
        self.segments, self.testbed = o.segments, o.testbed
        self.actions = a = ActionsBox()
        self.metrics_button, self.frf_button = a.metrics_button, a.frf_button
        self.hysteresis_button, self.step_button = a.hysteresis_button, a.step_button
        self.identify_button = a.identify_button
        self.cancel_button, self.export_button = a.cancel_button, a.export_button
        self.status = a.status

        self.tabs = QTabWidget()
        self.metrics_table = ResultTable(METRIC_COLUMNS)
        self.spectra = SpectraPlots()
        self.frf_plots = FrfPlots()
        self.hysteresis_plot = HysteresisPlot()
        self.step_plots = StepPlots()
        self.identify_view = IdentifyView()
        for name, w in zip(TABS, (self.metrics_table, self.spectra, self.frf_plots,
                                  self.hysteresis_plot, self.step_plots, self.identify_view)):
            self.tabs.addTab(w, name)

        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 2, 4, 2)
        lay.addWidget(controls_beside_plots([runs_box, o, a], self.tabs, min_width=240,
                                            plots_width=700, pad=20))

        self.file_button.clicked.connect(self.files_dialog)
        self.folder_button.clicked.connect(self.folder_dialog)
        self.remove_button.clicked.connect(self.runs.remove_selected)
        self.metrics_button.clicked.connect(self.run_metrics)
        self.frf_button.clicked.connect(self.run_frf)
        self.hysteresis_button.clicked.connect(self.run_hysteresis)
        self.step_button.clicked.connect(self.run_step)
        self.identify_button.clicked.connect(lambda: self.run_identify())
        self.identify_view.save_button.clicked.connect(self.save_testbed_dialog)
        self.identify_view.open_button.clicked.connect(self.open_in_workbench)
        self.cancel_button.clicked.connect(self.cancel)
        a.export_metrics_csv.triggered.connect(lambda: self.export_table_dialog("metrics", "csv"))
        a.export_metrics_json.triggered.connect(lambda: self.export_table_dialog("metrics", "json"))
        a.export_step_csv.triggered.connect(lambda: self.export_table_dialog("step", "csv"))
        a.export_step_json.triggered.connect(lambda: self.export_table_dialog("step", "json"))
        a.export_png.triggered.connect(self.export_plots_dialog)

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
        self._update_live()

    def _update_live(self, *_args) -> None:
        """The Live window row is there while a live link or a replay feeds the charts
        (asked of the session itself: its signals may arrive late from other threads)."""
        self.runs.set_live(live_available(self.session))

    def _on_run_ticked(self, item) -> None:
        if (item.column() == 0 and self.runs.is_live_row(item.row())
                and self.runs.live_checked()):
            span = self.options.live_span()
            what = f"the last {span:.1f} s" if span else "all"
            self._say(f"Live window: Metrics only, of {what} the window holds (FRF, "
                      f"Hysteresis and Step need a log: record one, it is listed when the "
                      f"recording stops)", "")

    def _on_recording_started(self, path: str) -> None:
        self._recording = (Path(path), getattr(self.session, "recorder", None))

    def _on_recording_stopped(self, _text: str) -> None:
        """List what the session just recorded (every file, if it rolled over), not
        ticked."""
        started, self._recording = self._recording, None
        if started is None:
            return
        first, recorder = started
        files = list(getattr(recorder, "files", None) or [first])
        for f in files:
            self.runs.add(f, "recorded", checked=False)
        if not any(self.jobs.busy(job) for job in BATCH_JOBS):
            self._say(f"recorded: {', '.join(Path(f).name for f in files)} listed (tick it to "
                      f"analyse)", "")

    def _on_logs_found(self, folder: str, paths: list) -> None:
        for p in paths:
            self.runs.add(p, Path(folder).name)
        self._say(f"{len(paths)} log(s) in {folder}" if paths else f"no logs (*.h5) in {folder}",
                  "" if paths else BAD_STYLE)

    # ------------------------------------------------------------------ the jobs
    def _window(self):
        try:
            return self.options.window()
        except ValueError as exc:
            self._say(str(exc), BAD_STYLE)
            return None

    def _targets(self, job: str) -> list:
        """The ticked logs; when none is ticked, the highlighted one (Metrics: ticked
        only, the Live window among them as LIVE; the others take logs only)."""
        if job == "metrics":
            paths = self.runs.checked_targets()
        else:
            paths = self.runs.checked_paths()
            current = self.runs.current_path() if self.runs.currentRow() >= 0 else None
            if not paths and current is not None:
                paths = [current]
        if not paths:
            why = ("the Live window has Metrics only; tick a log (record one: it is listed "
                   "when it stops)" if job != "metrics" and self.runs.live_checked()
                   else "tick at least one log")
            self._say(f"{LABELS[job]}: {why}", BAD_STYLE)
        return paths

    def _run(self, job: str, start) -> bool:
        paths = self._targets(job)
        window = self._window() if paths else None
        if window is None:
            return False
        started = start(paths, window, self.options.testbed_file())
        if started:
            self.actions.job_buttons()[job].setEnabled(False)
            left_out = job != "metrics" and self.runs.live_checked()
            self._say(f"{LABELS[job]}: 0/{len(paths)} logs done…"
                      + (" (not the Live window: Metrics only)" if left_out else ""), BUSY_STYLE)
        else:
            self._say(f"{LABELS[job]}: still working on the last one", BAD_STYLE)
        self._update_cancel()
        return started

    def run_metrics(self) -> bool:
        """Metrics of the ticked logs and, when ticked, the Live window: a copy of what
        the window holds, taken now (analysis_live.take_snapshot), computed with the logs."""
        def start(targets, window, testbed):
            if self.jobs.busy("metrics"):
                return False                    # no copy of the store for nothing
            options = dict(sensor=self.sensor.currentText(),
                           integration_period_s=self.period.value(), start_s=window[0],
                           stop_s=window[1])
            if testbed:
                options["testbed"] = testbed
            span = self.options.live_span()
            return self.jobs.metrics([take_snapshot(self.session, span) if t == LIVE else t
                                      for t in targets], **options)
        return self._run("metrics", start)

    def run_frf(self) -> bool:
        return self._run("frf", lambda paths, window, testbed: self.jobs.frf(
            paths, input_channel=self.frf_input.currentText(),
            output_channel=self.frf_output.currentText(), start_s=window[0], stop_s=window[1],
            nperseg=self.segments.currentData(), testbed=testbed))

    def run_hysteresis(self) -> bool:
        return self._run("hysteresis", lambda paths, window, testbed: self.jobs.hysteresis(
            paths, start_s=window[0], stop_s=window[1], testbed=testbed))

    def run_step(self) -> bool:
        return self._run("step", lambda paths, window, testbed: self.jobs.step(
            paths, start_s=window[0], stop_s=window[1]))

    def run_identify(self, base: str | Path | None = None) -> bool:
        """Identify the rig from the ticked logs, from the base testbed file `base` (None:
        see _base_testbed).  The logs' window does not apply: the fit takes whole logs."""
        paths = self._targets("identify")
        if not paths:
            return False
        if self.jobs.busy("identify"):
            self._say("Identify: still working on the last one", BAD_STYLE)
            return False
        base_path, how = self._base_testbed(base)
        if base_path is None:
            self._say("Identify: no base testbed chosen - choose one under Options (testbed) "
                      "or in the dialog (a log's own file is never the base)", BAD_STYLE)
            return False
        if not self.jobs.identify(paths, base_path):
            return False
        self.identify_button.setEnabled(False)
        self.identify_view.clear(f"identifying from {len(paths)} log(s), base {base_path.name} "
                                 f"({how})…")
        windowed = self.window_from.text().strip() or self.window_to.text().strip()
        self._say(f"Identify: {len(paths)} log(s), base {base_path.name} ({how})…"
                  + (" (whole logs: the window does not apply)" if windowed else ""), BUSY_STYLE)
        self._update_cancel()
        return True

    def _base_testbed(self, base: str | Path | None) -> tuple[Path | None, str]:
        """The base testbed file identify starts from and how it was chosen: the one given,
        the one under Options, the session's, or one asked for (None: none chosen).  Never
        the file a log recorded: on the simulated rig that is the very rig to be found."""
        if base is not None:
            return Path(base), "given"
        if self.options.testbed_file():
            return Path(self.options.testbed_file()), "chosen under Options"
        if getattr(self.session, "testbed", None):
            return Path(self.session.testbed), "the session's testbed"
        path, _ = QFileDialog.getOpenFileName(self, "The base testbed file to identify from",
                                              str(TESTBEDS_DIR), "Testbed files (*.toml)")
        return (Path(path), "chosen in the dialog") if path else (None, "")

    def cancel(self) -> bool:
        """Stop every analysis under way (metrics, FRF, hysteresis, step, identify)."""
        return bool([job for job in BATCH_JOBS if self.jobs.cancel(job)])

    def _update_cancel(self) -> None:
        self.cancel_button.setEnabled(any(self.jobs.busy(job) for job in BATCH_JOBS))

    def _job_ended(self, job: str) -> None:
        button = self.actions.job_buttons().get(job)
        if button is not None:
            button.setEnabled(True)
        self._update_cancel()

    # ------------------------------------------------------------------ results
    def _on_progress(self, job: str, done: int, total: int, text: str) -> None:
        if job == "identify":                     # one fit of all the logs: no count
            self._say(f"Identify: {text}…", BUSY_STYLE)
            return
        self._say(f"{LABELS.get(job, job)}: {done}/{total} logs done - {text}…", BUSY_STYLE)

    def _on_failed(self, job: str, message: str) -> None:
        self._job_ended(job)
        if job == "identify":                     # the pipeline's own words, nothing written
            message += "; nothing written"
            self.identify_view.clear(f"Identify failed: {message}")
            self.tabs.setCurrentIndex(TABS.index("Identify"))
        self._say(f"{LABELS.get(job, job)} failed: {message}", BAD_STYLE)

    def _on_cancelled(self, job: str) -> None:
        self._job_ended(job)
        self._say(f"{LABELS.get(job, job)} cancelled: nothing shown from it", "")

    def _done(self, job: str, batch: Batch, tab: str) -> None:
        """The status line and the tab shown after a batch: the failures said, the tab
        of the figures shown when there are any."""
        self._job_ended(job)
        n, asked = len(batch.results), len(batch.requested)
        if batch.results:
            self.tabs.setCurrentIndex(TABS.index(tab))
        if batch.failures:
            why = "; ".join(_failure(p, r) for p, r in batch.failures)
            self._say(f"{LABELS[job]} of {n} of {asked} log(s); {why}" if n else
                      f"{LABELS[job]} failed: {why}", BAD_STYLE)
        else:
            self._say(f"{LABELS[job]} of {n} log(s)", "")

    def _on_metrics(self, batch: Batch) -> None:
        table = self.metrics_table
        table.clear_rows()
        for m in batch.results:
            table.add_row(m.row())
        for path, reason in batch.failures:
            table.add_row({"log": path.name, "notes": reason}, bad=True)
        self.spectra.show_metrics(batch.results, batch.indices())
        self._done("metrics", batch, "PSD / CSP")
        if batch.failures or not batch.results:
            self.tabs.setCurrentIndex(TABS.index("Metrics"))

    def _on_frf(self, batch: Batch) -> None:
        if batch.results:
            self.frf_plots.show_frfs(batch.results, batch.indices())
        self._done("frf", batch, "FRF")
        if len(batch.results) == 1 and not batch.failures:
            res = batch.results[0]
            self._say(f"FRF of {res.path.name}: {res.input_channel} → {res.output_channel}, "
                      f"{res.measured.segments} segments"
                      + ("" if res.model is not None else " (no model: see the notes)"), "")

    def _on_hysteresis(self, batch: Batch) -> None:
        if batch.results:
            self.hysteresis_plot.show_loops(batch.results, batch.indices())
        self._done("hysteresis", batch, "Hysteresis")
        if batch.results and not batch.failures:
            self._say(f"Hysteresis of {len(batch.results)} log(s): "
                      + ", ".join(_loop_summary(r) for r in batch.results), "")

    def _on_step(self, batch: Batch) -> None:
        self.step_plots.show_steps(batch.results, batch.indices(), batch.failures)
        self._done("step", batch, "Step")
        if batch.failures:
            self.tabs.setCurrentIndex(TABS.index("Step"))

    def _on_identify(self, result: IdentifyResult) -> None:
        self._job_ended("identify")
        self.identify_view.show_result(result)
        self.tabs.setCurrentIndex(TABS.index("Identify"))
        ident = result.identification
        fitted = sum(1 for p in ident.provenance if p.status == "identified")
        self._say(f"Identify: {fitted} parameter(s) identified from "
                  f"{sum(u.used for u in ident.logs)} of {len(ident.logs)} log(s), base "
                  f"{result.base_path.name}; Save testbed file… writes it", "")

    def _say(self, text: str, style: str = "") -> None:
        self.actions.say(text, style)

    # ------------------------------------------------------------------ the identified file
    def save_testbed(self, path: str | Path, name: str | None = None) -> bool:
        """Write the identified testbed file shown in the Identify tab to `path`
        (identification.testbed_file.write_identified: nothing that would not load)."""
        if self.identify_view.result is None:
            self._say("Save testbed file: nothing identified yet (tick the identification "
                      "logs, then Identify)", BAD_STYLE)
            return False
        try:
            written = self.identify_view.save(path, name)
        except GroundStationError as exc:        # TestbedWriteError: the file's own words
            self._say(f"Save testbed file: {exc}", BAD_STYLE)
            return False
        self._say(f"identified testbed file written to {written}", "")
        return True

    def _ask_testbed_path(self) -> str:
        result = self.identify_view.result
        if result is None:
            return ""
        near = result.used_logs[0].parent if result.used_logs else Path.cwd()
        path, _ = QFileDialog.getSaveFileName(
            self, "Save the identified testbed file",
            str(near / f"{result.base_path.stem}_identified.toml"), "Testbed files (*.toml)")
        return path + ".toml" if path and not Path(path).suffix else path

    def save_testbed_dialog(self) -> bool:
        path = self._ask_testbed_path()
        return self.save_testbed(path) if path else False

    def open_in_workbench(self) -> bool:
        """Ask for the design workbench on the identified file (saved first if it is not)."""
        view = self.identify_view
        if view.result is None:
            self._say("Open in design workbench: nothing identified yet", BAD_STYLE)
            return False
        if view.saved is None:
            path = self._ask_testbed_path()
            if not path:
                self._say("Open in design workbench: save the identified testbed file first",
                          BAD_STYLE)
                return False
            if not self.save_testbed(path):
                return False
        self.sig_open_workbench.emit(str(view.saved))
        self._say(f"design workbench opened on {view.saved.name}: #1 a design on its base "
                  f"testbed, #2 the same design on the identified one", "")
        return True

    # ------------------------------------------------------------------ export
    def _table(self, which: str):
        return {"metrics": self.metrics_table, "step": self.step_plots.table}[which]

    def export_table(self, which: str, path: str | Path, fmt: str | None = None) -> bool:
        """The metrics or step table (`which`) to `path` as CSV or JSON (`fmt`, None:
        from the suffix): the values the table holds, one record per row."""
        table = self._table(which)
        if not table.count():
            self._say(f"Export: the {which} table is empty (run {LABELS[which]} first)", BAD_STYLE)
            return False
        try:
            written = write_rows(path, table.keys, table.rows(), fmt)
        except GroundStationError as exc:
            self._say(f"Export failed: {exc}", BAD_STYLE)
            return False
        self._say(f"{table.count()} record(s) of the {which} table written to {written}", "")
        return True

    def export_plots(self, path: str | Path) -> bool:
        """The plots of the tab shown, side by side, to `path` as a PNG."""
        widget = self.tabs.currentWidget()
        plots = widget.plot_widgets() if hasattr(widget, "plot_widgets") else []
        if not plots:
            self._say(f"Export: the {TABS[self.tabs.currentIndex()]} tab has no plots; show "
                      f"a plot tab ({', '.join(TABS[1:])})", BAD_STYLE)
            return False
        try:
            written = write_bytes(path, render_png(plots))
        except GroundStationError as exc:
            self._say(f"Export failed: {exc}", BAD_STYLE)
            return False
        self._say(f"{TABS[self.tabs.currentIndex()]} plots written to {written}", "")
        return True

    def export_table_dialog(self, which: str, fmt: str) -> None:
        path, _ = QFileDialog.getSaveFileName(self, f"Write the {which} table", f"{which}.{fmt}",
                                              f"{fmt.upper()} (*.{fmt})")
        if path:
            if not Path(path).suffix:
                path += f".{fmt}"
            self.export_table(which, path, fmt)

    def export_plots_dialog(self) -> None:
        name = TABS[self.tabs.currentIndex()].lower().replace(" / ", "_")
        path, _ = QFileDialog.getSaveFileName(self, "Write the plots shown", f"{name}.png",
                                              "PNG (*.png)")
        if path:
            self.export_plots(path if Path(path).suffix else path + ".png")

    # ------------------------------------------------------------------ closing
    def shutdown(self) -> None:
        self.jobs.shutdown()


def _failure(path: Path, reason: str) -> str:
    """A log's failure, named once (most messages start with the log's name already)."""
    return reason if path.name in reason else f"{path.name}: {reason}"


def _loop_summary(res) -> str:
    text = f"{len(res.loop.branches)} branches"
    if res.identification is not None:
        text += f", T_c {res.identification.coulomb_torque_in_oz:.3f} in-oz"
    return text


__all__ = ["AnalysisPanel", "TABS"]
