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

The panel lays out and owns its two sides, each an object with a module of its own:
`channel` (a `ChannelEditor`: instrument, basic wave, output; channel_editor.py) and
`base_motion` (a `BaseMotionEditor`: profile, upload, check, plots; base_motion.py).
The panel keeps the status line both sides report to; their common look is in
styles.py.
"""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QHBoxLayout, QLabel, QSizePolicy, QVBoxLayout, QWidget

from ..common.dock_layout import controls_beside_plots
from .base_motion import BaseMotionEditor
from .channel_editor import ChannelEditor
from .styles import BAD_STYLE, WARN_STYLE
from ..session.session import Session


class GeneratorPanel(QWidget):
    """The generator dock: the channel editor and the base-motion editor side by side
    above the status line they report to."""

    def __init__(self, session: Session, parent: QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.gen = session.generator
        self.status = QLabel("")
        self.status.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        # long messages must not widen the window: elided by the layout, whole in the tooltip
        self.status.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.busy = QLabel("")
        self.busy.setStyleSheet(WARN_STYLE)
        self.channel = ChannelEditor(session, self._say, self.busy.setText, self)
        self.base_motion = BaseMotionEditor(self.gen, self.channel, self._say, self)
        self._build()
        g = self.gen
        g.sig_failed.connect(lambda action, text: self._say(f"{action}: {text}", bad=True))
        g.sig_info.connect(self._say)
        g.sig_busy.connect(lambda what: self.busy.setText(f"{what}…" if what else ""))
        self.channel.refresh_resources()

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        outer = QVBoxLayout(self)
        outer.setContentsMargins(4, 2, 4, 2)
        outer.setSpacing(2)
        # three short columns (instrument, basic wave, base motion) beside the plots
        split = controls_beside_plots(
            [self.channel.instrument_box, self.channel.wave_box, self.base_motion.motion_box],
            self.base_motion.plots_view, min_width=280, plots_width=600, pad=40)
        outer.addWidget(split, 1)
        status = QHBoxLayout()
        status.addWidget(self.status, 1)
        status.addWidget(self.busy)
        outer.addLayout(status)

    # ------------------------------------------------------------------ status
    def _say(self, text: str, bad: bool = False) -> None:
        self.status.setText(text)
        self.status.setToolTip(text)
        self.status.setStyleSheet(BAD_STYLE if bad else "")
