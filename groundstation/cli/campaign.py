"""`groundstation campaign ...`: scripted test campaigns from the command line.

    groundstation campaign show FILE                  the steps, expanded over the matrix
    groundstation campaign run FILE [--device sim|ADDRESS] [--fast] [--log-folder DIR]
                                    [--report FILE.json] [--resume FILE.json] [--no-analysis]
    groundstation campaign report REPORT.json [--html-only] [--campaign FILE]
                                    the logs' metrics and comparison, again from a saved report

After a run (unless --no-analysis) every log is scored - jitter, control energy - over
the window the campaign's [analysis] table asks for, and compared as it asks; the
metrics (CSV, JSON), bar charts (PNG) and a self-contained HTML page are written beside
the report (campaign/metrics.py).

Exit codes: 0 completed, 1 a step failed or the operator aborted (the device was made
safe and the report says which step and why), 2 the campaign file is malformed or asks
for a value the rig must not be given (nothing was run), 130 interrupted by Ctrl-C (the
device was made safe, the log closed; the report says how to resume).
"""

from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
import time
from pathlib import Path

from ..core.kinds import GeneratorChoice
from ..core.errors import GroundStationError
from . import arguments
from .station import add_sim_port_option, status_for

EXIT_OK, EXIT_FAILED, EXIT_MALFORMED = 0, 1, 2
EXIT_INTERRUPTED = 130            # 128 + SIGINT, as a shell reports Ctrl-C


