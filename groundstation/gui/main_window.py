"""The operator's window: strip charts in the middle, panels in docks, Abort on Esc."""

from __future__ import annotations

import json

from PySide6.QtCore import QByteArray, QSettings, QSize, Qt, QTimer
from PySide6.QtGui import QAction, QGuiApplication, QKeySequence, QShortcut
from PySide6.QtWidgets import (QDockWidget, QFileDialog, QFrame, QLabel, QMainWindow, QMessageBox,
                               QPushButton, QScrollArea, QToolBar)

from ..core.kinds import LinkState
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
from .panels.connection import LAMP, LAMP_REPLAY, ConnectionBar, lamp_style
from .panels.session_panels import CommandPanel, RecordingPanel, StatusPanel
from .session.session import Session
from .charts.spectrum import SpectrumView

#: why the device's controls are off in a replay (their tooltip)
REPLAY_REASON = "a log is being replayed: nothing to command (File > Close replay, then connect)"
#: the Device menu's actions (MainWindow.device_actions) that each source switches off
SOURCE_OFF = {
    "replay": ("connect", "disconnect", "arm", "disarm", "upload", "read_back", "rollback", "play",
               "campaign"),
    "watch": ("connect", "arm", "disarm", "upload", "read_back", "rollback", "play", "campaign"),
}

