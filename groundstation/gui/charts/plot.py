"""One plot of the strip-chart stack: curves, gap markers, cursor line, info text, and
the time axis that switches between device seconds, wall-clock labels and (live) seconds
before the newest sample.

Live, the view's x range stays put at -window..0 and the plot's contents move instead:
every item that sits at a time (curves, gap markers, the cursor) lives in one layer that
is moved to minus the plot's `origin` (the newest sample's time), so their own
coordinates (`getData()`, `value()`) stay absolute times.  A scrolling view range made
pyqtgraph redo its range bookkeeping for every linked plot and regenerate the time axis's
ticks and labels on every frame; a fixed one does neither.  Paused, the origin is 0 and
the axis shows absolute time.  Times in and out of this class (`x_range`, `set_cursor`,
`sig_mouse_x`, `show_gaps`, curve data) are always absolute."""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from pyqtgraph import functions as fn
from PySide6.QtCore import QObject, QRectF, Qt, Signal
from PySide6.QtGui import QPainter
from PySide6.QtWidgets import QGraphicsItem, QMenu

from .channel_tree import DisplayUnit, channel_ids_from_text
from .autoscale import ChartViewBox
from .items import LeanPlotItem, legend_beside


def _cache_pixels(item: QGraphicsItem) -> None:
    """Keep the item and all its children as pixmaps, redrawn only when they change.
    The curves move under the axes' edges, the legend and the info text on every frame,
    and redrawing those from their text (shaping every glyph again) cost more than the
    curves themselves."""
    item.setCacheMode(QGraphicsItem.CacheMode.DeviceCoordinateCache)
    for child in item.childItems():
        _cache_pixels(child)


class _TextSizeCache:
    """Stands in for the QPainter while an axis lays out its ticks, remembering the size
    of each tick label: a scrolling time axis lays out every frame, and measuring the
    same few strings again was most of that work (bench_gui.py's profile)."""

    MAX = 4096

    def __init__(self) -> None:
        self._sizes: dict[tuple, object] = {}
        self._p = None
        self._font = ""

    def wrap(self, p):
        self._p = p
        self._font = p.font().key()
        return self

    def setFont(self, font) -> None:
        self._p.setFont(font)
        self._font = self._p.font().key()

    def boundingRect(self, rect, flags, text):
        key = (self._font, rect.width(), rect.height(), int(flags), text)
        size = self._sizes.get(key)
        if size is None:
            if len(self._sizes) > self.MAX:
                self._sizes.clear()
            size = self._sizes[key] = self._p.boundingRect(rect, flags, text)
        return size

    def __getattr__(self, name):
        return getattr(self._p, name)


class _KeptBounds:
    """An axis's bounding rect, kept until its size or style changes: Qt asks for it
    several times a frame (the axes border the curves' area), and pyqtgraph works it out
    in Python from the style, the linked view and the geometry each time.  With a grid
    the rect covers the linked view's, which can change at any time: not kept.

    The axis asks `rect(axis, compute)` from its boundingRect and calls `forget()` when
    it is resized or restyled."""

    def __init__(self) -> None:
        self._rect = None

    def rect(self, axis: pg.AxisItem, compute):
        if axis.grid is not False:
            return compute()
        if self._rect is None:
            self._rect = compute()
        return self._rect

    def forget(self) -> None:
        self._rect = None


def _kept_axis(base: type[pg.AxisItem]) -> type[pg.AxisItem]:
    """`base` (pyqtgraph's AxisItem or a subclass of it) with its bounding rect kept
    (_KeptBounds) and its tick labels' sizes cached (_TextSizeCache).  A class made from
    its base rather than a mixin: Qt calls these overrides on the C++ side, so they
    must sit on the one class pyqtgraph instantiates."""

    class KeptAxis(base):
        def __init__(self, orientation: str) -> None:
            # before the base class: its constructor already restyles and resizes the axis
            self._bounds = _KeptBounds()
            super().__init__(orientation=orientation)
            self._text_sizes = _TextSizeCache()

        def boundingRect(self):
            return self._bounds.rect(self, super().boundingRect)

        def resizeEvent(self, ev=None):
            self._bounds.forget()
            super().resizeEvent(ev)

        def setStyle(self, **kwargs):
            self._bounds.forget()
            super().setStyle(**kwargs)

        def generateDrawSpecs(self, p):
            return super().generateDrawSpecs(self._text_sizes.wrap(p))

    KeptAxis.__name__ = KeptAxis.__qualname__ = f"Kept{base.__name__}"
    return KeptAxis


