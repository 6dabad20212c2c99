"""Tests of ijoy_jax.tune.relax: limits of the relaxation, gradient checks, degenerate inputs."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax.footcost import foot_cost_terms
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.robots import get_leaf, set_leaf
from ijoy_jax.select import prepare, select_step
from ijoy_jax.tune import relax

RES = 0.02
NUM_QUERIES = 24
SCHEDULE = ((3.0, 1.0), (10.0, 0.3), (30.0, 0.1), (100.0, 0.03), (300.0, 0.01))  # (sharpness, tau)
# Fraction of queries whose most probable action is an exact optimum at the end of the schedule.
# Measured: 2D 24/24, 2.5D 20 of 23 valid queries (21 at the slope weight of 0.5; misses are footholds within a
# fraction of a cell of a limit).
FINAL_AGREEMENT = {False: 0.95, True: 0.85}
# Queries the agreement may drop by from one schedule point to the next (finite samples): at the first two points
# (tau 1 and 0.3, above most cost gaps) the mode is close to arbitrary; measured 2.5D: 8 -> 6 of 23 there with
# the slope weight of 1 (7 -> 7 at 0.5), increasing from then on (12, 17, 20; 13, 17, 21 at 0.5).
SLACK = 2
FD_RTOL64 = 1e-5  # float64 central differences, h = 1e-6: truncation ~h^2 and rounding ~1e-16 / h
FD_RTOL32 = 0.05  # float32 check_grads: eps 1e-2 of order-1 central differences on a sharp function


def _terrain(seed: int, has_height: bool) -> ij.Terrain:
    rng = np.random.default_rng(seed)
    n = 60
    free = np.ones((n, n), bool)
    for _ in range(4):
        x, y = rng.integers(0, n, 2)
        a, b = rng.integers(3, 12, 2)
        free[x : x + a, y : y + b] = False
    if not has_height:
        return ij.terrain.from_arrays(None, free, RES)
    xs = np.arange(n) * RES
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    h = np.zeros((n, n))
    for _ in range(3):
        cx, cy = rng.uniform(0, 1.2, 2)
        h += rng.uniform(-0.04, 0.04) * np.exp(-((gx - cx) ** 2 + (gy - cy) ** 2) / 0.02)
    h += (gx > rng.uniform(0.3, 1.0)) * rng.uniform(-0.05, 0.05)
    return ij.terrain.from_arrays(h, free, RES)


def _query(seed: int):
    rng = np.random.default_rng(1000 + seed)
    stance = np.array([0.6 + rng.uniform(-0.1, 0.1), 0.45 + rng.uniform(-0.1, 0.1), rng.uniform(-0.5, 0.5)])
    command = rng.uniform([-0.3, -0.1, -0.4], [0.3, 0.1, 0.4])
    return stance.astype(np.float32), command.astype(np.float32)


@pytest.fixture(scope="module")
def robot():
    return ij.robots.hrp2(margin=0.02, density=0.5, max_margin=0.03)


def _batch(has_height):
    ts = [_terrain(q, has_height) for q in range(NUM_QUERIES)]
    terrains = jax.tree.map(lambda *x: jnp.stack(x), *ts)
    qs = [_query(q) for q in range(NUM_QUERIES)]
    return terrains, jnp.asarray(np.stack([q[0] for q in qs])), jnp.asarray(np.stack([q[1] for q in qs]))


@jax.jit
def _exact_all(terrain, robot, stance, command):
    """Exact choice (quantize=False) and the exact cost of every action of one query."""
    index, targets = prepare(terrain, robot)
    choice = select_step(terrain, robot, stance, -1.0, command, options=ij.SelectOptions(quantize=False),
                         targets=targets, index=index)
    acts = ij.robots.side_actions(robot, 1.0)
    steps = ij.geometry.compose(stance, acts)
    n = acts.shape[0]
    fc = foot_cost_terms(terrain, robot, stance, -1.0, steps, action_index=jnp.arange(n), index=index).total
    p_next = ij.robots.side_p0(robot, 1.0) + robot.step_time * command
    return choice, fc + robot.w * ij.robots.dist(acts, p_next, robot.rotation_weight)


@jax.jit
def _relaxed_all(terrain, robot, stance, command, sharpness, tau):
    return relax.relaxed_select(terrain, robot, stance, -1.0, command, sharpness=sharpness, tau=tau)


@pytest.mark.slow
@pytest.mark.parametrize("has_height", [False, True])
def test_relaxed_selector_converges_to_exact(robot, has_height):
    terrains, stances, commands = _batch(has_height)
    choice, exact_cost = jax.vmap(_exact_all, (0, None, 0, 0))(terrains, robot, stances, commands)
    valid = np.asarray(choice.valid)
    assert valid.sum() >= NUM_QUERIES - 2
    best = np.asarray(choice.cost)
    optimal, invalid = [], []
    for sharpness, tau in SCHEDULE:
        r = jax.vmap(_relaxed_all, (0, None, 0, 0, None, None))(terrains, robot, stances, commands, sharpness, tau)
        assert np.all(np.isfinite(np.asarray(r.cost)))
        assert np.allclose(np.asarray(r.probs).sum(-1), 1.0, atol=1e-5)
        mode = np.asarray(r.mode)
        mode_cost = np.asarray(exact_cost)[np.arange(NUM_QUERIES), mode]
        optimal.append(int(np.sum(valid & (mode_cost <= best + 1e-5))))
        invalid.append(float(np.max(np.where(valid, np.asarray(r.invalid_mass), 0.0))))
    n_valid = int(valid.sum())
    print(f"has_height={has_height}: optimal mode {optimal} of {n_valid}; max invalid mass {invalid}")
    for a, b in zip(optimal, optimal[1:], strict=False):
        assert b >= a - SLACK
    assert optimal[-1] >= FINAL_AGREEMENT[has_height] * n_valid
    assert optimal[-1] > optimal[0]
    assert invalid[-1] < invalid[0] and invalid[-1] < 1e-3


@jax.jit
def _exact_and_soft_paths(terrain, robot, stance, swing_from, sharpness):
    """Exact and relaxed FootCost terms (each field (N,)) of every action's step from ``stance`` (3,), with the
    swing-path check from ``swing_from`` (3,) or without it (None); one program per terrain kind for these tests."""
    acts = ij.robots.side_actions(robot, 1.0)
    steps = ij.geometry.compose(stance, acts)
    idx = jnp.arange(acts.shape[0])
    e = foot_cost_terms(terrain, robot, stance, -1.0, steps, swing_from=swing_from, action_index=idx)
    s = relax.soft_foot_cost_terms(terrain, robot, stance, steps, idx, sharpness=sharpness, swing_from=swing_from)
    return e, s


def test_relaxed_cost_converges_to_exact_finite_costs(robot):
    """On exactly valid steps away from the validity boundary the relaxed FootCost tends to the exact one."""
    terrain = _terrain(3, True)
    stance, _ = _query(3)
    exact = np.asarray(_exact_and_soft_paths(terrain, robot, jnp.asarray(stance), None, 10.0)[0].total)
    ok = np.isfinite(exact)
    assert ok.sum() > 10
    errors = []
    for sharpness in (10.0, 100.0, 1000.0):
        soft = _exact_and_soft_paths(terrain, robot, jnp.asarray(stance), None, sharpness)[1].total
        errors.append(float(np.median(np.abs(np.asarray(soft)[ok] - exact[ok]))))
    print(f"median |relaxed - exact| over {ok.sum()} valid steps: {errors}")
    assert errors[0] > errors[1] > errors[2]
    assert errors[-1] < 0.02


@pytest.mark.slow
def test_relaxed_support_converges_to_the_exact_support(robot):
    """The soft support (the rested sole on tents with rounded corners, its contact polygon's margin an expectation
    over soft contacts) tends to the exact metric (footcost.sole) as the sharpness grows, on a map whose soles rest
    on all of their points, on some and on an edge through their centre."""
    rng = np.random.default_rng(8)
    h = 0.004 * rng.standard_normal((60, 60)) + np.arange(60)[:, None] * RES * 0.1
    terrain = ij.terrain.from_arrays(h.astype(np.float32), None, RES)
    stance, _ = _query(8)
    stance = jnp.asarray(stance)
    exact = np.asarray(_exact_and_soft_paths(terrain, robot, stance, None, 10.0)[0].support_m)
    assert (exact < 1e-6).any() and (exact > 0.05).any()

    def soft_support(k):
        return _exact_and_soft_paths(terrain, robot, stance, None, k)[1].support_m

    errors = [float(np.mean(np.abs(np.asarray(soft_support(k)) - exact))) for k in (10.0, 100.0, 1000.0)]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-3, errors


def _float_leaves(robot, dtype):
    return jax.tree.map(lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x, robot)


SCALAR_LEAVES = (
    "w",
    "rotation_weight",
    "margin",
    "foot_length",
    "foot_width",
    "step_time",
    "metrics.slope_weight",
    "metrics.slope_limit",
    "metrics.roughness_weight",
    "metrics.roughness_limit",
    "metrics.bump_weight",
    "metrics.bump_limit",
    "metrics.step_weight",
    "metrics.band_weight",
    "metrics.band_limit",
    "metrics.support_weight",
    "metrics.support_limit",
    "metrics.contact_inset",
    "metrics.contact_tol",
    "max_sole_pitch",
    "max_sole_roll",
    "max_sole_distance",
)


def _objective(terrain, robot, stance, command, sharpness, tau):
    r = relax.relaxed_select(terrain, robot, stance, -1.0, command, sharpness=sharpness, tau=tau, exact=False)
    return r.expected_cost + r.log_probs[3] + jnp.sum(r.expected_pose)


# One compiled gradient program per objective and dtype serves every gradient test of it: the finite differences
# take the value it returns, and the float32 checks share it with the degenerate-input tests.
_value_and_grad = jax.jit(jax.value_and_grad(_objective, argnums=(1, 2, 3)))


def _check_scaled_grads(value_and_grad, args, names, seed=0):
    """``jax.test_util.check_grads(order=1, modes=("rev",), eps=1e-2)`` of the objective as a function of each
    robot leaf in ``names`` as a multiple of its nominal value (so eps is a relative step), at 1: its reverse-mode
    derivative along a random direction of those scales against central differences, within FD_RTOL32.
    ``value_and_grad(terrain, robot, ...)`` returns the value and the gradients with respect to the robot first."""
    terrain, robot, *rest = args
    nominal = [get_leaf(robot, n) for n in names]

    def scaled(scales):
        rb = robot
        for n, v, s in zip(names, nominal, scales, strict=True):
            rb = set_leaf(rb, n, v * s)
        return rb

    ones = np.ones(len(names), np.float32)
    d = np.random.default_rng(seed).normal(size=len(names)).astype(np.float32)
    _, grads = value_and_grad(terrain, scaled(ones), *rest)
    an = sum(float(jnp.sum(get_leaf(grads[0], n) * v)) * float(di) for n, v, di in zip(names, nominal, d, strict=True))
    eps = 1e-2
    plus = float(value_and_grad(terrain, scaled(ones + eps * d), *rest)[0])
    minus = float(value_and_grad(terrain, scaled(ones - eps * d), *rest)[0])
    fd = (plus - minus) / (2 * eps)
    np.testing.assert_allclose(an, fd, atol=FD_RTOL32, rtol=FD_RTOL32)


@pytest.mark.slow
def test_gradients_match_finite_differences_float64(small_robot):
    """Every scalar and per-action leaf, the stance pose and the command, against float64 central differences.

    The objective is the swing-path one (the selection objective plus the corridor heights), so this check and
    test_swing_path_gradients_float64 share one float64 program; the objective without a swing start keeps its
    float32 check (test_gradients_float32_check_grads)."""
    with jax.enable_x64(True):
        terrain = _terrain(5, True)
        terrain = terrain.replace(height=terrain.height.astype(jnp.float64), origin=terrain.origin.astype(jnp.float64))
        r64 = _float_leaves(small_robot, jnp.float64)
        stance, command = (jnp.asarray(x, jnp.float64) for x in _query(5))
        swing_from = jnp.asarray(SWING_FROM, jnp.float64)

        def f(rb, pose, cmd):
            return _swing_value_and_grad(terrain, rb, pose, swing_from, cmd, 10.0, 1.0)[0]

        _, grads = _swing_value_and_grad(terrain, r64, stance, swing_from, command, 10.0, 1.0)
        worst = 0.0
        h = 1e-6
        for name in SCALAR_LEAVES + ("action_cost", "max_step_height"):
            leaf = get_leaf(r64, name)
            g = get_leaf(grads[0], name)
            direction = jnp.asarray(np.random.default_rng(len(name)).normal(size=leaf.shape))
            fd = (
                f(set_leaf(r64, name, leaf + h * direction), stance, command)
                - f(set_leaf(r64, name, leaf - h * direction), stance, command)
            ) / (2 * h)
            an = jnp.sum(g * direction)
            assert np.isfinite(float(an)), name
            err = abs(float(fd - an)) / max(1.0, abs(float(fd)))
            worst = max(worst, err)
            assert err < FD_RTOL64, (name, float(fd), float(an))
        for k, (x, g) in enumerate(((stance, grads[1]), (command, grads[3]))):
            d = jnp.asarray(np.random.default_rng(k).normal(size=3))
            xs = [a if j != k else None for j, a in enumerate((stance, command))]
            plus, minus = list(xs), list(xs)
            plus[k], minus[k] = x + h * d, x - h * d
            fd = (f(r64, plus[0], plus[1]) - f(r64, minus[0], minus[1])) / (2 * h)
            err = abs(float(fd - g @ d)) / max(1.0, abs(float(fd)))
            worst = max(worst, err)
            assert err < FD_RTOL64, ("pose" if k == 0 else "command", float(fd), float(g @ d))
        print(f"float64 worst relative gradient error: {worst:.2e}")


@pytest.mark.slow
def test_gradients_float32_check_grads(robot):
    terrain = _terrain(6, True)
    stance, command = _query(6)
    names = ("w", "rotation_weight", "margin", "foot_length", "step_time", "metrics.slope_limit")
    args = (terrain, robot, jnp.asarray(stance), jnp.asarray(command), 5.0, 3.0)
    _check_scaled_grads(_value_and_grad, args, names)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["zero_area", "cell_corner", "all_obstacle"])
@pytest.mark.parametrize("has_height", [False, True])
def test_no_nan_at_degenerate_inputs(robot, case, has_height):
    terrain = _terrain(7, has_height)
    stance = np.array([0.6, 0.4, 0.0], np.float32)  # on a cell corner
    command = np.zeros(3, np.float32)
    rb = robot
    if case == "zero_area":
        rb = robot.replace(foot_length=jnp.float32(0.0), foot_width=jnp.float32(0.0), margin=jnp.float32(0.0))
    elif case == "all_obstacle":
        terrain = terrain.replace(free=jnp.zeros_like(terrain.free))
    elif case == "cell_corner":
        command = np.array([0.05, 0.0, 0.0], np.float32) / 0.8  # p_next on a corner too

    val, grads = _value_and_grad(terrain, rb, jnp.asarray(stance), jnp.asarray(command), 20.0, 0.5)
    assert np.isfinite(float(val))
    for g in jax.tree.leaves(grads):
        assert np.all(np.isfinite(np.asarray(g)))
    r = relax.relaxed_select_jit(terrain, rb, stance, -1, command, sharpness=20.0, tau=0.5)
    assert np.all(np.isfinite(np.asarray(r.cost)))
    if case == "all_obstacle":
        assert float(r.invalid_mass) == pytest.approx(1.0)


def test_no_recompile_across_parameters(robot):
    terrain = _terrain(8, False)
    stance, command = _query(8)
    f = jax.jit(_objective)
    f(terrain, robot, stance, command, 10.0, 1.0)
    n = compiled_count(f)
    f(terrain, robot.replace(w=jnp.float32(2.0)), stance, command, 30.0, 0.1)
    assert compiled_count(f) == n


# ---------------------------------------------------------------------------
# Relaxed swing-path check (swing_from).

SWING_SCHEDULE = (3.0, 30.0, 300.0, 1000.0)  # sharpness
SWING_FROM = np.array([0.5, 0.62, 0.0], np.float32)  # left foot behind the right stance foot below
SWING_STANCE = np.array([0.6, 0.45, 0.1], np.float32)
# Soft corridor height vs exact at the largest sharpness: the soft max over K^2 = 50^2 gated cells is biased
# by at most temp * log(K^2 + 1) = (0.02 / 1000) * 7.8 = 1.6e-4 m (median); the worst step also carries the
# soft foothold planes' error next to a bar (measured 7e-4 m).
PATH_HEIGHT_MEDIAN_ATOL = 2e-4
PATH_HEIGHT_MAX_ATOL = 2e-3


def _bar_terrain(seed: int) -> ij.Terrain:
    """Flat ground with three 2-cell-thick bars 5-20 cm high across the swing paths (free cells)."""
    rng = np.random.default_rng(seed)
    n = 60
    h = np.zeros((n, n))
    for _ in range(3):
        x, y0 = rng.integers(10, 50), rng.integers(0, 40)
        h[x : x + 2, y0 : y0 + rng.integers(10, 30)] = rng.uniform(0.05, 0.2)
    return ij.terrain.from_arrays(h, None, RES)


@pytest.mark.slow
def test_swing_path_converges_to_exact(robot):
    agreement, height_err = [], []
    n_bad = 0
    for seed in range(3):
        terrain = _bar_terrain(seed)
        row_a, row_e = [], []
        for sharpness in SWING_SCHEDULE:
            e, s = _exact_and_soft_paths(terrain, robot, SWING_STANCE, SWING_FROM, sharpness)
            bad = np.isinf(np.asarray(e.swing_path))
            soft = np.asarray(s.swing_path)
            assert np.all(np.isfinite(soft))
            row_a.append(float(np.mean((soft > 1.0) == bad)))
            dh = np.maximum(np.asarray(e.path_height_m), 0.0) - np.asarray(s.path_height_m)
            row_e.append((float(np.median(np.abs(dh))), float(np.max(np.abs(dh)))))
        n_bad += int(bad.sum())
        # At the largest sharpness the barrier is ~0 on exactly clear corridors and large on blocked ones.
        assert np.all(soft[~bad] < 1e-3) and np.all(soft[bad] > 10.0), seed
        agreement.append(row_a)
        height_err.append(row_e)
    print(f"swing-path agreement per terrain over sharpness {SWING_SCHEDULE}: {agreement}; "
          f"(median, max) |dh| {height_err}")
    assert n_bad > 10  # the bars do block some swings
    for row_a, row_e in zip(agreement, height_err, strict=True):
        assert row_a[-1] == 1.0
        assert all(b[0] < a[0] for a, b in zip(row_e, row_e[1:], strict=False))
        assert row_e[-1][0] < PATH_HEIGHT_MEDIAN_ATOL and row_e[-1][1] < PATH_HEIGHT_MAX_ATOL


def _post_terrain(seed: int) -> ij.Terrain:
    """Flat ground with one 4 cm x 4 cm post, 20 cm high (twice the clearance), across the swing's way."""
    rng = np.random.default_rng(seed)
    h = np.zeros((60, 60))
    x, y = rng.integers(26, 31), rng.integers(28, 35)
    h[x : x + 2, y : y + 2] = 0.2
    return ij.terrain.from_arrays(h, None, RES)


