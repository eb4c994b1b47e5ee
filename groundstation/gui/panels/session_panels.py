"""The operator's panels: status and limits, commands with Abort, recording (the
connection bar: panels/connection.py; the event log and the replay bar: panels/logs.py).  They show models and call
Session methods; they do no I/O themselves.
"""

from __future__ import annotations

import time
from datetime import datetime
from PySide6.QtCore import QSignalBlocker, QTimer, Signal
from PySide6.QtGui import QColor, QFont
from PySide6.QtWidgets import (QAbstractScrollArea, QCheckBox, QComboBox, QFormLayout, QGridLayout, QHBoxLayout,
                               QHeaderView, QLabel, QLineEdit, QListWidget, QListWidgetItem,
                               QMessageBox, QPushButton, QTableWidget,
                               QTableWidgetItem, QVBoxLayout, QWidget)

from ...live.limits import GREEN, RED, YELLOW
from ..common.steady_label import SteadyLabel
from ..session.session import Session

#: commands the station sends by itself, many at a time (a table read-back is one
#: PARAM_READ per block, an upload one *_WRITE per block): a completion is counted on one
#: line, a failure has its own (the upload's BEGIN and COMMIT keep theirs).  The block
#: writes are matched by their suffix: the table commands' names appear only where they
#: are sent (tests/station/test_upload_gate.py holds the package to that)
ROUTINE_COMMANDS = {"PARAM_READ": "read-backs", "GET_INFO": "device queries"}
BLOCK_WRITE_SUFFIX = "_WRITE"


def routine_kind(name: str) -> str | None:
    """What a completed routine command counts as on its folded line, or None."""
    if name.endswith(BLOCK_WRITE_SUFFIX):
        return "blocks written"
    return ROUTINE_COMMANDS.get(name)
STATE_COLOURS = {GREEN: QColor("#2e7d32"), YELLOW: QColor("#f9a825"), RED: QColor("#c62828")}


class _LimitTable(QTableWidget):
    """The limit table: its size follows its contents (the dock shows every channel's
    whole name), but a new value, worst value or state colour - ten times a second -
    only repaints it.  QAbstractItemView asks the window to lay itself out again on every
    data change when the size follows the contents; only the names (column 0) can
    change that size, and the other columns have fixed widths."""

    def dataChanged(self, top_left, bottom_right, roles=()):
        if top_left.column() >= 1:
            self.viewport().update(self.visualRect(top_left).united(self.visualRect(bottom_right)))
            return
        super().dataChanged(top_left, bottom_right, roles)


