"""The operator's window: strip charts in the middle, panels in docks, Abort on Esc."""

from __future__ import annotations

import json
from pathlib import Path

from PySide6.QtCore import QByteArray, QSettings, Qt
from PySide6.QtGui import QAction, QKeySequence, QShortcut
from PySide6.QtWidgets import (QDockWidget, QFileDialog, QLabel, QMainWindow, QMessageBox,
                               QPushButton, QToolBar)

from ..plant.testbed import TESTBEDS_DIR
from .analysis.panel import AnalysisPanel
from .panels.campaign import CampaignPanel
from .charts.channel_tree import ChannelTree
from .charts.panel import StripChartPanel
from .demo import DEMO_TITLE, DemoController, plan_for
from .generator.panel import GeneratorPanel
from .panels.params import ParameterPanel
from .panels.profile import ProfilePanel
from .panels.logs import EventLog, ReplayBar
from .panels.session_panels import CommandPanel, ConnectionBar, RecordingPanel, StatusPanel
from .session.session import Session
from .charts.spectrum import SpectrumView

DEFAULT_LAYOUT = [["HIGH_RATE.encoder_outer", "HIGH_RATE.encoder_inner"],
                  ["HIGH_RATE.los_estimate", "HIGH_RATE.reference"],
                  ["HIGH_RATE.gyro_rate"],
                  ["HIGH_RATE.current_coarse", "HIGH_RATE.current_fine"]]