NUM_POST_QUERIES = 8


@pytest.mark.slow
def test_relaxed_select_with_swing_from_matches_exact(robot):
    """The mode equals ``select_step(swing_from=...)``'s choice, and the swing check changes most choices.

    The swing foot starts 20 cm behind the stance foot, a post stands between it and the commanded step.
    Measured: 8/8 modes agree, the check changes 7/8 exact choices. (Bars next to a foothold are avoided
    here: the soft band/bump metrics weight cells just outside the footprint by their membership, which
    lets a tall cell within its height of the foot leak in at any sharpness; see the report.)
    """
    stance = np.array([0.6, 0.45, 0.0], np.float32)
    swing_from = np.array([0.4, 0.64, 0.0], np.float32)
    agree = changed = 0
    for seed in range(NUM_POST_QUERIES):
        terrain = _post_terrain(seed)
        command = np.random.default_rng(100 + seed).uniform([0.1, -0.1, -0.3], [0.3, 0.1, 0.3]).astype(np.float32)
        e = ij.select_step(terrain, robot, stance, -1, command, swing_from=swing_from,
                           options=ij.SelectOptions(quantize=False))
        e0 = ij.select_step(terrain, robot, stance, -1, command, options=ij.SelectOptions(quantize=False))
        r = relax.relaxed_select_jit(
            terrain, robot, stance, -1, command, sharpness=300.0, tau=0.01, swing_from=swing_from
        )
        assert bool(e.valid)
        assert float(r.invalid_mass) < 1e-3
        agree += int(r.mode) == int(e.index)
        changed += int(e.index) != int(e0.index)
    print(f"swing_from: relaxed mode = exact choice in {agree}/{NUM_POST_QUERIES}; check changed {changed}")
    assert agree == NUM_POST_QUERIES
    assert changed >= NUM_POST_QUERIES // 2