#: docks whose panel is the dock's own widget (tests and the Analysis dock's callers
#: find it there), not in a scroll area: bounded by UNSCROLLED_MINIMUM instead, so a
#: small screen squeezes them rather than the window growing past the screen
UNSCROLLED_DOCKS = ("Analysis",)
UNSCROLLED_MINIMUM = (240, 120)
#: the bottom docks' height at first (the window's default size leaves the charts 500 px)
BOTTOM_DOCK_HEIGHT = 260
#: the window's size when no saved geometry says otherwise (made to fit the screen)
DEFAULT_SIZE = (1600, 950)

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
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, self.connection)
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
            dock.setWidget(_scrolled(widget) if name not in UNSCROLLED_DOCKS else widget)
            if name in UNSCROLLED_DOCKS:
                widget.setMinimumSize(*UNSCROLLED_MINIMUM)      # explicit: below its layout's
            self.addDockWidget(area, dock)
            self.docks[name] = dock
        for name in ("Spectrum", "Parameters", "Generator", "Profiles", "Campaign", "Analysis"):
            self.tabifyDockWidget(self.docks["Events"], self.docks[name])
        self.docks["Events"].raise_()
        # the limit table's channel names in full by default (a saved layout wins)
        self.status_panel.refresh()
        self.resizeDocks([self.docks["Status and limits"]],
                         [min(self.status_panel.preferred_width(), 480)], Qt.Orientation.Horizontal)
        # the docks scroll, so their panels no longer size them: the charts get the most
        # height, the command list room for a few lines
        self.resizeDocks([self.docks["Events"]], [BOTTOM_DOCK_HEIGHT], Qt.Orientation.Vertical)
        self.resizeDocks([self.docks["Commands"], self.docks["Status and limits"]], [2, 3],
                         Qt.Orientation.Vertical)

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
        # the actions a source may switch off (SOURCE_OFF): by a short name
        self.device_actions = {
            "connect": action(m, "Connect to the &simulated testbed", lambda: self.session.connect_sim(
                self.connection.testbed.currentText() or None), "F5"),
            "disconnect": action(m, "&Disconnect", self.session.disconnect_link, "Shift+F5")}
        action(m, "&ABORT", self.abort)
        self.device_actions["arm"] = action(m, "&Arm", lambda: self.commands.send("ARM"))
        self.device_actions["disarm"] = action(m, "Dis&arm", lambda: self.commands.send("DISARM"), "Ctrl+D")
        m.addSeparator()
        action(m, "&Load controller design...", self._load_design, "Ctrl+L")
        self.device_actions["upload"] = action(m, "&Upload parameter table...", self.parameters.upload, "Ctrl+U")
        self.device_actions["read_back"] = action(m, "Read &back parameter table", self.session.params_read)
        self.device_actions["rollback"] = action(m, "Roll back parameter table...", self.parameters.rollback)
        m.addSeparator()
        self.device_actions["play"] = action(m, "Play &profile...", self._play_profile_dialog, "Ctrl+P")
        self.device_actions["campaign"] = action(m, "Run &campaign...", self._run_campaign_dialog, "Ctrl+K")
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

    def _read_only(self, kind: str, reason: str | None) -> None:
        """What the source cannot do is off, with `reason` as its tooltip (None: all on).
        A read-only console: every command control and the panels that command (Abort,
        Esc and the ABORT menu stay: ABORT goes straight to the device).  A replay: the
        link's and the device's controls (the panels stay, to look at designs, profiles
        and campaigns; their Upload, Play and Run say why they are off)."""
        self.commands.set_read_only(reason)
        self.parameters.set_device_reason(reason)
        for w in (self.parameters, self.generator, self.profiles, self.campaign):
            off = kind == "watch"
            w.setEnabled(not off)
            w.setToolTip(reason if off else "")
        self.commands.abort_button.setToolTip(
            "ABORT straight to the device (any host may send it, no session needed)"
            if kind == "watch" else "")
        for name, action in self.device_actions.items():
            action.setEnabled(name not in SOURCE_OFF.get(kind, ()))

    def _source_changed(self, kind: str, text: str) -> None:
        from ..fanout.endpoints import read_only_message

        reason = (read_only_message(text) if kind == "watch" else REPLAY_REASON if kind == "replay"
                  else None)
        self._read_only(kind, reason)
        self.replay_toolbar.setVisible(kind == "replay")
        self.setWindowTitle(f"Ground station - read-only console watching {text}" if kind == "watch"
                            else f"Ground station - {self.connection.source.text()}" if kind != "none"
                            else "Ground station - hybrid flexure bearing testbed")
        if kind == "replay":
            self.connection.lamp.setStyleSheet(lamp_style(LAMP_REPLAY))
        elif kind == "none":
            self.connection.lamp.setStyleSheet(lamp_style(LAMP[LinkState.CLOSED]))

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
            self.restoreGeometry(geometry)        # saved on another (larger) screen, maybe
        else:
            self.resize(*DEFAULT_SIZE)
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
        self.fit_to_screen()

    def screen_room(self) -> QSize:
        """The most the window may be: its screen's available area (without the task
        bar and docks of the desktop) less the window's frame."""
        screen = self.screen() or QGuiApplication.primaryScreen()
        room = screen.availableGeometry().size()
        frame = self.frameGeometry().size() - self.geometry().size()   # title bar, borders
        return QSize(room.width() - max(frame.width(), 0), room.height() - max(frame.height(), 0))

    def fit_to_screen(self) -> None:
        """Shrink the window to its screen, and move it onto it.  Qt grows a window to
        its contents' minimum size when a dock or a chart is added or shown (the demo
        shows two docks): the docks scroll and the charts' area has a bounded minimum,
        so that minimum stays inside the screen, and this takes back the growth."""
        if self.isMaximized() or self.isFullScreen():
            return                                # the window manager sizes it
        room = self.screen_room()
        size = self.size().boundedTo(room)
        if size != self.size():
            self.resize(size)
        screen = self.screen() or QGuiApplication.primaryScreen()
        area, frame = screen.availableGeometry(), self.frameGeometry()
        if self.isVisible() and not area.contains(frame):
            self.move(max(area.left(), min(frame.left(), area.right() - frame.width() + 1)),
                      max(area.top(), min(frame.top(), area.bottom() - frame.height() + 1)))

    def showEvent(self, event) -> None:
        super().showEvent(event)
        # the frame (title bar) is known once the window is on the screen
        QTimer.singleShot(0, self.fit_to_screen)

    def resizeEvent(self, event) -> None:
        super().resizeEvent(event)
        room = self.screen_room()
        if event.size().width() > room.width() or event.size().height() > room.height():
            # after the layout that grew it has finished, not inside it
            QTimer.singleShot(0, self.fit_to_screen)

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


def _scrolled(panel):
    """A dock's panel in a scroll area: the dock may be smaller than the panel's minimum
    (a small screen, many docks) and scrolls instead of growing the window."""
    area = QScrollArea()
    area.setWidget(panel)
    area.setWidgetResizable(True)
    area.setFrameShape(QFrame.Shape.NoFrame)
    return area
