"""Strip charts: stacked plots on a shared time axis, pulled from the telemetry store.

The panel owns no data and does no I/O: a `QTimer` (~30 Hz, only while the panel is
visible) takes a snapshot of the channels on screen from the `TelemetryStore` the
receiver (or replay) fills, and redraws.  Per redraw and channel: one numpy slice to the
visible time range, `with_gap_breaks` (a NaN after every sequence gap, so the line
breaks instead of bridging lost frames), then `peak_decimate` to about two points per
horizontal pixel (min and max of each pixel column, so a one-sample spike is never
hidden).  Items are created once and updated with `setData`; gap markers come from a
fixed pool of `InfiniteLine`s.

Timebases:
- "device": seconds since the device booted (the tick counter / 1200 Hz).  Exact,
  free of host scheduling jitter; the default.
- "host": wall-clock time on a date axis (local time).  Frames arrive in bursts (one
  host stamp per datagram or block), so a sample is placed at its device time plus
  the smallest host−device offset seen in the window: the host clock's reading of
  the sample without queueing delay.  Gaps and the cursor use the same mapping.

Pausing freezes the picture at the newest sample of each packet; the store keeps
filling, and while paused the time axis can be panned and zoomed over the frozen
data at full resolution.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtWidgets import (QCheckBox, QComboBox, QHBoxLayout, QLabel, QMenu, QPushButton,
                               QSplitter, QVBoxLayout, QWidget)

from ..dictionary import Dictionary
from ..display_buffers import TelemetryStore, peak_decimate, with_gap_breaks
from .chart_plot import ChartPlot
from .channel_tree import (ChannelInfo, DisplayUnit, channel_catalog,
                           display_unit, format_value)

_EMPTY = np.empty(0)         # the data of a curve with nothing to show

log = logging.getLogger(__name__)

WINDOW_PRESETS_S = (1, 2, 5, 10, 20, 30, 60, 120, 300, 600)
WINDOW_MIN_S, WINDOW_MAX_S = 1.0, 600.0
TIMEBASES = ("device", "host")
REFRESH_HZ = 30.0
STATE_VERSION = 1


@dataclass(frozen=True)
class ChartStats:
    """Rendering figures for the status bar and the benchmark."""

    fps: float                 # redraws in the last second
    last_refresh_ms: float     # duration of the last refresh (snapshot + decimate + setData)
    points: int                # points handed to the curves in the last refresh
    decimation: int            # largest samples-per-bin factor in the last refresh (1: none)


@dataclass
class _Series:
    """One packet's samples as fetched for a redraw (oldest first)."""

    device_time: np.ndarray
    host_offset: float         # host clock − device clock (s), see the module docstring
    values: dict[str, np.ndarray]
    gap_times: np.ndarray      # device time of the first sample after each gap
    gap_sizes: np.ndarray

    def x(self, timebase: str) -> np.ndarray:
        return self.device_time + self.host_offset if timebase == "host" else self.device_time

    def gap_x(self, timebase: str) -> np.ndarray:
        return self.gap_times + self.host_offset if timebase == "host" else self.gap_times


def _window_label(seconds: float) -> str:
    return f"{seconds / 60:g} min" if seconds >= 60 else f"{seconds:g} s"