@pytest.fixture(scope="module")
def small_robot():
    """19 actions: gradient checks compile and run several times faster than with 117."""
    return ij.robots.hrp2(margin=0.02, density=0.25, max_margin=0.03)


def _swing_objective(terrain, robot, stance, swing_from, command, sharpness, tau):
    r = relax.relaxed_select(
        terrain, robot, stance, -1.0, command, sharpness=sharpness, tau=tau, exact=False, swing_from=swing_from
    )
    return r.expected_cost + r.log_probs[3] + jnp.sum(r.expected_pose) + jnp.sum(r.terms.path_height_m)


_swing_value_and_grad = jax.jit(jax.value_and_grad(_swing_objective, argnums=(1, 2, 3, 4)))


@pytest.mark.slow
def test_swing_path_gradients_float64(small_robot):
    robot = small_robot
    with jax.enable_x64(True):
        terrain = _bar_terrain(1)
        terrain = terrain.replace(height=terrain.height.astype(jnp.float64), origin=terrain.origin.astype(jnp.float64))
        r64 = _float_leaves(robot, jnp.float64)
        stance = jnp.asarray(SWING_STANCE, jnp.float64)
        swing_from = jnp.asarray(SWING_FROM, jnp.float64)
        command = jnp.array([0.2, 0.05, 0.1])

        def f(*a):
            return _swing_value_and_grad(*a)[0]

        _, grads = _swing_value_and_grad(terrain, r64, stance, swing_from, command, 10.0, 1.0)
        h = 1e-6
        worst = 0.0
        for name in ("clearance", "foot_width", "foot_length", "w", "margin"):
            leaf = get_leaf(r64, name)
            d = jnp.asarray(np.random.default_rng(len(name)).normal(size=leaf.shape))
            fd = (
                f(terrain, set_leaf(r64, name, leaf + h * d), stance, swing_from, command, 10.0, 1.0)
                - f(terrain, set_leaf(r64, name, leaf - h * d), stance, swing_from, command, 10.0, 1.0)
            ) / (2 * h)
            an = float(jnp.sum(get_leaf(grads[0], name) * d))
            err = abs(float(fd) - an) / max(1.0, abs(float(fd)))
            worst = max(worst, err)
            assert err < FD_RTOL64, (name, float(fd), an)
        assert abs(float(jnp.sum(grads[0].clearance))) > 0  # the clearance barrier is active somewhere
        for k, g in ((2, grads[1]), (3, grads[2])):
            d = jnp.asarray(np.random.default_rng(10 + k).normal(size=3))
            args = [terrain, r64, stance, swing_from, command, 10.0, 1.0]
            plus, minus = list(args), list(args)
            plus[k], minus[k] = args[k] + h * d, args[k] - h * d
            fd = (f(*plus) - f(*minus)) / (2 * h)
            err = abs(float(fd) - float(g @ d)) / max(1.0, abs(float(fd)))
            worst = max(worst, err)
            assert err < FD_RTOL64, (k, float(fd), float(g @ d))
        print(f"swing path float64 worst relative gradient error: {worst:.2e}")


