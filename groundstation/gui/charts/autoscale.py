"""The strip charts' y autoscale: a range that sticks.

pyqtgraph's autoscale fits the y range to the data on every frame, so a scrolling chart
changes its y range (and regenerates its y axis's ticks and labels) nearly every frame,
and the numbers on the axis jitter.  Here the range is chosen with a margin and snapped
outward to round values, and it is kept while the data stay inside it and fill at least
`SHRINK_BELOW` of it: the axis repaints when the data really grew or shrank.
"""

from __future__ import annotations

import math

import pyqtgraph as pg
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QPainterPath

#: margin on either side of the data when a range is chosen, as a fraction of the data's span
MARGIN = 0.1
#: a range is chosen anew when the data fill less than this fraction of it
SHRINK_BELOW = 0.4
#: about this many steps of a round size in a chosen range
STEPS = 8
#: the view shows this fraction of the round range beyond each end, so the labels of the
#: ticks on the round ends are drawn inside their plot, not over the neighbouring plot's
EDGE = 0.05
#: a flat channel's range spans at least this many steps of its resolution: a constant
#: or one-count-noisy channel reads as flat on a short axis, not as a full-height square
#: wave or a +-0.6 band of its unit whatever its size
FLAT_STEPS = 10
#: the least span for a channel the wire carries as a float (no resolution), per
#: dictionary unit; other float units keep the old band (a tenth of the value, or 1)
FLOAT_FLOORS = {"rad": 1e-6, "rad/s": 1e-6, "A": 1e-3, "V": 1e-3, "s": 1e-3, "ms": 1.0,
                "degC": 0.1, "in-oz": 1e-3}


def nice_step(size: float) -> float:
    """The smallest of 1, 2, 5 x 10^k that is at least `size` (> 0)."""
    power = 10.0 ** math.floor(math.log10(size))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * power >= size * (1 - 1e-12):
            return m * power
    return 10.0 * power


def least_span(wire_type: str, scale: float | None, units: str, display_scale: float = 1.0) -> float:
    """The least y span (in display units: value x `display_scale`) for a channel of the
    dictionary: FLAT_STEPS of its resolution (`scale` per count, or one count of an
    unscaled integer), or its unit's FLOAT_FLOORS entry for a float; 0 when unknown."""
    if wire_type.startswith("f"):
        return FLOAT_FLOORS.get(units, 0.0) * display_scale
    return FLAT_STEPS * abs(scale if scale else 1.0) * display_scale


def nice_range(lo: float, hi: float, least: float = 0.0) -> tuple[float, float]:
    """A range around data lo..hi with a margin, its ends on multiples of a round step,
    spanning at least `least` (centred on the data).  Depends on its arguments only, so
    the same data always give the same range."""
    span = hi - lo
    if span < least:                                 # (nearly) flat: the channel's least span
        mid = (lo + hi) / 2
        lo, hi, span = mid - least / 2, mid + least / 2, least
    if not span > abs(hi) * 1e-12:                  # constant data: a band around them
        span = abs(lo) * 0.1 if lo else 1.0
        lo, hi = lo - span / 2, hi + span / 2
    pad = MARGIN * span
    step = nice_step((span + 2 * pad) / STEPS)
    return math.floor((lo - pad) / step) * step, math.ceil((hi + pad) / step) * step


def sticky_range(lo: float, hi: float, shown: tuple[float, float] | None,
                 least: float = 0.0) -> tuple[float, float] | None:
    """The y range for data lo..hi given the range `shown` now: None to keep it (the data
    are inside and fill at least SHRINK_BELOW of it - flat data count as `least`), else
    a new `nice_range`."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return None
    if shown is not None:
        a, b = shown
        if a <= lo and hi <= b and max(hi - lo, least) >= SHRINK_BELOW * (b - a):
            return None
    new = nice_range(lo, hi, least)
    return None if shown is not None and new == tuple(shown) else new


class ChartViewBox(pg.ViewBox):
    """A ViewBox whose y autoscale (the usual "auto" state, menus included) follows
    `sticky_range` over the visible curves' bounds; x autoscale is never used by the
    strip charts and is left to pyqtgraph.

    Qt asks a view box for its bounding rect and shape several times a frame (see
    charts/items.py), and pyqtgraph works them out in two Python calls each time; here
    they are kept from one resize to the next.  Its paint draws a border the strip charts
    do not have: Qt is told there is nothing to paint."""

    def __init__(self, *args, **kwargs):
        self._rect_cache = None
        super().__init__(*args, **kwargs)
        self._border_changed()

    def setBorder(self, *args, **kwds):
        super().setBorder(*args, **kwds)
        self._border_changed()

    def _border_changed(self) -> None:
        # pyqtgraph's paint strokes the border pen only (an invisible NoPen by default)
        no_border = self.border is None or self.border.style() == Qt.PenStyle.NoPen
        self.setFlag(self.GraphicsItemFlag.ItemHasNoContents, no_border)
        # and its border item, over the whole box, would be visited on every frame
        self.borderRect.setVisible(not no_border)

    def resizeEvent(self, ev):
        self._rect_cache = None
        super().resizeEvent(ev)

    def boundingRect(self):
        """pyqtgraph's (the rectangle, half a pixel larger right and below), kept."""
        if self._rect_cache is None:
            br = QRectF(QPointF(0, 0), self.size()).adjusted(0, 0, 0.5, 0.5)
            path = QPainterPath()
            path.addRect(br)
            self._rect_cache = (br, path)
        return self._rect_cache[0]

    def shape(self):
        self.boundingRect()
        return self._rect_cache[1]

    def updateAutoRange(self):
        auto = self.state["autoRange"]
        if self._updatingRange or auto[0] is not False or not auto[1]:
            return super().updateAutoRange()
        self._updatingRange = True
        try:
            bounds = self._y_bounds()
            if bounds is not None:
                chosen = getattr(self, "_round_range", None)
                view = self.state["viewRange"][1]
                if chosen is not None and not all(
                        math.isclose(x, v, rel_tol=1e-9, abs_tol=1e-12 * abs(chosen[1] - chosen[0]))
                        for x, v in zip(_shown(chosen), view)):
                    chosen = None          # the range was set by other means since
                new = sticky_range(bounds[0], bounds[1], chosen, bounds[2])
                if new is not None:
                    self._round_range = new
                    self.setRange(yRange=_shown(new), padding=0.0, disableAutoRange=False)
        finally:
            self._autoRangeNeedsUpdate = False
            self._updatingRange = False

    def _y_bounds(self) -> tuple[float, float, float] | None:
        """Lowest and highest y of the visible items inside the x range shown, and the
        largest least span of those that have one (`least_span`).  Items that know their
        window's bounds (`window_y_bounds`) answer directly; otherwise pyqtgraph's
        general (slower) scan."""
        lo, hi, least = math.inf, -math.inf, 0.0
        for item in self.addedItems:
            if not item.isVisible():
                continue
            get = getattr(item, "window_y_bounds", None)
            if get is None:
                yr = self.childrenBounds(orthoRange=[None, self.state["viewRange"][0]])[1]
                return None if yr is None else (float(yr[0]), float(yr[1]), 0.0)
            b = get()
            if b is not None:
                lo, hi = min(lo, b[0]), max(hi, b[1])
                least = max(least, getattr(item, "least_span", 0.0))
        return (lo, hi, least) if lo <= hi else None


def _shown(round_range: tuple[float, float]) -> tuple[float, float]:
    """What the view shows for a round range: EDGE of it more at either end."""
    a, b = round_range
    e = EDGE * (b - a)
    return a - e, b + e
