"""Step selection: exhaustive vs the paper's ordered search vs a NumPy reference, and edge cases."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import select
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.testing import NumpyFootCost, foothold, ordered_select, rect_touches_cells

RES = 0.02
ROBOT = ij.robots.hrp2(margin=0.02)
TARGETS = ij.make_targets(ROBOT)
SHAPE = (48, 48)
# Two actions whose costs differ by less than float32 rounding of the sums
# involved may be ranked differently by differently fused computations.
TIE = 1e-5


def _random_terrains(seed, n, has_height):
    rng = np.random.default_rng(seed)
    free = rng.random((n,) + SHAPE) > rng.uniform(0.0, 0.03, (n, 1, 1))
    # a few walls and blocks so that some queries have no valid step at all
    for k in range(n):
        if rng.random() < 0.3:
            a, b = rng.integers(0, SHAPE[0] - 8, 2)
            free[k, a:a + rng.integers(2, 30), b:b + rng.integers(2, 30)] = False
    height = np.zeros((n,) + SHAPE, np.float32)
    if has_height:
        ramp = rng.uniform(-0.2, 0.2, (n, 1, 1)) * np.arange(SHAPE[0])[None, :, None] * RES
        steps = 0.03 * (np.arange(SHAPE[1])[None, None, :] > rng.integers(10, 40, (n, 1, 1)))
        # 1 mm cell noise: at 2 mm the former lean term (1.5 mm) rejected most steps, and few queries had a choice
        height = (ramp + steps + 0.001 * rng.standard_normal((n,) + SHAPE)).astype(np.float32)
    return ij.Terrain(jnp.asarray(height), jnp.asarray(free), jnp.zeros((n, 2)), RES, has_height)


def _random_queries(seed, n):
    rng = np.random.default_rng(seed)
    stance = np.column_stack([rng.uniform(0.35, 0.6, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    side = rng.choice([-1, 1], n)
    command = np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-0.2, 0.2, n), rng.uniform(-0.5, 0.5, n)])
    # swing foot somewhere behind-beside the stance foot (what a previous step would leave)
    rel = np.column_stack([rng.uniform(-0.2, 0.2, n), -side * rng.uniform(0.19, 0.33, n), rng.uniform(-0.3, 0.3, n)])
    c, s = np.cos(stance[:, 2]), np.sin(stance[:, 2])
    swing_from = np.column_stack([stance[:, 0] + c * rel[:, 0] - s * rel[:, 1],
                                  stance[:, 1] + s * rel[:, 0] + c * rel[:, 1], stance[:, 2] + rel[:, 2]])
    return [jnp.asarray(a, jnp.float32) for a in (stance, side, command, swing_from)]


def _batched(method, with_path):
    def one(t, st, sd, cmd, sw):
        return ij.select_step(t, ROBOT, st, sd, cmd, options=ij.SelectOptions(method=method),
                              swing_from=sw if with_path else None,
                              targets=TARGETS)

    # lax.map in vmapped chunks: 2.5D windows of thousands of decisions at once would not fit in memory.
    return jax.jit(lambda *args: jax.lax.map(lambda a: one(*a), args, batch_size=128))


def _agree(a, b):
    ia, ib = np.asarray(a.index), np.asarray(b.index)
    ca, cb = np.asarray(a.cost), np.asarray(b.cost)
    np.testing.assert_array_equal(np.asarray(a.valid), np.asarray(b.valid))
    np.testing.assert_array_equal(np.isinf(ca), np.isinf(cb))
    fin = np.isfinite(ca)
    np.testing.assert_allclose(ca[fin], cb[fin], rtol=TIE, atol=TIE)
    fa, fb = np.asarray(a.foot_cost), np.asarray(b.foot_cost)
    same = (ia == ib) & fin
    np.testing.assert_allclose(fa[same], fb[same], rtol=TIE, atol=TIE)
    differ = ia != ib
    # Different indices only where the two costs tie to rounding.
    assert np.all(np.abs(ca[differ & fin] - cb[differ & fin]) <= TIE)
    # The same step has the same full foothold (one plane fit of the same pose in either program).
    np.testing.assert_allclose(np.asarray(a.foothold)[~differ], np.asarray(b.foothold)[~differ], atol=1e-6)
    return differ.mean()


@pytest.mark.slow
@pytest.mark.parametrize("has_height", [False, True])
def test_ordered_equals_exhaustive_on_thousands_of_random_queries(has_height):
    n_t, n_q = (32, 64) if not has_height else (32, 32)  # 2048 (2D) + 1024 (2.5D) decisions
    terrains = _random_terrains(1 + has_height, n_t, has_height)
    queries = _random_queries(3 + has_height, n_t * n_q)
    rep = jax.tree_util.tree_map(lambda x: jnp.repeat(x, n_q, axis=0), terrains)
    ex = _batched("exhaustive", has_height)(rep, *queries)
    od = _batched("ordered", has_height)(rep, *queries)
    assert _agree(ex, od) < 0.01
    valid = np.asarray(ex.valid)
    assert 0.02 < 1 - valid.mean() < 0.6, "the random set must contain both valid and blocked queries"
    # The early exit really happens: the ordered search evaluates fewer actions on average.
    assert np.asarray(od.evaluated).mean() < 0.6 * ROBOT.num_actions
    assert np.all(np.asarray(ex.evaluated) == ROBOT.num_actions)


@pytest.mark.parametrize("has_height", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_matches_numpy_reference_of_the_papers_algorithm(has_height):
    terrains = _random_terrains(7 + has_height, 6, has_height)
    stance, side, command, swing_from = _random_queries(9, 60)
    got = _batched("ordered", has_height)(
        jax.tree_util.tree_map(lambda x: jnp.repeat(x, 10, axis=0), terrains), stance, side, command, swing_from)
    for q in range(60):
        t = jax.tree_util.tree_map(lambda x, q=q: x[q // 10], terrains)
        ref_i, ref_c, _ = ordered_select(NumpyFootCost(t, ROBOT), TARGETS, np.asarray(stance[q], np.float64),
                                         int(side[q]), np.asarray(command[q]),
                                         np.asarray(swing_from[q], np.float64) if has_height else None)
        assert bool(got.valid[q]) == (ref_i >= 0), q
        if ref_i >= 0:
            # float32 JAX vs float64 NumPy: costs to 1e-4; the index agrees unless costs tie to that.
            assert float(got.cost[q]) == pytest.approx(ref_c, abs=1e-4), q
            assert int(got.index[q]) == ref_i or abs(float(got.cost[q]) - ref_c) < 1e-4, q


@pytest.mark.slow
def test_exhaustive_is_the_brute_force_argmin_of_public_foot_cost_and_of_action_foot_costs():
    terrains = _random_terrains(11, 1, True)
    t = jax.tree_util.tree_map(lambda x: x[0], terrains)
    stance, side, command, swing_from = _random_queries(12, 20)
    for q in range(20):
        ch = ij.select_step(t, ROBOT, stance[q], side[q], command[q], swing_from=swing_from[q],
                            options=ij.SelectOptions(quantize=False))
        steps = ij.action_steps(ROBOT, stance[q], side[q])
        fc = np.asarray(ij.foot_cost(t, ROBOT, stance[q], side[q], steps, swing_from=swing_from[q],
                                     action_index=np.arange(496)), np.float64)
        p_next = np.asarray(ROBOT.p0) * [1, -float(side[q]), -float(side[q])] + 0.8 * np.asarray(command[q])
        rel = np.asarray(ij.geometry.relative(stance[q], steps), np.float64)
        d = np.hypot(*(rel[:, :2] - p_next[:2]).T) + 100 * np.abs((rel[:, 2] - p_next[2] + np.pi) % (2 * np.pi) - np.pi)
        total = fc + d
        # action_foot_costs is that one evaluation, and select_step decides the same from it.
        every = select.action_foot_costs(t, ROBOT, stance[q], side[q], swing_from=swing_from[q])
        np.testing.assert_array_equal(np.asarray(every, np.float64), fc)
        if q < 6:
            again = ij.select_step(t, ROBOT, stance[q], side[q], command[q], swing_from=swing_from[q],
                                   options=ij.SelectOptions(quantize=False),
                                   foot_costs=every)
            assert int(again.index) == int(ch.index) and float(again.cost) == float(ch.cost)
        if np.isinf(total).all():
            assert not bool(ch.valid) and int(ch.index) == -1
            continue
        assert float(ch.cost) == pytest.approx(total.min(), rel=1e-5, abs=1e-5)
        assert total[int(ch.index)] <= total.min() + 1e-5
        assert float(ch.foot_cost) == pytest.approx(fc[int(ch.index)], rel=1e-5, abs=1e-6)


@pytest.mark.slow
def test_a_shifted_world_frame_gives_the_same_steps_shifted_and_a_utm_frame_is_refused():
    h = np.asarray(_random_terrains(21, 1, True).height[0])
    stance, side, command, swing_from = (np.asarray(a[0], np.float64) for a in _random_queries(22, 1))
    shift = np.array([1000.0, -2000.0, 0.0])  # float32 keeps 0.1 mm here
    base = ij.terrain.from_arrays(h, None, RES)
    moved = ij.terrain.from_arrays(h, None, RES, origin=shift[:2])
    a = ij.select_step(base, ROBOT, stance, side, command, swing_from=swing_from, targets=TARGETS)
    b = ij.select_step(moved, ROBOT, stance + shift, side, command, swing_from=swing_from + shift, targets=TARGETS)
    assert bool(a.valid) and int(a.index) == int(b.index)
    np.testing.assert_allclose(np.asarray(b.pose, np.float64) - shift, np.asarray(a.pose), atol=2e-4)
    utm = ij.terrain.from_arrays(h, None, RES, origin=(5e5, 5.2e6))
    far = stance + [5e5, 5.2e6, 0.0]
    with pytest.raises(ValueError, match="shift your world frame"):
        ij.select_step(utm, ROBOT, far, side, command, targets=TARGETS)
    with pytest.raises(ValueError, match="shift your world frame"):
        ij.rollout(utm, ROBOT, np.stack([far, far + [0.0, 0.19, 0.0]]), [0.2, 0.0, 0.0], 2)


@pytest.mark.slow
def test_no_valid_step_is_explicit_and_finite():
    t = ij.terrain.from_arrays(None, np.zeros(SHAPE, bool), RES)  # all obstacle
    for method in select.METHODS:
        ch = ij.select_step(t, ROBOT, [0.5, 0.5, 0.0], -1, [0.2, 0.0, 0.0], options=ij.SelectOptions(method=method))
        assert not bool(ch.valid) and np.isinf(float(ch.cost))
        assert np.all(np.isfinite(np.asarray(ch.pose)))
        # the foothold is the reported pose's, level on a 2D map
        level = np.asarray(ch.pose)[[0, 1, 0, 0, 0, 2]] * [1, 1, 0, 0, 0, 1]
        np.testing.assert_array_equal(np.asarray(ch.foothold), level)
        if method != "naive":
            assert int(ch.index) == -1
            # the reported pose is stepping in place, never NaN
            np.testing.assert_allclose(np.asarray(ch.pose), [0.5, 0.69, 0.0], atol=1e-6)
    # On a 2.5D map with no valid step: the step in place's foothold, on the plane under it (a 10 deg ramp).
    h = np.tan(math.radians(10.0)) * (np.arange(SHAPE[0]) + 0.5)[:, None] * RES * np.ones((1, SHAPE[1]))
    t = ij.terrain.from_arrays(h, np.zeros(SHAPE, bool), RES)
    ch = ij.select_step(t, ROBOT, [0.5, 0.5, 0.0], -1, [0.2, 0.0, 0.0], targets=TARGETS)
    assert not bool(ch.valid) and int(ch.index) == -1
    np.testing.assert_allclose(np.asarray(ch.foothold), [0.5, 0.69, math.tan(math.radians(10.0)) * 0.5, 0.0,
                                                         -math.radians(10.0), 0.0], atol=2e-5)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_command_means_step_in_place_and_is_flagged(bad):
    t = ij.terrain.flat(SHAPE, RES)
    ch = ij.select_step(t, ROBOT, [0.5, 0.5, 0.0], -1, [0.2, bad, 0.0])
    ref = ij.select_step(t, ROBOT, [0.5, 0.5, 0.0], -1, [0.0, 0.0, 0.0])
    assert not bool(ch.command_ok) and bool(ref.command_ok)
    np.testing.assert_array_equal(np.asarray(ch.pose), np.asarray(ref.pose))
    np.testing.assert_allclose(np.asarray(ch.pose), [0.5, 0.69, 0.0], atol=1e-6)  # p0: in place


def test_commanded_rotation_is_preferred_when_valid():
    """A step with the commanded rotation beats any closer step with another rotation."""
    free = np.ones(SHAPE, bool)
    t = ij.terrain.from_arrays(None, free, RES)
    stance = np.array([0.4, 0.4, 0.0])
    dth = math.radians(20.0) / 3  # one lattice rotation
    ch = ij.select_step(t, ROBOT, stance, -1, [0.25, 0.0, dth / 0.8])
    assert float(ch.pose[2]) == pytest.approx(dth, abs=1e-5)
    # Block every step with that rotation except far ones: still the commanded rotation wins.
    steps = np.asarray(ij.action_steps(ROBOT, stance, -1))
    rot_ok = np.isclose(steps[:, 2], dth, atol=1e-5)
    fc = np.asarray(ij.foot_cost(t, ROBOT, stance, -1, steps, action_index=np.arange(496)))
    assert np.all(fc[rot_ok] == 0)
    # Wall in front of the forward steps: the chosen step keeps the rotation, moving less far.
    free2 = free.copy()
    free2[int(0.62 / RES):, :] = False
    t2 = ij.terrain.from_arrays(None, free2, RES)
    ch2 = ij.select_step(t2, ROBOT, stance, -1, [0.25, 0.0, dth / 0.8])
    assert bool(ch2.valid) and float(ch2.pose[2]) == pytest.approx(dth, abs=1e-5)
    assert float(ch2.pose[0]) < float(ch.pose[0])


def test_quantize_scores_against_f_or_p_next():
    t = ij.terrain.flat(SHAPE, RES)
    cmd = np.array([0.113, 0.031, 0.0])
    q = ij.select_step(t, ROBOT, [0.4, 0.4, 0.0], -1, cmd)
    p = ij.select_step(t, ROBOT, [0.4, 0.4, 0.0], -1, cmd, options=ij.SelectOptions(quantize=False))
    p_next = np.array([0.4, 0.4 + 0.19, 0.0]) + 0.8 * cmd
    np.testing.assert_allclose(np.asarray(p.target), p_next, atol=1e-6)
    f = np.asarray(q.target)
    # f_i is on the lattice (half an action spacing) and within half a spacing of p_next
    assert abs(f[0] - p_next[0]) <= 0.0125 + 1e-6 and abs(f[1] - p_next[1]) <= 0.005 + 1e-6
    assert float(q.cost) == pytest.approx(float(np.hypot(*(np.asarray(q.pose)[:2] - f[:2]))), abs=1e-6)


def test_naive_takes_the_nearest_action_whatever_the_terrain():
    free = np.ones(SHAPE, bool)
    free[int(0.55 / RES):int(0.7 / RES), :] = False
    t = ij.terrain.from_arrays(None, free, RES)
    ch = ij.select_step(t, ROBOT, [0.4, 0.4, 0.0], -1, [0.25, 0.0, 0.0], options=ij.SelectOptions(method="naive"))
    np.testing.assert_allclose(np.asarray(ch.pose), [0.6, 0.59, 0.0], atol=1e-6)
    assert not bool(ch.valid) and int(ch.index) >= 0


def test_no_recompile_across_parameters_and_commands():
    t = _random_terrains(5, 1, True)
    t = jax.tree_util.tree_map(lambda x: x[0], t)
    args = ([0.5, 0.5, 0.1], 1)
    ij.select_step(t, ROBOT, *args, [0.1, 0.0, 0.0], targets=TARGETS)
    n = select.compiled_programs()
    for r, cmd in [(ROBOT.replace(w=jnp.float32(5.0)), [0.2, 0.1, 0.0]),
                   (ROBOT.replace(margin=jnp.float32(0.1)), [0.0, 0.0, 0.3]),
                   (ROBOT.replace(step_time=jnp.float32(0.5)), [np.nan, 0.0, 0.0]),
                   (ROBOT.replace(max_sole_roll=jnp.float32(0.05), max_sole_distance=jnp.float32(0.3)),
                    [0.2, 0.0, 0.1])]:
        ij.select_step(t, r, *args, cmd, targets=TARGETS)
    assert select.compiled_programs() == n


@pytest.mark.slow
def test_prepared_tables_give_the_same_choice_and_checks_run_inside_jit():
    """``prepare`` builds what select_step builds by itself; the checks also run when select_step is traced."""
    t = jax.tree_util.tree_map(lambda x: x[0], _random_terrains(6, 1, True))
    p = select.prepare(t, ROBOT)
    assert isinstance(p.index, ij.footcost.TerrainIndex) and p.targets.order.shape == TARGETS.order.shape
    args = ([0.5, 0.5, 0.1], -1, [0.2, 0.05, 0.1])
    a = ij.select_step(t, ROBOT, *args, options=ij.SelectOptions(method="ordered"), swing_from=[0.45, 0.7, 0.0])
    b = ij.select_step(t, ROBOT, *args, options=ij.SelectOptions(method="ordered"), swing_from=[0.45, 0.7, 0.0],
                       index=p.index,
                       targets=p.targets)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    with pytest.raises(ValueError, match="command"):
        jax.jit(lambda s: ij.select_step(t, ROBOT, s, -1, jnp.zeros(2)))(jnp.zeros(3))
    with pytest.raises(ValueError, match="method"):
        jax.jit(lambda s: ij.select_step(t, ROBOT, s, -1, jnp.zeros(3),
                                         options=ij.SelectOptions(method="astar")))(jnp.zeros(3))
    with pytest.raises(TypeError, match="index"):
        ij.select_step(t, ROBOT, *args, index=p.targets)


def test_on_obstacle_is_the_bare_footprint_against_the_map():
    free = np.ones(SHAPE, bool)
    free[30:, :] = False  # obstacle from x = 0.6 m
    t = ij.terrain.from_arrays(None, free, RES)
    half = 0.5 * float(ROBOT.foot_length)
    # The bare footprint's front edge 1 mm before the obstacle: clear, although the margin would touch it.
    clear = [0.6 - half - 0.001, 0.5, 0.0]
    assert not bool(select.on_obstacle(t, ROBOT, clear))
    assert bool(select.on_obstacle(t, ROBOT, [0.6 - half + 0.005, 0.5, 0.0]))
    assert bool(select.on_obstacle(t, ROBOT, [0.05, 0.5, 0.0]))  # leaves the map
    assert np.isinf(float(ij.foot_cost(t, ROBOT, [0.3, 0.6, 0.0], -1, [clear], action_index=[0])[0]))


@pytest.mark.slow
def test_on_obstacle_is_footcosts_obstacle_term_and_the_cells_the_footprint_covers():
    """On a map of scattered obstacle cells, for random poses (some leaving the map) and margins: True exactly
    where FootCost's obstacle term of the footprint grown by the margin is +inf, and where a float64 brute force
    over every cell (the rectangle against each cell's interior) finds an obstacle or a cell off the map. Poses
    within 0.1 mm of a cell boundary, where float32 and float64 may round apart, are left to the first check."""
    rng = np.random.default_rng(7)
    free = rng.random(SHAPE) > 0.006
    t = ij.terrain.from_arrays(None, free, RES)
    index = select.prepare(t, ROBOT).index
    n = 300
    poses = np.stack([rng.uniform(-0.05, SHAPE[0] * RES + 0.05, n), rng.uniform(-0.05, SHAPE[1] * RES + 0.05, n),
                      rng.uniform(-np.pi, np.pi, n)], axis=1).astype(np.float32)
    for margin in (0.0, 0.04):
        got = np.asarray(jax.jit(jax.vmap(lambda p, m=margin: select.on_obstacle(t, ROBOT, p, index=index,
                                                                                 margin=m)))(poses))
        grown = ROBOT.replace(margin=jnp.float32(margin))
        terms = jax.vmap(lambda p, g=grown: ij.foot_cost_terms(t, g, p, 1, p[None], action_index=jnp.zeros(1, int),
                                                              index=index).obstacle[0])(poses)
        np.testing.assert_array_equal(got, np.isinf(np.asarray(terms)))
        hl, hw = 0.5 * float(ROBOT.foot_length) + margin, 0.5 * float(ROBOT.foot_width) + margin
        compared = 0
        for pose, hit in zip(poses.astype(np.float64), got, strict=True):
            ref = []
            for eps in (-1e-4, 1e-4):
                big = np.pad(rect_touches_cells(*pose, hl + eps, hw + eps, RES, (SHAPE[0] + 40, SHAPE[1] + 40),
                                                origin=(-20 * RES, -20 * RES)), 0)
                inner = big[20:-20, 20:-20]
                off_map = big.sum() > inner.sum()
                centre_off = not (0 < pose[0] < SHAPE[0] * RES and 0 < pose[1] < SHAPE[1] * RES)
                ref.append(bool(np.any(inner & ~free) or off_map or centre_off))
            if ref[0] == ref[1]:
                compared += 1
                assert hit == ref[0], (pose, margin)
        assert compared > 0.9 * n
        assert 0.1 * n < got.sum() < 0.9 * n  # both answers are common


def test_on_obstacle_refuses_bad_input_and_flags_a_bad_traced_margin():
    t = ij.terrain.flat(SHAPE, RES)
    with pytest.raises(ValueError, match=r"pose must have shape \(3,\)"):
        select.on_obstacle(t, ROBOT, [0.5, 0.5])
    with pytest.raises(ValueError, match="finite"):
        select.on_obstacle(t, ROBOT, [0.5, np.nan, 0.0])
    for bad in (-0.01, float("nan")):
        with pytest.raises(ValueError, match="margin must be a number >= 0"):
            select.on_obstacle(t, ROBOT, [0.5, 0.5, 0.0], margin=bad)
    with pytest.raises(TypeError, match="margin must be numbers"):
        select.on_obstacle(t, ROBOT, [0.5, 0.5, 0.0], margin="2 cm")
    with pytest.raises(ValueError, match="does not fit its static window"):  # the footprint's window: max_margin
        select.on_obstacle(t, ROBOT, [0.5, 0.5, 0.0], margin=0.3)
    with pytest.raises(TypeError, match="robot"):
        select.on_obstacle(t, None, [0.5, 0.5, 0.0])
    at = jax.jit(lambda m: select.on_obstacle(t, ROBOT, jnp.array([0.5, 0.5, 0.0]), margin=m))
    assert not bool(at(0.02)) and bool(at(-0.01)) and bool(at(jnp.nan))


def test_bad_input_at_the_boundary():
    t = ij.terrain.flat(SHAPE, RES)
    with pytest.raises(ValueError, match="method"):
        ij.select_step(t, ROBOT, [0.5, 0.5, 0.0], -1, [0.1, 0.0, 0.0], options=ij.SelectOptions(method="astar"))
    with pytest.raises(ValueError, match="command"):
        ij.select_step(t, ROBOT, [0.5, 0.5, 0.0], -1, [0.1, 0.0])
    with pytest.raises(ValueError, match="stance_side"):
        ij.select_step(t, ROBOT, [0.5, 0.5, 0.0], 2, [0.1, 0.0, 0.0])


def _wall_terrain():
    free = np.ones(SHAPE, bool)
    free[30:, :] = False  # a wall from x = 0.6 m
    return ij.terrain.from_arrays(None, free, RES)


@pytest.mark.parametrize("changes, match", [
    (dict(margin=-0.1), "margin"),  # would accept a foothold overlapping the wall
    (dict(margin=0.15), "static window"),  # would stop the robot silently, where hrp2(margin=0.15) steps
    (dict(w=-1.0), "w"),  # would give negative costs, on which the ordered search's early exit is wrong
    (dict(foot_length=0.40), "static window|overlap"),
])
def test_robot_values_set_by_replace_are_checked_at_the_boundary(changes, match):
    t = _wall_terrain()
    bad = ROBOT.replace(**{k: jnp.float32(v) for k, v in changes.items()})
    with pytest.raises(ValueError, match=match):
        ij.select_step(t, bad, [0.3, 0.5, 0.0], -1, [0.2, 0.0, 0.0], targets=TARGETS)
    with pytest.raises(ValueError, match=match):
        ij.foot_cost_terms(t, bad, [0.3, 0.5, 0.0], -1, [[0.3, 0.69, 0.0]])
    with pytest.raises(ValueError, match=match):
        ij.rollout(t, bad, [[0.3, 0.595, 0.0], [0.3, 0.405, 0.0]], [0.2, 0.0, 0.0], 2, targets=TARGETS)


@pytest.mark.parametrize("method", ["exhaustive", "ordered"])
@pytest.mark.parametrize("changes", [dict(margin=-0.1), dict(margin=0.15), dict(w=-1.0), dict(foot_length=0.40)])
def test_unsupported_robot_values_inside_jit_are_flagged_not_silent(method, changes):
    """Traced (a user's jit or vmap): no check can raise, so the choice is invalid WITH a reason, and its cost is
    +inf, never negative."""
    t = _wall_terrain()
    f = jax.jit(lambda r: ij.select_step(t, r, [0.5, 0.5, 0.0], -1, [0.2, 0.0, 0.0],
                                         options=ij.SelectOptions(method=method),
                                         targets=TARGETS))
    ok = f(ROBOT)
    assert bool(ok.valid) and not bool(ok.unsupported)
    c = f(ROBOT.replace(**{k: jnp.float32(v) for k, v in changes.items()}))
    assert not bool(c.valid) and bool(c.unsupported) and float(c.cost) == np.inf and int(c.index) == -1
    terms = jax.jit(lambda r: ij.foot_cost_terms(t, r, [0.5, 0.5, 0.0], -1, [[0.5, 0.69, 0.0]], action_index=[0]))(
        ROBOT.replace(**{k: jnp.float32(v) for k, v in changes.items()}))
    assert np.isinf(terms.unsupported).all() and np.isinf(terms.total).all()


def test_non_finite_origin_set_by_replace():
    t = ij.terrain.flat(SHAPE, RES)
    nan_origin = t.replace(origin=jnp.array([jnp.nan, 0.0]))
    with pytest.raises(ValueError, match="origin"):
        ij.select_step(nan_origin, ROBOT, [0.5, 0.5, 0.0], -1, [0.2, 0.0, 0.0], targets=TARGETS)
    f = jax.jit(lambda o: ij.select_step(t.replace(origin=o), ROBOT, [0.5, 0.5, 0.0], -1, [0.2, 0.0, 0.0],
                                         targets=TARGETS))
    assert bool(f(jnp.zeros(2)).valid)
    c = f(jnp.array([jnp.nan, 0.0]))
    assert not bool(c.valid) and bool(c.unsupported) and np.all(np.isfinite(c.pose))
    assert np.all(np.isfinite(c.foothold))


@pytest.mark.parametrize("side", ["left", True, None])
def test_stance_side_that_is_not_a_number_gets_a_clear_error(side):
    t = ij.terrain.flat(SHAPE, RES)
    with pytest.raises(ValueError, match=r"stance_side must be \+1 .* or -1"):
        ij.select_step(t, ROBOT, [0.5, 0.5, 0.0], side, [0.1, 0.0, 0.0], targets=TARGETS)


# ---------------------------------------------------------------------------------------------
# The full foothold (issue 20): StepChoice.foothold against an independent plane fit
# ---------------------------------------------------------------------------------------------

FOOT_Z_TOL = 3e-5  # m: float32 least squares over ~90 cells of heights up to ~0.4 m (relative to the centre cell)
FOOT_ANGLE_TOL = 3e-4  # rad: the float32 plane gradient (~1e-5 m/m over a 0.24 m foot) through atan
SLIVER = 1e-5  # m: a footprint edge this close to a cell edge may touch the cell or not in float32
LENIENT = ROBOT.replace(
    metrics=ROBOT.metrics.replace(slope_limit=jnp.float32(1.2), roughness_limit=jnp.float32(1.0),
                                  bump_limit=jnp.float32(1.0), band_limit=jnp.float32(1.0)),
    max_step_height=jnp.full(ROBOT.num_actions, 1.0, jnp.float32), max_sole_pitch=jnp.float32(1.2),
    max_sole_roll=jnp.float32(1.2))  # every limit out of the way: the choice is mostly valid, on any slope


def _sliver(pose, length, width):
    """Whether the footprint's cells at ``pose`` may differ under float32 rounding (an edge within SLIVER)."""
    inner = rect_touches_cells(*pose, length / 2 - SLIVER, width / 2 - SLIVER, RES, SHAPE)
    outer = rect_touches_cells(*pose, length / 2 + SLIVER, width / 2 + SLIVER, RES, SHAPE)
    return bool(np.any(inner != outer))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16), rough=st.booleans())
