"""`groundstation identify`: the lab's own rig identified from its logs, written as a
testbed file (identification/)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from . import arguments

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser(
        "identify", help="identify the rig's plant from its logs; write its testbed file",
        description="Fit the testbed's physical parameters (J1, J2, flexure stiffness and "
                    "damping, the fine motor's torque constant, the gyro's) to the frequency "
                    "responses of open-loop random-excitation logs (the open_loop_sysid "
                    "campaign), starting from a base testbed file, and write the identified "
                    "testbed file.  Exit 0: written; 1: the logs cannot identify the rig "
                    "(nothing written); 2: unreadable input or a report folder that cannot "
                    "be made.")
    s.add_argument("logs", nargs="+", metavar="LOG",
                   help="identification logs (.h5), or a campaign's report.json (its logs)")
    s.add_argument("--testbed", required=True, metavar="BASE.toml",
                   help="the base testbed file of the rig's kind, e.g. "
                        "profiles/testbeds/relative_2dof.toml")
    s.add_argument("--out", default=None, metavar="RIG.toml",
                   help="where to write the identified testbed file (default: only report)")
    s.add_argument("--name", default=None, help="the rig's name in the file "
                                                "(default: the base's name + ' (identified)')")
    s.add_argument("--band", nargs=2, type=arguments.positive, metavar=("LOW", "HIGH"),
                   default=None, help="the frequency band fitted, Hz (default 15 300)")
    s.add_argument("--no-twin-correction", action="store_true",
                   help="do not measure the plant fit's bias on a twin of the identified rig "
                        "(the bias the Dahl friction gives a linear fit, 0.5-1 %% on the "
                        "reference's rig; see docs/identification.md)")
    s.add_argument("--min-coherence", type=arguments.fraction, default=0.9,
                   help="bins below this coherence are not fitted (default 0.9)")
    s.add_argument("--json", default=None, metavar="FILE",
                   help="also write the figures as JSON ('-': standard output)")
    s.add_argument("--report", default=None, metavar="DIR",
                   help="also write the report into DIR (made if missing): identification.txt and "
                        ".json, the figures as identification.*.png and identification.html, "
                        "one self-contained page")
    s.set_defaults(func=_cmd_identify)


def _log_paths(items: list[str]) -> list[Path]:
    """The logs named, a campaign report standing for the logs it lists."""
    from ..campaign.report import CampaignReport

    paths: list[Path] = []
    for item in items:
        p = Path(item)
        if p.suffix == ".json":
            report = CampaignReport.load(p)
            for rec in report.recordings:
                paths += [Path(f) if Path(f).is_absolute() else p.parent / f
                          for f in rec.get("files", [])]
        else:
            paths.append(p)
    return paths


def _report_folder_problem(folder: Path) -> str:
    """Why `folder` cannot be made or written ('' if it can), told before the fit so a
    mistyped --report costs no identification."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        return f"{existing} is not a folder"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"{existing} is not writable"
    return ""


def _write_report(folder: Path, result, written: str) -> int:
    from ..identification.html import write_report

    try:
        paths = write_report(result, folder, written)
    except OSError as exc:
        kept = f" (the testbed file {written} is written)" if written else ""
        print(f"error: --report {folder}: cannot write the report ({exc}){kept}",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"report: {paths[-1].resolve()}", flush=True)
    return EXIT_OK


def _cmd_identify(args) -> int:
    from ..core.errors import GroundStationError
    from ..identification.pipeline import DEFAULT_BAND_HZ, IdentificationError, identify
    from ..identification.report import as_json, as_text
    from ..identification.testbed_file import write_identified

    report = Path(args.report) if args.report else None
    problem = _report_folder_problem(report) if report is not None else ""
    if problem:
        print(f"error: --report {report}: cannot make the report folder ({problem}); "
              f"nothing identified", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        paths = _log_paths(args.logs)
        missing = [str(p) for p in paths if not p.is_file()]
        if missing:
            print(f"error: no such log: {', '.join(missing)}", file=sys.stderr)
            return EXIT_BAD_INPUT
        band = tuple(args.band) if args.band else DEFAULT_BAND_HZ
        if not band[0] < band[1]:
            print(f"error: --band {band[0]:g} {band[1]:g}: LOW must be below HIGH", file=sys.stderr)
            return EXIT_BAD_INPUT
        result = identify(paths, args.testbed, band_hz=band, min_coherence=args.min_coherence,
                          twin_correction=not args.no_twin_correction)
    except IdentificationError as exc:
        print(f"error: {exc}; nothing written", file=sys.stderr)
        return EXIT_FAILED
    except GroundStationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    written = ""
    if args.out:
        name = args.name or f"{result.base.name} (identified)"
        try:
            tb = write_identified(result.base, result.written, result.provenance, args.out,
                                  name=name, logs=[u.path.name for u in result.logs if u.used],
                                  slope_table=result.slope_table)
        except GroundStationError as exc:
            print(as_text(result), flush=True)
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_FAILED
        written = str(tb.path)
    print(as_text(result, written), flush=True)
    if args.json:
        text = json.dumps(as_json(result, written), indent=2)
        if args.json == "-":
            print(text)
        else:
            Path(args.json).write_text(text + "\n", encoding="utf-8")
    return _write_report(report, result, written) if report is not None else EXIT_OK
