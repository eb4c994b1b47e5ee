"""The protocol's channel tree: packets → channels, searchable, a drag source for charts.

Built from the dictionary alone (the protocol is data), so a channel added to
`protocol/telemetry.toml` appears here without a code change.  Only periodic
device-to-host packets are listed (those with a `rate_hz`): they are the ones a strip
chart can draw; events and command responses belong to the event log.

A channel is named by its id "PACKET.channel" (e.g. "HIGH_RATE.encoder_outer"); status
bits are channels of their own, shown under the status item that carries them.  Drags
carry the selected ids as plain text, one per line, so any widget (or a text editor)
can accept them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pyqtgraph as pg
from PySide6.QtCore import QMimeData, Qt, Signal
from PySide6.QtWidgets import (QAbstractItemView, QLineEdit, QTreeWidget, QTreeWidgetItem,
                               QVBoxLayout, QWidget)

from ...core.dictionary import Dictionary, Item, PacketDef

#: the item data role holding a channel id (packet rows hold None)
ID_ROLE = Qt.ItemDataRole.UserRole

_HEADER_COUNTERS = (
    ("sequence", "counts", "Per-packet frame sequence number (header)"),
    ("tick", "ticks", "Device control-cycle counter (header)"),
)


def chartable_packets(dictionary: Dictionary) -> list[PacketDef]:
    """Periodic device-to-host packets: the telemetry a strip chart can show."""
    return [p for p in dictionary.packets if p.direction == "device_to_host" and p.rate_hz]


@dataclass(frozen=True)
class ChannelInfo:
    """What the GUI needs to know about one chartable channel."""

    id: str                      # "PACKET.channel"
    packet: str
    name: str
    units: str
    description: str
    item: Item | None            # None for header counters and status bits
    parent: str | None = None    # for a status bit: the id of the item carrying it


def channel_catalog(dictionary: Dictionary) -> dict[str, ChannelInfo]:
    """Every chartable channel by id, in protocol order (bits after their item)."""
    out: dict[str, ChannelInfo] = {}
    for packet in chartable_packets(dictionary):
        for name, units, description in _HEADER_COUNTERS:
            cid = f"{packet.name}.{name}"
            out[cid] = ChannelInfo(cid, packet.name, name, units, description, None)
        for item in packet.items:
            if item.is_variable:
                continue
            cid = f"{packet.name}.{item.name}"
            out[cid] = ChannelInfo(cid, packet.name, item.name, item.units, item.description, item)
            for bit_name, bit in item.bits.items():
                bid = f"{packet.name}.{bit_name}"
                out[bid] = ChannelInfo(bid, packet.name, bit_name, "",
                                       f"Status bit {bit} of {item.name} (1 = set)", None, cid)
    return out


def channel_ids_from_text(text: str) -> list[str]:
    """Channel ids from dropped text: one per line, blanks and duplicates removed."""
    seen: list[str] = []
    for line in text.splitlines():
        line = line.strip()
        if line and "." in line and line not in seen:
            seen.append(line)
    return seen


def _item_tooltip(channel_id: str, item: Item | None, units: str, description: str) -> str:
    lines = [f"<b>{channel_id}</b>"]
    if units:
        lines.append(f"units: {units}")
    if description:
        lines.append(description)
    if item is not None:
        if item.states:
            lines.append("states: " + ", ".join(f"{v} = {k}" for k, v in item.states.items()))
        if item.bits:
            lines.append("bits: " + ", ".join(f"{b}: {k}" for k, b in item.bits.items()))
        if item.limits is not None:
            if item.limits.yellow:
                lines.append(f"yellow limits: {item.limits.yellow[0]:g} … {item.limits.yellow[1]:g}")
            if item.limits.red:
                lines.append(f"red limits: {item.limits.red[0]:g} … {item.limits.red[1]:g}")
    return "<br>".join(lines)


class _DragTree(QTreeWidget):
    """A tree whose drags carry the selected channel ids as text lines."""

    def mimeTypes(self) -> list[str]:
        return ["text/plain"]

    def mimeData(self, items) -> QMimeData:
        ids = [i.data(0, ID_ROLE) for i in items if i.data(0, ID_ROLE)]
        mime = QMimeData()
        mime.setText("\n".join(ids))
        return mime

    def supportedDropActions(self) -> Qt.DropAction:
        return Qt.DropAction.CopyAction


class ChannelTree(QWidget):
    """Search box over a tree of packet → channel (units column, description tooltip)."""

    #: a channel was double-clicked (or Enter pressed on it): its id
    sig_channel_activated = Signal(str)

    def __init__(self, dictionary: Dictionary, parent: QWidget | None = None):
        super().__init__(parent)
        self.dictionary = dictionary
        self.search = QLineEdit(self)
        self.search.setPlaceholderText("Search channels (name or description)…")
        self.search.setClearButtonEnabled(True)
        self.tree = _DragTree(self)
        self.tree.setColumnCount(2)
        self.tree.setHeaderLabels(["Channel", "Units"])
        self.tree.setSelectionMode(QAbstractItemView.SelectionMode.ExtendedSelection)
        self.tree.setDragEnabled(True)
        self.tree.setDragDropMode(QAbstractItemView.DragDropMode.DragOnly)
        self.tree.setUniformRowHeights(True)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.search)
        layout.addWidget(self.tree)
        self.catalog = channel_catalog(dictionary)
        self._items: dict[str, QTreeWidgetItem] = {}
        self._search_text: dict[str, str] = {}
        self._build()
        self.search.textChanged.connect(self.set_filter)
        self.tree.itemActivated.connect(self._on_activated)

    # ---------------------------------------------------------------- building
    def _build(self) -> None:
        packets = {p.name: p for p in chartable_packets(self.dictionary)}
        tops: dict[str, QTreeWidgetItem] = {}
        for name, packet in packets.items():
            top = QTreeWidgetItem([name, f"{packet.rate_hz:g} Hz"])
            top.setToolTip(0, f"<b>{name}</b> (id 0x{packet.id:02X}, "
                              f"{packet.rate_hz:g} Hz)<br>{packet.description}")
            top.setFlags(top.flags() & ~Qt.ItemFlag.ItemIsDragEnabled)
            self.tree.addTopLevelItem(top)
            top.setExpanded(packet.rate_hz >= 100)
            tops[name] = top
        for info in self.catalog.values():
            parent = self._items[info.parent] if info.parent else tops[info.packet]
            row = QTreeWidgetItem([info.name, info.units])
            row.setData(0, ID_ROLE, info.id)
            tip = _item_tooltip(info.id, info.item, info.units, info.description)
            row.setToolTip(0, tip)
            row.setToolTip(1, tip)
            parent.addChild(row)
            self._items[info.id] = row
            self._search_text[info.id] = f"{info.id} {info.description}".lower()
        self.tree.resizeColumnToContents(0)

    # ---------------------------------------------------------------- queries
    def channel_ids(self) -> list[str]:
        """Every channel id in the tree, in tree order."""
        return list(self._items)

    def visible_ids(self) -> list[str]:
        """The channel ids the current search leaves visible."""
        return [cid for cid, row in self._items.items() if not row.isHidden()]

    def item_for(self, channel_id: str) -> QTreeWidgetItem:
        return self._items[channel_id]

    def units_of(self, channel_id: str) -> str:
        return self._items[channel_id].text(1)

    # ---------------------------------------------------------------- actions
    def set_filter(self, text: str) -> None:
        """Show channels whose id or description contains every word of `text`."""
        if self.search.text() != text:
            self.search.setText(text)          # re-enters through textChanged
            return
        words = text.lower().split()
        for t in range(self.tree.topLevelItemCount()):
            top = self.tree.topLevelItem(t)
            self._filter_subtree(top, words)
            if words:
                top.setExpanded(True)

    def _filter_subtree(self, row: QTreeWidgetItem, words: list[str]) -> bool:
        """Hide rows that neither match nor have a matching descendant."""
        cid = row.data(0, ID_ROLE)
        own = not words or (cid is not None and all(w in self._search_text[cid] for w in words))
        if cid is None and words:                  # a packet row matches by its name
            own = all(w in row.text(0).lower() for w in words)
        child_match = False
        for c in range(row.childCount()):
            child = row.child(c)
            if own:                                # a matching parent shows all its children
                self._filter_subtree(child, [])
                child_match = True
            else:
                child_match |= self._filter_subtree(child, words)
        shown = own or child_match
        row.setHidden(not shown)
        return shown

    def select(self, channel_ids: list[str]) -> None:
        self.tree.clearSelection()
        for cid in channel_ids:
            self._items[cid].setSelected(True)

    def _on_activated(self, row: QTreeWidgetItem, _column: int) -> None:
        cid = row.data(0, ID_ROLE)
        if cid:
            self.sig_channel_activated.emit(cid)


# ------------------------------------------------------------------ display units
@dataclass(frozen=True)
class DisplayUnit:
    """How a channel's values are shown: value × scale in `units`, with or without an
    automatic SI prefix (pyqtgraph picks µ/m/k from the visible range)."""

    units: str
    scale: float = 1.0
    si_prefix: bool = False
    si_ranges: tuple[tuple[float, float], ...] | None = None   # where a prefix is allowed


_DISPLAY_UNITS = {
    "rad": DisplayUnit("rad", si_prefix=True),          # µrad, mrad
    "rad/s": DisplayUnit("rad/s", si_prefix=True),
    "A": DisplayUnit("A", si_prefix=True),
    "V": DisplayUnit("V", si_prefix=True),
    # seconds get ms/µs below 1 s but never "ks": operators read 3600 s, not 3.6 ks
    "s": DisplayUnit("s", si_prefix=True, si_ranges=((0.0, 1.0),)),
    "ms": DisplayUnit("s", scale=1e-3, si_prefix=True, si_ranges=((0.0, 1.0),)),
    "degC": DisplayUnit("°C"),
    # the rig's torque unit stays as it is: a "milli-inch-ounce" helps nobody
    "in-oz": DisplayUnit("in-oz"),
}


def display_unit(units: str) -> DisplayUnit:
    """Display rule for a dictionary `units` string; unknown units are shown verbatim
    without prefix (counts, ticks, samples, bytes, enumerations)."""
    return _DISPLAY_UNITS.get(units, DisplayUnit(units))


def format_value(value: float, unit: DisplayUnit, precision: int = 4) -> str:
    """A value already in display units, with SI prefix where the unit takes one."""
    if value is None or not math.isfinite(value):
        return "—"
    if unit.si_prefix and not (unit.si_ranges and abs(value) >= 1.0):
        return pg.siFormat(value, precision=precision, suffix=unit.units)
    return f"{value:.{precision + 2}g} {unit.units}".rstrip()
