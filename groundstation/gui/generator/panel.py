"""The function-generator panel: the base-motion generator from the GUI.

Left, the instrument: resource picker (the VISA resources pyvisa finds and the
simulator's generator), connect, the basic wave with the allowed range of every field
(instrument and testbed), Apply, and the output button - whose state is what the
instrument last reported, never what was clicked.  Middle, base motion: a PSD table,
its synthesis settings, what it needs from the generator, Upload, Check.  Right, the
plots: one waveform period (generator volts and the base angle the stage model
expects), the PSD (target, synthesised, achieved) and the cumulative spectral power of
target and achieved on one plot.

The widget does no I/O and no numerics: the GeneratorController (session.generator)
talks to the instrument on its worker thread, `groundstation.basemotion` makes and
checks the profiles.

This module is the panel's shell (layout, status line, what needs an open generator);
its two sides are parts of it with a module each, `channel_editor` (instrument, basic
wave, output) and `base_motion` (profile, upload, check, plots), with their common
look in `styles`.
"""

from __future__ import annotations

from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import QHBoxLayout, QLabel, QSizePolicy, QVBoxLayout, QWidget

from ...basemotion import BaseMotionProfile
from ..common.dock_layout import controls_beside_plots
from .base_motion import BaseMotionEditor
from .channel_editor import ChannelEditor
from .records import CheckResult, GeneratorState
from .styles import BAD_STYLE, WARN_STYLE
from ..session.session import Session


class GeneratorPanel(ChannelEditor, BaseMotionEditor, QWidget):
    def __init__(self, session: Session, parent: QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.gen = session.generator
        self.profile: BaseMotionProfile | None = None       # the previewed profile
        self.result: CheckResult | None = None
        self.state: GeneratorState | None = None
        self._filling = False
        self._edited = False              # wave fields edited since the last read-back
        self._preview_timer = QTimer(self)
        self._preview_timer.setSingleShot(True)
        self._preview_timer.setInterval(150)  # one preview per burst of edits
        self._preview_timer.timeout.connect(self.preview)
        self._build()
        g = self.gen
        g.sig_resources.connect(self._on_resources)
        g.sig_opened.connect(self._on_opened)
        g.sig_closed.connect(self._on_closed)
        g.sig_state.connect(self._on_state)
        g.sig_uploaded.connect(self._on_uploaded)
        g.sig_failed.connect(lambda action, text: self._say(f"{action}: {text}", bad=True))
        g.sig_refused.connect(self._on_refused)
        g.sig_info.connect(self._say)
        g.sig_busy.connect(lambda what: self.busy.setText(f"{what}…" if what else ""))
        session.sig_link_state.connect(self._on_link)
        self._set_open(False)
        self._update_ranges()
        self.refresh_resources()
        self._schedule_preview()

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        outer = QVBoxLayout(self)
        outer.setContentsMargins(4, 2, 4, 2)
        outer.setSpacing(2)
        # three short columns (instrument, basic wave, base motion) beside the plots
        split = controls_beside_plots(
            [self._instrument_box(), self._wave_box(), self._motion_box()], self._plots(),
            min_width=280, plots_width=600, pad=40)
        outer.addWidget(split, 1)
        status = QHBoxLayout()
        self.status = QLabel("")
        self.status.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        # long messages must not widen the window: elided by the layout, whole in the tooltip
        self.status.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.busy = QLabel("")
        self.busy.setStyleSheet(WARN_STYLE)
        status.addWidget(self.status, 1)
        status.addWidget(self.busy)
        outer.addLayout(status)

    # ------------------------------------------------------------------ open or not (both sides)
    def _set_open(self, is_open: bool) -> None:
        self.connect_button.setText("Disconnect" if is_open else "Connect")
        for w in (self.apply_button, self.output_button, self.upload_button):
            w.setEnabled(is_open)

    # ------------------------------------------------------------------ status
    def _say(self, text: str, bad: bool = False) -> None:
        self.status.setText(text)
        self.status.setToolTip(text)
        self.status.setStyleSheet(BAD_STYLE if bad else "")
