"""`groundstation profile ...`: command profiles (profiles/waveforms/*.toml).

    groundstation profile show FILE [--csv OUT]
                                 what the file makes: target, duration, samples, range, RMS,
                                 rates, spectrum peak, checks against the target's range
    groundstation profile play FILE [--device sim|ADDRESS] [--testbed F] [--mode MODE]
                                 upload (CRC-checked, confirmed), set the mode, arm, start,
                                 follow the progress, disarm at the end; on Ctrl-C or any
                                 error: PROFILE_STOP and ABORT

Exit codes: 0 done (shown / played to the end), 1 refused or failed (nothing sent, or the
device was made safe), 2 the file cannot be read or is malformed.
"""

from __future__ import annotations

import argparse
import sys

from ..core.kinds import ProfileOrigin
from . import arguments
from .station import add_device_options, fail, print_progress, status_for
from ..core.errors import GroundStationError

EXIT_OK, EXIT_REFUSED, EXIT_UNREADABLE = 0, 1, 2
MODES = ("OPEN_LOOP", "RELATIVE", "INERTIAL")


def add_parsers(sub) -> argparse._SubParsersAction:
    """Add `profile` to the CLI's subcommands; returns its own subparsers for more actions."""
    return arguments.command_group(sub, "profile",
                                   "command profiles: show one, play one on the device",
                                   _add_show, _add_play)


def _add_show(actions) -> None:
    s = actions.add_parser("show", help="summarise a profile file and check it (no device needed)",
                           description="Build the profile, print its summary and the checks the "
                                       "device would make. Exit 0: may be played; 1: refused; "
                                       "2: unreadable or malformed file.")
    s.add_argument("file", help="profile file, e.g. profiles/waveforms/sine_reference_1hz.toml")
    s.add_argument("--csv", default=None, metavar="OUT", help="also write the samples to this CSV file")
    s.add_argument("--testbed", default=None,
                   help="testbed file whose gyro range bounds a RATE_REFERENCE profile")
    s.set_defaults(func=_cmd_show)


def _add_play(actions) -> None:
    s = actions.add_parser("play", help="upload a profile and play it on the device",
                           description="Upload (blocks, CRC, HOUSEKEEPING confirmation), set the "
                                       "mode, arm, start, follow HIGH_RATE.profile_index to the "
                                       "end, disarm. A relative REFERENCE profile is uploaded "
                                       "after arming, offset by the held position. Ctrl-C or any "
                                       "error: PROFILE_STOP and ABORT. Exit 0: played to the end; "
                                       "1: refused, failed or interrupted (device left safe); "
                                       "2: unreadable file.")
    s.add_argument("file", help="profile file")
    add_device_options(s)
    s.add_argument("--mode", choices=MODES, default=None,
                   help="mode to play in (default: OPEN_LOOP for currents, RELATIVE for a "
                        "reference, INERTIAL for a rate reference)")
    s.add_argument("--timeout", type=float, default=None,
                   help="seconds to wait for the end after the start (default: duration + 10)")
    s.set_defaults(func=_cmd_play)


def _gyro_range(args) -> float:
    from ..profiles.samples import DEFAULT_GYRO_RANGE
    if not args.testbed:
        return DEFAULT_GYRO_RANGE
    from ..plant.testbed import load_testbed
    return float(load_testbed(args.testbed).sensors["gyro_range"])


def _load(args):
    """(profile, check) or an exit code for an unreadable file."""
    from ..core.dictionary import load_dictionary
    from ..profiles.profile import load_profile
    from ..profiles.samples import ProfileFileError
    from ..profiles.checks import check_profile

    try:
        dictionary = load_dictionary(args.protocol_dir)
        gyro = _gyro_range(args)
        profile = load_profile(args.file, dictionary, validate=False)
    except ProfileFileError as exc:
        return fail(str(exc), EXIT_UNREADABLE)
    except GroundStationError as exc:
        return fail(str(exc), EXIT_UNREADABLE)
    return dictionary, profile, check_profile(profile, dictionary, gyro_range=gyro), gyro


