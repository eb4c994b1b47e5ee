"""Layouts shared by the docked panels (the docks are wide and low)."""

from __future__ import annotations

from collections.abc import Iterable

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QHBoxLayout, QScrollArea, QSplitter, QWidget


def controls_beside_plots(columns: Iterable[QWidget], plots: QWidget, *, min_width: int,
                          plots_width: int, pad: int) -> QSplitter:
    """A horizontal splitter: the short control `columns` side by side in a scroll area on
    the left, `plots` on the right.  `min_width`: the least the controls may shrink to;
    `plots_width`: the plots' starting width; `pad`: room added to the controls' own width
    at the start (for a vertical scroll bar in a low dock)."""
    controls = QWidget()
    # short columns side by side, the plots beside them: the dock is wide and low
    row = QHBoxLayout(controls)
    row.setContentsMargins(0, 0, 0, 0)
    row.setSpacing(6)
    for column in columns:
        row.addWidget(column)
    scroll = QScrollArea()
    scroll.setWidget(controls)
    scroll.setWidgetResizable(True)
    scroll.setFrameShape(QScrollArea.Shape.NoFrame)
    # the panel must not set the window's minimum width: the splitter starts with all the
    # controls in view, the controls never collapse, and on a narrow screen the plots
    # give way first
    scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
    scroll.setMinimumWidth(min_width)
    split = QSplitter(Qt.Orientation.Horizontal)
    split.addWidget(scroll)
    split.addWidget(plots)
    split.setStretchFactor(0, 0)
    split.setStretchFactor(1, 1)
    split.setCollapsible(0, False)
    split.setSizes([controls.sizeHint().width() + pad, plots_width])
    return split
