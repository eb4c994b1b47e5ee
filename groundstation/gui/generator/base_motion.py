"""The generator panel's base-motion side: a PSD table, its synthesis settings, what it
needs from the generator, Upload, Check; and the plots: one waveform period (generator
volts and the base angle the stage model expects), the PSD (target, synthesised,
achieved) and the cumulative spectral power of target and achieved on one plot.

No numerics here: `groundstation.basemotion` makes and checks the profiles (through the
GeneratorController).  `BaseMotionEditor` is owned by `GeneratorPanel`
(generator/panel.py), which places its box and its plots and gives it the controller,
the panel's `ChannelEditor` (the channel to upload to; an upload's read-back refills
the wave fields) and its status line (`say`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QObject, Qt, QTimer
from PySide6.QtGui import QFont
from PySide6.QtWidgets import (QCheckBox, QComboBox, QFileDialog, QGridLayout, QGroupBox,
                               QHBoxLayout, QLabel, QPushButton, QSpinBox, QVBoxLayout)

from ...basemotion import BaseMotionProfile, preview_spectrum
from ...core.errors import GroundStationError
from ...instruments import spec4050 as spec
from ...plant.testbed import PROFILES_DIR
from ..charts.items import legend_beside
from ..common.file_combo import select_file
from .limits_text import limit_texts
from .records import DEFAULT_TOLERANCE, CheckResult, UploadedProfile
from .styles import BAD_STYLE, OK_STYLE, SMALL_STYLE, WARN_STYLE, _spin

if TYPE_CHECKING:
    from .channel_editor import ChannelEditor
    from .controller import GeneratorController

BASE_MOTION_DIR = PROFILES_DIR / "base_motion"
PENS = {"target": pg.mkPen("#ffffff", width=1.5, style=Qt.PenStyle.DashLine),
        "synth": pg.mkPen("#4e9bff", width=2), "achieved": pg.mkPen("#ffa62b", width=2),
        "volts": pg.mkPen("#8ac926", width=1), "angle": pg.mkPen("#4e9bff", width=1)}
Z_TARGET, Z_SYNTH = 10, 5
MRAD = 1e3
MRAD2 = 1e6


class BaseMotionEditor(QObject):
    """Builds the "Base motion" box and the plots; previews, uploads and checks."""

    def __init__(self, gen: GeneratorController, channel: ChannelEditor,
                 say: Callable[..., None], parent: QObject | None = None):
        super().__init__(parent)
        self.gen = gen
        self.channel = channel
        self._say = say
        self.profile: BaseMotionProfile | None = None       # the previewed profile
        self.result: CheckResult | None = None
        self._preview_timer = QTimer(self)
        self._preview_timer.setSingleShot(True)
        self._preview_timer.setInterval(150)  # one preview per burst of edits
        self._preview_timer.timeout.connect(self.preview)
        self.motion_box = self._motion_box()
        self.plots_view = self._plots()
        gen.sig_uploaded.connect(self._on_uploaded)
        gen.sig_opened.connect(self._on_opened)
        gen.sig_closed.connect(self._on_closed)
        self.upload_button.setEnabled(False)
        self._schedule_preview()

    def _motion_box(self) -> QGroupBox:
        box = QGroupBox("Base motion")
        lay = QVBoxLayout(box)
        lay.setSpacing(3)
        pick = QHBoxLayout()
        self.profile_file = QComboBox()
        for path in sorted(BASE_MOTION_DIR.glob("*.csv")):
            self.profile_file.addItem(path.stem, str(path.resolve()))   # as select_file keys them
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
        # above the data: the PSD and CSP curves fill the small plots edge to edge
        self.psd_legend = legend_beside(self.psd_plot, text_size="7pt", above=True)
        self.csp_legend = legend_beside(self.csp_plot, text_size="7pt", above=True)
        layout = view.ci.layout
        layout.setColumnStretchFactor(0, 3)
        layout.setColumnStretchFactor(1, 3)
        layout.setColumnStretchFactor(2, 3)
        view.setMinimumWidth(300)
        return view

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
        path, _ = QFileDialog.getOpenFileName(self.motion_box, "PSD table", str(BASE_MOTION_DIR),
                                              "PSD tables (*.csv *.txt);;All files (*)")
        if path:
            self.set_profile_file(path)

    def set_profile_file(self, path: str | Path) -> None:
        select_file(self.profile_file, path)       # a change re-plots through the combo's signal

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
        reason = self.gen.upload_profile(self.channel.channel_number(), profile)
        if reason is None:                # a refusal was said by the channel editor
            self.channel.expect_readback()
            self._say(f"uploading {profile.name} ({profile.points} points)…")
        return reason

    def _on_opened(self, _resource: str, _identity: str) -> None:
        self.upload_button.setEnabled(True)

    def _on_closed(self, _resource: str) -> None:
        self.upload_button.setEnabled(False)

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