def test_foothold_matches_an_independent_plane_fit(seed, rough):
    """foothold = (x, y, z, roll, pitch, yaw): x, y, yaw the chosen pose's; z the least-squares plane's height at
    the foot centre and roll, pitch the sole lying on it, both from numpy.linalg.lstsq over the footprint's cell
    centres (testing.foothold), on random planes (up to 17 deg each way) and on rough maps (plus noise and bumps).
    A pure plane also has its closed form: z = the plane at the foot centre."""
    rng = np.random.default_rng(seed)
    gx, gy = rng.uniform(-0.3, 0.3, 2)
    centres = (np.arange(SHAPE[0]) + 0.5) * RES
    xc, yc = np.meshgrid(centres, centres, indexing="ij")
    h = 0.1 + gx * xc + gy * yc
    if rough:
        h = h + 0.01 * rng.standard_normal(SHAPE) + 0.05 * np.sin(7 * xc + rng.uniform(0, 6)) * np.cos(5 * yc)
    h = h.astype(np.float32)
    t = ij.terrain.from_arrays(h, None, RES)
    stance = np.array([*rng.uniform(0.4, 0.55, 2), rng.uniform(-np.pi, np.pi)], np.float32)
    command = rng.uniform([-0.3, -0.2, -0.5], [0.3, 0.2, 0.5]).astype(np.float32)
    ch = ij.select_step(t, LENIENT, stance, int(rng.choice([-1, 1])), command, targets=TARGETS)
    pose = np.asarray(ch.pose, np.float64)
    got = np.asarray(ch.foothold, np.float64)
    assert got.shape == (6,) and ch.foothold.dtype == jnp.float32
    np.testing.assert_array_equal(got[[0, 1, 5]], np.asarray(ch.pose)[[0, 1, 2]])
    if _sliver(pose, 0.242, 0.13):
        return  # the cell set itself is ambiguous to float32 (rare)
    ref = foothold(h.astype(np.float64), RES, (0.0, 0.0), pose, 0.242, 0.13)
    assert got[2] == pytest.approx(ref[2], abs=FOOT_Z_TOL)
    np.testing.assert_allclose(got[3:5], ref[3:5], atol=FOOT_ANGLE_TOL)
    if not rough:  # the fit of an exact plane is the plane
        assert got[2] == pytest.approx(0.1 + gx * pose[0] + gy * pose[1], abs=FOOT_Z_TOL)


