"""The design workbench's plots (pyqtgraph): they draw what they are given, compute nothing
beyond dB and wrapped angles.

Frequency views (one GraphicsLayoutWidget, 3 x 2):
  |PQ| over the magnitude contours | ||T_I|| and its bound |T_O|
  angle PQ over the phase contours  | ||S_I K|| and its bound |T_O| / ||G||
  phi(omega), phi_PQ and Q = 1      | the PQ locus over phi_PQ's filled contours
Time responses (a second one, 2 x 2): u1, u2 with the motor limits, and y, under the input
disturbance (left) and the reference step (right).

The contours are filled level regions of the alignment, 0-15, 15-30 ... 75-90 deg, green
(aligned) to red (the paths cancel), as in the reference's figures: on the |PQ| panel the
worst case over the phase, on the angle panel the worst case over the magnitude
(groundstation.params.pq: magnitude_band_db, phase_band_deg), on the locus the PQ-plane
alignment phi_PQ itself.  They do not depend on the design and are drawn once.
Design #1 is drawn in blue, #2 in orange.
"""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QRectF, Qt
from PySide6.QtWidgets import QSplitter, QVBoxLayout, QWidget

from ..charts.items import legend_beside
from ...params.pq import CONTOUR_LEVELS_DEG, magnitude_band_db, phase_band_deg, pq_alignment_deg

DESIGN_COLOURS = ("#4e9bff", "#ffa62b")
#: one colour per alignment band, 0-15 deg (green) ... 75-90 deg (red)
BAND_COLOURS = ("#1a9850", "#91cf60", "#d9ef8b", "#fee08b", "#fc8d59", "#d73027")
BAND_ALPHA = 100
LIMIT_PEN = pg.mkPen("#ff5050", width=1)
LIMIT_PEN_FINE = pg.mkPen("#ff5050", width=1, style=Qt.PenStyle.DashLine)
SHOW_GRIDS = False                  # pyqtgraph grids cost ~8 ms a plot per redraw: off
FAR_DB = 400.0                      # the outer edge of the 0-15 deg magnitude band
LOCUS_DB = 160.0                    # the locus image spans +-this


