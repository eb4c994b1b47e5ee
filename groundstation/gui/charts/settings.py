"""The strip chart's settings: the time window, the timebase, pause, autoscale and fixed
y ranges (what the toolbar and the plots' menus set, kept in step with the toolbar), and
their persistence (`state` / `restore_state`, for QSettings).

A part of `StripChartPanel` (charts/panel.py), which provides `store`, `plots`, the toolbar's
widgets, `column` (the plots' view and their heights), the redraw flags, `sig_paused_changed` and (from its plot stack)
`set_layout`, `layout_ids` and `is_valid_channel`.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from .data import TIMEBASES, WINDOW_MAX_S, WINDOW_MIN_S, _window_label, newest_times

if TYPE_CHECKING:
    from PySide6.QtWidgets import QComboBox, QPushButton

    from ...live.display_buffers import TelemetryStore
    from .column import PlotColumn
    from .plot import ChartPlot

# the panel's logger, as these messages always were
log = logging.getLogger("groundstation.gui.charts.panel")

STATE_VERSION = 1


class ChartSettings:
    """Window, timebase, pause, autoscale and y ranges; `state` and `restore_state`."""

    # provided by the panel shell (StripChartPanel)
    store: TelemetryStore
    plots: list[ChartPlot]
    window_combo: QComboBox
    timebase_combo: QComboBox
    pause_button: QPushButton
    column: PlotColumn
    _window_s: float
    _timebase: str
    _paused: bool
    _frozen_end: dict[str, float] | None
    _cursor_x: float | None
    _need_fetch: bool
    _render_pending: bool
    _snap_x: bool

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
        self._need_fetch = self._render_pending = self._snap_x = True

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
        for plot in self.plots:
            plot.set_time_mode(timebase, relative=not self._paused)
        self._cursor_x = None
        self._render_pending = self._snap_x = True

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
        for plot in self.plots:
            plot.set_mouse_x(paused)
            plot.set_time_mode(self._timebase, relative=not paused)
        self._need_fetch = self._render_pending = self._snap_x = True
        self.sig_paused_changed.emit(paused)

    def set_autoscale(self, plot_index: int, enabled: bool = True) -> None:
        self.plots[plot_index].set_autoscale(enabled)

    def set_y_range(self, plot_index: int, low: float, high: float) -> None:
        """Fix a plot's y range (in display units, e.g. rad not µrad); ends autoscale."""
        self.plots[plot_index].set_y_range(low, high)

    def _on_autoscale_all(self, on: bool) -> None:
        for plot in self.plots:
            plot.set_autoscale(on)

    def state(self) -> dict:
        """JSON-serialisable settings (for QSettings: store json.dumps of it)."""
        return {
            "version": STATE_VERSION,
            "layout": self.layout_ids(),
            "window_s": self._window_s,
            "timebase": self._timebase,
            "y": [{"auto": p.autoscale, "range": list(p.y_range())} for p in self.plots],
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
            keep = [c for c in ids if isinstance(c, str) and self.is_valid_channel(c)]
            for c in ids:
                if c not in keep:
                    log.warning("strip-chart settings: channel %r no longer exists; dropped", c)
            layout.append(keep)
        self.set_layout(layout)
        try:
            self.set_window_seconds(float(state.get("window_s", self._window_s)))
            self.set_timebase(state.get("timebase", self._timebase))
        except (TypeError, ValueError) as exc:
            log.warning("strip-chart settings: %s; default kept", exc)
        for plot, y in zip(self.plots, state.get("y") or []):
            try:                     # QSettings may hand back strings for numbers and bools
                if str(y.get("auto", True)).lower() in ("true", "1"):
                    plot.set_autoscale(True)
                else:
                    plot.set_y_range(float(y["range"][0]), float(y["range"][1]))
            except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
                log.warning("strip-chart settings: bad y range %r (%s); autoscale", y, exc)
                plot.set_autoscale(True)
        heights = state.get("heights")
        if isinstance(heights, list) and len(heights) == len(self.plots):
            self.column.setSizes([int(h) for h in heights])
