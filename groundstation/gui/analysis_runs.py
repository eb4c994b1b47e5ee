"""The Analysis dock's list of logs: a checkable table of runs (the replayed log, files
chosen, the logs of a folder).  Every analysis acts on the checked ones (FRF,
hysteresis and step on the current one when none is checked).  Only paths here:
nothing is read."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QAbstractItemView, QHeaderView, QTableWidget, QTableWidgetItem

PATH_ROLE = Qt.ItemDataRole.UserRole


class RunsTable(QTableWidget):
    COLUMNS = ("log", "from")

    def __init__(self, parent=None):
        super().__init__(0, len(self.COLUMNS), parent)
        self.setHorizontalHeaderLabels(list(self.COLUMNS))
        self.verticalHeader().setVisible(False)
        self.verticalHeader().setDefaultSectionSize(20)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.setSelectionMode(QAbstractItemView.SelectionMode.ExtendedSelection)
        self.setWordWrap(False)
        header = self.horizontalHeader()
        header.setSectionResizeMode(0, QHeaderView.ResizeMode.Stretch)
        header.setSectionResizeMode(1, QHeaderView.ResizeMode.ResizeToContents)
        self.setToolTip("tick the logs to analyse (a table row and a curve each, one colour "
                        "per log); with none ticked, FRF, Hysteresis and Step use the "
                        "highlighted log")

    def _row_of(self, path: Path) -> int:
        for row in range(self.rowCount()):
            if self.item(row, 0).data(PATH_ROLE) == str(path):
                return row
        return -1

    def add(self, path: str | Path, origin: str, *, checked: bool = True,
            make_current: bool = False) -> int:
        """List a log (once: a second add updates where it came from and ticks it)."""
        path = Path(path).resolve()
        row = self._row_of(path)
        if row < 0:
            row = self.rowCount()
            self.insertRow(row)
            item = QTableWidgetItem(path.name)
            item.setData(PATH_ROLE, str(path))
            item.setToolTip(str(path))
            item.setFlags(item.flags() | Qt.ItemFlag.ItemIsUserCheckable)
            self.setItem(row, 0, item)
            self.setItem(row, 1, QTableWidgetItem(origin))
        else:
            self.item(row, 1).setText(origin)
        self.item(row, 0).setCheckState(Qt.CheckState.Checked if checked else Qt.CheckState.Unchecked)
        if make_current:
            self.setCurrentCell(row, 0)
        return row

    def paths(self) -> list[Path]:
        return [Path(self.item(r, 0).data(PATH_ROLE)) for r in range(self.rowCount())]

    def checked_paths(self) -> list[Path]:
        return [Path(self.item(r, 0).data(PATH_ROLE)) for r in range(self.rowCount())
                if self.item(r, 0).checkState() == Qt.CheckState.Checked]

    def set_checked(self, path: str | Path, checked: bool) -> None:
        row = self._row_of(Path(path).resolve())
        if row >= 0:
            self.item(row, 0).setCheckState(Qt.CheckState.Checked if checked
                                            else Qt.CheckState.Unchecked)

    def current_path(self) -> Path | None:
        """The highlighted log, else the first ticked one."""
        row = self.currentRow()
        if 0 <= row < self.rowCount():
            return Path(self.item(row, 0).data(PATH_ROLE))
        checked = self.checked_paths()
        return checked[0] if checked else None

    def remove_selected(self) -> None:
        rows = sorted({i.row() for i in self.selectedIndexes()}, reverse=True)
        for row in rows:
            self.removeRow(row)


__all__ = ["RunsTable"]