class _ValueAxis(_kept_axis(pg.AxisItem)):
    """Left axis; its bounding rect is kept and its tick labels' sizes are cached."""

    def __init__(self) -> None:
        super().__init__(orientation="left")


class _TimeAxis(_kept_axis(pg.DateAxisItem)):
    """Bottom axis: plain seconds in device time, wall-clock labels in host time, or
    (`relative`, a live chart) seconds before the newest sample.  Its bounding rect is
    kept as the value axis's is."""

    def __init__(self) -> None:
        super().__init__(orientation="bottom")
        self.host = False
        self.relative = False
        self.shown = True          # only the bottom plot of the stack labels its time axis
        # No labels on the finest tick level: they never fit on a strip chart's time axis,
        # yet every one of them was measured on every scroll step.
        self.setStyle(maxTextLevel=1)

    def tickValues(self, minVal, maxVal, size):
        if self.host and not self.relative:
            return super().tickValues(minVal, maxVal, size)
        return pg.AxisItem.tickValues(self, minVal, maxVal, size)

    def tickStrings(self, values, scale, spacing):
        if self.host and not self.relative:
            return super().tickStrings(values, scale, spacing)
        return pg.AxisItem.tickStrings(self, values, scale, spacing)

    def set_mode(self, host: bool, relative: bool) -> None:
        if (host, relative) == (self.host, self.relative) and self.labelText:
            return
        self.host, self.relative = host, relative
        if relative:
            self.setLabel("time before the newest sample", units="s")
        elif host:
            self.setLabel("host time (local)")
        else:
            self.setLabel("device time", units="s")
        self.set_shown(self.shown)

    def set_shown(self, shown: bool) -> None:
        # Hidden outright, not just unlabelled: a hidden plot's axis costs nothing, and
        # only the bottom plot needs its labels.
        self.shown = shown
        self.setVisible(shown)
        self.showLabel(shown)


_PLOT_CHANGED = pg.PlotCurveItem.staticMetaObject.method(
    pg.PlotCurveItem.staticMetaObject.indexOfSignal("sigPlotChanged(PyObject)"))


