"""The PQ views of one design recomputed, vectorised vs a per-frequency Python loop.

One "full recompute" is what a design edit changes (issue 17's workbench target: under
100 ms on a 2-core machine):

  frequency  on the 800-point grid (0.1 Hz to Nyquist): G, [c1', c2'], K = c0 [c1', c2'],
             P, Q, PQ, phi (Eq. 4.9), phi_PQ, L, T_O, S_O, ||T_I||, ||S_I K|| and their
             bounds (groundstation.params.pq_design.analyze and pq.LoopFunctions);
  dc         T_I(0) from the leading terms at s = 0;
  loop       the sampled loop: the design's table discretised and the plant built
             (loop_response.loop_model; the protocol dictionary loaded once beforehand, as
             a workbench holds it);
  time       on that loop, the linear responses to the input disturbance and to the
             reference step, 600 periods (0.5 s) for both inputs at once
             (pq_response.linear_responses);
  margins    on that loop, the existing validation's margins (loop_response.margins of
             the loop broken at e and, inertial, of the rate and position loops) - the Bode
             view the workbench shows beside the PQ views.

The alignment-contour fills do not depend on the design and are drawn once, so they are
not part of a recompute.  Side by side, in the same run and on the same design:

  ours       the package's functions: each quantity a few numpy operations on the grid;
  naive      the same frequency views as a Python loop over the frequencies, each one
             evaluating the factors, building the 2x2 T_I with np.outer, its 2-norm by
             np.linalg.norm(ord=2) (an SVD), S_I K by np.linalg.solve and phi by arccos -
             what a first script does (python-control is not a dependency: its
             frequency responses are vectorised too, but it has no TISO alignment);
             dc, time and margins are the package's in both (no per-frequency loop).

The answers of the two are compared, so a speed-up cannot hide a wrong answer.  The
fastest of the repeats counts (other programs on a shared machine slow some runs down).

Run: .venv/bin/python benchmarks/bench_pq.py [--design inertial_design2] [--repeats 20]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
from common import machine, save

from groundstation.core.dictionary import load_dictionary
from groundstation.params.design_file import load_design
from groundstation.params.loop_response import loop_model, margins
from groundstation.params.pq_design import analyze, dc_input_sensitivity, frequency_grid
from groundstation.params.pq_response import linear_responses
from groundstation.plant.model import plant_transfer_functions

CONTROLLERS = Path(__file__).resolve().parent.parent / "profiles" / "controllers"


def ours_frequency(design, f):
    a = analyze(design, f)
    lf = a.functions
    return {"phi": a.phi_deg, "phi_pq": a.phi_pq_deg, "pq": a.pq, "t_out": lf.t_out,
            "s_out": lf.s_out, "ti": lf.ti_norm, "sik": lf.sik_norm, "ti_bound": lf.ti_bound,
            "sik_bound": lf.sik_bound}


def _tf_at(tf, s: complex) -> complex:
    out = complex(tf.gain)
    for z in tf.zeros:
        out *= s - z
    for p in tf.poles:
        out /= s - p
    return out


def naive_frequency(design, f):
    """The same views, one frequency at a time."""
    tb = design.testbed
    (n1, den), (n2, _) = plant_transfer_functions(tb)
    sens = tb.sensors
    wg = 2 * math.pi * sens["gyro_bandwidth"]
    out = {k: np.empty(len(f), complex if k in ("pq", "t_out", "s_out") else float)
           for k in ("phi", "phi_pq", "pq", "t_out", "s_out", "ti", "sik", "ti_bound", "sik_bound")}
    for i, fi in enumerate(f):
        s = 2j * math.pi * fi
        d = np.polyval(den, s)
        G = np.array([np.polyval(n1, s) / d, np.polyval(n2, s) / d])
        if design.mode == "inertial":
            G = G * s * wg * wg / (s * s + 2 * sens["gyro_damping"] * wg * s + wg * wg) \
                * np.exp(-s * sens["gyro_delay"])
        C = np.array([_tf_at(design.c1, s), _tf_at(design.c2, s)])
        K = _tf_at(design.c0, s) * C
        L = G @ K
        TI = np.outer(K, G) / (1 + L)
        SIK = np.linalg.solve(np.eye(2) + np.outer(K, G), K)
        ng = np.linalg.norm(G)
        pq = G[0] / G[1] * C[0] / C[1]
        out["phi"][i] = math.degrees(math.acos(min(1.0, abs(G @ C) / (ng * np.linalg.norm(C)))))
        out["phi_pq"][i] = math.degrees(math.acos(min(1.0, abs(1 + pq) / (1 + abs(pq)))))
        out["pq"][i] = pq
        out["t_out"][i] = L / (1 + L)
        out["s_out"][i] = 1 / (1 + L)
        out["ti"][i] = np.linalg.norm(TI, ord=2)
        out["sik"][i] = np.linalg.norm(SIK)
        out["ti_bound"][i] = abs(L / (1 + L))
        out["sik_bound"][i] = abs(L / (1 + L)) / ng
    return out


def sampled_margins(design, lm):
    loops = ("error", "inner", "outer") if design.mode == "inertial" else ("error",)
    nyquist = lm.loop.rate_hz / 2
    return [margins(lambda x, name=name: lm.response(x, name), nyquist) for name in loops]


def best_of(fn, repeats: int) -> tuple[float, object]:
    best, result = math.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--design", default="inertial_design2")
    p.add_argument("--repeats", type=int, default=20)
    args = p.parse_args()
    print(f"PQ views benchmark - {machine()}")
    design = load_design(CONTROLLERS / f"{args.design}.toml")
    f = frequency_grid()
    print(f"design {design.name}, {len(f)} frequencies, best of {args.repeats} (naive: of "
          f"{max(2, args.repeats // 5)})")

    t_freq, ours = best_of(lambda: ours_frequency(design, f), args.repeats)
    t_naive, naive = best_of(lambda: naive_frequency(design, f), max(2, args.repeats // 5))
    t_dc, _ = best_of(lambda: dc_input_sensitivity(design), args.repeats)
    d = load_dictionary()            # once, as a workbench would hold it
    t_loop, lm = best_of(lambda: loop_model(design, dictionary=d), max(2, args.repeats // 2))
    t_time, _ = best_of(lambda: linear_responses(design, lm=lm), max(2, args.repeats // 2))
    t_margins, _ = best_of(lambda: sampled_margins(design, lm), max(2, args.repeats // 4))
    worst = {}
    for k in ours:
        a, b = np.asarray(ours[k]), np.asarray(naive[k])
        # angles compare in deg (the naive arccos loses digits near 0); the rest relatively
        worst[k] = float(np.max(np.abs(a - b)) if k.startswith("phi")
                         else np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))
    agree = all(v < (1e-5 if k.startswith("phi") else 1e-8) for k, v in worst.items())

    shared = t_dc + t_loop + t_time + t_margins
    full_ours, full_naive = t_freq + shared, t_naive + shared
    print(f"\n{'':<36}{'ours':>10}{'naive':>10}{'ratio':>8}")
    print(f"{'frequency views (800 points), ms':<36}{1e3 * t_freq:>10.2f}{1e3 * t_naive:>10.1f}"
          f"{t_naive / t_freq:>7.0f}x")
    print(f"{'T_I(0), ms':<36}{1e3 * t_dc:>10.3f}{1e3 * t_dc:>10.3f}")
    print(f"{'sampled loop (table, plant), ms':<36}{1e3 * t_loop:>10.1f}{1e3 * t_loop:>10.1f}")
    print(f"{'time responses (2 x 600 periods), ms':<36}{1e3 * t_time:>10.1f}{1e3 * t_time:>10.1f}")
    print(f"{'sampled-loop margins (existing), ms':<36}{1e3 * t_margins:>10.1f}{1e3 * t_margins:>10.1f}")
    print(f"{'full recompute, ms':<36}{1e3 * full_ours:>10.1f}{1e3 * full_naive:>10.1f}"
          f"{full_naive / full_ours:>7.1f}x")
    print(f"answers agree: {agree} (worst: phi {max(worst['phi'], worst['phi_pq']):.1e} deg, "
          f"others {max(v for k, v in worst.items() if not k.startswith('phi')):.1e} relative)")
    path = save("pq", {"machine": machine(), "design": args.design, "points": len(f),
                       "ours_frequency_s": t_freq, "naive_frequency_s": t_naive,
                       "dc_s": t_dc, "loop_s": t_loop, "time_s": t_time, "margins_s": t_margins, "full_ours_s": full_ours,
                       "full_naive_s": full_naive, "agree": agree, "worst": worst})
    print(f"results: {path}")
    if not agree:
        raise SystemExit("the two ways disagree")


if __name__ == "__main__":
    main()
