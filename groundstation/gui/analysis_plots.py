"""The Analysis dock's plots (pyqtgraph): spectra of several logs, a frequency response
against the model, a hysteresis loop.  They draw results the analysis modules computed;
the only arithmetic here is for display (units, dropping the 0 Hz bin a log axis cannot
show, lining the measured phase up with the model's by whole turns).
"""

from __future__ import annotations

import html

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import QHBoxLayout, QLabel, QVBoxLayout, QWidget

URAD = 1e6
MODEL_PEN = pg.mkPen("#c62828", width=2, style=pg.QtCore.Qt.PenStyle.DashLine)
MEASURED_PEN = pg.mkPen("#1565c0", width=1.5)


def log_colour(index: int):
    """The pen of the index-th log: distinct hues, the same log the same colour in every plot."""
    return pg.mkPen(pg.intColor(index, hues=8, values=1, maxValue=200), width=1.5)


def _positive(x: np.ndarray, *ys: np.ndarray) -> np.ndarray:
    """Where x and every y are finite and > 0 (what a log-log axis can show)."""
    ok = np.isfinite(x) & (x > 0)
    for y in ys:
        ok &= np.isfinite(y) & (y > 0)
    return ok


def _plot(left: str, bottom: str, *, logx: bool, logy: bool) -> pg.PlotWidget:
    """A plot named by its axis labels (no title: the dock is low)."""
    w = pg.PlotWidget()
    w.setBackground("w")
    w.setLabel("left", left)
    w.setLabel("bottom", bottom)
    w.showGrid(x=True, y=True, alpha=0.3)
    w.setLogMode(x=logx, y=logy)
    w.setMinimumSize(160, 120)
    return w


