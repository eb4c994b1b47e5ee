"""`groundstation analyze LOG...`: LOS jitter, control energy and spectra of recorded logs,
and on request a step response, a frequency response, a hysteresis loop and the running
friction against velocity of each.

Argument parsing imports only the standard library; numpy, scipy and h5py come with the
command (groundstation.analysis), matplotlib only with --plot.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from ..analysis.names import AUTO_SENSOR, METRICS, SENSORS
from . import arguments

# the default metrics and the sensors come from analysis/names.py (no numerics); the
# choices below are repeated here so that parsing needs no numpy
# (tests/analysis/test_analysis_log.py checks they are the same)
#: asked for by name only (not in the default): analysis/log_step.py, log_frf.py,
#: log_hysteresis.py, log_friction_velocity.py
EXTRA_METRICS = ("step", "frf", "hysteresis", "friction_velocity")
ALL_METRICS = METRICS + EXTRA_METRICS
FRF_INPUTS = ("current_coarse", "torque_coarse_cmd", "current_fine", "torque_fine_cmd")
FRF_OUTPUTS = ("encoder_outer", "encoder_inner", "gyro_rate", "autocollimator", "los_estimate")
#: coherence at or above which a frequency-response bin counts (log_frf's)
MIN_COHERENCE = 0.9

EPILOG = """The window (--from/--to) is in seconds of device time from the start of each log.
Jitter figures are in urad: mean, RMS (mean included), standard deviation, the RMS after
the high-pass s/(s + 1/T) of the integration period T, and the windowed smear (the
variance within T, averaged over every window position).  Samples the scored sensor
could not measure (out of range, at the A/D rail) are excluded and counted.  Energy is
i^2 R of each motor (R from the testbed file recorded in the log, or --testbed),
integrated over the frames received; frames missing from the log are counted, not
bridged.
Asked for by name: step (response = reference - error_angle, the angle the mode
controls; the step is the reference's largest jump between frames in the window), frf
(H1 of --frf-input to --frf-output against the testbed model, compared over the bins with
coherence >= 0.9), hysteresis (the friction loop of a triangle test; --slope-table
writes the identified DB-DHM table) and friction_velocity (the mean torque across the
bearing on each constant-velocity pass of a velocity-ramp test, with its velocity).
See docs/analysis.md.
exit status: 0 every figure asked for was computed for every log; 1 a log could not
be analysed, or a figure could not be computed from its data (the lines under the table
say why); 2 bad arguments."""

#: (header, row key, format) of the text table, per metric
_COMMON = [("log", "log", "{}"), ("window s", "window", "{}"), ("frames", "frames", "{:d}"),
           ("missing", "missing_frames", "{:d}"), ("excl %", "excluded_pct", "{:.2f}"),
           ("valid", "valid", "{}")]
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


def __getattr__(name: str):
    # ROW_KEYS (every key of a row, in the order of the CSV columns) is defined beside the
    # code that fills a row (analysis/batch_rows.py, numpy); read on first use so that
    # parsing stays standard-library only
    if name == "ROW_KEYS":
        from ..analysis.batch_rows import ROW_KEYS
        return ROW_KEYS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _metrics(text: str) -> tuple[str, ...]:
    wanted = tuple(dict.fromkeys(m.strip() for m in text.split(",") if m.strip()))
    bad = [m for m in wanted if m not in ALL_METRICS]
    if bad or not wanted:
        raise argparse.ArgumentTypeError(
            f"choose one or more of {','.join(ALL_METRICS)} (comma-separated), not {text!r}")
    return wanted








def add_parsers(sub) -> None:
    s = sub.add_parser("analyze", help="LOS jitter, control energy and PSD of recorded logs",
                       description="One row of figures per log: jitter of the scored LOS sensor, "
                                   "control energy per motor, RMS currents, saturation, PSD.",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("logs", nargs="+", metavar="LOG",
                   help="recorded log(s) (.h5), folders of logs (searched recursively) or "
                        "quoted globs ('logs/2026-*/*.h5')")
    s.add_argument("--metrics", type=_metrics, default=METRICS,
                   help=f"comma-separated, from {','.join(ALL_METRICS)} "
                        f"(default: {','.join(METRICS)})")
    s.add_argument("--from", dest="start", type=arguments.seconds, default=None,
                   help="window start, s of device time from the log's start (default: its start)")
    s.add_argument("--to", dest="stop", type=arguments.seconds, default=None,
                   help="window end, s from the log's start (default: its end)")
    s.add_argument("--sensor", choices=(AUTO_SENSOR,) + tuple(SENSORS), default=AUTO_SENSOR,
                   help="LOS signal scored (default auto: per log, by its testbed - the "
                        "autocollimator, the reference's scoring sensor, on the inertial set-up; "
                        "encoder_inner on the relative set-up, which has no autocollimator)")
    s.add_argument("--integration-period", type=arguments.positive, default=1.0, metavar="S",
                   help="sensor integration period T for the high-pass and windowed figures "
                        "(default 1 s)")
    s.add_argument("--max-excluded-fraction", type=arguments.fraction, default=None, metavar="F",
                   help="a window with more than this fraction excluded (sensor out of range "
                        "or at its rail, frames missing) is marked not valid (default 0.01)")
    s.add_argument("--design", default="auto", metavar="auto|none|FILE",
                   help="the mode check: the share of the jitter in the band of the loop's "
                        "lightly damped mode, from the design the log records uploading (auto, "
                        "the default; only when the window ran in its closed-loop mode), from "
                        "FILE, or none")
    s.add_argument("--psd-segment", type=arguments.positive, default=10.0, metavar="S",
                   help="Welch segment length (default 10 s: 0.1 Hz resolution)")
    s.add_argument("--testbed", default=None, metavar="FILE",
                   help="testbed file for the autocollimator range and motor resistances "
                        "(default: the one recorded in each log)")
    s.add_argument("--frf-input", choices=FRF_INPUTS, default=FRF_INPUTS[0],
                   help="frf: the input channel (default current_coarse)")
    s.add_argument("--frf-output", choices=FRF_OUTPUTS, default=FRF_OUTPUTS[0],
                   help="frf: the output channel (default encoder_outer)")
    s.add_argument("--slope-table", default=None, metavar="OUT.csv",
                   help="write the DB-DHM slope table hysteresis identifies (implies "
                        "--metrics hysteresis; several logs: OUT_<log>.csv each)")
    out = s.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="one JSON record per log, to stdout")
    out.add_argument("--csv", action="store_true", help="one CSV row per log, to stdout")
    s.add_argument("--plot", default=None, metavar="FILE.png",
                   help="also draw the PSD and cumulative RMS of the scored sensor (computes "
                        "the PSD even if --metrics leaves it out)")
    b = s.add_argument_group(
        "many logs (a table, on Dask)",
        "With --table, --scheduler, --workers or --serial the logs are analysed as a\n"
        "batch: in a few tasks on Dask worker processes (or one after the other with\n"
        "--serial, which is also chosen, and said, when a local cluster would take longer\n"
        "than the loop), one row per log with its campaign, design, base motion and seed,\n"
        "a progress bar on stderr; a log that cannot be read is a row with its error.\n"
        "See docs/analysis.md, 'Many logs'.")
    b.add_argument("--table", default=None, metavar="OUT",
                   help="write the table to OUT.parquet and OUT.csv (only one of them if OUT "
                        "ends in .parquet or .csv)")
    b.add_argument("--scheduler", type=_scheduler, default=None, metavar="local|none|tcp://HOST:8786",
                   help="local: worker processes on this host (default for a batch big enough "
                        "to pay for starting them); none: a "
                        "serial loop in this process; tcp://HOST:8786: a dask.distributed "
                        "cluster whose workers see the logs under the same paths")
    b.add_argument("--workers", type=arguments.count, default=None, metavar="N",
                   help="local worker processes (default: one per core)")
    b.add_argument("--serial", action="store_true", help="the same as --scheduler none")
    b.add_argument("--scheduler-port", type=arguments.listen_address, default=None,
                   metavar="[HOST:]PORT",
                   help="the local cluster's scheduler listens here (127.0.0.1 unless a host "
                        "is given; default: a free port the system picks)")
    b.add_argument("--dashboard", type=arguments.listen_address, default=None,
                   metavar="[HOST:]PORT",
                   help="serve the local cluster's Dask dashboard here (default: none; needs "
                        "bokeh)")
    s.set_defaults(func=_cmd_analyze)


def _scheduler(text: str) -> str:
    if text in ("local", "none") or "://" in text:
        return text
    raise argparse.ArgumentTypeError(f"local, none or a scheduler address tcp://HOST:PORT, "
                                     f"not {text!r}")




def _expand(names: list[str]) -> list[str]:
    """The logs named on the command line: a folder gives its .h5 files (recursively), a
    glob the shell did not expand gives its matches; a file stays as it was written."""
    import glob

    out: list[str] = []
    for name in names:
        p = Path(name)
        if p.is_dir():
            out += sorted(str(q) for q in p.rglob("*.h5") if q.is_file())
        elif not p.exists() and glob.has_magic(name):
            out += sorted(q for q in glob.glob(name, recursive=True)
                          if q.endswith(".h5")) or [name]             # no match: its row says so
        else:
            out.append(name)
    return out


def _cmd_analyze(args) -> int:
    if args.start is not None and args.stop is not None and args.start > args.stop:
        print(f"error: --from {args.start:g} s is after --to {args.stop:g} s", file=sys.stderr)
        return 2
    if args.table or args.scheduler or args.workers or args.serial or args.scheduler_port \
            or args.dashboard:
        return _cmd_batch(args)
    args.logs = _expand(args.logs)
    from ..analysis.log_metrics import analyze_log
    from ..core.errors import GroundStationError
    from ..plant.testbed import load_testbed

    testbed = load_testbed(args.testbed) if args.testbed else None    # a bad file: exit 2
    extras = tuple(m for m in args.metrics if m in EXTRA_METRICS)
    if args.slope_table and "hysteresis" not in extras:
        extras += ("hysteresis",)
    metrics = tuple(m for m in args.metrics if m in METRICS)
    if args.plot and "psd" not in metrics:
        metrics = metrics + ("psd",)
    results = []
    extra_results = []
    for name in args.logs:
        m, error = None, ""
        if metrics:
            try:
                m = analyze_log(name, metrics=metrics, start_s=args.start, stop_s=args.stop,
                                sensor=args.sensor, integration_period_s=args.integration_period,
                                testbed=testbed, psd_segment_s=args.psd_segment,
                                design=None if args.design == "none" else args.design)
            except GroundStationError as exc:
                error = str(exc)
        results.append((name, m, error))
        # a log that cannot be read at all has that one error, not one per extra metric
        extra_results.append({} if error else _extras(name, extras, args, testbed))
    if args.slope_table:
        _write_slope_tables(Path(args.slope_table), args.logs, extra_results)
    rows = [_row(name, m, error, ex, args.max_excluded_fraction)
            for (name, m, error), ex in zip(results, extra_results)]
    if args.json or args.csv:
        from ..analysis.batch_rows import ROW_KEYS
        _print_rows(rows, ROW_KEYS, args.json)
    else:
        if metrics:
            _print_table(rows, args.metrics, results)
        _print_extras(rows, extra_results)
    # a figure asked for but not computable (all samples excluded, no PSD segment) fails too
    failed = any(error or (m is not None and m.missing_metrics) for _, m, error in results)
    failed = failed or any(isinstance(v, str) for ex in extra_results
                           for k, v in ex.items() if k in EXTRA_METRICS)
    if args.plot:
        spectra = [(m.path.name, m.spectrum) for _, m, _ in results if m is not None and m.spectrum]
        if spectra:
            scored = sorted({m.sensor for _, m, _ in results if m is not None and m.sensor})
            _plot(Path(args.plot), spectra, " / ".join(scored) or args.sensor)
            print(f"plot: {args.plot}", file=sys.stderr)
        else:
            print("error: no spectrum to plot (no log could be analysed)", file=sys.stderr)
            failed = True
    reasons = [(row["log"], row["error"] or
                f"not computed: {', '.join(m.missing_metrics)}"
                + (f" ({row['notes']})" if row["notes"] else ""))
               for (_, m, error), row in zip(results, rows)
               if row["error"] or (m is not None and m.missing_metrics)]
    _say_failures(reasons, len(rows), detailed=args.json or args.csv)
    return 1 if failed else 0


def _say_failures(reasons: list[tuple[str, str]], total: int, detailed: bool) -> None:
    """The reason for exit status 1, on stderr: with --json/--csv (stdout is data) each
    failed log and why; after the printed table, which already says why, their names."""
    if not reasons:
        return
    head = f"error: {len(reasons)} of {total} log(s) could not be analysed"
    if detailed:
        print(head + ":", file=sys.stderr)
        for log, why in reasons:
            print(f"  {log}: {why}", file=sys.stderr)
    else:
        print(f"{head}: {', '.join(log for log, _ in reasons)} (why: above)", file=sys.stderr)


def _batch_options_problem(args, scheduler: str) -> str:
    """What contradicts itself in a batch's options ("" when nothing)."""
    for flag, given in (("--plot", args.plot), ("--slope-table", args.slope_table)):
        if given:
            return f"{flag} is for single logs, not with --table/--scheduler/--workers/--serial"
    if args.serial and args.scheduler not in (None, "none"):
        return f"--serial and --scheduler {args.scheduler}: choose one"
    if scheduler != "local" and (args.scheduler_port or args.dashboard):
        return (f"--scheduler-port and --dashboard are for the local cluster this command "
                f"starts, not with --scheduler {scheduler}")
    return ""


def _cmd_batch(args) -> int:
    """Many logs as one table: in groups on Dask (analysis/batch_dask.py), or the same
    task in a loop here (--serial, or a batch too small to pay for a cluster); rows in
    the order of the sorted paths."""
    scheduler = "none" if args.serial else (args.scheduler or "local")
    problem = _batch_options_problem(args, scheduler)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    from ..analysis.batch import (TABLE_KEYS, BatchOptions, campaign_reports, default_workers,
                                  find_logs, run_serial)
    from ..analysis.batch_table import write_table
    from ..plant.testbed import load_testbed

    if args.testbed:
        load_testbed(args.testbed)                   # a bad file: exit 2 here, not per log
    paths = find_logs(args.logs)
    if not paths:
        print("error: no .h5 logs in " + " ".join(args.logs), file=sys.stderr)
        return 2
    missing = [p for p in paths if not p.exists()]
    if len(missing) == len(paths):          # say so now, not after starting a Dask cluster
        print("error: no such log or folder: " + ", ".join(str(p) for p in missing),
              file=sys.stderr)
        return 2
    for p in missing:
        print(f"note: no such log: {p} (its row says so)", file=sys.stderr)
    options = BatchOptions(metrics=tuple(args.metrics), start_s=args.start, stop_s=args.stop,
                           sensor=args.sensor, integration_period_s=args.integration_period,
                           psd_segment_s=args.psd_segment,
                           testbed=str(Path(args.testbed).absolute()) if args.testbed else None,
                           frf_input=args.frf_input, frf_output=args.frf_output,
                           design=None if args.design == "none" else
                           args.design if args.design == "auto" else str(Path(args.design).absolute()),
                           **({} if args.max_excluded_fraction is None else
                              {"max_excluded_fraction": args.max_excluded_fraction}))
    known, skipped = campaign_reports(paths)
    for report, why in skipped:            # a stray .json beside the logs costs a note
        print(f"note: skipped {report}: {why}", file=sys.stderr)
    if _serial_is_quicker(args, paths):
        scheduler = "none"
    progress = _ProgressBar(len(paths))
    if scheduler == "none":
        rows = run_serial(paths, options, known, progress)
    else:
        from ..analysis.batch_dask import run_dask
        if not args.verbose:
            # distributed logs every start and stop of its scheduler and workers at INFO;
            # the progress bar is what an operator wants to see (-v shows them)
            # (after importing distributed: its import sets its loggers' levels)
            import logging

            import distributed  # noqa: F401
            logging.getLogger("distributed").setLevel(logging.WARNING)
        workers = args.workers or default_workers()
        where = (f"{workers} local worker process(es)" if scheduler == "local"
                 else f"the cluster at {scheduler}")
        print(f"{len(paths)} logs on {where}", file=sys.stderr)
        try:
            rows = run_dask(paths, options, known, scheduler=scheduler, workers=workers,
                            listen=args.scheduler_port, dashboard=args.dashboard,
                            progress=progress)
        except (OSError, TimeoutError) as exc:       # no scheduler there, refused, timed out
            print(f"error: Dask scheduler {scheduler}: {exc}", file=sys.stderr)
            return 2
    failed = [r for r in rows if r["error"]]
    if args.table:
        files = write_table(rows, args.table, TABLE_KEYS)
        print("table: " + ", ".join(str(f) for f in files), file=sys.stderr)
    if args.json or args.csv:
        _print_rows(rows, TABLE_KEYS, args.json)
    else:
        print(f"{len(rows)} logs, {len(rows) - len(failed)} analysed without error, "
              f"{len(failed)} with errors")
        for r in failed:
            print(f"{r['log']}: error: {r['error']}")
    _say_failures([(r["log"], r["error"]) for r in failed], len(rows),
                  detailed=args.json or args.csv)
    return 1 if failed else 0


def _serial_is_quicker(args, paths: list[Path]) -> bool:
    """With no --scheduler, --workers, --serial or port asked for: would a local cluster
    finish after the serial loop (its start is seconds)?  Then say so and use the loop."""
    if args.scheduler or args.workers or args.serial or args.scheduler_port or args.dashboard:
        return False
    from ..analysis.batch import default_workers
    from ..analysis.batch_dask import local_cluster_pays

    sizes = [p.stat().st_size if p.exists() else 0 for p in paths]
    workers = default_workers()
    pays, serial_s, cluster_s = local_cluster_pays(sizes, workers)
    if pays:
        return False
    print(f"{len(paths)} logs ({sum(sizes) / 1e6:.0f} MB) analysed in this process: about "
          f"{serial_s:.0f} s here against {cluster_s:.0f} s on a local Dask cluster of {workers} "
          f"worker(s), its start included (--scheduler local to use it anyway)", file=sys.stderr)
    return True


class _ProgressBar:
    """`[#####-----] k/n logs` on stderr: redrawn in place on a terminal, a line per tenth
    of the batch otherwise (a log file should not get a line per log of thousands)."""

    WIDTH = 30

    def __init__(self, total: int):
        self.total = total
        self.tty = sys.stderr.isatty()
        self.shown = -1

    def __call__(self, done: int, total: int) -> None:
        tenth = done * 10 // max(total, 1)
        if not self.tty and tenth == self.shown and done != total:
            return
        self.shown = tenth
        fill = done * self.WIDTH // max(total, 1)
        bar = f"[{'#' * fill}{'-' * (self.WIDTH - fill)}] {done}/{total} logs"
        end = "\n" if (done == total or not self.tty) else ""
        print(("\r" if self.tty else "") + bar, end=end, file=sys.stderr, flush=True)


def _extras(name: str, extras: tuple[str, ...], args, testbed) -> dict:
    """{metric: result, or the error message} of the extra metrics of one log."""
    from ..analysis.batch_rows import extra_results

    return extra_results(name, extras, start_s=args.start, stop_s=args.stop,
                         frf_input=args.frf_input, frf_output=args.frf_output, testbed=testbed,
                         min_coherence=MIN_COHERENCE)


def _write_slope_tables(out: Path, logs: list[str], extra_results: list[dict]) -> None:
    """Write the slope table of each log whose hysteresis identified one: to `out` for a
    single log, to out's stem + _<log stem> for several.  A log without one is left alone
    (its row says why); an unwritable file becomes the log's hysteresis error."""
    from ..analysis.friction_id import write_slope_table
    from ..core.errors import GroundStationError

    for name, ex in zip(logs, extra_results):
        h = ex.get("hysteresis")
        if isinstance(h, str) or h is None or h.identification is None:
            continue
        path = out if len(logs) == 1 else out.with_name(f"{out.stem}_{Path(name).stem}{out.suffix}")
        ident = h.identification
        comment = (f"DB-DHM slope table identified from {h.path.name} "
                   f"({h.window_from_s:.3f}..{h.window_to_s:.3f} s, {h.torque_formula}), "
                   f"T_c {ident.coulomb_torque_in_oz:.4g} in-oz, "
                   f"sigma {ident.sigma_in_oz_per_rad:g} in-oz/rad")
        try:
            ex["hysteresis_file"] = str(write_slope_table(path, ident.x, ident.f, comment=comment))
        except GroundStationError as exc:
            ex["hysteresis"] = f"slope table not written: {exc}"


def _row(name: str, m, error: str, ex: dict, max_excluded_fraction: float | None = None) -> dict:
    from ..analysis.batch_rows import log_row
    from ..analysis.validity import MAX_EXCLUDED_FRACTION

    return log_row(name, m, error, ex, MIN_COHERENCE,
                   MAX_EXCLUDED_FRACTION if max_excluded_fraction is None else max_excluded_fraction)


def _ms(v) -> str:
    return "n/a" if v is None else f"{v * 1e3:.1f} ms"


def _print_extras(rows: list[dict], extra_results: list[dict]) -> None:
    """One line per extra metric and log (its figures, or its error), then its notes."""
    for row, ex in zip(rows, extra_results):
        log = row["log"]
        for metric, res in ex.items():
            if metric == "hysteresis_file":
                continue
            if isinstance(res, str):
                print(f"{log}: {metric}: error: {res}")
                continue
            if metric == "step":
                s = res.metrics
                settling = (_ms(row["step_settling_s"]) if s.settled else
                            f"not settled within {s.settling_band_fraction * 100:g} %")
                effort = ("n/a" if row["step_peak_effort"] is None else
                          f"{s.peak_effort:.4g} {res.effort_units} ({res.effort_channel})")
                print(f"{log}: step: {res.step_size * 1e6:.4g} urad at {res.step_time_s:.3f} s: "
                      f"rise {_ms(row['step_rise_s'])}, overshoot {s.overshoot_percent:.2f} %, "
                      f"settling {settling}, steady-state error "
                      f"{s.steady_state_error * 1e6:.3g} urad, peak effort {effort}")
            elif metric == "frf":
                if row["frf_coherent_bins"]:
                    band = (f"coherence >= {MIN_COHERENCE:g} from "
                            f"{row['frf_coherent_from_hz']:.3g} to {row['frf_coherent_to_hz']:.3g} "
                            f"Hz ({row['frf_coherent_bins']} bins)")
                else:
                    band = f"no bin with coherence >= {MIN_COHERENCE:g}"
                cmp_ = ("no model comparison" if row["frf_rms_db"] is None else
                        f"RMS {row['frf_rms_db']:.2f} dB from the model ({res.model_path}) "
                        f"over the coherent bins")
                print(f"{log}: frf: {res.input_channel} -> {res.output_channel}: {band}; {cmp_}")
            elif metric == "friction_velocity":
                for s in res.result.segments:
                    print(f"{log}: friction_velocity: {'+' if s.direction > 0 else '-'}"
                          f"{s.speed_deg_s:.4g} deg/s ({s.start_s:.2f}..{s.stop_s:.2f} s): "
                          f"{res.torque_formula} = {s.torque_in_oz:+.4g} in-oz (std "
                          f"{s.torque_std_in_oz:.3g}, drift {s.torque_drift_in_oz:+.3g})"
                          + ("" if s.settled else ", not settled"))
                f = row["fv_friction_in_oz"]
                print(f"{log}: friction_velocity: {row['fv_settled_segments']} of "
                      f"{row['fv_segments']} segment(s) settled; friction "
                      + ("n/a" if f is None else f"{f:.4g} in-oz")
                      + ("" if row["fv_offset_in_oz"] is None
                         else f", offset {row['fv_offset_in_oz']:+.3g} in-oz"))
                for note in res.result.notes:
                    print(f"{log}: {metric}: note: {note}")
            else:
                tc = ("T_c n/a" if row["hyst_coulomb_in_oz"] is None
                      else f"T_c {row['hyst_coulomb_in_oz']:.3f} in-oz")
                slope = row["hyst_turnaround_slope_in_oz_per_rad"]
                slope = "n/a" if slope is None else f"{slope:.4g} in-oz/rad"
                table = "slope table identified" if row["hyst_slope_table"] else "no slope table"
                if row["hyst_slope_table_file"]:
                    table += f", written to {row['hyst_slope_table_file']}"
                print(f"{log}: hysteresis: {row['hyst_branches']} branches "
                      f"({row['hyst_complete_branches']} complete), {tc}, turnaround slope "
                      f"(median) {slope}, {table}")
            for note in res.notes:
                print(f"{log}: {metric}: note: {note}")


def _print_table(rows: list[dict], metrics: tuple[str, ...], results) -> None:
    cols = _COMMON + [c for metric in METRICS if metric in metrics for c in _COLUMNS[metric]]
    table = [[h for h, _, _ in cols]]
    for row, (_, m, _) in zip(rows, results):
        if m is None:                                  # the log could not be analysed
            table.append([row["log"]] + ["-"] * (len(cols) - 1))
            continue
        cells = []
        for _, key, fmt in cols:
            v = (f"{row['from_s']:.3f}-{row['to_s']:.3f}" if key == "window" else
                 None if key == "excluded_pct" and row["excluded_fraction"] is None else
                 100.0 * row["excluded_fraction"] if key == "excluded_pct" else
                 ("yes" if row[key] else "NO") if key == "valid" else row[key])
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
        if not row["valid"]:
            print(f"{row['log']}: NOT VALID: {row['invalid_reason']}")
        if m.mode is not None:
            print(f"{row['log']}: mode check ({m.mode.source}): {m.mode.text()}")
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


def _print_rows(rows: list[dict], keys, as_json: bool) -> None:
    """--json: the rows as a JSON list; --csv: one CSV line per row, empty for None."""
    if as_json:
        print(json.dumps(rows, indent=2))
        return
    w = csv.DictWriter(sys.stdout, fieldnames=keys, lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: "" if v is None else v for k, v in row.items()})
