"""The operator's panels about what happened: the event log (filterable by level and
text), the event markers of a replayed log's timeline, and the replay bar (pause, speed,
seek).  They show models and call Session methods; they do no I/O themselves.
"""

from __future__ import annotations

from datetime import datetime

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (QComboBox, QHBoxLayout, QLabel, QLineEdit, QPushButton, QSlider,
                               QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget)

from ..session.session import Session


class EventLog(QWidget):
    """Device EVENTs, link events and command results, with a level filter and search."""

    LEVELS = ["DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"]

    def __init__(self, session: Session, parent=None):
        super().__init__(parent)
        lay = QVBoxLayout(self)
        row = QHBoxLayout()
        self.level = QComboBox()
        self.level.addItems(self.LEVELS)
        self.level.setCurrentText("INFO")
        self.search = QLineEdit()
        self.search.setPlaceholderText("search events")
        row.addWidget(QLabel("level ≥"))
        row.addWidget(self.level)
        row.addWidget(self.search, 1)
        lay.addLayout(row)
        self.table = QTableWidget(0, 4)
        self.table.setHorizontalHeaderLabels(["time", "level", "source", "message"])
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.verticalHeader().setVisible(False)
        lay.addWidget(self.table, 1)
        session.sig_event.connect(self.add)
        self.level.currentIndexChanged.connect(self._filter)
        self.search.textChanged.connect(self._filter)

    def add(self, level: str, source: str, text: str) -> None:
        row = self.table.rowCount()
        self.table.insertRow(row)
        colour = {"WARNING": "#f9a825", "ERROR": "#c62828", "CRITICAL": "#c62828"}.get(level)
        for col, value in enumerate((f"{datetime.now():%H:%M:%S.%f}"[:-3], level, source, text)):
            item = QTableWidgetItem(value)
            if colour:
                item.setForeground(QColor(colour))
            self.table.setItem(row, col, item)
        self._apply(row)
        self.table.scrollToBottom()

    def _apply(self, row: int) -> None:
        lvl = self.table.item(row, 1).text()
        rank = self.LEVELS.index(lvl) if lvl in self.LEVELS else 1
        needle = self.search.text().lower()
        text = " ".join(self.table.item(row, c).text() for c in range(4)).lower()
        self.table.setRowHidden(row, bool(rank < self.level.currentIndex() or (needle and needle not in text)))

    def _filter(self) -> None:
        for row in range(self.table.rowCount()):
            self._apply(row)


class EventMarkers(QWidget):
    """A thin strip above the timeline: one tick per EVENT of the log, coloured by level."""

    COLOURS = {0: "#9e9e9e", 1: "#1565c0", 2: "#f9a825", 3: "#c62828", 4: "#c62828"}

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setFixedHeight(8)
        self.events: list[tuple[float, int, str]] = []
        self.start, self.duration = 0.0, 0.0

    def set_events(self, events, start: float, duration: float) -> None:
        self.events, self.start, self.duration = events, start, duration
        self.setToolTip("\n".join(f"{t - start:8.2f} s  {text}" for t, _, text in events[:40]))
        self.update()

    def paintEvent(self, event) -> None:
        from PySide6.QtGui import QPainter
        if not self.duration:
            return
        p = QPainter(self)
        for t, level, _ in self.events:
            x = int((t - self.start) / self.duration * (self.width() - 1))
            p.fillRect(x, 0, 2, self.height(), QColor(self.COLOURS.get(level, "#9e9e9e")))
        p.end()


class ReplayBar(QWidget):
    """Timeline over the whole log with its events marked, play/pause, speed; seek by
    dragging."""

    def __init__(self, session: Session, parent=None):
        super().__init__(parent)
        self.session = session
        lay = QHBoxLayout(self)
        lay.setContentsMargins(4, 2, 4, 2)
        self.play = QPushButton("Pause")
        self.speed = QComboBox()
        self.speed.addItems(["0.1", "0.5", "1", "2", "5", "10", "50", "max"])
        self.speed.setCurrentText("1")
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setRange(0, 1000)
        self.position = QLabel("")
        lay.addWidget(QLabel("Replay"))
        lay.addWidget(self.play)
        lay.addWidget(QLabel("speed"))
        lay.addWidget(self.speed)
        timeline = QVBoxLayout()
        timeline.setSpacing(0)
        self.markers = EventMarkers()
        timeline.addWidget(self.markers)
        timeline.addWidget(self.slider)
        lay.addLayout(timeline, 1)
        lay.addWidget(self.position)
        self.play.clicked.connect(self._toggle)
        self.speed.currentTextChanged.connect(self._speed)
        self.slider.sliderReleased.connect(self._seek)
        self._timer = QTimer(self)
        self._timer.timeout.connect(self._update)
        self._timer.start(100)

    def _toggle(self) -> None:
        src = self.session.replay
        if src is None:
            return
        if src.playing:
            src.pause()
        else:
            src.play()

    def _speed(self, text: str) -> None:
        if self.session.replay is not None:
            self.session.replay.speed = None if text == "max" else float(text)

    def _seek(self) -> None:
        if self.session.replay is not None:
            self.session.replay.seek_fraction(self.slider.value() / 1000)

    def _update(self) -> None:
        src = self.session.replay
        if src is None:
            return
        self.play.setText("Pause" if src.playing else "Play")
        if self.markers.events is not self.session.replay_events:
            self.markers.set_events(self.session.replay_events, src.start_time, src.duration)
        if not self.slider.isSliderDown() and src.duration:
            pos = (src.position or src.start_time) - src.start_time
            self.slider.setValue(int(1000 * pos / src.duration))
            self.position.setText(f"{pos:8.2f} / {src.duration:.2f} s")
