"""Many consoles on one rig: frames delivered per viewer, publisher CPU, drops.

The commander (a DeviceClient with a session, in this process) receives a simulated
testbed's telemetry (a child process, real-time pacing) at 1200 Hz and at the 10x burst
(--speed 10: 12 000 frames/s).  Per rate it is measured alone, then publishing to 1, 4
and 8 viewers, each a child process running a WatchClient (fanout/viewer.py) that counts
what it decodes between "go" and "stop".  Each window lasts --seconds (default 10).

    frames/viewer   HIGH_RATE frames a viewer decoded per second in its window (the
                    commander's rate beside it), and the share of the frames in its window
                    it decoded (frames / (frames + its sequence-number drops))
    drops           frames missing from a viewer's sequence numbers + messages it missed
                    (publisher high-water mark), and the commander's own drops
    publisher CPU   the publish calls on the link's receiving thread (thread CPU time; the
                    same for any number of viewers) and ZeroMQ's I/O thread, which writes
                    each message to each viewer (/proc/self/task), per viewer; % of a core.  Also this
                    process's whole CPU next to the commander alone in the same run:
                    with viewers competing for the same cores that difference is noise
    viewer CPU      each viewer process's own CPU, % of a core (mean over viewers)

It measures, it asserts nothing.  Run on a shared machine, the figures are indicative.

    python benchmarks/bench_fanout.py [--seconds 10] [--viewers 1,4,8]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from common import machine, save  # noqa: E402

from groundstation.core.dictionary import load_dictionary  # noqa: E402
from groundstation.fanout.publisher import Publisher  # noqa: E402
from groundstation.link import open_client  # noqa: E402
from groundstation.sim.process import SimulatorProcess  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent

#: the viewer child: waits for the hello, then counts between "go" and "stop" (stdin)
VIEWER = r"""
import json, sys, time
from groundstation.core.dictionary import load_dictionary
from groundstation.fanout.viewer import WatchClient
v = WatchClient(load_dictionary(), sys.argv[1]).start().wait_up(30.0)
count = [0]
v.subscribe(lambda b: count.__setitem__(0, count[0] + len(b)) if b.name == "HIGH_RATE" else None)
print("READY", flush=True)
sys.stdin.readline()
def state():
    s = v.stats.snapshot()
    return count[0], s.dropped, v.counters.missed_messages, time.process_time()
start = state()
sys.stdin.readline()
end = state()
v.close()
print(json.dumps({"frames": end[0] - start[0], "dropped": end[1] - start[1],
                  "missed_messages": end[2] - start[2], "cpu_s": end[3] - start[3]}), flush=True)
