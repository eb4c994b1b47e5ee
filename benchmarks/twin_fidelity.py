"""Fidelity experiments on the twin's engine (docs/fidelity.md): one inertial run under
base motion, or a relative step, with one assumption of the twin changed at a time.

It drives the simulator's compiled engine directly (no link, no recorder), so a
hypothesis about the twin is tested in seconds and nothing else can blur it; the
campaign through the real path is the acceptance, not this.

    .venv/bin/python benchmarks/twin_fidelity.py inertial --design inertial_design1 --bm BM1
    .venv/bin/python benchmarks/twin_fidelity.py inertial --all [--set mechanics.bearing_viscous=0]
    .venv/bin/python benchmarks/twin_fidelity.py step --design relative_design1 [--raw]
    .venv/bin/python benchmarks/twin_fidelity.py ripple --amplitudes 0,1,2 --periods 4,8 [--bm BM1]

--set SECTION.KEY=VALUE changes the testbed for the plant only (the design and its
validation stay as written); --param NAME=VALUE changes an entry of the uploaded table
(e.g. anti_windup=0).  Figures: jitter (std and 1 s high-pass RMS) of the true LOS and of
the autocollimator, control energy, saturation fractions, the share of the LOS variance
in the band of the loop's lightly damped 22.8 Hz mode (MODE_BAND_HZ), faults.
`--testbed FILE` runs on another inertial testbed file (e.g. the appendix inertias);
`ripple` sweeps the bearing ripple's amplitude and period for Designs #1, #2 and #2 with
compensation and prints the reference's ratios (docs/fidelity.md, H7).
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from groundstation.analysis.energy import control_energy  # noqa: E402
from groundstation.analysis.jitter import los_jitter  # noqa: E402
from groundstation.basemotion.psd import load_psd  # noqa: E402
from groundstation.basemotion.stage import BaseStageModel  # noqa: E402
from groundstation.basemotion.synthesis import make_profile  # noqa: E402
from groundstation.core.dictionary import load_dictionary  # noqa: E402
from groundstation.params.design_file import load_design, table_values  # noqa: E402
from groundstation.params.table import default_values  # noqa: E402
from groundstation.plant.testbed import load_testbed  # noqa: E402
from groundstation.sim import core  # noqa: E402
from groundstation.sim.engine import Engine  # noqa: E402
from scipy import signal  # noqa: E402

CONTROLLERS = ROOT / "profiles" / "controllers"
TESTBEDS = ROOT / "profiles" / "testbeds"
BASE_MOTION = ROOT / "profiles" / "base_motion"
RATE = 1200.0
#: the band of the inertial loop's lightly damped flexure mode (22.8 Hz, H4) whose share
#: of the LOS variance is printed: wide enough for Welch's 0.3 Hz bins and the mode's
#: shift with the inertias, narrow enough to leave the loop's 15 Hz crossover out
MODE_BAND_HZ = (20.0, 26.0)
FAULTS = {core.FAULT_OVER_TRAVEL: "over-travel", core.FAULT_FLEXURE: "flexure", core.FAULT_WATCHDOG: "watchdog"}


def _value(text: str):
    try:
        return float(text)
    except ValueError:
        return text


def testbed_with(path: Path, changes: list[str]):
    tb = copy.deepcopy(load_testbed(path))
    for change in changes:
        key, value = change.split("=", 1)
        section, name = key.split(".", 1)
        getattr(tb, section)[name] = _value(value)
    return tb


def make_engine(design_name: str, testbed, params: list[str], seed: int):
    d = load_dictionary()
    design = load_design(CONTROLLERS / f"{design_name}.toml") if design_name != "open_loop" else None
    # open loop: the device's default table (never armed, so no controller runs)
    values = table_values(design, dictionary=d) if design else dict(default_values(d))
    for p in params:
        k, v = p.split("=", 1)
        if k == "friction_comp_table":          # a slope-table CSV for the compensator
            from groundstation.sim import friction as fr
            x, y = fr.load_slope_table(Path(v))
            rows = len(values["friction_comp_table_x"])
            values["friction_comp_table_points"] = len(x)
            values["friction_comp_table_x"] = list(x) + [2.0] * (rows - len(x))
            values["friction_comp_table_slope"] = list(y) + [0.0] * (rows - len(x))
            continue
        values[k] = _value(v)
    eng = Engine(testbed, values, seed=seed, control_rate_hz=RATE)
    eng.fw[core.FW_COMP_ON] = float(values["friction_comp_enabled"])
    return eng, design


def arm(eng: Engine, mode: int) -> None:
    eng.fw[core.FW_MODE] = mode
    eng.fw[core.FW_ARMED] = 1.0
    eng.fw[core.FW_FAULT] = core.FAULT_NONE
    eng.reset_controllers()


def run(eng: Engine, seconds: float, v_fg: np.ndarray | None = None, block: int = 1200):
    n = int(round(seconds * RATE))
    cols, truths, faults = [], [], []
    done = 0
    while done < n:
        m = min(block, n - done)
        c, t, ev = eng.run(m, None if v_fg is None else v_fg[done:done + m])
        cols.append(c)
        truths.append(t)
        faults += [(tick, code) for tick, code in ev if code in (core.EV_FLEXURE, core.EV_OVER_TRAVEL, core.EV_WATCHDOG)]
        done += m
    out = {k: np.concatenate([c[k] for c in cols]) for k in cols[0]}
    truth = np.concatenate(truths)
    return out, truth, faults


def drive_volts(profile, seconds: float, seed_offset_s: float = 0.0) -> np.ndarray:
    """The generator's staircase at 1200 Hz: point i held for duration/points seconds."""
    t = seed_offset_s + np.arange(int(round(seconds * RATE))) / RATE
    idx = np.floor(t / profile.sample_interval_s).astype(np.int64) % profile.points
    return profile.volts[idx]