def _cmd_show(args) -> int:
    from ..profiles.checks import sample_range
    from ..profiles.summary import summarise, write_csv

    loaded = _load(args)
    if isinstance(loaded, int):
        return loaded
    dictionary, profile, check, gyro = loaded
    for line in summarise(profile).lines():
        print(line)
    lo, hi = sample_range(dictionary, profile.target, gyro)
    print(f"allowed:  {lo:g} … {hi:g} {profile.units} ({profile.target})")
    if profile.description:
        print(f"about:    {profile.description}")
    if args.csv:
        try:
            write_csv(profile, args.csv)
        except OSError as exc:
            return fail(f"{args.csv}: cannot write ({exc.strerror})")
        print(f"samples written to {args.csv}")
    for w in check.warnings:
        print(f"warning:  {w}")
    if not check.ok:
        print(f"REFUSED: {len(check.problems)} problem(s)")
        for p in check.problems:
            print(f"problem:  {p}")
        return EXIT_REFUSED
    print("OK: the profile may be played")
    return EXIT_OK


class _PlayProgress:
    """Samples played, from HIGH_RATE.profile_index: live on a terminal, every 10 % otherwise."""

    def __init__(self, rate_hz: float) -> None:
        self.tty = sys.stderr.isatty()
        self.decile = -1
        self.rate_hz = rate_hz                # the profile's sample rate (the control rate)

    def __call__(self, index: int, count: int) -> None:
        fraction = index / count if count else 1.0
        if self.tty:
            print(f"\rplaying: {100 * fraction:5.1f} % ({index}/{count} samples, "
                  f"{index / self.rate_hz:.1f} s)", end="", file=sys.stderr, flush=True)
        elif int(fraction * 10) > self.decile:
            self.decile = int(fraction * 10)
            print(f"playing: {100 * fraction:3.0f} % ({index}/{count} samples)",
                  file=sys.stderr, flush=True)

    def done(self) -> None:
        if self.tty:
            print("", file=sys.stderr, flush=True)


def _safety(player) -> str:
    """What the operator needs to know about the device after play() made it safe."""
    if player is None or not player.made_safe:
        return "nothing was started on the device"
    if player.safe_failures:
        return ("COULD NOT CONFIRM THE DEVICE IS SAFE: " + "; ".join(player.safe_failures)
                + " - without heartbeats its watchdog disarms it within watchdog_timeout")
    return "PROFILE_STOP and ABORT completed: the device is disarmed and idle"


def _cmd_play(args) -> int:
    from .station import command_station
    from ..profiles.upload import default_mode

    loaded = _load(args)
    if isinstance(loaded, int):
        return loaded
    dictionary, profile, check, gyro = loaded
    mode = args.mode or default_mode(profile.target)
    if mode not in profile.info.modes:
        return fail(f"{args.file}: a {profile.target} profile plays in "
                     f"{' or '.join(profile.info.modes)}, not {mode}; nothing was sent")
    for w in check.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if not check.ok:
        return fail(f"{args.file}: refused, nothing was sent: " + "; ".join(check.problems))
    print(f"{profile.name}: {profile.target}, {profile.duration:g} s ({profile.sample_count} "
          f"samples), mode {mode}", flush=True)
    progress = _PlayProgress(profile.rate)
    players: list = []                       # the player, for what it made safe
    try:
        with command_station(args, dictionary) as station:
            try:
                result = station.play_profile(profile, mode, timeout=args.timeout, gyro_range=gyro,
                                              progress=progress, upload_progress=print_progress,
                                              on_step=lambda text: print(f"{text} ...", flush=True),
                                              player_out=players)
            except KeyboardInterrupt:
                progress.done()
                return fail("interrupted: " + _safety(players[0] if players else None))
            progress.done()
            rec = players[0].record
            assert rec is not None
            print(f"loaded: profile {rec.profile_id} crc {rec.crc:08x}, {rec.sample_count} "
                  f"samples in {rec.upload_s:.2f} s"
                  + (f", offset {rec.offset:.9g} rad" if rec.origin == ProfileOrigin.RELATIVE else ""))
            print(result.text())
            if not result.completed:
                return fail(f"{profile.name}: playback {result.reason}; " + _safety(players[0]))
            print("done: disarmed")
    except KeyboardInterrupt:
        return fail("interrupted before playback: the device was not started")
    except GroundStationError as exc:
        progress.done()
        player = players[0] if players else None
        return fail(f"{exc}" + (f"; {_safety(player)}" if player is not None and player.made_safe else ""),
                    status_for(exc))
    return EXIT_OK
