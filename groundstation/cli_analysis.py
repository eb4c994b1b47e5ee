"""`groundstation analyze LOG...`: LOS jitter, control energy and spectra of recorded logs.

Argument parsing imports only the standard library; numpy, scipy and h5py come with the
command (groundstation.analysis), matplotlib only with --plot.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

# the analysis package's choices, repeated here so that parsing needs no numpy
# (tests/test_analysis_log.py checks they are the same)
METRICS = ("jitter", "energy", "psd")
SENSORS = ("autocollimator", "los_estimate", "encoder_inner")

EPILOG = """The window (--from/--to) is in seconds of device time from the start of each log.
Jitter figures are in urad: mean, RMS (mean included), standard deviation, the RMS after
the high-pass s/(s + 1/T) of the integration period T, and the windowed smear (the
variance within T, averaged over every window position).  Samples the scored sensor
could not measure (out of range, at the A/D rail) are excluded and counted.  Energy is
i^2 R of each motor (R from the testbed file recorded in the log, or --testbed),
integrated over the frames received; frames missing from the log are counted, not
bridged.  See docs/analysis.md.
exit status: 0 every figure asked for was computed for every log; 1 a log could not
be analysed, or a figure could not be computed from its data (the lines under the table
say why); 2 bad arguments."""

#: (header, row key, format) of the text table, per metric
_COMMON = [("log", "log", "{}"), ("window s", "window", "{}"), ("frames", "frames", "{:d}"),
           ("missing", "missing_frames", "{:d}")]
_COLUMNS = {
    "jitter": [("used", "samples_used", "{:d}"), ("excl", "samples_excluded", "{:d}"),
               ("seg", "segments", "{:d}"), ("mean urad", "mean_urad", "{:.3f}"),
               ("RMS urad", "rms_urad", "{:.3f}"), ("std urad", "std_urad", "{:.3f}"),
               ("HP urad", "highpass_rms_urad", "{:.3f}"), ("smear urad", "smear_rms_urad", "{:.3f}")],
    "energy": [("E coarse J", "energy_coarse_j", "{:.4g}"), ("E fine J", "energy_fine_j", "{:.4g}"),
               ("E total J", "energy_total_j", "{:.4g}"),
               ("Irms coarse A", "rms_current_coarse_a", "{:.4g}"),
               ("Irms fine A", "rms_current_fine_a", "{:.4g}"),
               ("sat coarse %", "saturated_coarse_pct", "{:.2f}"),
               ("sat fine %", "saturated_fine_pct", "{:.2f}")],
    "psd": [("PSD rms urad", "psd_rms_urad", "{:.3f}"), ("df Hz", "psd_resolution_hz", "{:.3g}")],
}
#: every key of a row, in the order of the CSV columns
ROW_KEYS = ["log", "path", "test_name", "from_s", "to_s", "frames", "missing_frames", "sensor",
            "samples_used", "samples_excluded", "segments", "integration_period_s", "mean_urad",
            "rms_urad", "std_urad", "highpass_rms_urad", "smear_rms_urad", "energy_coarse_j",
            "energy_fine_j", "energy_total_j", "rms_current_coarse_a", "rms_current_fine_a",
            "saturated_coarse_pct", "saturated_fine_pct", "psd_rms_urad", "psd_resolution_hz",
            "psd_segments", "notes", "error"]


def _metrics(text: str) -> tuple[str, ...]:
    wanted = tuple(dict.fromkeys(m.strip() for m in text.split(",") if m.strip()))
    bad = [m for m in wanted if m not in METRICS]
    if bad or not wanted:
        raise argparse.ArgumentTypeError(
            f"choose one or more of {','.join(METRICS)} (comma-separated), not {text!r}")
    return wanted


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"must be > 0, not {text}")
    return value


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"not a finite number of seconds: {text}")
    return value


def add_parsers(sub) -> None:
    s = sub.add_parser("analyze", help="LOS jitter, control energy and PSD of recorded logs",
                       description="One row of figures per log: jitter of the scored LOS sensor, "
                                   "control energy per motor, RMS currents, saturation, PSD.",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("logs", nargs="+", metavar="LOG", help="recorded log(s) (.h5)")
    s.add_argument("--metrics", type=_metrics, default=METRICS,
                   help=f"comma-separated, from {','.join(METRICS)} (default: all)")
    s.add_argument("--from", dest="start", type=_seconds, default=None,
                   help="window start, s of device time from the log's start (default: its start)")
    s.add_argument("--to", dest="stop", type=_seconds, default=None,
                   help="window end, s from the log's start (default: its end)")
    s.add_argument("--sensor", choices=SENSORS, default=SENSORS[0],
                   help="LOS signal scored (default: autocollimator, the reference's scoring sensor)")
    s.add_argument("--integration-period", type=_positive, default=1.0, metavar="S",
                   help="sensor integration period T for the high-pass and windowed figures "
                        "(default 1 s)")
    s.add_argument("--psd-segment", type=_positive, default=10.0, metavar="S",
                   help="Welch segment length (default 10 s: 0.1 Hz resolution)")
    s.add_argument("--testbed", default=None, metavar="FILE",
                   help="testbed file for the autocollimator range and motor resistances "
                        "(default: the one recorded in each log)")
    out = s.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="one JSON record per log, to stdout")
    out.add_argument("--csv", action="store_true", help="one CSV row per log, to stdout")
    s.add_argument("--plot", default=None, metavar="FILE.png",
                   help="also draw the PSD and cumulative RMS of the scored sensor (computes "
                        "the PSD even if --metrics leaves it out)")
    s.set_defaults(func=_cmd_analyze)


def _cmd_analyze(args) -> int:
    if args.start is not None and args.stop is not None and args.start > args.stop:
        print(f"error: --from {args.start:g} s is after --to {args.stop:g} s", file=sys.stderr)
        return 2
    from .analysis.log_metrics import analyze_log
    from .errors import GroundStationError
    from .plant.testbed import load_testbed

    testbed = load_testbed(args.testbed) if args.testbed else None    # a bad file: exit 2
    metrics = args.metrics
    if args.plot and "psd" not in metrics:
        metrics = metrics + ("psd",)
    results = []
    for name in args.logs:
        try:
            m = analyze_log(name, metrics=metrics, start_s=args.start, stop_s=args.stop,
                            sensor=args.sensor, integration_period_s=args.integration_period,
                            testbed=testbed, psd_segment_s=args.psd_segment)
        except GroundStationError as exc:
            results.append((name, None, str(exc)))
        else:
            results.append((name, m, ""))
    rows = [_row(name, m, error) for name, m, error in results]
    if args.json:
        print(json.dumps(rows, indent=2))
    elif args.csv:
        w = csv.DictWriter(sys.stdout, fieldnames=ROW_KEYS, lineterminator="\n")
        w.writeheader()
        for row in rows:
            w.writerow({k: "" if v is None else v for k, v in row.items()})
    else:
        _print_table(rows, args.metrics, results)
    # a figure asked for but not computable (all samples excluded, no PSD segment) fails too
    failed = any(error or m.missing_metrics for _, m, error in results)
    if args.plot:
        spectra = [(m.path.name, m.spectrum) for _, m, _ in results if m is not None and m.spectrum]
        if spectra:
            _plot(Path(args.plot), spectra, args.sensor)
            print(f"plot: {args.plot}", file=sys.stderr)
        else:
            print("error: no spectrum to plot (no log could be analysed)", file=sys.stderr)
            failed = True
    return 1 if failed else 0


def _row(name: str, m, error: str) -> dict:
    if m is None:
        row = dict.fromkeys(ROW_KEYS)
        row.update(log=Path(name).name, path=str(name), error=error, notes="")
        return row
    row = {"path": str(name), **m.row()}
    return {k: row.get(k) for k in ROW_KEYS}


def _print_table(rows: list[dict], metrics: tuple[str, ...], results) -> None:
    cols = _COMMON + [c for metric in METRICS if metric in metrics for c in _COLUMNS[metric]]
    table = [[h for h, _, _ in cols]]
    for row in rows:
        if row["error"]:
            table.append([row["log"]] + ["-"] * (len(cols) - 1))
            continue
        cells = []
        for _, key, fmt in cols:
            v = f"{row['from_s']:.3f}-{row['to_s']:.3f}" if key == "window" else row[key]
            cells.append("n/a" if v is None else fmt.format(v))
        table.append(cells)
    widths = [max(len(r[i]) for r in table) for i in range(len(cols))]
    for r in table:
        print("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                        for i, (c, w) in enumerate(zip(r, widths))).rstrip())
    for (name, m, error), row in zip(results, rows):
        if error:
            print(f"{row['log']}: error: {error}")
            continue
        if m.jitter is not None:
            j = m.jitter
            what = f"sensor {j.sensor}, integration period {j.integration_period_s:g} s"
            if j.samples_excluded:
                what += f"; {j.samples_excluded} samples excluded ({j.exclusion_rule})"
            print(f"{row['log']}: {what}")
        if m.energy is not None:
            print(f"{row['log']}: resistances {m.energy.resistance_coarse_ohm:g} / "
                  f"{m.energy.resistance_fine_ohm:g} ohm from {m.testbed_source}")
        for note in m.notes:
            print(f"{row['log']}: note: {note}")


def _plot(path: Path, spectra, sensor: str) -> None:
    """PSD and cumulative RMS of each log's scored sensor, one figure (Agg: no display)."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 7), layout="constrained")
    FigureCanvasAgg(fig)
    ax_psd, ax_csp = fig.subplots(2, 1, sharex=True)
    for name, s in spectra:
        keep = s.frequency_hz > 0                  # log axes: no DC bin
        f = s.frequency_hz[keep]
        ax_psd.loglog(f, s.density[keep] * 1e12, label=name, linewidth=0.8)
        ax_csp.semilogx(f, np.sqrt(np.maximum(s.csp[keep], 0.0)) * 1e6, label=name)
    ax_psd.set_ylabel("PSD, urad^2/Hz")
    ax_psd.set_title(f"{sensor}: Welch PSD and cumulative RMS")
    ax_psd.grid(True, which="both", alpha=0.3)
    ax_csp.set_ylabel("sqrt(CSP), urad")
    ax_csp.set_xlabel("frequency, Hz")
    ax_csp.grid(True, which="both", alpha=0.3)
    ax_psd.legend(fontsize="small")
    fig.savefig(path, dpi=120)