def figures(out, truth, testbed) -> dict[str, float]:
    los = truth[:, 1]
    jit = los_jitter(los, RATE, integration_period_s=1.0)
    ac = los_jitter(out["autocollimator"], RATE, integration_period_s=1.0)
    r1, r2 = testbed.motor_coarse["resistance"], testbed.motor_fine["resistance"]
    e = control_energy(out["current_coarse"], out["current_fine"], RATE, r1, r2)
    ac_range = testbed.sensors["autocollimator_range"] * math.pi / 180
    f_hz, pxx = signal.welch(los - np.mean(los), fs=RATE, nperseg=4096)
    in_band = (f_hz > MODE_BAND_HZ[0]) & (f_hz < MODE_BAND_HZ[1])
    return {"mode_share": float(np.sum(pxx[in_band]) / np.sum(pxx)) if np.sum(pxx) > 0 else 0.0,
            "los_std_urad": jit.std_rad * 1e6, "los_hp_urad": jit.highpass_rms_rad * 1e6,
            "ac_std_urad": ac.std_rad * 1e6, "energy_j": e.energy_total_j,
            "sat_coarse": float(np.mean(out["coarse_saturated"])),
            "sat_fine": float(np.mean(out["fine_saturated"])),
            "ac_out_of_range": float(np.mean(np.abs(truth[:, 1]) > ac_range)),
            "defl_max_mrad": float(np.max(np.abs(truth[:, 5]))) * 1e3,
            "base_rms_mrad": float(np.std(truth[:, 2])) * 1e3}


def _psd_path(bm: str) -> Path:
    """A profile's stem in profiles/base_motion (BM1) or a PSD table's path."""
    path = Path(bm)
    return path if path.suffix == ".csv" else BASE_MOTION / f"{bm}.csv"


