"""The operator's window under load: the real MainWindow (offscreen, 1600x1000) on the
simulated inertial testbed streaming 1200 Hz, recording on, 8 channels on 4 plots with a
60 s window - then a 10x burst (12 000 frames/s).

Steady run (--minutes, default 10) and burst (--burst-seconds, default 10), each measured
over its own window (the first --warmup-seconds of the steady run are not counted):

  chart fps        StripChartPanel.stats.fps (redraws in the last second), sampled once a
                   second; every refresh() is also timed (snapshot + decimate + setData;
                   the paint that follows happens later in the event loop, so it shows in
                   the latency, not here).
  loop latency     a single-shot 20 ms Qt.PreciseTimer, re-armed from its own timeout:
                   lateness = fire time - (arm time + 20 ms).  This is how long anything
                   posted to the GUI thread (a key press, Esc, a redraw) can wait.
  CPU              GUI process: getrusage(RUSAGE_SELF) user+sys over wall time (all its
                   threads: Qt, link receivers, decoding, the store).  The simulator and
                   the recorder's writer are separate processes: /proc/<pid>/stat.
                   100 % = one core.
  drops            HIGH_RATE frames the link lost (sequence gaps, client stats), ticks
                   missing from what arrived (sequence gaps + simulator overruns), blocks
                   the recorder discarded (its queue full); frames received vs expected
                   from the device tick span, and ticks per wall second vs 1200 x speed.

The burst is a second simulator process at --speed 10; the window's link is ended, its
client closed, the first simulator stopped (a real rig is one device), and only then is
the window connected to the second one with Session.connect_address - a client still
closing when its simulator stops reports "lost", and the session would reconnect.  A
phase in which the session replaced its client anyway says so (client_changes).

Run: QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/bench_gui.py [--minutes 10]
     [--burst-seconds 10]
Writes benchmarks/results/gui.json.

Before and after in one run: --before REV [--after REV2] [--rounds N] checks REV (and
REV2, else the checkout as it is) out into temporary git worktrees and runs the whole
benchmark N times (default 2) for each side, in fresh processes, alternating which goes
first; each side's package is imported from its tree (PYTHONPATH), this script is the
same for both.  Prints the medians
side by side and writes benchmarks/results/gui_before_after.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import numpy as np
import pyqtgraph as pg
import PySide6
from PySide6.QtCore import QEventLoop, QObject, QSettings, Qt, QTimer
from PySide6.QtWidgets import QApplication

from common import proc_cpu_seconds
from gui_report import before_after, print_table

from groundstation.core.dictionary import load_dictionary
from groundstation.gui.main_window import MainWindow
from groundstation.gui.session.session import Session
from groundstation.logs.live import attach_recorder
from groundstation.sim.process import SimulatorProcess
from groundstation.plant.testbed import TESTBEDS_DIR

HERE = Path(__file__).resolve().parent
TESTBED = TESTBEDS_DIR / "inertial_2dof.toml"
RATE = 1200.0
LAYOUT = [["HIGH_RATE.encoder_outer", "HIGH_RATE.encoder_inner"],
          ["HIGH_RATE.los_estimate", "HIGH_RATE.reference"],
          ["HIGH_RATE.gyro_rate", "HIGH_RATE.error_rate"],
          ["HIGH_RATE.current_coarse", "HIGH_RATE.current_fine"]]
WINDOW_S = 60.0
PROBE_MS = 20

_interrupted = False


# ---------------------------------------------------------------------- helpers

def self_cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def system_cpu_seconds() -> float | None:
    """CPU seconds all processes used (every core), from /proc/stat."""
    try:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
    except OSError:
        return None
    user, nice, system, idle, iowait, irq, softirq, steal = (int(x) for x in fields[:8])
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def machine() -> str:
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{platform.machine()}, {os.cpu_count()} cores{' (' + cpu + ')' if cpu else ''}, "
            f"{platform.system()} {platform.release()}, Python {platform.python_version()}, "
            f"PySide6 {PySide6.__version__}, pyqtgraph {pg.__version__}, "
            f"Qt platform {os.environ.get('QT_QPA_PLATFORM', '?')}")


def wait(seconds: float, until=None, poll_ms: int = 50) -> bool:
    """Run the Qt event loop for `seconds` (or until `until()` is true): never a blocking
    sleep in the GUI thread.  Returns whether `until` came true (True without one)."""
    loop = QEventLoop()
    met = [until is None]
    deadline = QTimer()
    deadline.setSingleShot(True)
    deadline.setTimerType(Qt.TimerType.PreciseTimer)
    deadline.timeout.connect(loop.quit)
    poll = QTimer()

    def check():
        if _interrupted:
            loop.quit()
        elif until is not None and until():
            met[0] = True
            loop.quit()
    poll.timeout.connect(check)
    poll.start(poll_ms)
    deadline.start(max(0, int(seconds * 1000)))
    check()
    if _interrupted:
        return False
    if not met[0] or until is None:
        loop.exec()
    poll.stop()
    deadline.stop()
    return met[0] and not _interrupted


def pct(values, q) -> float | None:
    return float(np.percentile(values, q)) if len(values) else None


# ---------------------------------------------------------------------- probes
class LatencyProbe(QObject):
    """Lateness of a 20 ms single-shot precise timer, re-armed at each timeout."""

    def __init__(self, interval_ms: int = PROBE_MS):
        super().__init__()
        self.interval = interval_ms / 1000.0
        self.samples: list[float] = []          # seconds late
        self.recording = False
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setTimerType(Qt.TimerType.PreciseTimer)
        self._timer.timeout.connect(self._fired)
        self._armed = 0.0
        self._ms = interval_ms

    def start(self) -> None:
        self._armed = time.perf_counter()
        self._timer.start(self._ms)

    def stop(self) -> None:
        self._timer.stop()

    def _fired(self) -> None:
        now = time.perf_counter()
        if self.recording:
            self.samples.append(now - self._armed - self.interval)
        self._armed = now
        self._timer.start(self._ms)


class RefreshTimer:
    """Times every StripChartPanel.refresh() (wrapping the instance's method): wall time
    and the GUI thread's CPU time (the latter does not grow when other processes compete
    for the cores)."""

    def __init__(self, charts):
        self.samples: list[float] = []
        self.cpu_samples: list[float] = []
        self.recording = False
        inner = charts.refresh

        def timed():
            t, c = time.perf_counter(), time.thread_time()
            inner()
            if self.recording:
                self.samples.append(time.perf_counter() - t)
                self.cpu_samples.append(time.thread_time() - c)
        charts.refresh = timed


class TickCounter:
    """Subscriber on the link: HIGH_RATE frames received and ticks missing between them
    (a link drop or a simulator overrun both leave a hole in the tick sequence)."""

    def __init__(self):
        self._lock = threading.Lock()
        self.frames = 0
        self.missing = 0
        self.last_tick: int | None = None

    def reset_source(self) -> None:
        with self._lock:
            self.last_tick = None

    def __call__(self, block) -> None:
        if block.name != "HIGH_RATE" or not len(block):
            return
        ticks = np.asarray(block["tick"], dtype=np.int64)
        with self._lock:
            prev = self.last_tick if self.last_tick is not None else int(ticks[0]) - 1
            steps = np.diff(np.concatenate(([prev], ticks)))
            self.missing += int(np.clip(steps - 1, 0, None).sum())
            self.frames += len(ticks)
            self.last_tick = int(ticks[-1])

    def read(self) -> tuple[int, int, int | None]:
        with self._lock:
            return self.frames, self.missing, self.last_tick


# ---------------------------------------------------------------------- one measured phase
class Phase:
    """Counters at the start of a measurement window; `finish` gives the figures."""

    def __init__(self, name: str, ctx: "Bench", speed: float):
        self.name, self.ctx, self.speed = name, ctx, speed
        self.fps: list[float] = []
        self.refresh_ms_last: list[float] = []
        self.t0 = time.monotonic()
        self.cpu0 = self_cpu_seconds()
        self.thread_cpu0 = time.thread_time()          # the GUI thread (we run in it)
        self.system_cpu0 = system_cpu_seconds()
        self.load0 = os.getloadavg()[0]
        self.sim_cpu0 = proc_cpu_seconds(ctx.sim_pid) if ctx.sim_pid else None
        self.writer_cpu0 = proc_cpu_seconds(ctx.writer_pid) if ctx.writer_pid else None
        self.link0 = ctx.link_counts()
        self.ticks0 = ctx.counter.read()
        self.discarded0 = ctx.discarded()
        self.overruns0 = ctx.sim_overruns()
        self.lat0 = len(ctx.probe.samples)
        self.ref0 = len(ctx.refresh.samples)
        self.client = ctx.session.client
        self.client_changes = 0

    def sample(self) -> None:
        # a reconnect mid-phase (a new client) is counted and followed, not missed
        if self.ctx.session.client is not self.client and self.ctx.session.client is not None:
            self.client_changes += 1
            self.client = self.ctx.session.client
            self.ctx.count_on_client()
        s = self.ctx.window.charts.stats
        self.fps.append(s.fps)
        self.refresh_ms_last.append(s.last_refresh_ms)

    def finish(self) -> dict:
        ctx = self.ctx
        wall = time.monotonic() - self.t0
        cpu = self_cpu_seconds() - self.cpu0
        thread_cpu = time.thread_time() - self.thread_cpu0
        system_cpu1 = system_cpu_seconds()
        frames1, dropped1 = ctx.link_counts()
        f1, miss1, tick1 = ctx.counter.read()
        f0, miss0, tick0 = self.ticks0
        lat = np.array(ctx.probe.samples[self.lat0:]) * 1000.0
        ref = np.array(ctx.refresh.samples[self.ref0:]) * 1000.0
        ref_cpu = np.array(ctx.refresh.cpu_samples[self.ref0:]) * 1000.0
        received = f1 - f0
        span = (tick1 - tick0) if (tick0 is not None and tick1 is not None) else None
        sim_cpu1 = proc_cpu_seconds(ctx.sim_pid) if ctx.sim_pid else None
        writer_cpu1 = proc_cpu_seconds(ctx.writer_pid) if ctx.writer_pid else None
        overruns1 = ctx.sim_overruns()
        fps = np.array(self.fps)
        sim_pct = (100.0 * (sim_cpu1 - self.sim_cpu0) / wall
                   if sim_cpu1 is not None and self.sim_cpu0 is not None else None)
        writer_pct = (100.0 * (writer_cpu1 - self.writer_cpu0) / wall
                      if writer_cpu1 is not None and self.writer_cpu0 is not None else None)
        system_pct = (100.0 * (system_cpu1 - self.system_cpu0) / wall
                      if system_cpu1 is not None and self.system_cpu0 is not None else None)
        others = (system_pct - 100.0 * cpu / wall - (sim_pct or 0.0) - (writer_pct or 0.0)
                  if system_pct is not None else None)
        return {
            "seconds": wall,
            "speed": self.speed,
            "fps_mean": float(fps.mean()) if len(fps) else None,
            "fps_median": pct(fps, 50),
            "fps_p5": pct(fps, 5),
            "fps_min": float(fps.min()) if len(fps) else None,
            "fps_samples": [round(float(x), 1) for x in fps],
            "refresh_ms_p50": pct(ref, 50),
            "refresh_ms_p99": pct(ref, 99),
            "refresh_ms_max": float(ref.max()) if len(ref) else None,
            "refresh_cpu_ms_p50": pct(ref_cpu, 50),
            "refresh_cpu_ms_p99": pct(ref_cpu, 99),
            "refreshes": len(ref),
            "refreshes_per_s": len(ref) / wall if wall else None,
            "latency_probe": f"{PROBE_MS} ms single-shot Qt.PreciseTimer, lateness vs its schedule",
            "latency_ms_p50": pct(lat, 50),
            "latency_ms_p99": pct(lat, 99),
            "latency_ms_max": float(lat.max()) if len(lat) else None,
            "latency_samples": len(lat),
            "gui_cpu_percent": 100.0 * cpu / wall,
            "gui_thread_cpu_percent": 100.0 * thread_cpu / wall,
            # GUI-thread CPU per chart frame (all its work, charts or not): 1000 / this is
            # the frame rate the GUI thread could reach with a core to itself
            "gui_thread_cpu_ms_per_frame": (1000.0 * thread_cpu / len(ref)) if len(ref) else None,
            "sim_cpu_percent": sim_pct,
            "writer_cpu_percent": writer_pct,
            "machine_cpu_percent": system_pct,
            "machine_cores": os.cpu_count(),
            "other_processes_cpu_percent": others,
            "loadavg_1min": [self.load0, os.getloadavg()[0]],
            "high_rate_received": received,
            "high_rate_expected": span,
            "ticks_per_wall_s": span / wall if span is not None else None,
            "ticks_per_wall_s_target": RATE * self.speed,
            "link_dropped": dropped1 - self.link0[1],
            "tick_gaps": miss1 - miss0,
            "sim_overruns": (overruns1 - self.overruns0
                             if overruns1 is not None and self.overruns0 is not None else None),
            "recorder_discarded_blocks": ctx.discarded() - self.discarded0,
            "client_changes": self.client_changes,
        }


# ---------------------------------------------------------------------- the run
class Bench:
    def __init__(self, args):
        self.args = args
        self.d = load_dictionary()
        self.tmp = Path(tempfile.mkdtemp(prefix="gs-bench-gui-"))
        self.settings = QSettings(str(self.tmp / "settings.ini"), QSettings.Format.IniFormat)
        self.session = Session(self.d)
        self.window = MainWindow(self.session, self.settings)
        self.probe = LatencyProbe()
        self.refresh = RefreshTimer(self.window.charts)
        self.counter = TickCounter()
        self.burst_sim: SimulatorProcess | None = None
        self.sim_pid: int | None = None
        self.writer_pid: int | None = None
        self._counted_client = None
        self._discarded_before = 0       # recorders already closed

    # ---- readings
    def link_counts(self) -> tuple[int, int]:
        """HIGH_RATE frames and dropped frames of the current client (0, 0 without one)."""
        client = self.session.client
        if client is None:
            return 0, 0
        p = client.stats.snapshot().packets.get("HIGH_RATE")
        return (p.frames, p.dropped) if p is not None else (0, 0)

    def discarded(self) -> int:
        rec = self.session.recorder
        return self._discarded_before + (rec.discarded_blocks if rec is not None else 0)

    def sim_overruns(self) -> int | None:
        v = self.session.store.rings["HOUSEKEEPING"].latest("telemetry_overruns")
        return None if v is None or v != v else int(v)

    def link_up(self) -> bool:
        c = self.session.client
        return c is not None and c.link_state == "up"

    def count_on_client(self) -> None:
        """Subscribe the tick counter to the current client (once per client)."""
        c = self.session.client
        if c is not None and c is not self._counted_client:
            self.counter.reset_source()
            c.subscribe(self.counter)
            self._counted_client = c

    # ---- phases
    def measure(self, name: str, seconds: float, speed: float) -> dict:
        phase = Phase(name, self, speed)
        self.probe.recording = self.refresh.recording = True
        sampler = QTimer()
        sampler.setTimerType(Qt.TimerType.PreciseTimer)
        sampler.timeout.connect(phase.sample)
        sampler.start(1000)
        next_print = time.monotonic() + 60.0
        end = time.monotonic() + seconds
        while time.monotonic() < end and not _interrupted:
            wait(min(5.0, end - time.monotonic()))
            if time.monotonic() >= next_print and self.args.progress:
                next_print += 60.0
                lat = np.array(self.probe.samples[phase.lat0:]) * 1000
                print(f"  {name}: {time.monotonic() - phase.t0:5.0f} s, fps "
                      f"{np.mean(phase.fps[-60:]):.1f}, latency p99 {pct(lat, 99):.1f} ms, "
                      f"dropped {self.link_counts()[1] - phase.link0[1]}", flush=True)
        sampler.stop()
        self.probe.recording = self.refresh.recording = False
        return phase.finish()

    def run(self) -> dict:
        a = self.args
        w = self.window
        w.resize(1600, 1000)
        w.show()
        self.probe.start()
        t_start = time.monotonic()
        self.session.connect_sim(str(TESTBED))
        if not wait(60.0, self.link_up):
            raise SystemExit("the window did not connect to the simulated testbed within 60 s")
        self.sim_pid = self.session.sim.proc.pid if self.session.sim and self.session.sim.proc else None
        self.count_on_client()
        w.charts.set_layout(LAYOUT)
        w.charts.set_window_seconds(WINDOW_S)
        path = self.session.start_recording(str(self.tmp / "logs"), "bench_gui",
                                            "GUI benchmark: 1200 Hz, 8 channels, 60 s window")
        if path is None:
            raise SystemExit("the recording did not start")
        rec = self.session.recorder
        self.writer_pid = rec._proc.pid if getattr(rec, "_proc", None) is not None else None
        print(f"connected to {self.session.address} ({self.session.sim.address}), recording "
              f"to {path}; warm-up {a.warmup_seconds:g} s", flush=True)
        wait(a.warmup_seconds)
        steady = self.measure("steady", a.minutes * 60.0, 1.0)

        # ---- the burst: a second simulator at 10x, the window switched to it
        print(f"burst: starting a simulator at {a.burst_speed:g}x", flush=True)
        self.burst_sim = SimulatorProcess(testbed=str(TESTBED), speed=a.burst_speed)
        address = self.burst_sim.start()           # ~1 s, not measured
        old_sim, old_client = self.session.sim, self.session.client
        # First end the old link and wait until its client is closed, then stop the old
        # simulator, then connect: a client that is still closing when its simulator
        # stops reports "lost", and the session then "reconnects" - to the new address,
        # taking the new client's session over in the middle of the burst (seen:
        # the counter stayed on the replaced client and saw 400-800 ticks a wall second).
        self.session.disconnect_link()
        wait(10.0, lambda: old_client is None or old_client.link_state != "up")
        if old_sim is not None and self.session.sim is old_sim:
            self.session.sim = None
            old_sim.stop()
        wait(0.3)                                  # queued link signals of the old client
        self.session.connect_address(address)
        if not wait(30.0, self.link_up):
            raise SystemExit(f"the window did not connect to the burst simulator {address}")
        # The session attaches its recorder to a new client itself (older revisions did
        # not); the store keeps the old device's (later) device times.
        if self.session.recorder is not None and getattr(self.session, "_detach_recorder", None) is None:
            attach_recorder(self.session.client, self.session.recorder)
        if not a.keep_store:
            self.session.store.clear()
        self.count_on_client()
        self.sim_pid = self.burst_sim.proc.pid if self.burst_sim.proc else None
        wait(0.5)
        burst = self.measure("burst", a.burst_seconds, a.burst_speed)

        rec = self.session.recorder
        status = None
        if rec is not None:
            self.session.stop_recording()          # blocks until the writer closed the file
            status = rec.status()
            self._discarded_before += rec.discarded_blocks
        import groundstation
        return {
            "machine": machine(),
            "package": str(Path(groundstation.__file__).parent),
            "window": [w.width(), w.height()],
            "layout": LAYOUT,
            "window_s": WINDOW_S,
            "testbed": str(TESTBED.name),
            "warmup_seconds": a.warmup_seconds,
            "steady": steady,
            "burst": burst,
            "recording": {
                "frames": status.frames if status else None,
                "bytes": status.bytes if status else None,
                "state": status.state if status else None,
                "discarded_blocks": status.discarded_blocks if status else None,
            },
            "total_wall_s": time.monotonic() - t_start,
            "store_cleared_before_burst": not a.keep_store,
        }

    def close(self) -> None:
        self.probe.stop()
        try:
            self.window.close()                    # saves settings (temp file), shuts the session
        finally:
            self.session.shutdown()
            if self.burst_sim is not None:
                self.burst_sim.stop()
            QApplication.processEvents()
            shutil.rmtree(self.tmp, ignore_errors=True)


# ---------------------------------------------------------------------- main
def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=10.0, help="steady run at 1200 Hz (default 10)")
    p.add_argument("--burst-seconds", type=float, default=10.0, help="10x burst (default 10)")
    p.add_argument("--burst-speed", type=float, default=10.0, help=argparse.SUPPRESS)
    p.add_argument("--warmup-seconds", type=float, default=5.0,
                   help="after connecting, before measuring (default 5)")
    p.add_argument("--keep-store", action="store_true",
                   help="do not clear the chart store when switching to the burst simulator")
    p.add_argument("--no-progress", dest="progress", action="store_false",
                   help="no progress line every minute")
    p.add_argument("--out", default=str(HERE / "results" / "gui.json"))
    p.add_argument("--before", metavar="REV", default=None,
                   help="also run this git revision (temporary worktree), alternating")
    p.add_argument("--after", metavar="REV", default=None,
                   help="with --before: run this revision (a worktree too) instead of the checkout")
    p.add_argument("--rounds", type=int, default=2, help="runs per side with --before (default 2)")
    args = p.parse_args()
    if args.before:
        return before_after(args, Path(__file__).resolve())

    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName("groundstation-bench")

    def on_sigint(*_):
        global _interrupted
        _interrupted = True
    signal.signal(signal.SIGINT, on_sigint)

    bench = Bench(args)
    try:
        res = bench.run()
    finally:
        bench.close()
    if _interrupted:
        print("interrupted: no results written", file=sys.stderr)
        return 1
    print_table(res)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(f"\nwritten to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
