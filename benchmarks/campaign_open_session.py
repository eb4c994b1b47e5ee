"""A campaign run from an open session: `bench_campaign.py --open-session N CAMPAIGN`.

What a user gets who runs campaigns one after another in a session already open on the
fast simulator - a notebook or script holding a `Testbed("sim", fast=True)`, a sweep
driver calling `CampaignRunner(...).run()` per configuration - rather than one console
command per campaign, which pays the interpreter, the imports and the simulator child
every time (campaign_whole.py measures that).  In a process of its own:

  open         the session: the simulator child started, connected, a log writer
               started ahead (as `campaign run` does)
  run k        campaign run k from the open session: its steps, wall time, and the
               device seconds of the logs it wrote (HIGH_RATE frames at 1200 Hz)
  close        the session's close, which waits for the logs still being compressed
               behind the runs (logs/compress_behind.py)

A run's figure does not wait for its logs' compression (that goes on behind the next
run, and the close waits for what is left): the close is reported beside it, and the
whole session's figure - every run's device seconds over open + runs + close - too.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _session(campaign: Path, runs: int, folder: Path) -> dict:
    """Runs in the child process (see main)."""
    from groundstation import Testbed
    from groundstation.campaign import CampaignRunner, load_campaign
    from groundstation.logs.reader import LogReader

    t0 = time.perf_counter()
    c = load_campaign(campaign)
    tb = Testbed("sim", testbed=c.testbed, fast=True, log_folder=folder, echo=lambda text: None)
    tb.recording.prepare_ahead()       # as `campaign run` does: the writer starts with the device
    tb.__enter__()
    out = {"open_s": time.perf_counter() - t0, "runs": []}
    for _ in range(runs):
        before = len(tb.recordings)
        t = time.perf_counter()
        report = CampaignRunner(c, tb).run()
        wall = time.perf_counter() - t
        if report.status != "completed":
            raise SystemExit(report.summary())
        frames = 0
        for rec in tb.recordings[before:]:
            for path in rec["files"]:
                with LogReader(path) as log:
                    frames += log.n_frames("HIGH_RATE")
        out["runs"].append({"wall_s": wall, "device_s": frames / 1200.0})
    t = time.perf_counter()
    tb.__exit__(None, None, None)
    out["close_s"] = time.perf_counter() - t
    return out


def open_session(campaign: Path, runs: int) -> dict:
    """`runs` runs of `campaign` in one session, in a fresh process and folder."""
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.run([sys.executable, __file__, str(campaign), str(runs), tmp],
                              cwd=tmp, capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    if proc.returncode != 0:
        raise SystemExit(f"the open-session run failed:\n{proc.stdout[-2000:]}{proc.stderr[-3000:]}")
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    r["campaign"] = campaign.stem
    device = sum(x["device_s"] for x in r["runs"])
    r["session_wall_s"] = r["open_s"] + sum(x["wall_s"] for x in r["runs"]) + r["close_s"]
    r["session_device_per_wall"] = device / r["session_wall_s"]
    for x in r["runs"]:
        x["device_per_wall"] = x["device_s"] / x["wall_s"]
    return r


def print_open_session(r: dict) -> None:
    print(f"  {r['campaign']} from an open session: opened in {r['open_s']:.2f} s")
    for k, x in enumerate(r["runs"], 1):
        print(f"      run {k}: {x['device_s']:7.1f} device s in {x['wall_s']:.3f} wall s = "
              f"{x['device_per_wall']:6.1f}x real time")
    print(f"      close (the compression behind the runs finished): {r['close_s']:.2f} s")
    print(f"      the whole session, open to close: {r['session_device_per_wall']:.1f}x real time")


if __name__ == "__main__":
    print(json.dumps(_session(Path(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3]))))
