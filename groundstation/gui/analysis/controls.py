"""The Analysis dock's controls: the options the jobs take (OptionsBox) and the buttons,
the export menu and the status line (ActionsBox).  Widgets only: what the buttons do is
the panel's (analysis/panel.py)."""

from __future__ import annotations

import math

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (QComboBox, QDoubleSpinBox, QFormLayout, QGridLayout, QGroupBox,
                               QHBoxLayout, QLabel, QLineEdit, QMenu, QPushButton, QToolButton,
                               QVBoxLayout, QWidget)

from ...analysis.jitter import DEFAULT_INTEGRATION_PERIOD_S
from ...analysis.log_frf import FRF_INPUTS, FRF_OUTPUTS
from ...analysis.names import DEFAULT_SENSOR, SENSORS
from ...plant.testbed import TESTBEDS_DIR
from .live import DEFAULT_LIVE_SECONDS

SEGMENTS = (256, 512, 1024, 2048, 4096, 8192)
BAD_STYLE = "color:#c62828;"
BUSY_STYLE = "color:#1565c0;"


class OptionsBox(QGroupBox):
    """Scored sensor, integration period, window (of a log; of the live window: its last
    seconds), FRF channels and segments, testbed."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__("Options", parent)
        form = QFormLayout(self)
        form.setContentsMargins(6, 4, 6, 4)
        form.setVerticalSpacing(2)
        self.sensor = QComboBox()
        self.sensor.addItems(list(SENSORS))
        self.sensor.setCurrentText(DEFAULT_SENSOR)
        self.period = QDoubleSpinBox()
        self.period.setRange(0.001, 3600.0)
        self.period.setDecimals(3)
        self.period.setValue(DEFAULT_INTEGRATION_PERIOD_S)
        self.period.setSuffix(" s")
        self.period.setToolTip("integration period of the jitter's high-pass and windowed smear")
        window = QHBoxLayout()
        self.window_from = QLineEdit()
        self.window_from.setPlaceholderText("start")
        self.window_to = QLineEdit()
        self.window_to.setPlaceholderText("end")
        for w in (self.window_from, self.window_to):
            w.setToolTip("seconds from the log's start (empty: open end); the Live window's "
                         "span is 'live last'")
            w.setMaximumWidth(70)
            window.addWidget(w)
        self.live_seconds = QDoubleSpinBox()
        self.live_seconds.setRange(0.0, 86400.0)
        self.live_seconds.setDecimals(1)
        self.live_seconds.setValue(DEFAULT_LIVE_SECONDS)
        self.live_seconds.setSuffix(" s")
        self.live_seconds.setSpecialValueText("all it holds")
        self.live_seconds.setToolTip("the Live window row analyses the last seconds of "
                                     "telemetry the window holds (0: all it holds)")
        self.frf_input = QComboBox()
        self.frf_input.addItems(list(FRF_INPUTS))
        self.frf_output = QComboBox()
        self.frf_output.addItems(list(FRF_OUTPUTS))
        self.segments = QComboBox()
        self.segments.addItem("auto", None)
        for n in SEGMENTS:
            self.segments.addItem(str(n), n)
        self.segments.setToolTip("Welch segment length in samples (resolution = rate / length)")
        self.testbed = QComboBox()
        self.testbed.addItem("the log's", None)        # live: the session's
        for path in sorted(TESTBEDS_DIR.glob("*.toml")):
            self.testbed.addItem(path.stem, str(path))
        self.testbed.setToolTip("the testbed whose model and constants are used (default: the "
                                "file the log recorded; for the live window, the session's "
                                "testbed, or the replayed log's).  Identify starts from it as "
                                "the base; with \"the log's\" from the session's testbed file, "
                                "or one it asks for - never the file a log recorded")
        form.addRow("sensor", self.sensor)
        form.addRow("integration", self.period)
        form.addRow("window s", window)
        form.addRow("live last", self.live_seconds)
        form.addRow("FRF input", self.frf_input)
        form.addRow("FRF output", self.frf_output)
        form.addRow("segments", self.segments)
        form.addRow("testbed", self.testbed)

    def window(self) -> tuple[float | None, float | None]:
        """(from, to) in seconds (None: open end); ValueError saying which is not a number."""
        out = []
        for name, edit in (("from", self.window_from), ("to", self.window_to)):
            text = edit.text().strip()
            if not text:
                out.append(None)
                continue
            try:
                value = float(text)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise ValueError(f"window {name}: {text!r} is not a number of seconds")
            out.append(value)
        return out[0], out[1]

    def testbed_file(self) -> str | None:
        return self.testbed.currentData()

    def live_span(self) -> float | None:
        """The live window's span in seconds (None: all the window holds)."""
        return self.live_seconds.value() or None