class ChartCurve(pg.PlotCurveItem):
    """A strip chart's curve: a bare PlotCurveItem (the panel clips and decimates, so
    PlotDataItem's own clipping, downsampling and dataset bookkeeping are not needed),
    which also carries the bounds of its points inside the time window shown.

    The view box asks a curve for its bounds several times per frame to autoscale y;
    pyqtgraph would scan all points with a mask each time.  `set_points` computes
    them once, from the points between the window's edges only, as that scan would."""

    def __init__(self, pen) -> None:
        super().__init__(pen=pen)
        self._bounds: tuple | None = None
        self._ybounds: tuple[float, float] | None = None
        self._extent: tuple[float, float, float, float] | None = None   # all points
        self._finite = False
        self._poly = None                  # the points as a QPolygonF, reused frame to frame
        self._poly_xy = np.empty((0, 2))   # its memory, as numpy sees it
        self._poly_stale = True
        #: the least y span autoscale gives this curve's channel (autoscale.least_span)
        self.least_span = 0.0

    def set_points(self, x: np.ndarray, y: np.ndarray, lo: float, hi: float) -> None:
        """Draw (x, y); NaN in y breaks the line.  lo, hi: the time window shown."""
        # the old extent stays until setData has marked the old picture's area for repaint
        self._bounds = self._ybounds = None
        if not len(x):
            self.setData(x, y)
            self._extent = self._boundingRect = None
            return
        x0, x1 = float(x[0]), float(x[-1])
        # min and max carry a NaN through: one pass each also says whether all are finite
        ya, yb = float(np.minimum.reduce(y)), float(np.maximum.reduce(y))
        finite = not (math.isnan(ya) or math.isnan(yb))
        if finite and lo <= x0 and x1 <= hi:
            ybounds = (ya, yb)           # live: every point is inside the window
        else:
            a, b = int(x.searchsorted(lo, side="left")), int(x.searchsorted(hi, side="right"))
            inside = y[a:b]
            if finite:
                ybounds = ((float(inside.min()), float(inside.max())) if len(inside)
                           else (None, None))
            else:
                ybounds = ((float(np.nanmin(inside)), float(np.nanmax(inside)))
                           if len(inside) and not np.isnan(inside).all() else (None, None))
                ya, yb = ((float(np.nanmin(y)), float(np.nanmax(y)))
                          if not np.isnan(y).all() else (math.nan, math.nan))
        self._ybounds = ybounds if ybounds[0] is not None else None
        self._finite, self._poly_stale = finite, True
        if finite:
            self._set_finite(x, y)
        else:
            self.setData(x, y, connect="finite", skipFiniteCheck=False)
        self._bounds = ((x0, x1), ybounds)
        self._extent = (x0, x1, ya, yb) if math.isfinite(ya) else None
        self._boundingRect = None

    def _set_finite(self, x: np.ndarray, y: np.ndarray) -> None:
        """What pyqtgraph's setData does with two finite 1-D float arrays (connect 'all',
        no finite check), without its argument handling and profiler: that Python
        overhead was half the cost of handing a curve its points (py-spy, bench_gui)."""
        self.xData, self.yData = x, y
        self.opts["connect"] = "all"
        self.opts["skipFiniteCheck"] = True
        self.invalidateBounds()
        self.prepareGeometryChange()
        self.informViewBoundsChanged()
        self.path = self.fillPath = None
        self._fillPathList = self._mouseShape = None
        self._lineSegmentsRendered = False
        self.update()
        # nothing listens on the strip charts (pyqtgraph connects it for FillBetweenItem
        # only); asking is a quarter of the cost of emitting to nobody
        if self.isSignalConnected(_PLOT_CHANGED):
            self.sigPlotChanged.emit(self)

    def paint(self, p, opt, widget):
        """Finite points as one polyline from a reused QPolygonF: the same strokes as
        pyqtgraph's path, without building a QPainterPath every frame.  Anything else
        (NaN breaks) as pyqtgraph draws it."""
        x = self.xData
        if not self._finite or x is None or len(x) < 2:
            return super().paint(p, opt, widget)
        if self._poly_stale:
            if len(self._poly_xy) != len(x):
                self._poly = fn.create_qpolygonf(len(x))
                self._poly_xy = fn.ndarray_from_qpolygonf(self._poly)
            self._poly_xy[:, 0] = x
            self._poly_xy[:, 1] = self.yData
            self._poly_stale = False
        p.setRenderHint(QPainter.RenderHint.Antialiasing, bool(self.opts["antialias"]))
        p.setPen(self.opts["pen"])
        p.drawPolyline(self._poly)

    def boundingRect(self):
        """All points, with a margin of 1 % of the view's range for the pen: pyqtgraph
        works out its margin in pixels from the device transform on every new set of
        points, which cost more than building the curve's path."""
        if self._boundingRect is None:
            vb = self.getViewBox()
            if self._extent is None or vb is None:
                return QRectF()
            x0, x1, y0, y1 = self._extent
            (va, vb_), (wa, wb) = vb.state["viewRange"]
            px, py = 0.01 * (vb_ - va), 0.01 * (wb - wa)
            self._boundingRect = QRectF(x0 - px, y0 - py, x1 - x0 + 2 * px, y1 - y0 + 2 * py)
        return self._boundingRect

    def window_y_bounds(self) -> tuple[float, float] | None:
        """Lowest and highest y inside the time window (None: no finite points there)."""
        return self._ybounds

    def dataBounds(self, ax, frac=1.0, orthoRange=None):
        if self._bounds is None or frac < 1.0 or ax not in (0, 1):
            return super().dataBounds(ax, frac, orthoRange)
        return self._bounds[ax]


#: the legend's column right of each plot: the same for every plot of the stack, so
#: their data areas (and times) line up; a longer name is cut (its tooltip is whole)
LEGEND_WIDTH = 150


