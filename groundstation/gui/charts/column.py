"""The strip chart's plots in one graphics view, stacked top to bottom with a drag handle
between neighbours (what a vertical QSplitter gave four separate plot widgets).

One view and one scene for all the plots: a chart frame is one paint event and one
traversal of one scene instead of one per plot, and the view's fixed costs (the paint
event, the scene's item lookup, the background, pyqtgraph's prepare-for-paint
callbacks) are paid once a frame, not four times.

The column knows nothing about channels or data: the panel's `PlotStack`
(charts/stack.py) puts `ChartPlot`s in and takes them out; their heights behave as a splitter's
did: `sizes()` and `setSizes()` in pixels, a new plot gets an average share, a plot
never shrinks below its minimum height, a resize keeps the proportions.
"""

from __future__ import annotations

import pyqtgraph as pg
from PySide6.QtCore import QPointF, QRectF, Qt, Signal
from PySide6.QtWidgets import QGraphicsItem, QGraphicsWidget, QWidget

from .plot import ChartPlot

#: height of the drag handle between two plots, in pixels (a Fusion splitter's)
HANDLE_PX = 6


class _Handle(QGraphicsWidget):
    """The strip between plot `index` and plot `index + 1`; dragging it moves the
    boundary between them, as a splitter handle does."""

    def __init__(self, column: PlotColumn, parent: QGraphicsItem) -> None:
        super().__init__(parent)
        self.column = column
        self.index = 0
        self.setCursor(Qt.CursorShape.SplitVCursor)
        self.setZValue(10)                   # above the plots' edges it touches
        # the plots' updates expose it every frame: a pixmap, not a Python paint call
        self.setCacheMode(QGraphicsItem.CacheMode.DeviceCoordinateCache)

    def paint(self, p, opt, widget=None) -> None:
        # the window's colour, as a splitter's handle between the plots looked before
        p.fillRect(self.rect(), self.palette().window())

    def mouseDragEvent(self, ev) -> None:
        """pyqtgraph's scene hands drags to items that have this method and accept."""
        if ev.button() != Qt.MouseButton.LeftButton:
            ev.ignore()
            return
        ev.accept()
        self.column.move_boundary(self.index, ev.scenePos().y())


class _Stack(QGraphicsWidget):
    """The view's central item: lays the plots and handles out whenever it is resized."""

    def __init__(self, column: PlotColumn) -> None:
        super().__init__()
        self.column = column

    def resizeEvent(self, ev) -> None:
        super().resizeEvent(ev)
        self.column.lay_out()


