"""How long identifying a rig takes, and how close `groundstation identify` comes, on two
hidden rigs recorded through the shipped identification campaigns.

Each hidden rig is a shipped testbed file with its physical parameters moved away from
the reference (the issue's acceptance test, at full length): inertias, the flexure's
stiffness and damping, the fine motor's torque constant, the bearing's viscous b_f and
Coulomb torque T_c, the gyro's delay (inertial rig) and, on the relative rig, a slope
table of another shape written beside it.  Nobody tells `identify` about them:

  1. record    every shipped identification campaign that applies to the rig's kind is
               run on the hidden file with the fast simulator, through the command a
               lab types: `groundstation campaign run CAMPAIGN --testbed HIDDEN.toml
               --fast --no-analysis` (a subprocess; wall time measured around it, device
               time read from its logs' HIGH_RATE device clock)
  2. identify  `groundstation identify REPORT.json... --testbed BASE.toml --out RIG.toml
               --json FILE`, starting from the shipped (reference) file (a subprocess;
               wall time)
  3. compare   every parameter the JSON lists against the hidden file: error %, whether
               the truth is inside the 95 % interval, the status identify gave it; the
               identified slope table (if one is written) against the hidden one

Which campaigns apply: open_loop_sysid (open-loop current noise) runs on both kinds;
friction_hysteresis_2dof and steady_state_friction upload relative Design #2 and play
position references in RELATIVE mode, which the upload gate refuses on an inertial
rig, so the inertial rig gets only open_loop_sysid (its friction stays unidentified).

The baseline is the device time itself (a real rig, or the real-time simulator, takes
one wall second per device second); the ratio device / wall is printed beside it.
Parameters are compared generically: whatever identify lists ('section.key' names, and
'friction.slope_table f(X)' points) is looked up in the hidden file.

Run: .venv/bin/python benchmarks/bench_identify.py [--max-step-seconds S] [--rigs relative,inertial]
     [--keep DIR]
(--max-step-seconds caps every dwell and profile, as `campaign run` does: a shorter smoke
run with larger errors; the hysteresis triangles need their full 80 s and 400 s.)
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common import machine, save

ROOT = Path(__file__).resolve().parent.parent
TESTBEDS = ROOT / "profiles" / "testbeds"
CAMPAIGNS = ROOT / "profiles" / "campaigns"
SHIPPED_TABLE = ROOT / "profiles" / "friction_slope_lut.csv"
GS = [sys.executable, "-m", "groundstation"]
#: what "within a few percent" is taken to mean when rows are flagged (not asserted)
FEW_PERCENT = 3.0


@dataclass(frozen=True)
class Rig:
    base: str                                   # shipped file under profiles/testbeds
    scale: dict[str, float]                     # 'section.key' -> factor
    add: dict[str, float] = field(default_factory=dict)   # 'section.key' -> offset
    bent_table: bool = False                    # a slope table of another shape
    campaigns: tuple[str, ...] = ("open_loop_sysid",)


RIGS = {
    "relative": Rig("relative_2dof.toml",
                    {"mechanics.J1": 1.08, "mechanics.J2": 0.96,
                     "mechanics.flexure_stiffness": 0.88, "mechanics.flexure_damping": 2.0,
                     "motor_fine.torque_constant": 0.95, "mechanics.bearing_viscous": 1.5,
                     "friction.coulomb_torque": 1.2},
                    bent_table=True,
                    campaigns=("open_loop_sysid", "friction_hysteresis_2dof",
                               "steady_state_friction")),
    "inertial": Rig("inertial_2dof.toml",
                    {"mechanics.J1": 1.05, "mechanics.J2": 0.93,
                     "mechanics.flexure_stiffness": 1.10, "mechanics.flexure_damping": 1.5,
                     "motor_fine.torque_constant": 1.04, "mechanics.bearing_viscous": 1.5,
                     "friction.coulomb_torque": 1.2},
                    add={"sensors.gyro_delay": 0.0003}),
}


# ---------------------------------------------------------------------- pure helpers
def bent_slope_table(x, f, *, scale: float = 0.9, power: float = 0.85) -> tuple[np.ndarray, np.ndarray]:
    """Another valid DB-DHM table from (x, f): f evaluated along x' = 2 (x/2)^power (an
    increasing map of [0, 2] onto itself, so the result stays non-increasing with
    f(2) = 0; power < 1 makes the steep part after a reversal shorter), times `scale`."""
    x = np.asarray(x, dtype=float)
    f = np.asarray(f, dtype=float)
    bent = scale * np.interp(2.0 * (x / 2.0) ** power, x, f)
    bent[-1] = 0.0 if x[-1] == 2.0 else bent[-1]
    return x, bent


def slope_table_csv(x, f, comment: str) -> str:
    lines = [f"# {c}" for c in comment.splitlines()] + ["x,slope_ratio"]
    lines += [f"{a:.6g},{b:.6g}" for a, b in zip(x, f)]
    return "\n".join(lines) + "\n"


def hidden_text(base_text: str, base_dir: Path, rig: Rig, slope_table: Path | None,
                name: str) -> str:
    """The base file's text with the rig's moves applied, its name changed, and its slope
    table named by absolute path (`slope_table` if given, else the base's own)."""
    out, section = [], ""
    for line in base_text.splitlines():
        head = re.match(r"^\s*\[([A-Za-z_0-9]+)\]", line)
        if head:
            section = head.group(1)
        m = re.match(r"^(\s*)([A-Za-z_0-9]+)(\s*=\s*)([^#\s]+)(.*)$", line)
        if m and not head:
            key = f"{section}.{m.group(2)}"
            if key in rig.scale or key in rig.add:
                value = float(m.group(4)) * rig.scale.get(key, 1.0) + rig.add.get(key, 0.0)
                line = f"{m.group(1)}{m.group(2)}{m.group(3)}{value!r}{m.group(5)}"
            elif key == "testbed.name":
                line = f"name = {json.dumps(name)}"
            elif key == "friction.slope_table":
                shipped = tomllib.loads(line)["slope_table"]
                where = slope_table or (base_dir / shipped).resolve()
                line = f"slope_table = {json.dumps(where.as_posix())}"
        out.append(line)
    return "\n".join(out) + "\n"


def _table_of(doc: dict, folder: Path) -> tuple[np.ndarray, np.ndarray] | None:
    from groundstation.plant.slope_table import load_slope_table
    name = doc.get("friction", {}).get("slope_table")
    if not name:
        return None
    return load_slope_table((folder / name).resolve())


def truth_of(name: str, hidden: dict, hidden_dir: Path) -> float | None:
    """The hidden rig's value of a parameter identify lists, or None when the file has no
    such number: 'section.key' is looked up; 'friction.slope_table f(X)' is the hidden
    table at X."""
    m = re.match(r"^friction\.slope_table f\(([-+0-9.e]+)\)$", name)
    if m:
        table = _table_of(hidden, hidden_dir)
        return None if table is None else float(np.interp(float(m.group(1)), *table))
    section, _, key = name.partition(".")
    value = hidden.get(section, {}).get(key)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def compare(report: dict, hidden: dict, hidden_dir: Path) -> list[dict]:
    """One row per parameter of identify's JSON: truth, identified value, error %, the
    base's error % (how far the start was), inside the 95 % interval (None: no interval)."""
    rows = []
    for p in report.get("parameters", []):
        truth = truth_of(p["name"], hidden, hidden_dir)
        value, base, ci = p.get("value"), p.get("base"), p.get("ci95")
        err = base_err = inside = None
        if truth is not None and isinstance(value, (int, float)) and truth != 0:
            err = 100.0 * (value / truth - 1.0)
            base_err = 100.0 * (base / truth - 1.0) if isinstance(base, (int, float)) else None
            inside = bool(ci[0] <= truth <= ci[1]) if ci else None
        rows.append({"name": p["name"], "units": p.get("units", ""), "truth": truth,
                     "base": base, "value": value, "error_pct": err, "base_error_pct": base_err,
                     "ci95": ci, "inside_ci": inside, "status": p.get("status", "")})
    return rows


def unreported_rows(moved, rows: list[dict], hidden: dict, base: dict, rig: dict | None) -> list[dict]:
    """Rows for the parameters the hidden rig moved that identify's JSON does not list:
    the value RIG.toml carries for them (the base's, unless identify wrote it)."""
    listed = {r["name"] for r in rows}
    out = []
    for name in moved:
        if name in listed:
            continue
        section, _, key = name.partition(".")
        truth, b = hidden[section][key], base[section][key]
        value = (rig or {}).get(section, {}).get(key) if rig is not None else None
        err = None if value is None else 100.0 * (value / truth - 1.0)
        out.append({"name": name, "units": "", "truth": truth, "base": b, "value": value,
                    "error_pct": err, "base_error_pct": 100.0 * (b / truth - 1.0), "ci95": None,
                    "inside_ci": None, "status": "not in identify's report"})
    return out


def table_deviation(rig_file: Path, base_file: Path, hidden: dict, hidden_dir: Path) -> dict | None:
    """The identified slope table (the one RIG.toml names, if not the base's) against the
    hidden one on the hidden table's points: max |f_id - f_true| as % of f_true(0), and
    the same for the base's table (None: no table identified)."""
    if not rig_file.is_file():
        return None
    rig = tomllib.loads(rig_file.read_text())
    base = tomllib.loads(base_file.read_text())
    from groundstation.plant.slope_table import SlopeTableError
    try:
        ident, start, truth = (_table_of(rig, rig_file.parent), _table_of(base, base_file.parent),
                               _table_of(hidden, hidden_dir))
    except SlopeTableError as exc:
        return {"error": str(exc)}
    if ident is None or truth is None or start is None:
        return None
    if ident[0].shape == start[0].shape and np.allclose(ident[0], start[0]) \
            and np.allclose(ident[1], start[1]):
        return None                              # the base's table kept: nothing identified
    x = truth[0]
    scale = 100.0 / truth[1][0]
    dev = np.interp(x, *ident) - truth[1]
    return {"points": x.tolist(), "truth": truth[1].tolist(),
            "identified": np.interp(x, *ident).tolist(),
            "max_deviation_pct_of_f0": float(np.max(np.abs(dev)) * scale),
            "base_max_deviation_pct_of_f0": float(np.max(np.abs(np.interp(x, *start) - truth[1]))
                                                  * scale)}


def summary(rows: list[dict]) -> dict:
    """Max |error| and CI coverage over the identified parameters with a known truth."""
    ident = [r for r in rows if r["status"] == "identified" and r["error_pct"] is not None]
    with_ci = [r for r in ident if r["inside_ci"] is not None]
    worst = max(ident, key=lambda r: abs(r["error_pct"]), default=None)
    return {"identified": len(ident), "max_abs_error_pct": abs(worst["error_pct"]) if worst else None,
            "worst": worst["name"] if worst else None,
            "inside_ci": sum(r["inside_ci"] for r in with_ci), "with_ci": len(with_ci),
            "beyond_few_percent": [r["name"] for r in ident if abs(r["error_pct"]) > FEW_PERCENT],
            "outside_ci": [r["name"] for r in with_ci if not r["inside_ci"]],
            # moved away from the base, and left there (held, or not reported)
            "moved_not_identified": [r["name"] for r in rows if r["status"] != "identified"
                                     and r["base_error_pct"] is not None
                                     and abs(r["base_error_pct"]) > 1e-9]}


def _g(x) -> str:
    return "-" if x is None else f"{x:.5g}"


def format_rows(rows: list[dict]) -> str:
    out = [f"    {'parameter':30s} {'truth':>10s} {'base':>10s} {'identified':>10s} "
           f"{'error':>8s} {'base err':>8s}  {'95 % interval':25s} {'in CI':5s} status"]
    for r in rows:
        err = "-" if r["error_pct"] is None else f"{r['error_pct']:+.2f}%"
        berr = "-" if r["base_error_pct"] is None else f"{r['base_error_pct']:+.1f}%"
        ci = f"[{_g(r['ci95'][0])}, {_g(r['ci95'][1])}]" if r["ci95"] else "-"
        inside = {True: "yes", False: "NO", None: "-"}[r["inside_ci"]]
        flag = " <-- beyond 3 %" if (r["status"] == "identified" and r["error_pct"] is not None
                                     and abs(r["error_pct"]) > FEW_PERCENT) else ""
        out.append(f"    {r['name']:30s} {_g(r['truth']):>10s} {_g(r['base']):>10s} "
                   f"{_g(r['value']):>10s} {err:>8s} {berr:>8s}  {ci:25s} {inside:5s} "
                   f"{r['status']}{flag}")
    return "\n".join(out)


# ---------------------------------------------------------------------- the runs
def cpu_model() -> str:
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:                     # not Linux: the model is only a label in the output
        lines = []
    models = [line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")]
    return models[0] if models else "CPU model unknown"


def device_seconds(report_path: Path) -> float:
    """Device time the campaign's logs cover (HIGH_RATE device clock, first to last frame)."""
    from groundstation.logs.reader import LogReader
    total = 0.0
    for rec in json.loads(report_path.read_text()).get("recordings", []):
        for f in rec.get("files", []):
            path = Path(f) if Path(f).is_absolute() else report_path.parent / f
            with LogReader(path) as r:
                n = r.n_frames("HIGH_RATE")
                if n:
                    t = r.dataset("telemetry/HIGH_RATE/device_time")
                    total += float(t[n - 1] - t[0]) + 1.0 / r.tick_rate_hz
    return total


def run_campaign(campaign: str, hidden: Path, folder: Path, cap: float | None) -> dict:
    logs = folder / campaign
    cmd = [*GS, "campaign", "run", str(CAMPAIGNS / f"{campaign}.toml"), "--fast",
           "--testbed", str(hidden), "--no-analysis", "--log-folder", str(logs)]
    if cap:
        cmd += ["--max-step-seconds", f"{cap:g}"]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=folder, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    report = logs / "report.json"
    doc = json.loads(report.read_text()) if report.is_file() else {}
    status = doc.get("status", f"no report (exit {done.returncode})")
    if done.returncode != 0 or status != "completed":
        print(f"    {campaign}: {status} (exit {done.returncode})\n"
              + "\n".join("      " + ln for ln in (done.stdout + done.stderr).splitlines()[-8:]))
    return {"campaign": campaign, "exit": done.returncode, "status": status,
            "report": str(report), "wall_s": wall,
            "campaign_s": (doc.get("finished", 0.0) - doc.get("started", 0.0)) if doc else None,
            "device_s": device_seconds(report) if report.is_file() else 0.0,
            "logs": sum(len(r.get("files", [])) for r in doc.get("recordings", [])),
            "dropped": sum(r.get("dropped", 0) for r in doc.get("recordings", [])),
            "discarded_blocks": sum(r.get("discarded_blocks", 0) for r in doc.get("recordings", []))}


def run_identify(reports: list[str], base: Path, folder: Path) -> dict:
    out, js = folder / "identified.toml", folder / "identify.json"
    cmd = [*GS, "identify", *reports, "--testbed", str(base), "--out", str(out), "--json", str(js)]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=folder, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    return {"exit": done.returncode, "wall_s": wall, "out": out, "json": js,
            "stdout": done.stdout, "stderr": done.stderr}


def bench_rig(kind: str, rig: Rig, folder: Path, cap: float | None) -> dict:
    folder.mkdir(parents=True)
    base = TESTBEDS / rig.base
    table = None
    if rig.bent_table:
        from groundstation.plant.slope_table import load_slope_table, validate_slope_table
        x, f = bent_slope_table(*load_slope_table(SHIPPED_TABLE))
        validate_slope_table(x, f, "the hidden slope table")
        table = folder / "hidden_slope_lut.csv"
        table.write_text(slope_table_csv(x, f, "bench_identify.py: the hidden rig's slope table "
                                               "(the shipped one bent: 0.9 f(2 (x/2)^0.85))"))
    hidden = folder / f"hidden_{rig.base}"
    hidden.write_text(hidden_text(base.read_text(), base.parent, rig, table,
                                  f"hidden {kind} rig (bench_identify.py)"))
    hidden_doc = tomllib.loads(hidden.read_text())
    runs = []
    for campaign in rig.campaigns:
        runs.append(run_campaign(campaign, hidden, folder, cap))
        r = runs[-1]
        print(f"    recorded {campaign}: {r['logs']} log(s), {r['device_s']:.1f} s device time in "
              f"{r['wall_s']:.1f} s wall ({r['device_s'] / r['wall_s']:.1f}x), {r['status']}, "
              f"{r['dropped']} dropped, load {os.getloadavg()[0]:.1f}", flush=True)
    ok = [r["report"] for r in runs if r["status"] == "completed"]
    ident = run_identify(ok, base, folder) if ok else None
    res: dict = {"base": str(base), "hidden": str(hidden), "campaigns": runs,
                 "campaign_wall_s": sum(r["wall_s"] for r in runs),
                 "device_s": sum(r["device_s"] for r in runs)}
    res["device_per_wall"] = res["device_s"] / res["campaign_wall_s"]
    if ident is None:
        res["identify"] = {"exit": None, "error": "no campaign completed"}
        return res
    res["identify_wall_s"] = ident["wall_s"]
    res["identify"] = {"exit": ident["exit"], "stderr": ident["stderr"][-2000:]}
    print(f"    identify: exit {ident['exit']} in {ident['wall_s']:.1f} s wall", flush=True)
    if ident["exit"] != 0 or not ident["json"].is_file():
        print("      " + "\n      ".join((ident["stdout"] + ident["stderr"]).splitlines()[-10:]))
        return res
    report = json.loads(ident["json"].read_text())
    rows = compare(report, hidden_doc, hidden.parent)
    rig_doc = tomllib.loads(ident["out"].read_text()) if ident["out"].is_file() else None
    rows += unreported_rows([*rig.scale, *rig.add], rows, hidden_doc,
                            tomllib.loads(base.read_text()), rig_doc)
    res["parameters"] = rows
    res["slope_table"] = table_deviation(ident["out"], base, hidden_doc, hidden.parent)
    res["summary"] = summary(rows)
    if rig.bent_table and res["slope_table"] is None:
        res["summary"]["moved_not_identified"].append("friction.slope_table (RIG.toml keeps the base's)")
    res["logs"] = report.get("logs", [])
    res["notes"] = report.get("notes", [])
    res["fit"] = {k: report.get(k) for k in ("bins_used", "reduced_chi_square",
                                             "rms_magnitude_db", "rms_phase_deg")}
    return res


def print_rig(kind: str, res: dict) -> None:
    print(f"\n  {kind} rig ({Path(res['base']).name} moved; hidden file {Path(res['hidden']).name})")
    if "parameters" in res:
        print(format_rows(res["parameters"]))
        t = res.get("slope_table")
        if t is not None and "error" in t:
            print(f"    slope table: RIG.toml's table cannot be compared ({t['error']})")
        elif t is not None:
            print(f"    slope table: identified within {t['max_deviation_pct_of_f0']:.1f} % of the "
                  f"hidden f(0) at every hidden point (the base's table: "
                  f"{t['base_max_deviation_pct_of_f0']:.1f} %)")
        elif RIGS[kind].bent_table:
            print("    slope table: not identified (RIG.toml keeps the base's table)")
        used = [Path(u["path"]).name for u in res.get("logs", []) if u.get("used")]
        print(f"    logs used: {len(used)} of {len(res.get('logs', []))}")
        for n in res.get("notes", []):
            print(f"    note: {n}")
    s = res.get("summary", {})
    dev, wall = res["device_s"], res["campaign_wall_s"]
    ident = (f"{res['identify_wall_s']:.1f} s wall (exit {res['identify']['exit']})"
             if "identify_wall_s" in res else "not run")
    print(f"    campaigns: {wall:.1f} s wall for {dev:.1f} s of device time ({dev / wall:.1f}x); "
          f"identify: {ident}")
    if s:
        print(f"    max |error| over {s['identified']} identified parameters: "
              f"{_g(s['max_abs_error_pct'])} % ({s['worst']}); truth inside the 95 % interval: "
              f"{s['inside_ci']} of {s['with_ci']}"
              + (f"; beyond {FEW_PERCENT:g} %: {', '.join(s['beyond_few_percent'])}"
                 if s["beyond_few_percent"] else "")
              + (f"; outside the interval: {', '.join(s['outside_ci'])}" if s["outside_ci"] else "")
              + (f"; moved on the hidden rig but not identified: "
                 f"{', '.join(s['moved_not_identified'])}" if s["moved_not_identified"] else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-step-seconds", type=float, default=None,
                    help="cap every dwell and profile (a shorter smoke run; default: full campaigns)")
    ap.add_argument("--rigs", default=",".join(RIGS), help="which hidden rigs (default: all)")
    ap.add_argument("--keep", default=None, help="work in this folder and keep it (default: a temporary one)")
    args = ap.parse_args()
    kinds = [k for k in args.rigs.split(",") if k]
    unknown = set(kinds) - set(RIGS)
    if unknown:
        ap.error(f"unknown rig(s) {', '.join(sorted(unknown))}; choose from {', '.join(RIGS)}")
    if args.keep and Path(args.keep).exists() and any(Path(args.keep).iterdir()):
        ap.error(f"--keep {args.keep}: not empty (the campaigns would mix with earlier ones)")
    load0 = os.getloadavg()
    print(f"identification benchmark - {machine()}, {cpu_model()}, load average "
          f"{load0[0]:.1f} at the start" + (f"; every step capped at {args.max_step_seconds:g} s"
                                          if args.max_step_seconds else "; full campaigns"))
    res: dict = {"machine": machine(), "cpu": cpu_model(), "load_average_start": load0,
                 "max_step_seconds": args.max_step_seconds, "rigs": {}}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_identify_") as tmp:
        work = Path(args.keep).resolve() if args.keep else Path(tmp)
        for kind in kinds:
            print(f"  {kind} rig:", flush=True)
            res["rigs"][kind] = bench_rig(kind, RIGS[kind], work / kind, args.max_step_seconds)
    res["total_wall_s"] = time.perf_counter() - t0
    res["load_average_end"] = os.getloadavg()
    for kind in kinds:
        print_rig(kind, res["rigs"][kind])
    print(f"\n  whole benchmark {res['total_wall_s']:.1f} s wall; load average "
          f"{res['load_average_end'][0]:.1f} at the end (a device second costs a wall second "
          f"on a rig or the real-time simulator: the baseline of the ratios)")
    print(f"written to {save('identify', res)}")


if __name__ == "__main__":
    main()