class StripChartPanel(QWidget):
    """Stacked strip charts with a toolbar (window, timebase, pause, add plot)."""

    sig_layout_changed = Signal()
    sig_paused_changed = Signal(bool)

    def __init__(self, store: TelemetryStore, dictionary: Dictionary,
                 parent: QWidget | None = None):
        super().__init__(parent)
        self.store = store
        self.dictionary = dictionary
        self.catalog: dict[str, ChannelInfo] = channel_catalog(dictionary)
        self.plots: list[ChartPlot] = []
        self._window_s = 10.0
        self._timebase = "device"
        self._paused = False
        self._frozen_end: dict[str, float] | None = None   # packet -> device time
        self._series: dict[str, _Series] = {}
        self._need_fetch = True
        self._render_pending = True
        self._snap_x = True            # paused: the next redraw still shows the whole window
        self._colours: dict[str, int] = {}
        self._frame_times: deque[float] = deque()
        self._last_ms = 0.0
        self._points = 0
        self._decimation = 1
        self._cursor_x: float | None = None
        self._build_ui()
        self.set_layout([[]])
        self._timer = QTimer(self)
        self._timer.setInterval(int(1000 / REFRESH_HZ))
        self._timer.timeout.connect(self._on_timer)
        self._timer.start()

    # ------------------------------------------------------------------ widgets
    def _build_ui(self) -> None:
        self.window_combo = QComboBox(self)
        for s in WINDOW_PRESETS_S:
            self.window_combo.addItem(_window_label(s), float(s))
        self.window_combo.setToolTip("Length of the time window shown (1 s … 10 min)")
        self.timebase_combo = QComboBox(self)
        self.timebase_combo.addItem("Device time", "device")
        self.timebase_combo.addItem("Host time", "host")
        self.timebase_combo.setToolTip("Device: s since boot (tick/1200 Hz); "
                                       "host: wall clock of the ground station")
        self.pause_button = QPushButton("Pause", self)
        self.pause_button.setCheckable(True)
        self.pause_button.setToolTip("Freeze the charts; data keeps arriving")
        self.add_plot_button = QPushButton("Add plot", self)
        self.autoscale_all = QCheckBox("Autoscale", self)
        self.autoscale_all.setChecked(True)
        self.autoscale_all.setToolTip("Autoscale the y axis of every plot "
                                      "(per plot: right-click → Chart)")
        self.info_label = QLabel(self)
        self.info_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        bar = QHBoxLayout()
        bar.setContentsMargins(2, 2, 2, 2)
        for label, w in (("Window", self.window_combo), ("Time", self.timebase_combo)):
            bar.addWidget(QLabel(label, self))
            bar.addWidget(w)
        bar.addWidget(self.pause_button)
        bar.addWidget(self.autoscale_all)
        bar.addWidget(self.add_plot_button)
        bar.addStretch(1)
        bar.addWidget(self.info_label)
        self.splitter = QSplitter(Qt.Orientation.Vertical, self)
        self.splitter.setChildrenCollapsible(False)
        self.readout = QLabel(self)
        self.readout.setWordWrap(True)
        self.readout.setTextFormat(Qt.TextFormat.RichText)
        self.readout.setStyleSheet("background: black; color: #dddddd; padding: 2px")
        self.readout.setText("<i>Drop channels from the channel tree onto a plot; "
                             "move the mouse over a plot for values.</i>")
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(2)
        layout.addLayout(bar)
        layout.addWidget(self.splitter, 1)
        layout.addWidget(self.readout)
        self.window_combo.setCurrentIndex(WINDOW_PRESETS_S.index(10))
        self.window_combo.currentIndexChanged.connect(
            lambda i: self.set_window_seconds(self.window_combo.itemData(i)))
        self.timebase_combo.currentIndexChanged.connect(
            lambda i: self.set_timebase(self.timebase_combo.itemData(i)))
        self.pause_button.toggled.connect(self.set_paused)
        self.add_plot_button.clicked.connect(lambda: self.add_plot())
        self.autoscale_all.toggled.connect(self._on_autoscale_all)

    # ------------------------------------------------------------------ layout
    def is_valid_channel(self, channel_id: str) -> bool:
        packet, _, name = channel_id.partition(".")
        ring = self.store.rings.get(packet)
        return ring is not None and name in ring.channels

    def _check(self, channel_id: str) -> None:
        if not self.is_valid_channel(channel_id):
            raise ValueError(f"unknown channel {channel_id!r}: use 'PACKET.channel' with a "
                             f"periodic packet, e.g. 'HIGH_RATE.encoder_outer'")

    def unit_of(self, channel_id: str) -> DisplayUnit:
        info = self.catalog.get(channel_id)
        return display_unit(info.units if info else "")

    def set_layout(self, layout: list[list[str]]) -> None:
        """Replace all plots: one list of channel ids per plot, top to bottom."""
        for ids in layout:
            for cid in ids:
                self._check(cid)
        for plot in self.plots:
            plot.setParent(None)
            plot.deleteLater()
        self.plots = []
        self._colours.clear()
        for ids in layout or [[]]:
            plot = self._new_plot(len(self.plots))
            for cid in ids:
                self._add_curve(plot, cid)
        self._relayout()

    def layout_ids(self) -> list[list[str]]:
        return [list(p.curves) for p in self.plots]

    def add_plot(self, index: int | None = None) -> int:
        """Insert an empty plot (at the bottom by default); returns its index."""
        index = len(self.plots) if index is None else index
        if not 0 <= index <= len(self.plots):
            raise IndexError(f"plot index {index} outside 0..{len(self.plots)}")
        self._new_plot(index)
        self._relayout()
        return index

    def remove_plot(self, index: int) -> None:
        plot = self.plots.pop(index)
        for cid in plot.curves:
            if not self._shown_elsewhere(cid, None):
                self._colours.pop(cid, None)
        plot.setParent(None)
        plot.deleteLater()
        if not self.plots:
            self._new_plot(0)
        self._relayout()

    def add_channel(self, channel_id: str, plot_index: int | None = None) -> int:
        """Show a channel; returns the plot index it went to.

        plot_index None: the first plot already showing the same units, else the first
        empty plot, else a new plot at the bottom.  plot_index == number of plots: a
        new plot at the bottom."""
        self._check(channel_id)
        if plot_index is None:
            plot_index = self._plot_for(channel_id)
        if plot_index == len(self.plots):
            self._new_plot(plot_index)
        elif not 0 <= plot_index < len(self.plots):
            raise IndexError(f"plot index {plot_index} outside 0..{len(self.plots)}")
        self._add_curve(self.plots[plot_index], channel_id)
        self._relayout()
        return plot_index

    def remove_channel(self, channel_id: str, plot_index: int) -> None:
        plot = self.plots[plot_index]
        plot.remove_curve(channel_id)
        if not self._shown_elsewhere(channel_id, None):
            self._colours.pop(channel_id, None)
        self._relayout()

    def move_channel(self, channel_id: str, source: int, target: int) -> None:
        """Move a channel from plot `source` to plot `target` (== count: a new plot)."""
        if channel_id not in self.plots[source].curves:
            raise ValueError(f"{channel_id} is not on plot {source + 1}")
        if source == target:
            return
        if target == len(self.plots):
            self._new_plot(target)
        self.plots[source].remove_curve(channel_id)
        self._add_curve(self.plots[target], channel_id)
        self._relayout()

    def drop_channels(self, ids: list[str], plot_index: int) -> list[str]:
        """Add dropped ids (unknown ones are ignored and logged); returns those added."""
        added = []
        for cid in ids:
            if self.is_valid_channel(cid):
                self.add_channel(cid, plot_index)
                added.append(cid)
            else:
                log.warning("dropped text %r is not a chartable channel id; ignored", cid)
        return added

    def _plot_for(self, channel_id: str) -> int:
        units = self.unit_of(channel_id).units
        for i, plot in enumerate(self.plots):
            if plot.curves and channel_id not in plot.curves and all(
                    self.unit_of(c).units == units for c in plot.curves):
                return i
        for i, plot in enumerate(self.plots):
            if not plot.curves:
                return i
        return len(self.plots)

    def _shown_elsewhere(self, channel_id: str, exclude: ChartPlot | None) -> bool:
        return any(channel_id in p.curves for p in self.plots if p is not exclude)

    def _colour_for(self, channel_id: str) -> int:
        if channel_id not in self._colours:
            used = set(self._colours.values())
            free = [i for i in range(len(ChartPlot.PALETTE)) if i not in used]
            self._colours[channel_id] = free[0] if free else len(self._colours) % len(
                ChartPlot.PALETTE)
        return self._colours[channel_id]

    def _add_curve(self, plot: ChartPlot, channel_id: str) -> None:
        if channel_id in plot.curves:
            return
        info = self.catalog.get(channel_id)
        plot.add_curve(channel_id, info.name if info else channel_id,
                       self.unit_of(channel_id), self._colour_for(channel_id),
                       info.description if info else "")

    def _new_plot(self, index: int) -> ChartPlot:
        plot = ChartPlot(self)
        plot.set_timebase(self._timebase)
        plot.sig_dropped.connect(lambda ids, p=plot: self.drop_channels(ids, self.plots.index(p)))
        plot.sig_menu_about_to_show.connect(self._fill_menu)
        plot.sig_mouse_x.connect(self.set_cursor)
        plot.sig_x_range_changed.connect(self._on_x_range_changed)
        plot.set_autoscale(self.autoscale_all.isChecked())
        self.plots.insert(index, plot)
        self.splitter.insertWidget(index, plot)
        return plot

    def _relayout(self) -> None:
        """After any change of the plots: X links, which plot shows the time axis."""
        master = self.plots[0].getPlotItem()
        for i, plot in enumerate(self.plots):
            plot.getPlotItem().setXLink(master if i else None)
            plot.time_axis.set_shown(i == len(self.plots) - 1)
            plot.set_mouse_x(self._paused)
        self._need_fetch = True
        self._render_pending = True
        self.sig_layout_changed.emit()

    def _fill_menu(self, plot: ChartPlot) -> None:
        """The plot's right-click "Chart" menu, rebuilt each time it opens."""
        menu = plot.chart_menu
        menu.clear()
        for old in plot.channel_menus.values():      # submenus are children: free them
            old.deleteLater()
        plot.channel_menus = {}
        index = self.plots.index(plot)
        auto = menu.addAction("Autoscale Y")
        auto.setCheckable(True)
        auto.setChecked(plot.autoscale)
        auto.toggled.connect(plot.set_autoscale)
        menu.addAction("Fix Y range as shown", lambda: plot.set_y_range(*plot.y_range()))
        menu.addSeparator()
        for cid in plot.curves:
            # keep the wrapper: PySide invalidates one fetched back through QAction.menu()
            sub = plot.channel_menus[cid] = QMenu(cid, menu)
            menu.addMenu(sub)
            for t in range(len(self.plots) + 1):
                if t != index:
                    label = f"Move to plot {t + 1}" if t < len(self.plots) else "Move to a new plot"
                    sub.addAction(label, lambda c=cid, t=t: self.move_channel(c, index, t))
            sub.addAction("Remove", lambda c=cid: self.remove_channel(c, index))
        menu.addSeparator()
        menu.addAction("Add plot below", lambda: self.add_plot(index + 1))
        menu.addAction("Remove this plot", lambda: self.remove_plot(index))

    # ------------------------------------------------------------------ settings
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
            plot.set_timebase(timebase)
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
        self._frozen_end = self._newest_times() if paused else None
        self.pause_button.blockSignals(True)
        self.pause_button.setChecked(paused)
        self.pause_button.setText("Resume" if paused else "Pause")
        self.pause_button.blockSignals(False)
        for plot in self.plots:
            plot.set_mouse_x(paused)
        self._need_fetch = self._render_pending = self._snap_x = True
        self.sig_paused_changed.emit(paused)

    def _newest_times(self) -> dict[str, float]:
        """Device time of every packet's newest sample (a zero-length snapshot)."""
        out = {}
        for name, ring in self.store.rings.items():
            dev = ring.snapshot([], seconds=0.0).device_time
            if len(dev):
                out[name] = float(dev[-1])
        return out

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
            "heights": self.splitter.sizes(),
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
            self.splitter.setSizes([int(h) for h in heights])

    # ------------------------------------------------------------------ drawing
    @property
    def stats(self) -> ChartStats:
        now = time.perf_counter()
        while self._frame_times and now - self._frame_times[0] > 1.0:
            self._frame_times.popleft()
        return ChartStats(float(len(self._frame_times)), self._last_ms, self._points,
                          self._decimation)

    def _on_timer(self) -> None:
        if not self.isVisible():
            return
        if self._paused and not (self._render_pending or self._need_fetch):
            return
        self.refresh()

    def _on_x_range_changed(self) -> None:
        if self._paused:                           # re-decimate the frozen data for the new zoom
            self._render_pending = True

    def refresh(self) -> None:
        """Fetch (unless paused) and redraw every plot."""
        t0 = time.perf_counter()
        if not self._paused or self._need_fetch:
            self._series = self._fetch()
            self._need_fetch = False
        self._render()
        self._render_pending = False
        end = time.perf_counter()
        self._last_ms = (end - t0) * 1000.0
        self._frame_times.append(end)
        while end - self._frame_times[0] > 1.0:
            self._frame_times.popleft()

    def _fetch(self) -> dict[str, _Series]:
        wanted: dict[str, set[str]] = {}
        for plot in self.plots:
            for cid in plot.curves:
                packet, _, name = cid.partition(".")
                wanted.setdefault(packet, set()).add(name)
        out = {}
        for packet, names in wanted.items():
            ring = self.store.rings.get(packet)
            if ring is None:
                continue
            if self._frozen_end is None:
                snap = ring.snapshot(sorted(names), seconds=self._window_s)
                dev, values = snap.device_time, snap.values
                gaps, sizes = snap.gap_device_times, snap.gap_sizes
            else:
                end = self._frozen_end.get(packet, -math.inf)
                snap = ring.snapshot(sorted(names))
                dev = snap.device_time
                i0 = int(np.searchsorted(dev, end - self._window_s, side="left"))
                i1 = int(np.searchsorted(dev, end, side="right"))
                dev = dev[i0:i1]
                values = {k: v[i0:i1] for k, v in snap.values.items()}
                keep = snap.gap_device_times <= end
                gaps, sizes = snap.gap_device_times[keep], snap.gap_sizes[keep]
            if not len(dev):
                continue
            host = snap.host_time if self._frozen_end is None else snap.host_time[i0:i1]
            offset = float(np.nanmin(host - dev)) if np.isfinite(host).any() else 0.0
            out[packet] = _Series(dev, offset, values, gaps, sizes)
        return out

    def _live_x_range(self) -> tuple[float, float]:
        ends = [s.x(self._timebase)[-1] for s in self._series.values()]
        if ends:
            end = max(ends)
        else:
            end = time.time() if self._timebase == "host" else 0.0
        return end - self._window_s, end

    def _render(self) -> None:
        master = self.plots[0]
        if self._paused and not self._snap_x:
            lo, hi = master.x_range()
        else:
            lo, hi = self._live_x_range()
            master.getPlotItem().setXRange(lo, hi, padding=0)
            self._snap_x = False
        bins = max(64, int(master.plot_width()))
        points, worst = 0, 1
        for plot in self.plots:
            gap_x: dict[str, np.ndarray] = {}
            gap_n: dict[str, np.ndarray] = {}
            plot_worst = 1
            for cid, curve in plot.curves.items():
                packet, _, name = cid.partition(".")
                series = self._series.get(packet)
                if series is None or name not in series.values:
                    curve.setData(_EMPTY, _EMPTY)
                    continue
                x = series.x(self._timebase)
                i0 = max(int(np.searchsorted(x, lo, side="left")) - 1, 0)
                i1 = int(np.searchsorted(x, hi, side="right")) + 1
                xs, ys = x[i0:i1], series.values[name][i0:i1]
                scale = plot.units[cid].scale
                if scale != 1.0:
                    ys = ys * scale
                gx = series.gap_x(self._timebase)
                xs, ys = with_gap_breaks(xs, ys, gx)
                xd, yd, decimated = peak_decimate(xs, ys, bins)
                if decimated:
                    plot_worst = max(plot_worst, math.ceil(len(ys) / bins))
                has_nan = bool(np.isnan(yd).any())
                curve.setData(xd, yd, connect="finite", skipFiniteCheck=not has_nan)
                points += len(yd)
                gap_x[packet], gap_n[packet] = gx, series.gap_sizes
            gx = np.concatenate(list(gap_x.values())) if gap_x else np.empty(0)
            gn = np.concatenate(list(gap_n.values())) if gap_n else np.empty(0, dtype=np.int64)
            inside = (gx >= lo) & (gx <= hi)
            plot.show_gaps(gx[inside], gn[inside])
            plot.show_decimation(plot_worst)
            if plot.autoscale:      # now, not in the paint: saves a second paint per frame
                plot.getPlotItem().getViewBox().updateAutoRange()
            worst = max(worst, plot_worst)
        self._points, self._decimation = points, worst
        if self._cursor_x is not None:
            self.set_cursor(self._cursor_x)
        s = self.stats
        self.info_label.setText(f"{s.fps:.0f} fps · {s.last_refresh_ms:.1f} ms"
                                + (" · <b>paused</b>" if self._paused else ""))

    # ------------------------------------------------------------------ cursor
    def set_cursor(self, x: float | None) -> None:
        """Place the read-out cursor at time x (None hides it) and fill the read-out."""
        self._cursor_x = x
        for plot in self.plots:
            plot.set_cursor(x)
        if x is None:
            return
        self.readout.setText(self.cursor_readout(x))

    def cursor_readout(self, x: float) -> str:
        """Time and every channel's value at time x (the newest sample at or before x)."""
        if self._timebase == "host":
            t = time.strftime("%H:%M:%S", time.localtime(x)) + f".{int((x % 1) * 1000):03d}"
        else:
            t = f"{x:.4f} s"
        parts = [f"<b>t = {t}</b>"]
        for plot in self.plots:
            for cid, curve in plot.curves.items():
                packet, _, name = cid.partition(".")
                value = self.value_at(cid, x)
                colour = ChartPlot.PALETTE[self._colours.get(cid, 0)]
                parts.append(f"<span style='color:{colour}'>{name}</span> "
                             f"{format_value(value, plot.units[cid])}")
        return " &nbsp;│&nbsp; ".join(parts)

    def value_at(self, channel_id: str, x: float) -> float:
        """The value (display units) of the newest sample at or before x; NaN when that
        sample is more than 1.5 sample periods older than x (a gap, or no data yet)."""
        packet, _, name = channel_id.partition(".")
        series = self._series.get(packet)
        if series is None or name not in series.values:
            return math.nan
        t = series.x(self._timebase)
        i = int(np.searchsorted(t, x, side="right")) - 1
        rate = self.dictionary.packet(packet).rate_hz or 1.0
        if i < 0 or x - t[i] > 1.5 / rate:
            return math.nan
        return float(series.values[name][i]) * self.unit_of(channel_id).scale
