"""How fast a campaign runs on the simulated testbed with --fast, recording on.

Side by side, in one run, repeated (--rounds, interleaved; medians):

  ours       Testbed(fast=FastSimOptions(where="process")), what `campaign run --fast` does:
             relative Design #2 uploaded, a 60 s band-limited current profile played
             open loop and a 60 s dwell, both recorded - device seconds per wall second;
             the simulator in a child process of its own, pipelined (clock.FastPacing():
             several 0.75 s chunks in flight, many frames per datagram, device held
             between steps)
  inline     the same with the simulator in this process (FastSimOptions(where="inline")), sharing
             the interpreter with the telemetry receiver
  one chunk  the same with the pacing before issue 19: one chunk in flight, one frame per
             datagram, the device running in real time between steps
  baseline   the real-time simulator (what a rig, or `--device sim` without --fast, takes:
             1 device second per wall second, by definition)
  limit      the simulator alone in fast mode, every frame encoded, nothing sent, received
             or recorded (the same engine and firmware: bench_sim.py's figure)

Where the wall time goes (--profile): per phase, the simulator's own time (engine,
firmware, frame encoding; wall and the thread's CPU time - for the child process, its
CPU time, sending included), sending, the clock's waits
for credits, and the CPU time of the other threads of this process (the receiver, the
queue's feeder to the log writer) and of the log writer process (Linux: from /proc).  Each round's ratios to the simulator alone (measured at the start of the
round) are printed, and their medians.

Run: .venv/bin/python benchmarks/bench_campaign.py [--rounds 3] [--profile]
     .venv/bin/python benchmarks/bench_campaign.py --whole CAMPAIGN... [--before DIR]
         (whole campaigns as `campaign run` runs them: campaign_whole.py)
     .venv/bin/python benchmarks/bench_campaign.py --whole CAMPAIGN... --open-session N
         (N runs of each from one open session: campaign_open_session.py)
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

from campaign_open_session import open_session, print_open_session
from campaign_whole import print_whole, whole
from common import machine, save, stat_cpu_seconds

from groundstation import Testbed
from groundstation.station.clock import ONE_CHUNK_IN_FLIGHT, FastPacing
from groundstation.station.options import FastSimOptions
from groundstation.core.dictionary import load_dictionary
from groundstation.sim.device import SimulatedDevice
from groundstation.sim.firmware import Firmware
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

ROOT = Path(__file__).resolve().parent.parent
PROFILE = ROOT / "profiles" / "waveforms" / "sysid_coarse_noise_0p02A.toml"


def simulator_alone(seconds: float) -> tuple[float, float]:
    """Device seconds per wall second of the engine + firmware + frame encoding, and the
    CPU seconds it took (below the wall time when the machine's load took the core)."""
    d = load_dictionary()
    fw = Firmware(d, seed=0, testbed=load_testbed(TESTBEDS_DIR / "relative_2dof.toml"))
    dev = SimulatedDevice(d, pacing="manual", firmware=fw)
    n = int(seconds * d.control_rate_hz)
    dev._simulate(1200)                            # compile and warm up
    t0, c0 = time.perf_counter(), time.thread_time()
    done = 0
    while done < n:
        dev._simulate(600)
        done += 600
    return seconds / (time.perf_counter() - t0), time.thread_time() - c0


def _cpu_of(stat: Path) -> float:
    """utime + stime of a /proc stat file, s (0 when it cannot be read)."""
    return stat_cpu_seconds(stat) or 0.0


class _Timers:
    """Wall time inside the device's simulate and send, for --profile (wraps the methods
    of one SimulatedDevice instance); CPU time of this process's other threads and of
    the log writer process."""

    def __init__(self, device, tb) -> None:
        self.tb = tb
        #: the simulator's child process (where="process"), else None
        self.child = getattr(device, "proc", None)
        self.cpu0 = self._cpus()
        self.t: Counter = Counter()
        if self.child is None:
            for name in ("_simulate", "_send_telemetry"):
                fn = getattr(device, name)
                setattr(device, name, self._timed(fn, name))

    def _timed(self, fn, name):
        def wrapper(*a, **k):
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                return fn(*a, **k)
            finally:
                self.t[name] += time.perf_counter() - t0
                self.t[name + " cpu"] += time.thread_time() - c0
        return wrapper

    def _cpus(self) -> dict[str, float]:
        """CPU seconds so far: the receiver thread, every other thread of this process
        but the main one and the clock's (both run the simulator), and the log writer
        process."""
        out = {"receiver": 0.0, "other threads": 0.0, "writer": 0.0}
        for t in threading.enumerate():
            if t is threading.main_thread() or t.native_id is None:
                continue
            if t.name == "gs-sim-idle-clock":      # runs the simulator while a profile plays
                continue                            # (counted in simulate)
            key = "receiver" if t.name == "gs-udp-reader" else "other threads"
            out[key] += _cpu_of(Path(f"/proc/self/task/{t.native_id}/stat"))
        rec = self.tb.recording.recorder
        proc = getattr(rec, "_proc", None)
        if proc is not None and proc.pid is not None:
            out["writer"] = _cpu_of(Path(f"/proc/{proc.pid}/stat"))
        if self.child is not None:
            out["simulator process"] = _cpu_of(Path(f"/proc/{self.child.pid}/stat"))
        return out

    def take(self, clock) -> dict[str, float]:
        # simulate cpu: the thread's own CPU time in it; the rest of "simulate" is time the
        # thread waited for a core or for the interpreter (receiver, recorder, other load)
        out = ({"simulate_s": self.t["_simulate"], "simulate cpu_s": self.t["_simulate cpu"],
                "send_s": self.t["_send_telemetry"]} if self.child is None else {})
        out["clock_waits_s"] = clock.waited_s
        cpu = self._cpus()
        for k, v in cpu.items():
            out[f"{k} cpu_s"] = max(0.0, v - self.cpu0.get(k, 0.0))
        self.cpu0 = cpu
        self.t.clear()
        clock.waited_s = 0.0
        return out


def campaign(tmp: str, pacing: FastPacing, between_steps: str, fast_sim: str,
             profile: bool) -> dict:
    fast = FastSimOptions(where=fast_sim, pacing=pacing, between_steps=between_steps)
    with Testbed("sim", testbed=TESTBEDS_DIR / "relative_2dof.toml", fast=fast,
                 log_folder=tmp, history=Path(tmp) / "history") as tb:
        tb.upload_design(ROOT / "profiles" / "controllers" / "relative_design2.toml")
        tb.start_recording("bench")
        timers = _Timers(tb.simulator, tb) if profile else None
        if timers:
            timers.take(tb.clock)
        t0 = time.perf_counter()
        result = tb.play(PROFILE, mode="OPEN_LOOP")
        t_play = time.perf_counter() - t0
        prof_play = timers.take(tb.clock) if timers else {}
        t0 = time.perf_counter()
        tb.dwell(60.0)
        t_dwell = time.perf_counter() - t0
        prof_dwell = timers.take(tb.clock) if timers else {}
        t0 = time.perf_counter()
        rec = tb.stop_recording()
        t_stop = time.perf_counter() - t0
    device_play = result.sample_count / 1200.0
    return {"play_x": device_play / t_play, "dwell_x": 60.0 / t_dwell, "play_wall_s": t_play,
            "dwell_wall_s": t_dwell, "profile_device_s": device_play, "frames": rec["frames"],
            "dropped": rec["dropped"], "discarded_blocks": rec["discarded_blocks"],
            "stop_recording_s": t_stop,
            "profile_play": prof_play, "profile_dwell": prof_dwell}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--profile", action="store_true", help="where the wall time goes, per phase")
    ap.add_argument("--whole", nargs="+", metavar="CAMPAIGN", default=None,
                    help="instead: whole campaigns (profiles/campaigns/NAME.toml or a path) as a "
                         "user runs them, wall time split per step kind and CPU per process "
                         "(campaign_whole.py)")
    ap.add_argument("--analysis", action="store_true", help="--whole: with the analysis at the end")
    ap.add_argument("--before", metavar="DIR", default=None,
                    help="--whole: also run each campaign from this checkout (a git worktree of "
                         "an earlier commit), interleaved, for a before/after in one run")
    ap.add_argument("--before-python", metavar="PYTHON", default=None,
                    help="--whole --before: run that checkout with this interpreter (another "
                         "virtualenv: a dependency's version before and after as well)")
    ap.add_argument("--open-session", type=int, default=0, metavar="N",
                    help="--whole: also run each campaign N times from one open session "
                         "(campaign_open_session.py)")
    args = ap.parse_args()
    print(f"campaign benchmark - {machine()}, load average {os.getloadavg()[0]:.1f} at the start")
    if args.whole and args.open_session:
        return open_sessions(args.whole, args.rounds, args.open_session)
    if args.whole:
        return whole_campaigns(args.whole, args.rounds, args.analysis,
                               Path(args.before).resolve() if args.before else None,
                               args.before_python)
    ways = {"ours": (FastPacing(), "held", "process"), "inline": (FastPacing(), "held", "inline"),
            "one chunk": (ONE_CHUNK_IN_FLIGHT, "realtime", "inline")}
    runs: dict[str, list[dict]] = {k: [] for k in ways}
    limits: list[float] = []
    for r in range(args.rounds):
        rate, cpu = simulator_alone(60.0)
        limits.append(rate)
        if args.profile:
            print(f"  round {r + 1} simulator alone: {rate:6.1f}x, 60 s in {60.0 / rate:.2f} s "
                  f"wall, {cpu:.2f} s CPU")
        for name, (pacing, between, fast_sim) in ways.items():
            with tempfile.TemporaryDirectory() as tmp:
                runs[name].append(campaign(tmp, pacing, between, fast_sim, args.profile))
            x = runs[name][-1]
            # each round's ratios to the simulator alone measured just before it: the
            # machine's load moves both alike within a round, far less across rounds
            x["dwell_ratio"], x["play_ratio"] = x["dwell_x"] / limits[-1], x["play_x"] / limits[-1]
            print(f"  round {r + 1} {name:9s}: dwell {x['dwell_x']:6.1f}x ({x['dwell_ratio']:.2f}), "
                  f"profile {x['play_x']:6.1f}x ({x['play_ratio']:.2f}), "
                  f"simulator alone {limits[-1]:6.1f}x, load {os.getloadavg()[0]:.1f}; "
                  f"{x['frames']} frames, {x['dropped']} dropped, "
                  f"{x['discarded_blocks']} discarded"
                  + (f"; dwell {x['dwell_wall_s']:.2f} s = {_fmt(x['profile_dwell'])}; profile "
                     f"{x['play_wall_s']:.2f} s = {_fmt(x['profile_play'])}; stop_recording "
                     f"{x['stop_recording_s']:.2f} s" if args.profile else ""))
    limit = statistics.median(limits)
    res: dict = {"machine": machine(), "load_average_end": os.getloadavg(), "rounds": args.rounds,
                 "simulator_alone_x_realtime": limit, "simulator_alone_rounds": limits}
    print(f"\nmedians of {args.rounds} rounds, recording on (load average now "
          f"{os.getloadavg()[0]:.1f}):")
    print(f"  limit, the simulator alone (nothing sent or recorded): {limit:6.1f}x real time")
    for name, xs in runs.items():
        dwell = statistics.median(x["dwell_x"] for x in xs)
        play = statistics.median(x["play_x"] for x in xs)
        ok = all(x["dropped"] == 0 and x["discarded_blocks"] == 0 for x in xs)
        dwell_r = statistics.median(x["dwell_ratio"] for x in xs)
        play_r = statistics.median(x["play_ratio"] for x in xs)
        res[name] = {"dwell_x_realtime": dwell, "play_x_realtime": play, "runs": xs,
                     "dwell_ratio_to_limit": dwell / limit, "play_ratio_to_limit": play / limit,
                     "dwell_ratio_median_of_rounds": dwell_r, "play_ratio_median_of_rounds": play_r}
        print(f"  {name:9s}: 60 s dwell {dwell:6.1f}x ({dwell / limit:.2f} of the limit; median of "
              f"the rounds' ratios {dwell_r:.2f}), 60 s profile (upload, arm, play, disarm) "
              f"{play:6.1f}x ({play / limit:.2f}; {play_r:.2f}); "
              f"{'0 dropped, 0 discarded' if ok else 'FRAMES LOST'}")
    print("  baseline, real-time simulator or a rig:                  1.0x real time")
    print(f"written to {save('campaign', res)}")


def whole_campaigns(names: list[str], rounds: int, analysis: bool, before: Path | None,
                    before_python: str | None = None) -> None:
    """Each campaign `rounds` times (and from `before` too), interleaved, the simulator
    alone measured before each round; the round with the median wall time is printed in
    full."""
    paths = [Path(n).resolve() if Path(n).exists() else ROOT / "profiles" / "campaigns" / f"{n}.toml"
             for n in names]
    trees = [("now", None)] + ([("before", before)] if before is not None else [])
    results: dict[str, list[dict]] = {f"{p.stem} {label}": [] for p in paths for label, _ in trees}
    limits = []
    for r in range(rounds):
        rate, _ = simulator_alone(60.0)
        limits.append(rate)
        for p, (label, tree) in ((p, t) for p in paths for t in trees):
            x = whole(p, analysis=analysis, tree=tree, python=before_python if tree else None)
            x["simulator_alone_x"] = rate
            x["ratio_to_limit"] = x["device_per_wall"] / rate
            results[f"{p.stem} {label}"].append(x)
            print(f"  round {r + 1} {p.stem} {label}: {x['device_per_wall']:.1f}x real time "
                  f"({x['ratio_to_limit']:.2f} of the simulator alone, {rate:.1f}x), "
                  f"{x['wall_s']:.2f} s wall, load {os.getloadavg()[0]:.1f}")
    print(f"\nthe median round of each (load average now {os.getloadavg()[0]:.1f}):")
    out: dict = {"machine": machine(), "rounds": rounds, "simulator_alone_rounds": limits}
    for name, xs in results.items():
        mid = sorted(xs, key=lambda x: x["wall_s"])[len(xs) // 2]
        print_whole(mid, mid["simulator_alone_x"])
        out[name] = {"median_device_per_wall": statistics.median(x["device_per_wall"] for x in xs),
                     "median_ratio_to_limit": statistics.median(x["ratio_to_limit"] for x in xs),
                     "runs": xs}
        print(f"    median of {rounds}: {out[name]['median_device_per_wall']:.1f}x real time, "
              f"{out[name]['median_ratio_to_limit']:.2f} of the simulator alone")
    print(f"written to {save('campaign_whole', out)}")


def _fmt(p: dict) -> str:
    return ", ".join(f"{k[:-2]} {v:.2f} s" for k, v in p.items())


def open_sessions(names: list[str], rounds: int, runs: int) -> None:
    """Each campaign `runs` times from one open session, `rounds` sessions; the session
    with the median whole-session figure is printed in full."""
    out: dict = {"machine": machine(), "rounds": rounds, "runs_per_session": runs}
    for n in names:
        path = Path(n).resolve() if Path(n).exists() else ROOT / "profiles" / "campaigns" / f"{n}.toml"
        sessions = []
        for r in range(rounds):
            sessions.append(open_session(path, runs))
            x = sessions[-1]
            print(f"  round {r + 1} {path.stem}: first run {x['runs'][0]['device_per_wall']:.1f}x, "
                  f"later runs {statistics.median(y['device_per_wall'] for y in x['runs'][1:]):.1f}x "
                  f"(median), session {x['session_device_per_wall']:.1f}x, load {os.getloadavg()[0]:.1f}")
        mid = sorted(sessions, key=lambda x: x["session_device_per_wall"])[len(sessions) // 2]
        print_open_session(mid)
        out[path.stem] = {"sessions": sessions}
    print(f"written to {save('campaign_open_session', out)}")


if __name__ == "__main__":
    main()

