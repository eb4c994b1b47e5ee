"""`groundstation fg ...`: the base-motion function generator (B&K Precision 4053B) from the
command line.

    groundstation fg list [--backend @py]
    groundstation fg identify --resource R
    groundstation fg set --resource R --channel 1 --waveform SINE --frequency 2 \\
                         --amplitude 0.5 --offset 0 [--phase 0] [--load HZ] [--output on --hold S]
    groundstation fg upload --resource R --profile profiles/base_motion/BM1.csv \\
                         [--duration 60 --seed 0 --rms-mrad 3 --testbed F] [--output on --hold S]
    groundstation fg off --resource R

R is a VISA resource (USB0::...::INSTR, TCPIP0::HOST::PORT::SOCKET, ...) opened with
--backend (@py by default, @ivi for a vendor VISA, FILE.yaml for pyvisa-sim), or `sim`:
start the simulated testbed with its generator for the duration of the command (its
stage then moves; to drive a simulator that keeps running, start `groundstation sim
--fg-port 0` and give the TCPIP0::...::SOCKET resource it prints).

Every setting is checked against the generator's limits and the testbed's [limits]
(--testbed, default the inertial testbed) before it is sent.  Every command ends with
both outputs off: `--output on` keeps the output on for --hold seconds (default: until
Ctrl-C) and then switches it off - nothing is left driving the stage unattended.
"""

from __future__ import annotations

import argparse
import re
import signal
import threading
from contextlib import contextmanager
from pathlib import Path

from .errors import GroundStationError

SIM = "sim"


def _default_testbed() -> Path:
    from .sim.testbed import TESTBEDS_DIR

    return TESTBEDS_DIR / "inertial_2dof.toml"


@contextmanager
def _generator(args, testbed):
    """The opened generator (and the simulated testbed behind `--resource sim`)."""
    from .instruments import SafetyLimits, open_generator
    from .sim.process import SimulatorProcess

    sim = None
    resource, backend = args.resource, args.backend
    if resource == SIM:
        sim = SimulatorProcess(pacing="realtime", testbed=str(testbed.path), fg_port=0)
        address = sim.start()
        resource, backend = sim.fg_resource, "@py"
        if not resource:
            sim.stop()
            raise GroundStationError("the simulated testbed did not announce its function generator")
        print(f"started the simulated testbed on {address}, generator on {resource}", flush=True)
    try:
        fg = open_generator(resource, backend=backend, limits=SafetyLimits.from_testbed(testbed),
                            timeout_s=args.timeout)
        try:
            yield fg
        finally:
            fg.close()                        # outputs off, whatever happened
    finally:
        if sim is not None:
            sim.stop()


def _testbed(args):
    from .sim.testbed import load_testbed

    return load_testbed(args.testbed or _default_testbed())


def _hold(fg, channel: int, seconds: float | None) -> None:
    """Output on, for `seconds` (None: until Ctrl-C or SIGTERM), then off."""
    fg.set_output(channel, True)
    print(f"{fg.describe(channel)}", flush=True)
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        if seconds is None:
            print("output ON - Ctrl-C to switch it off", flush=True)
            while not stop.wait(0.5):
                pass
        elif seconds > 0:
            stop.wait(seconds)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        fg.set_output(channel, False)
    print(f"output of channel {channel} switched off", flush=True)


def _cmd_list(args) -> int:
    from .instruments import list_resources

    listing = list_resources(args.backend, args.query)
    if listing.resources:
        for r in listing.resources:
            print(r)
    else:
        print(f"no VISA resources matching {args.query} on {listing.backend}")
    for note in listing.notes:
        print(f"note: {note}")
    return 0


def _cmd_identify(args) -> int:
    with _generator(args, _testbed(args)) as fg:
        print(f"{fg.resource_name}: {fg.identity}")
        for ch in (1, 2):
            print(fg.describe(ch))
    return 0


def _cmd_set(args) -> int:
    testbed = _testbed(args)
    with _generator(args, testbed) as fg:
        ch = args.channel
        wave = any(v is not None for v in (args.waveform, args.frequency, args.amplitude,
                                           args.offset, args.phase))
        # every step is checked; order them so that the step in between is the smaller
        # drive: to high impedance (half the real volts of a 50 ohm setting) first, to 50 last
        if args.load == "HZ":
            fg.set_load(ch, args.load)
        if wave:
            fg.configure(ch, waveform=args.waveform, frequency_hz=args.frequency,
                         amplitude_vpp=args.amplitude, offset_v=args.offset, phase_deg=args.phase)
        if args.load == "50":
            fg.set_load(ch, args.load)
        print(fg.describe(ch), flush=True)
        if args.output == "on":
            _hold(fg, ch, args.hold)
    return 0