class ChartPlot(QObject):
    """One plot of the stack: its curves, gap markers, cursor line and info text.

    A PlotItem (`getPlotItem()`) in the panel's one graphics view (charts/column.py), not
    a view of its own.  Holds no data; the panel hands it arrays.  A drop of channel ids
    (text lines) emits sig_dropped."""

    #: curve colours, distinct on the dark background; red is kept for gap markers
    PALETTE = ("#4e9bff", "#ffa62b", "#2ec4b6", "#c792ea", "#f7e03c", "#8ac926",
               "#ff70a6", "#00d0ff", "#c0c0c0", "#ff8c61")
    MAX_GAP_MARKERS = 100
    MIN_HEIGHT = 90

    sig_dropped = Signal(list)
    sig_menu_about_to_show = Signal(object)
    sig_mouse_x = Signal(object)                 # float, or None when the mouse leaves
    sig_x_range_changed = Signal()

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self.time_axis = _TimeAxis()
        self._pi = pi = LeanPlotItem(viewBox=ChartViewBox(),
                                     axisItems={"bottom": self.time_axis, "left": _ValueAxis()})
        self.origin = 0.0          # absolute time of view x = 0 (see the module docstring)
        pi.setMinimumHeight(self.MIN_HEIGHT)
        # No grid by default: on the raster engine a translucent grid doubles the paint
        # time of a scrolling plot (measured); Plot Options → Grid in the menu adds one.
        pi.hideButtons()
        pi.getAxis("left").setWidth(80)
        for side in ("left", "bottom"):
            _cache_pixels(pi.getAxis(side))
        self.legend = legend_beside(pi, LEGEND_WIDTH)
        vb = pi.getViewBox()
        vb.setAutoVisible(y=True)
        vb.disableAutoRange(axis="x")
        self.curves: dict[str, ChartCurve] = {}
        self.units: dict[str, DisplayUnit] = {}
        self._names: dict[str, str] = {}
        # the decimation and gap notes under the legend, in its column: over the data
        # they hid the newest samples' corner, as the legend did
        self.info = pg.TextItem(anchor=(0, 1), color=(235, 235, 235))
        self.info.setParentItem(pi)
        self.info.setTextWidth(LEGEND_WIDTH - 4)
        self.info.hide()
        _cache_pixels(self.info)
        vb.sigResized.connect(self._place_info)
        self._gap_text = self._dec_text = ""
        self._info_html: str | None = None
        self.cursor = pg.InfiniteLine(angle=90, movable=False,
                                      pen=pg.mkPen((255, 255, 255, 150), style=Qt.PenStyle.DotLine))
        # the layer of everything placed in time, moved as a whole by set_origin; the
        # curves stay among the view box's items (autoscale, "View All") as they join it
        self._layer = pg.ItemGroup()
        vb.addItem(self._layer, ignoreBounds=True)
        # Moving it tells nobody: the y autoscale reads the curves' own bounds, and each
        # move had pyqtgraph's itemChange (Python) ask the view box to recompute them.
        self._layer.setFlag(self._layer.GraphicsItemFlag.ItemSendsGeometryChanges, False)
        self.cursor.setParentItem(self._layer)
        self.cursor.hide()
        self._gap_pen = pg.mkPen((255, 50, 50, 200), width=1, style=Qt.PenStyle.DashLine)
        self.gap_lines: list[pg.InfiniteLine] = []
        # no parent widget (a plot item is none); the attribute keeps the menu alive
        self.chart_menu = QMenu("Chart")
        self.channel_menus: dict[str, QMenu] = {}      # filled by the panel with the menu
        vb.menu.addSeparator()
        vb.menu.addMenu(self.chart_menu)
        vb.menu.aboutToShow.connect(lambda: self.sig_menu_about_to_show.emit(self))
        vb.sigXRangeChanged.connect(lambda *_: self.sig_x_range_changed.emit())

    def getPlotItem(self) -> pg.PlotItem:          # noqa: N802 - PlotWidget's name
        return self._pi

    # ------------------------------------------------------------ curves, axes
    def add_curve(self, cid: str, name: str, unit: DisplayUnit, colour: int,
                  description: str = "", least_span: float = 0.0) -> ChartCurve:
        curve = ChartCurve(pg.mkPen(self.PALETTE[colour], width=1))
        curve.least_span = least_span
        curve.setToolTip(f"{cid}: {description}" if description else cid)
        self.curves[cid] = curve
        self.units[cid] = unit
        self._names[cid] = name
        self.getPlotItem().addItem(curve)
        curve.setParentItem(self._layer)
        self._relabel()
        return curve

    def remove_curve(self, cid: str) -> None:
        self.getPlotItem().removeItem(self.curves.pop(cid))
        del self.units[cid], self._names[cid]
        self._relabel()

    def _relabel(self) -> None:
        """Axis label with units (SI prefix where the unit takes one), legend entries."""
        axis = self.getPlotItem().getAxis("left")
        kinds = {u.units for u in self.units.values()}
        names = list(self._names.values())
        if len(kinds) == 1:             # the units only: the legend names the channels
            unit = next(iter(self.units.values()))
            ranges = unit.si_ranges if unit.si_prefix else ()
            text = names[0] if len(names) == 1 and not unit.units else ""
            axis.setLabel(text, units=unit.units or None, siPrefixEnableRanges=ranges)
        else:
            axis.setLabel("mixed units" if names else "", siPrefixEnableRanges=())
        self.legend.clear()
        for cid, curve in self.curves.items():
            label = self._names[cid]
            if len(kinds) > 1 and self.units[cid].units:
                label += f" [{self.units[cid].units}]"
            self.legend.addItem(curve, label)
        self.legend.setVisible(bool(self.curves))
        _cache_pixels(self.legend)

    def set_time_mode(self, timebase: str, relative: bool) -> None:
        """Label the time axis for the timebase, relative to the newest sample or not."""
        self.time_axis.set_mode(timebase == "host", relative)

    def set_origin(self, origin: float) -> None:
        """Place the plot's contents so that absolute time `origin` is at view x = 0."""
        if origin == self.origin:
            return
        self.origin = origin
        self._layer.setPos(-origin, 0.0)

    def set_x_view(self, lo: float, hi: float) -> None:
        """Show view x lo..hi (in view coordinates: absolute time − origin); nothing
        happens when it is shown already, so a live chart's fixed range costs nothing."""
        vb = self.getPlotItem().getViewBox()
        if list(vb.state["viewRange"][0]) != [lo, hi]:
            vb.setXRange(lo, hi, padding=0)

    def set_mouse_x(self, enabled: bool) -> None:
        """Pan/zoom in time only while paused; live, the window follows the data."""
        self.getPlotItem().getViewBox().setMouseEnabled(x=enabled, y=True)

    @property
    def autoscale(self) -> bool:
        return bool(self.getPlotItem().getViewBox().state["autoRange"][1])

    def set_autoscale(self, enabled: bool) -> None:
        self.getPlotItem().getViewBox().enableAutoRange(axis="y", enable=bool(enabled))

    def set_y_range(self, low: float, high: float) -> None:
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f"y range needs finite low < high, got {low!r}, {high!r}")
        self.getPlotItem().setYRange(low, high, padding=0)   # also ends autoscale

    def y_range(self) -> tuple[float, float]:
        lo, hi = self.getPlotItem().getViewBox().viewRange()[1]
        return float(lo), float(hi)

    def x_range(self) -> tuple[float, float]:
        """The time span shown, in absolute time (device s, or host s since the epoch)."""
        lo, hi = self.getPlotItem().getViewBox().viewRange()[0]
        return float(lo) + self.origin, float(hi) + self.origin

    def plot_width(self) -> float:
        """Width of the data area in pixels (the decimation target)."""
        w = self.getPlotItem().getViewBox().width()
        return w if w >= 10 else 800.0          # not laid out yet: a typical width

    # ------------------------------------------------------------ markers, text
    def show_gaps(self, gap_x: np.ndarray, sizes: np.ndarray) -> None:
        """Red markers at the newest gaps (reused lines), and a count in the info text."""
        shown = gap_x[-self.MAX_GAP_MARKERS:]
        while len(self.gap_lines) < len(shown):
            line = pg.InfiniteLine(angle=90, movable=False, pen=self._gap_pen)
            line.setParentItem(self._layer)
            self.gap_lines.append(line)
        for line, x in zip(self.gap_lines, shown.tolist()):
            if line.value() != x:
                line.setValue(x)
            line.show()
        for line in self.gap_lines[len(shown):]:
            line.hide()
        self._gap_text = (f"<span style='color:#ff5050'>{len(gap_x)} gap(s), "
                          f"{int(sizes.sum())} frames lost</span>" if len(gap_x) else "")
        self._update_info()

    def show_decimation(self, factor: int) -> None:
        self._dec_text = f"decimated ×{factor} (min/max)" if factor > 1 else ""
        self._update_info()

    def info_text(self) -> str:
        return self.info.textItem.toPlainText() if self.info.isVisible() else ""

    def _update_info(self) -> None:
        parts = [p for p in (self._dec_text, self._gap_text) if p]
        html = "<br>".join(parts)                    # one note a line in the narrow column
        if html != self._info_html:
            self._info_html = html
            self.info.setHtml(f"<span style='font-size:7pt; color:#b0b0b0'>{html}</span>")
            self.info.setVisible(bool(parts))
            self._place_info()

    def _place_info(self) -> None:
        box = self.getPlotItem().getViewBox().geometry()       # in the plot item's coordinates
        self.info.setPos(box.right() + 2, box.bottom())

    # ------------------------------------------------------------ cursor, mouse, drops
    def set_cursor(self, x: float | None) -> None:
        if x is None:
            self.cursor.hide()
        else:
            self.cursor.setValue(x)
            self.cursor.show()

    def mouse_moved(self, pos) -> None:
        """The scene's mouse position (the column hands it to every plot): over this
        plot's data area, the time there."""
        vb = self.getPlotItem().getViewBox()
        if vb.sceneBoundingRect().contains(pos):
            self.sig_mouse_x.emit(float(vb.mapSceneToView(pos).x()) + self.origin)

    def dropEvent(self, event) -> None:                # noqa: N802 - the view's drop, passed on
        ids = channel_ids_from_text(event.mimeData().text())
        if ids:
            event.acceptProposedAction()
            self.sig_dropped.emit(ids)
        else:
            event.ignore()
