"""The mode check (analysis/loop_mode.py): the band is taken from the design's own
sampled closed loop, and the share of a PSD in it is the share of the variance there."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.analysis import psd
from groundstation.analysis.loop_mode import (DOMINANT_SHARE, MODE_BAND_HALF_WIDTH, LoopMode,
                                              band_share, design_mode, least_damped_mode, mode_check)
from groundstation.params.design_file import load_design
from groundstation.params.loop_response import loop_model, margins

ROOT = Path(__file__).resolve().parents[2]
RATE_HZ = 1200.0


def test_a_known_share_in_the_band():
    """Two sinusoids and white noise of known variances: the band around one line holds
    its variance (and the noise's in the band's width), nothing of the other."""
    rng = np.random.default_rng(5)
    t = np.arange(int(200 * RATE_HZ)) / RATE_HZ
    a_mode, a_base, noise = 3e-4, 4e-4, 2e-5
    x = (a_mode * np.sin(2 * np.pi * 22.8 * t) + a_base * np.sin(2 * np.pi * 3.0 * t + 1)
         + noise * rng.standard_normal(len(t)))
    s = psd(x, RATE_HZ, segment_s=10.0)
    mode = LoopMode("test", 22.8, -0.0005)
    check = mode_check(mode, s.frequency_hz, s.density, s.resolution_hz)
    lo, hi = check.band_hz
    assert (lo, hi) == pytest.approx((22.8 * (1 - MODE_BAND_HALF_WIDTH), 22.8 * (1 + MODE_BAND_HALF_WIDTH)))
    var_mode, var_base, var_noise = a_mode ** 2 / 2, a_base ** 2 / 2, noise ** 2
    in_band_noise = var_noise * (hi - lo) / (RATE_HZ / 2)
    expected = (var_mode + in_band_noise) / (var_mode + var_base + var_noise)
    assert check.share == pytest.approx(expected, rel=0.01)
    assert not check.dominates and expected < DOMINANT_SHARE
    # the same line, larger: it dominates, and the text says so
    s = psd(2 * a_mode * np.sin(2 * np.pi * 22.8 * t) + a_base * np.sin(2 * np.pi * 3.0 * t), RATE_HZ)
    check = mode_check(mode, s.frequency_hz, s.density, s.resolution_hz)
    assert check.share == pytest.approx(0.36 / (0.36 + 0.16), rel=0.01) and check.dominates
    assert "the mode dominates" in check.text()
    # a coarse PSD widens the band to 3 bins either side
    assert mode.band_hz(resolution_hz=1.0) == pytest.approx((19.8, 25.8))


def test_the_share_is_of_the_bins_above_dc():
    f = np.arange(6, dtype=float)
    p = np.array([100.0, 1.0, 1.0, 2.0, 0.0, 0.0])
    assert band_share(f, p, (2.5, 3.5)) == pytest.approx(0.5)


def test_the_band_of_an_inertial_design_comes_from_its_own_loop():
    """Design #1's least-damped closed-loop pole pair is its flexure mode; the band
    around it holds the loop's second and third gain crossovers, not the first."""
    design = load_design(ROOT / "profiles/controllers/inertial_design1.toml")
    mode = design_mode(design)
    lm = loop_model(design)
    cross = margins(lambda f: lm.response(f, "error"), lm.loop.rate_hz / 2).gain_crossovers_hz
    assert mode is not None and abs(mode.damping) < 0.01
    assert mode.gain_crossovers_hz == pytest.approx(cross)
    lo, hi = mode.band_hz()
    assert len(cross) == 3 and lo < cross[1] < cross[2] < hi and cross[0] < lo
    assert design.name in mode.rule() and "least-damped closed-loop pole pair" in mode.rule()


def test_a_well_damped_loop_has_no_mode_to_check():
    rate = RATE_HZ
    s = np.array([-2 * math.pi * 10 * (0.5 + 0.866j), -2 * math.pi * 10 * (0.5 - 0.866j), -50.0])
    assert least_damped_mode(np.exp(s / rate), rate) is None          # damping 0.5
    s = np.array([2 * math.pi * 20 * (-0.01 + 1j), 2 * math.pi * 20 * (-0.01 - 1j), -50.0])
    m = least_damped_mode(np.exp(s / rate), rate)
    assert m.frequency_hz == pytest.approx(20.0, rel=1e-9) and m.damping == pytest.approx(0.01, rel=1e-3)


def test_a_real_closed_loop_log_gets_the_check_and_an_open_loop_one_does_not(tmp_path):
    """Design #1 closed on the simulated inertial rig, at rest for 8 s: the design is
    found in the log's journal, its band from its own loop, its mode not excited; the
    part of the same log before the loop was closed gets no check."""
    from groundstation.analysis import analyze_log
    from groundstation import Testbed

    design = ROOT / "profiles/controllers/inertial_design1.toml"
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/inertial_2dof.toml", fast=True,
                 generator=None, log_folder=tmp_path, history=tmp_path / "history") as tb:
        tb.start_recording("mode_check")
        tb.dwell(1.0)                            # idle: no loop closed yet
        tb.upload_design(design, accept_risk="a test of the analysis")
        tb.set_mode("INERTIAL")
        tb.arm()
        tb.dwell(8.0)
        log = Path(tb.stop_recording()["files"][0])
    m = analyze_log(log, design="auto", start_s=3.0, psd_segment_s=2.0)
    expected = design_mode(load_design(design))
    assert m.mode is not None and m.mode.mode.frequency_hz == pytest.approx(expected.frequency_hz)
    assert "inertial_design1.toml with the table the log recorded" in m.mode.source
    row = m.row()
    assert row["valid"] and row["mode_share"] < DOMINANT_SHARE and not row["mode_dominates"]
    assert row["mode_band_hz"][0] < expected.frequency_hz < row["mode_band_hz"][1]
    idle = analyze_log(log, design="auto", stop_s=0.9, psd_segment_s=0.5)
    assert idle.mode is None and idle.row()["mode_share"] is None
    assert any("was not closed over most of the window" in n for n in idle.notes)
