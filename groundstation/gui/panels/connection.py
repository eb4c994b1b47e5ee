"""The connection bar at the top of the window: what is connected, in words; the
choosers of the next connection (simulated testbed, TCP address, serial port) and
Connect; the link's lamp and health.  It shows the Session's state and calls its
methods; it does no I/O itself."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QAction
from PySide6.QtWidgets import QComboBox, QLabel, QLineEdit, QPushButton, QToolBar, QWidget

from ...core.errors import GroundStationError
from ...core.kinds import SIMULATED_DEVICE, LinkState
from ...link import format_snapshot
from ...link.address import parse_address
from ..common.steady_label import SteadyLabel
from ..session.session import Session
from ..session.source import source_text

#: the link lamp's colour per link state
LAMP = {LinkState.UP: "#2e7d32", LinkState.CONNECTING: "#f9a825", LinkState.LOST: "#c62828",
        LinkState.FAILED: "#c62828", LinkState.ENDED: "#c62828", LinkState.CLOSED: "#616161"}
#: the link states the health line shows in red (ended: another station took the session)
#: the most the source's words take in the bar (pixels; longer ones are elided)
SOURCE_WIDTH = 640
#: the lamp's colour while a log is replayed (no link)
LAMP_REPLAY = "#1565c0"
LINK_FAULTS = (LinkState.LOST, LinkState.FAILED, LinkState.ENDED)
def lamp_style(colour: str) -> str:
    return f"background:{colour}; border-radius:7px; min-width:14px; max-width:14px; min-height:14px; max-height:14px;"


class ConnectionBar(QToolBar):
    """Source (simulated testbed, TCP/UDP address, serial port), connect, link health."""

    def __init__(self, session: Session, testbeds: list[str], parent=None):
        super().__init__("Connection", parent)
        self.setObjectName("connection_bar")          # the saved window state's name for it
        self.session = session
        self.kind = QComboBox()
        self.kind.addItems(["Simulated testbed", "Ethernet (tcp://host:port)", "Serial port"])
        self.testbed = QComboBox()
        # sized to a typical file name, not the longest one: a long variant's name
        # (inertial_2dof_appendix_inertia.toml) must not widen the whole window
        self.testbed.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.testbed.setMinimumContentsLength(22)
        self.testbed.currentTextChanged.connect(self.testbed.setToolTip)   # the whole name
        self.testbed.addItems(testbeds)
        self._show_testbed(None)                 # the simulator's default, until one is chosen
        self.address = QLineEdit("tcp://127.0.0.1:5020")
        self.serial = QComboBox()
        self.serial.setEditable(True)
        self.baud = QComboBox()
        self.baud.setEditable(True)
        self.baud.addItems(["2000000", "3000000", "921600", "115200"])
        self.connect_button = QPushButton("Connect")
        self.lamp = QLabel()
        self.lamp.setStyleSheet(lamp_style(LAMP[LinkState.CLOSED]))
        # The text changes twice a second: a fixed width (the usual figures fit; the
        # tooltip has them all), so it never sets the window's minimum width and a new
        # text does not lay the window out again.
        self.health = SteadyLabel("not connected", width=self.fontMetrics().horizontalAdvance(
            "12000 frames/s · dropped 000000 · CRC errors 0000 · latency 000.0 ms") + 12)
        # what is connected, in words: the choosers beside it say what Connect opens next,
        # and are shown only where a connection can be made (not in a replay or a console)
        self.source = QLabel(source_text("none", ""))
        self.source.setStyleSheet("font-weight:bold;")
        self.source.setObjectName("source_label")
        self._source: tuple[str, str] = ("none", "")
        self.choose_label = QLabel("Connect to")
        # each widget a toolbar item: what does not fit a narrow screen goes into the
        # toolbar's extension menu instead of widening the window past the screen, the
        # choosers first (what is connected and its health come first); a toolbar item
        # is shown and hidden through its action
        self._items: dict[QWidget, QAction] = {}
        for w in (self.source, self.lamp, self.health):
            self._items[w] = self.addWidget(w)
        self.addSeparator()
        for w in (self.choose_label, self.kind, self.testbed, self.address, self.serial, self.baud,
                  self.connect_button):
            self._items[w] = self.addWidget(w)
        self.kind.currentIndexChanged.connect(self._kind_changed)
        self.connect_button.clicked.connect(self._toggle)
        self._kind_changed()
        session.sig_link_state.connect(self._link_state)
        session.sig_source.connect(self.show_source)
        self._timer = QTimer(self)
        self._timer.timeout.connect(self._update_health)
        self._timer.start(500)

    def _kind_changed(self) -> None:
        k = self.kind.currentIndex()
        choosing = self._source[0] in ("live", "none")
        self._show(self.testbed, choosing and k == 0)
        self._show(self.address, choosing and k == 1)
        self._show(self.serial, choosing and k == 2)
        self._show(self.baud, choosing and k == 2)
        if k == 2 and not self.serial.count():
            from serial.tools import list_ports   # lists ports; opens nothing
            self.serial.addItems([p.device for p in list_ports.comports()])

    def _toggle(self) -> None:
        if self.session.client is not None or self.connect_button.text() == "Disconnect":
            self.session.disconnect_link()
            self.connect_button.setText("Connect")
            return
        k = self.kind.currentIndex()
        if k == 0:
            self.session.connect_sim(self.testbed.currentText() or None)
        elif k == 1:
            self.session.connect_address(self.address.text().strip())
        else:
            self.session.connect_address(f"serial://{self.serial.currentText()}?baud={self.baud.currentText()}")
        self.connect_button.setText("Disconnect")

    def show_source(self, kind: str, text: str) -> None:
        """The Session's source changed: say what it is, set the choosers to it (a live
        link), or hide them with the connect button (a replay, a read-only console:
        File ▸ Close replay or Device ▸ Disconnect leaves them)."""
        self._source = (kind, text)
        choosing = kind in ("live", "none")
        for w in (self.choose_label, self.kind, self.connect_button):
            self._show(w, choosing)
        if kind == "live":
            self._choose(self.session.address)
        self._kind_changed()
        self._say_source()

    def _say_source(self) -> None:
        kind, text = self._source
        s = self.session
        device = (getattr(s.client, "device", None) or {}) if kind == "watch" else {}
        words = source_text(kind, text, simulated=s.address == SIMULATED_DEVICE, testbed=s.testbed,
                            description=s.device_description, watched_device=device.get("address", ""))
        # a long description (a rig's free text) elided: the whole is the tooltip
        shown = self.source.fontMetrics().elidedText(words, Qt.TextElideMode.ElideRight, SOURCE_WIDTH)
        if shown != self.source.text():
            self.source.setText(shown)
            self.source.setToolTip(text if kind == "replay" else words)

    def _show(self, widget: QWidget, on: bool) -> None:
        self._items[widget].setVisible(on)

    def offers(self, widget: QWidget) -> bool:
        """Is `widget` in the bar (in view, or in its extension menu on a narrow screen)?"""
        return self._items[widget].isVisible()

    def _choose(self, address: str) -> None:
        """The choosers set to the address the link was opened on (the CLI, a script or
        the Device menu may have opened it, not the choosers)."""
        if address == SIMULATED_DEVICE:
            self.kind.setCurrentIndex(0)
            self._show_testbed(self.session.testbed)
            return
        try:
            addr = parse_address(address)
        except GroundStationError:
            return
        if addr.kind == "serial":
            self.kind.setCurrentIndex(2)
            self.serial.setCurrentText(addr.serial_port)
            self.baud.setCurrentText(str(addr.baud))
        else:
            self.kind.setCurrentIndex(1)
            self.address.setText(address)

    def _show_testbed(self, path: str | None) -> None:
        """Select the testbed the simulator runs (a script or the CLI may have chosen it),
        so the bar never names another one."""
        from ...plant.testbed import DEFAULT_TESTBED
        name = Path(path).name if path else DEFAULT_TESTBED.name
        for i in range(self.testbed.count()):
            if Path(self.testbed.itemText(i)).name == name:
                self.testbed.setCurrentIndex(i)
                return

    def _link_state(self, state: str, message: str) -> None:
        if state == LinkState.CONNECTING and self.session.address == SIMULATED_DEVICE:
            self._show_testbed(self.session.testbed)
        self.connect_button.setText("Connect" if state == LinkState.CLOSED else "Disconnect")
        self.lamp.setStyleSheet(lamp_style(LAMP.get(state, "#616161")))
        self.lamp.setToolTip(f"{state}: {message}")
        if state in LINK_FAULTS:
            self.health.setText(f"LINK {state.upper()}: {message}")
            self.health.setToolTip(f"LINK {state.upper()}: {message}")
            self.health.setStyleSheet("color:#c62828; font-weight:bold;")
        elif state == LinkState.CLOSED:
            self.health.setText("not connected")
            self.health.setStyleSheet("")

    def _update_health(self) -> None:
        if self._source[0] == "watch":          # the watched device, once its hello told
            self._say_source()
        src = self.session.source
        if src is None or getattr(src, "link_state", "") != LinkState.UP:
            return
        snap = src.stats.snapshot()
        if self.health.styleSheet():
            self.health.setStyleSheet("")
        self.health.setText(_compact_health(snap))
        self.health.setToolTip(format_snapshot(snap).replace(" | ", "\n"))


def _compact_health(snap) -> str:
    """The link's health in a few words for the bar; the full per-packet line is the
    tooltip.  Errors are named only when there are some, so a healthy link reads short."""
    hr = snap.packets.get("HIGH_RATE")
    dropped = sum(ps.dropped for name, ps in snap.packets.items() if name != "RESPONSE")
    parts = [f"{hr.rate_hz:.0f} frames/s" if hr is not None else "no HIGH_RATE yet",
             f"dropped {dropped}"]
    f = snap.framing
    crc = f.get("crc_errors", 0)
    parts.append(f"CRC errors {crc}")
    other = f.get("resyncs", 0) + f.get("version_errors", 0)
    if other:
        parts.append(f"resyncs {f.get('resyncs', 0)} · version errors {f.get('version_errors', 0)}")
    if snap.latency_ms_mean is not None:
        parts.append(f"latency {snap.latency_ms_mean:.1f} ms")
    return " · ".join(parts)