def inertial_run(design: str, bm: str, args) -> dict[str, float]:
    tb = testbed_with(Path(args.testbed), args.set)
    eng, _ = make_engine(design, tb, args.param, args.seed)
    if design != "open_loop":
        arm(eng, core.MODE_INERTIAL)
    run(eng, args.settle)
    volts = None
    if bm != "none":
        psd = load_psd(_psd_path(bm))
        profile = make_profile(psd, BaseStageModel.from_testbed(load_testbed(TESTBEDS / "inertial_2dof.toml")),
                               seed=args.profile_seed, target_rms_rad=psd.rms_rad() * args.bm_scale)
        volts = drive_volts(profile, args.seconds)
    out, truth, faults = run(eng, args.seconds, volts)
    f = figures(out, truth, tb)
    f["fault"] = (f"{FAULTS.get(int(eng.fw[core.FW_FAULT]), '?')} at "
                  f"{(faults[0][0] / RATE) - args.settle:.2f} s") if faults else ""
    return f


def step_run(design: str, args) -> dict[str, float]:
    """The reference's raw step: SET_REFERENCE to +step at 0.5 s (one control period), back at
    `back` s; the figures of the first transition and the saturation of each motor."""
    tb = testbed_with(TESTBEDS / "relative_2dof.toml", args.set)
    eng, _ = make_engine(design, tb, args.param, args.seed)
    arm(eng, core.MODE_RELATIVE)
    run(eng, 0.5)
    eng.fw[core.FW_REF] = args.step_mrad * 1e-3
    up, up_truth, f1 = run(eng, args.back - 0.5)
    eng.fw[core.FW_REF] = 0.0
    down, down_truth, f2 = run(eng, args.seconds - args.back)
    y = up["encoder_inner"] * 1e3
    final = float(np.mean(y[-int(0.2 * RATE):]))
    rise = np.argmax(y >= 0.9 * args.step_mrad) / RATE if np.any(y >= 0.9 * args.step_mrad) else math.nan
    both = {k: np.concatenate([up[k], down[k]]) for k in ("coarse_saturated", "fine_saturated", "torque_coarse_cmd",
                                                        "torque_fine_cmd")}
    tail = np.abs(y - args.step_mrad) > 0.02 * args.step_mrad
    settle = (np.nonzero(tail)[0][-1] + 1) / RATE if np.any(tail) else 0.0
    return {"final_mrad": final, "overshoot_pct": (float(np.max(y)) / args.step_mrad - 1) * 100,
            "rise_s": rise, "settle_2pct_s": settle,
            "sat_coarse_s": float(np.sum(both["coarse_saturated"])) / RATE,
            "sat_fine_s": float(np.sum(both["fine_saturated"])) / RATE,
            "u1_peak": float(np.max(np.abs(both["torque_coarse_cmd"]))),
            "u2_peak": float(np.max(np.abs(both["torque_fine_cmd"]))),
            "fault": "fault" if (f1 or f2) else "", "y": y}