class ActionsBox(QWidget):
    """The job buttons (Metrics, FRF, Hysteresis, Step, Identify), Cancel, Export and the
    status line."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        col = QVBoxLayout(self)
        col.setContentsMargins(0, 0, 0, 0)
        grid = QGridLayout()
        grid.setSpacing(3)
        self.metrics_button = QPushButton("Metrics")
        self.metrics_button.setToolTip("jitter, energy and spectra of every ticked log")
        self.frf_button = QPushButton("FRF")
        self.frf_button.setToolTip("frequency response of every ticked log against the model")
        self.hysteresis_button = QPushButton("Hysteresis")
        self.hysteresis_button.setToolTip("friction torque against angle of every ticked log")
        self.step_button = QPushButton("Step")
        self.step_button.setToolTip("step response (rise, overshoot, settling) of every ticked log")
        self.identify_button = QPushButton("Identify")
        self.identify_button.setToolTip("fit the rig's testbed to the ticked open-loop "
                                        "identification logs, from the base testbed chosen "
                                        "under Options; save it as a testbed file")
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setToolTip("stop the analysis under way (its results are dropped)")
        self.cancel_button.setEnabled(False)
        self.export_button = QToolButton()
        self.export_button.setText("Export")
        self.export_button.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextOnly)
        self.export_button.setPopupMode(QToolButton.ToolButtonPopupMode.InstantPopup)
        self.export_menu = QMenu(self.export_button)
        self.export_metrics_csv = self.export_menu.addAction("Metrics table as CSV…")
        self.export_metrics_json = self.export_menu.addAction("Metrics table as JSON…")
        self.export_step_csv = self.export_menu.addAction("Step table as CSV…")
        self.export_step_json = self.export_menu.addAction("Step table as JSON…")
        self.export_menu.addSeparator()
        self.export_png = self.export_menu.addAction("Shown plots as PNG…")
        self.export_button.setMenu(self.export_menu)
        self.export_button.setToolTip("write a table (CSV, JSON) or the plots of the tab shown "
                                      "(PNG)")
        buttons = (self.metrics_button, self.frf_button, self.hysteresis_button,
                   self.step_button, self.identify_button, self.cancel_button,
                   self.export_button)
        for i, b in enumerate(buttons):
            grid.addWidget(b, i // 2, i % 2)
        self.export_button.setSizePolicy(self.metrics_button.sizePolicy())
        col.addLayout(grid)
        self.status = QLabel("tick logs, then Metrics, FRF, Hysteresis, Step or Identify")
        self.status.setWordWrap(True)
        self.status.setTextFormat(Qt.TextFormat.PlainText)
        self.status.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.status.setMinimumWidth(160)
        self.status.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        col.addWidget(self.status, 1)

    def job_buttons(self) -> dict[str, QPushButton]:
        return {"metrics": self.metrics_button, "frf": self.frf_button,
                "hysteresis": self.hysteresis_button, "step": self.step_button,
                "identify": self.identify_button}

    def say(self, text: str, style: str = "") -> None:
        self.status.setStyleSheet(style)
        self.status.setText(text)


__all__ = ["ActionsBox", "BAD_STYLE", "BUSY_STYLE", "OptionsBox", "SEGMENTS"]