def test_foothold_is_the_pose_with_zero_height_and_tilt_on_2d_maps_under_vmap():
    terrains = _random_terrains(31, 4, False)
    stance, side, command, swing_from = _random_queries(32, 64)
    got = _batched("exhaustive", False)(jax.tree_util.tree_map(lambda x: jnp.repeat(x, 16, axis=0), terrains),
                                        stance, side, command, swing_from)
    fh, pose = np.asarray(got.foothold), np.asarray(got.pose)
    assert fh.shape == (64, 6) and np.asarray(got.valid).sum() > 16
    np.testing.assert_array_equal(fh[:, [0, 1, 5]], pose)
    np.testing.assert_array_equal(fh[:, 2:5], 0.0)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["ordered", "naive"])
def test_foothold_of_every_method_is_that_of_its_pose(method):
    """Whatever pose a method reports (a step, the naive action, the step in place), the foothold is its plane's."""
    terrains = _random_terrains(33, 1, True)
    t = jax.tree_util.tree_map(lambda x: x[0], terrains)
    stance, side, command, _ = _random_queries(34, 8)
    for q in range(8):
        ch = ij.select_step(t, ROBOT, stance[q], side[q], command[q], options=ij.SelectOptions(method=method),
                            targets=TARGETS)
        want = select.foothold(t, ROBOT, ch.pose)
        np.testing.assert_allclose(np.asarray(ch.foothold), np.asarray(want), atol=1e-6)


