"""How fast a campaign runs on the simulated testbed with --fast, recording on.

Side by side, in one run:

  ours       Testbed(fast=True): relative Design #2 uploaded, a 60 s band-limited current
             profile played open loop and a 60 s dwell, both recorded - device seconds
             per wall second
  baseline   the real-time simulator (what a rig, or `--device sim` without --fast, takes:
             1 device second per wall second, by definition)
  limit      the simulator alone in fast mode, every frame encoded, nothing sent, received
             or recorded (the same engine and firmware: bench_sim.py's figure)

Run: .venv/bin/python benchmarks/bench_campaign.py
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from common import machine, save

from groundstation import Testbed
from groundstation.dictionary import load_dictionary
from groundstation.sim.device import SimulatedDevice
from groundstation.sim.firmware import Firmware
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

ROOT = Path(__file__).resolve().parent.parent
PROFILE = ROOT / "profiles" / "waveforms" / "sysid_coarse_noise_0p02A.toml"


def simulator_alone(seconds: float) -> float:
    """Device seconds per wall second of the engine + firmware + frame encoding."""
    d = load_dictionary()
    fw = Firmware(d, seed=0, testbed=load_testbed(TESTBEDS_DIR / "relative_2dof.toml"))
    dev = SimulatedDevice(d, pacing="manual", firmware=fw)
    n = int(seconds * d.control_rate_hz)
    dev._simulate(1200)                            # compile and warm up
    t0 = time.perf_counter()
    done = 0
    while done < n:
        dev._simulate(600)
        done += 600
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    print(f"campaign benchmark - {machine()}")
    with tempfile.TemporaryDirectory() as tmp:
        with Testbed("sim", testbed=TESTBEDS_DIR / "relative_2dof.toml", fast=True,
                     log_folder=tmp, history=Path(tmp) / "history") as tb:
            tb.upload_design(ROOT / "profiles" / "controllers" / "relative_design2.toml")
            tb.start_recording("bench")
            t0 = time.perf_counter()
            result = tb.play(PROFILE, mode="OPEN_LOOP")
            t_play = time.perf_counter() - t0
            t0 = time.perf_counter()
            tb.dwell(60.0)
            t_dwell = time.perf_counter() - t0
            rec = tb.stop_recording()
    device_play = result.sample_count / 1200.0
    ours_play, ours_dwell = device_play / t_play, 60.0 / t_dwell
    limit = simulator_alone(60.0)
    res = {"machine": machine(), "profile_device_s": device_play, "profile_wall_s": t_play,
           "dwell_wall_s": t_dwell, "ours_play_x_realtime": ours_play,
           "ours_dwell_x_realtime": ours_dwell, "simulator_alone_x_realtime": limit,
           "recorded_frames": rec["frames"], "dropped": rec["dropped"],
           "discarded_blocks": rec["discarded_blocks"]}
    print(f"\nfast campaign on the simulated testbed, recording on ({rec['frames']} frames, "
          f"{rec['dropped']} dropped, {rec['discarded_blocks']} blocks discarded):")
    print(f"  ours, playing a {device_play:.0f} s profile (upload, arm, play, disarm): "
          f"{t_play:5.2f} s wall = {ours_play:5.1f}x real time")
    print(f"  ours, a 60 s dwell:                                        {t_dwell:5.2f} s wall = "
          f"{ours_dwell:5.1f}x real time")
    print("  baseline, real-time simulator or a rig:                             1.0x real time")
    print(f"  limit, the simulator alone (nothing sent or recorded):          {limit:6.1f}x real time "
          f"(ours = {ours_dwell / limit:.2f} of it)")
    print(f"written to {save('campaign', res)}")


if __name__ == "__main__":
    main()