"""


def zmq_threads_cpu_s() -> float:
    """CPU seconds of this process's ZeroMQ background threads (named ZMQbg/...): from
    schedstat (nanoseconds on the CPU), else stat (clock ticks, 10 ms)."""
    total, tick = 0.0, os.sysconf("SC_CLK_TCK")
    for task in Path("/proc/self/task").iterdir():
        try:
            if not (task / "comm").read_text().startswith("ZMQbg"):
                continue
            try:
                total += int((task / "schedstat").read_text().split()[0]) / 1e9
            except OSError:
                fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
                total += (int(fields[11]) + int(fields[12])) / tick     # utime + stime
        except (OSError, IndexError, ValueError):
            continue
    return total


class Commander:
    """The station that holds the session, counting what it receives."""

    def __init__(self, dictionary, address: str):
        self.client = open_client(dictionary, address)
        self.frames = 0
        self.publish_cpu_s = 0.0           # in the publisher's calls, on the link's thread
        self.client.subscribe(self._count)
        self.client.connect()

    def _count(self, block) -> None:
        if block.name == "HIGH_RATE":
            self.frames += len(block)

    def timed(self, publish):
        def tap(path, chunks, times):
            t = time.thread_time()
            publish(path, chunks, times)
            self.publish_cpu_s += time.thread_time() - t
        return tap

    def state(self) -> tuple[int, int, float, float, float]:
        return (self.frames, self.client.stats.snapshot().dropped, time.process_time(),
                zmq_threads_cpu_s(), self.publish_cpu_s)


def measure(commander: Commander, seconds: float, endpoint: str | None, n_viewers: int) -> dict:
    viewers = []
    for _ in range(n_viewers if endpoint else 0):
        viewers.append(subprocess.Popen([sys.executable, "-c", VIEWER, endpoint], cwd=ROOT,
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                        env={**os.environ, "PYTHONUNBUFFERED": "1"}))
    try:
        for v in viewers:
            line = v.stdout.readline()
            if "READY" not in line:
                raise RuntimeError(f"a viewer did not start: {line!r}")
        for v in viewers:
            v.stdin.write("go\n")
            v.stdin.flush()
        f0, d0, c0, z0, p0 = commander.state()
        t0 = time.monotonic()
        time.sleep(seconds)                   # the measurement window itself
        f1, d1, c1, z1, p1 = commander.state()
        wall = time.monotonic() - t0
        for v in viewers:
            v.stdin.write("stop\n")
            v.stdin.flush()
        results = [json.loads(v.stdout.readline()) for v in viewers]
    finally:
        for v in viewers:
            try:
                v.wait(timeout=20)
            except subprocess.TimeoutExpired:
                v.kill()
    frames = f1 - f0
    out = {"viewers": n_viewers if endpoint else 0, "commander_frames": frames,
           "commander_rate_hz": round(frames / wall, 1), "commander_dropped": d1 - d0,
           "process_cpu_pct": round(100 * (c1 - c0) / wall, 2),
           "zmq_io_cpu_pct": round(100 * (z1 - z0) / wall, 2),
           "publish_calls_cpu_pct": round(100 * (p1 - p0) / wall, 2)}
    if results:
        # a viewer's window starts and ends a pipe write later than the commander's
        out["frames_per_viewer"] = [r["frames"] for r in results]
        out["viewer_rate_hz_min"] = round(min(r["frames"] for r in results) / wall, 1)
        # of the frames in a viewer's window, the share it decoded (the rest: its drops)
        out["delivered_fraction_min"] = round(min(r["frames"] / max(r["frames"] + r["dropped"], 1)
                                                  for r in results), 4)
        out["viewer_dropped"] = [r["dropped"] for r in results]
        out["viewer_missed_messages"] = [r["missed_messages"] for r in results]
        out["viewer_cpu_pct_mean"] = round(100 * sum(r["cpu_s"] for r in results)
                                           / len(results) / wall, 2)
    return out


def run_rate(dictionary, speed: float, seconds: float, counts: list[int]) -> dict:
    sim = SimulatorProcess(pacing="realtime", speed=speed)
    address = sim.start()
    commander = Commander(dictionary, address)
    publisher = None
    try:
        time.sleep(1.0)                       # let the stream settle before measuring
        rows = [measure(commander, seconds, None, 0)]
        alone = rows[0]["process_cpu_pct"]
        publisher = Publisher("tcp://127.0.0.1:*")
        publisher.publish_frames = commander.timed(publisher.publish_frames)
        publisher.attach(commander.client, address)
        for n in counts:
            row = measure(commander, seconds, publisher.endpoint, n)
            row["process_cpu_pct_vs_alone_per_viewer"] = round((row["process_cpu_pct"] - alone) / n, 2)
            # the publish calls cost the same for any number of viewers; ZeroMQ's I/O
            # thread writes each message to each viewer
            row["zmq_io_cpu_pct_per_viewer"] = round(row["zmq_io_cpu_pct"] / n, 3)
            rows.append(row)
            print(f"  speed {speed:g}x, {n} viewer(s): {row}", flush=True)
        return {"speed": speed, "rows": rows, "publisher_sent": publisher.sent,
                "publisher_send_errors": publisher.send_errors}
    finally:
        if publisher is not None:
            publisher.close()
        commander.client.close()
        sim.stop()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--viewers", default="1,4,8")
    args = ap.parse_args()
    counts = [int(n) for n in args.viewers.split(",")]
    d = load_dictionary()
    results = {"machine": machine(), "seconds": args.seconds, "rates": []}
    for speed in (1.0, 10.0):
        print(f"speed {speed:g}x ({speed * d.control_rate_hz:.0f} frames/s)", flush=True)
        results["rates"].append(run_rate(d, speed, args.seconds, counts))
    print(f"wrote {save('fanout', results)}")
    for rate in results["rates"]:
        for row in rate["rows"]:
            extra = ""
            if row["viewers"]:
                extra = (f", slowest viewer {row['viewer_rate_hz_min']} frames/s, delivered >= "
                         f"{100 * row['delivered_fraction_min']:.2f} %, viewer drops "
                         f"{sum(row['viewer_dropped'])}, missed msgs {sum(row['viewer_missed_messages'])}, "
                         f"publisher: calls on the link thread {row['publish_calls_cpu_pct']} %, "
                         f"ZeroMQ I/O {row['zmq_io_cpu_pct_per_viewer']} % per viewer; viewer CPU "
                         f"{row['viewer_cpu_pct_mean']} %")
            print(f"{rate['speed']:g}x {row['viewers']} viewer(s): commander "
                  f"{row['commander_rate_hz']} frames/s, drops {row['commander_dropped']}, process CPU "
                  f"{row['process_cpu_pct']} %{extra}")


if __name__ == "__main__":
    threading.current_thread().name = "bench"
    main()
