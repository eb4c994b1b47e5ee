"""`groundstation fg ...`: the base-motion function generator (B&K Precision 4053B) from the
command line.

    groundstation fg list [--backend @py]
    groundstation fg identify --resource R
    groundstation fg set --resource R --channel 1 --waveform SINE --frequency 2 \\
                         --amplitude 0.5 --offset 0 [--phase 0] [--load HZ] [--output on --hold S]
    groundstation fg upload --resource R --profile profiles/base_motion/BM1.csv \\
                         [--duration 60 --seed 0 --rms-mrad 3 --testbed F] [--output on --hold S]
                         [--check [--device ADDRESS] [--tolerance 0.1] [--csv FILE]]
    groundstation fg check LOG --profile profiles/base_motion/BM1.csv \\
                         [--duration 60 --seed 0 --rms-mrad 3] [--end S] [--tolerance 0.1] [--csv FILE]
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

Achieved vs target: `upload --check` watches the base encoder (HIGH_RATE.encoder_base)
during the hold - from the simulated testbed behind `--resource sim`, or from the device
at --device ADDRESS - and compares the last whole waveform period of settled motion with
the profile's target; `check LOG` does the same with a recorded log (the period before
the output went off, when the log's journal says so - the GUI journals it - else the
log's last).  Both print the RMS of target and achieved and their difference, the RMS per
octave band, and exit 0 when the RMS is within --tolerance (default 10 %), 1 when not,
2 when the log, the profile or the instrument cannot be used.
"""

from __future__ import annotations

import argparse
import csv
import math
import signal
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from ..core.contracts import BaseMotionInstrument
from ..core.errors import GroundStationError
from . import arguments

if TYPE_CHECKING:
    import numpy as np

SIM = "sim"
DEFAULT_TOLERANCE = 0.10


def _default_testbed() -> Path:
    from ..plant.testbed import TESTBEDS_DIR

    return TESTBEDS_DIR / "inertial_2dof.toml"


@contextmanager
def _generator(args, testbed, on_sim=None):
    """The opened generator (and the simulated testbed behind `--resource sim`; once the
    generator is open, the testbed's command address goes to `on_sim`)."""
    from ..station.rig import open_testbed_generator, start_simulator

    sim = None
    resource, backend = args.resource, args.backend
    if resource == SIM:
        sim = start_simulator(testbed.path, generator=True)
        resource, backend = sim.fg_resource, "@py"
        print(f"started the simulated testbed on {sim.address}, generator on {resource}", flush=True)
    try:
        fg = open_testbed_generator(resource, testbed, backend=backend, timeout_s=args.timeout)
        try:
            if sim is not None and on_sim is not None:
                on_sim(sim.address)
            yield fg
        finally:
            fg.close()                        # outputs off, whatever happened
    finally:
        if sim is not None:
            sim.stop()


def _testbed(args):
    from ..plant.testbed import load_testbed

    return load_testbed(args.testbed or _default_testbed())


def _hold(fg: BaseMotionInstrument, channel: int, seconds: float | None, marks: list | None = None,
          clock=None) -> None:
    """Output on, for `seconds` (None: until Ctrl-C or SIGTERM), then off.  With `clock`
    (the newest device time seen), `marks` gets the device times of on and off."""
    fg.set_output(channel, True)
    if marks is not None and clock is not None:
        marks.append(clock())
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
        # the stop is dated before the command: the telemetry lags the device, so the
        # output was still on then, and a window ending there holds no free decay
        if marks is not None and clock is not None:
            marks.append(clock())
        fg.set_output(channel, False)
    print(f"output of channel {channel} switched off", flush=True)


def _cmd_list(args) -> int:
    from ..instruments import list_resources

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
        if wave or args.load is not None:
            # one call: the new values are checked against the new load, and the driver
            # sends the load and the wave in the order the instrument (and, with the output
            # on, the stage) accepts
            fg.configure(ch, waveform=args.waveform, frequency_hz=args.frequency,
                         amplitude_vpp=args.amplitude, offset_v=args.offset, phase_deg=args.phase,
                         load=args.load)
        print(fg.describe(ch), flush=True)
        if args.output == "on":
            _hold(fg, ch, args.hold)
    return 0