class PlotColumn(pg.GraphicsView):
    """A column of `ChartPlot`s in one view (see the module docstring)."""

    sig_left = Signal()            # the mouse left the view (the read-out cursor hides)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.plots: list[ChartPlot] = []
        self._sizes: list[float] = []        # wanted heights, scaled to fit when laid out
        self._handles: list[_Handle] = []
        self._shown_sizes: list[int] = []    # heights as laid out last
        self.stack = _Stack(self)            # (setting it lays out: the lists first)
        self.setCentralItem(self.stack)
        self.scene().sigMouseMoved.connect(self._on_mouse_moved)
        # One rectangle a frame around what changed, not the region of the four plots'
        # data areas: QPainter clips to the exposed region, and a region of several
        # rectangles is a complex clip for every stroke of the raster engine.
        self.setViewportUpdateMode(self.ViewportUpdateMode.BoundingRectViewportUpdate)
        # The background is plain black: filling the exposed rectangle is cheaper than
        # copying it from pyqtgraph's cached background pixmap (0.2-0.35 ms a frame of
        # 2.7-3.5 for the four plots, measured in one process, alternating).
        self.setCacheMode(self.CacheModeFlag.CacheNone)
        # pyqtgraph's GraphicsView ignores drag events; the column takes channel drops
        self.setAcceptDrops(True)

    # ------------------------------------------------------------ plots in and out
    def insert(self, index: int, plot: ChartPlot) -> None:
        """Put a plot at `index`; it gets the existing plots' average height."""
        share = sum(self._sizes) / len(self._sizes) if self._sizes else 1.0
        self.plots.insert(index, plot)
        self._sizes.insert(index, share)
        plot.getPlotItem().setParentItem(self.stack)
        self._sync_handles()
        self.lay_out()

    def remove(self, plot: ChartPlot) -> None:
        """Take a plot out and free it; the others share its height."""
        index = self.plots.index(plot)
        del self.plots[index], self._sizes[index]
        pi = plot.getPlotItem()
        pi.setXLink(None)                    # no signal from its range to the others
        self.scene().removeItem(pi)
        pi.deleteLater()
        plot.deleteLater()
        self._sync_handles()
        self.lay_out()

    def _sync_handles(self) -> None:
        while len(self._handles) < len(self.plots) - 1:
            self._handles.append(_Handle(self, self.stack))
        while len(self._handles) > max(len(self.plots) - 1, 0):
            handle = self._handles.pop()
            self.scene().removeItem(handle)
        for i, handle in enumerate(self._handles):
            handle.index = i
        # as a splitter whose children do not collapse: the view is never shorter than
        # its plots' minimum heights
        self.setMinimumHeight(int(sum(self._minimum(p) for p in self.plots)
                                  + HANDLE_PX * len(self._handles)))

    @staticmethod
    def _minimum(plot: ChartPlot) -> float:
        return plot.getPlotItem().minimumHeight()

    # ------------------------------------------------------------ heights
    def sizes(self) -> list[int]:
        """Each plot's height in pixels, top to bottom (as QSplitter.sizes)."""
        return list(self._shown_sizes) if len(self._shown_sizes) == len(self.plots) else [
            int(round(s)) for s in self._sizes]

    def setSizes(self, sizes: list[int]) -> None:     # noqa: N802 - QSplitter's name
        """Heights in pixels, top to bottom; scaled to the space there is."""
        if len(sizes) != len(self.plots):
            raise ValueError(f"{len(sizes)} heights for {len(self.plots)} plots")
        self._sizes = [max(float(s), 1.0) for s in sizes]
        self.lay_out()

    def _fit(self, total: float) -> list[float]:
        """The wanted heights scaled to `total`, none below its plot's minimum."""
        mins = [self._minimum(p) for p in self.plots]
        fixed = [False] * len(self.plots)
        heights = list(self._sizes)
        for _ in range(len(heights)):        # the minimums first, the rest in proportion
            free = total - sum(m for m, f in zip(mins, fixed) if f)
            want = sum(s for s, f in zip(self._sizes, fixed) if not f)
            heights = [m if f else s * free / want if want > 0 else m
                       for s, m, f in zip(self._sizes, mins, fixed)]
            low = [i for i, h in enumerate(heights) if not fixed[i] and h < mins[i]]
            if not low:
                break
            for i in low:
                fixed[i] = True
        return heights

    def lay_out(self) -> None:
        """Place the plots and the handles in the view's central item."""
        if not self.plots:
            self._shown_sizes = []
            return
        rect = self.stack.rect()
        avail = max(rect.height() - HANDLE_PX * len(self._handles), 0.0)
        heights = self._fit(avail)
        y = rect.top()
        shown = []
        for i, (plot, h) in enumerate(zip(self.plots, heights)):
            top, bottom = round(y), round(y + h)
            plot.getPlotItem().setGeometry(QRectF(rect.left(), top, rect.width(), bottom - top))
            shown.append(bottom - top)
            y += h
            if i < len(self._handles):
                self._handles[i].setGeometry(QRectF(rect.left(), round(y), rect.width(), HANDLE_PX))
                y += HANDLE_PX
        self._shown_sizes = shown

    def move_boundary(self, index: int, y: float) -> None:
        """Put the boundary between plots index and index + 1 at scene y (the handle's
        middle), within both plots' minimum heights; the other plots keep theirs."""
        sizes = [float(s) for s in self.sizes()]
        top = self.plots[index].getPlotItem().geometry().top()
        pair = sizes[index] + sizes[index + 1]
        upper = y - HANDLE_PX / 2 - top
        lo = self._minimum(self.plots[index])
        hi = pair - self._minimum(self.plots[index + 1])
        upper = min(max(upper, lo), max(hi, lo))
        sizes[index], sizes[index + 1] = upper, pair - upper
        self._sizes = sizes
        self.lay_out()

    # ------------------------------------------------------------ mouse, drops
    def plot_at(self, scene_pos: QPointF) -> ChartPlot | None:
        """The plot at a scene position; on a handle, the plot above it."""
        for plot in reversed(self.plots):
            if plot.getPlotItem().geometry().top() <= scene_pos.y():
                return plot
        return self.plots[0] if self.plots else None

    def _on_mouse_moved(self, pos) -> None:
        for plot in self.plots:
            plot.mouse_moved(pos)

    def leaveEvent(self, event) -> None:
        self.sig_left.emit()
        super().leaveEvent(event)

    def dragEnterEvent(self, event) -> None:
        if event.mimeData().hasText():
            event.acceptProposedAction()
        else:
            event.ignore()

    def dragMoveEvent(self, event) -> None:
        self.dragEnterEvent(event)

    def dropEvent(self, event) -> None:
        plot = self.plot_at(self.mapToScene(event.position().toPoint()))
        if plot is None:
            event.ignore()
        else:
            plot.dropEvent(event)
