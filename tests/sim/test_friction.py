"""Bearing friction models (reference §5): the properties that define SFM, DHM, DB-SFM, DB-DHM."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from groundstation.core.errors import GroundStationError
from groundstation.plant.slope_table import DEFAULT_SLOPE_TABLE, SlopeTableError, load_slope_table
from groundstation.sim.friction import (
                                        FRICTION_MODELS, S_CLOSURES, S_DEPTH, S_DIR, S_OVERFLOW, S_REVERSALS,
                                        S_T, FrictionConfigError, FrictionParams, friction_step, new_state, simulate_friction,
                                        )

SHIPPED = Path(__file__).resolve().parents[2] / "profiles" / "friction_slope_lut.csv"
SIGMA, TC = 5730.0, 2.25
TINY = 1e-10          # rad: a "numerical derivative" step (changes T by ~1e-6 in-oz)


@pytest.fixture(scope="module")
def table():
    return load_slope_table(SHIPPED)


def params(model: str, table=None, **kw) -> FrictionParams:
    if model.startswith("DB-"):
        kw.setdefault("lut_x", table[0])
        kw.setdefault("lut_y", table[1])
    return FrictionParams(model=model, **kw)


def path_through(*points, n=400):
    """Piecewise-linear angle trajectory through the given reversal points, n steps per leg."""
    legs = [np.linspace(a, b, n, endpoint=False) for a, b in zip(points[:-1], points[1:])]
    return np.concatenate(legs + [[points[-1]]])


def run(p: FrictionParams, phi, direction=0):
    state, stack = new_state(p, direction)
    T = simulate_friction(phi, p, state=state, stack=stack)
    return T, state, stack


def slope_after(p, state, stack, direction, copy=True):
    """Numerical dT/dφ for a tiny move in ``direction`` from the current state (copied)."""
    st, sk = (state.copy(), stack.copy()) if copy else (state, stack)
    T0 = st[S_T]
    dphi = direction * TINY
    T1 = friction_step(st, sk, dphi, dphi, *p.step_args())
    return (T1 - T0) / dphi


# --- (1) DHM: slope right after any reversal is 2^α σ --------------------------------------
@pytest.mark.parametrize("alpha", [1.0, 2.0])
def test_dhm_slope_after_any_reversal_is_2_pow_alpha_sigma(alpha):
    p = params("DHM", alpha=alpha)
    # reversal points: on the outer branch (positive and negative torque), inside a
    # minor loop, inside a nested minor loop, and close to saturation
    pts = [0.0, 3e-4, 1e-4, 2e-4, 1.5e-4, 1.8e-4, -2e-3, 4e-3]
    T, state, stack = run(p, path_through(*pts))
    state, stack = new_state(p)
    checked = 0
    for a, b, c in zip(pts[:-2], pts[1:-1], pts[2:]):
        leg = path_through(a, b)
        simulate_friction(leg, p, state=state, stack=stack)
        new_dir = 1.0 if c > b else -1.0
        slope = slope_after(p, state, stack, new_dir)
        assert slope == pytest.approx(2.0 ** alpha * SIGMA, rel=1e-5), (a, b, state[S_T])
        checked += 1
    assert checked == len(pts) - 2
    # whereas mid-branch the slope is smaller
    assert slope_after(p, state, stack, state[S_DIR]) < 2.0 ** alpha * SIGMA


# --- (2) DHM minor loop closes and is forgotten ---------------------------------------------
@pytest.mark.parametrize("model", ["DHM", "DB-DHM"])
@pytest.mark.parametrize("alpha", [1.0, 2.0])
def test_minor_loop_closes_where_it_started_and_is_forgotten(model, alpha, table):
    p = params(model, table, alpha=alpha)
    a, b, end = 2.5e-4, 1.2e-4, 6e-4          # up to a, down to b, up past a to end
    n = 500
    T_loop, st_loop, _ = run(p, path_through(0.0, a, b, a, end, n=n))
    T_plain, _, _ = run(p, path_through(0.0, a, end, n=n))   # same grid, no minor loop
    T_a = T_loop[n]                           # torque at the first reversal (φ = a)
    assert T_loop[2 * n] < T_a - 0.1          # a real minor loop
    # the minor-loop branch comes back to T_a exactly when φ returns to a ...
    assert T_loop[3 * n - 1] < T_a
    assert T_loop[3 * n] == pytest.approx(T_a, abs=1e-9)
    # ... and beyond it the curve is the one that never had the minor loop
    assert np.allclose(T_loop[3 * n:], T_plain[n:], rtol=0, atol=1e-9)
    assert T_plain[-1] - T_a > 0.3            # (and that part of the curve is not flat)
    assert st_loop[S_CLOSURES] == 1 and st_loop[S_DEPTH] == 2


def test_minor_loop_closure_inside_one_large_step():
    """A step that crosses the closure point is split there (no dependence on step size)."""
    p = params("DHM")
    fine, _, _ = run(p, path_through(0.0, 2e-4, 1e-4, 8e-4, n=300))
    coarse, _, _ = run(p, np.array([0.0, 2e-4, 1e-4, 8e-4]))
    assert coarse[-1] == pytest.approx(fine[-1], abs=1e-12)


# --- (3) SFM turnaround slope depends on the reversal torque ------------------------------
@pytest.mark.parametrize("alpha", [1.0, 2.0])
def test_sfm_turnaround_slope_varies_with_reversal_torque(alpha):
    sfm, dhm = params("SFM", alpha=alpha), params("DHM", alpha=alpha)
    sfm_slopes, dhm_slopes = [], []
    for top in (5e-5, 1.5e-4, 4e-4):
        for p, out in ((sfm, sfm_slopes), (dhm, dhm_slopes)):
            _, state, stack = run(p, path_through(0.0, top))
            T_r = state[S_T]
            assert T_r > 0
            slope = slope_after(p, state, stack, -1.0)
            out.append(slope)
            if p is sfm:
                assert slope == pytest.approx(SIGMA * (1 + abs(T_r) / TC) ** alpha, rel=1e-5)
    assert sfm_slopes[0] < sfm_slopes[1] < sfm_slopes[2]
    assert np.allclose(dhm_slopes, 2.0 ** alpha * SIGMA, rtol=1e-5)


# --- (4) the reversal stack never overflows silently ---------------------------------------
def nested_reversals(count, step=4e-6):
    """Reversal points alternating around 0 with shrinking amplitude: each loop nests."""
    amps = step * np.arange(count, 0, -1)
    return [0.0] + [a if i % 2 == 0 else -a for i, a in enumerate(amps)]


@pytest.mark.parametrize("model", ["DHM", "DB-DHM"])
def test_stack_overflow_is_counted_and_torque_stays_bounded(model, table):
    p = params(model, table, stack_capacity=8)
    pts = nested_reversals(40)
    T, state, stack = run(p, path_through(*pts, n=20))
    assert state[S_OVERFLOW] >= 1
    assert state[S_REVERSALS] == len(pts) - 2
    assert np.all(np.isfinite(T)) and np.all(np.abs(T) <= TC)
    assert 2 <= state[S_DEPTH] <= 8
    # the same motion with room for every reversal does not overflow
    big = params(model, table, stack_capacity=64)
    _, st_big, _ = run(big, path_through(*pts, n=20))
    assert st_big[S_OVERFLOW] == 0 and st_big[S_DEPTH] == 2 + (len(pts) - 2)
    # the slope right after every reversal is right, also right after an overflow reset
    expect = 2 * SIGMA if model == "DHM" else SIGMA * table[1][0]
    state, stack = new_state(p)
    resets_checked = 0
    for a, b in zip(pts[:-1], pts[1:]):
        simulate_friction(path_through(a, b, n=20), p, state=state, stack=stack)
        st, sk = state.copy(), stack.copy()
        assert slope_after(p, st, sk, -state[S_DIR], copy=False) == pytest.approx(expect, rel=1e-4)
        resets_checked += st[S_OVERFLOW] > state[S_OVERFLOW]
    assert resets_checked >= 1


@pytest.mark.parametrize("model", ["DHM", "DB-DHM"])
def test_periodic_motion_does_not_grow_the_stack(model, table):
    p = params(model, table, stack_capacity=8)
    t = np.arange(20_000) / 12_000.0
    phi = 3e-5 * np.sin(2 * np.pi * 60 * t) + 1e-6 * np.sin(2 * np.pi * 1100 * t)
    T, state, _ = run(p, phi)
    assert state[S_OVERFLOW] == 0
    assert state[S_DEPTH] <= 6
    assert np.all(np.abs(T) <= TC)


# --- (5) DB-DHM follows the slope table, mirrored for negative velocity --------------------
def test_db_dhm_slope_follows_table_and_mirrors(table):
    lx, ly = table
    p = params("DB-DHM", table)
    T, state, stack = run(p, path_through(0.0, 3e-4, 2e-4))     # reversal at 3e-4, going down
    assert slope_after(p, state, stack, 1.0) == pytest.approx(SIGMA * ly[0], rel=1e-4)
    for direction in (+1.0, -1.0):
        st, sk = new_state(p)
        simulate_friction(path_through(0.0, -direction * 5e-3), p, state=st, stack=sk)
        assert slope_after(p, st, sk, direction) == pytest.approx(SIGMA * ly[0], rel=1e-4)
        # walk along the branch; the local slope is σ·f(x), x = (T − T_k)/T_c·sgn
        for _ in range(100):
            friction_step(st, sk, direction * 6e-6, direction, *p.step_args())
            T_k = sk[int(st[S_DEPTH]) - 1]
            x = direction * (st[S_T] - T_k) / TC
            assert 0.0 <= x <= 2.0
            assert slope_after(p, st, sk, direction) == pytest.approx(
                SIGMA * np.interp(x, lx, ly), rel=1e-4, abs=1e-3)
        assert x > 1.0                          # well into the shallow part of the table
    # the negative branch is the mirror image of the positive one
    phi = path_through(0.0, 2e-4, -1e-4, 3e-4, -5e-4)
    T_pos, _, _ = run(p, phi)
    T_neg, _, _ = run(p, -phi)
    assert np.allclose(T_neg, -T_pos, rtol=0, atol=1e-12)


def test_db_sfm_uses_table_with_x_from_coulomb_level(table):
    lx, ly = table
    p = params("DB-SFM", table)
    _, state, stack = run(p, path_through(0.0, -2e-2))              # saturated at −T_c
    assert state[S_T] == pytest.approx(-TC, abs=1e-9)
    assert slope_after(p, state, stack, 1.0) == pytest.approx(SIGMA * ly[0], rel=1e-4)  # x = 0
    _, state, stack = run(p, path_through(0.0, 1e-4))
    x = 1.0 + state[S_T] / TC
    assert slope_after(p, state, stack, 1.0) == pytest.approx(SIGMA * np.interp(x, lx, ly),
                                                              rel=1e-4)


# --- (6) steady sliding saturates at ±T_c, for every model ---------------------------------
@pytest.mark.parametrize("model", list(FRICTION_MODELS))
def test_steady_sliding_converges_to_coulomb_torque(model, table):
    p = params(model, table)
    amp = 50 * TC / SIGMA                    # ≫ T_c/σ (≈ 0.39 mrad)
    phi = path_through(0.0, amp, -amp, amp, -amp, amp, n=300)
    T, state, _ = run(p, phi)
    assert np.all(np.abs(T) <= TC)
    quarter = 300
    for k, sign in ((1, 1), (2, -1), (3, 1), (4, -1), (5, 1)):
        assert T[k * quarter] == pytest.approx(sign * TC, abs=1e-6), (model, k)
    # the loop is a closed, repeatable hysteresis loop once saturated
    assert np.allclose(T[2 * quarter: 3 * quarter], T[4 * quarter: 5 * quarter], atol=1e-9)


@pytest.mark.parametrize("model", list(FRICTION_MODELS))
def test_one_huge_step_cannot_overshoot(model, table):
    p = params(model, table, alpha=0.5)
    for dphi in (1.0, -1.0, 1e3):
        state, stack = new_state(p, 1, T0=0.3)
        T = friction_step(state, stack, dphi, dphi, *p.step_args())
        assert abs(T) <= TC and T == pytest.approx(np.sign(dphi) * TC, abs=1e-9)
    # a large step from inside a minor loop lands on the Coulomb level, not beyond
    T, _, _ = run(p, np.array([0.0, 1e-4, 5e-5, 7e-5, 1.0]))
    assert T[-1] == pytest.approx(TC, abs=1e-9)


def test_split_steps_give_the_same_torque_for_all_models(table):
    pts = [0.0, 2e-4, 1.2e-4, 1.6e-4, 1.4e-4, 5e-4, -3e-4, -1e-4, -2e-4, 1e-3]
    for model in FRICTION_MODELS:
        for alpha in (0.5, 1.0, 2.0):
            p = params(model, table, alpha=alpha)
            fine, _, _ = run(p, path_through(*pts, n=97))
            coarse, _, _ = run(p, np.array(pts))
            assert np.allclose(fine[::97], coarse, rtol=0, atol=1e-12), (model, alpha)


def test_zero_velocity_changes_nothing(table):
    p = params("DB-DHM", table)
    state, stack = new_state(p, 1, T0=0.5)
    before = state.copy(), stack.copy()
    assert friction_step(state, stack, 1e-5, 0.0, *p.step_args()) == 0.5
    assert np.array_equal(state, before[0]) and np.array_equal(stack, before[1])
    T, st, _ = run(p, path_through(0.0, 1e-4, 1e-4, 2e-4))   # a dwell (repeated φ) in a ramp
    assert st[S_REVERSALS] == 0
    assert np.all(np.diff(T) >= 0)


def test_initial_stack_follows_initial_direction():
    p = params("DHM")
    for direction in (1, -1):
        state, stack = new_state(p, direction)
        assert state[S_DEPTH] == 2 and state[S_DIR] == direction
        assert stack[1] == -direction * TC and stack[0] == direction * TC   # T_k on top
        # on the outer branch the DHM and the SFM coincide
        phi = direction * np.linspace(0, 1e-3, 50)
        T_dhm = simulate_friction(phi, p, initial_direction=direction)
        T_sfm = simulate_friction(phi, params("SFM"), initial_direction=direction)
        assert np.allclose(T_dhm, T_sfm, atol=1e-12)


# --- (7) bad slope tables are refused, naming the file --------------------------------------
GOOD_ROWS = "0,12\n0.5,3\n1,1\n2,0\n"


@pytest.mark.parametrize("body, problem", [
    ("x,slope_ratio\n0,1\n0.5,3\n2,0\n", "monotone"),
    ("x,ratio\n" + GOOD_ROWS, "header"),
    ("x,slope_ratio,extra\n" + GOOD_ROWS, "header"),
    ("x,slope_ratio\n0,12,1\n2,0\n", "2 columns"),
    ("x,slope_ratio\n0,12\n1.5,0\n", "cover [0, 2]"),
    ("x,slope_ratio\n0.1,12\n2,0\n", "cover [0, 2]"),
    ("x,slope_ratio\n0,12\n1,2\n1,1\n2,0\n", "strictly increasing"),
    ("x,slope_ratio\n0,1\n2,-1\n", ">= 0"),
    ("x,slope_ratio\n0,1\n", "at least 2 rows"),
    ("x,slope_ratio\n0,abc\n2,0\n", "not a number"),
    ("# only a comment\n", "header"),
])
def test_bad_slope_tables_are_refused(tmp_path, body, problem):
    path = tmp_path / "bad_lut.csv"
    path.write_text("# a comment line\n" + body)
    with pytest.raises(SlopeTableError) as exc:
        load_slope_table(path)
    assert str(path) in str(exc.value) and problem in str(exc.value)
    assert isinstance(exc.value, GroundStationError)
    with pytest.raises(SlopeTableError):
        FrictionParams.from_csv(path)


def test_missing_slope_table_names_the_file(tmp_path):
    path = tmp_path / "nope.csv"
    with pytest.raises(SlopeTableError, match="nope.csv"):
        load_slope_table(path)


@pytest.mark.parametrize("field, value, words", [
    ("sigma", 0.0, "sigma"), ("sigma", -5730.0, "sigma"), ("T_c", 0.0, "T_c"),
    ("T_c", float("nan"), "T_c"), ("alpha", -1.0, "alpha"),
    ("stack_capacity", 3, "[4,"), ("stack_capacity", 8.5, "stack_capacity"),
    ("model", "LuGre", "SFM, DHM, DB-SFM, DB-DHM"),
])
def test_bad_parameters_are_refused(field, value, words):
    kwargs = {"model": "DHM", field: value}
    with pytest.raises(FrictionConfigError) as exc:
        FrictionParams(**kwargs)
    assert words in str(exc.value) and isinstance(exc.value, ValueError)
    assert isinstance(exc.value, GroundStationError)


def test_data_based_model_needs_a_table():
    with pytest.raises(FrictionConfigError, match="slope table"):
        FrictionParams(model="DB-DHM")


# --- (8) the shipped table loads -------------------------------------------------------------
def test_shipped_slope_table_loads():
    assert SHIPPED.resolve() == DEFAULT_SLOPE_TABLE
    assert SHIPPED.read_text().startswith("#")            # header comments kept
    x, y = load_slope_table(SHIPPED)
    assert x[0] == 0.0 and x[-1] == 2.0 and y[0] == 12.0 and y[-1] == 0.0
    assert np.all(np.diff(x) > 0) and np.all(np.diff(y) <= 0)
    p = FrictionParams.from_csv()
    assert p.model == "DB-DHM" and p.sigma == SIGMA and p.T_c == TC and p.alpha == 1.0
    assert np.array_equal(p.lut_x, x)
