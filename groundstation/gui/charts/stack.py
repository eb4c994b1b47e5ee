"""The strip chart's stack of plots: which channels are on which plot (added, moved,
removed, dropped from the channel tree), their colours, the shared time axis, and each
plot's right-click "Chart" menu.

`PlotStack` is owned by `StripChartPanel` (charts/panel.py).  It is given the telemetry
store (which channels exist), the channel catalog (names, units, descriptions) and the
`PlotColumn` the plots are shown in (charts/column.py).  It keeps the time mode and
autoscale a new plot starts with, as `ChartSettings` last set them, and tells the panel
about its plots through signals: `sig_layout_changed` after any change of the plots,
and the plots' own `sig_mouse_x` and `sig_x_range_changed`, passed on.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Signal
from PySide6.QtWidgets import QMenu

from .autoscale import least_span
from .plot import ChartPlot
from .channel_tree import ChannelInfo, DisplayUnit, display_unit

if TYPE_CHECKING:
    from ...live.display_buffers import TelemetryStore
    from .column import PlotColumn

# the panel's logger, as these messages always were
log = logging.getLogger("groundstation.gui.charts.panel")


class PlotStack(QObject):
    """Plots and the channels on them (`plots`, top to bottom)."""

    sig_layout_changed = Signal()
    sig_mouse_x = Signal(object)            # a plot's mouse time (float), None when it leaves
    sig_x_range_changed = Signal()

    def __init__(self, store: TelemetryStore, catalog: dict[str, ChannelInfo],
                 column: PlotColumn, parent: QObject | None = None):
        super().__init__(parent)
        self.store = store
        self.catalog = catalog
        self.column = column
        self.plots: list[ChartPlot] = []
        self._colours: dict[str, int] = {}
        # what a new plot starts with (ChartSettings keeps these in step with the toolbar)
        self._timebase = "device"
        self._relative = True
        self._pan_x = False
        self._autoscale = True

    # ------------------------------------------------------------------ the look of every plot
    def set_time_mode(self, timebase: str, relative: bool) -> None:
        """Label every time axis for the timebase, relative to the newest sample or not."""
        self._timebase, self._relative = timebase, relative
        for plot in self.plots:
            plot.set_time_mode(timebase, relative)

    def set_pan_x(self, enabled: bool) -> None:
        """Let the mouse pan and zoom in time (paused) or not (live)."""
        self._pan_x = enabled
        for plot in self.plots:
            plot.set_mouse_x(enabled)

    def set_autoscale_all(self, enabled: bool) -> None:
        self._autoscale = enabled
        for plot in self.plots:
            plot.set_autoscale(enabled)

    # ------------------------------------------------------------------ channels
    def shown_by_packet(self) -> dict[str, set[str]]:
        """The channel names shown on any plot, by packet."""
        wanted: dict[str, set[str]] = {}
        for plot in self.plots:
            for cid in plot.curves:
                packet, _, name = cid.partition(".")
                wanted.setdefault(packet, set()).add(name)
        return wanted

    def colour_of(self, channel_id: str) -> str:
        """The channel's curve colour (the first of the palette when it is not shown)."""
        return ChartPlot.PALETTE[self._colours.get(channel_id, 0)]

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
            self.column.remove(plot)
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
        self.column.remove(plot)
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
        unit = self.unit_of(channel_id)
        item = info.item if info else None
        # header counters and status bits are integer counts
        least = (least_span(item.type, item.scale, item.units, unit.scale) if item is not None
                 else least_span("u32", None, "", unit.scale))
        plot.add_curve(channel_id, info.name if info else channel_id, unit,
                       self._colour_for(channel_id), info.description if info else "", least)

    def _new_plot(self, index: int) -> ChartPlot:
        plot = ChartPlot(self)
        plot.set_time_mode(self._timebase, relative=self._relative)
        plot.sig_dropped.connect(lambda ids, p=plot: self.drop_channels(ids, self.plots.index(p)))
        plot.sig_menu_about_to_show.connect(self._fill_menu)
        plot.sig_mouse_x.connect(self.sig_mouse_x)
        plot.sig_x_range_changed.connect(self.sig_x_range_changed)
        plot.set_autoscale(self._autoscale)
        self.plots.insert(index, plot)
        self.column.insert(index, plot)
        return plot

    def _relayout(self) -> None:
        """After any change of the plots: X links, which plot shows the time axis."""
        master = self.plots[0].getPlotItem()
        for i, plot in enumerate(self.plots):
            plot.getPlotItem().setXLink(master if i else None)
            plot.time_axis.set_shown(i == len(self.plots) - 1)
            plot.set_mouse_x(self._pan_x)
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
