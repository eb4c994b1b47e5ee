"""The Analysis dock's list of logs: a checkable table of runs (the replayed log, files
chosen, the logs of a folder, what the session just recorded) and, while a live link or
a replay feeds the charts, the "Live window" row.  Every analysis acts on the checked
ones (FRF, hysteresis and step on the current one when none is checked; the live window
only takes Metrics).  Only paths here: nothing is read."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QAbstractItemView, QHeaderView, QTableWidget, QTableWidgetItem

PATH_ROLE = Qt.ItemDataRole.UserRole
#: what checked_targets() lists for the Live window row
LIVE = "live"
LIVE_LABEL = "Live window"


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
                        "highlighted log.  'Live window': the telemetry the window holds "
                        "(Metrics only)")
        self._live_ticked = False          # the Live row's tick, kept while it is away

    # ------------------------------------------------------------------ the live row
    def _live_row(self) -> int:
        for row in range(self.rowCount()):
            if self.item(row, 0).data(PATH_ROLE) is None:
                return row
        return -1

    def is_live_row(self, row: int) -> bool:
        return 0 <= row < self.rowCount() and self.item(row, 0).data(PATH_ROLE) is None

    def has_live(self) -> bool:
        return self._live_row() >= 0

    def set_live(self, present: bool) -> None:
        """Show or take away the Live window row (at the end; its tick is remembered
        while it is away, unticked the first time)."""
        row = self._live_row()
        if present and row < 0:
            row = self.rowCount()
            self.insertRow(row)
            item = QTableWidgetItem(LIVE_LABEL)
            item.setData(PATH_ROLE, None)
            item.setToolTip("the telemetry the window holds now (the live link or the replay): "
                            "its last seconds, as the options say - Metrics only")
            item.setFlags(item.flags() | Qt.ItemFlag.ItemIsUserCheckable)
            item.setCheckState(Qt.CheckState.Checked if self._live_ticked
                               else Qt.CheckState.Unchecked)
            self.setItem(row, 0, item)
            self.setItem(row, 1, QTableWidgetItem("session"))
        elif not present and row >= 0:
            self._live_ticked = self.live_checked()
            self.removeRow(row)

    def live_checked(self) -> bool:
        row = self._live_row()
        return row >= 0 and self.item(row, 0).checkState() == Qt.CheckState.Checked

    def set_live_checked(self, checked: bool) -> None:
        row = self._live_row()
        if row >= 0:
            self.item(row, 0).setCheckState(Qt.CheckState.Checked if checked
                                            else Qt.CheckState.Unchecked)
        else:
            self._live_ticked = checked

    def checked_targets(self) -> list[Path | str]:
        """The ticked rows in their order: a log's path, LIVE for the Live window."""
        out: list[Path | str] = []
        for r in range(self.rowCount()):
            item = self.item(r, 0)
            if item.checkState() == Qt.CheckState.Checked:
                path = item.data(PATH_ROLE)
                out.append(LIVE if path is None else Path(path))
        return out

    # ------------------------------------------------------------------ logs
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
        """The logs listed (not the Live window)."""
        return [Path(self.item(r, 0).data(PATH_ROLE)) for r in range(self.rowCount())
                if not self.is_live_row(r)]

    def checked_paths(self) -> list[Path]:
        """The ticked logs (not the Live window)."""
        return [t for t in self.checked_targets() if t != LIVE]

    def set_checked(self, path: str | Path, checked: bool) -> None:
        row = self._row_of(Path(path).resolve())
        if row >= 0:
            self.item(row, 0).setCheckState(Qt.CheckState.Checked if checked
                                            else Qt.CheckState.Unchecked)

    def current_path(self) -> Path | None:
        """The highlighted log, else the first ticked one (None: neither; the Live window
        is not a log)."""
        row = self.currentRow()
        if 0 <= row < self.rowCount() and not self.is_live_row(row):
            return Path(self.item(row, 0).data(PATH_ROLE))
        checked = self.checked_paths()
        return checked[0] if checked else None

    def remove_selected(self) -> None:
        """Take the selected logs off the list (the Live window row stays: it is there
        while the session feeds the charts)."""
        rows = sorted({i.row() for i in self.selectedIndexes()}, reverse=True)
        for row in rows:
            if self.is_live_row(row):
                continue
            self.removeRow(row)


__all__ = ["LIVE", "LIVE_LABEL", "RunsTable"]