def _profile(args, testbed, duration_s: float | None = None, seed: int | None = None,
             rms_mrad: float | None = None, precompensate: bool | None = None):
    from ..basemotion import load_profile

    # the command line first, then what the log's journal says was uploaded, then defaults
    rms = args.rms_mrad if args.rms_mrad is not None else rms_mrad
    if args.no_precompensate:
        precompensate = False
    elif precompensate is None:
        precompensate = True
    return load_profile(args.profile, testbed,
                        duration_s=args.duration if args.duration is not None else (duration_s or 60.0),
                        seed=args.seed if args.seed is not None else (seed or 0),
                        target_rms_rad=None if rms is None else rms / 1e3,
                        precompensate=precompensate)


def _report(check, window, tolerance: float, csv_path: str | None) -> int:
    """Print the comparison; write the CSP curves; 0 within tolerance, 1 not."""
    from ..basemotion import band_rms

    lo, hi = check.band_hz
    print(f"window: device time {window.start_s:.3f} .. {window.end_s:.3f} s "
          f"({window.seconds:g} s, {len(window.angle_rad)} samples"
          + (f", {window.missing_frames} missing" if window.missing_frames else ", none missing") + ")")
    print(f"RMS: target {check.target_rms_rad * 1e3:.3f} mrad, achieved "
          f"{check.achieved_rms_rad * 1e3:.3f} mrad, difference "
          f"{(check.achieved_rms_rad - check.target_rms_rad) * 1e3:+.3f} mrad "
          f"({check.rms_error * 100:+.1f} %)")
    dmax, fmax = check.max_cumulative_rms_difference_rad
    print(f"spectrum: {check.in_band_fraction * 100:.1f} % of the achieved power in {lo:g}-{hi:g} Hz; "
          f"largest cumulative-RMS difference {dmax * 1e3:.3f} mrad at {fmax:.3g} Hz")
    print(f"{'per band (RMS, mrad)':<22}{'target':>8}{'achieved':>10}{'difference':>12}")
    for b in band_rms(check):
        diff = f"{b.error * 100:+.1f} %" if math.isfinite(b.error) else "-"
        band = f"{b.low_hz:.3g}-{b.high_hz:.3g} Hz"
        print(f"{band:>20}  {b.target_rms_rad * 1e3:8.3f}{b.achieved_rms_rad * 1e3:10.3f}{diff:>12}")
    if csv_path:
        _write_csp(csv_path, check)
        print(f"CSP curves written to {csv_path}")
    ok = check.within(tolerance)
    print(f"result: {'PASS' if ok else 'FAIL'} - the achieved RMS is "
          f"{'within' if ok else 'NOT within'} {tolerance * 100:g} % of the target", flush=True)
    return 0 if ok else 1


def _write_csp(path: str, check) -> None:
    c = check.csp
    try:
        with open(path, "w", newline="", encoding="utf-8") as fh:
            fh.write(f"# {check.name}: cumulative spectral power of the base angle, target vs "
                     f"achieved (rad^2); sqrt at the last row = RMS\n")
            w = csv.writer(fh)
            w.writerow(["frequency_hz", "target_csp_rad2", "achieved_csp_rad2"])
            for f, t, a in zip(c.frequency_hz, c.target_csp_rad2, c.achieved_csp_rad2):
                w.writerow([f"{f:.6g}", f"{t:.6e}", f"{a:.6e}"])
    except OSError as exc:
        raise GroundStationError(f"cannot write {path}: {exc}") from None


