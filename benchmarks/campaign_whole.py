"""Where a whole campaign's wall time goes: `bench_campaign.py --whole CAMPAIGN`.

The campaign runs as a user runs it - `groundstation campaign run CAMPAIGN --device sim
--fast`, through the console script, as a process of its own, in a fresh folder - and
its wall time is split:

  start        from the process's launch to the campaign's first step (interpreter and
               imports, the simulator child, connecting)
  <action>     the steps, summed per action kind (start_recording, upload_design, dwell,
               play, settle, stop_recording, ...), from the report's own step timings
  after steps  from the last step's end to the process's exit (the report, the analysis
               unless --no-analysis, closing)

and its CPU time per process: the campaign's own process, the simulator child and the
log writer processes, sampled from /proc while they live (a process's last sample before
it exits is its figure: the few ms after it are missed).  Device seconds are the
HIGH_RATE frames of every log the campaign wrote, at the rig's 1200 Hz.  The simulator
alone (every frame encoded, nothing sent or recorded) is measured in the same run, just
before, as the limit.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter, defaultdict
from pathlib import Path

from common import proc_cpu_seconds

ROOT = Path(__file__).resolve().parent.parent
SAMPLE_S = 0.05          # how often the process tree's CPU is read


def _cpu_and_kind(pid: int) -> tuple[float, str] | None:
    cpu = proc_cpu_seconds(pid)
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return None
    if cpu is None:
        return None
    if "resource_tracker" in cmd:
        kind = "multiprocessing resource tracker"
    elif "compress_behind" in cmd:
        kind = "log compression behind the runs"
    elif "spawn_main" in cmd:
        kind = "log writer (spawned)"
    elif "campaign run" in cmd:
        kind = "campaign process"
    elif "stepped" in cmd or " sim" in cmd:
        kind = "simulator child"
    else:
        kind = "other: " + cmd.split(" ")[0].rsplit("/", 1)[-1]
    return cpu, kind


def _children(pid: int) -> list[int]:
    out = []
    # a process that ended meanwhile has no children to list: none
    with contextlib.suppress(OSError):
        for task in Path(f"/proc/{pid}/task").iterdir():
            out += [int(p) for p in (task / "children").read_text().split()]
    return out


class TreeSampler:
    """The last-seen CPU seconds of every process under `root` (itself included)."""

    def __init__(self, root: int) -> None:
        self.root = root
        self.cpu: dict[int, tuple[float, str]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="tree-sampler", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            todo, seen = [self.root], set()
            while todo:
                pid = todo.pop()
                if pid in seen:
                    continue
                seen.add(pid)
                got = _cpu_and_kind(pid)
                if got is not None:
                    # a zombie's cmdline is empty: the kind is the one seen while it lived
                    kind = self.cpu[pid][1] if pid in self.cpu and got[1].startswith("other: ") else got[1]
                    self.cpu[pid] = (got[0], kind)
                todo += _children(pid)
            self._stop.wait(SAMPLE_S)

    def stop(self) -> dict[str, float]:
        self._stop.set()
        self._thread.join()
        per_kind: Counter = Counter()
        counts: Counter = Counter()
        for cpu, kind in self.cpu.values():
            per_kind[kind] += cpu
            counts[kind] += 1
        return {f"{k} (x{counts[k]})": v for k, v in per_kind.items()}


def _console_script(tree: Path, folder: Path) -> Path:
    """The `groundstation` script as pip writes it for `tree` (its pyproject.toml's entry
    point, imported at the top), so the campaign starts as a user's does.  Not `python
    -m groundstation`: multiprocessing's spawn runs the parent's main script again in
    each log writer, but skips a package's __main__ - so the script's imports are a cost
    of every writer that -m would hide."""
    import tomllib
    entry = tomllib.loads((tree / "pyproject.toml").read_text())["project"]["scripts"]["groundstation"]
    module, function = entry.split(":")
    script = folder / "groundstation-script.py"
    script.write_text(f"import sys\nfrom {module} import {function}\n"
                      f"if __name__ == '__main__':\n    sys.exit({function}())\n")
    return script


def _device_seconds(folder: Path) -> tuple[float, int]:
    from groundstation.logs.reader import LogReader
    frames, logs = 0, 0
    for path in sorted(folder.rglob("*.h5")):
        with LogReader(str(path)) as log:
            frames += log.n_frames("HIGH_RATE")
            logs += 1
    return frames / 1200.0, logs


def whole(campaign: Path, *, analysis: bool, tree: Path | None = None,
          python: str | None = None) -> dict:
    """One whole campaign, split as the module says.  `tree`: run the package of another
    checkout (a `git worktree` of an earlier commit: before and after in one run);
    `python`: with that interpreter (another virtualenv), else this one."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
        campaign = tree / campaign.relative_to(ROOT)
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [python or sys.executable, str(_console_script(tree or ROOT, Path(tmp))), "campaign", "run",
               str(campaign), "--device", "sim", "--fast"] + ([] if analysis else ["--no-analysis"])
        t_launch = time.time()
        w0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, env=env)
        sampler = TreeSampler(proc.pid)
        output, _ = proc.communicate()
        wall = time.perf_counter() - w0
        t_exit = t_launch + wall
        cpu = sampler.stop()
        if proc.returncode != 0:
            raise SystemExit(f"campaign run exited {proc.returncode}:\n{output[-3000:]}")
        report_path = next(Path(tmp).rglob("report.json"))
        report = json.loads(report_path.read_text())
        per_action: dict[str, float] = defaultdict(float)
        counts: Counter = Counter()
        for step in report["steps"]:
            action = step["label"].rsplit(": ", 1)[-1]
            per_action[action] += step["seconds"] or 0.0
            counts[action] += 1
        steps_total = sum(per_action.values())
        device_s, logs = _device_seconds(Path(tmp))
    split = {"start": report["started"] - t_launch}
    split.update({f"{a} (x{counts[a]})": s for a, s in sorted(per_action.items(), key=lambda kv: -kv[1])})
    # between the runner's start and end, what no step accounts for (the runner's own work)
    split["between steps"] = max(0.0, (report["finished"] - report["started"]) - steps_total)
    split["after steps"] = t_exit - report["finished"]
    return {"campaign": campaign.stem, "tree": str(tree or ROOT), "analysis": analysis,
            "wall_s": wall, "device_s": device_s,
            "logs": logs, "device_per_wall": device_s / wall, "split_s": split, "cpu_s": cpu}


def print_whole(r: dict, limit_x: float) -> None:
    print(f"  {r['campaign']} ({'with' if r['analysis'] else 'no'} analysis, {r['tree']}): {r['logs']} logs, "
          f"{r['device_s']:.1f} device s in {r['wall_s']:.2f} wall s = {r['device_per_wall']:.1f}x "
          f"real time, {r['device_per_wall'] / limit_x:.2f} of the simulator alone ({limit_x:.1f}x)")
    for name, s in r["split_s"].items():
        print(f"      {name:28s} {s:8.2f} s  {100 * s / r['wall_s']:5.1f} %")
    print("    CPU per process:")
    for name, s in sorted(r["cpu_s"].items(), key=lambda kv: -kv[1]):
        print(f"      {name:28s} {s:8.2f} s")