class StatusPanel(QWidget):
    """Mode, arm state, saturation, faults, temperatures, watchdog, parameter table CRC,
    and the limit table (latched until acknowledged)."""

    def __init__(self, session: Session, parent=None):
        super().__init__(parent)
        self.session = session
        self.d = session.d
        lay = QVBoxLayout(self)
        grid = QGridLayout()
        self.fields: dict[str, QLabel] = {}
        self._shown: dict = {}     # what each label (and limit row colour) shows: (text, colour)
        names = ["mode", "armed", "coarse_saturated", "fine_saturated", "fault", "fault_code",
                 "watchdog", "temp_motor_coarse", "temp_flexure", "param_table_crc"]
        for i, name in enumerate(names):
            grid.addWidget(QLabel(name.replace("_", " ")), i, 0)
            lab = SteadyLabel("-")           # temperatures change ten times a second
            lab.setFont(QFont("monospace"))
            grid.addWidget(lab, i, 1)
            self.fields[name] = lab
        lay.addLayout(grid)
        self.crc_warning = QLabel("")
        self.crc_warning.setWordWrap(True)
        lay.addWidget(self.crc_warning)
        self.limits = _LimitTable(0, 4)
        self.limits.setHorizontalHeaderLabels(["channel", "value", "latched", "worst"])
        # the channel's full name, always: its column is as wide as the longest name (four
        # equal stretched columns cut "HOUSEKEEPING.temp_electronics" to "HOUSE…"); the
        # numbers get fixed widths that fit them, and a narrow dock scrolls sideways
        header = self.limits.horizontalHeader()
        header.setSectionResizeMode(0, QHeaderView.ResizeMode.ResizeToContents)
        fm = self.limits.fontMetrics()
        for col, sample in ((1, "-0.0001234 rad/s"), (2, "yellow"), (3, "-0.0001234")):
            header.setSectionResizeMode(col, QHeaderView.ResizeMode.Interactive)
            self.limits.setColumnWidth(col, fm.horizontalAdvance(sample) + 16)
        header.setStretchLastSection(True)
        self.limits.setSizeAdjustPolicy(QAbstractScrollArea.SizeAdjustPolicy.AdjustToContents)
        self.limits.verticalHeader().setVisible(False)
        lay.addWidget(self.limits, 1)
        self._limit_tips = self._limit_tooltips()
        self.ack = QPushButton("Acknowledge limits")
        self.ack.clicked.connect(lambda: session.limits.acknowledge())
        lay.addWidget(self.ack)
        self._states = {v: k for k, v in self.d.packet("HIGH_RATE").item_by_name["mode"].states.items()}
        hk = self.d.packet("HOUSEKEEPING").item_by_name
        self._faults = {v: k for k, v in hk["fault_code"].states.items()}
        self._watchdog = {v: k for k, v in hk["watchdog"].states.items()}
        self._timer = QTimer(self)
        self._timer.timeout.connect(self.refresh)
        self._timer.start(100)

    def refresh(self) -> None:
        hr = self.session.store.ring("HIGH_RATE")
        hk = self.session.store.ring("HOUSEKEEPING")
        mode = hr.latest("mode")
        if mode is not None:
            self._set("mode", self._states.get(int(mode), str(mode)))
            for flag in ("armed", "coarse_saturated", "fine_saturated", "fault"):
                on = bool(hr.latest(flag))
                alarm = on and flag != "armed"
                self._set(flag, "YES" if on else "no", "#c62828" if alarm else ("#2e7d32" if on else ""))
        code = hk.latest("fault_code")
        if code is not None:
            self._set("fault_code", self._faults.get(int(code), str(code)), "#c62828" if code else "")
            wd = int(hk.latest("watchdog"))
            self._set("watchdog", self._watchdog.get(wd, str(wd)), "#c62828" if wd == 2 else "")
            self._set("temp_motor_coarse", f"{hk.latest('temp_motor_coarse'):.1f} degC")
            self._set("temp_flexure", f"{hk.latest('temp_flexure'):.1f} degC")
            crc = int(hk.latest("param_table_crc"))
            self._set("param_table_crc", f"{crc:08x}")
            want = self.session.last_uploaded_crc
            self._set_crc_warning(
                f"ACTIVE PARAMETER TABLE {crc:08x} IS NOT THE ONE LAST UPLOADED ({want:08x})"
                if want is not None and want != crc else "")
        states = self.session.limits.snapshot()
        self.limits.setRowCount(len(states))
        for row, st in enumerate(states):
            cells = [st.channel, f"{st.value:.4g} {st.units}", ("green", "yellow", "red")[st.latched],
                     f"{st.worst_value:.4g}" if st.latched else ""]
            for col, text in enumerate(cells):
                item = self.limits.item(row, col)
                if item is None:
                    item = QTableWidgetItem()
                    self.limits.setItem(row, col, item)
                if item.text() != text:
                    item.setText(text)
                    if col == 0:
                        item.setToolTip(self._limit_tips.get(text, text))
                if col == 2 and self._shown.get(("latched", row)) != (st.channel, st.latched):
                    self._shown[("latched", row)] = (st.channel, st.latched)
                    item.setBackground(STATE_COLOURS[st.latched])

    def _limit_tooltips(self) -> dict[str, str]:
        """'PACKET.item' -> its full name, description and limits, for the name's tooltip."""
        tips = {}
        for p in self.d.packets:
            for item in p.items:
                lim = item.limits
                if lim is None:
                    continue
                bands = [f"{name} outside [{band[0]:g}, {band[1]:g}] {item.units}"
                         for name, band in (("yellow", lim.yellow), ("red", lim.red))
                         if band is not None]
                tips[f"{p.name}.{item.name}"] = "\n".join(
                    [f"{p.name}.{item.name}", item.description] + bands)
        return tips

    def preferred_width(self) -> int:
        """The width that shows the whole limit table (names and numbers) unscrolled."""
        t = self.limits
        return (sum(t.columnWidth(c) for c in range(t.columnCount() - 1))
                + t.sizeHintForColumn(t.columnCount() - 1) + t.frameWidth() * 2
                + t.verticalScrollBar().sizeHint().width() + 24)

    def _set(self, name: str, text: str, colour: str = "") -> None:
        # only on a change: the panel refreshes ten times a second, and every style sheet
        # set (even the same one) re-polishes the label and lays the main window out again
        if self._shown.get(name) == (text, colour):
            return
        self._shown[name] = (text, colour)
        lab = self.fields[name]
        lab.setText(text)
        lab.setStyleSheet(f"color:{colour}; font-weight:bold;" if colour else "")

    def _set_crc_warning(self, text: str) -> None:
        if self._shown.get("crc_warning") == (text, ""):
            return
        self._shown["crc_warning"] = (text, "")
        self.crc_warning.setText(text)
        self.crc_warning.setStyleSheet(
            "background:#c62828; color:white; font-weight:bold; padding:4px;" if text else "")


