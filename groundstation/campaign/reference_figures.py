"""The reference metrics drawn (matplotlib's Agg canvas, a Figure of its own per chart,
no pyplot: safe on a GUI worker thread), laid out for the HTML page, and the hysteresis
slope tables written beside the report.

    pngs = figures(metrics)                      # {"step": PNG bytes, "frf_current_coarse": ...}
    html = html_section(metrics, pngs)           # tables + the charts as data: URIs
    files = write_slope_tables(metrics, "logs/NAME/report.json")

Charts, each only when some log has the metric:

    step                  every log's response (reference - error_angle) from its step,
                          overlaid, the commanded reference dashed; the coarse effort below
    frf_<input channel>   magnitude, phase and coherence of each log whose input was that
                          channel, the testbed model's response dashed beside it
    hysteresis            each log's loop: friction torque against the bearing's angle
    slope_table           each identified DB-DHM slope table f(x), with the testbed file's
    friction_velocity     running friction torque against speed (log axis), both directions,
                          the campaign's Coulomb + viscous fit and the testbed file's
                          T_c + b_f v
"""

from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from .metrics import CampaignMetrics
from .metrics_words import describe, num

TITLES = {"step": "Step responses", "hysteresis": "Hysteresis loops",
          "slope_table": "Identified slope tables", "friction_velocity": "Friction against velocity",
          "frf_current_coarse": "Frequency response from the coarse current",
          "frf_current_fine": "Frequency response from the fine current"}
MAX_LOOP_PANELS = 12
#: frequency-response bins below this coherence are not drawn (the coherence panel shows them)
SHOWN_COHERENCE = 0.5


def _label(metrics: CampaignMetrics, i: int) -> str:
    r = metrics.rows[i]
    return describe(r["variables"]) or Path(r["file"]).stem[-32:] or f"log {i + 1}"


def _new(width: float, height: float, rows: int = 1, cols: int = 1, **kw):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, cols, squeeze=False, **kw)


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    return buf.getvalue()


def _having(metrics: CampaignMetrics, name: str) -> list[tuple[int, dict[str, Any]]]:
    return [(i, d[name]) for i, d in sorted(metrics.reference_data.items()) if name in d]


# ---------------------------------------------------------------------- charts
def figures(metrics: CampaignMetrics) -> dict[str, bytes]:
    """The reference metrics' charts as PNG bytes, by name ({} without any)."""
    out: dict[str, bytes] = {}
    steps = _having(metrics, "step")
    if steps:
        out["step"] = _step_chart(metrics, steps)
    by_input: dict[str, list] = {}
    for i, d in _having(metrics, "frf"):
        by_input.setdefault(d["result"].input_channel, []).append((i, d))
    for channel, items in by_input.items():
        out[f"frf_{channel}"] = _frf_chart(metrics, channel, items)
    loops = _having(metrics, "hysteresis")
    if loops:
        out["hysteresis"] = _loop_chart(metrics, loops)
        tables = [(i, d) for i, d in loops if d["result"].identification is not None]
        if tables:
            out["slope_table"] = _slope_chart(metrics, tables)
    fv = _having(metrics, "friction_velocity")
    if fv:
        out["friction_velocity"] = _friction_chart(metrics, fv)
    return out


def _step_chart(metrics, items) -> bytes:
    fig, ax = _new(9.0, 6.0, 2, 1, sharex=True)
    resp, eff = ax[0][0], ax[1][0]
    units = ""
    for k, (i, d) in enumerate(items):
        st, tr = d["result"], d["trace"]
        c = f"C{k % 10}"
        t = (tr["time_s"] - st.step_time_s) * 1e3
        resp.plot(t, (tr["response"] - st.metrics.initial_value) * 1e6, color=c, lw=1.2,
                  label=_label(metrics, i))
        resp.plot(t, (tr["reference"] - st.reference_before) * 1e6, color=c, lw=0.8, ls="--")
        if tr["effort"] is not None:
            eff.plot(t, tr["effort"], color=c, lw=1.0)
            units = f"{st.effort_channel}, {st.effort_units}"
    size = items[0][1]["result"].step_size * 1e6
    for level in (0.98, 1.02):
        resp.axhline(size * level, color="0.6", lw=0.6, ls=":")
    resp.set_ylabel("response from its start, µrad")
    resp.set_title("Step responses (solid) and the commanded reference (dashed); ±2 % band dotted",
                   fontsize=9)
    resp.legend(fontsize=7)
    eff.set_ylabel(units or "effort")
    eff.set_xlabel("time from the step, ms")
    for a in (resp, eff):
        a.grid(alpha=0.3)
    return _png(fig)


