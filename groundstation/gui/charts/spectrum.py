"""Live power spectral density of one channel (log-log), from the telemetry store.

On its own timer (a few Hz, only while visible) the view takes the last N seconds of
the chosen channel and has the ground station's Welch PSD computed from it
(`groundstation.analysis.spectra.psd_by_time`: Hann window, 50 % overlap, density
scaling, one-sided).  Sequence gaps and NaN split the record: only segments wholly
inside one contiguous stretch are averaged, so lost frames never get spliced into a
fake step.  The text line gives the total RMS (the square
root of the PSD integrated over the shown band, analysis.spectra.band_rms, the same
trapezoid as the analysis's cumulative spectral power) and the frequency of the
largest peak.
"""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from ...analysis.spectra import MIN_SEGMENT, band_rms, psd_by_time
from ...core.dictionary import Dictionary
from ...live.display_buffers import TelemetryStore
from .channel_tree import channel_catalog, display_unit, format_value
from ..common.steady_label import SteadyLabel

SECONDS_CHOICES = (1, 2, 5, 10, 30, 60)
REFRESH_HZ = 4.0


class SpectrumView(QWidget):
    """PSD of one channel over the last N seconds, log-log, with total RMS."""

    def __init__(self, store: TelemetryStore, dictionary: Dictionary,
                 parent: QWidget | None = None):
        super().__init__(parent)
        self.store = store
        self.catalog = channel_catalog(dictionary)
        self.freqs = np.empty(0)
        self.psd = np.empty(0)
        self.total_rms = math.nan
        self.channel_combo = QComboBox(self)
        for cid, info in self.catalog.items():
            if info.units and info.item is not None and not info.item.states:
                self.channel_combo.addItem(cid, cid)
        self.seconds_combo = QComboBox(self)
        for s in SECONDS_CHOICES:
            self.seconds_combo.addItem(f"{s} s", float(s))
        self.seconds_combo.setCurrentIndex(SECONDS_CHOICES.index(10))
        self.seconds_combo.setToolTip("Length of data the PSD is computed over")
        self.rms_label = SteadyLabel("", self)     # new figures on every refresh: no relayout
        self.rms_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.plot = pg.PlotWidget(self)
        pi = self.plot.getPlotItem()
        pi.setLogMode(x=True, y=True)
        pi.showGrid(x=True, y=True, alpha=0.25)
        pi.setLabel("bottom", "frequency", units="Hz", siPrefixEnableRanges=())
        self.curve = pi.plot(pen=pg.mkPen("#4e9bff", width=1))
        bar = QHBoxLayout()
        bar.setContentsMargins(2, 2, 2, 2)
        bar.addWidget(QLabel("Channel", self))
        bar.addWidget(self.channel_combo, 1)
        bar.addWidget(QLabel("over", self))
        bar.addWidget(self.seconds_combo)
        bar.addWidget(self.rms_label, 1)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(bar)
        layout.addWidget(self.plot, 1)
        self.channel_combo.currentIndexChanged.connect(lambda _i: self._on_channel())
        self.seconds_combo.currentIndexChanged.connect(lambda _i: self.refresh())
        self._on_channel()
        self._timer = QTimer(self)
        self._timer.setInterval(int(1000 / REFRESH_HZ))
        self._timer.timeout.connect(self._on_timer)
        self._timer.start()

    @property
    def channel(self) -> str:
        return self.channel_combo.currentData() or ""

    def set_channel(self, channel_id: str) -> None:
        packet, _, name = channel_id.partition(".")
        ring = self.store.rings.get(packet)
        if ring is None or name not in ring.channels:
            raise ValueError(f"unknown channel {channel_id!r}: use 'PACKET.channel'")
        i = self.channel_combo.findData(channel_id)
        if i < 0:
            self.channel_combo.addItem(channel_id, channel_id)
            i = self.channel_combo.count() - 1
        self.channel_combo.setCurrentIndex(i)

    @property
    def seconds(self) -> float:
        return float(self.seconds_combo.currentData())

    def set_seconds(self, seconds: float) -> None:
        i = self.seconds_combo.findData(float(seconds))
        if i < 0:
            raise ValueError(f"spectrum length {seconds!r} s not one of {SECONDS_CHOICES}")
        self.seconds_combo.setCurrentIndex(i)

    def _on_channel(self) -> None:
        info = self.catalog.get(self.channel)
        unit = display_unit(info.units if info else "")
        u = unit.units or "units"
        # log axis: decades on the ticks, no SI prefix
        self.plot.getPlotItem().setLabel("left", f"PSD ({u}²/Hz)", siPrefixEnableRanges=())
        self.refresh()

    def _on_timer(self) -> None:
        # Shown and on screen.  A dock tabbed behind another one is still "visible" to
        # Qt, only placed outside the window (nothing of it can be seen): the PSD was
        # computed four times a second for nobody (6 % of the GUI thread in bench_gui).
        if self.isVisible() and not self.visibleRegion().isEmpty():
            self.refresh()

    def refresh(self) -> None:
        cid = self.channel
        packet, _, name = cid.partition(".")
        ring = self.store.rings.get(packet)
        info = self.catalog.get(cid)
        unit = display_unit(info.units if info else "")
        if ring is None or name not in ring.channels:
            self._show(np.empty(0), np.empty(0), unit)
            return
        snap = ring.snapshot([name], seconds=self.seconds)
        y = snap.values[name] * unit.scale
        spectrum = psd_by_time(snap.device_time, y, snap.gap_device_times, units=unit.units)
        if spectrum is None:
            self._show(np.empty(0), np.empty(0), unit)
        else:
            self._show(spectrum.frequency_hz, spectrum.density, unit)

    def _show(self, freqs: np.ndarray, psd: np.ndarray, unit) -> None:
        keep = (freqs > 0) & (psd > 0) if len(freqs) else np.zeros(0, dtype=bool)
        self.freqs, self.psd = freqs[keep], psd[keep]
        if not len(self.freqs):
            self.curve.setData(np.empty(0), np.empty(0))   # not lists: see charts._EMPTY
            self.total_rms = 0.0 if len(freqs) else math.nan
            self.rms_label.setText("<i>constant signal: no spectrum</i>" if len(freqs) else
                                   f"<i>fewer than {MIN_SEGMENT} gap-free samples</i>")
            return
        self.curve.setData(self.freqs, self.psd, skipFiniteCheck=True)
        self.total_rms = band_rms(self.freqs, self.psd)
        peak = self.freqs[int(np.argmax(self.psd))]
        self.rms_label.setText(
            f"RMS {format_value(self.total_rms, unit)} "
            f"({self.freqs[0]:.3g}–{self.freqs[-1]:.4g} Hz) · peak {peak:.4g} Hz")

    def peak_frequency(self) -> float:
        return float(self.freqs[int(np.argmax(self.psd))]) if len(self.psd) else math.nan