def _cmd_upload(args) -> int:
    from ..instruments.spec4050 import arb_name_for
    from .fg_watch import BaseEncoderWatch, first_frame_before_output

    testbed = _testbed(args)
    profile = _profile(args, testbed)
    print(profile.summary(), flush=True)
    name = arb_name_for(args.name or profile.name)
    settle = profile.stage.settling_time_s()
    if args.check:
        # refused before anything moves: a check needs a settled, whole period
        if args.output != "on":
            raise GroundStationError("--check needs --output on (and a --hold long enough to "
                                     "settle and play one period)")
        need = settle + profile.duration_s
        if args.hold is not None and args.hold < need:
            raise GroundStationError(
                f"--hold {args.hold:g} is too short for --check: the stage settles in {settle:.1f} s "
                f"and one period lasts {profile.duration_s:g} s - hold at least {math.ceil(need + 1):g} s")
        if args.device is None and args.resource != SIM:
            raise GroundStationError("--check reads the base encoder from the device: give "
                                     "--device ADDRESS (or use --resource sim)")
    watch: dict = {}

    def start_watching(address: str) -> None:
        from ..core.dictionary import load_dictionary
        from ..station.rig import open_link

        d = load_dictionary(args.protocol_dir)
        enc = BaseEncoderWatch(d.control_rate_hz, profile.duration_s + settle + 30.0)
        client = open_link(d, address)
        packet_rate = next((p.rate_hz for p in d.packets if p.name == "HIGH_RATE"), None)
        watch.update(client=client, encoder=enc, rate=float(packet_rate or d.control_rate_hz))
        client.subscribe(enc)
        client.connect()
        print(f"watching the base encoder on {address}", flush=True)

    def stop_watching() -> None:
        client = watch.pop("client", None)
        if client is not None:
            client.close()

    try:
        on_sim = start_watching if args.check and args.device is None else None
        marks: list = []
        with _generator(args, testbed, on_sim=on_sim) as fg:
            try:
                if args.check and args.device is not None:
                    start_watching(args.device)
                up = fg.upload_arbitrary(args.channel, profile.volts, name=name,
                                         frequency_hz=profile.frequency_hz)
                print(f"uploaded {name} to channel {up.channel}: {up.points} points, played at "
                      f"{up.frequency_hz:.6g} Hz (one period in {profile.duration_s:g} s), "
                      f"{up.amplitude_vpp:.3f} Vpp", flush=True)
                print(fg.describe(args.channel), flush=True)
                if args.output == "on":
                    enc = watch.get("encoder")
                    if enc is not None:
                        first_frame_before_output(enc)
                    _hold(fg, args.channel, args.hold, marks, enc.newest if enc else None)
            finally:
                stop_watching()               # before the simulator it watches stops
        if not args.check:
            return 0
        from ..basemotion import check_record

        enc = watch["encoder"]
        if len(marks) < 2 or None in marks:
            raise GroundStationError("no base-encoder telemetry arrived during the hold: "
                                     "nothing to check")
        t, x = enc.arrays()
        check, window = check_record(t, x, watch["rate"], profile, end_s=marks[1],
                                     not_before_s=marks[0] + settle)
        print(f"achieved vs target ({profile.name}, settled {settle:.1f} s after output on):")
        return _report(check, window, args.tolerance, args.csv)
    finally:
        stop_watching()


def _journal_motion(reader) -> tuple:
    """From the log's journal of the function generator (written by the GUI): the last
    upload (a GeneratorJournalRecord), the device times where its motion started and
    stopped, and notes on the records left out because they do not follow the schema."""
    from ..instruments.generator_journal import (JOURNAL_KIND, GeneratorJournalError,
                                                 GeneratorJournalRecord)
    from ..logs.opening import LogQueryError

    try:
        entries = reader.journal(JOURNAL_KIND)
    except LogQueryError:
        return None, None, None, []
    upload, start, end, on, notes = None, None, None, {}, []
    for i, entry in enumerate(entries):
        try:
            rec = GeneratorJournalRecord.from_record(entry.data)
        except GeneratorJournalError as exc:
            notes.append(f"journal record {i + 1} of {len(entries)} left out: {exc}")
            continue
        t = rec.device_time
        if t is None:
            t = _host_to_device(reader, entry.time)
        if rec.action == "upload":
            upload, start, end = rec, None, None
            if on.get(rec.channel):               # uploading while on restarts the motion
                start = t
        elif rec.action == "output":
            ch = rec.channel
            was = on.get(ch, False)
            on[ch] = rec.on
            if upload is not None and ch == upload.channel:
                if on[ch] and not was:
                    start, end = t, None
                elif was and not on[ch] and start is not None:
                    end = t
        elif rec.action in ("abort", "close"):
            if upload is not None and on.get(upload.channel) and start is not None:
                end = t
            on = {}
    return upload, start, end, notes


def _host_to_device(reader, host_time: float) -> float | None:
    """The device time of the first HIGH_RATE frame that arrived at or after `host_time`."""
    n = reader.n_frames("HIGH_RATE")
    if not n:
        return None
    i0, _ = reader.index_range("HIGH_RATE", start=host_time, stop=None, timebase="host")
    row = reader.read_rows("HIGH_RATE", [], min(i0, n - 1), min(i0, n - 1) + 1)
    return float(row["device_time"][0])


