"""The Analysis dock's Identify tab: the rig's testbed identified from the ticked logs.

What the worker (jobs.AnalysisJobs.identify) computed, shown: the parameter table (base,
identified, change, 95 % interval, status; a held parameter greyed and in italics, its
reason in the tooltip), a one-line summary of the fit, the notes (which logs served and
why not, what was fitted and not written), and, for the response chosen, the measured
magnitude and phase with the base and identified models over it (the bins the fit used
as dots) and both models' residuals on those bins.  The curves are identification.curves' arrays as they came; the only
arithmetic here is for display (the phase drawn about the identified model's, as the FRF
tab does, so a noisy bin never throws the rest of a curve a turn away).

Save testbed file writes the identified file through identification.testbed_file
(write_identified, which writes nothing that would not load); Open in design workbench
is the panel's (it asks the main window).  The view keeps which file holds the result
shown, so the workbench is only ever opened on the file written from it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor, QFont
from PySide6.QtWidgets import (QComboBox, QHBoxLayout, QLabel, QPlainTextEdit, QPushButton,
                               QSplitter, QVBoxLayout, QWidget)

from ...identification.report import log_line
from ...identification.testbed_file import write_identified
from .jobs import IdentifyResult
# the FRF tab's phase drawing, shared in the package (its tests know it by this name)
from .plots import (_phase_about_model, analysis_plot, caption_label, positive, side_by_side,
                    small_legend)
from .tables import IDENTIFY_COLUMNS, ResultTable, held, identify_row

MEASURED_PEN = pg.mkPen("#90caf9", width=1)
FITTED_BRUSH = pg.mkBrush("#1565c0")
BASE_PEN = pg.mkPen("#616161", width=2, style=Qt.PenStyle.DashLine)
IDENTIFIED_PEN = pg.mkPen("#c62828", width=2)
HELD_COLOUR = QColor("#757575")


def summary_line(result: IdentifyResult) -> str:
    """The fit in one line: logs, bins, how well each model matches the measurements."""
    ident = result.identification
    fit = ident.fit
    used = sum(u.used for u in ident.logs)
    fitted = sum(1 for r in result.rows if not held(r))
    return (f"{used} of {len(ident.logs)} log(s) used, base {ident.base.path.name}; "
            f"{fitted} of {len(result.rows)} parameters identified from {fit.bins_used} bins "
            f"(γ² ≥ {fit.min_coherence:g}, {fit.band_hz[0]:g}-{fit.band_hz[1]:g} Hz); "
            f"model vs measured RMS: base {fit.base_rms_magnitude_db:.2f} dB / "
            f"{fit.base_rms_phase_deg:.1f}°, identified {fit.rms_magnitude_db:.2f} dB / "
            f"{fit.rms_phase_deg:.1f}° (reduced χ² {fit.reduced_chi_square:.2f})")


def notes_text(result: IdentifyResult) -> str:
    """What each log served for, then the identification's notes."""
    lines = [log_line(u) for u in result.identification.logs]
    lines += [f"note: {n}" for n in result.identification.notes]
    return "\n".join(lines)