@pytest.mark.slow
def test_swing_path_gradients_float32_check_grads(small_robot):
    robot = small_robot
    terrain = _bar_terrain(2)
    names = ("clearance", "foot_width", "w")
    args = (terrain, robot, jnp.asarray(SWING_STANCE), jnp.asarray(SWING_FROM), jnp.array([0.2, 0.05, 0.1]), 5.0, 3.0)
    _check_scaled_grads(_swing_value_and_grad, args, names)


@pytest.mark.slow
def test_swing_path_zero_length_swing_is_finite(small_robot):
    robot = small_robot
    """A swing that ends where it starts (corridor of zero length) has finite values and gradients."""
    terrain = _bar_terrain(0)
    stance = jnp.asarray(SWING_STANCE)
    swing_from = ij.geometry.compose(stance, ij.robots.side_actions(robot, 1.0)[5])  # exactly on candidate 5
    val, grads = _swing_value_and_grad(terrain, robot, stance, swing_from, jnp.zeros(3), 20.0, 0.5)
    assert np.isfinite(float(val))
    for g in jax.tree.leaves(grads):
        assert np.all(np.isfinite(np.asarray(g)))


@pytest.mark.slow
def test_tall_cell_beside_the_band_does_not_leak_into_bump_or_band():
    """A 0.3 m column one cell outside the grown footprint: exact bump and band are 0, and the soft ones are
    under 1 cm at sharpness 30 (memberships scale the values; as log-sum-exp weights the column leaked 0.26 m
    into band at sharpness 10 and 30, and only dropped out from about 100)."""
    res = 0.02
    h = np.zeros((40, 40), np.float32)
    robot = ij.robots.hrp2(margin=0.02)
    pose = np.array([0.4, 0.4, 0.0], np.float32)
    # the grown footprint reaches x = 0.4 + 0.121 + 0.02 = 0.541; the column is the cell [0.56, 0.58)
    i = int((0.541 + 0.02) / res)
    h[i, 20] = 0.3
    terrain = ij.terrain.from_arrays(h, None, res)
    idx = jnp.zeros(1, jnp.int32)
    exact = ij.foot_cost_terms(terrain, robot, pose, 1, pose[None], action_index=idx)
    assert float(exact.bump_m[0]) == 0.0 and float(exact.band_m[0]) == 0.0
    soft = [relax.soft_foot_cost_terms(terrain, robot, pose, pose[None], idx, sharpness=k) for k in (10.0, 30.0)]
    assert float(soft[1].bump_m[0]) < 0.01 and float(soft[1].band_m[0]) < 0.01
    assert float(soft[1].band_m[0]) <= float(soft[0].band_m[0]) + 1e-6