def _cmd_check(args) -> int:
    import numpy as np

    from ..basemotion import check_record
    from ..logs import LogReader

    testbed = _testbed(args)
    with LogReader(args.log) as reader:
        if "HIGH_RATE" not in reader.packets() or not reader.n_frames("HIGH_RATE"):
            raise GroundStationError(f"{args.log}: no HIGH_RATE telemetry recorded (nothing "
                                     f"to check)")
        upload, start, end, notes = _journal_motion(reader)
        for note in notes:
            print(f"note: {note}")
        if upload is not None:
            profile = _profile(args, testbed, upload.duration_s, upload.seed,
                               upload.target_rms_rad * 1e3, upload.precompensated)
            journaled = Path(upload.psd_source).name
            if journaled and journaled != Path(args.profile).name:
                print(f"note: the log's journal says {journaled} was uploaded, not "
                      f"{Path(args.profile).name}")
        else:
            profile = _profile(args, testbed)
        print(profile.summary())
        settle = profile.stage.settling_time_s()
        n = reader.n_frames("HIGH_RATE")
        last = float(reader.read_rows("HIGH_RATE", [], n - 1, n)["device_time"][0])
        if args.end is not None:
            end_s, why = reader.origin("device") + args.end, f"--end {args.end:g} s"
        elif end is not None:
            end_s, why = end, "where the output went off (journal)"
        else:
            end_s, why = None, "at the end of the log"
        not_before = start + settle if start is not None else None
        # only the rows of the window (and a second before it) are read, however long the log
        stop = end_s if end_s is not None else last + 1e-3
        data = reader.read("HIGH_RATE", ["encoder_base"],
                           start=stop - args.periods * profile.duration_s - 1.0, stop=stop)
        steps = np.diff(data["device_time"])
        if not len(steps):
            raise GroundStationError(f"{args.log}: no base-encoder samples before "
                                     f"{stop - reader.origin('device'):.2f} s")
        rate = 1.0 / float(np.median(steps))          # the packet's own rate, as recorded
        print(f"log: {args.log}; window ends {why}"
              + (f"; the motion started at device time {start:.2f} s, settled {settle:.1f} s later"
                 if start is not None else ""))
        check, window = check_record(data["device_time"], data["encoder_base"], rate, profile,
                                     end_s=end_s, not_before_s=not_before, periods=args.periods)
    return _report(check, window, args.tolerance, args.csv)


def _cmd_off(args) -> int:
    with _generator(args, _testbed(args)) as fg:
        fg.abort()
        for ch in (1, 2):
            print(fg.describe(ch))
    return 0








#: a VISA timeout shorter than a millisecond cannot be kept by any instrument
_AT_LEAST_A_MILLI = arguments.number(lambda v: 0.001 <= v < math.inf,
                                     "must be at least 0.001")
_FRACTION_BELOW_ONE = arguments.number(lambda v: 0 <= v < 1, "a fraction below 1 (0.1 = 10 %)")


def _common_arguments(p, resource: bool = True) -> None:
    """--backend, and with `resource` the generator's --resource, --testbed, --timeout."""
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
        p.add_argument("--timeout", type=_AT_LEAST_A_MILLI, default=5.0, help="VISA timeout, s")


def _channel_argument(p) -> None:
    p.add_argument("--channel", type=int, choices=(1, 2), default=1)


def _output_arguments(p) -> None:
    p.add_argument("--output", choices=("on", "off"), default="off",
                   help="on: switch the output on after setting (for --hold s), then off")
    p.add_argument("--hold", type=arguments.non_negative, default=None,
                   help="with --output on: seconds to keep the output on (default: until "
                        "Ctrl-C)")


def _profile_arguments(p, journal_defaults: bool = False) -> None:
    """The base-motion profile's PSD and synthesis; with `journal_defaults` the period
    and the seed default to what a log's journal says was uploaded."""
    later = " (default: what the log's journal says was uploaded, else {})"
    p.add_argument("--profile", required=True, help="PSD table (profiles/base_motion/BM1.csv)")
    p.add_argument("--duration", type=float, default=None if journal_defaults else 60.0,
                   help="one waveform period, s" + (later.format(60) if journal_defaults else ""))
    p.add_argument("--seed", type=int, default=None if journal_defaults else 0,
                   help="random phases (same seed, same profile)"
                        + (later.format(0) if journal_defaults else ""))
    p.add_argument("--rms-mrad", type=float, default=None,
                   help="target base RMS (default: the PSD table's own)")
    p.add_argument("--no-precompensate", action="store_true",
                   help="divide by the stage's DC gain only (no resonance compensation)")


