"""`groundstation params ...`: controller designs and the parameter table.

    groundstation params validate FILE    check a design file before anything is sent
    groundstation params upload FILE [--device sim|ADDRESS]
                                          validate, upload, verify (read-back + HOUSEKEEPING CRC)
    groundstation params show [--device ...] [--against FILE] [--differences]
                                          the device's table beside the design and the last upload
    groundstation params rollback [--device ...]
                                          re-activate the table active before the last upload
    groundstation params analyze FILE [--against OTHER] [--plot FILE.png] [--freqs 1,5,14,22]
                                          [--disturbance step:u1:2.25] [--step-mrad 0.5]
                                          the PQ method's numbers: margins, PQ crossovers,
                                          T_I(0), alignment, predicted saturation (no device)

Each action is one `_add_<action>(actions)` function below, called from `add_parsers`;
an action that talks to the device adds its own the same way.
Exit codes: 0 accepted, 1 refused (the design is readable but must not be sent),
2 the file cannot be read or is malformed.
"""

from __future__ import annotations

import argparse
import sys

from . import arguments
from .station import add_device_options, command_station, fail, print_progress, status_for
from ..core.errors import GroundStationError

EXIT_OK, EXIT_REFUSED, EXIT_UNREADABLE = 0, 1, 2


def add_parsers(sub) -> argparse._SubParsersAction:
    """Add `params` to the CLI's subcommands; returns its own subparsers for more actions."""
    return arguments.command_group(sub, "params", "controller designs and the parameter table",
                                   _add_validate, _add_upload, _add_show, _add_rollback,
                                   _add_analyze)


def _add_validate(actions) -> None:
    s = actions.add_parser("validate", help="check a controller design file (no device needed)",
                           description="Load a design, discretise it as it would be uploaded, "
                                       "and check it in its loop with the testbed's model. "
                                       "Exit 0: may be sent; 1: refused; 2: unreadable file.")
    s.add_argument("file", help="design file, e.g. profiles/controllers/relative_design2.toml")
    s.set_defaults(func=_cmd_validate)


def _cmd_validate(args) -> int:
    from ..core.dictionary import load_dictionary
    from ..params.design_file import load_design, table_values
    from ..params.loop import report_lines, validate

    try:
        design = load_design(args.file)
        dictionary = load_dictionary(args.protocol_dir)
        report = validate(design, table_values(design, dictionary=dictionary), dictionary)
    except GroundStationError as exc:
        text = str(exc)
        print(f"error: {text if text.startswith(str(args.file)) else f'{args.file}: {text}'}",
              file=sys.stderr)
        return EXIT_UNREADABLE
    for line in report_lines(design, report):
        print(line)
    return EXIT_OK if report.ok else EXIT_REFUSED


def _add_upload(actions) -> None:
    s = actions.add_parser("upload", help="validate a design, upload it and verify it on the device",
                           description="The design's table is built over the device's active one, "
                                       "validated, uploaded in blocks, committed with its CRC, read "
                                       "back entry by entry and confirmed by HOUSEKEEPING. Exit 0: "
                                       "verified; 1: refused or failed (the previous table stays "
                                       "active); 2: unreadable file.")
    s.add_argument("file", help="design file, e.g. profiles/controllers/relative_design2.toml")
    add_device_options(s, history=True)
    s.set_defaults(func=_cmd_upload)


def _add_show(actions) -> None:
    s = actions.add_parser("show", help="the device's active parameter table",
                           description="Three columns: the design (--against), the last table "
                                       "uploaded from this computer, and the device's.")
    s.add_argument("--against", default=None, help="a design file to compare with")
    s.add_argument("--differences", action="store_true", help="only the entries that differ")
    add_device_options(s, history=True)
    s.set_defaults(func=_cmd_show)


def _add_rollback(actions) -> None:
    s = actions.add_parser("rollback", help="re-activate the table active before the last upload")
    add_device_options(s, history=True)
    s.set_defaults(func=_cmd_rollback)


def load_dictionary_for(args):
    from ..core.dictionary import load_dictionary
    return load_dictionary(args.protocol_dir)


