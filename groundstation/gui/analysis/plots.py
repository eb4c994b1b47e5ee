"""The Analysis dock's plots (pyqtgraph): spectra, frequency responses against the model,
hysteresis loops and step responses, one curve (one colour) per log.  They draw results
the analysis modules computed; the only arithmetic here is for display (units, dropping
the 0 Hz bin a log axis cannot show, drawing the measured phase about the model's:
model phase + arg(H / model), so a noisy bin can never put the rest of the curve a turn
away).  `render_png` makes one image of a tab's plots for an export.  The Identify tab
(identify.py) builds its plots with the same helpers (analysis_plot, small_legend,
caption_label, side_by_side, positive), so every tab of the dock looks alike.
"""

from __future__ import annotations

import html

import numpy as np
import pyqtgraph as pg
import pyqtgraph.exporters as pg_exporters
from PySide6.QtCore import QBuffer, QByteArray, QIODevice, Qt
from PySide6.QtGui import QColor, QImage, QPainter
from PySide6.QtWidgets import QHBoxLayout, QLabel, QVBoxLayout, QWidget

from .tables import STEP_COLUMNS, FiguresTable, step_row

URAD = 1e6
MODEL_PEN = pg.mkPen("#212121", width=2, style=Qt.PenStyle.DashLine)
LEAD_IN_PEN = pg.mkPen("#bdbdbd", width=1)
#: the logs' colours, in turn (matplotlib's "tab10": ten that tell apart on white)
LOG_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
               "#7f7f7f", "#bcbd22", "#17becf")


def log_colour(index: int, style=Qt.PenStyle.SolidLine):
    """The pen of the index-th log: the same log the same colour in every plot."""
    return pg.mkPen(LOG_COLOURS[index % len(LOG_COLOURS)], width=1.5, style=style)


def small_legend(plot: pg.PlotWidget, offset) -> None:
    """A small legend in black on a pale ground (it may sit over a curve; log names are
    long and the plots narrow)."""
    plot.addLegend(offset=offset, labelTextColor="k", labelTextSize="7pt", verSpacing=-6,
                   brush=pg.mkBrush(255, 255, 255, 210), pen=pg.mkPen("#bdbdbd"))


def positive(x: np.ndarray, *ys: np.ndarray) -> np.ndarray:
    """Where x and every y are finite and > 0 (what a log-log axis can show)."""
    ok = np.isfinite(x) & (x > 0)
    for y in ys:
        ok &= np.isfinite(y) & (y > 0)
    return ok


def analysis_plot(left: str, bottom: str, *, logx: bool, logy: bool) -> pg.PlotWidget:
    """A plot named by its axis labels (no title: the dock is low)."""
    w = pg.PlotWidget()
    w.setBackground("w")
    w.setLabel("left", left)
    w.setLabel("bottom", bottom)
    w.showGrid(x=True, y=True, alpha=0.3)
    w.setLogMode(x=logx, y=logy)
    w.setMinimumSize(160, 120)
    return w


def caption_label() -> QLabel:
    label = QLabel("")
    label.setWordWrap(True)
    label.setTextFormat(Qt.TextFormat.RichText)
    label.setStyleSheet("font-size:8pt;")
    label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
    return label


def side_by_side(widget: QWidget, caption: QLabel | None, plots, stretches) -> None:
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


def _caption(text: str) -> str:
    return html.escape(text).replace("\n", "<br>")


def _indices(results, order) -> list[int]:
    return list(order) if order else list(range(len(results)))


