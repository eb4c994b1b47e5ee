"""Strip charts: stacked plots on a shared time axis, pulled from the telemetry store.

The panel owns no data and does no I/O: a `QTimer` (~30 Hz, only while the panel is
visible) asks the `TelemetryStore` the receiver (or replay) fills for what to draw.  Live,
each packet's ring answers from its min/max pyramids (`PacketRing.envelope`): the samples
themselves while there are at most two per horizontal pixel, else the min and max of
each bin of a power-of-two number of samples, aligned to the sample count, so a
one-sample spike is never hidden and only the samples that arrived since the last frame
are reduced.  A NaN point before the first sample after each sequence gap breaks the
line instead of bridging lost frames.  Curves (`ChartCurve`) are created once and
updated with `setData` (finite data skip pyqtgraph's finite check); gap markers come
from a fixed pool of `InfiniteLine`s.

Timebases:
- "device": seconds since the device booted (the tick counter / 1200 Hz).  Exact,
  free of host scheduling jitter; the default.
- "host": wall-clock time on a date axis (local time).  Frames arrive in bursts (one
  host stamp per datagram or block), so a sample is placed at its device time plus
  the smallest host−device offset seen in the window: the host clock's reading of
  the sample without queueing delay.  Gaps and the cursor use the same mapping.

Live, the time axis reads seconds before the newest sample (-window … 0) and stays put
while the curves move under it (see charts/plot.py: a scrolling axis cost more than the
curves); the toolbar names the newest sample's time (device seconds, or the wall clock in
host time), and the cursor read-out gives the absolute time of any point.  Pausing
freezes the picture at the newest sample of each packet and switches the axis to
absolute time: the shown channels are copied once, the store keeps filling, and while
paused the time axis can be panned and zoomed over the frozen data at full resolution
(binned as live, `frozen_trace`).

The panel draws; its parts are objects it owns, each with a module of its own:
`stack` (a `PlotStack`: the plots and the channels on them, charts/stack.py) and
`settings` (a `ChartSettings`: window, timebase, pause, y ranges and their persistence,
charts/settings.py).  What is fetched from the store, without Qt, is in charts/data.py,
and one plot is a `ChartPlot` (charts/plot.py).
"""

from __future__ import annotations

import math
import time
from collections import deque

import numpy as np
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtWidgets import QFrame, QHBoxLayout, QLabel, QPushButton, QScrollArea, QVBoxLayout, QWidget

from ...core.dictionary import Dictionary
from ...live.display_buffers import TelemetryStore, insert_breaks
from .channel_tree import channel_catalog, format_value
from .data import ChartStats, _Series, _Trace, fetch_series, frozen_trace
from .column import PlotColumn
from ..common.steady_label import SteadyLabel
from .settings import ChartSettings
from .stack import PlotStack

_EMPTY = np.empty(0)         # the data of a curve with nothing to show

REFRESH_HZ = 30.0