def _frf_chart(metrics, channel, items) -> bytes:
    """Measured H1 where its coherence is at least SHOWN_COHERENCE (elsewhere it is noise
    or an unexcited bin), its phase drawn about the model's (model + arg(H/model)), so a
    wrap of the estimate does not break the curve."""
    fig, ax = _new(9.5, 8.0, 3, 1, sharex=True)
    mag, ph, coh = ax[0][0], ax[1][0], ax[2][0]
    for k, (i, d) in enumerate(items):
        res = d["result"]
        m = res.measured
        keep = m.freq_hz > 0
        f = m.freq_hz[keep]
        h = np.asarray(m.response)[keep]
        gamma = np.asarray(m.coherence)[keep]
        shown = np.nan_to_num(gamma) >= SHOWN_COHERENCE
        c = f"C{k % 10}"
        with np.errstate(divide="ignore", invalid="ignore"):
            mag.semilogx(f, np.where(shown, 20 * np.log10(np.abs(h)), np.nan), color=c, lw=0.8,
                         label=_label(metrics, i))
            if res.model is not None:
                model = np.asarray(res.model)[keep]
                model_phase = np.degrees(np.unwrap(np.angle(model)))
                phase = model_phase + np.degrees(np.angle(h / model))
                mag.semilogx(f, 20 * np.log10(np.abs(model)), color=c, lw=1.0, ls="--",
                             label=f"model {res.model_path}")
                ph.semilogx(f, model_phase, color=c, lw=1.0, ls="--")
            else:
                phase = np.degrees(np.angle(h))
        ph.semilogx(f, np.where(shown, phase, np.nan), color=c, lw=0.8)
        coh.semilogx(f, gamma, color=c, lw=0.8)
    coh.axhline(0.9, color="0.4", lw=0.7, ls=":")
    out = items[0][1]["result"].output_channel
    mag.set_title(f"{channel} -> {out}: H1 (solid, where coherence >= {SHOWN_COHERENCE:g}) and the "
                  f"testbed model (dashed)", fontsize=9)
    mag.set_ylabel(f"|H|, dB ({items[0][1]['result'].measured.units})")
    ph.set_ylabel("phase, deg")
    coh.set_ylabel("coherence")
    coh.set_ylim(0, 1.05)
    coh.set_xlabel("frequency, Hz")
    mag.legend(fontsize=7, ncol=2)
    for a in (mag, ph, coh):
        a.grid(alpha=0.3, which="both")
    return _png(fig)


