"""The Analysis dock's tables: the metrics of each log (LogMetrics.row()), the step
figures of each log (step_row) and the parameters of an identification (identify_row).
A cell shows its value formatted and keeps the value itself (VALUE_ROLE), which is what
an export writes - the table and its file agree."""

from __future__ import annotations

import math
from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QAbstractItemView, QHeaderView, QTableWidget, QTableWidgetItem

#: the metrics table: header, LogMetrics.row() key, format ('' : text as it is)
METRIC_COLUMNS = (("log", "log", ""), ("sensor", "sensor", ""), ("from s", "from_s", ".3f"),
                  ("to s", "to_s", ".3f"), ("RMS µrad", "rms_urad", ".4g"),
                  ("std µrad", "std_urad", ".4g"), ("high-pass µrad", "highpass_rms_urad", ".4g"),
                  ("smear µrad", "smear_rms_urad", ".4g"), ("energy J", "energy_total_j", ".4g"),
                  ("sat. coarse %", "saturated_coarse_pct", ".3g"),
                  ("sat. fine %", "saturated_fine_pct", ".3g"), ("note", "notes", ""))
#: the step table: header, step_row() key, format
STEP_COLUMNS = (("log", "log", ""), ("at s", "step_time_s", ".3f"),
                ("step µrad", "step_urad", ".4g"), ("rise ms", "rise_ms", ".4g"),
                ("overshoot %", "overshoot_pct", ".3g"), ("settling ms", "settling_ms", ".4g"),
                ("steady err. %", "steady_state_error_pct", ".3g"),
                ("peak effort", "peak_effort", ".3g"), ("effort", "effort", ""),
                ("note", "notes", ""))
#: the identification's parameters: header, identify_row() key, format
IDENTIFY_COLUMNS = (("parameter", "name", ""), ("units", "units", ""), ("base", "base", ".6g"),
                    ("identified", "value", ".6g"), ("change %", "change_pct", "+.2f"),
                    ("95 % interval", "interval", ""), ("status", "status", ""))
VALUE_ROLE = Qt.ItemDataRole.UserRole


def _finite(v: float, scale: float = 1.0) -> float | None:
    return None if v is None or not math.isfinite(v) else v * scale


def step_row(step) -> dict[str, Any]:
    """A log_step.LogStep as one flat record (µrad, ms, %); None where there is no figure
    (never reached 90 %, not settled, no effort), the reason in the note."""
    m = step.metrics
    notes = list(step.notes)
    if math.isnan(m.rise_time_s):
        notes.append("never reached 90 % of the step")
    if not m.settled:
        notes.append(f"not settled within ±{m.settling_band_fraction * 100:g} % by the end")
    return {
        "log": step.path.name, "step_time_s": step.step_time_s, "step_urad": step.step_size * 1e6,
        "rise_ms": _finite(m.rise_time_s, 1e3), "overshoot_pct": _finite(m.overshoot_percent),
        "settling_ms": _finite(m.settling_time_s, 1e3),
        "steady_state_error_pct": _finite(m.steady_state_error_percent),
        "peak_effort": _finite(m.peak_effort),
        "effort": f"{step.effort_channel} ({step.effort_units})" if step.effort_channel else "",
        "notes": "; ".join(notes),
    }


def identify_row(row: dict[str, Any]) -> dict[str, Any]:
    """A row of identification.report.parameter_rows with its 95 % interval as the text
    the table shows ('' for a held parameter: its status says why it has none)."""
    ci = row.get("ci95")
    interval = f"[{ci[0]:.6g}, {ci[1]:.6g}]" if ci else ""
    return {**row, "interval": interval}


def held(row: dict[str, Any]) -> bool:
    """A parameter the fit did not change (held at the base value, or fitted and not
    written): anything but 'identified'."""
    return row.get("status") != "identified"