@pytest.mark.slow
def test_on_a_plane_the_slope_weight_moves_every_cost_alike_and_no_choice():
    """On ground of one plane every candidate pays the same slope cost, so ``metrics.slope_weight`` shifts every
    valid candidate's cost by (weight change) x (plane angle) and leaves the choice alone: the reason the slope
    families' walks do not depend on it (docs/walk_families.md, "Refined footholds on image maps"). The
    margins (2 cm) keep the footprints on the map; traced weights, one compiled program."""
    rng = np.random.default_rng(11)
    n_maps, per_map = 4, 24
    angle = np.radians(rng.uniform(2.0, 10.0, n_maps))
    direction = rng.uniform(-np.pi, np.pi, n_maps)
    xy = (np.stack(np.meshgrid(np.arange(SHAPE[0]), np.arange(SHAPE[1]), indexing="ij"), -1) + 0.5) * RES
    height = np.tan(angle)[:, None, None] * (np.cos(direction)[:, None, None] * xy[..., 0]
                                             + np.sin(direction)[:, None, None] * xy[..., 1])
    n = n_maps * per_map
    maps = ij.Terrain(jnp.asarray(np.repeat(height, per_map, 0), jnp.float32), jnp.ones((n,) + SHAPE, bool),
                      jnp.zeros((n, 2)), RES, True)
    stance, side, command, _ = _random_queries(12, n)

    @jax.jit
    def choose(weight):
        robot = ij.robots.set_leaves(ROBOT, {"metrics.slope_weight": weight})
        return jax.vmap(lambda t, st, sd, cmd: ij.select_step(t, robot, st, sd, cmd, targets=TARGETS))(
            maps, stance, side, command)

    low, high = choose(0.5), choose(2.0)
    assert compiled_count(choose) == 1  # the weight is traced
    valid = np.asarray(low.valid)
    assert valid.sum() >= n // 2  # most queries have a choice: the comparison is not empty
    np.testing.assert_array_equal(np.asarray(high.valid), valid)
    # The best cost moves by 1.5 x the plane's angle (each candidate's fit of an exact plane, float32 rounding):
    # every candidate moved alike, so the choice is the same one, or one that was within rounding of it (a tie).
    shift = (np.asarray(high.cost, np.float64) - np.asarray(low.cost, np.float64))[valid]
    np.testing.assert_allclose(shift, 1.5 * np.repeat(angle, per_map)[valid], atol=TIE)
    same = np.asarray(high.index) == np.asarray(low.index)
    assert same.mean() >= 0.9, np.nonzero(~same)
