"""`groundstation conformance --device ADDR`: the protocol conformance suite (SPEC.md)
against any device: `sim` (the simulated testbed, started for the run), tcp://HOST:PORT,
or serial://PORT.  See docs/firmware.md, "Conformance suite".

Exit status: 0 every check passed (skips allowed), 1 a check failed, 2 the suite could
not run (no device, refused session, bad options).
"""

from __future__ import annotations

import sys
import time

EXIT_PASS, EXIT_FAIL, EXIT_CANNOT_RUN = 0, 1, 2


def add_parsers(sub) -> None:
    s = sub.add_parser("conformance", help="check a device against protocol/SPEC.md",
                       description="Run the protocol conformance suite against a device. Each "
                                   "check is named after the SPEC section it tests and prints "
                                   "PASS, FAIL or SKIP with its evidence. Exit 0: all passed "
                                   "(skips allowed); 1: a check failed; 2: cannot run.")
    s.add_argument("--device", default="sim",
                   help="sim (a simulated testbed started for the run) | tcp://HOST:PORT | "
                        "HOST:PORT | serial://PORT?baud=N")
    s.add_argument("--serial", default=None, metavar="PORT",
                   help="talk over this serial port instead (same as --device serial://PORT)")
    s.add_argument("--only", nargs="+", default=[], metavar="SECTION",
                   help="run only these SPEC sections (e.g. 7 §11.1 2.1) or checks whose "
                        "title holds the word")
    s.add_argument("--junit", default=None, metavar="FILE.xml",
                   help="also write a JUnit XML report (one testcase per check)")
    s.add_argument("--allow-motion", action="store_true",
                   help="run the checks that arm the drives (watchdog, profiles); without it "
                        "they are skipped")
    s.add_argument("--testbed", default=None, help="testbed file for --device sim")
    s.set_defaults(func=_cmd_conformance)


def _cmd_conformance(args) -> int:
    from ..core.dictionary import load_dictionary
    from ..core.errors import GroundStationError
    from ..link.address import parse_address
    from ..conformance import report
    from ..conformance.runner import ALL_CHECKS, run_checks

    if args.only and not any(c.selected_by(args.only) for c in ALL_CHECKS):
        sections = sorted({c.section for c in ALL_CHECKS},
                          key=lambda s: [int(x) for x in s[1:].split(".")])
        print(f"error: --only {' '.join(args.only)} selects no check (sections: "
              f"{', '.join(sections)}; or a word of a check's title)", file=sys.stderr)
        return EXIT_CANNOT_RUN
    d = load_dictionary(args.protocol_dir)
    text = f"serial://{args.serial}" if args.serial else args.device
    sim = None
    results = []
    t0 = time.monotonic()
    try:
        if text == "sim":              # real-time pacing: the heartbeat is wall-clock paced
            from ..station.rig import start_simulator

            sim = start_simulator(args.testbed)
            text = f"tcp://{sim.address}" if "://" not in sim.address else sim.address
            print(f"started the simulated testbed on {text}", flush=True)
        address = parse_address(text)
        results = run_checks(d, address, only=args.only, allow_motion=args.allow_motion,
                             say=lambda line: print(line, flush=True),
                             on_result=lambda r: report.print_result(r, lambda l: print(l, flush=True)))
    except GroundStationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_CANNOT_RUN
    finally:
        if sim is not None:
            sim.stop()
    print(f"{report.summary(results)} in {time.monotonic() - t0:.1f} s", flush=True)
    if args.junit:
        try:
            report.write_junit(results, args.junit, suite="hfb-testbed conformance", device=text)
        except OSError as exc:
            print(f"error: {args.junit}: cannot write ({exc.strerror})", file=sys.stderr)
            return EXIT_CANNOT_RUN
        print(f"JUnit report written to {args.junit}")
    return EXIT_FAIL if any(r.status == "FAIL" for r in results) else EXIT_PASS
