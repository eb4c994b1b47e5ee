"""Simulated-testbed speed, side by side in one run.

Fast mode: simulated seconds per wall second of the 2-DOF inertial configuration with
DB-DHM friction and full-size controllers running (every cascade 12 sections, more than
the thesis's Design #2 needs), friction compensation on:
  core      Firmware.run (sensors, control law, plant, friction) - no frame encoding
  frames    SimulatedDevice.run_fast (the same plus encoding every frame for a consumer)
  limit     real time (1x) and the 50x target

Paced mode (--paced-seconds, default 60): `groundstation sim` as its own process; a
client records when each HIGH_RATE frame arrives against its tick, and we report the
lateness distribution (arrival - (t0 + tick/1200), t0 fitted as the earliest possible)
and the simulator process's CPU use from /proc.

Speed factor (--speed-seconds, default 1; moved here from tests/sim/test_sim_speed.py,
which now checks the pacing law on a controlled clock): device ticks per wall second of
the paced simulator at `speed` 1 and 5, in this process and as `groundstation sim
--speed 5`, against 1200 x speed; the tolerance is 0.85-1.1 (in process) and 0.8-1.2
(the process, measured on frame arrivals).

Run: .venv/bin/python benchmarks/bench_sim.py [--paced-seconds 60] [--speed-seconds 1]
"""

from __future__ import annotations

import argparse
import threading
import time
import zlib
from pathlib import Path

import numpy as np
from scipy import signal

from common import machine, proc_cpu_seconds, save
from groundstation.codec.frames import encode_items
from groundstation.core.dictionary import load_dictionary
from groundstation.link import open_client
from groundstation.params import table as ptable
from groundstation.sim import SimulatedDevice
from groundstation.sim.firmware import COMPLETED, Firmware
from groundstation.sim.process import SimulatorProcess
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

RATE = 1200.0


def full_size_cascade(seed: int) -> np.ndarray:
    """12 stable, non-trivial second-order sections (a 24th-order filter)."""
    rng = np.random.default_rng(seed)
    sos = []
    for _ in range(12):
        r, th = rng.uniform(0.5, 0.95), rng.uniform(0.05, 2.5)
        z = rng.uniform(0.3, 0.9)
        sos.append([1.0, -2 * z * np.cos(th), z * z, 1.0, -2 * r * np.cos(th), r * r])
    sos = np.array(sos)
    gain = np.abs(signal.sosfreqz(sos, worN=[0.0])[1][0])
    sos[0, :3] /= gain                                   # unit DC gain overall
    return sos


def command(fw: Firmware, seq: int, token: int, name: str, **args) -> bytes:
    cmd = fw.d.command(name)
    stages = fw.handle_command(seq, token, cmd.opcode, encode_items(cmd.args, args, name), "bench")
    assert stages[-1].stage == COMPLETED, (name, stages)
    return stages[-1].data


def configured_firmware(d, seed=0) -> Firmware:
    fw = Firmware(d, testbed=load_testbed(TESTBEDS_DIR / "inertial_2dof.toml"), seed=seed)
    data = command(fw, 1, 0, "CONNECT", protocol_major=d.version_major, protocol_minor=d.version_minor,
                   dictionary_hash=d.hash, telemetry_port=0, take_over=0)
    token = int.from_bytes(data[:4], "big")
    values = {**ptable.default_values(d), "watchdog_timeout": 10.0}
    for i, key in enumerate(("inertial_c0", "inertial_c1", "inertial_c2")):
        values[key] = full_size_cascade(i)
    values["inertial_c0"][0, :3] *= 5.0               # in-oz per rad/s of rate error
    blob = ptable.pack(d, values)
    seq = 2
    command(fw, seq, token, "PARAM_BEGIN", table_version=1, table_length=len(blob))
    for off in range(0, len(blob), 900):
        seq += 1
        command(fw, seq, token, "PARAM_WRITE", offset=off, data=blob[off:off + 900])
    for name, args in (("PARAM_COMMIT", {"table_crc": zlib.crc32(blob)}),
                       ("SET_MODE", {"mode": "INERTIAL"}), ("ARM", {}),
                       ("FRICTION_COMP", {"enable": 1})):
        seq += 1
        command(fw, seq, token, name, **args)
    fw._bench_token, fw._bench_seq = token, seq
    return fw


