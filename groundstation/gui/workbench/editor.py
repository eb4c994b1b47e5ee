"""The design workbench's editor: one slot's transfer functions as gain and factors, the
way the design file writes them, in a table whose value column is editable.

It shows what it is given (a design_workbench_model.Slot) and says what the operator
asked for through signals; the workbench applies that to the model and shows the slot
again (so a refused edit puts the old value back).  Values are typed as the file writes
them: "60.27" for (s + 60.27), "25.92, 86100" for (s^2 + 25.92 s + 86100), "0" for s.
"""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (QAbstractItemView, QCheckBox, QComboBox, QGridLayout,
                               QHBoxLayout, QHeaderView, QLabel, QLineEdit, QPushButton,
                               QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget)

from ...params.design_writer import factor_text

PART_WORDS = {"numerator": "zero", "denominator": "pole"}
TF_LABELS = {"c0": "c0", "Q": "Q = c1'/c2'", "c1": "c1'", "c2": "c2'"}
COMPUTED = QBrush(QColor(128, 128, 128))
GAIN_STEP = 1.25                    # the gain buttons multiply or divide by this


class FactorEditor(QWidget):
    sig_slot = Signal(int)                       # edit design #1 (0) or #2 (1)
    sig_edit = Signal(str, str, object, str)     # key, "gain"|"numerator"|"denominator", position, text
    sig_add = Signal(str, str)                   # key, side
    sig_remove = Signal(str, str, int)           # key, side, position
    sig_scale = Signal(str, float)               # key, factor on its gain
    sig_reference = Signal(int)                  # index in the reference list, -1: off
    sig_rename = Signal(str)
    sig_reset = Signal()

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        top = QGridLayout()
        self.slot_combo = QComboBox()
        self.slot_combo.addItems(["#1", "#2"])
        self.name_edit = QLineEdit()
        self.name_edit.setPlaceholderText("the name the saved file gives the design")
        top.addWidget(QLabel("Edit design"), 0, 0)
        top.addWidget(self.slot_combo, 0, 1)
        top.addWidget(QLabel("name"), 1, 0)
        top.addWidget(self.name_edit, 1, 1)
        self.keep = QCheckBox("keep c0 output-equivalent to")
        self.keep.setToolTip("after each edit of Q, c0 is recomputed so that the loop gain "
                             "c0 (c1' g1 + c2' g2) is the chosen design's (c0.equivalent_to)")
        self.reference = QComboBox()
        top.addWidget(self.keep, 2, 0)
        top.addWidget(self.reference, 2, 1)
        top.setColumnStretch(1, 1)
        lay.addLayout(top)
        self.table = QTableWidget(0, 3)
        self.table.setHorizontalHeaderLabels(["", "factor", "value"])
        self.table.verticalHeader().setVisible(False)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(0, QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(1, QHeaderView.ResizeMode.Stretch)
        header.setSectionResizeMode(2, QHeaderView.ResizeMode.Interactive)
        self.table.setColumnWidth(2, 130)
        lay.addWidget(self.table, 1)
        row = QHBoxLayout()
        self.gain_up = QPushButton(f"gain ×{GAIN_STEP:g}")
        self.gain_down = QPushButton(f"gain ÷{GAIN_STEP:g}")
        self.add_zero = QPushButton("+ zero")
        self.add_pole = QPushButton("+ pole")
        self.remove = QPushButton("remove")
        self.reset = QPushButton("reset")
        for b, tip in ((self.gain_up, "the selected transfer function's gain"),
                       (self.gain_down, "the selected transfer function's gain"),
                       (self.add_zero, "a factor (s + 100) in the selected transfer function's numerator"),
                       (self.add_pole, "a factor (s + 100) in the selected transfer function's denominator"),
                       (self.remove, "the selected factor"),
                       (self.reset, "this design back to its file")):
            b.setToolTip(tip)
            row.addWidget(b)
        lay.addLayout(row)
        self._filling = False
        self._keys: tuple[str, ...] = ()
        self._computed_c0 = False
        self.table.itemChanged.connect(self._on_item)
        self.slot_combo.currentIndexChanged.connect(self.sig_slot)
        self.name_edit.editingFinished.connect(lambda: self.sig_rename.emit(self.name_edit.text()))
        self.keep.toggled.connect(self._on_reference)
        self.reference.currentIndexChanged.connect(self._on_reference)
        self.gain_up.clicked.connect(lambda: self._scale(GAIN_STEP))
        self.gain_down.clicked.connect(lambda: self._scale(1.0 / GAIN_STEP))
        self.add_zero.clicked.connect(lambda: self._add("numerator"))
        self.add_pole.clicked.connect(lambda: self._add("denominator"))
        self.remove.clicked.connect(self._remove)
        self.reset.clicked.connect(self.sig_reset)

    # ------------------------------------------------------------------ showing
    def show_slot(self, slot, references: list[str], chosen: int | None) -> None:
        """Fill from a model Slot (None: nothing to edit).  `references` are the labels of
        the designs c0 may be kept equivalent to; `chosen` the one in use (None: off)."""
        self._filling = True
        try:
            self.setEnabled(slot is not None)
            self.table.setRowCount(0)
            self.reference.clear()
            self.reference.addItems(references)
            self.keep.setChecked(chosen is not None)
            self.reference.setCurrentIndex(chosen if chosen is not None else 0)
            if slot is None:
                self.name_edit.clear()
                return
            self.name_edit.setText(slot.name)
            self._keys = slot.keys
            self._computed_c0 = slot.reference is not None
            for key in sorted(slot.keys, key=lambda k: k == "c0"):     # Q (or c1', c2') first
                f = slot.factors[key]
                self._row(key, "gain", None, "gain", f"{f.gain:.10g}")
                for side in ("numerator", "denominator"):
                    for i, factor in enumerate(f.side(side)):
                        value = ", ".join(f"{v:.10g}" for v in factor)
                        self._row(key, side, i, f"{PART_WORDS[side]} {factor_text(factor)}", value)
        finally:
            self._filling = False

    def _row(self, key: str, part: str, position: int | None, what: str, value: str) -> None:
        r = self.table.rowCount()
        self.table.insertRow(r)
        first = QTableWidgetItem(TF_LABELS[key] if part == "gain" else "")
        factor = QTableWidgetItem(what)
        cell = QTableWidgetItem(value)
        for item in (first, factor, cell):
            item.setData(Qt.ItemDataRole.UserRole, (key, part, position))
            item.setFlags(item.flags() & ~Qt.ItemFlag.ItemIsEditable)
        if key == "c0" and self._computed_c0:
            for item in (first, factor, cell):
                item.setForeground(COMPUTED)
            cell.setToolTip("computed: c0 is kept output-equivalent (untick that to edit it)")
        else:
            cell.setFlags(cell.flags() | Qt.ItemFlag.ItemIsEditable)
        self.table.setItem(r, 0, first)
        self.table.setItem(r, 1, factor)
        self.table.setItem(r, 2, cell)

    def row_of(self, key: str, part: str, position: int | None = None) -> int:
        """The table row of a gain or factor (for tests and scripts); -1 if none."""
        for r in range(self.table.rowCount()):
            if self.table.item(r, 2).data(Qt.ItemDataRole.UserRole) == (key, part, position):
                return r
        return -1

    def set_value(self, key: str, part: str, position: int | None, text: str) -> None:
        """Type `text` into a value cell, as the operator would."""
        r = self.row_of(key, part, position)
        if r < 0:
            raise KeyError(f"no {key} {part} {position} in the editor")
        self.table.item(r, 2).setText(text)

    # ------------------------------------------------------------------ asking
    def _on_item(self, item: QTableWidgetItem) -> None:
        if self._filling or item.column() != 2:
            return
        key, part, position = item.data(Qt.ItemDataRole.UserRole)
        self.sig_edit.emit(key, part, position, item.text())

    def _on_reference(self, *_):
        if not self._filling:
            self.sig_reference.emit(self.reference.currentIndex() if self.keep.isChecked() else -1)

    def _selected(self) -> tuple[str, str, int | None] | None:
        rows = self.table.selectionModel().selectedRows() if self.table.selectionModel() else []
        if not rows:
            return None
        return self.table.item(rows[0].row(), 2).data(Qt.ItemDataRole.UserRole)

    def _selected_key(self) -> str:
        sel = self._selected()
        return sel[0] if sel else ("Q" if "Q" in self._keys else self._keys[-1] if self._keys else "")

    def _scale(self, factor: float) -> None:
        key = self._selected_key()
        if key:
            self.sig_scale.emit(key, factor)

    def _add(self, side: str) -> None:
        key = self._selected_key()
        if key:
            self.sig_add.emit(key, side)

    def _remove(self) -> None:
        sel = self._selected()
        if sel and sel[1] in ("numerator", "denominator"):
            self.sig_remove.emit(sel[0], sel[1], sel[2])
