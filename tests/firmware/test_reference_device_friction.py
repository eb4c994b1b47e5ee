"""The reference device's friction compensator (firmware/reference_device/src/friction.c,
SPEC §10.1) against the simulator's friction_step, the reference SPEC names for the
stack bookkeeping: the same torques for every model, on motion with minor loops and on
nested reversals that overflow the stack."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from groundstation.core.dictionary import load_dictionary
from groundstation.params.table import default_values
from groundstation.sim.friction import FrictionParams, new_state, simulate_friction
from reference_device_helpers import FIRMWARE_DIR

HARNESS = r"""
#include <stdio.h>
#include <string.h>
#include "device.h"
device_t dev;
static int resets;
void event_send(uint8_t level, uint16_t code, const char *text)
{
    (void)level; (void)text;
    if (code == HFB_EVT_FRICTION_COMP_RESET) resets++;
}
int main(int argc, char **argv)
{
    double phi, prev = 0.0;
    int first = 1;
    memcpy(dev.table, hfb_param_default_table, sizeof dev.table);
    dev.table[HFB_PARAM_FRICTION_COMP_MODEL_OFFSET] = (uint8_t)(argv[1][0] - '0');
    (void)argc;
    friction_reset();
    while (scanf("%lf", &phi) == 1) {
        printf("%.17g\n", friction_step(first ? 0.0 : phi - prev));
        first = 0;
        prev = phi;
    }
    fprintf(stderr, "%d\n", resets);
    return 0;
}
"""

MODELS = ("SFM", "DHM", "DB-SFM", "DB-DHM")


@pytest.fixture(scope="module")
def harness(tmp_path_factory):
    d = tmp_path_factory.mktemp("friction")
    (d / "harness.c").write_text(HARNESS)
    out = subprocess.run(
        ["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", f"-I{FIRMWARE_DIR / 'kit'}",
         f"-I{FIRMWARE_DIR / 'src'}", "-o", str(d / "h"), str(d / "harness.c"),
         str(FIRMWARE_DIR / "src" / "friction.c"), str(FIRMWARE_DIR / "kit" / "hfb_protocol.c"), "-lm"],
        capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return d / "h"


def params(model: str) -> FrictionParams:
    v = default_values(load_dictionary())
    n = int(v["friction_comp_table_points"])
    f32 = lambda x: float(np.float32(x))          # the table carries f32 values
    return FrictionParams(model=model, sigma=f32(v["friction_comp_sigma"]),
                          T_c=f32(v["friction_comp_coulomb"]), alpha=f32(v["friction_comp_alpha"]),
                          lut_x=np.asarray(v["friction_comp_table_x"][:n], np.float32).astype(float),
                          lut_y=np.asarray(v["friction_comp_table_slope"][:n], np.float32).astype(float))


def run_c(harness, model_id: int, phi: np.ndarray) -> tuple[np.ndarray, int]:
    out = subprocess.run([str(harness), str(model_id)], input="\n".join(f"{x:.17g}" for x in phi),
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return np.array(out.stdout.split(), float), int(out.stderr.split()[-1])


t = np.arange(0, 4, 1 / 1200)
MINOR_LOOPS = 1e-3 * np.sin(2 * np.pi * 0.5 * t) + 1e-4 * np.sin(2 * np.pi * 7 * t)
# an oscillation that shrinks: every reversal nests inside the last, none closes, so the
# stack fills (80 reversals > 62)
NESTED = 1e-3 * np.exp(-t) * np.sin(2 * np.pi * 10 * t)
# ... then a growing one that unwinds the nested loops again, through the forgotten ones
GROWING = np.concatenate([NESTED, NESTED[-1] + (NESTED[::-1] - NESTED[-1]) * 1.0])


@pytest.mark.parametrize("model_id,model", list(enumerate(MODELS)))
@pytest.mark.parametrize("trajectory", ["minor_loops", "nested", "growing"])
def test_compensator_agrees_with_the_simulator(harness, model_id, model, trajectory):
    phi = {"minor_loops": MINOR_LOOPS, "nested": NESTED, "growing": GROWING}[trajectory]
    p = params(model)
    state, stack = new_state(p)
    want = simulate_friction(phi, p, state=state, stack=stack)
    got, resets = run_c(harness, model_id, phi)
    assert np.max(np.abs(got - want)) < 1e-6 * p.T_c
    if trajectory != "minor_loops" and model.endswith("DHM"):
        assert resets >= 1                    # the overflow was met, and told