class StripChartPanel(QWidget):
    """Stacked strip charts with a toolbar (window, timebase, pause, add plot)."""

    sig_layout_changed = Signal()
    sig_paused_changed = Signal(bool)

    def __init__(self, store: TelemetryStore, dictionary: Dictionary,
                 parent: QWidget | None = None):
        super().__init__(parent)
        self.store = store
        self.dictionary = dictionary
        self._series: dict[str, _Series] = {}               # paused: the frozen data
        self._offsets: dict[str, float] = {}                # live: host − device time (s)
        self._drawn_key: tuple | None = None                # live: what the picture shows
        self._need_fetch = True
        self._render_pending = True
        self._snap_x = True            # paused: the next redraw still shows the whole window
        self._frame_times: deque[float] = deque()
        self._last_ms = 0.0
        self._points = 0
        self._decimation = 1
        self._cursor_x: float | None = None
        self._info_at = -1.0                # when the toolbar's figures were last set
        self._info_paused = False
        self._newest: float | None = None   # live: absolute time of the newest sample shown
        # all plots in one view: one paint event and one scene traversal a frame
        self.column = PlotColumn(self)
        self.stack = PlotStack(store, channel_catalog(dictionary), self.column, self)
        self.settings = ChartSettings(store, self.stack, self.column, self)
        self._build_ui()
        self.column.sig_left.connect(lambda: self.set_cursor(None))
        self.stack.sig_layout_changed.connect(self._on_layout_changed)
        self.stack.sig_mouse_x.connect(self.set_cursor)
        self.stack.sig_x_range_changed.connect(self._on_x_range_changed)
        self.settings.sig_window_changed.connect(self._on_window_changed)
        self.settings.sig_timebase_changed.connect(self._on_timebase_changed)
        self.settings.sig_paused_changed.connect(self._on_paused_changed)
        self.stack.set_layout([[]])
        self._timer = QTimer(self)
        self._timer.setInterval(int(1000 / REFRESH_HZ))
        self._timer.timeout.connect(self._on_timer)
        self._timer.start()

    # ------------------------------------------------------------------ widgets
    def _build_ui(self) -> None:
        self.add_plot_button = QPushButton("Add plot", self)
        self.add_plot_button.clicked.connect(lambda: self.stack.add_plot())
        self.info_label = SteadyLabel("", self)     # new figures twice a second: no relayout
        self.info_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        settings = self.settings
        bar = QHBoxLayout()
        bar.setContentsMargins(2, 2, 2, 2)
        for label, w in (("Window", settings.window_combo), ("Time", settings.timebase_combo)):
            bar.addWidget(QLabel(label, self))
            bar.addWidget(w)
        bar.addWidget(settings.pause_button)
        bar.addWidget(settings.autoscale_all)
        bar.addWidget(self.add_plot_button)
        bar.addWidget(_room_for(self.info_label), 1)
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
        layout.addWidget(self.column, 1)
        layout.addWidget(self.readout)

    # ------------------------------------------------------------------ what the window asks
    # The main window and the demo set up the charts through these verbs; the rest of
    # the charts' surface is on `stack` and `settings`.
    def set_layout(self, layout: list[list[str]]) -> None:
        """Replace all plots: one list of channel ids per plot, top to bottom."""
        self.stack.set_layout(layout)

    def set_window_seconds(self, seconds: float) -> None:
        self.settings.set_window_seconds(seconds)

    def set_paused(self, paused: bool) -> None:
        self.settings.set_paused(paused)

    # ------------------------------------------------------------------ what needs a redraw
    def _on_layout_changed(self) -> None:
        self._need_fetch = self._render_pending = True
        self.sig_layout_changed.emit()

    def _on_window_changed(self) -> None:
        self._need_fetch = self._render_pending = self._snap_x = True

    def _on_timebase_changed(self) -> None:
        self._cursor_x = None
        self._render_pending = self._snap_x = True

    def _on_paused_changed(self, paused: bool) -> None:
        self._need_fetch = self._render_pending = self._snap_x = True
        self.sig_paused_changed.emit(paused)

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
        paused = self.settings.paused
        if paused and not (self._render_pending or self._need_fetch):
            return
        if not paused and not self._render_pending and self._live_key() == self._drawn_key:
            return                     # nothing arrived, nothing changed: the picture stands
        self.refresh()

    def _live_key(self) -> tuple | None:
        """What a live picture depends on besides the settings (which set _render_pending):
        each shown packet's ring changes, and the width in bins.  None: always redraw."""
        rings = []
        for packet in sorted(self.stack.shown_by_packet()):
            ring = self.store.rings.get(packet)
            rings.append((packet, ring.changes if ring is not None else -1))
        if not rings and self.settings.timebase == "host":
            return None                # an empty host-time axis follows the clock
        return tuple(rings), self._bins()

    def _on_x_range_changed(self) -> None:
        if self.settings.paused:                   # re-decimate the frozen data for the new zoom
            self._render_pending = True

    def refresh(self) -> None:
        """Redraw every plot: live from the store's min/max pyramids, or paused from the
        data frozen when pausing."""
        t0 = time.perf_counter()
        if self.settings.paused:
            if self._need_fetch:
                self._series = fetch_series(self.store, self.stack.shown_by_packet(),
                                            self.settings.window_seconds,
                                            self.settings.frozen_end)
                self._need_fetch = False
            traces, lo, hi = self._frozen_traces()
        else:
            self._series = {}
            self._need_fetch = False
            self._drawn_key = self._live_key()
            traces, lo, hi = self._live_traces()
        self._render(traces, lo, hi)
        self._render_pending = False
        end = time.perf_counter()
        self._last_ms = (end - t0) * 1000.0
        self._frame_times.append(end)
        while end - self._frame_times[0] > 1.0:
            self._frame_times.popleft()

    def _bins(self) -> int:
        return max(64, int(self.stack.plots[0].plot_width()))

    def _place(self, origin: float, lo: float, hi: float) -> None:
        """Put absolute time `origin` at view x = 0 on every plot and show lo..hi (view x);
        the other plots follow the first through their x links."""
        relative = not self.settings.paused
        for plot in self.stack.plots:
            plot.set_time_mode(self.settings.timebase, relative)
            plot.set_origin(origin)
        self.stack.plots[0].set_x_view(lo, hi)

    def _live_traces(self) -> tuple[dict[str, _Trace], float, float]:
        """The newest window of every packet shown, min/max per bin from the pyramids
        (only the samples that arrived since the last frame are reduced)."""
        host = self.settings.timebase == "host"
        window_s = self.settings.window_seconds
        shown = self.stack.shown_by_packet()
        ends, offsets = [], {}
        for packet in shown:
            ring = self.store.rings.get(packet)
            newest = ring.newest_time() if ring is not None else None
            if newest is None:
                continue
            offsets[packet] = ring.host_offset(window_s) if host else 0.0
            ends.append(newest + offsets[packet])
        end = max(ends) if ends else (time.time() if host else 0.0)
        lo, hi = end - window_s, end
        self._place(end, -window_s, 0.0)
        self._newest = end if ends else None
        bins = self._bins()
        traces = {}
        for packet, names in shown.items():
            if packet not in offsets:
                continue
            off = offsets[packet]
            # the window starts at its first sample: none older (a live window is
            # the newest `window_s` seconds, exactly)
            env = self.store.rings[packet].envelope(sorted(names), lo - off, hi - off, bins,
                                                    before=False)
            if env is not None:
                traces[packet] = _Trace(env.x + off if off else env.x, env.values, env.per,
                                        env.breaks, env.gap_times + off, env.gap_sizes)
        self._offsets = offsets
        return traces, lo, hi

    def _frozen_traces(self) -> tuple[dict[str, _Trace], float, float]:
        """While paused: the frozen data between the plot's edges (zoom and pan freely),
        binned as the live view bins (aligned to the sample numbers)."""
        timebase = self.settings.timebase
        if self._snap_x:
            ends = [s.x(timebase)[-1] for s in self._series.values()]
            end = max(ends) if ends else (time.time() if timebase == "host" else 0.0)
            self._place(0.0, end - self.settings.window_seconds, end)
            self._snap_x = False
        lo, hi = self.stack.plots[0].x_range()
        bins = self._bins()
        traces = {}
        for packet, series in self._series.items():
            traces[packet] = frozen_trace(series, timebase, lo, hi, bins)
        return traces, lo, hi

    def _render(self, traces: dict[str, _Trace], lo: float, hi: float) -> None:
        points, worst = 0, 1
        for plot in self.stack.plots:
            gap_x: dict[str, np.ndarray] = {}
            gap_n: dict[str, np.ndarray] = {}
            plot_worst = 1
            for cid, curve in plot.curves.items():
                packet, _, name = cid.partition(".")
                trace = traces.get(packet)
                if trace is None or name not in trace.values:
                    curve.set_points(_EMPTY, _EMPTY, lo, hi)
                    continue
                ys = trace.values[name]
                scale = plot.units[cid].scale
                if scale != 1.0:
                    ys = ys * scale
                xs, ys = insert_breaks(trace.x, ys, trace.breaks)
                curve.set_points(xs, ys, lo, hi)
                plot_worst = max(plot_worst, trace.per)
                points += len(ys)
                gap_x[packet], gap_n[packet] = trace.gap_x, trace.gap_sizes
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
        # The figures twice a second, not every frame: a label whose text changes asks
        # the window to lay itself out again.
        now = time.perf_counter()
        paused = self.settings.paused
        if now - self._info_at >= 0.5 or paused != self._info_paused:
            self._info_at, self._info_paused = now, paused
            s = self.stats
            self.info_label.setText(f"{s.fps:.0f} fps · {s.last_refresh_ms:.1f} ms · "
                                    + ("<b>paused</b>" if paused else
                                       self._newest_text()))

    def _newest_text(self) -> str:
        """The live axis's 0: the newest sample's time, as the timebase reads it."""
        t = self._newest
        if t is None:
            return "no data"
        if self.settings.timebase == "host":
            return "newest " + time.strftime("%H:%M:%S", time.localtime(t))
        return f"newest {t:.1f} s"

    # ------------------------------------------------------------------ cursor
    def set_cursor(self, x: float | None) -> None:
        """Place the read-out cursor at time x (None hides it) and fill the read-out."""
        self._cursor_x = x
        for plot in self.stack.plots:
            plot.set_cursor(x)
        if x is None:
            return
        self.readout.setText(self.cursor_readout(x))

    def cursor_readout(self, x: float) -> str:
        """Time and every channel's value at time x (the newest sample at or before x)."""
        if self.settings.timebase == "host":
            t = time.strftime("%H:%M:%S", time.localtime(x)) + f".{int((x % 1) * 1000):03d}"
        else:
            t = f"{x:.4f} s"
        parts = [f"<b>t = {t}</b>"]
        for plot in self.stack.plots:
            for cid, curve in plot.curves.items():
                packet, _, name = cid.partition(".")
                value = self.value_at(cid, x)
                colour = self.stack.colour_of(cid)
                parts.append(f"<span style='color:{colour}'>{name}</span> "
                             f"{format_value(value, plot.units[cid])}")
        return " &nbsp;│&nbsp; ".join(parts)

    def value_at(self, channel_id: str, x: float) -> float:
        """The value (display units) of the newest sample at or before x; NaN when that
        sample is more than 1.5 sample periods older than x (a gap, or no data yet)."""
        packet, _, name = channel_id.partition(".")
        rate = self.dictionary.packet(packet).rate_hz or 1.0
        series = self._series.get(packet)
        if series is not None and name in series.values:         # paused: the frozen data
            t = series.x(self.settings.timebase)
            i = int(np.searchsorted(t, x, side="right")) - 1
            if i < 0 or x - t[i] > 1.5 / rate:
                return math.nan
            return float(series.values[name][i]) * self.stack.unit_of(channel_id).scale
        ring = self.store.rings.get(packet)
        if self.settings.paused or ring is None or name not in ring.channels:
            return math.nan
        offset = self._offsets.get(packet, 0.0) if self.settings.timebase == "host" else 0.0
        found = ring.sample_at(name, x - offset)
        if found is None or x - offset - found[0] > 1.5 / rate:
            return math.nan
        return found[1] * self.stack.unit_of(channel_id).scale


def _room_for(label: QLabel) -> QScrollArea:
    """The figures on the right of the bar, in whatever room is left: in a scroll area
    without bars, so the label's width never sets the window's minimum (on a narrow
    screen it is cut from the left; its text is for the curious)."""
    area = QScrollArea()
    area.setWidget(label)
    area.setWidgetResizable(False)
    area.setFrameShape(QFrame.Shape.NoFrame)
    area.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
    for policy in (area.setHorizontalScrollBarPolicy, area.setVerticalScrollBarPolicy):
        policy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
    area.setFixedHeight(label.fontMetrics().height() + 6)
    return area