def _verdict_arguments(p) -> None:
    p.add_argument("--tolerance", type=_FRACTION_BELOW_ONE, default=DEFAULT_TOLERANCE,
                   help="largest |achieved/target - 1| of the RMS that passes (default 0.1)")
    p.add_argument("--csv", default=None, metavar="FILE",
                   help="write the CSP curves (frequency_hz, target_csp_rad2, "
                        "achieved_csp_rad2) to FILE")


def _add_instrument_commands(fsub) -> None:
    """list, identify and set: the instrument and its basic waves."""
    s = fsub.add_parser("list", help="list the VISA resources a backend sees")
    _common_arguments(s, resource=False)
    s.add_argument("--query", default="?*::INSTR", help="VISA resource pattern")
    s.set_defaults(func=_cmd_list)

    s = fsub.add_parser("identify", help="*IDN? and both channels' settings")
    _common_arguments(s)
    s.set_defaults(func=_cmd_identify)

    s = fsub.add_parser("set", help="set a channel's basic wave (checked against the limits)")
    _common_arguments(s)
    _channel_argument(s)
    s.add_argument("--waveform", type=str.upper, choices=("SINE", "SQUARE", "RAMP", "DC", "ARB"))
    s.add_argument("--frequency", type=float, help="Hz")
    s.add_argument("--amplitude", type=float, help="Vpp into the set load")
    s.add_argument("--offset", type=float, help="V")
    s.add_argument("--phase", type=float, help="deg")
    s.add_argument("--load", choices=("HZ", "50"), type=str.upper,
                   help="load the amplitude refers to (the stage amplifier: HZ)")
    _output_arguments(s)
    s.set_defaults(func=_cmd_set)


def _add_profile_commands(fsub) -> None:
    """upload and check: a base-motion profile played, and its achieved motion judged."""
    s = fsub.add_parser("upload", help="synthesise a base-motion profile from a PSD and upload it")
    _common_arguments(s)
    _channel_argument(s)
    _profile_arguments(s)
    s.add_argument("--name", default=None, help="waveform name on the instrument")
    _output_arguments(s)
    s.add_argument("--check", action="store_true",
                   help="with --output on: watch the base encoder during the hold and compare "
                        "its last settled period with the target")
    s.add_argument("--device", default=None, metavar="ADDRESS",
                   help="with --check: the device whose telemetry carries the base encoder "
                        "(default with --resource sim: the simulated testbed)")
    _verdict_arguments(s)
    s.set_defaults(func=_cmd_upload)

    s = fsub.add_parser("check", help="a recorded log's base motion against a profile's target",
                        description="Compare HIGH_RATE.encoder_base of a recorded log with a "
                                    "base-motion profile: RMS and spectrum of the last whole "
                                    "period(s) before the output went off (from the log's "
                                    "journal) or before --end / the end of the log.  Exit 0 "
                                    "within --tolerance, 1 not, 2 unreadable log or profile.")
    s.add_argument("log", help="a ground-station log (.h5)")
    _profile_arguments(s, journal_defaults=True)
    s.add_argument("--testbed", default=None,
                   help="testbed whose base-stage model made the profile (default: "
                        "profiles/testbeds/inertial_2dof.toml)")
    s.add_argument("--end", type=arguments.non_negative, default=None, metavar="S",
                   help="the window ends S seconds after the start of the log")
    s.add_argument("--periods", type=int, default=1, help="whole waveform periods to compare")
    _verdict_arguments(s)
    s.set_defaults(func=_cmd_check)


def add_parsers(sub) -> None:
    """The `fg` command and its subcommands, on the main parser's subparsers `sub`."""
    fg = sub.add_parser("fg", help="the base-motion function generator (B&K 4053B, VISA)",
                        description=__doc__,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    fsub = fg.add_subparsers(dest="fg_command", required=True)
    _add_instrument_commands(fsub)
    _add_profile_commands(fsub)
    s = fsub.add_parser("off", help="switch both outputs off")
    _common_arguments(s)
    s.set_defaults(func=_cmd_off)
