"""The function-generator panel: the base-motion generator from the GUI.

Left, the instrument: resource picker (the VISA resources pyvisa finds and the
simulator's generator), connect, the basic wave with the allowed range of every field
(instrument and testbed), Apply, and the output button - whose state is what the
instrument last reported, never what was clicked.  Middle, base motion: a PSD table,
its synthesis settings, what it needs from the generator, Upload, Check.  Right, the
plots: one waveform period (generator volts and the base angle the stage model
expects), the PSD (target, synthesised, achieved) and the cumulative spectral power of
target and achieved on one plot.

The widget does no I/O and no numerics: the GeneratorController (session.generator)
talks to the instrument on its worker thread, `groundstation.basemotion` makes and
checks the profiles.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QFont
from PySide6.QtWidgets import (QCheckBox, QComboBox, QDoubleSpinBox, QFileDialog, QGridLayout, QGroupBox, QHBoxLayout, QLabel, QPushButton,
                               QScrollArea, QSizePolicy, QSpinBox, QSplitter, QVBoxLayout,
                               QWidget)

from ..basemotion import BaseMotionProfile, preview_spectrum
from ..errors import GroundStationError
from ..instruments import spec4050 as spec
from ..plant.testbed import PROFILES_DIR
from .fg_controller import (DEFAULT_TOLERANCE, SIMULATOR, CheckResult, GeneratorState,
                        ResourceChoice, UploadedProfile, limit_texts, limits_source)
from .session import Session

BASE_MOTION_DIR = PROFILES_DIR / "base_motion"
BAD_STYLE = "color:#c62828; font-weight:bold;"
WARN_STYLE = "color:#b26a00;"
OK_STYLE = "color:#2e7d32; font-weight:bold;"
SMALL_STYLE = "color:#808080; font-size:8pt;"
FIELD_BAD = "QDoubleSpinBox { background:#ffcdd2; }"
OUTPUT_ON_STYLE = ("QPushButton { background:#c62828; color:white; font-weight:bold; "
                   "padding:6px; border-radius:4px; }")
OUTPUT_OFF_STYLE = ("QPushButton { background:#424242; color:#e0e0e0; font-weight:bold; "
                    "padding:6px; border-radius:4px; } QPushButton:disabled { color:#808080; }")
PENS = {"target": pg.mkPen("#ffffff", width=1.5, style=Qt.PenStyle.DashLine),
        "synth": pg.mkPen("#4e9bff", width=2), "achieved": pg.mkPen("#ffa62b", width=2),
        "volts": pg.mkPen("#8ac926", width=1), "angle": pg.mkPen("#4e9bff", width=1)}
LEGEND_BRUSH = pg.mkBrush(0, 0, 0, 150)
Z_TARGET, Z_SYNTH = 10, 5
MRAD = 1e3
MRAD2 = 1e6


class GeneratorPanel(QWidget):
    def __init__(self, session: Session, parent: QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.gen = session.generator
        self.profile: BaseMotionProfile | None = None       # the previewed profile
        self.result: CheckResult | None = None
        self.state: GeneratorState | None = None
        self._filling = False
        self._edited = False              # wave fields edited since the last read-back
        self._preview_timer = QTimer(self)
        self._preview_timer.setSingleShot(True)
        self._preview_timer.setInterval(150)  # one preview per burst of edits
        self._preview_timer.timeout.connect(self.preview)
        self._build()
        g = self.gen
        g.sig_resources.connect(self._on_resources)
        g.sig_opened.connect(self._on_opened)
        g.sig_closed.connect(self._on_closed)
        g.sig_state.connect(self._on_state)
        g.sig_uploaded.connect(self._on_uploaded)
        g.sig_failed.connect(lambda action, text: self._say(f"{action}: {text}", bad=True))
        g.sig_refused.connect(self._on_refused)
        g.sig_info.connect(self._say)
        g.sig_busy.connect(lambda what: self.busy.setText(f"{what}…" if what else ""))
        session.sig_link_state.connect(self._on_link)
        self._set_open(False)
        self._update_ranges()
        self.refresh_resources()
        self._schedule_preview()

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        outer = QVBoxLayout(self)
        outer.setContentsMargins(4, 2, 4, 2)
        outer.setSpacing(2)
        split = QSplitter(Qt.Orientation.Horizontal)
        controls = QWidget()
        row = QHBoxLayout(controls)
        row.setContentsMargins(0, 0, 0, 0)
        row.setSpacing(6)
        # three short columns side by side: the dock is wide and low
        row.addWidget(self._instrument_box())
        row.addWidget(self._wave_box())
        row.addWidget(self._motion_box())
        scroll = QScrollArea()
        scroll.setWidget(controls)
        scroll.setWidgetResizable(True)
        scroll.setFrameShape(QScrollArea.Shape.NoFrame)
        # the panel must not set the window's minimum width: the splitter starts with all
        # the controls in view (room left for a vertical scroll bar in a low dock), and on
        # a narrow screen the plots give way first
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        scroll.setMinimumWidth(280)
        split.addWidget(scroll)
        split.addWidget(self._plots())
        split.setStretchFactor(0, 0)
        split.setStretchFactor(1, 1)
        split.setCollapsible(0, False)
        split.setSizes([controls.sizeHint().width() + 40, 600])
        outer.addWidget(split, 1)
        status = QHBoxLayout()
        self.status = QLabel("")
        self.status.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        # long messages must not widen the window: elided by the layout, whole in the tooltip
        self.status.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.busy = QLabel("")
        self.busy.setStyleSheet(WARN_STYLE)
        status.addWidget(self.status, 1)
        status.addWidget(self.busy)
        outer.addLayout(status)

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
        self.channel = QComboBox()
        self.channel.addItems(["1", "2"])
        self.channel.setToolTip("the channel wired to the base-stage amplifier (the simulator: 1)")
        conn.addWidget(self.connect_button, 1)
        conn.addWidget(QLabel("Channel"))
        conn.addWidget(self.channel)
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
        self.channel.currentIndexChanged.connect(lambda _: self._channel_changed())
        return box

    def _wave_box(self) -> QGroupBox:
        box = QGroupBox("Basic wave")
        self.wave_box = box
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

    def _motion_box(self) -> QGroupBox:
        box = QGroupBox("Base motion")
        lay = QVBoxLayout(box)
        lay.setSpacing(3)
        pick = QHBoxLayout()
        self.profile_file = QComboBox()
        for path in sorted(BASE_MOTION_DIR.glob("*.csv")):
            self.profile_file.addItem(path.stem, str(path))
        self.profile_file.setToolTip("a PSD table: frequency_hz,psd_rad2_per_hz "
                                     "(profiles/base_motion/README.md)")
        self.browse_button = QPushButton("File…")
        pick.addWidget(self.profile_file, 1)
        pick.addWidget(self.browse_button)
        lay.addLayout(pick)
        grid = QGridLayout()
        grid.setHorizontalSpacing(6)
        grid.setVerticalSpacing(2)
        self.duration = _spin(" s", 1, 1.0, 3600.0, 60.0)
        self.duration.setToolTip(f"one waveform period, synthesised as {spec.ARB_POINTS_MAX} points "
                                 f"(an upload takes {limit_texts('ARB', 'HZ', None)['points']}); "
                                 f"the generator plays it at 1/period")
        self.seed = QSpinBox()
        self.seed.setRange(0, 2 ** 31 - 1)
        self.seed.setToolTip("random phases: the same seed gives the same profile")
        self.rms = _spin(" mrad", 3, 0.001, 100.0, 3.0)
        self.rms.setToolTip("target base RMS (the table's own when a table is chosen)")
        self.precompensate = QCheckBox("pre-compensate")
        self.precompensate.setChecked(True)
        self.precompensate.setToolTip("divide by the modelled stage response (its resonance "
                                      "included), not only by its DC gain")
        grid.addWidget(QLabel("Period"), 0, 0)
        grid.addWidget(self.duration, 0, 1)
        grid.addWidget(QLabel("Seed"), 0, 2)
        grid.addWidget(self.seed, 0, 3)
        grid.addWidget(QLabel("RMS"), 1, 0)
        grid.addWidget(self.rms, 1, 1)
        grid.addWidget(self.precompensate, 1, 2, 1, 2)
        lay.addLayout(grid)
        self.profile_info = QLabel("")
        self.profile_info.setWordWrap(True)
        self.profile_info.setStyleSheet(SMALL_STYLE)
        lay.addWidget(self.profile_info)
        buttons = QHBoxLayout()
        self.upload_button = QPushButton("Upload to generator")
        self.upload_button.setToolTip("upload as the channel's arbitrary waveform and select it "
                                      "(ARB at 1/period); the output stays as it is")
        self.check_button = QPushButton("Check vs target")
        self.check_button.setToolTip("the base encoder's last settled period from the telemetry, "
                                     "against the target RMS and spectrum")
        buttons.addWidget(self.upload_button)
        buttons.addWidget(self.check_button)
        lay.addLayout(buttons)
        self.check_text = QLabel("")
        self.check_text.setWordWrap(True)
        self.check_text.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        lay.addWidget(self.check_text)
        lay.addStretch(1)
        box.setFixedWidth(315)

        self.profile_file.currentIndexChanged.connect(lambda _: self._table_changed())
        self.browse_button.clicked.connect(self._browse)
        for w in (self.duration, self.rms):
            w.valueChanged.connect(lambda _=None: self._schedule_preview())
        self.seed.valueChanged.connect(lambda _=None: self._schedule_preview())
        self.precompensate.toggled.connect(lambda _=None: self._schedule_preview())
        self.upload_button.clicked.connect(self.upload)
        self.check_button.clicked.connect(self.check)
        self._table_changed(preview=False)
        return box

    def _plots(self) -> pg.GraphicsLayoutWidget:
        view = pg.GraphicsLayoutWidget()
        view.ci.setContentsMargins(2, 2, 2, 2)
        self.volts_plot = view.addPlot(row=0, col=0)
        self.angle_plot = view.addPlot(row=1, col=0)
        self.psd_plot = view.addPlot(row=0, col=1, rowspan=2)
        self.csp_plot = view.addPlot(row=0, col=2, rowspan=2)
        self.volts_plot.setTitle("generator (V), one period", size="8pt")
        self.volts_plot.hideAxis("bottom")
        self.angle_plot.setTitle("base (mrad)", size="8pt")
        self.angle_plot.setXLink(self.volts_plot)
        self.psd_plot.setTitle("PSD (rad²/Hz)", size="8pt")
        self.psd_plot.setLogMode(x=True, y=True)
        self.csp_plot.setTitle("CSP (mrad²)", size="8pt")
        self.csp_plot.setLogMode(x=True, y=False)
        font = QFont()
        font.setPointSize(7)
        for p in (self.volts_plot, self.angle_plot, self.psd_plot, self.csp_plot):
            p.showGrid(x=True, y=True, alpha=0.25)
            for side in ("left", "bottom"):
                p.getAxis(side).setStyle(tickFont=font)
            p.getAxis("left").setWidth(38)
        self.psd_legend = self.psd_plot.addLegend(offset=(2, -2), labelTextSize="7pt",
                                                  brush=LEGEND_BRUSH)
        self.csp_legend = self.csp_plot.addLegend(offset=(2, 2), labelTextSize="7pt",
                                                  brush=LEGEND_BRUSH)
        layout = view.ci.layout
        layout.setColumnStretchFactor(0, 3)
        layout.setColumnStretchFactor(1, 3)
        layout.setColumnStretchFactor(2, 3)
        view.setMinimumWidth(300)
        return view

    # ------------------------------------------------------------------ resources and connection
    def refresh_resources(self) -> None:
        self.refresh_button.setEnabled(False)
        self.busy.setText("listing VISA resources…")
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
        self.busy.setText("")
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
        self._set_open(True)
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
        self._set_open(False)
        self._show_output(None)
        self._say(f"{resource} closed (outputs off)")

    def _set_open(self, is_open: bool) -> None:
        self.connect_button.setText("Disconnect" if is_open else "Connect")
        for w in (self.apply_button, self.output_button, self.upload_button):
            w.setEnabled(is_open)

    def _on_link(self, state: str, _message: str) -> None:
        if state in ("up", "closed"):
            self.refresh_resources()      # the simulator's generator comes and goes with it

    # ------------------------------------------------------------------ the basic wave
    def _channel(self) -> int:
        return int(self.channel.currentText())

    def _channel_changed(self) -> None:
        if self.gen.is_open:
            self._edited = False
            self.gen.refresh(self._channel())

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
        reason = self.gen.apply(self._channel(), waveform=self.waveform.currentText(),
                                frequency_hz=self.frequency.value(),
                                amplitude_vpp=self.amplitude.value(), offset_v=self.offset.value(),
                                phase_deg=self.phase.value(), load=self.load.currentData())
        if reason is None:
            self._edited = False          # the read-back that follows fills the fields
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
        if state.channel != self._channel():
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
        return self.gen.set_output(self._channel(), on)

    # ------------------------------------------------------------------ base motion
    def _table_changed(self, preview: bool = True) -> None:
        """A new PSD table: its own RMS becomes the target."""
        path = self.profile_file.currentData()
        if not path:
            return
        try:
            psd = self.gen.load_psd(path)
        except GroundStationError as exc:
            self._say(str(exc), bad=True)
            return
        self.rms.blockSignals(True)
        self.rms.setValue(psd.rms_rad() * MRAD)
        self.rms.blockSignals(False)
        if preview:
            self._schedule_preview()

    def _browse(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "PSD table", str(BASE_MOTION_DIR),
                                              "PSD tables (*.csv *.txt);;All files (*)")
        if path:
            self.set_profile_file(path)

    def set_profile_file(self, path: str | Path) -> None:
        path = str(path)
        index = self.profile_file.findData(path)
        if index < 0:
            self.profile_file.addItem(Path(path).stem, path)
            index = self.profile_file.count() - 1
        self.profile_file.setCurrentIndex(index)

    def _schedule_preview(self) -> None:
        self._preview_timer.start()

    def preview(self) -> BaseMotionProfile | None:
        """Make the profile (nothing is sent) and plot what it asks of the generator."""
        self._preview_timer.stop()
        path = self.profile_file.currentData()
        if not path:
            return None
        try:
            profile = self.gen.make_profile(path, duration_s=self.duration.value(),
                                            seed=self.seed.value(), target_rms_mrad=self.rms.value(),
                                            precompensate=self.precompensate.isChecked())
        except GroundStationError as exc:
            self.profile = None
            self.profile_info.setText(str(exc))
            self.profile_info.setStyleSheet(BAD_STYLE)
            self._clear_preview()
            return None
        self.profile = profile
        self._show_profile_info(profile)
        self._plot_profile(profile)
        return profile

    def _show_profile_info(self, p: BaseMotionProfile) -> None:
        lo, hi = p.psd.band_hz
        try:
            limit = self.gen.limits or self.gen.safety_limits()
        except GroundStationError:
            limit = None
        needs = f"needs {p.amplitude_vpp:.3f} Vpp"
        style = ""
        if limit is not None:
            needs += f" of the {limit.max_amplitude_vpp:g} Vpp allowed"
            if p.amplitude_vpp > limit.max_amplitude_vpp:
                needs += " - TOO MUCH: lower the RMS, lengthen the period or change the seed"
                style = BAD_STYLE
        self.profile_info.setText(
            f"{p.name} {lo:g}-{hi:g} Hz, {p.points} points at {p.frequency_hz:.5g} Hz; {needs}")
        self.profile_info.setToolTip(p.summary() + f"; the stage settles in "
                                     f"{p.stage.settling_time_s():.1f} s")
        self.profile_info.setStyleSheet(style or SMALL_STYLE)

    def _clear_preview(self) -> None:
        for p in (self.volts_plot, self.angle_plot, self.psd_plot, self.csp_plot):
            p.clear()

    def _plot_profile(self, p: BaseMotionProfile) -> None:
        self._clear_preview()
        t = p.time_s
        self.volts_plot.plot(t, p.volts, pen=PENS["volts"])
        if not p.precompensated:            # else the expected angle is the target
            self.angle_plot.plot(t, p.target_angle_rad * MRAD, pen=PENS["target"])
        self.angle_plot.plot(t, p.expected_angle_rad * MRAD, pen=PENS["angle"])
        self.angle_plot.setTitle("base (mrad): expected" + ("" if p.precompensated else
                                                            ", target dashed"), size="8pt")
        self.volts_plot.setXRange(0, p.duration_s, padding=0)
        spectrum = preview_spectrum(p)
        # drawn over the achieved curve (Z): where they agree, the target must still show
        self.psd_plot.plot(spectrum.frequency_hz, spectrum.target_psd_rad2_per_hz,
                           pen=PENS["target"], name="target").setZValue(Z_TARGET)
        keep = spectrum.synthesised_psd_rad2_per_hz > 0
        self.psd_plot.plot(spectrum.frequency_hz[keep], spectrum.synthesised_psd_rad2_per_hz[keep],
                           pen=None, symbol="o", symbolSize=4, symbolBrush="#4e9bff",
                           symbolPen=None, name="synthesised").setZValue(Z_SYNTH)
        # the target's decades (the achieved curve's numerical floor is no news)
        top = float(spectrum.target_psd_rad2_per_hz.max())
        self.psd_plot.setYRange(np.log10(top) - 4, np.log10(top) + 0.5, padding=0)
        target = p.psd.scaled_to_rms(p.target_rms_rad)
        self.csp_plot.plot(spectrum.frequency_hz, target.cumulative(spectrum.frequency_hz) * MRAD2,
                           pen=PENS["target"], name=f"target {p.target_rms_rad * MRAD:.2f} mrad"
                           ).setZValue(Z_TARGET)
        if self.result is not None and self.result.check.name == p.name:
            self._plot_check(self.result, clear=False)

    def upload(self) -> str | None:
        profile = self.profile or self.preview()
        if profile is None:
            self._say("nothing to upload: the profile could not be made (see above)", bad=True)
            return "no profile"
        reason = self.gen.upload_profile(self._channel(), profile)
        if reason is None:                # a refusal was said by _on_refused
            self._edited = False
            self._say(f"uploading {profile.name} ({profile.points} points)…")
        return reason

    def _on_uploaded(self, up: UploadedProfile) -> None:
        self.result = None
        self.check_text.setText(f"{up.profile.name} uploaded: output on, wait "
                                f"{up.profile.stage.settling_time_s():.0f} s (settling) + "
                                f"{up.profile.duration_s:g} s (one period), then Check")
        self.check_text.setStyleSheet(SMALL_STYLE)

    def check(self, tolerance: float = DEFAULT_TOLERANCE) -> CheckResult | None:
        """Achieved vs target from the telemetry (the controller selects the window)."""
        try:
            result = self.gen.check_achieved(tolerance)
        except GroundStationError as exc:
            self.check_text.setText(f"cannot check yet: {exc}")
            self.check_text.setStyleSheet(WARN_STYLE)
            return None
        self.result = result
        self.check_text.setText(result.headline())
        self.check_text.setToolTip(result.text())
        self.check_text.setStyleSheet(OK_STYLE if result.ok else BAD_STYLE)
        self._plot_check(result)
        self._say(result.text(), bad=not result.ok)
        return result

    def _plot_check(self, result: CheckResult, clear: bool = True) -> None:
        c = result.check
        f = c.frequency_hz
        inside = f > 0                     # log axes: the 0 Hz bin has no place
        if clear:
            self.csp_plot.clear()
            self.csp_plot.plot(f[inside], c.csp.target_csp_rad2[inside] * MRAD2, pen=PENS["target"],
                               name=f"target {c.target_rms_rad * MRAD:.2f} mrad").setZValue(Z_TARGET)
        self.csp_plot.plot(f[inside], c.csp.achieved_csp_rad2[inside] * MRAD2, pen=PENS["achieved"],
                           name=f"achieved {c.achieved_rms_rad * MRAD:.2f}")
        lo, hi = c.band_hz
        band = inside & (f >= lo / 2) & (f <= hi * 2) & (c.achieved_psd_rad2_per_hz > 0)
        self.psd_plot.plot(f[band], c.achieved_psd_rad2_per_hz[band], pen=PENS["achieved"],
                           name="achieved")
        self.csp_plot.setXRange(np.log10(max(lo, f[1]) / 2), np.log10(hi * 2), padding=0)

    # ------------------------------------------------------------------ status
    def _say(self, text: str, bad: bool = False) -> None:
        self.status.setText(text)
        self.status.setToolTip(text)
        self.status.setStyleSheet(BAD_STYLE if bad else "")


def _spin(suffix: str, decimals: int, lo: float, hi: float, value: float) -> QDoubleSpinBox:
    """A number field that lets a value outside the limits be typed: the limits are
    checked on Apply, with the reason shown, rather than clamped silently."""
    s = QDoubleSpinBox()
    s.setDecimals(decimals)
    s.setRange(lo, hi)
    s.setValue(value)
    s.setSuffix(suffix)
    s.setKeyboardTracking(False)
    s.setMinimumWidth(100)
    return s