def _cmd_upload(args) -> int:
    """params/upload_path.py does the work, through the Station's verb: the table is the
    design's over the device's active one, validated again at the upload gate."""
    from ..params.clearance import ValidationRefused
    from ..params.design_file import load_design
    from ..params.loop import report_lines
    from ..params.upload_path import prepare

    try:
        design = load_design(args.file)
    except GroundStationError as exc:
        text = str(exc)
        return fail(text if text.startswith(str(args.file)) else f"{args.file}: {text}", EXIT_UNREADABLE)
    dictionary = load_dictionary_for(args)
    # refuse before touching the device: the design over the defaults must already pass
    first = prepare(design, dictionary).report
    if not first.ok:
        for line in report_lines(design, first):
            print(line)
        return fail(f"{args.file}: refused, nothing was sent")
    try:
        with command_station(args, dictionary, testbed=str(design.testbed.path)) as station:
            try:
                record = station.upload_design(
                    design, progress=print_progress,
                    on_report=lambda report: print("\n".join(report_lines(design, report))))
            except GroundStationError as exc:
                if isinstance(exc.__cause__, ValidationRefused):
                    return fail(f"{args.file}: refused, nothing was sent")
                raise
            print(f"verified: table {record.crc:08x} v{record.version} active since tick "
                  f"{record.activated_tick} (previous {record.previous_crc:08x}); read back bit for "
                  f"bit, HOUSEKEEPING agrees")
    except GroundStationError as exc:
        return fail(str(exc), status_for(exc))
    return EXIT_OK


def _cmd_show(args) -> int:
    from ..params.compare import format_rows, three_way
    from ..params.upload import provenance
    from ..params.design_file import load_design, table_values
    from ..params import table as ptable

    design_values = None
    testbed = None
    try:
        if args.against:
            design = load_design(args.against)
            testbed = str(design.testbed.path)
    except GroundStationError as exc:
        return fail(str(exc), EXIT_UNREADABLE)
    try:
        with command_station(args, load_dictionary_for(args), testbed=testbed) as station:
            loader = station.parameter_loader()
            active = loader.read_active()
            if args.against:
                design_values = table_values(design, base=active.values, dictionary=station.d)
            uploaded = None
            records = loader.history.records()
            if records:
                uploaded = ptable.unpack(station.d, loader.history.table(records[-1].crc))
            rows = three_way(station.d, {"design": design_values, "uploaded": uploaded,
                                                 "device": active.values})
            print(f"device {station.address}: active table {active.crc:08x}")
            # the same account of the active table that rollback acts on
            origin = provenance(records, active.crc)
            print(f"active {origin.text()}")
            for line in _history_lines(loader.history, active.crc):
                print(line)
            if origin.rollback_target is not None:
                print(f"rollback would re-activate {origin.rollback_target:08x}")
            else:
                print("rollback: nothing to roll back to from this table")
            if station.simulated:
                print(_SIM_NOTE)
            print(format_rows(rows, only_differences=args.differences))
            differ = [r.name for r in rows if r.status == "differs"]
            if differ:
                print(f"{len(differ)} entr{'y differs' if len(differ) == 1 else 'ies differ'}: "
                      + ", ".join(differ))
    except GroundStationError as exc:
        return fail(str(exc), status_for(exc))
    return EXIT_OK


def _history_lines(history, active_crc: int) -> list[str]:
    """What the history holds for this device (params/upload.DeviceHistory): its last
    upload against the active table, or that it has none - never another device's."""
    records = history.records()
    lines = [f"history of this device: {history.identity.text()}"]
    if records:
        r = records[-1]
        lines.append(f"last uploaded from here: {r.crc:08x} v{r.version} from {r.source} - "
                     + ("the device's active table" if r.crc == active_crc else
                        f"NOT the device's active table ({active_crc:08x}): changed since, "
                        f"by another station or a restart"))
        return lines
    others = history.other_records()
    unnamed = sum(1 for r in others if r.identity is None)
    devices = {r.identity for r in others if r.identity is not None}
    lines.append("no upload from here to this device yet: nothing to compare with"
                 + (f" (the history holds {len(others) - unnamed} upload(s) to "
                    f"{len(devices)} other device(s), not compared)" if devices else "")
                 + (f" ({unnamed} older upload(s) name no device and are not compared)"
                    if unnamed else ""))
    return lines


_SIM_NOTE = ("note: --device sim started a new simulated testbed for this command, with its "
             "default table; tables uploaded by earlier commands went with their simulators "
             "(run `groundstation sim` and use --device tcp://... to keep one)")


def _cmd_rollback(args) -> int:
    try:
        with command_station(args, load_dictionary_for(args)) as station:
            try:
                record = station.rollback_params(progress=print_progress)
            except GroundStationError as exc:
                return fail(str(exc) + (f"\n{_SIM_NOTE}" if station.simulated else ""))
            print(f"rolled back: table {record.crc:08x} active again (was {record.previous_crc:08x}), "
                  f"verified")
    except GroundStationError as exc:
        return fail(str(exc), status_for(exc))
    return EXIT_OK