def fast_mode(d, seconds: float) -> dict:
    fw = configured_firmware(d)
    fw.run(1200)                                         # compile / warm up
    t = time.perf_counter()
    done = 0
    while done < seconds * RATE:
        fw.run(1200)
        done += 1200
        fw._bench_seq += 1
        command(fw, fw._bench_seq, fw._bench_token, "HEARTBEAT")
    core_x = seconds / (time.perf_counter() - t)
    assert fw.armed, "the benchmark configuration must stay armed (no fault)"

    dev = SimulatedDevice(d, pacing="manual", firmware=configured_firmware(d))
    sink = []
    dev.run_fast(1.0, sink.append)
    nbytes = [0]

    def consume(data: bytes) -> None:                    # the host: counts bytes, heartbeats
        nbytes[0] += len(data)
        fw = dev.firmware
        fw._bench_seq += 1
        command(fw, fw._bench_seq, fw._bench_token, "HEARTBEAT")
    t = time.perf_counter()
    dev.run_fast(seconds, consume)
    frames_x = seconds / (time.perf_counter() - t)
    return {"fast_core_x_realtime": core_x, "fast_frames_x_realtime": frames_x,
            "fast_bytes_per_sim_s": nbytes[0] / seconds}




def paced_mode(d, seconds: float) -> dict:
    sim = SimulatorProcess(pacing="realtime", testbed=str(TESTBEDS_DIR / "inertial_2dof.toml"))
    address = sim.start()
    arrivals: list[tuple[np.ndarray, np.ndarray]] = []
    try:
        client = open_client(d, address)
        try:
            client.subscribe(lambda b: arrivals.append((b["tick"].astype(np.int64), b.host_time.copy()))
                             if b.name == "HIGH_RATE" else None)
            client.connect()
            time.sleep(1.0)                              # settle
            arrivals.clear()
            cpu0, t0 = proc_cpu_seconds(sim.proc.pid), time.monotonic()
            time.sleep(seconds)
            cpu = (proc_cpu_seconds(sim.proc.pid) - cpu0) / (time.monotonic() - t0)
            snap = client.stats.snapshot()
        finally:
            client.close()
    finally:
        sim.stop()
    ticks = np.concatenate([a[0] for a in arrivals])
    host = np.concatenate([a[1] for a in arrivals])
    nominal = ticks / RATE
    offset = np.min(host - nominal)
    late_ms = (host - nominal - offset) * 1e3
    return {"paced_seconds": seconds, "paced_frames": int(len(ticks)),
            "paced_expected_frames": int(round(seconds * RATE)),
            "paced_dropped": snap.dropped,
            "paced_lateness_ms_p50": float(np.percentile(late_ms, 50)),
            "paced_lateness_ms_p99": float(np.percentile(late_ms, 99)),
            "paced_lateness_ms_max": float(late_ms.max()),
            "paced_sim_cpu_percent": 100 * cpu}


def _tick_rate(dev: SimulatedDevice, warmup: float, span: float) -> float:
    """Device ticks per wall second, measured after a short warm-up."""
    time.sleep(warmup)
    t0, k0 = time.monotonic(), dev.firmware.tick
    time.sleep(span)
    t1, k1 = time.monotonic(), dev.firmware.tick
    return (k1 - k0) / (t1 - t0)


