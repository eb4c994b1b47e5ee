"""The window benchmark's reports: one run's table against the targets (`print_table`),
and `bench_gui.py --before REV [--after REV]`, two trees side by side (`before_after`).

For the latter each side runs bench_gui.py (this checkout's script) in a fresh process with its own
tree's package on PYTHONPATH, the sides alternating round by round so the machine's
drift falls on both alike; medians of each figure, before and after, steady and burst.
Qt-free: the runs are child processes.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path


#: the issue's targets for the window
TARGET_FPS = 30.0
TARGET_P99_MS = 50.0


def fmt(v, spec=".1f") -> str:
    return "-" if v is None else format(v, spec)


def verdict(ok: bool | None) -> str:
    return "" if ok is None else ("ok" if ok else "MISSED")


def print_table(res: dict) -> None:
    s, b = res["steady"], res["burst"]
    rows = [
        ("chart fps mean / p5 / min",
         lambda r: f"{fmt(r['fps_mean'])} / {fmt(r['fps_p5'], '.0f')} / {fmt(r['fps_min'], '.0f')}",
         ">= 30", lambda r: r["fps_mean"] is not None and r["fps_mean"] >= TARGET_FPS),
        ("refresh() ms p50 / p99", lambda r: f"{fmt(r['refresh_ms_p50'])} / {fmt(r['refresh_ms_p99'])}",
         "", None),
        ("refresh() CPU ms p50 / p99",
         lambda r: f"{fmt(r['refresh_cpu_ms_p50'])} / {fmt(r['refresh_cpu_ms_p99'])}", "", None),
        ("loop latency ms p50 / p99", lambda r: f"{fmt(r['latency_ms_p50'])} / {fmt(r['latency_ms_p99'])}",
         "p99 < 50", lambda r: r["latency_ms_p99"] is not None and r["latency_ms_p99"] < TARGET_P99_MS),
        ("loop latency ms max", lambda r: fmt(r["latency_ms_max"]), "", None),
        ("GUI thread CPU ms per frame", lambda r: fmt(r["gui_thread_cpu_ms_per_frame"]), "", None),
        ("GUI process / GUI thread CPU %",
         lambda r: f"{fmt(r['gui_cpu_percent'], '.0f')} / {fmt(r['gui_thread_cpu_percent'], '.0f')}",
         "", None),
        ("simulator CPU %", lambda r: fmt(r["sim_cpu_percent"], ".0f"), "", None),
        ("log writer CPU %", lambda r: fmt(r["writer_cpu_percent"], ".0f"), "", None),
        ("HIGH_RATE received / expected",
         lambda r: f"{r['high_rate_received']} / {fmt(r['high_rate_expected'], 'd')}", "", None),
        ("ticks per wall s (target)",
         lambda r: f"{fmt(r['ticks_per_wall_s'], '.0f')} ({r['ticks_per_wall_s_target']:.0f})", "", None),
        ("dropped: link / tick gaps", lambda r: f"{r['link_dropped']} / {r['tick_gaps']}",
         "0", lambda r: r["link_dropped"] == 0 and r["tick_gaps"] == 0),
        ("dropped: recorder blocks", lambda r: str(r["recorder_discarded_blocks"]), "0",
         lambda r: r["recorder_discarded_blocks"] == 0),
        ("simulator overruns", lambda r: fmt(r["sim_overruns"], "d"), "", None),
        ("other processes CPU %", lambda r: fmt(r["other_processes_cpu_percent"], ".0f"), "", None),
    ]
    head = (f"steady {s['seconds'] / 60:.1f} min @1x", f"burst {b['seconds']:.0f} s @{b['speed']:g}x")
    print(f"\nGUI benchmark - {res['machine']}")
    print(f"window {res['window'][0]}x{res['window'][1]}, 8 channels on 4 plots, "
          f"{res['window_s']:g} s window, recording on\n")
    print(f"{'':31} {head[0]:>20} {head[1]:>20}  {'target':>9}")
    for label, cell, target, check in rows:
        marks = ""
        if check is not None:
            marks = "  " + " / ".join(verdict(check(r)) for r in (s, b))
        print(f"{label:31} {cell(s):>20} {cell(b):>20}  {target:>9}{marks}")
    busy = max((r["other_processes_cpu_percent"] or 0.0) for r in (s, b))
    if busy > 25.0:
        print(f"\nWARNING: other processes used up to {busy:.0f} % CPU (100 % = one core, "
              f"{s['machine_cores']} cores) during the run: the figures are not those of a "
              f"quiet machine.")
    for r, name in ((s, "steady"), (b, "burst")):
        if r.get("client_changes"):
            print(f"\nWARNING: the session replaced its client {r['client_changes']} time(s) during "
                  f"the {name} phase (a reconnect): its link figures are the last client's.")
    rec = res["recording"]
    print(f"\nrecording: {rec['state']}, {rec['frames']} frames, "
          f"{(rec['bytes'] or 0) / 1e6:.1f} MB, discarded blocks {rec['discarded_blocks']}")


COMPARED = [   # (label, key, format)
    ("chart fps mean", "fps_mean", ".1f"),
    ("refresh() CPU ms p50", "refresh_cpu_ms_p50", ".2f"),
    ("GUI thread CPU ms per frame", "gui_thread_cpu_ms_per_frame", ".2f"),
    ("GUI process CPU % of a core", "gui_cpu_percent", ".0f"),
    ("GUI thread CPU % of a core", "gui_thread_cpu_percent", ".0f"),
    ("loop latency ms p50", "latency_ms_p50", ".1f"),
    ("loop latency ms p99", "latency_ms_p99", ".1f"),
    ("loop latency ms max", "latency_ms_max", ".1f"),
    ("HIGH_RATE dropped (link + tick gaps)", "dropped", "d"),
    ("recorder blocks discarded", "recorder_discarded_blocks", "d"),
    ("ticks per wall s", "ticks_per_wall_s", ".0f"),
    ("other processes CPU %", "other_processes_cpu_percent", ".0f"),
]


def _median(runs: list[dict], phase: str, key: str):
    vals = []
    for r in runs:
        ph = r[phase]
        v = ph["link_dropped"] + ph["tick_gaps"] if key == "dropped" else ph.get(key)
        if v is not None:
            vals.append(v)
    return statistics.median(vals) if vals else None


def before_after(args, bench: Path) -> int:
    """Run `bench` (bench_gui.py) for REV (a temporary worktree) and for this checkout
    (or --after REV), alternately, each in a fresh process; print the medians side by side."""
    root = bench.parent.parent
    tmp = Path(tempfile.mkdtemp(prefix="gs-bench-gui-ba-"))
    tree = tmp / "before"
    subprocess.run(["git", "worktree", "add", "--detach", str(tree), args.before], cwd=root,
                   check=True, capture_output=True)
    after_tree = root
    if args.after:                  # a committed revision, without uncommitted work in the checkout
        after_tree = tmp / "after"
        subprocess.run(["git", "worktree", "add", "--detach", str(after_tree), args.after],
                       cwd=root, check=True, capture_output=True)
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    loads = []
    try:
        for k in range(args.rounds):
            order = ("before", "after") if k % 2 == 0 else ("after", "before")
            for side in order:
                src = tree if side == "before" else after_tree
                out = tmp / f"{side}_{k}.json"
                cmd = [sys.executable, str(bench), "--minutes", str(args.minutes),
                       "--burst-seconds", str(args.burst_seconds), "--warmup-seconds",
                       str(args.warmup_seconds), "--no-progress", "--out", str(out)]
                env = dict(os.environ, PYTHONPATH=str(src), QT_QPA_PLATFORM="offscreen")
                loads.append(os.getloadavg())
                name = args.before if side == "before" else (args.after or "this checkout")
                print(f"round {k + 1}/{args.rounds}: {side} ({name})", flush=True)
                done = subprocess.run(cmd, cwd=src, env=env, capture_output=True, text=True)
                if done.returncode != 0 or not out.exists():
                    raise SystemExit(f"{side} run failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
                res = json.loads(out.read_text())
                if not res["package"].startswith(str(src)):
                    raise SystemExit(f"{side} imported {res['package']}, not {src}")
                runs[side].append(res)
    finally:
        for t in {tree, after_tree} - {root}:
            subprocess.run(["git", "worktree", "remove", "--force", str(t)], cwd=root,
                           capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)
    loads.append(os.getloadavg())
    one = [l[0] for l in loads]
    print(f"\nGUI benchmark, before ({args.before}) and after ({args.after or 'this checkout'}), median of {args.rounds} runs each, "
          f"alternating - {runs['after'][0]['machine']}")
    print(f"steady {args.minutes:g} min at 1200 Hz, burst {args.burst_seconds:g} s at 10x; "
          f"1-min load average at the starts of the runs {min(one):.1f} to {max(one):.1f}\n")
    print(f"{'':40} {'before':>9} {'after':>9}   {'before':>9} {'after':>9}")
    print(f"{'':40} {'steady':>9} {'steady':>9}   {'burst':>9} {'burst':>9}")
    table = {}
    for label, key, spec in COMPARED:
        cells = [_median(runs[side], phase, key) for phase in ("steady", "burst")
                 for side in ("before", "after")]
        table[label] = dict(zip(("steady_before", "steady_after", "burst_before", "burst_after"), cells))
        txt = [fmt(c if spec != "d" or c is None else int(c), spec) for c in cells]
        print(f"{label:40} {txt[0]:>9} {txt[1]:>9}   {txt[2]:>9} {txt[3]:>9}")
    out = Path(args.out).with_name("gui_before_after.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"before": args.before, "after": args.after, "rounds": args.rounds,
                               "minutes": args.minutes, "burst_seconds": args.burst_seconds,
                               "loadavg_at_starts": loads, "medians": table, "runs": runs},
                              indent=2) + "\n")
    print(f"\nwritten to {out}")
    return 0
