"""The strip charts' plot items answer Qt's per-frame questions (bounding rect, shape)
without Python where pyqtgraph's answer is Qt's own, or from a kept value: the answers
must stay pyqtgraph's, and the legend must still work (clicking a sample hides its
curve)."""

from __future__ import annotations

import pyqtgraph as pg
import pytest
from PySide6.QtCore import QRectF
from PySide6.QtWidgets import QGraphicsItem

from groundstation.gui.charts.items import LeanLegend, LeanPlotItem


@pytest.fixture
def panel(strip_chart):
    p = strip_chart(10.0, (900, 600))
    p.set_layout([["HIGH_RATE.error_angle", "HIGH_RATE.encoder_outer"], ["HIGH_RATE.gyro_rate"]])
    return p


def _rect(r: QRectF) -> tuple:
    return (r.x(), r.y(), r.width(), r.height())


def test_lean_items_answer_as_pyqtgraph(panel, qtbot):
    plot = panel.stack.plots[0]
    pi = plot.getPlotItem()
    assert isinstance(pi, LeanPlotItem) and isinstance(plot.legend, LeanLegend)
    assert _rect(pi.boundingRect()) == _rect(pg.GraphicsWidget.boundingRect(pi))
    legend = plot.legend
    assert _rect(legend.boundingRect()) == _rect(pg.LegendItem.boundingRect(legend))
    for sample, label in legend.items:
        assert _rect(sample.boundingRect()) == (0, 0, 20, 20)
        assert _rect(label.boundingRect()) == _rect(pg.GraphicsWidget.boundingRect(label))
    vb = pi.getViewBox()
    assert _rect(vb.boundingRect()) == _rect(pg.ViewBox.boundingRect(vb))
    assert vb.shape().boundingRect() == vb.boundingRect()
    assert vb.flags() & QGraphicsItem.GraphicsItemFlag.ItemHasNoContents
    # after a resize the kept rects follow
    panel.resize(700, 900)
    qtbot.waitUntil(lambda: vb.width() < 650, timeout=5000)
    assert _rect(vb.boundingRect()) == _rect(pg.ViewBox.boundingRect(vb))
    for axis in (pi.getAxis("left"), plot.time_axis, panel.stack.plots[1].time_axis):
        assert _rect(axis.boundingRect()) == _rect(pg.AxisItem.boundingRect(axis))
    # with a grid an axis's rect covers the linked view's, as pyqtgraph's does
    axis = pi.getAxis("left")
    axis.setGrid(80)
    assert _rect(axis.boundingRect()) == _rect(pg.AxisItem.boundingRect(axis))
    assert axis.boundingRect().width() > 100


def test_legend_sample_click_still_hides_its_curve(panel):
    plot = panel.stack.plots[0]
    sample, _ = plot.legend.items[0]
    curve = plot.curves["HIGH_RATE.error_angle"]
    assert curve.isVisible()

    class Click:                   # what pyqtgraph's scene hands an item on a click
        def button(self):
            from PySide6.QtCore import Qt
            return Qt.MouseButton.LeftButton

        def accept(self):
            self.accepted = True

    sample.mouseClickEvent(Click())
    assert not curve.isVisible()


def test_curve_signals_a_listener_only_when_there_is_one(panel):
    import numpy as np

    curve = panel.stack.plots[0].curves["HIGH_RATE.error_angle"]
    curve.set_points(np.arange(3.0), np.zeros(3), 0.0, 5.0)      # nobody listens: fine
    got = []
    curve.sigPlotChanged.connect(got.append)
    curve.set_points(np.arange(3.0), np.ones(3), 0.0, 5.0)
    assert got == [curve]


def test_every_legend_sits_beside_its_plot_not_over_the_data(panel, qtbot):
    """The legend boxes covered the traces and the axis labels: each is now in its plot's
    layout, right of the data area, as wide in every plot (the data areas line up)."""
    panel.stack.add_plot()
    panel.stack.add_channel("HOUSEKEEPING.temp_flexure", 2)
    qtbot.waitUntil(lambda: all(p.getPlotItem().getViewBox().width() > 100 for p in panel.stack.plots),
                    timeout=5000)
    lefts, widths = set(), set()
    for plot in panel.stack.plots:
        vb = plot.getPlotItem().getViewBox().sceneBoundingRect()
        legend = plot.legend.sceneBoundingRect()
        assert plot.legend.isVisible() and legend.height() > 0
        # the view box's rect is half a pixel larger, right and below (pyqtgraph's)
        assert legend.left() >= vb.right() - 1, (legend, vb)
        axis = plot.getPlotItem().getAxis("left").sceneBoundingRect()
        assert not legend.intersects(axis)
        lefts.add(round(vb.left()))
        widths.add(round(vb.width()))
        # every entry whole inside the legend
        for sample, label in plot.legend.items:
            assert legend.contains(label.sceneBoundingRect().center())
    assert len(lefts) == 1 and len(widths) == 1
    # the decimation and gap notes too: under the legend, not over the newest samples
    plot = panel.stack.plots[0]
    plot.show_decimation(4)
    vb = plot.getPlotItem().getViewBox().sceneBoundingRect()
    note = plot.info.sceneBoundingRect()
    assert "decimated ×4" in plot.info_text() and note.width() > 0
    assert note.left() >= vb.right() - 1 and note.top() >= plot.legend.sceneBoundingRect().bottom()