def add_parsers(sub) -> argparse._SubParsersAction:
    p = sub.add_parser("campaign", help="scripted test campaigns")
    actions = p.add_subparsers(dest="campaign_action", required=True, metavar="ACTION")
    s = actions.add_parser("show", help="list a campaign's steps and check its values",
                           description="Lists every step of every run and checks every value "
                                       "against the protocol dictionary, the testbed's limits "
                                       "and the function generator's, and that every referenced "
                                       "file loads. Exit 0: it may run; 2: problems (listed).")
    s.add_argument("file")
    s.set_defaults(func=_cmd_show)
    s = actions.add_parser("run", help="run a campaign",
                           formatter_class=argparse.RawDescriptionHelpFormatter,
                           description="Checks every value of every step first (as `campaign "
                                       "show` does; nothing runs if any is refused), then runs "
                                       "every step.  On a failure or Ctrl-C the device is "
                                       "aborted, the generator switched off and the recording "
                                       "closed with the reason, and the report names the step "
                                       "and the reason.",
                           epilog="exit status:\n"
                                  "  0    completed\n"
                                  "  1    a step failed or the operator aborted (rig made safe)\n"
                                  "  2    the campaign file is malformed or asks for a value the\n"
                                  "       rig must not be given (nothing was run)\n"
                                  "  130  interrupted by Ctrl-C: rig made safe (ABORT, generator\n"
                                  "       off), the run's log closed with the reason; continue\n"
                                  "       with --resume REPORT.json")
    s.add_argument("file")
    # device ... log folder: None when not typed (a resume takes the report's own: run_setup.py)
    s.add_argument("--device", default=None, help="sim (default) | tcp://HOST:PORT | serial://PORT?baud=N")
    add_sim_port_option(s)
    s.add_argument("--fast", action="store_true", default=None,
                   help="with --device sim: run the simulator as fast as it goes (device time)")
    s.add_argument("--fast-sim", choices=("process", "inline"), default=None,
                   help="with --fast: the simulator in a child process of its own (default; "
                        "a core to itself) or in this process")
    s.add_argument("--generator", default="auto",
                   help="VISA resource of the base-motion generator (auto: the simulator's, "
                        "for an inertial testbed; none: no generator)")
    s.add_argument("--log-folder", default=None, help="where the logs go (default logs/CAMPAIGN)")
    s.add_argument("--report", default=None, help="report file (default: LOG_FOLDER/report.json)")
    s.add_argument("--resume", default=None,
                   help="a report of a failed or interrupted run: continue from its failed run, "
                        "on the set-up the report records (device, fast, seed, testbed, log folder)")
    s.add_argument("--allow-setup-change", action="store_true",
                   help="with --resume: allow a device, clock, seed or testbed other than the "
                        "report's (its runs then come from two set-ups; the report says so)")
    s.add_argument("--max-step-seconds", type=arguments.positive_seconds, default=None,
                   help="cap every dwell and profile at S seconds (trial runs and tests; "
                        "a base-motion profile keeps its period)")
    s.add_argument("--seed", type=int, default=None, help="simulator seed (default 0)")
    s.add_argument("--testbed", default=None, metavar="TESTBED.toml",
                   help="run on this testbed file in place of the campaign's own (e.g. a variant "
                        "of the same rig); every step is checked against it before anything runs")
    s.add_argument("--take-over", action="store_true", help="end another host's session")
    s.add_argument("--no-analysis", action="store_true",
                   help="do not score the logs after the run (no metrics, charts or HTML)")
    # the same two options as monitor/gui (cli.py); this module cannot import cli.py
    s.add_argument("--publish", default=None, metavar="tcp://127.0.0.1:PORT",
                   help="publish what this station receives for read-only consoles "
                        "(gui/monitor/record --watch; loopback; a wider address needs --curve-keys)")
    s.add_argument("--curve-keys", default=None, metavar="DIR",
                   help="the lab's CURVE keys (groundstation fanout keys DIR)")
    s.set_defaults(func=_cmd_run)
    s = actions.add_parser("report", help="score a campaign's logs again from its saved report",
                           description="Reads REPORT.json (written by `campaign run`), scores "
                                       "every log it lists (jitter, control energy) over the "
                                       "window of the campaign file's [analysis] table, and "
                                       "writes beside the report: NAME.metrics.csv, "
                                       "NAME.metrics.json, the bar charts NAME.jitter.png, "
                                       "NAME.energy.png, NAME.relative.png, NAME.html "
                                       "(self-contained) and NAME.txt.  Exit 0: every log "
                                       "scored; 1: some could not be (their rows say why); "
                                       "2: the report or the [analysis] table is unusable.")
    s.add_argument("report", metavar="REPORT.json")
    s.add_argument("--html-only", action="store_true", help="write the HTML page only")
    s.add_argument("--campaign", default=None,
                   help="the campaign file (default: the one the report names), for its "
                        "[analysis] table and matrix")
    s.set_defaults(func=_cmd_report)
    return actions




def _cmd_show(args) -> int:
    from ..campaign import read_campaign
    from ..core.dictionary import load_dictionary

    try:
        c, problems = read_campaign(args.file, load_dictionary(getattr(args, "protocol_dir", None)))
    except GroundStationError as exc:
        _print_problems(exc)
        return EXIT_MALFORMED
    print(f"campaign {c.name}: {c.description}")
    print(f"testbed {c.testbed}; {c.runs} run(s) over {', '.join(c.matrix) or 'no matrix'}")
    for s in c.steps:
        print(f"  {s.index + 1:3d}  {'run ' + str(s.run) if s.run else s.phase:<9} {s.action:<16} "
              + ", ".join(f"{k}={_short(k, v)}" for k, v in s.args.items()))
    if problems:
        for p in problems:
            print(f"error: {p}", file=sys.stderr)
        print(f"refused: {len(problems)} problem(s); `campaign run` would run nothing",
              file=sys.stderr)
        return EXIT_MALFORMED
    print("checked: every value is within the protocol's, the testbed's and the generator's "
          "limits, and every referenced file loads")
    return EXIT_OK


def _refused(why: str) -> int:
    print(f"error: {why}", file=sys.stderr)
    return EXIT_MALFORMED


