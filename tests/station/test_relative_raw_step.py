"""The reference's relative step test, as it ran it (a raw jump of the reference), through
the product's own path - validated upload, played profile, recorded log - on the fast
simulator: Design #1 saturates the coarse motor and recovers, Design #2 saturates
neither, and the two output-equivalent designs give the same output within the
tolerance docs/fidelity.md states."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from groundstation import Testbed
from groundstation.logs import LogReader

ROOT = Path(__file__).resolve().parents[2]
STEP = ROOT / "profiles/waveforms/step_relative_0p5mrad_raw.toml"
STEP_RAD = 0.5e-3
RATE = 1200


@pytest.fixture(scope="module")
def responses(tmp_path_factory):
    """Per design: the inner encoder, the reference and the saturation bits from 0.1 s
    before the jump to 2 s after it (the reference jumps back at 3 s)."""
    folder = tmp_path_factory.mktemp("raw_step")
    out = {}
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/relative_2dof.toml", fast=True,
                 log_folder=folder, history=folder / "h", seed=3) as tb:
        for name in ("relative_design1", "relative_design2"):
            tb.upload_design(ROOT / f"profiles/controllers/{name}.toml")     # validated
            path = tb.start_recording(name)
            assert tb.play(STEP, "RELATIVE").completed
            tb.stop_recording()
            with LogReader(path) as log:
                d = log.read("HIGH_RATE", ["encoder_inner", "reference", "coarse_saturated",
                                           "fine_saturated", "profile_active"])
            ref = d["reference"] - d["reference"][d["profile_active"]][0]      # the held offset
            jump = int(np.argmax(ref > STEP_RAD / 2))
            sl = slice(jump - RATE // 10, jump + 2 * RATE)
            out[name] = {k: v[sl] for k, v in d.items()}
            out[name]["y"] = d["encoder_inner"][sl] - d["reference"][jump - 1]
    return out


def test_design1_saturates_the_coarse_motor_and_recovers_design2_saturates_neither(responses):
    d1, d2 = responses["relative_design1"], responses["relative_design2"]
    assert d1["coarse_saturated"].any() and not d1["fine_saturated"].any()
    assert not d2["coarse_saturated"].any() and not d2["fine_saturated"].any()
    for d in (d1, d2):                      # settled on the step: no saturated oscillation
        tail = d["y"][RATE // 10 + RATE // 2:]
        assert np.max(np.abs(tail - STEP_RAD)) < 0.02 * STEP_RAD


def test_the_output_equivalent_designs_give_the_same_output_within_the_stated_tolerance(responses):
    """docs/fidelity.md's tolerance for the raw 0.5 mrad step: while Design #1's coarse
    motor saturates its response leads with more overshoot (measured 32-41 % of the step
    apart near 45 ms, depending on where the previous run left the bearing's friction);
    from 0.2 s after the jump the outputs agree within 12 % of the step, from 0.5 s within
    2 % (the bearing's presliding friction decides the last percent)."""
    y1, y2 = responses["relative_design1"]["y"], responses["relative_design2"]["y"]
    diff = np.abs(y1 - y2) / STEP_RAD
    start = RATE // 10                       # the jump's index in the window
    assert np.max(diff) < 0.5
    assert np.max(diff[start + RATE // 5:]) < 0.12
    assert np.max(diff[start + RATE // 2:]) < 0.02
