"""pyqtgraph's plot items, minus the Python calls Qt makes on every frame.

Qt asks every item in the exposed part of a scene for its `boundingRect` (and the view
boxes for their `shape`, to clip) several times per paint.  pyqtgraph implements these
in Python for its GraphicsWidgets, so each question is a call from C++ into Python
through shiboken: about 200 of them a frame for the strip charts' four plots (counted;
76 for the classes below), each several times the cost of the C++ answer (2 vs 17 us an
item in a scene of plain widgets, measured).  For the widgets below pyqtgraph's answer is the C++ one - the
widget's own rectangle (`rect()`; they are not transformed, and an ItemSample is 20 x
20 px, fixed) - so naming the C++ methods in the subclass makes shiboken find no Python
override and Qt answer without Python.
"""

from __future__ import annotations

import pyqtgraph as pg
from pyqtgraph.graphicsItems.LegendItem import ItemSample
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QGraphicsWidget, QSizePolicy


class LeanPlotItem(pg.PlotItem):
    """A PlotItem whose bounding rect and shape are Qt's (its rectangle)."""

    boundingRect = QGraphicsWidget.boundingRect
    shape = QGraphicsWidget.shape


class _LeanSample(ItemSample):
    boundingRect = QGraphicsWidget.boundingRect
    shape = QGraphicsWidget.shape


class _LeanLabel(pg.LabelItem):
    boundingRect = QGraphicsWidget.boundingRect
    shape = QGraphicsWidget.shape


class LeanLegend(pg.LegendItem):
    """A legend whose frame, samples and labels answer their bounding rects in C++."""

    boundingRect = QGraphicsWidget.boundingRect
    shape = QGraphicsWidget.shape

    def __init__(self, **kwargs) -> None:
        super().__init__(sampleType=_LeanSample, **kwargs)

    def addItem(self, item, name) -> None:
        """As LegendItem.addItem, with the lean label."""
        label = _LeanLabel(name, color=self.opts["labelTextColor"], justify="left",
                           size=self.opts["labelTextSize"])
        sample = item if isinstance(item, self.sampleType) else self.sampleType(item)
        sample.sigClicked.connect(self.sigSampleClicked)
        self.items.append((sample, label))
        self._addItemToLayout(sample, label)
        self.updateSize()


class _PlacedLegend(LeanLegend):
    """A legend in its plot's layout: a drag would pull it out of its cell (pyqtgraph's
    drag re-anchors it over the view box), so it does not move."""

    def mouseDragEvent(self, ev) -> None:
        ev.ignore()


def legend_beside(plot: pg.PlotItem, width: int | None = None, *, text_size: str = "8pt",
                  above: bool = False) -> LeanLegend:
    """A legend outside the data: in the plot's own layout, right of the view box (a
    column of entries, `width` wide when given) or above it (one row of entries), so it
    never covers a trace or a label.  PlotItem keeps its title in (0, 1), its top axis
    in (1, 1) and the view box in (2, 1); the legend takes (2, 3) beside the data, or
    (1, 1) between the title and the data - the top axis (never shown on our plots)
    then leaves the layout."""
    legend = _PlacedLegend(labelTextSize=text_size, frame=False, verSpacing=-4,
                           size=(width, 20) if width else None)
    plot.legend = legend
    if above:
        legend.setColumnCount(2)          # two entries a row: narrow plots stay narrow
        top = plot.getAxis("top")
        top.hide()
        plot.layout.removeItem(top)
        plot.layout.addItem(legend, 1, 1)
        plot.layout.setAlignment(legend, Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignBottom)
    else:
        plot.layout.addItem(legend, 2, 3)
        plot.layout.setAlignment(legend, Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
    if width:
        legend.setMinimumWidth(width)
        legend.setMaximumWidth(width)
    # as high as its entries: a cell as high as the plot would spread them over it
    legend.setSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Fixed)
    return legend