def _print_problems(exc: GroundStationError) -> None:
    problems = getattr(exc, "problems", None) or [str(exc)]
    for p in problems:
        print(f"error: {p}", file=sys.stderr)
    if len(problems) > 1:
        print(f"refused: {len(problems)} problems; nothing was run", file=sys.stderr)


def _short(key: str, v) -> str:
    """A file reference by its name (the full path is in the campaign file); any other
    value as it is, slashes and all."""
    from ..campaign import PATH_KEYS

    text = str(v)
    return Path(text).name if key in PATH_KEYS and isinstance(v, str) else text


class _Progress:
    """One line per step on a log, a live bar on a terminal."""

    def __init__(self, total: int, interrupted=None):
        self.total = total
        self.tty = sys.stdout.isatty()
        self._last = None
        #: a Ctrl-C noted but not surfaced stops the campaign here (core.stop_request)
        self.interrupted = interrupted

    def __call__(self, step, fraction: float) -> None:
        if self.interrupted is not None and self.interrupted.is_set():
            raise KeyboardInterrupt
        head = f"[{step.index + 1}/{self.total}] {step.label()}"
        if self.tty:
            bar = "#" * int(20 * fraction)
            print(f"\r{head:<60} [{bar:<20}] {100 * fraction:3.0f}%", end="", flush=True)
            if fraction >= 1.0:
                print(flush=True)
        elif fraction == 0.0 and self._last != step.index:
            self._last = step.index
            print(head, flush=True)


def _on_testbed(campaign, testbed: Path, dictionary):
    """The campaign on another testbed file, checked against that file's limits as the
    campaign's own would be (CampaignError listing the problems)."""
    from ..campaign import CampaignError
    from ..campaign.reading import check_campaign

    if not testbed.is_file():
        raise CampaignError(f"--testbed: no file {testbed}")
    campaign = dataclasses.replace(campaign, testbed=testbed.resolve())
    problems = check_campaign(campaign, dictionary)
    if problems:
        raise CampaignError(f"{campaign.path.name} on {testbed.name}: " + "; ".join(problems), problems)
    return campaign


def _cmd_run(args) -> int:
    from ..sim.launch_ahead import discard

    try:
        return _run(args)
    finally:
        discard()           # a simulator launched ahead that the session did not take


def _run(args) -> int:
    from ..campaign import CampaignReport, load_campaign
    from ..campaign.designs_ahead import discretise_designs_ahead
    from ..campaign.run_setup import resolve_setup
    from ..campaign.scoring_behind import ScoringBehind, import_scoring
    from ..core.dictionary import load_dictionary

    given = {k: getattr(args, k) for k in ("device", "fast", "fast_sim", "seed", "testbed", "log_folder")
             if getattr(args, k) is not None}
    # first of all, before this process imports numpy: the simulator's child starts (0.45
    # s, the longest thing before the first run) while this one loads and checks
    _simulator_ahead(args, given)
    try:
        dictionary = load_dictionary(getattr(args, "protocol_dir", None))
        c = load_campaign(args.file, dictionary)
        resume = CampaignReport.load(args.resume) if args.resume else None
        setup, notes = resolve_setup(given, resume.setup if resume else None,
                                     allow_change=args.allow_setup_change,
                                     report_name=args.resume or "the report")
        if setup["testbed"]:
            c = _on_testbed(c, Path(setup["testbed"]), dictionary)
        if args.publish:                # refused before the rig is touched, not after
            from ..fanout.endpoints import check_bind
            check_bind(args.publish, have_keys=bool(args.curve_keys))
    except GroundStationError as exc:
        _print_problems(exc)
        return EXIT_MALFORMED
    if setup["fast"] and args.sim_port is not None:
        return _refused("--sim-port is for the real-time simulator: with --fast the simulator "
                        "is this campaign's own, on a private link - leave out one or the other")
    for note in notes:
        print(note, flush=True)
    folder = Path(setup["log_folder"] or Path("logs") / c.name)
    # a resume writes its report where the one it continues was, unless told otherwise
    report_path = Path(args.report or (args.resume if resume else folder / "report.json"))
    setup = {**setup, "testbed": str(Path(setup["testbed"]).resolve()) if setup["testbed"] else None,
             "log_folder": str(folder)}
    t0 = time.monotonic()
    # while the simulator's child starts: a new design's imports paid here, not in a run
    discretise_designs_ahead(c, dictionary)
    if not args.no_analysis:
        # scoring's imports too, here rather than in its thread: this thread would only
        # wait for the child, and a thread importing beside it measured 3 % slower
        import_scoring()
    scoring = None if args.no_analysis else ScoringBehind(c)
    try:
        return _run_and_score(args, c, setup, folder, report_path, resume, scoring, t0)
    finally:
        if scoring is not None:
            scoring.close()