def _caption_label() -> QLabel:
    label = QLabel("")
    label.setWordWrap(True)
    label.setTextFormat(pg.QtCore.Qt.TextFormat.RichText)
    label.setStyleSheet("font-size:8pt;")
    label.setTextInteractionFlags(pg.QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
    return label


def _side_by_side(widget: QWidget, caption: QLabel | None, plots, stretches) -> None:
    """The caption on top, the plots beside each other under it (a wide, low dock)."""
    lay = QVBoxLayout(widget)
    lay.setContentsMargins(0, 0, 0, 0)
    lay.setSpacing(2)
    if caption is not None:
        lay.addWidget(caption)
    row = QHBoxLayout()
    row.setSpacing(4)
    for plot, stretch in zip(plots, stretches):
        row.addWidget(plot, stretch)
    lay.addLayout(row, 1)


class SpectraPlots(QWidget):
    """PSD (log-log) and CSP (log frequency) of the scored sensor, one curve per log."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.caption = _caption_label()
        self.psd = _plot("PSD (µrad²/Hz)", "frequency (Hz)", logx=True, logy=True)
        self.csp = _plot("CSP (µrad²)", "frequency (Hz)", logx=True, logy=False)
        self.csp.setXLink(self.psd)
        # the legend where the CSP is low (it rises to the right)
        self.csp.addLegend(offset=(10, 10))
        _side_by_side(self, self.caption, (self.psd, self.csp), (1, 1))
        #: log name -> its curves (tests and the legend read them)
        self.psd_curves: dict[str, pg.PlotDataItem] = {}
        self.csp_curves: dict[str, pg.PlotDataItem] = {}

    def clear(self) -> None:
        for plot in (self.psd, self.csp):
            plot.clear()
        self.psd_curves.clear()
        self.csp_curves.clear()
        self.caption.setText("")

    def show_metrics(self, results) -> None:
        """One PSD and one CSP curve per LogMetrics that has a spectrum."""
        self.clear()
        flat = []
        for i, m in enumerate(results):
            s = m.spectrum
            if s is None or not len(s.frequency_hz):
                continue
            f = np.asarray(s.frequency_hz)
            p = np.asarray(s.density) * URAD ** 2
            c = np.asarray(s.csp) * URAD ** 2
            ok = _positive(f, p)
            if not np.any(ok):
                flat.append(m.path.name)
            pen = log_colour(i)
            name = m.path.name
            self.psd_curves[name] = self.psd.plot(f[ok], p[ok], pen=pen)
            ok = _positive(f) & np.isfinite(c)
            self.csp_curves[name] = self.csp.plot(f[ok], c[ok], pen=pen, name=name)
        sensors = {m.sensor for m in results if m.spectrum is not None}
        sensor = sensors.pop() if len(sensors) == 1 else "the scored sensor"
        text = (f"PSD and cumulative spectral power of {sensor}, one curve per log (the square "
                f"root of the CSP's right end is the RMS)")
        if flat:
            text += (f"\nnothing to draw on the log axis for {', '.join(flat)}: the spectrum is "
                     f"zero (the sensor reads a constant there; score another sensor)")
        self.caption.setText(_caption(text))


class FrfPlots(QWidget):
    """Magnitude and phase (measured and model) and coherence of one frequency response."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.caption = _caption_label()
        self.magnitude = _plot("magnitude (dB)", "frequency (Hz)", logx=True, logy=False)
        self.phase = _plot("phase (deg)", "frequency (Hz)", logx=True, logy=False)
        self.coherence = _plot("coherence γ²", "frequency (Hz)", logx=True, logy=False)
        self.coherence.setYRange(0.0, 1.05)
        for p in (self.phase, self.coherence):
            p.setXLink(self.magnitude)
        self.magnitude.addLegend(offset=(-10, -10))
        _side_by_side(self, self.caption, (self.magnitude, self.phase, self.coherence), (3, 3, 2))
        #: what is drawn: measured_magnitude, model_magnitude, measured_phase, model_phase,
        #: coherence (tests read them)
        self.items: dict[str, pg.PlotDataItem] = {}

    def clear(self) -> None:
        for p in (self.magnitude, self.phase, self.coherence):
            p.clear()
        self.items.clear()
        self.caption.setText("")

    def show_frf(self, res) -> None:
        """A log_identification.LogFrf."""
        self.clear()
        m = res.measured
        f = np.asarray(m.freq_hz)
        mag = m.magnitude_db
        phase = m.phase_deg
        units = m.units
        self.magnitude.setLabel("left", f"magnitude (dB {units})")
        ok = _positive(f) & np.isfinite(mag)
        self.items["measured_magnitude"] = self.magnitude.plot(
            f[ok], mag[ok], pen=MEASURED_PEN, name=f"measured ({res.input_channel} → "
                                                   f"{res.output_channel})")
        if res.model is not None:
            h = np.asarray(res.model)
            mok = _positive(f, np.abs(h))
            model_db = 20.0 * np.log10(np.abs(h[mok]))
            model_phase = np.degrees(np.unwrap(np.angle(h[mok])))
            self.items["model_magnitude"] = self.magnitude.plot(
                f[mok], model_db, pen=MODEL_PEN, name=f"model {res.model_path}")
            self.items["model_phase"] = self.phase.plot(f[mok], model_phase, pen=MODEL_PEN)
            phase = _align_phase(f, phase, f[mok], model_phase)
        pok = _positive(f) & np.isfinite(phase)
        self.items["measured_phase"] = self.phase.plot(f[pok], phase[pok], pen=MEASURED_PEN)
        coh = np.asarray(m.coherence)
        cok = _positive(f) & np.isfinite(coh)
        self.items["coherence"] = self.coherence.plot(f[cok], coh[cok], pen=MEASURED_PEN)
        self.caption.setText(_caption(res.text()))


def _caption(text: str) -> str:
    return html.escape(text).replace("\n", "<br>")


def _align_phase(f: np.ndarray, phase: np.ndarray, fm: np.ndarray, model_phase: np.ndarray):
    """The measured unwrapped phase shifted by whole turns to start near the model's
    (each curve is unwrapped from its own first bin)."""
    both = np.isfinite(phase) & np.isin(f, fm) & (f > 0)
    if not np.any(both):
        return phase
    i = int(np.flatnonzero(both)[0])
    j = int(np.searchsorted(fm, f[i]))
    turns = np.round((model_phase[j] - phase[i]) / 360.0)
    return phase + 360.0 * turns


class HysteresisPlot(QWidget):
    """Friction torque against angle: the lead-in grey, the branches by direction (one
    curve per direction, the branches apart: a noisy record can have hundreds)."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.caption = _caption_label()
        self.caption.setAlignment(pg.QtCore.Qt.AlignmentFlag.AlignTop)
        self.plot = _plot("friction torque (in-oz)", "angle (µrad)", logx=False, logy=False)
        self.plot.addLegend(offset=(10, 10))
        # the loop wants room both ways: the caption beside it, not above
        _side_by_side(self, None, (self.plot, self.caption), (3, 2))
        #: "lead-in", "angle rising", "angle falling" -> the curve (tests read them)
        self.curves: dict[str, pg.PlotDataItem] = {}
        self.branches_drawn = 0

    def clear(self) -> None:
        self.plot.clear()
        self.curves.clear()
        self.branches_drawn = 0
        self.caption.setText("")

    def show_loop(self, res) -> None:
        """A log_identification.LogHysteresis."""
        self.clear()
        loop = res.loop
        lead = loop.lead_in
        self.curves["lead-in"] = self.plot.plot(loop.angle_rad[lead] * URAD,
                                                loop.torque_in_oz[lead],
                                                pen=pg.mkPen("#9e9e9e", width=1), name="lead-in")
        pieces: dict[str, list[np.ndarray]] = {"angle rising": [], "angle falling": []}
        for i, b in enumerate(loop.branches):
            angle, torque = loop.branch_arrays(i)
            key = "angle rising" if b.direction > 0 else "angle falling"
            # a nan between branches: one curve, not a line from one branch's end to the next
            pieces[key].append(np.column_stack((angle * URAD, torque)))
            pieces[key].append(np.array([[np.nan, np.nan]]))
        for key, colour in (("angle rising", "#1565c0"), ("angle falling", "#c62828")):
            if pieces[key]:
                xy = np.concatenate(pieces[key])
                self.curves[key] = self.plot.plot(xy[:, 0], xy[:, 1], connect="finite",
                                                  pen=pg.mkPen(colour, width=1.5), name=key)
        self.branches_drawn = len(loop.branches)
        self.caption.setText(_caption(res.text()))


__all__ = ["FrfPlots", "HysteresisPlot", "SpectraPlots", "log_colour"]
