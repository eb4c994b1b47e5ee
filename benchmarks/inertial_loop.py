"""H4 of docs/fidelity.md: is the reference's inertial loop stable on its own numbers?

Two views of the same loop, each with one number moved at a time:

* continuous: the reference's own model (section 4 plant with b_f, gyro 2nd order with
  its pure delay as a Pade approximant, the designs' continuous transfer functions, the
  outer loop K_p on a complementary LOS estimate), i.e. the loop as the reference
  designed it, before any sampling.  Printed: the least-damped closed-loop pole, its
  frequency and damping ratio (negative = growing).
* sampled: the loop the device closes (ZOH plant at 1200 Hz, the uploaded cascades),
  exactly as `groundstation params validate` computes it.  Printed: the largest |z|.

The printed numbers of the reference carry 3-5 significant figures; moving one by half
its last digit shows whether its stated precision decides stability at all.

    .venv/bin/python benchmarks/inertial_loop.py
"""

from __future__ import annotations

import copy
import dataclasses
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from groundstation.params.continuous_loop import continuous_loop, with_scaled_notch  # noqa: E402
from groundstation.params.design_file import load_design  # noqa: E402
from groundstation.params.loop import validate  # noqa: E402

DESIGNS = ["inertial_design1", "inertial_design2"]


def continuous_pole(design, testbed, *, notch_scale: float = 1.0, crossover_hz: float = 2.0) -> complex:
    """Least-damped closed-loop pole of the continuous loop (rad/s), with the testbed's
    own gyro delay (groundstation/params/continuous_loop.py builds the loop)."""
    c0 = with_scaled_notch(design.c0, notch_scale) if notch_scale != 1.0 else None
    loop = continuous_loop(design, testbed, gyro_delay_s=testbed.sensors["gyro_delay"],
                           crossover_hz=crossover_hz, c0=c0)
    return loop.least_damped_pole()


def sampled_radius(design, testbed, prewarp: str | float | None = "keep") -> float:
    kw = {"testbed": testbed}
    if prewarp != "keep":
        kw["prewarp_hz"] = prewarp
    return validate(dataclasses.replace(design, **kw)).max_pole_radius


REFERENCE_GYRO_DELAY_S = 0.0026          # T_d as the reference prints it (section 2)
APPENDIX_INERTIAS = {"J1": 2.7206, "J2": 1.7878}   # in-oz-s^2, the appendix's mass properties


def _variants(design_testbed):
    """(label, testbed, notch_scale): the loop as the reference prints it (its T_d of
    2.6 ms, not the twin's T_d - T/2 of the testbed file), then one printed number at a
    time moved by half its last digit, the appendix's inertias, and the gyro delay read as
    including the hold (the twin's choice, H4)."""
    tb = copy.deepcopy(design_testbed)
    tb.sensors["gyro_delay"] = REFERENCE_GYRO_DELAY_S

    def changed(section: str, key: str, value: float):
        t = copy.deepcopy(tb)
        getattr(t, section)[key] = value
        return t
    m = tb.mechanics
    yield "as the reference gives it (T_d 2.6 ms)", tb, 1.0
    for key, half in [("J1", 0.005), ("J2", 0.005), ("flexure_stiffness", 5.0),
                      ("flexure_damping", 0.005), ("bearing_viscous", 0.5)]:
        for sign in (-1, 1):
            yield f"{key} {m[key] + sign * half:g}", changed("mechanics", key, m[key] + sign * half), 1.0
    appendix = copy.deepcopy(tb)
    appendix.mechanics.update(APPENDIX_INERTIAS)
    yield "appendix inertias J1 2.7206, J2 1.7878", appendix, 1.0
    for scale in (1.955e4 / 1.96e4, 1.965e4 / 1.96e4):
        yield f"c0 notch 1.96e4 read as {1.96e4 * scale:.4g}", tb, scale
    d = tb.sensors["gyro_delay"]
    yield f"gyro delay {d * 1e3:.3f} - T/2 (the hold lumped into T_d)", changed("sensors", "gyro_delay", d - 1 / 2400), 1.0
    yield "bearing_viscous 0 (H2)", changed("mechanics", "bearing_viscous", 0.0), 1.0


def main() -> int:
    for name in DESIGNS:
        design = load_design(ROOT / "profiles" / "controllers" / f"{name}.toml")
        print(f"== {name}  (prewarp {design.prewarp_hz} Hz as shipped)")
        print(f"   {'variant':<48} {'continuous pole':>28} {'zeta':>9} {'sampled |z|':>12} {'plain Tustin':>13}")
        for label, tb, notch in _variants(design.testbed):
            p = continuous_pole(design, tb, notch_scale=notch)
            zeta = -p.real / abs(p)
            if notch == 1.0:
                r, r_plain = sampled_radius(design, tb), sampled_radius(design, tb, None)
                zs = f"{r:12.6f} {r_plain:13.6f}"
            else:
                zs = f"{'-':>12} {'-':>13}"
            print(f"   {label:<48} {p.real:+9.3f}{p.imag:+10.2f}j ({abs(p.imag) / 2 / math.pi:5.2f} Hz) "
                  f"{zeta:+9.5f} {zs}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
