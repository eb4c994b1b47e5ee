"""`groundstation campaign ...`: scripted test campaigns from the command line.

    groundstation campaign show FILE                  the steps, expanded over the matrix
    groundstation campaign run FILE [--device sim|ADDRESS] [--fast] [--log-folder DIR]
                                    [--report FILE.json] [--resume FILE.json]

Exit codes: 0 completed, 1 a step failed or the operator aborted (the device was made
safe and the report says which step and why), 2 the campaign file is malformed.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .errors import GroundStationError

EXIT_OK, EXIT_FAILED, EXIT_MALFORMED = 0, 1, 2


def add_parsers(sub) -> argparse._SubParsersAction:
    p = sub.add_parser("campaign", help="scripted test campaigns")
    actions = p.add_subparsers(dest="campaign_action", required=True, metavar="ACTION")
    s = actions.add_parser("show", help="list a campaign's steps")
    s.add_argument("file")
    s.set_defaults(func=_cmd_show)
    s = actions.add_parser("run", help="run a campaign",
                           description="Runs every step; on a failure or Ctrl-C the device is "
                                       "aborted, the generator switched off and the recording "
                                       "closed, and the report names the step and the reason.")
    s.add_argument("file")
    s.add_argument("--device", default="sim", help="sim | tcp://HOST:PORT | serial://PORT?baud=N")
    s.add_argument("--fast", action="store_true",
                   help="with --device sim: run the simulator as fast as it goes (device time)")
    s.add_argument("--generator", default="auto",
                   help="VISA resource of the base-motion generator (auto: the simulator's, "
                        "for an inertial testbed; none: no generator)")
    s.add_argument("--log-folder", default=None, help="where the logs go (default logs/CAMPAIGN)")
    s.add_argument("--report", default=None, help="report file (default: LOG_FOLDER/report.json)")
    s.add_argument("--resume", default=None, help="a report of a failed run: continue from its failed run")
    s.add_argument("--max-step-seconds", type=float, default=None,
                   help="cap every dwell and profile at S seconds (trial runs and tests; "
                        "a base-motion profile keeps its period)")
    s.add_argument("--seed", type=int, default=0, help="simulator seed")
    s.add_argument("--take-over", action="store_true", help="end another host's session")
    s.set_defaults(func=_cmd_run)
    return actions


def _cmd_show(args) -> int:
    from .campaign import load_campaign
    try:
        c = load_campaign(args.file)
    except GroundStationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_MALFORMED
    print(f"campaign {c.name}: {c.description}")
    print(f"testbed {c.testbed}; {c.runs} run(s) over {', '.join(c.matrix) or 'no matrix'}")
    for s in c.steps:
        print(f"  {s.index + 1:3d}  {'run ' + str(s.run) if s.run else s.phase:<9} {s.action:<16} "
              + ", ".join(f"{k}={_short(v)}" for k, v in s.args.items()))
    return EXIT_OK


def _short(v) -> str:
    text = str(v)
    return Path(text).name if "/" in text else text


class _Progress:
    """One line per step on a log, a live bar on a terminal."""

    def __init__(self, total: int):
        self.total = total
        self.tty = sys.stdout.isatty()
        self._last = None

    def __call__(self, step, fraction: float) -> None:
        head = f"[{step.index + 1}/{self.total}] {step.label()}"
        if self.tty:
            bar = "#" * int(20 * fraction)
            print(f"\r{head:<60} [{bar:<20}] {100 * fraction:3.0f}%", end="", flush=True)
            if fraction >= 1.0:
                print(flush=True)
        elif fraction == 0.0 and self._last != step.index:
            self._last = step.index
            print(head, flush=True)


def _cmd_run(args) -> int:
    from .campaign import CampaignReport, CampaignRunner, load_campaign
    from .scripting import Testbed

    try:
        c = load_campaign(args.file)
        resume = CampaignReport.load(args.resume) if args.resume else None
    except GroundStationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_MALFORMED
    folder = Path(args.log_folder or Path("logs") / c.name)
    report_path = Path(args.report or folder / "report.json")
    operator = (lambda prompt: input(f"{prompt} - continue? [y/N] ").strip().lower() == "y") \
        if sys.stdin.isatty() else None
    generator = None if args.generator == "none" else args.generator
    t0 = time.monotonic()
    report = None
    try:
        with Testbed(args.device, testbed=c.testbed, fast=args.fast, generator=generator,
                     log_folder=folder, seed=args.seed, take_over=args.take_over, operator=operator,
                     echo=lambda text: print(f"    {text}", flush=True)) as tb:
            runner = CampaignRunner(c, tb, max_step_seconds=args.max_step_seconds,
                                    progress=_Progress(len(c.steps)))
            report = runner.run(resume)
    except KeyboardInterrupt:
        print("\ninterrupted: the device was aborted and the generator switched off", file=sys.stderr)
    except GroundStationError as exc:
        print(f"error: {exc}", file=sys.stderr)
    if report is None:
        return EXIT_FAILED
    report.save(report_path)
    print(report.summary())
    print(f"report: {report_path} (and {report_path.with_suffix('.txt').name}); "
          f"{time.monotonic() - t0:.1f} s")
    return EXIT_OK if report.status == "completed" else EXIT_FAILED
