"""`params analyze --plot`: the PQ views of one or two designs as one PNG (matplotlib's
Agg canvas on a Figure of its own: no global backend, no Qt).

Left column: the PQ Bode plot - |PQ| over the magnitude contours, angle PQ over the phase
contours (filled level regions of phi, groundstation.params.pq) - and phi(omega) beneath.
Right column: ||T_I|| and ||S_I K|| against their perfect-alignment bounds |T_O| and
|T_O| / ||G||, and PQ's locus on the (angle PQ, |PQ|) plane over phi_PQ's filled contours.
Bottom row: the linear responses to the input disturbance and to the reference step,
u1 and u2 with the motor limits, y on the right axis.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .pq import (CONTOUR_LEVELS_DEG, magnitude_contour_deg, phase_contour_deg,
                 pq_alignment_deg)
from .pq_design import ratio_alignment_deg
from .pq_report import DesignSummary
from .tf_algebra import TransferFunction

COLOURS = ("tab:blue", "tab:orange")
CMAP = "RdYlGn_r"                   # green: aligned, red: the paths cancel
FILL_ALPHA = 0.35


def _db(x: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return 20 * np.log10(np.abs(x))


def _wrapped_deg(z: np.ndarray) -> np.ndarray:
    return np.degrees(np.angle(z))


def _bands(ax, f: np.ndarray, y: np.ndarray, z: np.ndarray):
    """Fill the level regions of z(y) (a function of the ordinate only) across f."""
    return ax.contourf([f[0], f[-1]], y, np.column_stack([z, z]), levels=CONTOUR_LEVELS_DEG,
                       cmap=CMAP, alpha=FILL_ALPHA)


def write_figure(summaries: list[DesignSummary], path: str | Path) -> Path:
    """Draw the views of one or two summarized designs into `path` (PNG)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(15, 17), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots(4, 2)
    f = summaries[0].analysis.freqs_hz
    names = " vs ".join(s.design.name for s in summaries)
    fig.suptitle(f"PQ analysis: {names}")

    # --- contours ---------------------------------------------------------------------
    mags = np.concatenate([_db(s.analysis.pq) for s in summaries])
    mags = np.abs(mags[np.isfinite(mags)])        # none when a design leaves u2 unused
    top = max(60.0, float(np.ceil(mags.max() / 20) * 20)) if len(mags) else 60.0
    db = np.linspace(-top, top, 801)
    filled = _bands(ax[0, 0], f, db, magnitude_contour_deg(10 ** (db / 20)))
    deg = np.linspace(-180, 180, 721)
    _bands(ax[1, 0], f, deg, phase_contour_deg(deg))
    grid_db, grid_deg = np.meshgrid(db, deg, indexing="ij")
    pq_grid = 10 ** (grid_db / 20) * np.exp(1j * np.radians(grid_deg))
    ax[2, 1].contourf(grid_deg, grid_db, pq_alignment_deg(pq_grid), levels=CONTOUR_LEVELS_DEG,
                      cmap=CMAP, alpha=FILL_ALPHA)
    fig.colorbar(filled, ax=ax[:3, 0], label="alignment contour (deg)", shrink=0.6)

    one = TransferFunction.constant(1.0)
    ax[2, 0].plot(f, ratio_alignment_deg(summaries[0].design.testbed, one, one, f), ":",
                  color="grey", label="Q = 1")
    for s, colour in zip(summaries, COLOURS):
        a, lf, name = s.analysis, s.analysis.functions, s.design.name
        ax[0, 0].semilogx(f, _db(a.pq), color=colour, label=name)
        ax[1, 0].semilogx(f, _wrapped_deg(a.pq), ".", ms=1.5, color=colour, label=name)
        ax[2, 0].semilogx(f, a.phi_deg, color=colour, label=f"{name}: phi")
        ax[2, 0].semilogx(f, a.phi_pq_deg, "--", color=colour, lw=0.9, label=f"{name}: phi_PQ")
        ax[0, 1].semilogx(f, _db(lf.ti_norm), color=colour, label=f"{name}: ||T_I||")
        ax[0, 1].semilogx(f, _db(lf.ti_bound), "--", color=colour, lw=0.9, label="|T_O| (bound)")
        ax[1, 1].semilogx(f, _db(lf.sik_norm), color=colour, label=f"{name}: ||S_I K||")
        ax[1, 1].semilogx(f, _db(lf.sik_bound), "--", color=colour, lw=0.9,
                          label="|T_O| / ||G|| (bound)")
        ax[2, 1].plot(_wrapped_deg(a.pq), _db(a.pq), ".", ms=1.5, color=colour, label=name)
        for col, resp in ((0, s.responses.disturbance), (1, s.responses.step)):
            ax[3, col].plot(1e3 * resp.t, resp.u[:, 0], color=colour, label=f"{name}: u1")
            ax[3, col].plot(1e3 * resp.t, resp.u[:, 1], "--", color=colour, label=f"{name}: u2")
    d = summaries[0].design
    for col, resp in ((0, summaries[0].responses.disturbance), (1, summaries[0].responses.step)):
        a3 = ax[3, col]
        for lim, style in ((d.saturation_coarse_in_oz, "-"), (d.saturation_fine_in_oz, "--")):
            for sign in (1, -1):
                a3.axhline(sign * lim, color="red", ls=style, lw=0.8)
        peak = max(max(s.saturation.peaks_in_oz + s.step_saturation.peaks_in_oz) for s in summaries)
        a3.set_ylim(-1.15 * max(peak, d.saturation_fine_in_oz), 1.15 * max(peak, d.saturation_fine_in_oz))
        a3.set(xlabel="t (ms)", ylabel="torque (in-oz)",
               title=f"under {resp.label} (linear; red: limits u1 solid, u2 dashed)")
        twin = a3.twinx()
        for s, colour in zip(summaries, COLOURS):
            r = s.responses.disturbance if col == 0 else s.responses.step
            twin.plot(1e3 * r.t, 1e3 * r.y, ":", color=colour, lw=1.0)
        twin.set_ylabel("y (mrad, dotted)")

    ax[0, 0].set(ylabel="|PQ| (dB)", ylim=(-top, top), title="PQ magnitude, magnitude contours")
    ax[1, 0].set(ylabel="angle PQ (deg)", ylim=(-180, 180), yticks=np.arange(-180, 181, 60),
                 title="PQ phase, phase contours")
    ax[2, 0].set(ylabel="phi (deg)", xlabel="frequency (Hz)", ylim=(0, 90),
                 yticks=np.arange(0, 91, 15), title="alignment phi(omega)")
    ax[0, 1].set(ylabel="dB", title="||T_I|| and its bound |T_O|")
    ax[1, 1].set(ylabel="dB (in-oz per rad or rad/s)", xlabel="frequency (Hz)",
                 title="||S_I K|| and its bound |T_O| / ||G||")
    ax[2, 1].set(xlabel="angle PQ (deg)", ylabel="|PQ| (dB)", xlim=(-180, 180), ylim=(-top, top),
                 xticks=np.arange(-180, 181, 60), title="PQ locus over phi_PQ (|P| = |Q|)")
    for a in ax[:2].ravel().tolist() + [ax[2, 0]]:
        a.set_xscale("log")
        a.grid(True, which="both", lw=0.3)
    for a in ax.ravel():
        a.legend(fontsize=7, loc="best")
    out = Path(path)
    fig.savefig(out, dpi=90)
    return out