class SpectraPlots(QWidget):
    """PSD (log-log) and CSP (log frequency) of the scored sensor, one curve per log."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.caption = caption_label()
        self.psd = analysis_plot("PSD (µrad²/Hz)", "frequency (Hz)", logx=True, logy=True)
        self.csp = analysis_plot("CSP (µrad²)", "frequency (Hz)", logx=True, logy=False)
        self.csp.setXLink(self.psd)
        # the legend where the CSP is low (it rises to the right)
        small_legend(self.csp, (10, 10))
        side_by_side(self, self.caption, (self.psd, self.csp), (1, 1))
        #: log name -> its curves (tests and the legend read them)
        self.psd_curves: dict[str, pg.PlotDataItem] = {}
        self.csp_curves: dict[str, pg.PlotDataItem] = {}

    def plot_widgets(self) -> list[pg.PlotWidget]:
        return [self.psd, self.csp]

    def clear(self) -> None:
        for plot in (self.psd, self.csp):
            plot.clear()
        self.psd_curves.clear()
        self.csp_curves.clear()
        self.caption.setText("")

    def show_metrics(self, results, order=()) -> None:
        """One PSD and one CSP curve per LogMetrics that has a spectrum (`order`: each
        one's colour index)."""
        self.clear()
        flat = []
        for i, m in zip(_indices(results, order), results):
            s = m.spectrum
            if s is None or not len(s.frequency_hz):
                continue
            f = np.asarray(s.frequency_hz)
            p = np.asarray(s.density) * URAD ** 2
            c = np.asarray(s.csp) * URAD ** 2
            ok = positive(f, p)
            if not np.any(ok):
                flat.append(m.label)
            pen = log_colour(i)
            name = m.label                        # the log's name, or "live window (...)"
            self.psd_curves[name] = self.psd.plot(f[ok], p[ok], pen=pen)
            ok = positive(f) & np.isfinite(c)
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
    """Magnitude and phase and coherence of the frequency responses of several logs, one
    colour each, and the testbed model's once (dashed)."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.caption = caption_label()
        self.magnitude = analysis_plot("magnitude (dB)", "frequency (Hz)", logx=True, logy=False)
        self.phase = analysis_plot("phase (deg)", "frequency (Hz)", logx=True, logy=False)
        self.coherence = analysis_plot("coherence γ²", "frequency (Hz)", logx=True, logy=False)
        self.coherence.setYRange(0.0, 1.05)
        for p in (self.phase, self.coherence):
            p.setXLink(self.magnitude)
        # bottom left: the plant's magnitude falls with frequency
        small_legend(self.magnitude, (10, -10))
        side_by_side(self, self.caption, (self.magnitude, self.phase, self.coherence), (3, 3, 2))
        #: log name -> {"magnitude", "phase", "coherence"} curves; the model's
        #: {"magnitude", "phase"} (tests read them)
        self.curves: dict[str, dict[str, pg.PlotDataItem]] = {}
        self.model: dict[str, pg.PlotDataItem] = {}

    def plot_widgets(self) -> list[pg.PlotWidget]:
        return [self.magnitude, self.phase, self.coherence]

    def clear(self) -> None:
        for p in (self.magnitude, self.phase, self.coherence):
            p.clear()
        self.curves.clear()
        self.model.clear()
        self.caption.setText("")
        self.caption.setToolTip("")

    def show_frfs(self, results, order=()) -> None:
        """log_frf.LogFrf of one or more logs (`order`: colour indices)."""
        self.clear()
        if not results:
            return
        units = {r.measured.units for r in results}
        self.magnitude.setLabel("left", f"magnitude (dB {units.pop()})" if len(units) == 1
                                else "magnitude (dB)")
        with_model = next((r for r in results if r.model is not None), None)
        if with_model is not None:
            f = np.asarray(with_model.measured.freq_hz)
            h = np.asarray(with_model.model)
            ok = positive(f, np.abs(h))
            self.model["magnitude"] = self.magnitude.plot(
                f[ok], 20.0 * np.log10(np.abs(h[ok])), pen=MODEL_PEN,
                name=f"model {with_model.model_path}")
            self.model["phase"] = self.phase.plot(f[ok], np.degrees(np.unwrap(np.angle(h[ok]))),
                                                  pen=MODEL_PEN)
        for i, res in zip(_indices(results, order), results):
            self._one(res, log_colour(i), name=res.path.name)
        if len(results) == 1:
            text = results[0].text()
        else:
            text = "\n".join(_frf_line(r) for r in results)
            if with_model is not None:
                text += (f"\nmodel (dashed): {with_model.model_description} "
                         f"({with_model.testbed_source})")
            self.caption.setToolTip("\n\n".join(r.text() for r in results))
        self.caption.setText(_caption(text))

    def show_frf(self, res) -> None:
        """One log's response (show_frfs of one)."""
        self.show_frfs([res])

    def _one(self, res, pen, name: str) -> None:
        m = res.measured
        f = np.asarray(m.freq_hz)
        mag, phase = m.magnitude_db, m.phase_deg
        ok = positive(f) & np.isfinite(mag)
        curves = {"magnitude": self.magnitude.plot(f[ok], mag[ok], pen=pen, name=name)}
        if res.model is not None:
            phase = _phase_about_model(f, np.asarray(m.response), np.asarray(res.model), phase)
        pok = positive(f) & np.isfinite(phase)
        curves["phase"] = self.phase.plot(f[pok], phase[pok], pen=pen)
        coh = np.asarray(m.coherence)
        cok = positive(f) & np.isfinite(coh)
        curves["coherence"] = self.coherence.plot(f[cok], coh[cok], pen=pen)
        self.curves[name] = curves


def _frf_line(res) -> str:
    """One log's FRF in a line (several logs share the caption)."""
    m = res.measured
    line = (f"{res.path.name}: {res.input_channel} → {res.output_channel}, {res.frames} frames, "
            f"{m.segments} segments ({m.resolution_hz:.3g} Hz)")
    c = res.comparison
    if c is not None and c.bins_used:
        line += f", vs model RMS {c.rms_magnitude_ratio_db:.2f} dB"
    if res.notes:
        line += f" ({len(res.notes)} note{'s' if len(res.notes) > 1 else ''}: hover)"
    return line


def _phase_about_model(f: np.ndarray, measured: np.ndarray, model: np.ndarray,
                       phase: np.ndarray) -> np.ndarray:
    """The measured phase drawn about the model's: the model's unwrapped phase plus the
    wrapped angle of measured/model, bin by bin.  Unwrapping the measured phase on its
    own lets one noisy bin (an antiresonance, a low-coherence bin) shift everything
    after it by a turn; the difference to the model is small where the model is right,
    so no turn is ever lost.  Where the model is undefined the measured phase stays."""
    out = np.array(phase, dtype=float, copy=True)
    usable = positive(f, np.abs(model)) & np.isfinite(measured) & (np.abs(measured) > 0)
    if not np.any(usable):
        return out
    model_phase = np.full(len(f), np.nan)
    model_phase[usable] = np.degrees(np.unwrap(np.angle(model[usable])))
    out[usable] = model_phase[usable] + np.degrees(np.angle(measured[usable] / model[usable]))
    return out


class HysteresisPlot(QWidget):
    """Friction torque against angle of one or more logs: a colour per log, the angle
    rising solid and falling dashed (one curve per direction, the branches apart: a noisy
    record has hundreds), the lead-in grey."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.caption = caption_label()
        self.caption.setAlignment(Qt.AlignmentFlag.AlignTop)
        self.plot = analysis_plot("friction torque (in-oz)", "angle (µrad)", logx=False, logy=False)
        small_legend(self.plot, (10, 10))
        # the loop wants room both ways: the caption beside it, not above
        side_by_side(self, None, (self.plot, self.caption), (3, 2))
        #: log name -> {"lead-in", "angle rising", "angle falling"} curves (tests read them)
        self.curves: dict[str, dict[str, pg.PlotDataItem]] = {}
        self.branches_drawn = 0

    def plot_widgets(self) -> list[pg.PlotWidget]:
        return [self.plot]

    def clear(self) -> None:
        self.plot.clear()
        self.curves.clear()
        self.branches_drawn = 0
        self.caption.setText("")

    def show_loops(self, results, order=()) -> None:
        """log_hysteresis.LogHysteresis of one or more logs (`order`: colour indices)."""
        self.clear()
        for i, res in zip(_indices(results, order), results):
            self._one(res, i)
        text = "solid: angle rising, dashed: angle falling, grey: lead-in\n"
        self.caption.setText(_caption(text + "\n".join(r.text() for r in results)))

    def show_loop(self, res) -> None:
        self.show_loops([res])

    def _one(self, res, index: int) -> None:
        loop = res.loop
        name = res.path.name
        lead = loop.lead_in
        curves = {"lead-in": self.plot.plot(loop.angle_rad[lead] * URAD, loop.torque_in_oz[lead],
                                            pen=LEAD_IN_PEN)}
        pieces: dict[str, list[np.ndarray]] = {"angle rising": [], "angle falling": []}
        for k, b in enumerate(loop.branches):
            angle, torque = loop.branch_arrays(k)
            key = "angle rising" if b.direction > 0 else "angle falling"
            # a nan between branches: one curve, not a line from one branch's end to the next
            pieces[key].append(np.column_stack((angle * URAD, torque)))
            pieces[key].append(np.array([[np.nan, np.nan]]))
        for key, style, label in (("angle rising", Qt.PenStyle.SolidLine, name),
                                  ("angle falling", Qt.PenStyle.DashLine, None)):
            if pieces[key]:
                xy = np.concatenate(pieces[key])
                curves[key] = self.plot.plot(xy[:, 0], xy[:, 1], connect="finite",
                                             pen=log_colour(index, style), name=label)
        self.curves[name] = curves
        self.branches_drawn += len(loop.branches)


class StepPlots(QWidget):
    """Step responses of one or more logs: the response (solid) and the reference (dashed)
    against the time from each log's step, and the figures in a table beside."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.caption = caption_label()
        self.plot = analysis_plot("angle (µrad)", "time from the step (s)", logx=False, logy=False)
        small_legend(self.plot, (-10, -10))
        self.plot.setClipToView(True)
        self.plot.setDownsampling(auto=True, mode="peak")
        self.table = FiguresTable(STEP_COLUMNS)
        self.table.setToolTip("rise 10-90 %, overshoot and settling (±2 %) against the commanded "
                              "step; steady-state error over the last 10 % of the record")
        side_by_side(self, self.caption, (self.plot, self.table), (3, 2))
        #: log name -> {"response", "reference"} curves (tests read them)
        self.curves: dict[str, dict[str, pg.PlotDataItem]] = {}

    def plot_widgets(self) -> list[pg.PlotWidget]:
        return [self.plot]

    def clear(self) -> None:
        self.plot.clear()
        self.curves.clear()
        self.table.clear_rows()
        self.caption.setText("")

    def show_steps(self, results, order=(), failures=()) -> None:
        """analysis_jobs.StepResult of one or more logs (`order`: colour indices) and the
        logs that have no step figures (path, reason) as rows with the reason."""
        self.clear()
        for i, res in zip(_indices(results, order), results):
            name = res.path.name
            self.curves[name] = {
                "response": self.plot.plot(res.time_s, res.response * URAD, pen=log_colour(i),
                                           name=name),
                "reference": self.plot.plot(res.time_s, res.reference * URAD,
                                            pen=log_colour(i, Qt.PenStyle.DashLine))}
            self.table.add_row(step_row(res.step), colour=log_colour(i).color())
        for path, reason in failures:
            self.table.add_row({"log": path.name, "notes": reason}, bad=True)
        if results:
            self.caption.setText(_caption("response (reference − error angle) solid, reference "
                                          "dashed, each log from its own step; the largest "
                                          "step in the window is scored"))


def render_png(plots: list[pg.PlotWidget], width: int = 900) -> bytes:
    """The plots side by side in one PNG image (each `width` pixels wide, pyqtgraph's
    ImageExporter at the plot's own aspect)."""
    images: list[QImage] = []
    for p in plots:
        exporter = pg_exporters.ImageExporter(p.getPlotItem())
        exporter.parameters()["width"] = int(width)
        images.append(exporter.export(toBytes=True))
    total = QImage(sum(i.width() for i in images), max(i.height() for i in images),
                   QImage.Format.Format_ARGB32)
    total.fill(QColor("white"))
    painter = QPainter(total)
    x = 0
    for image in images:
        painter.drawImage(x, 0, image)
        x += image.width()
    painter.end()
    data = QByteArray()
    buffer = QBuffer(data)
    buffer.open(QIODevice.OpenModeFlag.WriteOnly)
    total.save(buffer, "PNG")
    buffer.close()
    return bytes(data.data())


__all__ = ["FrfPlots", "HysteresisPlot", "SpectraPlots", "StepPlots", "analysis_plot",
           "caption_label", "log_colour", "positive", "render_png", "side_by_side",
           "small_legend"]