def _arb_name(text: str) -> str:
    name = re.sub(r"[^A-Za-z0-9_]", "_", text)
    if not name or not name[0].isalpha():
        name = "BM_" + name
    return name[:16]


def _cmd_upload(args) -> int:
    from .basemotion import load_profile

    testbed = _testbed(args)
    profile = load_profile(args.profile, testbed, duration_s=args.duration, seed=args.seed,
                           target_rms_rad=None if args.rms_mrad is None else args.rms_mrad / 1e3,
                           precompensate=not args.no_precompensate)
    print(profile.summary(), flush=True)
    name = _arb_name(args.name or profile.name)
    with _generator(args, testbed) as fg:
        up = fg.upload_arbitrary(args.channel, profile.volts, name=name,
                                 frequency_hz=profile.frequency_hz)
        print(f"uploaded {name} to channel {up.channel}: {up.points} points, played at "
              f"{up.frequency_hz:.6g} Hz (one period in {profile.duration_s:g} s), "
              f"{up.amplitude_vpp:.3f} Vpp", flush=True)
        print(fg.describe(args.channel), flush=True)
        if args.output == "on":
            _hold(fg, args.channel, args.hold)
    return 0


def _cmd_off(args) -> int:
    with _generator(args, _testbed(args)) as fg:
        fg.abort()
        for ch in (1, 2):
            print(fg.describe(ch))
    return 0


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be >= 0, not {text}")
    return value


def add_parsers(sub) -> None:
    fg = sub.add_parser("fg", help="the base-motion function generator (B&K 4053B, VISA)",
                        description=__doc__,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    fsub = fg.add_subparsers(dest="fg_command", required=True)

    def common(p, resource: bool = True):
        if resource:
            p.add_argument("--resource", required=True,
                           help="VISA resource, or 'sim' to start the simulated testbed with "
                                "its generator for this command")
        p.add_argument("--backend", default=None,
                       help="pyvisa backend: @py (default), @ivi (vendor VISA) or a pyvisa-sim "
                            "FILE.yaml")
        if resource:
            p.add_argument("--testbed", default=None,
                           help="testbed file whose [limits] apply (default: "
                                "profiles/testbeds/inertial_2dof.toml)")
            p.add_argument("--timeout", type=float, default=5.0, help="VISA timeout, s")

    def channel(p):
        p.add_argument("--channel", type=int, choices=(1, 2), default=1)

    def output(p):
        p.add_argument("--output", choices=("on", "off"), default="off",
                       help="on: switch the output on after setting (for --hold s), then off")
        p.add_argument("--hold", type=_non_negative, default=None,
                       help="with --output on: seconds to keep the output on (default: until "
                            "Ctrl-C)")

    s = fsub.add_parser("list", help="list the VISA resources a backend sees")
    common(s, resource=False)
    s.add_argument("--query", default="?*::INSTR", help="VISA resource pattern")
    s.set_defaults(func=_cmd_list)

    s = fsub.add_parser("identify", help="*IDN? and both channels' settings")
    common(s)
    s.set_defaults(func=_cmd_identify)

    s = fsub.add_parser("set", help="set a channel's basic wave (checked against the limits)")
    common(s)
    channel(s)
    s.add_argument("--waveform", type=str.upper, choices=("SINE", "SQUARE", "RAMP", "DC", "ARB"))
    s.add_argument("--frequency", type=float, help="Hz")
    s.add_argument("--amplitude", type=float, help="Vpp into the set load")
    s.add_argument("--offset", type=float, help="V")
    s.add_argument("--phase", type=float, help="deg")
    s.add_argument("--load", choices=("HZ", "50"), type=str.upper,
                   help="load the amplitude refers to (the stage amplifier: HZ)")
    output(s)
    s.set_defaults(func=_cmd_set)

    s = fsub.add_parser("upload", help="synthesise a base-motion profile from a PSD and upload it")
    common(s)
    channel(s)
    s.add_argument("--profile", required=True, help="PSD table (profiles/base_motion/BM1.csv)")
    s.add_argument("--duration", type=float, default=60.0, help="one waveform period, s")
    s.add_argument("--seed", type=int, default=0, help="random phases (same seed, same profile)")
    s.add_argument("--rms-mrad", type=float, default=None,
                   help="target base RMS (default: the PSD table's own)")
    s.add_argument("--no-precompensate", action="store_true",
                   help="divide by the stage's DC gain only (no resonance compensation)")
    s.add_argument("--name", default=None, help="waveform name on the instrument")
    output(s)
    s.set_defaults(func=_cmd_upload)

    s = fsub.add_parser("off", help="switch both outputs off")
    common(s)
    s.set_defaults(func=_cmd_off)