class CommandPanel(QWidget):
    """Mode, arm/disarm, friction compensation, the big Abort, and command stages."""

    sig_abort = Signal()

    def __init__(self, session: Session, parent=None):
        super().__init__(parent)
        self.session = session
        lay = QVBoxLayout(self)
        self.abort_button = QPushButton("ABORT  (Esc)")
        self.abort_button.setMinimumHeight(64)
        self.abort_button.setStyleSheet("QPushButton{background:#c62828; color:white; font-size:20px; "
                                        "font-weight:bold; border-radius:6px;} QPushButton:pressed{background:#8e0000;}")
        self.abort_button.clicked.connect(self.sig_abort.emit)
        lay.addWidget(self.abort_button)
        form = QFormLayout()
        self.mode = QComboBox()
        self.mode.addItems(list(session.d.command("SET_MODE").args[0].states))
        set_mode = QPushButton("Set mode")
        set_mode.clicked.connect(lambda: self.send("SET_MODE", mode=self.mode.currentText()))
        row = QHBoxLayout()
        row.addWidget(self.mode, 1)
        row.addWidget(set_mode)
        form.addRow("Mode", row)
        arm, disarm = QPushButton("Arm"), QPushButton("Disarm")
        arm.clicked.connect(lambda: self.send("ARM"))
        disarm.clicked.connect(lambda: self.send("DISARM"))
        row2 = QHBoxLayout()
        row2.addWidget(arm)
        row2.addWidget(disarm)
        form.addRow("Drives", row2)
        self.friction = QCheckBox("friction compensation")
        self.friction.toggled.connect(lambda on: self.send("FRICTION_COMP", enable=int(on)))
        form.addRow("", self.friction)
        lay.addLayout(form)
        lay.addWidget(QLabel("Commands (newest first)"))
        self.stages = QListWidget()
        lay.addWidget(self.stages, 1)
        #: routine commands' completions so far, and the one line that counts them
        self._routine_counts: dict[str, int] = {}
        self._routine_items: dict[str, QListWidgetItem] = {}
        session.sig_command.connect(self._stage)
        #: tests answer the confirmation dialog through this (None: ask the operator)
        self.confirm_override: bool | None = None
        # The box and the checkbox show what the device reports whenever that changes -
        # whoever changed it (Set mode, a profile, a campaign, a script, ABORT).  Between
        # changes the operator's choice stays, until Set mode sends it.
        self.mode.setToolTip("follows the mode the device reports; choose one and press "
                             "Set mode to change it")
        self._mode_names = {v: k for k, v in session.d.command("SET_MODE").args[0].states.items()}
        self._device_mode: int | None = None
        self._device_friction: bool | None = None
        self._follow_timer = QTimer(self)
        self._follow_timer.timeout.connect(self.follow_device)
        self._follow_timer.start(100)

    def set_read_only(self, reason: str | None) -> None:
        """A watching console (`reason` says why) has every control off but Abort, each
        with the reason as its tooltip; None turns them back on."""
        if not hasattr(self, "_own_tips"):
            self._own_tips = {}
        controls = [w for kind in (QPushButton, QComboBox, QCheckBox) for w in self.findChildren(kind)]
        for w in controls:
            if w is self.abort_button:
                continue
            self._own_tips.setdefault(w, w.toolTip())
            w.setEnabled(reason is None)
            w.setToolTip(reason if reason is not None else self._own_tips[w])

    def follow_device(self) -> None:
        """Show the device's newest mode and friction-compensation state when they
        change.  Signals are blocked: following the device sends nothing."""
        hr = self.session.store.ring("HIGH_RATE")
        mode, comp = hr.latest("mode"), hr.latest("friction_comp_on")
        if mode is None:                   # no telemetry (yet, or a fresh store)
            self._device_mode = self._device_friction = None
            return
        if int(mode) != self._device_mode:
            self._device_mode = int(mode)
            name = self._mode_names.get(int(mode))
            if name is not None:
                with QSignalBlocker(self.mode):
                    self.mode.setCurrentText(name)
        if comp is not None and bool(comp) != self._device_friction:
            self._device_friction = bool(comp)
            with QSignalBlocker(self.friction):
                self.friction.setChecked(bool(comp))

    def send(self, name: str, **args) -> None:
        cmd = self.session.d.command(name)
        if cmd.critical and not self._confirm(name, args):
            self._stage(name, "", "CANCELLED", "not confirmed")
            return
        self.session.command(name, **args)

    def _confirm(self, name: str, args: dict) -> bool:
        if self.confirm_override is not None:
            return self.confirm_override
        text = f"Send {name}{' ' + str(args) if args else ''} to the device?"
        return QMessageBox.question(self, "Critical command", text) == QMessageBox.StandardButton.Yes

    def _stage(self, name: str, seq: str, stage: str, reason: str) -> None:
        colour = {"COMPLETED": "#2e7d32", "ACCEPTED": "#1565c0", "REJECTED": "#c62828",
                  "FAILED": "#c62828", "TIMEOUT": "#c62828", "CANCELLED": "#616161"}.get(stage, "")
        now = datetime.now()
        if routine_kind(name) is not None and stage == "COMPLETED":
            self._routine(name, now, colour)
            return
        text = f"{now:%H:%M:%S}  {name}: {stage}" + (f" ({reason})" if reason not in ("", "OK") else "")
        item = QListWidgetItem(text)
        if colour:
            item.setForeground(QColor(colour))
        self._insert(item)

    def _routine(self, name: str, now: datetime, colour: str) -> None:
        """A routine read-back that completed: counted on one line per command (a table
        read is dozens of PARAM_READs, each a line of its own drowned what the operator
        sent); the line moves to the top, as the newest."""
        count = self._routine_counts.get(name, 0) + 1
        self._routine_counts[name] = count
        item = self._routine_items.get(name)
        if item is None or self.stages.row(item) < 0:     # new, or scrolled off the end
            item = self._routine_items[name] = QListWidgetItem()
            item.setForeground(QColor(colour))
        else:
            self.stages.takeItem(self.stages.row(item))
        # the line's time is the last completion's, as every line's is its command's
        item.setText(f"{now:%H:%M:%S}  {name} ×{count} {routine_kind(name)}, last COMPLETED")
        self._insert(item)

    def _insert(self, item: QListWidgetItem) -> None:
        self.stages.insertItem(0, item)
        while self.stages.count() > 200:
            self.stages.takeItem(self.stages.count() - 1)


