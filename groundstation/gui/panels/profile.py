"""The profile panel: a command profile file -> what it is, what it looks like, and
playing it on the device.

Left, the profile: a file (profiles/waveforms/ or any), its summary (target and units,
length, range, RMS, steepest slope, spectral peak, CRC), what the device would refuse
or warn about, and "Play on device" with the mode, a progress bar and the outcome.
Right, the preview: the samples against time (with a playhead while it plays) and their
power spectral density on log axes.

The widget does no I/O and no numerics: `groundstation.profiles` reads, checks,
summarises and previews the profile; the Session plays it on its worker thread
(`Session.play_profile`, the Station's verb) and its ProfilePlayback (`session.profiles`)
answers with its sig_* signals.
Esc (MainWindow.abort) stops it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QFont
from PySide6.QtWidgets import (QComboBox, QGridLayout, QGroupBox, QHBoxLayout, QLabel,
                               QMessageBox, QProgressBar, QPushButton, QSizePolicy, QVBoxLayout,
                               QWidget)

from ...core.dictionary import Dictionary
from ...core.errors import GroundStationError
from ...core.kinds import LinkState, ProfileOrigin
from ...profiles import (TARGETS, Profile, ProfileCheck, ProfileSummary, check_profile,
                         default_mode, load_profile, preview, summarise)
from ...profiles.profile import WAVEFORMS_DIR
from ..common.dock_layout import controls_beside_plots
from ..common.file_combo import FilePicker
from ..session.session import Session
from ..session.events import PlayOutcome

BAD_STYLE = "color:#c62828; font-weight:bold;"
WARN_STYLE = "color:#b26a00;"
OK_STYLE = "color:#2e7d32; font-weight:bold;"
SMALL_STYLE = "color:#707070; font-size:8pt;"
PLAY_STYLE = ("QPushButton { background:#2e7d32; color:white; font-weight:bold; padding:6px; "
              "border-radius:4px; } QPushButton:disabled { background:#9e9e9e; color:#eeeeee; }")
STOP_STYLE = ("QPushButton { background:#c62828; color:white; font-weight:bold; padding:6px; "
              "border-radius:4px; } QPushButton:disabled { background:#9e9e9e; color:#eeeeee; }")
PENS = {"samples": pg.mkPen("#4e9bff", width=1.5), "psd": pg.mkPen("#ffa62b", width=1.5),
        "playhead": pg.mkPen("#ff5050", width=1.5)}
#: decades of the PSD shown below its peak (a smooth profile's numerical floor is no news)
PSD_DECADES = 9
STATUS_STYLES = {"completed": OK_STYLE, "aborted": BAD_STYLE, "failed": BAD_STYLE,
                 "ended early": BAD_STYLE}


class ProfilePanel(QWidget):
    #: the panel's Stop button: the window's Abort (the device's ABORT, generator off)
    sig_abort = Signal()

    def __init__(self, session: Session, dictionary: Dictionary | None = None,
                 parent: QWidget | None = None):
        super().__init__(parent)
        self.session = session
        self.d = dictionary or session.d
        self.profile: Profile | None = None
        self.check: ProfileCheck | None = None
        self.summary: ProfileSummary | None = None
        self.path: Path | None = None
        #: the last playback's outcome (status, text, PlaybackResult or None)
        self.outcome: PlayOutcome | None = None
        #: tests answer the confirmation dialog through this (None: ask the operator)
        self.confirm_override: bool | None = None
        self._build()
        playback = session.profiles
        playback.sig_step.connect(self._on_step)
        playback.sig_upload.connect(self._on_upload)
        playback.sig_progress.connect(self._on_progress)
        playback.sig_done.connect(self._on_done)
        session.sig_link_state.connect(lambda *_: self._update_buttons())
        session.sig_source.connect(lambda *_: self._update_buttons())
        session.campaign.sig_started.connect(lambda *_: self._update_buttons(campaign=True))
        session.campaign.sig_finished.connect(lambda *_: self._update_buttons(campaign=False))
        session.campaign.sig_failed.connect(lambda *_: self._update_buttons(campaign=False))
        self._update_buttons()

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        outer = QVBoxLayout(self)
        outer.setContentsMargins(4, 2, 4, 2)
        # two short columns (the profile, playing it) beside the plots
        split = controls_beside_plots([self._profile_box(), self._play_box()], self._plots(),
                                      min_width=300, plots_width=800, pad=20)
        outer.addWidget(split, 1)

    def _profile_box(self) -> QGroupBox:
        box = QGroupBox("Profile")
        lay = QVBoxLayout(box)
        lay.setSpacing(3)
        pick = QHBoxLayout()
        self.file = QComboBox()
        self.file.addItem("choose a profile…", "")
        for path in sorted(WAVEFORMS_DIR.glob("*.toml")):
            self.file.addItem(path.stem, str(path))
        self.file.setToolTip("a profile file (profiles/waveforms/README.md describes the format)")
        self.file.setMinimumContentsLength(18)
        self.file.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.browse_button = QPushButton("File…")
        pick.addWidget(self.file, 1)
        pick.addWidget(self.browse_button)
        lay.addLayout(pick)
        self.description = QLabel("")
        self.description.setWordWrap(True)
        self.description.setTextFormat(Qt.TextFormat.PlainText)
        self.description.setStyleSheet(SMALL_STYLE)
        lay.addWidget(self.description)
        grid = QGridLayout()
        grid.setHorizontalSpacing(6)
        grid.setVerticalSpacing(1)
        self.fields: dict[str, QLabel] = {}
        mono = QFont("monospace")
        mono.setStyleHint(QFont.StyleHint.TypeWriter)
        mono.setPointSize(8)
        # two pairs a row: the whole summary in four lines
        for i, (key, label) in enumerate((("target", "Target"), ("duration", "Length"),
                                          ("range", "Range"), ("rms", "RMS"),
                                          ("slope", "Max slope"), ("accel", "Max 2nd der."),
                                          ("peak", "Peak at"), ("crc", "CRC-32"))):
            name = QLabel(label)
            name.setStyleSheet("color:#606060;")
            value = QLabel("-")
            value.setFont(mono)
            value.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            r, c = divmod(i, 2)
            grid.addWidget(name, r, 2 * c)
            grid.addWidget(value, r, 2 * c + 1)
            self.fields[key] = value
        grid.setColumnStretch(1, 1)
        grid.setColumnStretch(3, 1)
        grid.setColumnMinimumWidth(2, 70)
        lay.addLayout(grid)
        self.checks = QLabel("")
        self.checks.setWordWrap(True)
        self.checks.setTextFormat(Qt.TextFormat.RichText)
        self.checks.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        lay.addWidget(self.checks)
        lay.addStretch(1)
        box.setFixedWidth(490)
        self.file_picker = FilePicker(
            self, self.file, self.browse_button, self.load, title="Command profile",
            folder=WAVEFORMS_DIR, file_filter="Profiles (*.toml);;All files (*)",
            loaded=lambda path: self.profile is not None and self.path == path)
        return box

    def _play_box(self) -> QGroupBox:
        box = QGroupBox("Play on the device")
        lay = QVBoxLayout(box)
        lay.setSpacing(3)
        row = QHBoxLayout()
        row.addWidget(QLabel("Mode"))
        self.mode = QComboBox()
        self.mode.setToolTip("the controller mode that plays the profile (SPEC §11.2): set, "
                             "armed, played, disarmed")
        row.addWidget(self.mode, 1)
        lay.addLayout(row)
        buttons = QHBoxLayout()
        self.play_button = QPushButton("▶  Play on device")
        self.play_button.setStyleSheet(PLAY_STYLE)
        self.play_button.setMinimumHeight(32)
        self.play_button.setToolTip("upload (CRC-checked), set the mode, arm, play sample-exact "
                                    "to the end, disarm; journaled in the recording")
        self.stop_button = QPushButton("■  Abort (Esc)")
        self.stop_button.setStyleSheet(STOP_STYLE)
        self.stop_button.setMinimumHeight(32)
        self.stop_button.setToolTip("ABORT: motors to zero, drives off, generator off")
        buttons.addWidget(self.play_button, 2)
        buttons.addWidget(self.stop_button, 1)
        lay.addLayout(buttons)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setValue(0)
        self.progress.setFormat("")
        self.progress.setTextVisible(True)
        lay.addWidget(self.progress)
        self.status = QLabel("")
        self.status.setWordWrap(True)
        self.status.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.status.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        lay.addWidget(self.status)
        lay.addStretch(1)
        box.setFixedWidth(270)
        self.play_button.clicked.connect(self.play)
        self.stop_button.clicked.connect(self.sig_abort.emit)
        return box

    def _plots(self) -> pg.GraphicsLayoutWidget:
        view = pg.GraphicsLayoutWidget()
        view.ci.setContentsMargins(2, 2, 2, 2)
        # side by side: a low dock leaves each plot its full height
        self.time_plot = view.addPlot(row=0, col=0)
        self.psd_plot = view.addPlot(row=0, col=1)
        self.time_plot.setLabel("bottom", "time", units="s")
        self.psd_plot.setLabel("bottom", "frequency", units="Hz")
        self.psd_plot.setLogMode(x=True, y=True)
        # a log axis scaled by an SI prefix reads "(x1e-06)": the label carries the units
        for side in ("left", "bottom"):
            self.psd_plot.getAxis(side).enableAutoSIPrefix(False)
        # labelled decades, unlabelled minor ticks: pyqtgraph's own labels every minor
        # tick of a log axis, and they run into each other
        self.psd_plot.getAxis("bottom").setTicks(_log_ticks())
        # a profile can be minutes long at 1200 samples/s: draw what the pixels can show
        self.time_plot.setDownsampling(auto=True, mode="peak")
        self.time_plot.setClipToView(True)
        font = QFont()
        font.setPointSize(7)
        for p in (self.time_plot, self.psd_plot):
            p.showGrid(x=True, y=True, alpha=0.25)
            for side in ("left", "bottom"):
                p.getAxis(side).setStyle(tickFont=font)
            p.getAxis("left").setWidth(52)
        self.time_plot.setTitle("samples as played", size="9pt")
        self.psd_plot.setTitle("power spectral density", size="9pt")
        self.playhead = pg.InfiniteLine(pos=0, angle=90, pen=PENS["playhead"])
        self.playhead.setVisible(False)
        view.setMinimumWidth(300)
        return view

    # ------------------------------------------------------------------ loading
    def load_dialog(self) -> None:
        self.file_picker.dialog()

    def set_file(self, path: str | Path) -> bool:
        """Choose a profile file (added to the list if needed) and load it."""
        return self.file_picker.set_file(path)

    def load(self, path: str | Path) -> bool:
        """Read, check, summarise and plot a profile (nothing is sent)."""
        path = Path(path)
        try:
            # unchecked: a profile the device would refuse is still shown, with the reason
            profile = load_profile(path, self.d, validate=False)
            check = check_profile(profile, self.d)
            summary = summarise(profile)
            t, x, freqs, psd = preview(profile)
        except GroundStationError as exc:
            self.profile = self.check = self.summary = None
            self.path = None
            self._clear()
            self.checks.setText(f"<span style='color:#c62828'><b>cannot use this file:</b> "
                                f"{_html(str(exc))}</span>")
            self._update_buttons()
            return False
        self.profile, self.check, self.summary, self.path = profile, check, summary, path
        self.outcome = None
        self._show_summary(profile, summary, check)
        self._plot(profile, t, x, freqs, psd)
        self.mode.clear()
        self.mode.addItems(list(TARGETS[profile.target].modes))
        self.mode.setCurrentText(default_mode(profile.target))
        self.progress.setValue(0)
        self.progress.setFormat("")
        self._say(f"{path.name} loaded: nothing sent" + ("" if check.ok else " (the device "
                                                          "would refuse it)"), bad=not check.ok)
        self._update_buttons()
        return True

    def _clear(self) -> None:
        self.description.setText("")
        for label in self.fields.values():
            label.setText("-")
        self.time_plot.clear()
        self.psd_plot.clear()
        self.mode.clear()

    def _show_summary(self, p: Profile, s: ProfileSummary, check: ProfileCheck) -> None:
        u = s.units
        self.description.setText(p.description or "(no description)")
        self.description.setToolTip(p.source)
        origin = ("offsets from the position held after ARM" if s.origin == ProfileOrigin.RELATIVE
                  else "absolute values")
        self.fields["target"].setText(f"{s.target} in {u}")
        self.fields["target"].setToolTip(origin)
        self.fields["duration"].setText(f"{s.duration_s:g} s, {s.sample_count} samples")
        self.fields["range"].setText(f"{_si(s.minimum, u)} … {_si(s.maximum, u)}")
        self.fields["rms"].setText(_si(s.rms, u))
        self.fields["slope"].setText(_si(s.max_slope, f"{u}/s"))
        self.fields["accel"].setText(_si(s.max_accel, f"{u}/s²"))
        self.fields["peak"].setText(f"{s.peak_frequency_hz:.4g} Hz")
        self.fields["crc"].setText(f"{s.crc:08x}")
        lines = []
        if check.ok:
            lines.append("<span style='color:#2e7d32'><b>✓ the device would accept it</b></span>"
                         + (f" ({origin})" if s.origin == ProfileOrigin.RELATIVE else ""))
        lines += [f"<span style='color:#c62828'>✗ {_html(t)}</span>" for t in check.problems]
        lines += [f"<span style='color:#b26a00'>! {_html(t)}</span>" for t in check.warnings]
        self.checks.setText("<br>".join(lines))

    def _plot(self, p: Profile, t: np.ndarray, x: np.ndarray, freqs: np.ndarray,
              psd: np.ndarray) -> None:
        self.time_plot.clear()
        self.psd_plot.clear()
        # short: the axis is only as tall as the dock (the title names the profile)
        what = {"REFERENCE": "angle", "RATE_REFERENCE": "rate"}.get(p.target, "current")
        self.time_plot.setLabel("left", f"Δ {what}" if p.origin == ProfileOrigin.RELATIVE else what,
                                units=p.units)
        self.time_plot.plot(t, x, pen=PENS["samples"])
        self.time_plot.addItem(self.playhead)
        self.playhead.setVisible(False)
        self.time_plot.setXRange(0, max(p.duration, 1.0 / p.rate), padding=0.01)
        self.time_plot.enableAutoRange(axis="y")
        self.time_plot.setTitle(f"{p.name}: samples as played ({p.rate:g} Hz)", size="9pt")
        # log axes: no place for the 0 Hz bin or an empty bin
        keep = (freqs > 0) & (psd > 0)
        self.psd_plot.setLabel("left", f"PSD ({p.units}²/Hz)")
        if keep.any():
            self.psd_plot.plot(freqs[keep], psd[keep], pen=PENS["psd"])
            top = float(np.log10(psd[keep].max()))
            self.psd_plot.setYRange(top - PSD_DECADES, top + 0.5, padding=0)
            self.psd_plot.setXRange(np.log10(freqs[keep][0]), np.log10(freqs[keep][-1]), padding=0)
        self.psd_plot.setTitle(f"power spectral density ({p.units}²/Hz, Welch)", size="9pt")

    # ------------------------------------------------------------------ playing
    def play(self, confirm: bool = True) -> str | None:
        """Ask the Session to play the loaded profile; returns why not (nothing sent).
        confirm=False skips the question: for the simulator's demo, which the operator
        asked for."""
        p = self.profile
        if p is None or self.check is None:
            return self._refuse("load a profile first")
        if not self.check.ok:
            return self._refuse("the device would refuse this profile: " + "; ".join(self.check.problems))
        mode = self.mode.currentText() or default_mode(p.target)
        if confirm and not self._confirm(f"Play {p.name} on the device?\n\nMode {mode}, drives armed, "
                                         f"{p.duration:g} s of {p.target} samples, then disarmed.\n"
                                         f"Esc aborts at any time."):
            self._say("not played (cancelled)")
            return "cancelled"
        reason = self.session.play_profile(p, mode)
        if reason:
            return self._refuse(reason)
        self.outcome = None
        self.progress.setValue(0)
        self.progress.setFormat("starting…")
        self.playhead.setValue(0)
        self.playhead.setVisible(True)
        self._say(f"playing {p.name} in {mode}…")
        self._update_buttons()
        return None

    def _refuse(self, reason: str) -> str:
        self._say(f"not played: {reason}", bad=True)
        return reason

    def _confirm(self, text: str) -> bool:
        if self.confirm_override is not None:
            return self.confirm_override
        return QMessageBox.question(self, "Play profile", text) == QMessageBox.StandardButton.Yes

    def _on_step(self, text: str) -> None:
        self.progress.setFormat(f"{text}…")
        self._say(f"{text}…")
        self._update_buttons()

    def _on_upload(self, fraction: float) -> None:
        self.progress.setFormat("uploading %p%")
        self.progress.setValue(int(1000 * fraction))
        self._update_buttons()

    def _on_progress(self, played: int, count: int) -> None:
        rate = self.profile.rate if self.profile is not None else self.d.control_rate_hz
        self.progress.setFormat(f"playing %p% - {played / rate:.1f} of {count / rate:.1f} s")
        self.progress.setValue(int(1000 * played / max(count, 1)))
        self.playhead.setValue(played / rate)
        self._update_buttons()

    def _on_done(self, outcome: PlayOutcome) -> None:
        self.outcome = outcome
        self.progress.setFormat(outcome.status)
        if outcome.completed:
            self.progress.setValue(1000)
        self.playhead.setVisible(not outcome.completed)   # where it stopped
        self._say(f"{outcome.status.upper()}: {outcome.text}",
                  style=STATUS_STYLES.get(outcome.status, ""))
        self._update_buttons()

    def _update_buttons(self, campaign: bool | None = None) -> None:
        s = self.session
        running_campaign = s.campaign.running if campaign is None else campaign
        connected = (s.replay is None and s.client is not None
                     and s.client.link_state == LinkState.UP)
        ok = self.profile is not None and self.check is not None and self.check.ok
        playing = s.profiles.playing
        self.play_button.setEnabled(ok and connected and not playing and not running_campaign)
        why = ("" if ok and connected and not playing and not running_campaign else
               "load a profile the device accepts" if not ok else
               "connect to the device first" if not connected else
               "a profile is playing" if playing else "a campaign is running")
        self.play_button.setToolTip(why or "upload (CRC-checked), set the mode, arm, play "
                                    "sample-exact to the end, disarm; journaled in the recording")
        self.mode.setEnabled(ok and not playing)

    def _say(self, text: str, bad: bool = False, style: str | None = None) -> None:
        self.status.setText(text)
        self.status.setToolTip(text)
        self.status.setStyleSheet(style if style is not None else (BAD_STYLE if bad else ""))


def _log_ticks(first_decade: int = -4, last_decade: int = 5) -> list[list[tuple[float, str]]]:
    """Fixed ticks for a log10 axis: every decade labelled (0.01, 0.1, 1, 10, ...), the
    2..9 multiples between them unlabelled."""
    major = [(float(d), f"{10.0 ** d:g}") for d in range(first_decade, last_decade + 1)]
    minor = [(float(np.log10(k * 10.0 ** d)), "") for d in range(first_decade, last_decade)
             for k in range(2, 10)]
    return [major, minor]


def _si(value: float, units: str) -> str:
    """1.5e-3 rad -> '1.5 mrad' (0 stays '0 rad')."""
    if value == 0:
        return f"0 {units}"
    return pg.siFormat(float(value), precision=4, suffix=units)


def _html(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


__all__ = ["ProfilePanel"]
