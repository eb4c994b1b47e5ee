"""`groundstation ...` - the command-line entry point.

    groundstation run                      the main job (live view of the simulated testbed)
    groundstation sim [--tcp-port 5020]    run the simulated testbed
    groundstation monitor --device ADDR    connect and print live link statistics
    groundstation protocol info|check      the protocol dictionary
    groundstation protocol export-c DIR    the firmware kit: C header and reference codec
    groundstation protocol export-wireshark FILE.lua   ... and a Wireshark/tshark dissector
    groundstation record --folder logs     record a session to HDF5 (see cli/logs.py)
    groundstation params validate|upload|show|rollback   controller designs (see cli/params.py)
    groundstation profile show|play FILE   command profiles (see cli/profile.py)
    groundstation campaign show|run FILE   scripted test campaigns, scored and compared (cli/campaign.py)
    groundstation campaign report REPORT.json   the metrics, charts and HTML again from the logs
    groundstation fg list|identify|set|upload|off   the base-motion generator (cli/fg.py)
    groundstation analyze LOG...           jitter, control energy, PSD of logs (cli/analysis.py)
    groundstation gui|monitor|record --watch tcp://HOST:PORT   a read-only console (fanout/)
    groundstation gui|monitor --publish tcp://127.0.0.1:PORT   ... fed by the commanding station
    groundstation fanout keys DIR [--name NAME]   CURVE keys for consoles beyond loopback
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import time

from ..core.contracts import DeviceLink
from . import analysis as cli_analysis
from . import conformance as cli_conformance
from . import campaign as cli_campaign
from . import fg as cli_fg
from . import identify as cli_identify
from . import logs as cli_logs
from . import params as cli_params
from . import profile as cli_profile
from .. import __version__
from ..core.errors import GroundStationError
from . import arguments
from .station import add_sim_port_option


def load_dictionary(protocol_dir=None):
    """The protocol dictionary, imported when a command needs it (numpy comes with it:
    `groundstation --help` must not wait for that)."""
    from ..core.dictionary import load_dictionary as load

    return load(protocol_dir)

log = logging.getLogger("groundstation")


def _cmd_protocol(args) -> int:
    d = load_dictionary(args.protocol_dir)
    if args.action.startswith("export-"):
        return _export_kit(args, d)
    if args.action == "check":
        print(f"protocol {d.name} {d.version}: {len(d.packets)} packets, {len(d.commands)} "
              f"commands, {len(d.parameters)} parameters - OK (hash {d.hash:08x})")
        return 0
    print(f"protocol {d.name} version {d.version}  dictionary hash {d.hash:08x}")
    for p in d.packets:
        size = f"{p.fixed_payload_size}+ bytes" if p.variable_item else f"{p.fixed_payload_size} bytes"
        rate = f" @ {p.rate_hz:g} Hz" if p.rate_hz else ""
        print(f"  packet 0x{p.id:02X} {p.name:<13} {size:>10}{rate}  {len(p.items)} items")
    for c in d.commands:
        flag = " critical" if c.critical else ""
        print(f"  command 0x{c.opcode:04X} {c.name:<15}{flag}")
    return 0


def _export_kit(args, d) -> int:
    """The firmware kit from the dictionary (docs/firmware.md): C header and reference
    codec into a directory, or a Wireshark Lua dissector into a file."""
    if not args.target:
        what = "a directory" if args.action == "export-c" else "a .lua file"
        print(f"error: protocol {args.action} needs {what} to write to", file=sys.stderr)
        return 2
    from ..firmware_kit import export_c, export_wireshark

    if args.action == "export-c":
        paths = export_c(d, args.target)
    else:
        paths = [export_wireshark(d, args.target, port=args.port)]
    for path in paths:
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    print(f"protocol {d.name} {d.version}, dictionary hash {d.hash:08x}")
    return 0


def _cmd_sim(args) -> int:
    from ..sim import SimulatedDevice
    from ..plant.testbed import load_testbed

    # Started by a ground station (--announce): end with it, even if it was killed.  Its
    # pid is taken now, while it is certainly alive (it waits for our LISTENING line):
    # taken after that line, a parent that exits at once was already gone, the child
    # took init for its parent and ran on forever (seen on a busy machine, 1 start in 6).
    parent = os.getppid() if args.announce else None
    stop = threading.Event()
    # Ctrl-C and SIGTERM both ask for a clean stop, whenever they come (even during start)
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    testbed = load_testbed(args.testbed)        # refuses a bad file before anything starts
    dev = SimulatedDevice(load_dictionary(args.protocol_dir), host=args.host,
                          tcp_port=args.tcp_port, pacing=args.pacing, seed=args.seed,
                          frames_per_datagram=args.frames_per_datagram, testbed=testbed,
                          speed=args.speed, deviations=_deviations(args))
    dev.start()
    fg = None
    if args.fg_port is not None:          # the base-stage function generator (SCPI on TCP)
        from ..sim.process import FG_ANNOUNCE
        from ..sim.scpi_server import attach_generator

        try:
            fg = attach_generator(dev, host=args.host, port=args.fg_port)
        except BaseException:
            dev.stop()
            raise
        if args.announce:                 # before LISTENING, which ends the parent's wait
            print(f"{FG_ANNOUNCE}{fg.resource}", flush=True)
    if not args.announce:
        print(f"testbed: {testbed.name} ({testbed.path}), friction model "
              f"{testbed.friction['model']}, seed {args.seed}", flush=True)
    if args.announce:
        print(f"LISTENING tcp://{dev.host}:{dev.tcp_port}", flush=True)
    else:
        print(f"simulated testbed on tcp://{dev.host}:{dev.tcp_port} (Ctrl-C to stop)", flush=True)
        if fg is not None:
            print(f"function generator on {fg.resource} (VISA resource for pyvisa-py)", flush=True)
    if args.pty:
        from ..sim.pty import PtyMasterStream

        pty = PtyMasterStream()
        dev.attach_stream(pty)
        print(f"serial link on serial://{pty.slave_name}", flush=True)
    try:
        while not stop.wait(0.5):
            if parent is not None and os.getppid() != parent:
                break
    finally:
        if fg is not None:
            fg.stop()
        dev.stop()
    return 0


def _deviations(args):
    from ..sim.deviations import Deviations

    return Deviations(args.deviate or ())


def _cmd_monitor(args) -> int:
    """Exit status as for `record`: 0 ended as asked, 1 link lost with --no-reconnect,
    2 could not connect, 3 the session was taken over by another station."""
    from ..link import format_snapshot
    from ..station.keeper import LinkKeeper
    from ..core.stop_request import StopRequest

    d = load_dictionary(args.protocol_dir)
    if getattr(args, "watch", None):
        from ..fanout.commands import watch_monitor
        return watch_monitor(args, d)
    from ..fanout.commands import start_publisher

    publisher = start_publisher(args)

    def publish(client: DeviceLink):
        publisher.attach(client, keeper.address)
        return publisher.detach

    with StopRequest() as stop:
        keeper = LinkKeeper(d, args.device, args.testbed, take_over=args.take_over,
                            on_client=publish if publisher is not None else None,
                            say=lambda text: print(text, flush=True), sim_listen=args.sim_port)
        try:
            client = keeper.open()
            info = client.command("GET_INFO").reply
            print(f"connected to {keeper.address}: {info['description']} - firmware "
                  f"{info['firmware_version'] >> 16}.{(info['firmware_version'] >> 8) & 255}."
                  f"{info['firmware_version'] & 255}, protocol {d.version}", flush=True)
            t_end = time.monotonic() + args.duration if args.duration else None
            reported: set[int] = set()
            while not stop.event.wait(args.interval):
                ending = keeper.keep_up(stop.event, reconnect=not args.no_reconnect,
                                        on_event=lambda *_: reported.clear())
                if ending is not None:
                    if ending.status != 0:
                        return ending.status
                    break
                client = keeper.client
                print(format_snapshot(client.stats.snapshot()), flush=True)
                for err in client.stats.recent_errors():
                    if id(err) not in reported:
                        reported.add(id(err))
                        print(f"  {type(err).__name__}: {err}", flush=True)
                if t_end is not None and time.monotonic() >= t_end:
                    break
            if stop.reason:
                print(f"stopped: {stop.reason}", flush=True)
            return 0
        finally:
            keeper.close()
            if publisher is not None:
                publisher.close()


def _cmd_run(args) -> int:
    """The main job: the window on the simulated testbed, or a headless view without a screen."""
    from ..gui.app import display_available, run_gui

    if display_available():
        return run_gui(load_dictionary(args.protocol_dir), connect="sim", testbed=args.testbed)
    print("no display (DISPLAY/WAYLAND_DISPLAY unset): falling back to the headless live "
          "view of the simulated testbed (Ctrl-C to stop)", flush=True)
    args.device = "sim"
    return _cmd_monitor(args)


def _cmd_gui(args) -> int:
    from ..gui.app import run_gui

    connect = None if args.device == "none" else args.device
    return run_gui(load_dictionary(args.protocol_dir), connect=connect, testbed=args.testbed,
                   replay=args.replay, watch=args.watch, publish=args.publish,
                   curve_keys=args.curve_keys, key_name=args.key_name)


def _cmd_watch_record(args) -> int:
    from ..fanout.commands import watch_record

    return watch_record(args, load_dictionary(args.protocol_dir))


def _cmd_fanout(args) -> int:
    from ..fanout.commands import make_keys

    return make_keys(args)


def _add_console_options(s, *, watch: bool = True, publish: bool = True) -> None:
    """Many consoles on one rig (docs/consoles.md): watch a publishing station, or publish."""
    if watch:
        s.add_argument("--watch", default=None, metavar="tcp://HOST:PORT",
                       help="a read-only console on the station publishing there (--device "
                            "is then not used): same views, no commands but Abort")
        s.add_argument("--wait", type=float, default=10.0, help=argparse.SUPPRESS)
    if publish:
        s.add_argument("--publish", default=None, metavar="tcp://127.0.0.1:PORT",
                       help="publish what this station receives for read-only consoles "
                            "(loopback; a wider address needs --curve-keys)")
    s.add_argument("--curve-keys", default=None, metavar="DIR",
                   help="the lab's CURVE keys (groundstation fanout keys DIR)")
    s.add_argument("--key-name", default="viewer",
                   help="--watch with --curve-keys: this console's key pair (default viewer)")




def _add_deviate_option(s) -> None:
    """`sim --deviate NAME`: test only (sim/deviations.py); the names are repeated here so
    that parsing the command line imports nothing."""
    s.add_argument("--deviate", action="append", default=None, metavar="NAME",
                   choices=["crc-range", "retry-twice", "watchdog-x2", "commit-no-crc",
                            "profile-late", "foreign-host", "shared-history"],
                   help="test only: break one rule of the SPEC on purpose, to show that "
                        "`groundstation conformance` catches it")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="groundstation",
                                description="Ground station for hybrid-flexure-bearing testbeds")
    p.add_argument("--version", action="version", version=f"groundstation {__version__}")
    p.add_argument("--protocol-dir", default=None,
                   help="directory with telemetry/commands/parameters.toml (default: protocol/)")
    p.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("protocol", help="show or check the protocol dictionary; export the "
                                        "firmware kit (C header and codec, Wireshark dissector)")
    s.add_argument("action", choices=["info", "check", "export-c", "export-wireshark"])
    s.add_argument("target", nargs="?", default=None,
                   help="export-c: directory for hfb_protocol.h/.c; export-wireshark: the .lua file")
    s.add_argument("--port", type=int, default=5020,
                   help="export-wireshark: the device's TCP command port, also the UDP port its "
                        "telemetry comes from (default 5020, the simulator's; a Wireshark "
                        "preference changes it)")
    s.set_defaults(func=_cmd_protocol)

    s = sub.add_parser("sim", help="run the simulated testbed")
    s.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    s.add_argument("--tcp-port", type=int, default=5020, help="command port (0: any free port)")
    s.add_argument("--testbed", default=None,
                   help="testbed file (default: profiles/testbeds/relative_2dof.toml)")
    s.add_argument("--pacing", choices=["realtime", "fast"], default="realtime")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--speed", type=arguments.positive, default=1.0,
                   help="realtime pacing: control periods per 1/1200 s of wall time "
                        "(10: a 10x burst of 12 000 frames/s; default 1)")
    s.add_argument("--frames-per-datagram", type=int, default=1)
    s.add_argument("--fg-port", type=int, default=None,
                   help="also serve the simulated function generator (SCPI on TCP) on this "
                        "port, 0: any free port (default: no generator)")
    s.add_argument("--pty", action="store_true",
                   help="also serve a serial link on a pseudo-terminal (prints its name)")
    s.add_argument("--announce", action="store_true", help=argparse.SUPPRESS)
    _add_deviate_option(s)
    s.set_defaults(func=_cmd_sim)

    for name, helptext in (("monitor", "connect to a device and print live link statistics"),
                           ("run", "the main job: live view of the simulated testbed")):
        s = sub.add_parser(name, help=helptext)
        if name == "monitor":
            s.add_argument("--device", default="sim",
                           help="sim | tcp://HOST:PORT | HOST:PORT | serial://PORT?baud=N")
            add_sim_port_option(s)
        s.add_argument("--testbed", default=None, help="testbed file for --device sim")
        s.add_argument("--duration", type=float, default=0.0, help="seconds (0: until Ctrl-C)")
        s.add_argument("--interval", type=float, default=1.0, help="seconds between lines")
        s.add_argument("--take-over", action="store_true",
                       help="take the session over from another host")
        s.add_argument("--no-reconnect", action="store_true",
                       help="stop (exit status 1) when the link is lost, instead of reconnecting")
        if name == "monitor":
            _add_console_options(s)
        s.set_defaults(func=_cmd_monitor if name == "monitor" else _cmd_run)
    s = sub.add_parser("gui", help="the operator's window")
    s.add_argument("--device", default="sim", help="sim | tcp://HOST:PORT | serial://PORT | none")
    s.add_argument("--testbed", default=None, help="testbed file for --device sim")
    s.add_argument("--replay", default=None, help="open this log in replay instead")
    _add_console_options(s)
    s.set_defaults(func=_cmd_gui)
    cli_logs.add_parsers(sub)
    record = sub.choices["record"]            # `record --watch`: the viewer's recording
    _add_console_options(record, publish=False)
    own_record = record.get_default("func")
    record.set_defaults(func=lambda a: _cmd_watch_record(a) if a.watch else own_record(a))
    s = sub.add_parser("fanout", help="CURVE keys for read-only consoles beyond loopback")
    fsub = s.add_subparsers(dest="action", required=True)
    k = fsub.add_parser("keys", help="make the publisher's key pair (once) and a viewer's, "
                                     "authorised (docs/consoles.md)")
    k.add_argument("folder")
    k.add_argument("--name", default="viewer", help="the viewer's key pair (default viewer)")
    s.set_defaults(func=_cmd_fanout)
    for module in (cli_params, cli_profile, cli_campaign, cli_fg, cli_analysis, cli_identify,
                   cli_conformance):
        module.add_parsers(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except GroundStationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:            # output piped into `head` and the like
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:          # a command without its own Ctrl-C handling: its
        # `finally` blocks have run (links closed: the device disarms, generator off)
        print("interrupted by the operator (Ctrl-C)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