def _run_and_score(args, c, setup: dict, folder: Path, report_path: Path, resume, scoring,
                   t0: float) -> int:
    """The campaign run, its report saved and its logs scored (each log behind the runs,
    by `scoring`, as its recording ends); the exit status."""
    from ..campaign import CampaignRunner
    from ..core.stop_request import InterruptMemory

    report = None
    interrupted = False
    try:
        tb = _campaign_testbed(args, c, setup, folder)
        with InterruptMemory() as ctrl_c, tb:
            runner = CampaignRunner(c, tb, max_step_seconds=args.max_step_seconds,
                                    progress=_Progress(len(c.steps), ctrl_c.requested),
                                    on_recording=scoring.submit if scoring is not None else None)
            report = runner.run(resume)
    except KeyboardInterrupt:
        # outside a step (connecting, closing): the Testbed's exit has made the rig safe
        interrupted = True
        print("\ninterrupted by the operator (Ctrl-C): the device was aborted and the generator "
              "switched off", file=sys.stderr)
    except GroundStationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        if report is None:
            return status_for(exc)      # 2: the device was not reached, nothing ran
    if report is None:
        return EXIT_INTERRUPTED if interrupted else EXIT_FAILED
    report.setup = setup
    report.save(report_path)
    print(report.summary())
    print(f"report: {report_path} (and {report_path.with_suffix('.txt').name}); "
          f"{time.monotonic() - t0:.1f} s")
    if report.status == "interrupted" and report.recordings and not args.no_analysis:
        # the operator asked to stop: the report is written, the scoring (seconds for a
        # long campaign) waits until asked for
        print(f"metrics not computed after the interrupt: groundstation campaign report "
              f"{shlex.quote(str(report_path))}")
    elif not args.no_analysis and report.recordings:
        _write_metrics(report, report_path, c, scored=scoring)
    if report.status == "interrupted":
        return EXIT_INTERRUPTED
    return EXIT_OK if report.status == "completed" else EXIT_FAILED


def _simulator_ahead(args, given: dict) -> None:
    """With `--device sim --fast` (the simulator in a child process), launch that child
    now, so that its start overlaps the campaign's check (sim/launch_ahead.py).  A guess
    from the campaign file's testbed: when anything about it is off, nothing is launched
    and the check says what is wrong; a child the session does not take is ended."""
    from ..core.kinds import SIMULATED_DEVICE, FastSim, wants_simulated_generator
    from ..core.tomlfile import read_toml
    from ..plant.testbed import load_testbed
    from ..sim.launch_ahead import launch_ahead

    if (args.resume or not given.get("fast") or given.get("device", SIMULATED_DEVICE) != SIMULATED_DEVICE
            or given.get("fast_sim", FastSim.PROCESS) != FastSim.PROCESS):
        return
    path = Path(args.file)
    try:
        testbed = Path(given["testbed"]) if given.get("testbed") else \
            path.parent / read_toml(path, GroundStationError)[0]["campaign"]["testbed"]
        inertial = load_testbed(testbed).inertial
    except (GroundStationError, OSError, KeyError, TypeError, ValueError):
        return
    generator = None if args.generator == GeneratorChoice.NONE else args.generator
    launch_ahead(testbed=testbed, seed=given.get("seed", 0),
                 generator=wants_simulated_generator(generator, inertial=inertial))