class IdentifyView(QWidget):
    """Parameter table, summary, notes and the overlays of one identification."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.result: IdentifyResult | None = None
        #: the identified testbed file written from `result` (None: not saved yet)
        self.saved: Path | None = None
        #: the curves of the response shown: plot -> {"measured", "fitted bins", "base",
        #: "identified"} (the residual plot: "base", "identified"); tests read them
        self.curves: dict[str, dict[str, pg.PlotDataItem]] = {}
        self._build()
        self.clear()

    def _build(self) -> None:
        self.summary = caption_label()
        self.summary.setTextFormat(Qt.TextFormat.PlainText)
        self.save_button = QPushButton("Save testbed file…")
        self.save_button.setToolTip("write the identified testbed file (the base file's text "
                                    "with the identified values and an [identification] block)")
        self.open_button = QPushButton("Open in design workbench")
        self.open_button.setToolTip("a controller design on the saved file beside the same "
                                    "design on its base testbed (saves first if needed)")
        self.table = ResultTable(IDENTIFY_COLUMNS)
        self.table.setToolTip("grey, in italics: held at the base value (the status and its "
                              "tooltip say why)")
        self.notes = QPlainTextEdit()
        self.notes.setReadOnly(True)
        self.notes.setStyleSheet("font-size:8pt;")
        self.response = QComboBox()
        self.response.setToolTip("the measured response drawn (input current -> output)")
        self.response.currentIndexChanged.connect(self._draw)
        self.magnitude = analysis_plot("magnitude (dB)", "frequency (Hz)", logx=True, logy=False)
        self.phase = analysis_plot("phase (deg)", "frequency (Hz)", logx=True, logy=False)
        self.residual = analysis_plot("model / measured (dB)", "frequency (Hz)", logx=True,
                                      logy=False)
        for p in (self.phase, self.residual):
            p.setXLink(self.magnitude)
        small_legend(self.magnitude, (10, -10))
        self._lay_out()

    def _lay_out(self) -> None:
        top = QHBoxLayout()
        top.addWidget(self.summary, 1)
        top.addWidget(self.save_button)
        top.addWidget(self.open_button)
        left = QSplitter(Qt.Orientation.Vertical)
        left.addWidget(self.table)
        left.addWidget(self.notes)
        left.setSizes([300, 90])
        plots = QWidget()
        choice = QHBoxLayout()
        choice.addWidget(QLabel("response"))
        choice.addWidget(self.response, 1)
        side_by_side(plots, None, (self.magnitude, self.phase, self.residual), (3, 3, 2))
        plots.layout().insertLayout(0, choice)
        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(left)
        split.addWidget(plots)
        split.setSizes([430, 700])
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(2)
        lay.addLayout(top)
        lay.addWidget(split, 1)

    def plot_widgets(self) -> list[pg.PlotWidget]:
        return [self.magnitude, self.phase, self.residual]

    # ------------------------------------------------------------------ showing
    def clear(self, text: str = "Identify: the rig's testbed fitted to the ticked open-loop "
                                 "identification logs, from the base testbed under "
                                 "Options") -> None:
        self.result, self.saved = None, None
        self.table.clear_rows()
        self.notes.setPlainText("")
        self.response.blockSignals(True)
        self.response.clear()
        self.response.blockSignals(False)
        self._clear_plots()
        self.summary.setText(text)
        self.save_button.setEnabled(False)
        self.open_button.setEnabled(False)

    def _clear_plots(self) -> None:
        for p in self.plot_widgets():
            p.clear()
        self.curves = {}

    def show_result(self, result: IdentifyResult) -> None:
        self.clear()
        self.result = result
        for row in result.rows:
            self._add_parameter(identify_row(row))
        self.summary.setText(summary_line(result) + "; not saved")
        self.summary.setToolTip(result.text)
        self.notes.setPlainText(notes_text(result))
        self.response.blockSignals(True)
        for c in result.curves:
            self.response.addItem(f"{c.label} ({c.which}, {c.source})")
        self.response.blockSignals(False)
        self.response.setCurrentIndex(0)
        self._draw()
        self.save_button.setEnabled(True)
        self.open_button.setEnabled(True)

    def _add_parameter(self, row: dict) -> None:
        self.table.add_row(row)
        r = self.table.rowCount() - 1
        why = row.get("reason") or ""
        sources = ", ".join(row.get("sources") or ())
        tip = "; ".join(t for t in (row["status"], why, f"from {sources}" if sources else "") if t)
        for c in range(self.table.columnCount()):
            item = self.table.item(r, c)
            item.setToolTip(tip)
            if held(row):
                item.setForeground(HELD_COLOUR)
                font = QFont(item.font())
                font.setItalic(True)
                item.setFont(font)

    def _draw(self, *_args) -> None:
        """The chosen response: measured (the fitted bins as dots) with both models over
        it, and the models' residuals."""
        self._clear_plots()
        i = self.response.currentIndex()
        if self.result is None or not 0 <= i < len(self.result.curves):
            return
        c = self.result.curves[i]
        f = c.freq_hz
        self.magnitude.setLabel("left", f"magnitude (dB {c.units})")
        mag = {w: c.magnitude_db(w) for w in ("measured", "base", "identified")}
        # the phases drawn about the identified model's unwrapped phase (display only)
        phase = {w: _phase_about_model(f, getattr(c, w), c.identified, c.phase_deg(w))
                 for w in ("measured", "base", "identified")}
        self.curves["magnitude"] = self._overlay(self.magnitude, f, mag, c.fitted, legend=True)
        self.curves["phase"] = self._overlay(self.phase, f, phase, c.fitted, legend=False)
        res = {}
        for which, pen in (("base", BASE_PEN), ("identified", IDENTIFIED_PEN)):
            y = c.residual_db(which)
            ok = positive(f) & c.fitted
            res[which] = self.residual.plot(f[ok], y[ok], pen=pen)
        self.curves["residual"] = res

    def _overlay(self, plot: pg.PlotWidget, f, y: dict, fitted, legend: bool) -> dict:
        def finite(v):
            return positive(f) & np.isfinite(v)
        out = {}
        ok = finite(y["measured"])
        out["measured"] = plot.plot(f[ok], y["measured"][ok], pen=MEASURED_PEN,
                                    name="measured" if legend else None)
        ok = ok & fitted
        out["fitted bins"] = plot.plot(f[ok], y["measured"][ok], pen=None, symbol="o",
                                       symbolSize=4, symbolPen=None, symbolBrush=FITTED_BRUSH,
                                       name="fitted bins" if legend else None)
        for which, pen, label in (("base", BASE_PEN, "base model"),
                                  ("identified", IDENTIFIED_PEN, "identified model")):
            ok = finite(y[which])
            out[which] = plot.plot(f[ok], y[which][ok], pen=pen, name=label if legend else None)
        return out

    # ------------------------------------------------------------------ saving
    def save(self, path: str | Path, name: str | None = None) -> Path:
        """Write the identified testbed file of the result shown to `path` (its name in
        the file: `name`, default the base's + ' (identified)'); the file as written.
        TestbedWriteError (a GroundStationError) when it is not written."""
        if self.result is None:
            raise ValueError("nothing identified to save")
        ident = self.result.identification
        # the friction logs' slope table, when there were any, goes beside the file; without
        # one the file points at the base's table
        testbed = write_identified(ident.base, ident.written, ident.provenance, path,
                                   name=name or f"{ident.base.name} (identified)",
                                   logs=[p.name for p in self.result.used_logs],
                                   slope_table=ident.slope_table)
        self.saved = testbed.path
        self.summary.setText(f"{summary_line(self.result)}; saved as {testbed.path.name}")
        return testbed.path


__all__ = ["IdentifyView", "notes_text", "summary_line"]