def db(x: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 20 * np.log10(np.abs(x))
    return np.where(np.isfinite(out), out, np.nan)


def broken_at_wraps(x: np.ndarray, y: np.ndarray, wrapped: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x, y with a NaN point where the wrapped angle jumps by more than 180 deg, so that
    the curve is not drawn across the wrap."""
    jumps = np.nonzero(np.abs(np.diff(wrapped)) > 180.0)[0] + 1
    return np.insert(x.astype(float), jumps, np.nan), np.insert(y.astype(float), jumps, np.nan)


def band_brush(i: int):
    c = pg.mkColor(BAND_COLOURS[i])
    c.setAlpha(BAND_ALPHA)
    return pg.mkBrush(c)


def _region(plot, lo: float, hi: float, i: int) -> None:
    item = pg.LinearRegionItem(values=(lo, hi), orientation="horizontal", movable=False,
                               brush=band_brush(i), pen=pg.mkPen(None))
    for line in item.lines:
        line.setPen(pg.mkPen(None))
    item.setZValue(-100)
    plot.addItem(item, ignoreBounds=True)


def band_legend_html() -> str:
    levels = CONTOUR_LEVELS_DEG
    cells = "".join(f"<span style='background:{BAND_COLOURS[i]}; color:black'>&nbsp;"
                    f"{levels[i]:.0f}-{levels[i + 1]:.0f}°&nbsp;</span>"
                    for i in range(len(levels) - 1))
    return f"alignment φ: {cells}"


class WorkbenchPlots(QWidget):
    """All of the workbench's plots; `show_fast` / `show_slow` per slot."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        split = QSplitter(Qt.Orientation.Vertical)
        self.freq_view = pg.GraphicsLayoutWidget()
        self.time_view = pg.GraphicsLayoutWidget()
        split.addWidget(self.freq_view)
        split.addWidget(self.time_view)
        split.setSizes([640, 360])
        lay.addWidget(split)
        fv = self.freq_view
        fv.addLabel(band_legend_html(), row=0, col=0, colspan=2)
        self.mag = self._plot(fv, 1, 0, "|PQ| over the magnitude contours", "|PQ|", "dB")
        self.ti = self._plot(fv, 1, 1, "‖T_I‖ (solid) and its bound |T_O| (dashed)", "‖T_I‖", "dB", grid=True)
        self.phase = self._plot(fv, 2, 0, "∠PQ over the phase contours", "∠PQ", "°")
        self.sik = self._plot(fv, 2, 1, "‖S_I K‖ (solid) and its bound |T_O|/‖G‖ (dashed)",
                              "‖S_I K‖", "dB", grid=True)
        self.phi = self._plot(fv, 3, 0, "alignment φ (solid), φ_PQ (dashed), Q = 1 (dotted)",
                              "φ", "°")
        self.locus = self._plot(fv, 3, 1, "PQ locus over φ_PQ (|P| = |Q|)", "|PQ|", "dB", log_x=False)
        for p in (self.phase, self.phi):
            p.setXLink(self.mag)
        self.sik.setXLink(self.ti)
        self.ti.setXLink(self.mag)
        for p in (self.phi, self.sik):
            p.setLabel("bottom", "frequency", units="Hz")
        self.locus.setLabel("bottom", "∠PQ (°)")
        # above the data, not over the contours it labels (the plots below keep its width)
        self.legend = legend_beside(self.mag, above=True)
        tv = self.time_view
        self.dist_u = self._plot(tv, 0, 0, "under the input disturbance", "torque", "in-oz", log_x=False, grid=True)
        self.step_u = self._plot(tv, 0, 1, "under the reference step", "torque", "in-oz", log_x=False,
                                 grid=True)
        self.dist_y = self._plot(tv, 1, 0, "y under the input disturbance", "y", "rad", log_x=False, grid=True)
        self.step_y = self._plot(tv, 1, 1, "y under the reference step", "y", "rad", log_x=False,
                                 grid=True)
        for p, top in ((self.dist_y, self.dist_u), (self.step_y, self.step_u)):
            p.setXLink(top)
            p.setLabel("bottom", "t", units="s")
        self._draw_bands()
        self.curves: list[dict[str, pg.PlotDataItem]] = [{}, {}]
        self._limits: list = []
        self._q_one = self.phi.plot([], [], pen=pg.mkPen((200, 200, 200), width=1,
                                                         style=Qt.PenStyle.DotLine))
        self.top_db = 60.0

    @staticmethod
    def _plot(view, row: int, col: int, title: str, label: str, units: str, log_x: bool = True,
              grid: bool = False):
        p = view.addPlot(row=row, col=col, title=title)
        p.setLogMode(x=log_x, y=False)
        if grid and SHOW_GRIDS:
            p.showGrid(x=True, y=True, alpha=0.2)
        p.setLabel("left", label, units=units)
        p.setMenuEnabled(False)
        p.titleLabel.setAttr("size", "9pt")
        return p

    def _draw_bands(self) -> None:
        levels = CONTOUR_LEVELS_DEG
        for i in range(len(levels) - 1):
            outer = magnitude_band_db(levels[i])
            inner = magnitude_band_db(levels[i + 1])
            outer = FAR_DB if math.isinf(outer) else outer
            if inner < 1e-9:                             # 90 deg: the band spans 0 dB
                _region(self.mag, -outer, outer, i)
            else:
                _region(self.mag, inner, outer, i)
                _region(self.mag, -outer, -inner, i)
            lo, hi = phase_band_deg(levels[i]), phase_band_deg(levels[i + 1])
            if lo == 0.0:
                _region(self.phase, -hi, hi, i)
            else:
                _region(self.phase, lo, hi, i)
                _region(self.phase, -hi, -lo, i)
            _region(self.phi, levels[i], levels[i + 1], i)
        # the locus: phi_PQ on the (angle, dB) plane, quantised to the bands
        ang = np.linspace(-180, 180, 361)
        mag = np.linspace(-LOCUS_DB, LOCUS_DB, 641)
        A, M = np.meshgrid(ang, mag, indexing="ij")          # image[x, y]
        phi = pq_alignment_deg(10 ** (M / 20) * np.exp(1j * np.radians(A)))
        band = np.clip(np.digitize(phi, levels[1:-1]), 0, len(BAND_COLOURS) - 1)
        lut = np.array([[*pg.mkColor(c).getRgb()[:3], 110] for c in BAND_COLOURS], np.ubyte)
        img = pg.ImageItem(lut[band])
        img.setRect(QRectF(-180, -LOCUS_DB, 360, 2 * LOCUS_DB))
        img.setZValue(-100)
        self.locus.addItem(img, ignoreBounds=True)
        self.phase.setYRange(-180, 180, padding=0)
        self.phase.getAxis("left").setTicks([[(v, f"{v}") for v in range(-180, 181, 60)]])
        self.phi.setYRange(0, 90, padding=0)
        self.phi.getAxis("left").setTicks([[(v, f"{v}") for v in range(0, 91, 15)]])
        self.locus.setXRange(-180, 180, padding=0)
        self.locus.getAxis("bottom").setTicks([[(v, f"{v}") for v in range(-180, 181, 60)]])
        for p in (self.mag, self.phase, self.phi, self.locus):
            p.vb.disableAutoRange(axis=pg.ViewBox.YAxis)
        self.locus.vb.disableAutoRange(axis=pg.ViewBox.XAxis)

    # ------------------------------------------------------------------ curves
    def _curve(self, slot: int, key: str, plot, style=Qt.PenStyle.SolidLine, width: float = 1.0,
               name: str | None = None) -> pg.PlotDataItem:
        curves = self.curves[slot]
        if key not in curves:
            pen = pg.mkPen(DESIGN_COLOURS[slot], width=width, style=style)
            curves[key] = plot.plot([], [], pen=pen, name=name)
        return curves[key]

    def show_fast(self, slot: int, fast, q_one: np.ndarray | None = None) -> None:
        """Draw one slot's frequency views (None: remove them)."""
        if fast is None:
            self._remove(slot, keep=("u1_d", "u2_d", "y_d", "u1_r", "u2_r", "y_r"))
            self._rescale()
            return
        a, lf = fast.analysis, fast.analysis.functions
        f = a.freqs_hz
        pq_db = db(a.pq)
        wrapped = np.degrees(np.angle(a.pq))
        dash, dot = Qt.PenStyle.DashLine, Qt.PenStyle.DotLine
        name = f"#{slot + 1} {fast.design.name}"
        mag = self._curve(slot, "pq_mag", self.mag, width=2, name=name)
        mag.setData(f, pq_db)
        if mag.name() != name:                      # the legend says which design is which
            self.legend.removeItem(mag)
            mag.opts["name"] = name
            self.legend.addItem(mag, name)
        self._curve(slot, "pq_phase", self.phase, width=2).setData(*broken_at_wraps(f, wrapped, wrapped))
        self._curve(slot, "phi", self.phi, width=2).setData(f, a.phi_deg)
        self._curve(slot, "phi_pq", self.phi, dash).setData(f, a.phi_pq_deg)
        self._curve(slot, "ti", self.ti, width=2).setData(f, db(lf.ti_norm))
        self._curve(slot, "ti_bound", self.ti, dash).setData(f, db(lf.ti_bound))
        self._curve(slot, "sik", self.sik, width=2).setData(f, db(lf.sik_norm))
        self._curve(slot, "sik_bound", self.sik, dash).setData(f, db(lf.sik_bound))
        self._curve(slot, "locus", self.locus).setData(*broken_at_wraps(wrapped, pq_db, wrapped))
        if q_one is not None and slot == 0:
            self._q_one.setData(f, q_one)
        self.mag.setXRange(math.log10(f[0]), math.log10(f[-1]), padding=0)
        self._rescale()

    def _rescale(self) -> None:
        """|PQ|'s range: +-60 dB, or more to hold every curve (in steps of 20 dB); the
        norms' ranges their curves' (set here: pyqtgraph's auto-range costs more)."""
        for plot, keys in ((self.ti, ("ti", "ti_bound")), (self.sik, ("sik", "sik_bound"))):
            ys = [c.yData for curves in self.curves for k, c in curves.items()
                  if k in keys and c.yData is not None]
            ys = np.concatenate(ys) if ys else np.zeros(0)
            ys = ys[np.isfinite(ys)]
            if len(ys):
                lo, hi = float(ys.min()), float(ys.max())
                pad = max(3.0, 0.05 * (hi - lo))
                plot.setYRange(lo - pad, hi + pad, padding=0)
        worst = 0.0
        for curves in self.curves:
            c = curves.get("pq_mag")
            if c is not None and c.yData is not None and np.any(np.isfinite(c.yData)):
                worst = max(worst, float(np.nanmax(np.abs(c.yData))))
        self.top_db = min(LOCUS_DB, max(60.0, 20.0 * math.ceil(worst / 20.0)))
        self.mag.setYRange(-self.top_db, self.top_db, padding=0)
        self.locus.setYRange(-self.top_db, self.top_db, padding=0)

    def show_slow(self, slot: int, summary, stale: bool = False) -> None:
        """Draw one slot's time responses (None: remove them) and the motor limits."""
        if summary is None:
            self._remove(slot, keep=("pq_mag", "pq_phase", "phi", "phi_pq", "ti", "ti_bound",
                                     "sik", "sik_bound", "locus"))
            return
        r = summary.responses
        dash = Qt.PenStyle.DashLine
        for tag, resp, top, bottom in (("d", r.disturbance, self.dist_u, self.dist_y),
                                       ("r", r.step, self.step_u, self.step_y)):
            self._curve(slot, f"u1_{tag}", top).setData(resp.t, resp.u[:, 0])
            self._curve(slot, f"u2_{tag}", top, dash).setData(resp.t, resp.u[:, 1])
            self._curve(slot, f"y_{tag}", bottom).setData(resp.t, resp.y)
        self.dist_u.setTitle(f"u1 (solid), u2 (dashed) under {summary.disturbance.text()}; "
                             f"red: motor limits", size="9pt")
        self.step_u.setTitle(f"u1 (solid), u2 (dashed) under {r.step.label}; red: motor limits",
                             size="9pt")
        for tag, plot, what in (("d", self.dist_y, "the input disturbance"),
                                ("r", self.step_y, "the reference step")):
            same = self._same_y(tag)
            plot.setTitle(f"y under {what}" + (" - #1 and #2 alike (the same loop gain)"
                                               if same else ""), size="9pt")
        self.set_stale(slot, stale)
        if slot == 0 or not self._limits:
            self._draw_limits(summary.design)
        self._range_torques()

    def _same_y(self, tag: str) -> bool:
        """Do both slots' y curves coincide (within 2 % of their peak), as output-
        equivalent designs' do?  Then the title says so: one hides the other."""
        ys = [c[f"y_{tag}"].yData for c in self.curves if f"y_{tag}" in c]
        if len(ys) < 2 or len(ys[0]) != len(ys[1]):
            return False
        peak = float(np.max(np.abs(ys[0])))
        return peak > 0 and float(np.max(np.abs(ys[0] - ys[1]))) <= 0.02 * peak

    def _draw_limits(self, design) -> None:
        for plot, item in self._limits:
            plot.removeItem(item)
        self._limits = []
        self._fine_limit = design.saturation_fine_in_oz
        for plot in (self.dist_u, self.step_u):
            for lim, pen in ((design.saturation_coarse_in_oz, LIMIT_PEN),
                             (design.saturation_fine_in_oz, LIMIT_PEN_FINE)):
                for sign in (1, -1):
                    line = pg.InfiniteLine(pos=sign * lim, angle=0, pen=pen)
                    plot.addItem(line, ignoreBounds=True)
                    self._limits.append((plot, line))

    def _range_torques(self) -> None:
        """Each torque plot from -1.15 to 1.15 times its largest |u| or the fine motor's
        limit, whichever is larger (so that the limit a design is judged by shows)."""
        for plot, tag in ((self.dist_u, "d"), (self.step_u, "r")):
            peak = getattr(self, "_fine_limit", 0.0)
            for curves in self.curves:
                for key in (f"u1_{tag}", f"u2_{tag}"):
                    c = curves.get(key)
                    if c is not None and c.yData is not None and len(c.yData):
                        peak = max(peak, float(np.nanmax(np.abs(c.yData))))
            if peak > 0:
                plot.setYRange(-1.15 * peak, 1.15 * peak, padding=0)

    def set_stale(self, slot: int, stale: bool) -> None:
        """Responses of an older edit: drawn faint until the new ones arrive."""
        for key, curve in self.curves[slot].items():
            if key[:2] in ("u1", "u2") or key.startswith("y_"):
                curve.setOpacity(0.3 if stale else 1.0)

    def _remove(self, slot: int, keep: tuple[str, ...] = ()) -> None:
        for key in [k for k in self.curves[slot] if k not in keep]:
            curve = self.curves[slot].pop(key)
            if key == "pq_mag":
                self.legend.removeItem(curve)
            vb = curve.getViewBox()
            if vb is not None:
                vb.removeItem(curve)
        if slot == 0 and "phi" not in self.curves[0]:
            self._q_one.setData([], [])

    def curve_data(self, slot: int, key: str) -> tuple[np.ndarray, np.ndarray] | None:
        """(x, y) of one slot's curve as given (frequencies in Hz, not log10), or None."""
        c = self.curves[slot].get(key)
        return None if c is None or c.xData is None else (c.xData, c.yData)