def _campaign_testbed(args, c, setup: dict, folder: Path):
    """The campaign's Testbed (a Station), not yet opened."""
    from ..station.options import ConsolePublishing, FastSimOptions
    from ..station.station import Station as Testbed

    operator = (lambda prompt: input(f"{prompt} - continue? [y/N] ").strip().lower() == "y") \
        if sys.stdin.isatty() else None
    generator = None if args.generator == GeneratorChoice.NONE else args.generator
    fast = FastSimOptions(where=setup["fast_sim"]) if setup["fast"] else False
    publishing = (ConsolePublishing(args.publish, curve_keys=args.curve_keys)
                  if args.publish else None)
    tb = Testbed(setup["device"], testbed=c.testbed, fast=fast, generator=generator,
                 log_folder=folder, seed=setup["seed"], take_over=args.take_over,
                 operator=operator, publishing=publishing, sim_listen=args.sim_port,
                 echo=lambda text: print(f"    {text}", flush=True))
    if sum(s.action == "start_recording" for s in c.steps) > 1:
        # the first run's log writer does its imports while the device starts and
        # connects, not in the first start_recording (CampaignRunner would start it only
        # once connected)
        tb.recording.prepare_ahead()
    return tb


def _write_metrics(report, report_path: Path, campaign, *, html_only: bool = False,
                   folder: Path | None = None, scored=None):
    """Score the report's logs (those `scored` has not scored behind the runs) and write
    the outputs beside it; the metrics, or None when they could not be written (said why)."""
    from ..campaign.metrics import campaign_metrics, write_metrics

    t0 = time.monotonic()
    try:
        metrics = campaign_metrics(report, campaign, folder=folder, scored=scored)
        written = write_metrics(metrics, report, report_path, html_only=html_only)
    except (GroundStationError, OSError, ImportError) as exc:
        print(f"error: the metrics could not be written: {exc}", file=sys.stderr)
        return None
    print(metrics.text())
    print(f"metrics: {', '.join(p.name for p in written)} in {report_path.parent}; "
          f"{time.monotonic() - t0:.1f} s")
    return metrics


def _cmd_report(args) -> int:
    from ..campaign import CampaignReport, read_campaign
    from ..core.dictionary import load_dictionary

    report_path = Path(args.report)
    try:
        report = CampaignReport.load(report_path)
    except GroundStationError as exc:
        _print_problems(exc)
        return EXIT_MALFORMED
    source = Path(args.campaign or report.file)
    campaign = None
    try:
        campaign, problems = read_campaign(source, load_dictionary(getattr(args, "protocol_dir", None)))
    except GroundStationError as exc:
        problems = []
        if args.campaign:                       # asked for by name: it must load
            _print_problems(exc)
            return EXIT_MALFORMED
        print(f"warning: the campaign file {source} cannot be read ({str(exc).splitlines()[0]}): "
              f"every log is scored whole, nothing is compared (give --campaign FILE)",
              file=sys.stderr)
    mine = [p for p in problems if ": [analysis]" in p]
    if mine:
        for p in mine:
            print(f"error: {p}", file=sys.stderr)
        return EXIT_MALFORMED
    if not report.recordings:
        print(f"{report_path}: the report lists no recordings: nothing to score", file=sys.stderr)
        return EXIT_FAILED
    metrics = _write_metrics(report, report_path, campaign, html_only=args.html_only,
                             folder=report_path.parent)
    if metrics is None:
        return EXIT_FAILED
    # a log that could not be scored - its jitter/energy or its campaign's own metric - fails
    return EXIT_FAILED if any(r["error"] or r.get("reference_error") for r in metrics.rows) else EXIT_OK
