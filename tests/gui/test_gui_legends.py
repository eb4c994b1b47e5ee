"""Legends outside the data (issue: legend boxes sat over the traces and hid labels):
the design workbench's |PQ| plot and the base-motion PSD and CSP plots keep theirs
between the title and the data (the strip charts': test_gui_chart_items.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation.gui.generator.panel import GeneratorPanel
from groundstation.gui.panels.params import ParameterPanel
from groundstation.gui.session.session import Session

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def session(dictionary, tmp_path):
    s = Session(dictionary, store_seconds=1.0, param_history=tmp_path / "history")
    yield s
    s.shutdown()


def outside(plot, legend) -> bool:
    """The legend has entries and lies between the title and the data."""
    vb = plot.getViewBox().sceneBoundingRect()
    box = legend.sceneBoundingRect()
    title = plot.titleLabel.sceneBoundingRect()
    # the view box's rect is half a pixel larger, right and below (pyqtgraph's)
    return (bool(legend.items) and legend.isVisible() and box.height() > 0
            and box.bottom() <= vb.top() + 1
            and (not plot.titleLabel.isVisible() or box.top() >= title.bottom() - 1))


def test_the_workbench_legend_is_above_the_magnitude_plot(qtbot, session):
    params = ParameterPanel(session, session.d)
    qtbot.addWidget(params)
    assert params.load_design(ROOT / "profiles/controllers/relative_design2.toml")
    workbench = params.open_workbench()
    qtbot.addWidget(workbench)
    workbench.resize(1400, 900)
    workbench.show()
    plots = workbench.plots
    # laid out once the design's views are drawn
    qtbot.waitUntil(lambda: outside(plots.mag, plots.legend), timeout=30000)


def test_the_base_motion_legends_are_above_their_plots(qtbot, session):
    session.testbed = str(ROOT / "profiles/testbeds/inertial_2dof.toml")   # it has a base stage
    panel = GeneratorPanel(session)
    qtbot.addWidget(panel)
    panel.resize(1900, 420)
    panel.show()
    motion = panel.base_motion
    motion.set_profile_file(ROOT / "profiles/base_motion/BM3.csv")
    motion.duration.setValue(10.0)
    assert motion.preview() is not None
    qtbot.waitUntil(lambda: outside(motion.psd_plot, motion.psd_legend)
                    and outside(motion.csp_plot, motion.csp_legend), timeout=5000)