class MainWindow(QMainWindow):
    def __init__(self, session: Session, settings: QSettings | None = None):
        super().__init__()
        self.session = session
        self.settings = settings or QSettings("groundstation", "groundstation")
        self.setWindowTitle("Ground station - hybrid flexure bearing testbed")
        self.setAcceptDrops(True)
        self._link_bars()
        self._panels()
        self._docks()
        self._status_line()
        self._follow_campaigns()
        self._demo_bar()
        self._menus()
        self._abort_key()
        self.charts.set_layout(DEFAULT_LAYOUT)
        self.restore()

    # ------------------------------------------------------------------ building the window
    def _link_bars(self) -> None:
        """The connection bar at the top; the replay bar at the bottom, shown during a replay."""
        root = TESTBEDS_DIR.parent.parent
        testbeds = [str(p.relative_to(root)) if p.is_relative_to(root) else str(p)
                    for p in sorted(TESTBEDS_DIR.glob("*.toml"))]
        self.connection = ConnectionBar(self.session, testbeds)
        bar = QToolBar("Connection")
        bar.setObjectName("connection_bar")
        bar.addWidget(self.connection)
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, bar)
        self.replay_bar = ReplayBar(self.session)
        self.replay_toolbar = QToolBar("Replay")
        self.replay_toolbar.setObjectName("replay_bar")
        self.replay_toolbar.addWidget(self.replay_bar)
        self.addToolBar(Qt.ToolBarArea.BottomToolBarArea, self.replay_toolbar)
        self.replay_toolbar.setVisible(False)

    def _panels(self) -> None:
        """The strip charts in the middle and every panel the docks hold."""
        session, d = self.session, self.session.d
        self.charts = StripChartPanel(session.store, d)
        self.setCentralWidget(self.charts)
        self.tree = ChannelTree(d)
        self.tree.sig_channel_activated.connect(lambda cid: self.charts.stack.add_channel(cid))
        self.status_panel = StatusPanel(session)
        self.commands = CommandPanel(session)
        self.commands.sig_abort.connect(self.abort)
        self.recording = RecordingPanel(session)
        self.events = EventLog(session)
        self.spectrum = SpectrumView(session.store, d)
        self.parameters = ParameterPanel(session, d)
        self.generator = GeneratorPanel(session)
        self.profiles = ProfilePanel(session)
        self.profiles.sig_abort.connect(self.abort)
        self.campaign = CampaignPanel(session)
        self.campaign.sig_abort.connect(self.abort)
        self.analysis = AnalysisPanel(session)
        self.analysis.sig_open_workbench.connect(self.open_workbench_on_testbed)
        # the one-click demo on the simulated testbed (through the two docks above)
        self.demo = DemoController(session, self.parameters, self.profiles, self.charts, parent=self)

    def _docks(self) -> None:
        """One dock per panel; the bottom ones tabbed behind the event log."""
        left, right = Qt.DockWidgetArea.LeftDockWidgetArea, Qt.DockWidgetArea.RightDockWidgetArea
        bottom = Qt.DockWidgetArea.BottomDockWidgetArea
        self.docks = {}
        for name, widget, area in (("Channels", self.tree, left),
                                   ("Commands", self.commands, right),
                                   ("Status and limits", self.status_panel, right),
                                   ("Recording", self.recording, left),
                                   ("Events", self.events, bottom),
                                   ("Spectrum", self.spectrum, bottom),
                                   ("Parameters", self.parameters, bottom),
                                   ("Generator", self.generator, bottom),
                                   ("Profiles", self.profiles, bottom),
                                   ("Campaign", self.campaign, bottom),
                                   ("Analysis", self.analysis, bottom)):
            dock = QDockWidget(name)
            dock.setObjectName(name.lower().replace(" ", "_"))
            dock.setWidget(widget)
            self.addDockWidget(area, dock)
            self.docks[name] = dock
        for name in ("Spectrum", "Parameters", "Generator", "Profiles", "Campaign", "Analysis"):
            self.tabifyDockWidget(self.docks["Events"], self.docks[name])
        self.docks["Events"].raise_()
        # the limit table's channel names in full by default (a saved layout wins)
        self.status_panel.refresh()
        self.resizeDocks([self.docks["Status and limits"]],
                         [min(self.status_panel.preferred_width(), 480)], Qt.Orientation.Horizontal)

    def _status_line(self) -> None:
        """The link's state in the status bar; the window follows the data's source."""
        self.link_label = QLabel("not connected")
        self.statusBar().addPermanentWidget(self.link_label)
        self.session.sig_link_state.connect(
            lambda s, m: self.link_label.setText(f"link {s} {m}".strip()))
        self.session.sig_source.connect(self._source_changed)

    def _follow_campaigns(self) -> None:
        # while a campaign runs it owns the device: the manual controls that would fight
        # it are off (ABORT never is)
        runner = self.session.campaign
        runner.sig_started.connect(lambda *_: self._campaign_running(True))
        runner.sig_finished.connect(lambda *_: self._campaign_running(False))
        runner.sig_failed.connect(lambda *_: self._campaign_running(False))

    def _abort_key(self) -> None:
        # Abort: one key from anywhere in the application, whatever has the focus
        self.abort_shortcut = QShortcut(QKeySequence(Qt.Key.Key_Escape), self)
        self.abort_shortcut.setContext(Qt.ShortcutContext.ApplicationShortcut)
        self.abort_shortcut.activated.connect(self.abort)

    # ------------------------------------------------------------------ menus
    def _menus(self) -> None:
        def action(menu, text, slot, shortcut=None):
            a = QAction(text, self)
            if shortcut:
                a.setShortcut(QKeySequence(shortcut))
            a.triggered.connect(slot)
            menu.addAction(a)
            return a
        m = self.menuBar().addMenu("&File")
        action(m, "&Open log...", self.open_log_dialog, "Ctrl+O")
        action(m, "Start/stop &recording", self.recording.toggle, "Ctrl+R")
        action(m, "Close replay", self.session.close_replay)
        m.addSeparator()
        action(m, "&Quit", self.close, "Ctrl+Q")
        m = self.menuBar().addMenu("&Device")
        action(m, "Connect to the &simulated testbed", lambda: self.session.connect_sim(
            self.connection.testbed.currentText() or None), "F5")
        action(m, "&Disconnect", self.session.disconnect_link, "Shift+F5")
        action(m, "&ABORT", self.abort)
        action(m, "&Arm", lambda: self.commands.send("ARM"))
        action(m, "Dis&arm", lambda: self.commands.send("DISARM"), "Ctrl+D")
        m.addSeparator()
        action(m, "&Load controller design...", self._load_design, "Ctrl+L")
        action(m, "&Upload parameter table...", self.parameters.upload, "Ctrl+U")
        action(m, "Read &back parameter table", self.session.params_read)
        action(m, "Roll back parameter table...", self.parameters.rollback)
        m.addSeparator()
        action(m, "Play &profile...", self._play_profile_dialog, "Ctrl+P")
        action(m, "Run &campaign...", self._run_campaign_dialog, "Ctrl+K")
        m = self.menuBar().addMenu("&Analysis")
        action(m, "&Analyse logs", lambda: self._show_dock("Analysis"), "Ctrl+Shift+A")
        action(m, "Add log &file...", self._analysis_files_dialog)
        action(m, "Add log f&older...", self._analysis_folder_dialog)
        m = self.menuBar().addMenu("D&emo")
        m.addAction(self.demo_action)
        m = self.menuBar().addMenu("&View")
        action(m, "&Pause charts", lambda: self.charts.set_paused(not self.charts.settings.paused), "Ctrl+Space")
        for dock in self.docks.values():
            m.addAction(dock.toggleViewAction())
        action(m, "Reset layout", self.reset_layout)
        m = self.menuBar().addMenu("&Help")
        action(m, "&About", lambda: QMessageBox.about(
            self, "Ground station", "Ground station for hybrid-flexure-bearing testbeds.\n"
            "Esc aborts: both motors to zero, drives off, mode IDLE, and the function "
            "generator's outputs off."))

    # ------------------------------------------------------------------ demo
    def _demo_bar(self) -> None:
        self.demo_action = QAction(DEMO_TITLE, self)
        self.demo_action.setObjectName("demo_action")
        self.demo_action.triggered.connect(self.start_demo)
        self.demo_toolbar = QToolBar("Demo")
        self.demo_toolbar.setObjectName("demo_bar")
        self.demo_toolbar.addAction(self.demo_action)
        self.demo_button = self.demo_toolbar.widgetForAction(self.demo_action)
        self.demo_button.setStyleSheet("QToolButton:enabled { background:#2e7d32; color:white; "
                                       "font-weight:bold; padding:3px 8px; border-radius:4px; }")
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, self.demo_toolbar)
        # the demo's state in a word, beside the link's (the details are its tooltip and
        # the status bar's message): the top bar keeps its room for the link's health
        self.demo_status = QLabel("")
        self.statusBar().addPermanentWidget(self.demo_status)
        self.demo.sig_state.connect(self._demo_state)
        self.demo.sig_available.connect(self._demo_available)
        self.demo.update_availability()

    def start_demo(self) -> None:
        reason = self.demo.start()
        if reason:
            self.statusBar().showMessage(f"Demo not started: {reason}", 8000)

    def _demo_available(self, can_start: bool, reason: str) -> None:
        offered = self.demo.offered()
        self.demo_action.setVisible(offered)
        self.demo_status.setVisible(offered)
        self.demo_action.setEnabled(can_start)
        plan = plan_for(self.session.testbed)
        what = plan.describe() if plan is not None else ""
        tip = f"On the simulated testbed: {what}" if can_start else f"Not now: {reason}"
        self.demo_action.setToolTip(tip)
        self.demo_action.setStatusTip(tip)

    def _demo_state(self, state: str, text: str) -> None:
        if state == "refused":
            return
        colour = {"completed": "#2e7d32", "aborted": "#c62828", "failed": "#c62828"}.get(state, "")
        self.demo_status.setStyleSheet(f"color:{colour}; font-weight:bold;" if colour else "")
        self.demo_status.setText(f"Demo {state}")
        self.demo_status.setToolTip(text)
        if state == "uploading":
            self._show_dock("Parameters")
        elif state == "playing":
            self._show_dock("Profiles")
        self.statusBar().showMessage(f"Demo {state}: {text}", 8000)

    # ------------------------------------------------------------------ actions
    def _load_design(self) -> None:
        self.docks["Parameters"].show()
        self.docks["Parameters"].raise_()
        self.parameters.load_design_dialog()

    def _show_dock(self, name: str) -> None:
        self.docks[name].show()
        self.docks[name].raise_()

    def _play_profile_dialog(self) -> None:
        self._show_dock("Profiles")
        self.profiles.load_dialog()

    def _run_campaign_dialog(self) -> None:
        self._show_dock("Campaign")
        self.campaign.load_dialog()

    def _analysis_files_dialog(self) -> None:
        self._show_dock("Analysis")
        self.analysis.files_dialog()

    def _analysis_folder_dialog(self) -> None:
        self._show_dock("Analysis")
        self.analysis.folder_dialog()

    def open_workbench_on_testbed(self, path: str) -> bool:
        """The design workbench (the Parameters dock's window) on a testbed file the
        Analysis dock identified: the dock's design, or a shipped one of the rig's kind,
        on that file beside the same design on the testbed it names."""
        workbench = self.parameters.open_workbench()
        return workbench.open_on_testbed(path, self.parameters.design)

    def _campaign_running(self, running: bool) -> None:
        for button in self.commands.findChildren(QPushButton):
            if button is not self.commands.abort_button:
                button.setEnabled(not running)
        for w in (self.commands.mode, self.commands.friction, self.parameters, self.generator):
            w.setEnabled(not running)
        if running:
            self._show_dock("Campaign")

    def abort(self) -> None:
        # the device's ABORT, the generator's outputs off, a running campaign stopped
        # (its Testbed.abort) and a playing profile's wait ended; the demo starts nothing more
        self.demo.cancel()
        self.session.abort()
        self.statusBar().showMessage("ABORT sent; function generator outputs off", 3000)

    def open_log_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open log", "", "Logs (*.h5)")
        if path:
            self.session.open_log(path)

    def _read_only(self, reason: str | None) -> None:
        """Watch mode: every command control off with the reason as its tooltip; the
        Abort button, Esc and the ABORT menu stay (ABORT goes straight to the device)."""
        self.commands.set_read_only(reason)
        for w in (self.parameters, self.generator, self.profiles, self.campaign):
            w.setEnabled(reason is None)
            w.setToolTip(reason or "")
        self.commands.abort_button.setToolTip(
            "ABORT straight to the device (any host may send it, no session needed)"
            if reason is not None else "")

    def _source_changed(self, kind: str, text: str) -> None:
        from ..fanout.endpoints import read_only_message

        self._read_only(read_only_message(text) if kind == "watch" else None)
        if kind == "watch":
            self.setWindowTitle(f"Ground station - read-only console watching {text}")
            return
        self.replay_toolbar.setVisible(kind == "replay")
        if kind == "replay":
            self.setWindowTitle(f"Ground station - replay of {Path(text).name}")
            self.connection.lamp.setStyleSheet("background:#1565c0; border-radius:7px; min-width:14px; "
                                               "max-width:14px; min-height:14px; max-height:14px;")
        else:
            self.setWindowTitle("Ground station - hybrid flexure bearing testbed")

    def dragEnterEvent(self, event) -> None:
        if any(u.toLocalFile().endswith(".h5") for u in event.mimeData().urls()):
            event.acceptProposedAction()

    def dropEvent(self, event) -> None:
        for url in event.mimeData().urls():
            if url.toLocalFile().endswith(".h5"):
                self.session.open_log(url.toLocalFile())
                break

    # ------------------------------------------------------------------ persistence
    def restore(self) -> None:
        geometry = self.settings.value("geometry")
        if isinstance(geometry, QByteArray):
            self.restoreGeometry(geometry)
        else:
            self.resize(1600, 950)
        state = self.settings.value("window_state")
        if isinstance(state, QByteArray):
            self.restoreState(state)
        charts = self.settings.value("charts")
        if isinstance(charts, str):
            try:
                state = json.loads(charts)
            except ValueError:
                state = None                              # damaged settings: defaults
            if isinstance(state, dict):
                self.charts.settings.restore_state(state)

    def save(self) -> None:
        self.settings.setValue("geometry", self.saveGeometry())
        self.settings.setValue("window_state", self.saveState())
        # as JSON text: QSettings would hand numbers and booleans back as strings
        self.settings.setValue("charts", json.dumps(self.charts.settings.state()))

    def reset_layout(self) -> None:
        self.charts.set_layout(DEFAULT_LAYOUT)
        for dock in self.docks.values():
            dock.setVisible(True)

    def closeEvent(self, event) -> None:
        self.save()
        self.analysis.shutdown()
        self.session.shutdown()
        super().closeEvent(event)
