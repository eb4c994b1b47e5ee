"""The identification drawn: PNG figures of what the fit saw and what it changed
(matplotlib's Agg canvas, a Figure of its own per chart, no pyplot, so drawing on a
worker thread of the window touches no global state).

    pngs = figures(result)                    # {"responses": PNG bytes, "residuals": ..., ...}
    paths = write_figures(result, folder)     # folder/identification.<name>.png

    responses    each measured response (Bode magnitude and phase) with the base and the
                 identified model; the bins the fit did not use drawn lighter
    residuals    model / measured over the fitted bins, base and identified, per response
    hysteresis   each friction loop with the base and the identified friction model, only
                 when the identification carries a friction fit (`result.friction`)

The curves come from identification.curves and the friction fit's `loop_curves()`: this
module draws and computes no model of its own.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .curves import ResponseCurves, response_curves

TITLES = {"responses": "Measured frequency responses and both models",
          "residuals": "Model / measured over the fitted bins",
          "hysteresis": "Friction loops and both friction models"}
#: the file name of figure NAME in a report folder: identification.NAME.png
FILE_STEM = "identification"
#: responses per row of the Bode figure (a row is a magnitude over a phase panel)
RESPONSES_PER_ROW = 2
LOOPS_PER_ROW = 3
#: the colours of the three things every figure compares, the same in all of them
MEASURED_COLOUR, BASE_COLOUR, IDENTIFIED_COLOUR = "C0", "0.45", "C3"
#: unfitted measured bins are drawn at this opacity: shown, but visibly not what was fitted
UNFITTED_ALPHA = 0.2
#: the base model's dashed line is drawn above the identified one, so where the fit left a
#: curve where it was both stay visible
BASE_ZORDER = 3


def _new_figure(width_in: float, height_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def png_bytes(fig) -> bytes:
    """The figure as PNG; no software tag, so the same drawing gives the same bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    return buf.getvalue()


# ---------------------------------------------------------------------- responses
def _positive_bins(c: ResponseCurves) -> np.ndarray:
    """The bins a log frequency axis can show (the DC bin cannot)."""
    return np.asarray(c.freq_hz) > 0.0


def _broken_at_wraps(phase_deg: np.ndarray) -> np.ndarray:
    """The wrapped phase with a gap where it jumps from +180 to -180 deg, so a model's
    line is not drawn straight across the panel at each wrap."""
    out = np.array(phase_deg, dtype=float)
    if out.size > 1:
        out[1:][np.abs(np.diff(out)) > 180.0] = np.nan
    return out


def _frequency_axis(ax, freq_hz: np.ndarray) -> None:
    """A log frequency axis labelled at 1, 2, 5 x 10^n Hz in plain numbers: the default
    labels of a narrow band (15-300 Hz) print every minor tick as a power of ten."""
    from matplotlib.ticker import NullFormatter

    ax.set_xscale("log")
    f = freq_hz[np.isfinite(freq_hz) & (freq_hz > 0.0)]
    if f.size:
        decades = range(int(np.floor(np.log10(f.min()))), int(np.ceil(np.log10(f.max()))) + 1)
        ticks = [m * 10.0 ** d for d in decades for m in (1, 2, 5)
                 if f.min() <= m * 10.0 ** d <= f.max()]
        ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="both", alpha=0.3)


def _bode_panels(mag_ax, phase_ax, c: ResponseCurves) -> None:
    shown = _positive_bins(c)
    f = c.freq_hz[shown]
    fitted = c.fitted[shown]
    for ax, values, line in ((mag_ax, c.magnitude_db, np.asarray),
                             (phase_ax, c.phase_deg, _broken_at_wraps)):
        measured = values("measured")[shown]
        ax.plot(f[fitted], measured[fitted], ".", color=MEASURED_COLOUR, markersize=3,
                label="measured (fitted bins)")
        ax.plot(f[~fitted], measured[~fitted], ".", color=MEASURED_COLOUR, markersize=3,
                alpha=UNFITTED_ALPHA, label="measured (not fitted)")
        ax.plot(f, line(values("base")[shown]), "--", color=BASE_COLOUR, linewidth=1.0,
                label="base model", zorder=BASE_ZORDER)
        ax.plot(f, line(values("identified")[shown]), "-", color=IDENTIFIED_COLOUR,
                linewidth=1.2, label="identified model")
        _frequency_axis(ax, f)
    mag_ax.set_title(f"{c.label} ({c.which}), {c.source}", fontsize=8)
    mag_ax.set_ylabel(f"magnitude (dB re 1 {c.units})", fontsize=8)
    mag_ax.tick_params(labelbottom=False)
    phase_ax.set_ylabel("phase (deg)", fontsize=8)
    phase_ax.set_xlabel("frequency (Hz)", fontsize=8)
    phase_ax.set_ylim(-185.0, 185.0)
    phase_ax.set_yticks([-180, -90, 0, 90, 180])


def response_figure(curves: Sequence[ResponseCurves]):
    """Bode magnitude over phase for each response, RESPONSES_PER_ROW side by side."""
    cols = min(RESPONSES_PER_ROW, max(1, len(curves)))
    rows = -(-len(curves) // cols)
    fig = _new_figure(6.0 * cols, 4.6 * rows)
    grid = fig.add_gridspec(2 * rows, cols, height_ratios=[2.0, 1.0] * rows)
    for i, c in enumerate(curves):
        row, col = divmod(i, cols)
        mag_ax = fig.add_subplot(grid[2 * row, col])
        phase_ax = fig.add_subplot(grid[2 * row + 1, col], sharex=mag_ax)
        _bode_panels(mag_ax, phase_ax, c)
        if i == 0:
            mag_ax.legend(fontsize=7, loc="best")
    return fig


# ---------------------------------------------------------------------- residuals
def _rms(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(np.square(finite)))) if finite.size else float("nan")