class RecordingPanel(QWidget):
    def __init__(self, session: Session, default_folder: str = "logs", parent=None):
        super().__init__(parent)
        self.session = session
        form = QFormLayout(self)
        self.folder = QLineEdit(default_folder)
        self.name = QLineEdit("test")
        self.notes = QLineEdit()
        self.button = QPushButton("Start recording")
        self.info = QLabel("not recording")
        self.info.setWordWrap(True)
        # time, frames and size twice a second, in a label of their own whose size is
        # fixed: a new text in the word-wrapped one laid the main window out every time
        self.figures = SteadyLabel("")
        self.figures.setFont(QFont("monospace"))
        for label, w in (("Folder", self.folder), ("Test name", self.name), ("Notes", self.notes)):
            form.addRow(label, w)
        form.addRow(self.button)
        form.addRow(self.figures)
        form.addRow(self.info)
        self.button.clicked.connect(self.toggle)
        session.sig_recording_started.connect(self._started_recording)
        session.sig_recording_stopped.connect(self._stopped_recording)
        session.sig_recording_failed.connect(self._failed_recording)
        self._started = 0.0
        self._timer = QTimer(self)
        self._timer.timeout.connect(self._update)
        self._timer.start(500)

    def toggle(self) -> None:
        if self.session.recorder is not None and self.session.recorder.state == "recording":
            self.session.stop_recording()
        else:
            self.session.start_recording(self.folder.text(), self.name.text(), self.notes.text())

    def _started_recording(self, path: str) -> None:
        self._started = time.monotonic()
        self.button.setText("Stop recording")
        self.info.setStyleSheet("color:#c62828; font-weight:bold;")
        self.info.setText(f"recording to {path}")

    def _stopped_recording(self, text: str) -> None:
        self.button.setText("Start recording")
        self.info.setStyleSheet("")
        self.info.setText(f"stopped: {text}")
        self.figures.setText("")

    def _failed_recording(self, text: str) -> None:
        self.button.setText("Start recording")
        self.info.setStyleSheet("color:#c62828; font-weight:bold;")
        self.info.setText(f"failed: {text}")
        self.figures.setText("")

    def _update(self) -> None:
        rec = self.session.recorder
        if rec is None or rec.state != "recording":
            return
        st = rec.status()
        self.figures.setText(f"REC {time.monotonic() - self._started:6.0f} s  {st.frames:9d} frames  "
                             f"{st.bytes / 1e6:7.1f} MB")
        path = f"recording to {st.path}"
        if self.info.text() != path:          # a new file of the same recording
            self.info.setText(path)