def _loop_chart(metrics, items) -> bytes:
    items = items[:MAX_LOOP_PANELS]
    cols = min(3, len(items))
    rows = int(math.ceil(len(items) / cols))
    fig, ax = _new(4.2 * cols, 3.6 * rows, rows, cols)
    for k, (i, d) in enumerate(items):
        a = ax[k // cols][k % cols]
        h = d["result"]
        angle = d["angle_rad"]
        a.plot((angle - angle.mean()) * 1e6, d["torque_in_oz"], lw=0.7, color=f"C{k % 10}")
        ident = h.identification
        tc = f"T_c {ident.coulomb_torque_in_oz:.3f} in-oz" if ident else "no T_c"
        a.set_title(f"{_label(metrics, i)}\n{len(h.loop.branches)} branches, {tc}", fontsize=8)
        a.set_xlabel(f"{h.angle_channel} about its mean, µrad", fontsize=8)
        a.set_ylabel(f"{h.torque_formula}, in-oz", fontsize=8)
        a.grid(alpha=0.3)
    for k in range(len(items), rows * cols):
        ax[k // cols][k % cols].set_visible(False)
    return _png(fig)


def _slope_chart(metrics, items) -> bytes:
    fig, ax = _new(8.0, 4.5)
    a = ax[0][0]
    shown = set()
    for k, (i, d) in enumerate(items):
        ident = d["result"].identification
        c = f"C{k % 10}"
        a.plot(ident.x, ident.f, color=c, lw=1.0, label=_label(metrics, i))
        a.plot(ident.x[ident.identified], ident.f[ident.identified], "o", color=c, ms=2.5)
        table = d.get("testbed_table")
        if table is not None and table[2] not in shown:
            shown.add(table[2])
            a.plot(table[0], table[1], color="k", lw=1.2, ls="--", label=f"testbed file ({table[2]})")
    a.set_yscale("symlog", linthresh=0.1)
    a.set_xlabel("x = (T - T_k) / T_c")
    a.set_ylabel("f(x) = slope / sigma")
    a.set_title("Identified DB-DHM slope tables (dots: measured points, the rest filled)", fontsize=9)
    a.grid(alpha=0.3)
    a.legend(fontsize=7)
    return _png(fig)


def _friction_chart(metrics, items) -> bytes:
    fig, ax = _new(8.5, 5.0)
    a = ax[0][0]
    speeds = []
    for k, (i, d) in enumerate(items):
        c = f"C{k % 10}"
        name = _label(metrics, i)
        for s in d["result"].result.segments:
            speeds.append(s.speed_deg_s)
            a.plot([s.speed_deg_s], [abs(s.torque_in_oz)], "^" if s.direction > 0 else "v", color=c,
                   ms=7, mfc=c if s.settled else "none", label=name)
            name = None
    summary = metrics.reference_summary.get("friction_velocity", {})
    if speeds:
        grid = np.logspace(np.log10(min(speeds) / 2), np.log10(max(speeds) * 2), 100)
        rad = grid * math.pi / 180
        if summary.get("coulomb_in_oz") is not None:
            b = summary.get("viscous_in_oz_s_per_rad") or 0.0
            a.plot(grid, summary["coulomb_in_oz"] + b * rad, color="k", lw=1.0,
                   label=f"fit: {summary['coulomb_in_oz']:.3g} + {b:.3g}·|v| in-oz")
        tb = summary.get("testbed")
        if tb:
            a.plot(grid, tb["coulomb_in_oz"] + tb["viscous_in_oz_s_per_rad"] * rad, color="0.5",
                   lw=1.0, ls="--", label=f"testbed file: T_c {tb['coulomb_in_oz']:g} + b_f "
                                          f"{tb['viscous_in_oz_s_per_rad']:g}·|v| in-oz")
    a.set_xscale("log")
    a.set_xlabel("speed |v|, deg/s (v in rad/s in the fit)")
    a.set_ylabel("running friction |T|, in-oz")
    a.set_title("Running friction per constant-velocity pass (▲ positive, ▼ negative; hollow: "
                "not settled)", fontsize=9)
    a.grid(alpha=0.3, which="both")
    a.legend(fontsize=7)
    return _png(fig)


# ---------------------------------------------------------------------- slope tables
def slope_table_path(report_path: str | Path, log: str | Path) -> Path:
    return Path(f"{Path(report_path).with_suffix('')}.slope_table.{Path(log).stem}.csv")


def write_slope_tables(metrics: CampaignMetrics, report_path: str | Path) -> list[Path]:
    """Each identified slope table as NAME.slope_table.LOG.csv (the layout of
    profiles/friction_slope_lut.csv); the row's hyst_slope_table_file names it.  A table
    that cannot be written is the row's reference error, not an exception."""
    from ..analysis.friction_id import write_slope_table
    from ..core.errors import GroundStationError

    written = []
    for i, d in _having(metrics, "hysteresis"):
        h = d["result"]
        ident = h.identification
        if ident is None:
            continue
        row = metrics.rows[i]
        path = slope_table_path(report_path, row["file"])
        comment = (f"DB-DHM slope table identified from {Path(row['file']).name} "
                   f"({h.window_from_s:.3f}..{h.window_to_s:.3f} s, {h.torque_formula}), "
                   f"campaign {metrics.campaign}, run {row['run']}\n"
                   f"T_c {ident.coulomb_torque_in_oz:.4g} in-oz"
                   f"{' (estimated from the loop)' if ident.coulomb_torque_estimated else ''}, "
                   f"sigma {ident.sigma_in_oz_per_rad:g} in-oz/rad; "
                   f"{int(np.count_nonzero(ident.identified))} of {ident.x.size} points measured, "
                   f"the rest filled")
        try:
            written.append(write_slope_table(path, ident.x, ident.f, comment=comment))
        except GroundStationError as exc:
            row["reference_error"] = "; ".join(e for e in [row.get("reference_error", ""),
                                                           f"hysteresis: slope table not written: {exc}"] if e)
            continue
        row["metrics"]["hyst_slope_table_file"] = str(path)
    return written


# ---------------------------------------------------------------------- the page
def _e(v: Any) -> str:
    return html.escape("" if v is None else str(v))


def _table(head: list[str], rows: list[list[Any]]) -> str:
    lines = ["<table><tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>"]
    for r in rows:
        lines.append("<tr>" + "".join(f'<td class="text">{_e(v)}</td>' if isinstance(v, str)
                                      else f"<td>{_e(num(v) if isinstance(v, float) else v)}</td>"
                                      for v in r) + "</tr>")
    lines.append("</table>")
    return "\n".join(lines)


def _ms(v: Any) -> Any:
    return None if v is None else v * 1e3


def html_section(metrics: CampaignMetrics, pngs: dict[str, bytes]) -> str:
    """The reference metrics' part of the page: a table per metric, the charts embedded
    ('' when the campaign asks for none)."""
    names = metrics.analysis.metrics
    if not names:
        return ""
    out = [f"<h2>Reference metrics: {_e(', '.join(names))}</h2>"]
    rows = list(enumerate(metrics.rows))

    def head(r):
        return [r["run"], describe(r["variables"]), Path(r["file"]).name]
    if "step" in names:
        out.append("<h3>Step response</h3>")
        out.append(_table(["run", "matrix", "log", "step (µrad)", "rise 10-90 % (ms)", "overshoot (%)",
                           "settling 2 % (ms)", "steady-state error (µrad)", "peak effort"],
                          [head(r) + [m.get("step_size_urad"), _ms(m.get("step_rise_time_s")),
                                      m.get("step_overshoot_pct"), _ms(m.get("step_settling_time_s")),
                                      m.get("step_steady_state_error_urad"),
                                      f"{num(m.get('step_peak_effort'))} {m.get('step_effort_units', '')}"]
                           for _, r in rows if "step" in r["reference"] for m in [r["metrics"]]]))
    if "frf" in names:
        out.append("<h3>Frequency response</h3>")
        out.append(_table(["run", "matrix", "log", "input (RMS A)", "model", "coherence ≥ 0.9 (Hz)",
                           "bins", "median coherence in that band", "vs model RMS (dB)", "max (dB)", "phase max (deg)"],
                          [head(r) + [f"{m.get('frf_input')} ({num(m.get('frf_input_rms_a'))})",
                                      m.get("frf_model") or "n/a",
                                      f"{num(m.get('frf_coherent_from_hz'))}-{num(m.get('frf_coherent_to_hz'))}",
                                      m.get("frf_coherent_bins"), m.get("frf_band_median_coherence"),
                                      m.get("frf_rms_db"), m.get("frf_max_abs_db"),
                                      m.get("frf_max_abs_phase_deg")]
                           for _, r in rows if "frf" in r["reference"] for m in [r["metrics"]]]))
        choices = [f"run {r['run']}: {r['reference']['frf']['input_choice']}" for _, r in rows
                   if "frf" in r["reference"]]
        out.append("<ul>" + "".join(f"<li>{_e(c)}</li>" for c in choices) + "</ul>")
    if "hysteresis" in names:
        out.append("<h3>Hysteresis</h3>")
        out.append(_table(["run", "matrix", "log", "branches (complete)", "travel (µrad)", "torque swing (in-oz)",
                           "T_c (in-oz)", "turnaround slope (in-oz/rad)", "late slope (in-oz/rad)", "f(0)",
                           "slope table"],
                          [head(r) + [f"{m.get('hyst_branches')} ({m.get('hyst_complete_branches')})",
                                      m.get("hyst_travel_urad"), m.get("hyst_torque_swing_in_oz"),
                                      m.get("hyst_coulomb_in_oz"), m.get("hyst_turnaround_slope_in_oz_per_rad"),
                                      m.get("hyst_late_slope_in_oz_per_rad"), m.get("hyst_slope_f0"),
                                      Path(m["hyst_slope_table_file"]).name if m.get("hyst_slope_table_file")
                                      else "identified, not written" if m.get("hyst_slope_table")
                                      else "none"]
                           for _, r in rows if "hysteresis" in r["reference"] for m in [r["metrics"]]]))
    if "friction_velocity" in names:
        out.append("<h3>Friction against velocity</h3>")
        out.append(_table(["run", "matrix", "log", "direction", "speed (deg/s)", "torque (in-oz)",
                           "std (in-oz)", "drift (in-oz)", "settled"],
                          [head(r) + ["+" if s["direction"] > 0 else "-", s["speed_deg_s"],
                                      s["torque_in_oz"], s["torque_std_in_oz"], s["torque_drift_in_oz"],
                                      "yes" if s["settled"] else "no"]
                           for _, r in rows if "friction_velocity" in r["reference"]
                           for s in r["reference"]["friction_velocity"]["segments"]]))
        from .reference_metrics import summary_lines
        lines = summary_lines(metrics.reference_summary)
        if lines:
            out.append("<p>" + "<br>".join(_e(x) for x in lines) + "</p>")
    errors = [f"run {r['run']} {Path(r['file']).name}: {r['reference_error']}" for _, r in rows
              if r.get("reference_error")]
    if errors:
        out.append("<p>Could not be computed:</p><ul>" + "".join(f"<li>{_e(x)}</li>" for x in errors)
                   + "</ul>")
    for name, png in pngs.items():
        title = TITLES.get(name, name)
        data = base64.b64encode(png).decode("ascii")
        out.append(f"<h3>{_e(title)}</h3>"
                   f'<img alt="{_e(title)}" src="data:image/png;base64,{data}">')
    return "\n".join(out)


__all__ = ["TITLES", "figures", "html_section", "slope_table_path", "write_slope_tables"]
