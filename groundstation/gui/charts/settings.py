"""The strip chart's settings: the time window, the timebase, pause, autoscale and fixed
y ranges (what the toolbar and the plots' menus set, kept in step with the toolbar), and
their persistence (`state` / `restore_state`, for QSettings).

`ChartSettings` is owned by `StripChartPanel` (charts/panel.py).  It makes the toolbar's
controls for these settings (the panel places them) and is given the telemetry store
(the newest sample of each packet, frozen on pausing), the panel's `PlotStack` (the
plots the settings apply to, and the layout that is persisted) and the `PlotColumn`
(the plots' heights).  The panel redraws on its signals.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Signal
from PySide6.QtWidgets import QCheckBox, QComboBox, QPushButton, QWidget

from .data import (TIMEBASES, WINDOW_MAX_S, WINDOW_MIN_S, WINDOW_PRESETS_S, _window_label,
                   newest_times)

if TYPE_CHECKING:
    from ...live.display_buffers import TelemetryStore
    from .column import PlotColumn
    from .stack import PlotStack

# the panel's logger, as these messages always were
log = logging.getLogger("groundstation.gui.charts.panel")

STATE_VERSION = 1


class ChartSettings(QObject):
    """Window, timebase, pause, autoscale and y ranges; `state` and `restore_state`."""

    sig_window_changed = Signal()
    sig_timebase_changed = Signal()
    sig_paused_changed = Signal(bool)

    def __init__(self, store: TelemetryStore, stack: PlotStack, column: PlotColumn,
                 parent: QWidget):
        super().__init__(parent)
        self.store = store
        self.stack = stack
        self.column = column
        self._window_s = 10.0
        self._timebase = "device"
        self._paused = False
        self._frozen_end: dict[str, float] | None = None   # paused: packet -> device time
        self.window_combo = QComboBox(parent)
        for s in WINDOW_PRESETS_S:
            self.window_combo.addItem(_window_label(s), float(s))
        self.window_combo.setToolTip("Length of the time window shown (1 s … 10 min)")
        self.timebase_combo = QComboBox(parent)
        self.timebase_combo.addItem("Device time", "device")
        self.timebase_combo.addItem("Host time", "host")
        self.timebase_combo.setToolTip("Device: s since boot (tick/1200 Hz); "
                                       "host: wall clock of the ground station")
        self.pause_button = QPushButton("Pause", parent)
        self.pause_button.setCheckable(True)
        self.pause_button.setToolTip("Freeze the charts; data keeps arriving")
        self.autoscale_all = QCheckBox("Autoscale", parent)
        self.autoscale_all.setChecked(True)
        self.autoscale_all.setToolTip("Autoscale the y axis of every plot "
                                      "(per plot: right-click → Chart)")
        self.window_combo.setCurrentIndex(WINDOW_PRESETS_S.index(self._window_s))
        stack.set_time_mode(self._timebase, relative=not self._paused)
        stack.set_pan_x(self._paused)
        stack.set_autoscale_all(self.autoscale_all.isChecked())
        self.window_combo.currentIndexChanged.connect(
            lambda i: self.set_window_seconds(self.window_combo.itemData(i)))
        self.timebase_combo.currentIndexChanged.connect(
            lambda i: self.set_timebase(self.timebase_combo.itemData(i)))
        self.pause_button.toggled.connect(self.set_paused)
        self.autoscale_all.toggled.connect(stack.set_autoscale_all)

    @property
    def frozen_end(self) -> dict[str, float] | None:
        """While paused: each packet's newest device time when pausing; else None."""
        return self._frozen_end

    @property
    def window_seconds(self) -> float:
        return self._window_s

    def set_window_seconds(self, seconds: float) -> None:
        seconds = float(seconds)
        if not WINDOW_MIN_S <= seconds <= WINDOW_MAX_S:
            raise ValueError(f"window {seconds:g} s outside {WINDOW_MIN_S:g} … {WINDOW_MAX_S:g} s")
        self._window_s = seconds
        i = self.window_combo.findData(seconds)
        if i < 0:
            self.window_combo.addItem(_window_label(seconds), seconds)
            i = self.window_combo.count() - 1
        self.window_combo.blockSignals(True)
        self.window_combo.setCurrentIndex(i)
        self.window_combo.blockSignals(False)
        self.sig_window_changed.emit()

    @property
    def timebase(self) -> str:
        return self._timebase

    def set_timebase(self, timebase: str) -> None:
        if timebase not in TIMEBASES:
            raise ValueError(f"timebase must be one of {TIMEBASES}, not {timebase!r}")
        self._timebase = timebase
        self.timebase_combo.blockSignals(True)
        self.timebase_combo.setCurrentIndex(TIMEBASES.index(timebase))
        self.timebase_combo.blockSignals(False)
        self.stack.set_time_mode(timebase, relative=not self._paused)
        self.sig_timebase_changed.emit()

    @property
    def paused(self) -> bool:
        return self._paused

    def set_paused(self, paused: bool) -> None:
        paused = bool(paused)
        if paused == self._paused:
            return
        self._paused = paused
        self._frozen_end = newest_times(self.store) if paused else None
        self.pause_button.blockSignals(True)
        self.pause_button.setChecked(paused)
        self.pause_button.setText("Resume" if paused else "Pause")
        self.pause_button.blockSignals(False)
        self.stack.set_pan_x(paused)
        self.stack.set_time_mode(self._timebase, relative=not paused)
        self.sig_paused_changed.emit(paused)

    def set_autoscale(self, plot_index: int, enabled: bool = True) -> None:
        self.stack.plots[plot_index].set_autoscale(enabled)

    def set_y_range(self, plot_index: int, low: float, high: float) -> None:
        """Fix a plot's y range (in display units, e.g. rad not µrad); ends autoscale."""
        self.stack.plots[plot_index].set_y_range(low, high)

    def state(self) -> dict:
        """JSON-serialisable settings (for QSettings: store json.dumps of it)."""
        return {
            "version": STATE_VERSION,
            "layout": self.stack.layout_ids(),
            "window_s": self._window_s,
            "timebase": self._timebase,
            "y": [{"auto": p.autoscale, "range": list(p.y_range())} for p in self.stack.plots],
            "heights": self.column.sizes(),
        }

    def restore_state(self, state: dict) -> None:
        """Apply `state()` output; tolerant of settings from older protocol versions
        (unknown channels are dropped with a log message, bad values keep defaults)."""
        if not isinstance(state, dict):
            log.warning("strip-chart settings ignored: expected a dict, got %r", type(state))
            return
        layout = []
        for ids in state.get("layout") or [[]]:
            ids = ids if isinstance(ids, list) else []
            keep = [c for c in ids if isinstance(c, str) and self.stack.is_valid_channel(c)]
            for c in ids:
                if c not in keep:
                    log.warning("strip-chart settings: channel %r no longer exists; dropped", c)
            layout.append(keep)
        self.stack.set_layout(layout)
        try:
            self.set_window_seconds(float(state.get("window_s", self._window_s)))
            self.set_timebase(state.get("timebase", self._timebase))
        except (TypeError, ValueError) as exc:
            log.warning("strip-chart settings: %s; default kept", exc)
        for plot, y in zip(self.stack.plots, state.get("y") or []):
            try:                     # QSettings may hand back strings for numbers and bools
                if str(y.get("auto", True)).lower() in ("true", "1"):
                    plot.set_autoscale(True)
                else:
                    plot.set_y_range(float(y["range"][0]), float(y["range"][1]))
            except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
                log.warning("strip-chart settings: bad y range %r (%s); autoscale", y, exc)
                plot.set_autoscale(True)
        heights = state.get("heights")
        if isinstance(heights, list) and len(heights) == len(self.stack.plots):
            self.column.setSizes([int(h) for h in heights])