def _cell(value, fmt: str) -> QTableWidgetItem:
    """A cell showing `value` formatted, holding the value itself."""
    if value is None or value == "":
        text = ""
    elif fmt and isinstance(value, (int, float)):
        text = format(value, fmt)
    else:
        text = str(value)
    item = QTableWidgetItem(text)
    item.setData(VALUE_ROLE, value)
    if fmt:
        item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
    if text:
        item.setToolTip(text)
    return item


class ResultTable(QTableWidget):
    """A read-only table of records, one row each, columns (header, key, format)."""

    def __init__(self, columns, parent=None):
        super().__init__(0, len(columns), parent)
        self.columns = tuple(columns)
        self.setHorizontalHeaderLabels([c[0] for c in self.columns])
        self.verticalHeader().setVisible(False)
        self.verticalHeader().setDefaultSectionSize(20)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(c[1] for c in self.columns)

    def clear_rows(self) -> None:
        self.setRowCount(0)

    def count(self) -> int:
        """How many records (rows) it shows."""
        return self.rowCount()

    def add_row(self, values: dict, bad: bool = False) -> None:
        """A record's row; `bad`: a log that could not be analysed (its note in red)."""
        row = self.rowCount()
        self.insertRow(row)
        for col, (_, key, fmt) in enumerate(self.columns):
            item = _cell(values.get(key), fmt)
            if key == "notes" and bad and item.text():
                item.setForeground(Qt.GlobalColor.red)
            self.setItem(row, col, item)

    def rows(self) -> list[dict[str, Any]]:
        """The records as shown, each value as the analysis gave it."""
        return [{key: self.item(r, c).data(VALUE_ROLE) for c, key in enumerate(self.keys)}
                for r in range(self.rowCount())]


class FiguresTable(QTableWidget):
    """Records side by side: a column per record (its first column's value the header,
    e.g. the log), a row per figure - narrow enough to sit beside a plot.  `rows()` gives
    the records back as `ResultTable.rows()` does."""

    def __init__(self, columns, parent=None):
        super().__init__(len(columns) - 1, 0, parent)
        self.columns = tuple(columns)
        self.setVerticalHeaderLabels([c[0] for c in self.columns[1:]])
        self.verticalHeader().setDefaultSectionSize(20)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        header = self.horizontalHeader()
        header.setTextElideMode(Qt.TextElideMode.ElideLeft)    # a log's name ends telling
        header.setDefaultSectionSize(150)
        header.setSectionResizeMode(QHeaderView.ResizeMode.Interactive)
        self.setTextElideMode(Qt.TextElideMode.ElideRight)

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(c[1] for c in self.columns)

    def clear_rows(self) -> None:
        self.setColumnCount(0)

    def count(self) -> int:
        """How many records (columns) it shows."""
        return self.columnCount()

    def add_row(self, values: dict, bad: bool = False, colour: QColor | None = None) -> None:
        """A record's column; `colour`: its header's (the log's curve's); `bad`: its note red."""
        col = self.columnCount()
        self.insertColumn(col)
        (_, key0, fmt0), *rest = self.columns
        head = _cell(values.get(key0), fmt0)
        if colour is not None:
            head.setForeground(colour)
        self.setHorizontalHeaderItem(col, head)
        for row, (_, key, fmt) in enumerate(rest):
            item = _cell(values.get(key), fmt)
            if key == "notes" and bad and item.text():
                item.setForeground(Qt.GlobalColor.red)
            self.setItem(row, col, item)

    def item_of(self, key: str, record: int) -> QTableWidgetItem:
        """The cell of figure `key` of the record-th record."""
        if key == self.columns[0][1]:
            return self.horizontalHeaderItem(record)
        return self.item(self.keys.index(key) - 1, record)

    def rows(self) -> list[dict[str, Any]]:
        return [{key: self.item_of(key, c).data(VALUE_ROLE) for key in self.keys}
                for c in range(self.columnCount())]


__all__ = ["FiguresTable", "IDENTIFY_COLUMNS", "METRIC_COLUMNS", "ResultTable", "STEP_COLUMNS",
           "VALUE_ROLE", "held", "identify_row", "step_row"]
