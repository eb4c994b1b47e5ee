"""The generator panel's instrument side: which generator (the VISA resources pyvisa
finds and the simulator's generator, or an address typed in), connect, channel, the
basic wave with the allowed range of every field (instrument and testbed), Apply, and
the output button - whose state is what the instrument last reported, never what was
clicked.

`ChannelEditor` is owned by `GeneratorPanel` (generator/panel.py), which places its two
boxes and gives it the session (the GeneratorController, and the link whose simulator
brings a generator), its status line (`say`) and its busy line (`show_busy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

from PySide6.QtCore import QObject, Qt
from PySide6.QtWidgets import (QComboBox, QDoubleSpinBox, QGridLayout, QGroupBox, QHBoxLayout,
                               QLabel, QPushButton, QVBoxLayout)

from ...core.kinds import LinkState
from ...core.errors import GroundStationError
from ...instruments import spec4050 as spec
from .limits_text import limit_texts, limits_source
from .records import SIMULATOR, GeneratorState, ResourceChoice
from .styles import SMALL_STYLE, WARN_STYLE, _spin

if TYPE_CHECKING:
    from ..session.session import Session

FIELD_BAD = "QDoubleSpinBox { background:#ffcdd2; }"
OUTPUT_ON_STYLE = ("QPushButton { background:#c62828; color:white; font-weight:bold; "
                   "padding:6px; border-radius:4px; }")
OUTPUT_OFF_STYLE = ("QPushButton { background:#424242; color:#e0e0e0; font-weight:bold; "
                    "padding:6px; border-radius:4px; } QPushButton:disabled { color:#808080; }")


class ChannelEditor(QObject):
    """Builds the "Instrument" and "Basic wave" boxes and follows the controller's
    resources, connection, read-back and refusals."""

    def __init__(self, session: Session, say: Callable[..., None],
                 show_busy: Callable[[str], None], parent: QObject | None = None):
        super().__init__(parent)
        self.gen = session.generator
        self._say = say
        self._show_busy = show_busy
        self.state: GeneratorState | None = None   # what the instrument last reported
        self._edited = False              # wave fields edited since the last read-back
        self._filling = False             # the read-back is being put into the fields
        self.instrument_box = self._instrument_box()
        self.wave_box = self._wave_box()
        g = self.gen
        g.sig_resources.connect(self._on_resources)
        g.sig_opened.connect(self._on_opened)
        g.sig_closed.connect(self._on_closed)
        g.sig_state.connect(self._on_state)
        g.sig_refused.connect(self._on_refused)
        session.sig_link_state.connect(self._on_link)
        self._show_open(False)
        self._update_ranges()

    def _instrument_box(self) -> QGroupBox:
        box = QGroupBox("Instrument")
        lay = QVBoxLayout(box)
        lay.setSpacing(3)
        pick = QHBoxLayout()
        self.resource = QComboBox()
        self.resource.setEditable(True)          # an address may also be typed
        self.resource.setMinimumContentsLength(22)
        self.resource.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.resource.setToolTip("VISA resource: the simulator's generator, what pyvisa finds, "
                                 "or an address typed in (USB0::...::INSTR, TCPIP0::host::port::SOCKET)")
        self.refresh_button = QPushButton("↻")
        self.refresh_button.setToolTip("list the VISA resources again")
        self.refresh_button.setFixedWidth(28)
        pick.addWidget(self.resource, 1)
        pick.addWidget(self.refresh_button)
        lay.addLayout(pick)
        conn = QHBoxLayout()
        self.connect_button = QPushButton("Connect")
        self.channel_combo = QComboBox()
        self.channel_combo.addItems(["1", "2"])
        self.channel_combo.setToolTip("the channel wired to the base-stage amplifier (the simulator: 1)")
        conn.addWidget(self.connect_button, 1)
        conn.addWidget(QLabel("Channel"))
        conn.addWidget(self.channel_combo)
        lay.addLayout(conn)
        self.identity = QLabel("not connected")
        self.identity.setStyleSheet(SMALL_STYLE)
        self.identity.setWordWrap(True)
        lay.addWidget(self.identity)
        self.output_button = QPushButton("Output (not connected)")
        self.output_button.setToolTip("the output state the instrument reports; click to ask for "
                                      "the other (Esc switches it off from anywhere)")
        self.output_button.setStyleSheet(OUTPUT_OFF_STYLE)
        self.output_button.setMinimumHeight(32)
        lay.addWidget(self.output_button)
        self.readback = QLabel("")
        self.readback.setWordWrap(True)
        self.readback.setStyleSheet(SMALL_STYLE)
        self.readback.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        lay.addWidget(self.readback)
        lay.addStretch(1)
        box.setFixedWidth(250)

        self.refresh_button.clicked.connect(self.refresh_resources)
        self.connect_button.clicked.connect(self._toggle_connection)
        self.output_button.clicked.connect(self._toggle_output)
        self.channel_combo.currentIndexChanged.connect(lambda _: self._channel_changed())
        return box

    def _wave_box(self) -> QGroupBox:
        box = QGroupBox("Basic wave")
        lay = QVBoxLayout(box)
        lay.setSpacing(3)
        top = QHBoxLayout()
        self.waveform = QComboBox()
        self.waveform.addItems(list(spec.WAVEFORMS))
        self.load = QComboBox()
        self.load.addItem("high-Z (amplifier)", "HZ")
        self.load.addItem("50 ohm", "50")
        self.load.setToolTip("the load the amplitude refers to; the stage amplifier's input is "
                             "high impedance (a 50 ohm setting puts twice the volts on it)")
        top.addWidget(self.waveform)
        top.addWidget(QLabel("Load"))
        top.addWidget(self.load, 1)
        lay.addLayout(top)
        self.frequency = _spin(" Hz", 5, 0.0, 1e9, 1.0)
        self.amplitude = _spin(" Vpp", 4, 0.0, 1000.0, 0.1)
        self.offset = _spin(" V", 4, -1000.0, 1000.0, 0.0)
        self.phase = _spin(" °", 2, -1000.0, 1000.0, 0.0)
        self.fields = {"frequency": self.frequency, "amplitude": self.amplitude,
                       "offset": self.offset, "phase": self.phase}
        self.ranges = {name: QLabel("") for name in self.fields}
        grid = QGridLayout()
        grid.setHorizontalSpacing(6)
        grid.setVerticalSpacing(2)
        for i, (name, spin) in enumerate(self.fields.items()):
            grid.addWidget(QLabel(name.capitalize()), i, 0)
            grid.addWidget(spin, i, 1)
            label = self.ranges[name]
            label.setStyleSheet(SMALL_STYLE)
            label.setWordWrap(True)
            label.setFixedWidth(180)
            grid.addWidget(label, i, 2)
        lay.addLayout(grid)
        bottom = QHBoxLayout()
        self.apply_button = QPushButton("Apply")
        self.apply_button.setToolTip("check against the limits, send, read back")
        self.refusal = QLabel("")
        self.refusal.setWordWrap(True)
        self.refusal.setStyleSheet(WARN_STYLE + " font-size:8pt;")
        bottom.addWidget(self.apply_button)
        bottom.addWidget(self.refusal, 1)
        lay.addLayout(bottom)
        lay.addStretch(1)
        box.setFixedWidth(405)

        self.apply_button.clicked.connect(self.apply)
        self.waveform.currentIndexChanged.connect(lambda _: self._wave_edited())
        self.load.currentIndexChanged.connect(lambda _: self._wave_edited())
        for spin in self.fields.values():
            spin.valueChanged.connect(lambda _=None, s=spin: self._wave_edited(s))
        return box

    # ------------------------------------------------------------------ resources and connection
    def _show_open(self, is_open: bool) -> None:
        self.connect_button.setText("Disconnect" if is_open else "Connect")
        for w in (self.apply_button, self.output_button):
            w.setEnabled(is_open)

    def refresh_resources(self) -> None:
        self.refresh_button.setEnabled(False)
        self._show_busy("listing VISA resources…")
        self.gen.refresh_resources()

    def _on_resources(self, choices: list[ResourceChoice], notes) -> None:
        # the simulator's address changes with every simulator started: follow the entry
        was_sim = self.resource.currentText().startswith(SIMULATOR)
        current = self.selected_resource()
        self.resource.blockSignals(True)
        self.resource.clear()
        for c in choices:
            self.resource.addItem(c.label, c.resource)
            if c.simulated:
                self.resource.setItemData(self.resource.count() - 1,
                                          "the simulated testbed's generator (drives its base stage)",
                                          Qt.ItemDataRole.ToolTipRole)
        # keep what was picked (or typed); else the open generator; else the simulator
        if was_sim:
            index = next((i for i, c in enumerate(choices) if c.simulated), -1)
        else:
            index = self.resource.findData(current) if current else -1
        if index < 0 and self.gen.is_open:
            index = self.resource.findData(self.gen.resource)
        if index < 0 and current and not was_sim:
            self.resource.setEditText(current)
        elif index < 0 and choices:
            index = 0                     # the simulator comes first when there is one
        if index >= 0:
            self.resource.setCurrentIndex(index)
        self.resource.lineEdit().setCursorPosition(0)     # the start names the resource
        self.resource.blockSignals(False)
        self.refresh_button.setEnabled(True)
        self._show_busy("")
        self.resource.setToolTip("VISA resources found: " + (", ".join(c.resource for c in choices)
                                                              or "none")
                                 + ("\n" + "\n".join(notes) if notes else ""))

    def selected_resource(self) -> str:
        """The picked resource's address (or the text typed in)."""
        data = self.resource.currentData()
        text = self.resource.currentText().strip()
        if data and self.resource.itemText(self.resource.currentIndex()) == text:
            return str(data)
        return text

    def select_simulator(self) -> bool:
        index = next((i for i in range(self.resource.count())
                      if self.resource.itemText(i).startswith(SIMULATOR)), -1)
        if index >= 0:
            self.resource.setCurrentIndex(index)
        return index >= 0

    def _toggle_connection(self) -> None:
        if self.gen.is_open:
            self.gen.close()
            return
        resource = self.selected_resource()
        if not resource:
            self._say("pick a resource first (↻ lists them)", bad=True)
            return
        self._say(f"opening {resource}…")
        self.gen.open(resource)

    def _on_opened(self, resource: str, identity: str) -> None:
        limits = self.gen.limits
        self.identity.setText(identity.split(" (")[0] + " connected")
        self.identity.setToolTip(f"{identity}\n{resource}")
        self._show_open(True)
        self._edited = False
        self._say(f"connected to {identity}; testbed limits: {limits.max_amplitude_vpp:g} Vpp, "
                  f"±{limits.max_offset_v:g} V offset ({limits.source})" if limits else
                  f"connected to {identity}")
        self._update_ranges()

    def _on_closed(self, resource: str) -> None:
        self.identity.setText("not connected")
        self.readback.setText("")
        self.refusal.setText("")
        self.state = None
        self._show_open(False)
        self._show_output(None)
        self._say(f"{resource} closed (outputs off)")

    def _on_link(self, state: str, _message: str) -> None:
        if state in (LinkState.UP, LinkState.CLOSED):
            self.refresh_resources()      # the simulator's generator comes and goes with it

    # ------------------------------------------------------------------ the basic wave
    def channel_number(self) -> int:
        """The generator channel wired to the base stage (1 or 2), as picked."""
        return int(self.channel_combo.currentText())

    def expect_readback(self) -> None:
        """Something was sent: the read-back that follows fills the wave fields."""
        self._edited = False

    def _channel_changed(self) -> None:
        if self.gen.is_open:
            self._edited = False
            self.gen.refresh(self.channel_number())

    def _wave_edited(self, field: QDoubleSpinBox | None = None) -> None:
        if self._filling:
            return
        self._edited = True
        if field is not None:
            field.setStyleSheet("")
        self._update_ranges()

    def _update_ranges(self) -> None:
        wave = self.waveform.currentText()
        used = spec.WAVE_PARAMETERS.get(wave, ())
        for name, key in (("frequency", "FRQ"), ("amplitude", "AMP"), ("offset", "OFST"),
                          ("phase", "PHSE")):
            self.fields[name].setEnabled(key in used)
        limits = self.gen.limits
        if limits is None:
            try:
                limits = self.gen.safety_limits()
            except GroundStationError:
                limits = None
        texts = limit_texts(wave, self.load.currentData(), limits)
        for name, label in self.ranges.items():
            label.setText(texts[name])
            label.setToolTip(f"{texts[name]}\n(testbed limits from {limits.source})" if limits
                             else texts[name])
        self.wave_box.setTitle(f"Basic wave - limits: {spec.MODEL}; testbed "
                               f"{limits_source(limits)}")

    def apply(self) -> str | None:
        """Send the fields (checked first: a refusal names the limit and sends nothing)."""
        for spin in self.fields.values():
            spin.setStyleSheet("")
        reason = self.gen.apply(self.channel_number(), waveform=self.waveform.currentText(),
                                frequency_hz=self.frequency.value(),
                                amplitude_vpp=self.amplitude.value(), offset_v=self.offset.value(),
                                phase_deg=self.phase.value(), load=self.load.currentData())
        if reason is None:
            self.expect_readback()
            self._say("sending…")
        return reason

    def _on_refused(self, setting: str, text: str) -> None:
        spin = self.fields.get(setting)
        if spin is None and setting == "envelope":
            spin = self.offset
        if spin is not None:
            spin.setStyleSheet(FIELD_BAD)
        self._say(f"refused, nothing sent: {text.replace('; nothing was sent', '')}", bad=True)

    def _on_state(self, state: GeneratorState) -> None:
        if state.channel != self.channel_number():
            return
        self.state = state
        self.readback.setText(f"instrument reports: {state.text()}")
        self.refusal.setText(f"output ON would be refused: {state.refusal}" if state.refusal else "")
        self._show_output(state.output.on)
        if not self._edited:
            self._fill(state)
        self._update_ranges()

    def _fill(self, state: GeneratorState) -> None:
        self._filling = True
        try:
            w = state.wave
            if self.waveform.findText(w.waveform) >= 0:
                self.waveform.setCurrentText(w.waveform)
            for spin, value in ((self.frequency, w.frequency_hz), (self.amplitude, w.amplitude_vpp),
                                (self.offset, w.offset_v), (self.phase, w.phase_deg)):
                if value is not None:
                    spin.setValue(value)
                    spin.setStyleSheet("")
            index = self.load.findData(state.output.load)
            if index >= 0:
                self.load.setCurrentIndex(index)
        finally:
            self._filling = False

    # ------------------------------------------------------------------ output
    def _show_output(self, on: bool | None) -> None:
        """The button shows the reported state (None: unknown/closed)."""
        if on:
            self.output_button.setText("OUTPUT ON - click to switch off")
            self.output_button.setStyleSheet(OUTPUT_ON_STYLE)
        else:
            self.output_button.setText("Output off - click to switch on" if on is not None
                                       else "Output (not connected)")
            self.output_button.setStyleSheet(OUTPUT_OFF_STYLE)

    @property
    def output_reported_on(self) -> bool | None:
        return None if self.state is None else self.state.output.on

    def _toggle_output(self) -> None:
        self.set_output(not bool(self.output_reported_on))

    def set_output(self, on: bool) -> str | None:
        """Ask for the output on/off; the button follows the read-back, not this call."""
        return self.gen.set_output(self.channel_number(), on)
