"""Where can the base-motion profiles lie?  Design #2 against Design #1, linear.

The reference reports (testbed.md §9) that under every base-motion profile Design #2 has
lower jitter than Design #1 and Design #1 uses significantly more control energy.  The
designs' own closed loops decide at which frequencies that can hold.  Printed, for the
reference's continuous loop (groundstation/params/continuous_loop.py; T_d 2.6 ms, K_p,
the complementary LOS estimate, the bearing linearised with k_f = 0, so base motion is
the torque b_f s theta_b on the coarse axis):

1. the loop's margins against the reference's stated ones (§9a), every |L| = 1 crossing;
2. per frequency, Design #2 / Design #1: LOS jitter |theta2|, motor power
   (i1^2 R1 + i2^2 R2) and fine-motor torque |u2|; where the power ratio passes 1;
3. per PSD table given: each design's linear jitter RMS (plain and 1 s high-pass),
   control energy over 60 s, motor torque RMS with the fine motor against its limit, and
   the D2/D1 ratios.

    .venv/bin/python benchmarks/disturbance_ratios.py profiles/base_motion/BM1.csv ...
        [--designs A.toml B.toml] [--testbed T.toml] [--freqs 0.5,1,2] [--gyro-delay-ms 2.6]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from groundstation.basemotion.psd import load_psd  # noqa: E402
from groundstation.params.continuous_loop import REFERENCE_GYRO_DELAY_S  # noqa: E402
from groundstation.params.continuous_margins import inertial_margins  # noqa: E402
from groundstation.params.design_file import load_design  # noqa: E402
from groundstation.params.disturbance_ratios import (disturbance_ratios,  # noqa: E402
                                                     energy_ratio_crossings_hz, figure_ratios,
                                                     predicted_figures)
from groundstation.plant.testbed import load_testbed  # noqa: E402

CONTROLLERS = ROOT / "profiles" / "controllers"
DEFAULT_DESIGNS = [CONTROLLERS / "inertial_design1.toml", CONTROLLERS / "inertial_design2.toml"]
DEFAULT_FREQS_HZ = "0.2,0.5,1,2,3,4,5,5.6,6,7,8,10,15,20"
# testbed.md §9a, as stated (the test tests/params/test_inertial_margins.py holds the loop to them)
REFERENCE_MARGINS = ("rate loop (Design #1): crossover ~15 Hz, PM ~40 deg, GM >= 10 dB, bandwidth ~25 Hz; "
                     "outer loop K_p = 25: GM ~10 dB, PM ~80 deg, ~5 Hz bandwidth")


def _margin_lines(designs, testbed, delay_s: float) -> list[str]:
    out = [f"margins of the continuous loop (gyro delay {delay_s * 1e3:.3f} ms); reference: {REFERENCE_MARGINS}"]
    for d in designs:
        m = inertial_margins(d, testbed, gyro_delay_s=delay_s)
        p = m.least_damped_pole
        out += [f"  {d.name}",
                f"    rate loop:  {m.inner.text()}",
                f"    outer loop: {m.outer.text()}",
                f"    least-damped closed-loop pole {p.real:+.3f} {p.imag:+.2f}j rad/s "
                f"({abs(p.imag) / 2 / np.pi:.2f} Hz), damping {m.least_damped_zeta:+.5f}"]
    return out


def _ratio_lines(first, second, testbed, freqs_hz, delay_s: float) -> list[str]:
    r = disturbance_ratios(first, second, freqs_hz, testbed, gyro_delay_s=delay_s)
    out = [f"{second.name} / {first.name}, per frequency of the base motion",
           f"  {'Hz':>6} {'jitter':>9} {'energy':>11} {'|u2|':>9}"]
    for f, j, e, u in zip(r.frequency_hz, r.jitter_ratio, r.energy_ratio, r.fine_torque_ratio):
        out.append(f"  {f:6.2f} {j:9.4f} {e:11.4g} {u:9.3f}")
    crossings = energy_ratio_crossings_hz(first, second, min(freqs_hz), max(freqs_hz), testbed,
                                          gyro_delay_s=delay_s)
    out.append("  energy ratio passes 1 at: "
               + (", ".join(f"{f:.3f} Hz" for f in crossings) if crossings else "nowhere in the range"))
    return out


def _figure_lines(first, second, testbed, psd_path: Path, delay_s: float) -> list[str]:
    psd = load_psd(psd_path)
    figs = [predicted_figures(d, testbed, psd, gyro_delay_s=delay_s) for d in (first, second)]
    lo, hi = psd.band_hz
    out = [f"{psd_path.name}: band {lo:g}-{hi:g} Hz, base {figs[0]['base_rms_rad'] * 1e3:.2f} mrad RMS, "
           f"{figs[0]['duration_s']:g} s",
           f"  {'design':<22} {'jitter urad':>11} {'1 s HP urad':>11} {'energy J':>10} "
           f"{'u1 RMS':>8} {'u2 RMS':>8} {'u2/limit':>9} {'u2 sat (Gauss)':>15}"]
    for f in figs:
        out.append(f"  {f['design']:<22} {f['jitter_rms_rad'] * 1e6:11.2f} {f['jitter_highpass_rms_rad'] * 1e6:11.2f} "
                   f"{f['energy_j']:10.3f} {f['coarse_rms_in_oz']:8.3f} {f['fine_rms_in_oz']:8.3f} "
                   f"{f['fine_rms_over_limit']:9.3f} {f['fine_saturated_fraction'] * 100:14.3f}%")
    r = figure_ratios(*figs)
    out.append(f"  D2/D1: jitter {r['jitter_rms_rad']:.4f} (1 s HP {r['jitter_highpass_rms_rad']:.4f}), "
               f"energy {r['energy_j']:.4f}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("psd", nargs="*", type=Path, help="base-motion PSD tables (profiles/base_motion/*.csv)")
    ap.add_argument("--designs", nargs=2, type=Path, default=DEFAULT_DESIGNS, metavar=("FIRST", "SECOND"))
    ap.add_argument("--testbed", type=Path, default=None, help="default: the first design's")
    ap.add_argument("--freqs", default=DEFAULT_FREQS_HZ, help="Hz, comma separated")
    ap.add_argument("--gyro-delay-ms", type=float, default=REFERENCE_GYRO_DELAY_S * 1e3,
                    help="the continuous loop's gyro delay (default: the reference's T_d)")
    args = ap.parse_args(argv)
    first, second = (load_design(p) for p in args.designs)
    testbed = load_testbed(args.testbed) if args.testbed else first.testbed
    freqs_hz = np.array([float(x) for x in args.freqs.split(",") if x.strip()])
    delay_s = args.gyro_delay_ms * 1e-3
    lines = [f"testbed {testbed.path.name}; bearing linearised with k_f = 0, b_f = "
             f"{testbed.mechanics['bearing_viscous']:g} in-oz-s/rad (base motion = a coarse-axis torque)"]
    lines += _margin_lines((first, second), testbed, delay_s) + [""]
    lines += _ratio_lines(first, second, testbed, freqs_hz, delay_s)
    for path in args.psd:
        lines += [""] + _figure_lines(first, second, testbed, path, delay_s)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