def ripple_sweep(args) -> int:
    """Designs #1, #2 and #2 with compensation under one base motion for every ripple
    (amplitude, period): the high-pass jitter and energy of each and the reference's
    ratios (D2/D1 about 0.4 and 0.05, FC/D2 about 0.6 and 0.75 under BM1)."""
    designs = ["inertial_design1", "inertial_design2", "inertial_design2_friction_comp"]
    bm = args.bm or "BM1"
    base_set = list(args.set)
    print(f"{'A in-oz':>7s} {'P mrad':>7s}  {'D1 hp/E':>15s}  {'D2 hp/E':>14s} {'sat2':>5s}  "
          f"{'FC hp/E (mode)':>21s}  {'D2/D1 j, E':>11s}  {'FC/D2 j, E':>10s}")
    for amplitude in (float(a) for a in args.amplitudes.split(",")):
        for period_mrad in (float(p) for p in args.periods.split(",")):
            args.set = base_set + [f"bearing_ripple.amplitude={amplitude}",
                                   f"bearing_ripple.period={period_mrad * 1e-3}"]
            d1, d2, fc = (inertial_run(d, bm, args) for d in designs)
            diverged = bool(d1["fault"]) or any(f["sat_fine"] > 0.5 or f["fault"] for f in (d2, fc))
            print(f"{amplitude:7.2f} {period_mrad:7.2f}  {d1['los_hp_urad']:7.1f}/{d1['energy_j']:6.1f}  "
                  f"{d2['los_hp_urad']:6.1f}/{d2['energy_j']:6.2f} {d2['sat_fine']:5.3f}  "
                  f"{fc['los_hp_urad']:6.1f}/{fc['energy_j']:6.2f} ({fc['mode_share']:.2f})  "
                  f"{d2['los_hp_urad'] / d1['los_hp_urad']:5.2f} {d2['energy_j'] / d1['energy_j']:5.3f}  "
                  f"{fc['los_hp_urad'] / d2['los_hp_urad']:5.2f} {fc['energy_j'] / d2['energy_j']:4.2f}"
                  f"{'  (a run diverged or faulted)' if diverged else ''}", flush=True)
    args.set = base_set
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=["inertial", "step", "ripple"])
    ap.add_argument("--testbed", default=str(TESTBEDS / "inertial_2dof.toml"),
                    help="the inertial testbed file of the plant (inertial and ripple)")
    ap.add_argument("--amplitudes", default="0,1,2", help="ripple amplitudes, in-oz (ripple)")
    ap.add_argument("--periods", default="4,8", help="ripple periods, mrad of bearing angle (ripple)")
    ap.add_argument("--step-mrad", type=float, default=1.0)
    ap.add_argument("--back", type=float, default=3.0)
    ap.add_argument("--design", default="inertial_design1")
    ap.add_argument("--bm", default=None,
                    help="profile stems in profiles/base_motion or PSD .csv paths, comma-separated "
                         "(default: BM1, or BM1-BM3 with --all)")
    ap.add_argument("--all", action="store_true", help="open loop + the three designs under BM1-BM3")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--settle", type=float, default=5.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--profile-seed", type=int, default=0)
    ap.add_argument("--bm-scale", type=float, default=1.0, help="scale the profile's RMS")
    ap.add_argument("--set", action="append", default=[], help="SECTION.KEY=VALUE of the plant's testbed")
    ap.add_argument("--param", action="append", default=[], help="NAME=VALUE of the uploaded table")
    args = ap.parse_args()
    if args.what == "step":
        for design in (["relative_design1", "relative_design2"] if args.all else [args.design]):
            f = step_run(design, args)
            print(f"{design:20s} final {f['final_mrad']:.4f} mrad, overshoot {f['overshoot_pct']:.1f} %, rise "
                  f"{f['rise_s'] * 1e3:.1f} ms, settles (2 %) {f['settle_2pct_s']:.3f} s after the step; "
                  f"saturated coarse {f['sat_coarse_s'] * 1e3:.0f} ms, fine {f['sat_fine_s'] * 1e3:.0f} ms; "
                  f"peaks u1 {f['u1_peak']:.1f}, u2 {f['u2_peak']:.1f} in-oz {f['fault']}")
        return 0
    if args.what == "ripple":
        return ripple_sweep(args)
    designs = (["open_loop", "inertial_design1", "inertial_design2", "inertial_design2_friction_comp"]
               if args.all else args.design.split(","))
    bms = (["BM1", "BM2", "BM3"] if args.all and args.bm is None
           else (args.bm or "BM1").split(","))
    print(f"{'design':34s} {'bm':4s} {'LOS std':>9s} {'LOS hp':>9s} {'AC std':>9s} {'E [J]':>9s} "
          f"{'sat1':>6s} {'sat2':>6s} {'defl':>6s} {'base':>6s} {'mode':>5s}  fault")
    for bm in bms:
        for design in designs:
            f = inertial_run(design, bm, args)
            print(f"{design:34s} {Path(bm).stem:4s} {f['los_std_urad']:9.2f} {f['los_hp_urad']:9.2f} "
                  f"{f['ac_std_urad']:9.2f} {f['energy_j']:9.3f} {f['sat_coarse']:6.3f} "
                  f"{f['sat_fine']:6.3f} {f['defl_max_mrad']:6.2f} {f['base_rms_mrad']:6.2f} {f['mode_share']:5.2f}  "
                  f"{f['fault']}",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