def _process_tick_rate(d, speed: float, span: float) -> float:
    """`groundstation sim --speed S`: ticks per wall second over the last `span` s of
    frame arrivals (host time)."""
    lock = threading.Lock()
    ticks: list[np.ndarray] = []
    hosts: list[float] = []

    def on_block(block):
        if block.name == "HIGH_RATE":
            with lock:
                ticks.append(np.asarray(block["tick"], dtype=np.int64))
                hosts.append(float(np.max(block.host_time)))

    with SimulatorProcess(speed=speed) as address:
        client = open_client(d, address)
        try:
            client.subscribe(on_block)
            client.connect()
            time.sleep(span + 0.2)
        finally:
            client.close()
    with lock:
        k = np.concatenate(ticks)
        h = np.array(hosts)
    keep = h >= h[-1] - span
    first = int(np.argmax(keep))
    sizes = np.cumsum([len(t) for t in ticks])
    return float((k[-1] - k[sizes[first] - 1]) / (h[-1] - h[first]))


def speed_factor(d, span: float) -> dict:
    out = {}
    for speed in (1.0, 5.0):
        with SimulatedDevice(d, pacing="realtime", speed=speed) as dev:
            rate = _tick_rate(dev, 0.2, span)
            out[f"speed{speed:g}_ticks_per_s"] = rate
            out[f"speed{speed:g}_ratio"] = rate / (RATE * speed)
            out[f"speed{speed:g}_overruns"] = int(dev.firmware.overruns)
    rate = _process_tick_rate(d, 5.0, span)
    out["process_speed5_ticks_per_s"] = rate
    out["process_speed5_ratio"] = rate / (RATE * 5.0)
    return out


def main() -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--fast-seconds", type=float, default=60.0)
    ap.add_argument("--paced-seconds", type=float, default=60.0)
    ap.add_argument("--speed-seconds", type=float, default=1.0)
    args = ap.parse_args()
    d = load_dictionary()
    res = {"machine": machine()}
    res.update(fast_mode(d, args.fast_seconds))
    print(f"fast mode, 2-DOF inertial, DB-DHM, 3 x 12-section cascades, compensation on "
          f"({args.fast_seconds:g} s simulated):")
    print(f"  core (no encoding)   {res['fast_core_x_realtime']:8.0f} x real time")
    print(f"  frames to consumer   {res['fast_frames_x_realtime']:8.0f} x real time   -> "
          f"{res['fast_frames_x_realtime'] / res['fast_core_x_realtime']:.2f} of the core")
    print(f"  target                     50 x real time   -> frames/target = "
          f"{res['fast_frames_x_realtime'] / 50:.1f}")
    if args.paced_seconds > 0:
        res.update(paced_mode(d, args.paced_seconds))
        print(f"paced mode over {args.paced_seconds:g} s (frames {res['paced_frames']} of "
              f"{res['paced_expected_frames']}, dropped {res['paced_dropped']}):")
        print(f"  lateness p50 {res['paced_lateness_ms_p50']:.2f} ms  p99 "
              f"{res['paced_lateness_ms_p99']:.2f} ms  max {res['paced_lateness_ms_max']:.2f} ms"
              f"   (target p99 < 5 ms)")
        print(f"  simulator CPU {res['paced_sim_cpu_percent']:.0f} % of one core")
    if args.speed_seconds > 0:
        res.update(speed_factor(d, args.speed_seconds))
        print(f"speed factor (paced, {args.speed_seconds:g} s each; tolerance 0.85-1.1, process 0.8-1.2):")
        for speed in (1, 5):
            ratio = res[f"speed{speed}_ratio"]
            print(f"  speed {speed}: {res[f'speed{speed}_ticks_per_s']:8.0f} ticks/s = {ratio:.3f} x "
                  f"{RATE * speed:.0f}, overruns {res[f'speed{speed}_overruns']}"
                  f"{'' if 0.85 <= ratio <= 1.1 else '   OUTSIDE TOLERANCE'}")
        ratio = res["process_speed5_ratio"]
        print(f"  sim --speed 5 (process): {res['process_speed5_ticks_per_s']:8.0f} ticks/s = "
              f"{ratio:.3f} x {RATE * 5:.0f}{'' if 0.8 <= ratio <= 1.2 else '   OUTSIDE TOLERANCE'}")
    save("sim", res)
    return res


if __name__ == "__main__":
    main()