def _add_analyze(actions) -> None:
    s = actions.add_parser(
        "analyze", help="the PQ method's numbers for a design (no device needed)",
        description="Margins and crossovers of the sampled loop (as validate), the PQ "
                    "crossovers, the DC input sensitivity T_I(0), the plant/controller "
                    "alignment at chosen frequencies (with Q = 1 for comparison), and the "
                    "peak motor torques of the linear loop under an input disturbance and a "
                    "reference step against the saturation limits. Exit 0: analysed; "
                    "2: unreadable file or bad option.")
    s.add_argument("file", help="design file, e.g. profiles/controllers/inertial_design1.toml")
    s.add_argument("--against", default=None, metavar="OTHER",
                   help="a second design file, analysed beside the first")
    s.add_argument("--plot", default=None, metavar="FILE.png",
                   help="write the PQ Bode plot with alignment contours, phi(omega), the "
                        "input sensitivities and the time responses as a PNG")
    s.add_argument("--freqs", default="1,5,14,22", metavar="HZ,HZ,...",
                   help="frequencies (Hz) for the alignment table (default 1,5,14,22)")
    s.add_argument("--disturbance", default=None, metavar="SPEC",
                   help="input disturbance: step:u1|u2:IN_OZ or sine:u1|u2:IN_OZ:HZ "
                        "(default: a step of the testbed's Coulomb friction torque into u1)")
    s.add_argument("--step-mrad", type=float, default=0.5,
                   help="reference step for the step response, mrad (default 0.5)")
    s.add_argument("--duration", type=float, default=0.5,
                   help="length of the time responses, s (default 0.5)")
    s.add_argument("--no-gyro", action="store_true",
                   help="inertial designs: leave the gyro's dynamics and delay out of G")
    s.add_argument("--testbed", default=None, metavar="RIG.toml",
                   help="also analyse each design on this testbed (e.g. one written by "
                        "`groundstation identify`), beside the testbed its file names")
    s.set_defaults(func=_cmd_analyze)


def _cmd_analyze(args) -> int:
    from dataclasses import replace

    from ..params.design_file import load_design
    from ..plant.testbed import load_testbed
    from ..params.pq_report import summarize, summary_lines
    from ..params.pq_response import DisturbanceError, parse_disturbance

    try:
        freqs = [float(x) for x in args.freqs.split(",") if x.strip()]
    except ValueError:
        return fail(f"--freqs {args.freqs!r}: give frequencies in Hz separated by commas",
                    EXIT_UNREADABLE)
    if not freqs or not all(0 < f < float("inf") for f in freqs):
        return fail(f"--freqs {args.freqs!r}: give frequencies > 0 Hz", EXIT_UNREADABLE)
    if not (args.duration > 0 and 0 < abs(args.step_mrad) < float("inf")):
        return fail("--duration must be > 0 s and --step-mrad finite and not 0", EXIT_UNREADABLE)
    try:
        disturbance = parse_disturbance(args.disturbance) if args.disturbance else None
    except DisturbanceError as exc:
        return fail(f"--disturbance: {exc}", EXIT_UNREADABLE)
    try:
        rig = load_testbed(args.testbed) if args.testbed else None
    except GroundStationError as exc:
        return fail(f"--testbed: {exc}", EXIT_UNREADABLE)
    summaries = []
    for path in [args.file] + ([args.against] if args.against else []):
        try:
            design = load_design(path)
            # the same controller on the rig's own plant, named so in the report
            on_rig = [] if rig is None else [replace(design, testbed=rig,
                                                     name=f"{design.name} on {rig.name}")]
            for d in [design] + on_rig:
                summaries.append(summarize(d, freqs, disturbance, args.step_mrad * 1e-3,
                                           args.duration, sensor=not args.no_gyro,
                                           dictionary=load_dictionary_for(args)))
        except GroundStationError as exc:
            text = str(exc)
            return fail(text if text.startswith(str(path)) else f"{path}: {text}", EXIT_UNREADABLE)
    for line in summary_lines(summaries):
        print(line)
    if args.plot:
        from ..params.pq_plot import write_figure

        try:
            out = write_figure(summaries, args.plot)
        except OSError as exc:
            return fail(f"--plot {args.plot}: cannot write the figure ({exc.strerror or exc})",
                        EXIT_UNREADABLE)
        print(f"figure:   {out}")
    return EXIT_OK
