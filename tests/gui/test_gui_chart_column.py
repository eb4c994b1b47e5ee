"""The strip charts' plots share one graphics view (chart_column.PlotColumn): one paint
event a frame for all of them, while each plot keeps its own y autoscale, its heights
behave as a splitter's (drag handle, minimum height, saved and restored), channels
dropped anywhere on the column land on the plot under the mouse, and the read-out
cursor follows the mouse over any plot."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QEvent, QMimeData, QObject, QPoint, QPointF, Qt
from PySide6.QtGui import QDragEnterEvent, QDropEvent, QMouseEvent
from PySide6.QtWidgets import QApplication, QGraphicsView

from groundstation.gui.charts.column import HANDLE_PX

from conftest import HighRateFeeder

RATE = 1200.0
LAYOUT = [["HIGH_RATE.error_angle"], ["HIGH_RATE.encoder_outer"],
          ["HIGH_RATE.gyro_rate"], ["HIGH_RATE.current_coarse"]]


@pytest.fixture
def panel(strip_chart):
    return strip_chart(30.0, (900, 700))


class _Paints(QObject):
    def __init__(self, widget):
        super().__init__()
        self.count = 0
        widget.installEventFilter(self)

    def eventFilter(self, obj, event):
        if event.type() == QEvent.Type.Paint:
            self.count += 1
        return False


def _feed(panel, dictionary, start, n, scales=(1e-4, 1.0, 10.0, 0.01)):
    s = np.arange(start, start + n)
    wave = np.sin(s / 100.0)
    HighRateFeeder(dictionary, panel.store)(
        s, error_angle=scales[0] * wave, encoder_outer=scales[1] * wave,
        gyro_rate=scales[2] * wave, current_coarse=scales[3] * wave)


def _plot_centre(panel, i) -> QPoint:
    rect = panel.stack.plots[i].getPlotItem().getViewBox().sceneBoundingRect()
    return panel.column.mapFromScene(rect.center())


def test_four_plots_one_view_one_paint_a_frame(panel, dictionary, qtbot):
    panel.set_layout(LAYOUT)
    views = panel.findChildren(QGraphicsView)
    assert views == [panel.column]
    scene = panel.column.scene()
    assert all(p.getPlotItem().scene() is scene for p in panel.stack.plots)
    _feed(panel, dictionary, 0, 2400)
    panel.refresh()
    qtbot.wait(50)
    paints = _Paints(panel.column.viewport())
    for k in range(5):
        _feed(panel, dictionary, 2400 + 40 * k, 40)
        panel.refresh()
        QApplication.processEvents()
    assert paints.count == 5                    # one paint event serves all four plots
    # the plots are stacked top to bottom, the same width, their data areas aligned
    tops = [p.getPlotItem().geometry().top() for p in panel.stack.plots]
    assert tops == sorted(tops)
    lefts = {round(p.getPlotItem().getViewBox().sceneBoundingRect().left()) for p in panel.stack.plots}
    assert len(lefts) == 1
    # only the bottom plot labels its time axis
    assert [p.time_axis.isVisible() for p in panel.stack.plots] == [False, False, False, True]


def test_each_plot_autoscales_on_its_own(panel, dictionary):
    panel.set_layout(LAYOUT)
    panel.set_window_seconds(2.0)
    _feed(panel, dictionary, 0, 2400)
    panel.refresh()
    spans = []
    for plot, scale in zip(panel.stack.plots, (1e-4, 1.0, 10.0, 0.01)):
        lo, hi = plot.y_range()
        assert lo < -0.9 * scale and hi > 0.9 * scale and hi - lo < 4 * scale
        spans.append(hi - lo)
    assert len(set(spans)) == 4
    panel.settings.set_y_range(2, -100.0, 100.0)                 # one plot fixed, the others still follow
    _feed(panel, dictionary, 2400, 2400, scales=(2e-4, 2.0, 20.0, 0.02))
    panel.refresh()
    assert panel.stack.plots[2].y_range() == pytest.approx((-100.0, 100.0))
    assert not panel.stack.plots[2].autoscale and panel.stack.plots[0].autoscale
    assert panel.stack.plots[0].y_range()[1] >= 2e-4 * 0.99
    assert panel.stack.plots[1].y_range()[1] >= 2.0 * 0.99
    assert panel.stack.plots[3].y_range()[1] >= 0.02 * 0.99
    # x stays linked: every plot shows the same time span
    assert len({p.x_range() for p in panel.stack.plots}) == 1


def test_heights_behave_as_a_splitter(panel, dictionary, qtbot):
    panel.set_layout(LAYOUT)
    column = panel.column
    sizes = column.sizes()
    assert len(sizes) == 4 and max(sizes) - min(sizes) <= 1       # equal shares
    height = column.stack.rect().height()
    assert sum(sizes) + 3 * HANDLE_PX == pytest.approx(height, abs=2)
    # drag the first handle down by 60 px with the mouse
    handle = column._handles[0]
    start = column.mapFromScene(handle.sceneBoundingRect().center())
    vp = column.viewport()

    def mouse(kind, pos, buttons):
        ev = QMouseEvent(kind, QPointF(pos), QPointF(vp.mapToGlobal(pos)), Qt.MouseButton.LeftButton,
                         buttons, Qt.KeyboardModifier.NoModifier)
        QApplication.sendEvent(vp, ev)
        qtbot.wait(25)                 # pyqtgraph's scene drops moves closer than ~17 ms

    left = Qt.MouseButton.LeftButton
    mouse(QEvent.Type.MouseMove, start, Qt.MouseButton.NoButton)
    mouse(QEvent.Type.MouseButtonPress, start, left)
    for dy in range(5, 65, 5):
        mouse(QEvent.Type.MouseMove, start + QPoint(0, dy), left)
    mouse(QEvent.Type.MouseButtonRelease, start + QPoint(0, 60), Qt.MouseButton.NoButton)
    dragged = column.sizes()
    assert dragged[0] == pytest.approx(sizes[0] + 60, abs=3)
    assert dragged[1] == pytest.approx(sizes[1] - 60, abs=3)
    assert dragged[2:] == sizes[2:]
    # a plot never gets shorter than its minimum height
    column.move_boundary(0, 10_000.0)
    assert column.sizes()[1] == panel.stack.plots[1].MIN_HEIGHT
    # the heights are saved and restored with the other settings, and kept on a resize
    column.setSizes([100, 300, 100, 100])
    state = panel.settings.state()
    panel.set_layout(LAYOUT)
    panel.settings.restore_state(state)
    got = column.sizes()
    assert got[1] == max(got) and got[1] == pytest.approx(3 * got[0], rel=0.05)
    panel.resize(900, 900)
    qtbot.waitUntil(lambda: column.stack.rect().height() > height + 100, timeout=5000)
    grown = column.sizes()
    assert grown[1] == pytest.approx(3 * grown[0], rel=0.05) and grown[0] > got[0]


def test_adding_and_removing_plots_keeps_the_scene_clean(panel, dictionary):
    panel.set_layout(LAYOUT)
    panel.stack.remove_plot(1)
    panel.stack.add_plot(0)
    panel.set_layout([["HIGH_RATE.error_angle"], ["HIGH_RATE.gyro_rate"]])
    QApplication.sendPostedEvents(None, QEvent.Type.DeferredDelete)
    import pyqtgraph as pg
    items = [i for i in panel.column.scene().items() if isinstance(i, pg.PlotItem)]
    assert len(items) == 2 and len(panel.column._handles) == 1
    _feed(panel, dictionary, 0, 1200)
    panel.refresh()                                    # the remaining plots still draw
    assert len(panel.stack.plots[1].curves["HIGH_RATE.gyro_rate"].getData()[0]) == 1200


def test_drop_lands_on_the_plot_under_the_mouse(panel):
    panel.set_layout([["HIGH_RATE.error_angle"], ["HIGH_RATE.encoder_outer"], []])
    mime = QMimeData()
    mime.setText("HIGH_RATE.gyro_rate\n")
    at = QPointF(_plot_centre(panel, 2))
    enter = QDragEnterEvent(at.toPoint(), Qt.DropAction.CopyAction, mime,
                            Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier)
    panel.column.dragEnterEvent(enter)
    assert enter.isAccepted()
    drop = QDropEvent(at, Qt.DropAction.CopyAction, mime,
                      Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier)
    panel.column.dropEvent(drop)
    assert panel.stack.layout_ids()[2] == ["HIGH_RATE.gyro_rate"]


def test_cursor_follows_the_mouse_over_any_plot(panel, dictionary):
    panel.set_layout(LAYOUT)
    _feed(panel, dictionary, 0, 2400)
    panel.set_window_seconds(2.0)
    panel.refresh()
    vp = panel.column.viewport()
    pos = _plot_centre(panel, 2)
    ev = QMouseEvent(QEvent.Type.MouseMove, QPointF(pos), QPointF(vp.mapToGlobal(pos)),
                     Qt.MouseButton.NoButton, Qt.MouseButton.NoButton, Qt.KeyboardModifier.NoModifier)
    QApplication.sendEvent(vp, ev)
    lo, hi = panel.stack.plots[0].x_range()
    assert all(p.cursor.isVisible() for p in panel.stack.plots)
    assert panel.stack.plots[0].cursor.value() == pytest.approx((lo + hi) / 2, abs=0.05)
    assert "error_angle" in panel.readout.text()
    QApplication.sendEvent(panel.column, QEvent(QEvent.Type.Leave))
    assert not any(p.cursor.isVisible() for p in panel.stack.plots)