def _residual_panel(ax, c: ResponseCurves, residual, unit: str) -> None:
    f = c.freq_hz[c.fitted]
    for which, colour, style in (("base", BASE_COLOUR, "--"),
                                 ("identified", IDENTIFIED_COLOUR, "-")):
        r = residual(which)[c.fitted]
        ax.plot(f, r, style, marker=".", markersize=2.5, linewidth=0.8, color=colour,
                label=f"{which} (RMS {_rms(r):.2f} {unit})")
    ax.axhline(0.0, color="0.2", linewidth=0.6)
    _frequency_axis(ax, f)
    ax.set_xlabel("frequency (Hz)", fontsize=8)
    ax.legend(fontsize=7, loc="best")


def residual_figure(curves: Sequence[ResponseCurves]):
    """One row per response: the magnitude (dB) and the phase (deg) of model / measured,
    base and identified, over the bins the fit used."""
    fig = _new_figure(11.0, 2.6 * max(1, len(curves)))
    axes = fig.subplots(max(1, len(curves)), 2, squeeze=False)
    for (mag_ax, phase_ax), c in zip(axes, curves):
        if not c.fitted.any():
            mag_ax.set_title(f"{c.label}, {c.source}: no fitted bin", fontsize=8)
            continue
        _residual_panel(mag_ax, c, c.residual_db, "dB")
        _residual_panel(phase_ax, c, c.residual_deg, "deg")
        mag_ax.set_ylabel("magnitude residual (dB)", fontsize=8)
        phase_ax.set_ylabel("phase residual (deg)", fontsize=8)
        mag_ax.set_title(f"{c.label} ({c.which})", fontsize=8)
        phase_ax.set_title(c.source, fontsize=8)
    return fig


# ---------------------------------------------------------------------- hysteresis
def friction_loops(result: Any) -> list:
    """The friction fit's loops (each with `source`, `angle_rad`, `measured_in_oz`,
    `base_in_oz`, `identified_in_oz`); [] when the identification has no friction fit."""
    friction = getattr(result, "friction", None)
    return list(friction.loop_curves()) if friction is not None else []


def _angle_scale(angles_rad: Sequence[np.ndarray]) -> tuple[float, str]:
    """A unit the loops read in: presliding loops span microradians, sliding ones more."""
    span = max((float(np.nanmax(np.abs(a))) for a in angles_rad if np.size(a)), default=0.0)
    if span < 1e-3:
        return 1e6, "µrad"
    if span < 1.0:
        return 1e3, "mrad"
    return 1.0, "rad"


def hysteresis_figure(loops: Sequence[Any]):
    """Each loop: the measured friction torque against the bearing's angle, and the base
    and the identified friction model's torque along the same angle."""
    cols = min(LOOPS_PER_ROW, max(1, len(loops)))
    rows = max(1, -(-len(loops) // cols))
    fig = _new_figure(4.6 * cols, 3.6 * rows)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    scale, unit = _angle_scale([np.asarray(lp.angle_rad, dtype=float) for lp in loops])
    for ax, lp in zip(axes, loops):
        angle = np.asarray(lp.angle_rad, dtype=float) * scale
        ax.plot(angle, lp.measured_in_oz, ".", color=MEASURED_COLOUR, markersize=2,
                label="measured")
        ax.plot(angle, lp.base_in_oz, "--", color=BASE_COLOUR, linewidth=1.0, label="base model",
                zorder=BASE_ZORDER)
        ax.plot(angle, lp.identified_in_oz, "-", color=IDENTIFIED_COLOUR, linewidth=1.2,
                label="identified model")
        ax.set_title(str(lp.source), fontsize=8)
        ax.set_xlabel(f"bearing angle ({unit})", fontsize=8)
        ax.set_ylabel("friction torque (in-oz)", fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for ax in axes[len(loops):]:
        ax.set_visible(False)
    return fig


# ---------------------------------------------------------------------- all of them
def figures(result: Any) -> dict[str, bytes]:
    """Every figure of the identification as PNG bytes, by name (see TITLES); each only
    when there is something to draw in it (the hysteresis: friction loops)."""
    curves = response_curves(result)
    out = {}
    if curves:
        out["responses"] = png_bytes(response_figure(curves))
        out["residuals"] = png_bytes(residual_figure(curves))
    loops = friction_loops(result)
    if loops:
        out["hysteresis"] = png_bytes(hysteresis_figure(loops))
    return out


def figure_path(folder: str | Path, name: str) -> Path:
    return Path(folder) / f"{FILE_STEM}.{name}.png"


def write_figures(result: Any, folder: str | Path,
                  pngs: dict[str, bytes] | None = None) -> list[Path]:
    """Write every figure into `folder` (which must exist) as identification.NAME.png and
    return the paths.  `pngs`: the figures already drawn by figures(result), so a page
    and its files show one drawing instead of drawing twice."""
    drawn = figures(result) if pngs is None else pngs
    paths = []
    for name, png in drawn.items():
        path = figure_path(folder, name)
        path.write_bytes(png)
        paths.append(path)
    return paths


__all__ = ["TITLES", "figure_path", "figures", "friction_loops", "hysteresis_figure",
           "png_bytes", "residual_figure", "response_figure", "write_figures"]
