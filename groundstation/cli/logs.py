"""`groundstation record | log ... | replay`: the logging commands of the CLI."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from ..core.contracts import CommandChannel, DeviceLink
from ..core.kinds import LinkState
from ..core.errors import GroundStationError
from .station import add_sim_port_option


RECORD_EPILOG = """exit status: 0 the recording ended as asked (--duration, Ctrl-C or SIGTERM: the
log is closed with the reason); 1 the recording failed (disk full ...) or the link was
lost with --no-reconnect; 2 nothing could start (bad input, connection refused: the log,
if one was created, is closed with the reason); 3 another station took the session
over (the log says who and when). After a lost link the recording goes on and the
link is reopened with back-off (1, 2, 4, 8, then every 10 s); the log records the gap."""


def _cmd_record(args) -> int:
    from ..core.dictionary import load_dictionary

    from ..link import format_snapshot
    from ..station.keeper import EXIT_REFUSED, LinkKeeper
    from ..logs.live import attach_recorder, recorder_from_args
    from ..plant.testbed import load_testbed
    from ..core.stop_request import StopRequest

    d = load_dictionary(args.protocol_dir)
    testbed = load_testbed(args.testbed) if args.testbed else None
    failures: list[str] = []
    with StopRequest() as stop:
        rec = recorder_from_args(d, args, testbed, failures.append)
        path = rec.start()
        print(f"recording to {path}", flush=True)
        keeper = LinkKeeper(d, args.device, args.testbed, take_over=args.take_over,
                            on_client=lambda c: attach_recorder(c, rec),
                            say=lambda text: print(text, flush=True), sim_listen=args.sim_port)
        try:
            try:
                client = keeper.open()
            except GroundStationError as exc:
                st = rec.stop(reason=f"connect failed: {exc}")
                # a log that got nothing is removed (Recorder.stop says so in its note)
                kept = (f"the log {path} is closed with that reason" if not st.removed
                        else st.note or f"nothing was recorded: {path} removed")
                print(f"error: {exc}\n{kept}", file=sys.stderr, flush=True)
                return EXIT_REFUSED
            if args.notes:
                rec.note(args.notes)
            _record_device(client, keeper.address, testbed, rec)
            code, reason = _record_loop(args, rec, keeper, client, stop, failures, format_snapshot)
        finally:
            keeper.close()
        st = rec.stop(reason=reason)
        print(f"recorded {st.frames} frames in {len(st.files)} file(s): "
              + ", ".join(str(p) for p in st.files) + f" - {reason}", flush=True)
        return code


def _record_loop(args, rec, keeper, client: DeviceLink, stop, failures,
                 format_snapshot) -> tuple[int, str]:
    """Print the status once a second until the recording should end; returns the exit
    status and the reason the log is closed with."""
    from ..station.keeper import EXIT_FAILED, EXIT_OK

    def journal(state: str, message: str) -> None:
        rec.record("event", {"source": "link", "state": state, "message": message})

    t_end = time.monotonic() + args.duration if args.duration else None
    while True:
        if failures:
            print(f"error: {failures[0]}", file=sys.stderr, flush=True)
            return EXIT_FAILED, failures[0]
        ending = keeper.keep_up(stop.event, reconnect=not args.no_reconnect, on_event=journal)
        if ending is not None:
            return ending.status, ending.reason or stop.reason
        client = keeper.client
        if (reason := stop.ending(t_end, args.duration)) is not None:
            return EXIT_OK, reason
        if not stop.status_due(t_end):
            continue
        st = rec.status()
        print(f"{st.path.name if st.path else ''}: {st.frames} frames, "
              f"{st.bytes / 1e6:.1f} MB | {format_snapshot(client.stats.snapshot())}", flush=True)


def _record_device(client: CommandChannel, address: str, testbed, rec) -> None:
    """Journal what the device says it is (GET_INFO).  Without --testbed, the testbed
    file its description names (logs/device_testbed.py) goes into the journal with it,
    so that `analyze` finds the testbed's constants; with --testbed, warn (and journal
    it) when the device says it runs another testbed."""
    from ..logs.device_testbed import JOURNAL_KIND, described_testbed, device_record

    try:
        reply = client.command("GET_INFO").reply
    except GroundStationError as exc:
        rec.note(f"the device did not say what it is (GET_INFO: {exc})")
        return
    description = str(reply.get("description", ""))
    named, why = (None, "") if testbed is not None else described_testbed(description)
    rec.record(JOURNAL_KIND, device_record(address, reply, named))
    if testbed is None:
        print(f"testbed: {named.path}, named by the device at connect (\"{description}\"); "
              f"recorded in the log (--testbed FILE records another)" if named is not None else
              f"note: the log records no testbed file: {why} - analysing it needs --testbed "
              f"FILE for the motor resistances and the autocollimator's range (or record "
              f"with --testbed FILE)", flush=True)
        return
    rec.record("note", {"text": f"device: {description}"})
    if testbed.path.name in description or testbed.name in description:
        return
    warning = (f"warning: --testbed {testbed.path.name} ({testbed.name}) but the device "
               f"describes itself as \"{description}\" - the log records both; check "
               f"that the testbed file matches the rig")
    print(warning, flush=True)
    rec.record("note", {"text": warning})


def _cmd_log(args) -> int:
    from ..core.dictionary import load_dictionary

    from ..logs import LogReader

    if args.action == "check":
        from ..logs.check import check_log
        result = check_log(args.file)
        try:
            print(result.format(), flush=True)
        except BrokenPipeError:
            # the output's reader left (`log check F | head -1`): the verdict is the exit
            # status all the same (main() would make it 0); the rest of the output goes
            # nowhere, so that Python's flush at exit does not fail on the closed pipe
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        return result.exit_code
    if args.action == "compress":
        # in a process of its own: HDF5 may crash on a failed write (logs/compress_behind.py)
        from ..logs.compress import FAILED
        from ..logs.compress_behind import CompressBehind
        compressing = CompressBehind(echo=lambda text: print(text, flush=True), background=False)
        compressing.submit(args.files)
        outcomes = compressing.finish()
        return 1 if any(o.state == FAILED for o in outcomes) else 0
    if args.action == "info":
        with LogReader(args.file) as r:
            info = r.summary()
            print(info.format())
            for packet in r.packets():
                chans = r.channels(packet)
                print(f"  {packet}: " + ", ".join(
                    f"{c.name} [{c.units}]" if c.units else c.name
                    for c in chans if c.kind in ("eng", "flag", "text")))
            journal = r.journal()
            kinds: dict[str, int] = {}
            for rec in journal:
                kinds[rec.kind] = kinds.get(rec.kind, 0) + 1
            print("  journal: " + (", ".join(f"{n} {k}" for k, n in kinds.items()) or "empty"))
            for rec in r.journal(["parameter_table", "note"]):
                print(f"    {rec.kind}: {rec.data}")
            if "EVENT" in r.packets() and r.n_frames("EVENT"):
                ev = r.read("EVENT", ["level", "code", "text"])
                print(f"  events ({len(ev['text'])}):")
                for t, lvl, code, text in zip(ev["device_time"], ev["level"], ev["code"], ev["text"]):
                    print(f"    t={t:10.3f} s level {int(lvl)} code {int(code)}: {text}")
        return 0
    if args.action == "export":
        out = Path(args.output) if args.output else Path(args.file).with_suffix(
            ".csv" if args.format == "csv" else ".mat")
        channels = args.channels.split(",") if args.channels else None
        from ..logs.export import export
        with LogReader(args.file, salvage=args.salvage) as r:
            res = export(r, out, args.packet, args.format, channels, start=args.start,
                         stop=args.stop, timebase=args.timebase, relative=args.relative,
                         salvage=args.salvage)
        if res.damage:
            print(f"salvaged {res.rows} rows of {args.packet} to {out}; {res.damage}; "
                  f"nothing after that was exported")
            return 1
        print(f"wrote {res.rows} rows of {args.packet} to {out}")
        return 0
    if args.action == "redecode":
        from ..logs.redecode import redecode
        counts = redecode(args.file, args.output, load_dictionary(args.protocol_dir))
        print(f"wrote {args.output}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
        return 0
    raise GroundStationError(f"unknown log action {args.action}")


def _cmd_replay(args) -> int:
    from ..core.dictionary import load_dictionary

    from ..gui.app import display_available
    from ..link import format_snapshot
    from ..logs import ReplaySource

    if not args.headless and display_available():
        from ..gui.app import run_gui
        return run_gui(load_dictionary(args.protocol_dir), connect=None, replay=args.file)

    speed = None if args.speed == "max" else float(args.speed)
    with ReplaySource(args.file, speed=speed) as src:
        if args.start is not None:
            src.seek(args.start)
        print(f"replaying {args.file}: {src.duration:.1f} s of device time at "
              f"{'full speed' if speed is None else f'{speed:g}x'}", flush=True)
        src.play()
        try:
            while not src.wait_finished(args.interval):
                print(f"t={src.position:9.3f} s | {format_snapshot(src.stats.snapshot())}", flush=True)
        except KeyboardInterrupt:
            src.pause()
        if src.link_state == LinkState.LOST and isinstance(src.error, GroundStationError):
            raise src.error              # a damaged log: main() prints the one-line reason
        snap = src.stats.snapshot()
        end = "-" if src.position is None else f"{src.position:.3f}"
        print(f"end t={end} s | {format_snapshot(snap)}", flush=True)
        for name, ps in sorted(snap.packets.items()):
            print(f"  {name:<13} {ps.frames:>9} frames, {ps.dropped} dropped in "
                  f"{sum(1 for g in snap.gap_events if g[1] == name)} gap(s)")
    return 0


def add_parsers(sub) -> None:
    s = sub.add_parser("record", help="record a session to HDF5 (from the simulator or a rig)",
                       epilog=RECORD_EPILOG)
    s.add_argument("--device", default="sim",
                   help="sim | tcp://HOST:PORT | serial://PORT?baud=N (default: sim)")
    add_sim_port_option(s)
    s.add_argument("--testbed", default=None, help="testbed file (recorded in the log; for sim: the one to run)")
    s.add_argument("--folder", default="logs", help="folder for the log files (default: logs/)")
    s.add_argument("--name", default="test", help="test name, part of the file name")
    s.add_argument("--notes", default="", help="operator notes stored in the log")
    s.add_argument("--duration", type=float, default=0.0, help="seconds (0: until Ctrl-C)")
    s.add_argument("--rollover-mb", type=float, default=0.0, help="start a new file after this size")
    s.add_argument("--rollover-min", type=float, default=0.0, help="start a new file after this time")
    s.add_argument("--take-over", action="store_true", help="take the session from another host")
    s.add_argument("--no-reconnect", action="store_true",
                   help="stop (exit status 1) when the link is lost, instead of reconnecting")
    s.set_defaults(func=_cmd_record)

    s = sub.add_parser("log", help="inspect, export or re-decode a recorded log")
    lsub = s.add_subparsers(dest="action", required=True)
    a = lsub.add_parser("info", help="packets, channels, duration, drops, parameters, events")
    a.add_argument("file")
    a = lsub.add_parser("check", help="what of a (damaged) log is readable: exit 0 intact, "
                                      "1 damaged but partly readable, 2 unreadable")
    a.add_argument("file")
    a = lsub.add_parser("compress", help="deflate logs recorded uncompressed (a fast campaign "
                                         "stopped before it compressed them), in place")
    a.add_argument("files", nargs="+", metavar="file")
    a = lsub.add_parser("export", help="channels of one packet to CSV or MATLAB .mat")
    a.add_argument("file")
    a.add_argument("--format", choices=["csv", "mat"], default="csv")
    a.add_argument("--packet", default="HIGH_RATE")
    a.add_argument("--channels", default="", help="comma-separated (default: all)")
    a.add_argument("--from", dest="start", type=float, default=None, help="start time, s")
    a.add_argument("--to", dest="stop", type=float, default=None, help="end time, s")
    a.add_argument("--timebase", choices=["device", "host"], default="device")
    a.add_argument("--relative", action="store_true",
                   help="--from/--to count from the start of the log")
    a.add_argument("-o", "--output", default=None, help="output file (default: beside the log)")
    a.add_argument("--salvage", action="store_true",
                   help="from a damaged log, export the rows before the first unreadable one "
                        "(exit 1 when the damage cut the range short)")
    a = lsub.add_parser("redecode", help="decode the recorded frames again with another dictionary")
    a.add_argument("file")
    a.add_argument("output")
    s.set_defaults(func=_cmd_log)

    s = sub.add_parser("replay", help="replay a log in the window (or headless statistics)")
    s.add_argument("file")
    s.add_argument("--headless", action="store_true",
                   help="print link statistics instead of opening the window (default without a display)")
    s.add_argument("--speed", default="max", help="0.1 to 50 (x real time) or max (default)")
    s.add_argument("--from", dest="start", type=float, default=None, help="start at this device time, s")
    s.add_argument("--interval", type=float, default=1.0, help="seconds between status lines")
    s.set_defaults(func=_cmd_replay)
