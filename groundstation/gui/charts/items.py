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
from PySide6.QtWidgets import QGraphicsWidget


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


def add_lean_legend(plot: pg.PlotItem, **kwargs) -> LeanLegend:
    """What PlotItem.addLegend does, with a LeanLegend."""
    plot.legend = LeanLegend(**kwargs)
    plot.legend.setParentItem(plot.vb)
    return plot.legend
