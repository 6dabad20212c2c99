"""Lookahead selection (ijoy_jax.lookahead through select_step / rollout): exact against NumPy brute force over all
sequences, the one-step selector at horizon 1, the beam, the dead-end map, no recompiles, hostile options.

Small maps (1 m x 1 m at 2 cm) and small action sets (HRP-2's lattice at density 0.25: 19 actions, 361 pairs;
0.1: 10 actions, 1000 triples) keep the NumPy enumeration and the compiles short; the dead-end map uses the
paper's 496 actions.
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import control, geometry, lookahead, select, testing

SMALL = ij.robots.hrp2(margin=0.02, density=0.25)  # 19 actions
TINY = ij.robots.hrp2(margin=0.02, density=0.1)  # 10 actions
HRP2 = ij.robots.hrp2(margin=0.02)
SHAPE = (50, 50)
RES = 0.02
# Cost units: the JAX search runs in float32 and the NumPy reference in float64. Scores are sums of at most three
# costs of order 1-100 (w * dist with rotation weight 100), whose float32 rounding is ~1e-5 relative; a first
# action whose score is within this of the best is a tie between the two implementations.
SCORE_TOL = 1e-4
EXAMPLES = settings(max_examples=12, deadline=None)


def _map(seed: int, has_height: bool):
    """A 1 m x 1 m map: random 2-6 cm obstacles (and a 2.5D ramp with bumps), the stance area kept clear."""
    rng = np.random.default_rng(seed)
    free = np.ones(SHAPE, bool)
    for _ in range(rng.integers(3, 9)):
        i, j = rng.integers(0, SHAPE[0] - 3, 2)
        a, b = rng.integers(1, 4, 2)
        free[i:i + a, j:j + b] = False
    free[:18, 15:35] = True  # the feet stand at x ~ 0.25 m
    h = None
    if has_height:
        x = np.arange(SHAPE[0])[:, None] * RES
        h = (0.03 * np.sin(3.0 * x) + 0.004 * rng.standard_normal(SHAPE)).astype(np.float32)
    return ij.terrain.from_arrays(h, free, RES)


def _decision(seed: int):
    rng = np.random.default_rng(seed)
    stance = np.array([0.25 + rng.uniform(-0.03, 0.03), 0.5 + rng.uniform(-0.03, 0.03), rng.uniform(-0.2, 0.2)])
    command = np.array([rng.uniform(0.0, 0.25), rng.uniform(-0.1, 0.1), rng.uniform(-0.4, 0.4)])
    side = ij.RIGHT if rng.random() < 0.5 else ij.LEFT
    swing_from = np.asarray(geometry.compose(jnp.asarray(stance, jnp.float32),
                                             jnp.asarray([0.0, 0.19 * -side, 0.0], jnp.float32)), np.float64)
    return stance, side, command, swing_from


def _check_against_brute_force(terrain, robot, stance, side, command, swing_from, horizon, discount, **kw):
    targets = ij.make_targets(robot)
    options = ij.SelectOptions(method="lookahead", horizon=horizon, discount=discount, **kw)
    c = ij.select_step(terrain, robot, stance, side, command, options, swing_from=swing_from, targets=targets)
    fc = testing.NumpyFootCost(terrain, robot)
    v, c1, d1 = testing.lookahead_values(fc, targets, stance, side, command, swing_from, horizon, discount)
    if not np.isfinite(c1).any():
        assert not bool(c.valid) and int(c.index) == -1
        return v, c
    assert bool(c.valid)
    j = int(c.index)
    if np.isfinite(v).any():
        best = float(np.min(v))
        tol = SCORE_TOL * max(1.0, abs(best))
        assert v[j] <= best + tol, (j, v[j], best)
        near = np.flatnonzero(v <= best + tol)
        if len(near) == 1:
            assert j == int(near[0])
    else:  # every valid first step is a dead end: the one-step choice
        best = float(np.min(c1))
        near = np.flatnonzero(c1 <= best + SCORE_TOL * max(1.0, abs(best)))
        assert j in near.tolist()
    return v, c


@pytest.mark.slow
@EXAMPLES
@given(seed=st.integers(0, 2**31 - 1), has_height=st.booleans(), discount=st.sampled_from([0.0, 0.5, 1.0, 1.5]))
def test_exact_horizon_two_is_the_numpy_brute_force_over_all_pairs(seed, has_height, discount):
    stance, side, command, swing_from = _decision(seed)
    _check_against_brute_force(_map(seed, has_height), SMALL, stance, side, command,
                               swing_from if has_height else None, 2, discount)


@pytest.mark.slow
def test_exact_horizon_three_is_the_numpy_brute_force_over_all_triples():
    seed = 3  # one 2D decision (1110 NumPy FootCosts; the pairs' test covers 2.5D and swing paths)
    stance, side, command, _ = _decision(seed)
    v, c = _check_against_brute_force(_map(seed, False), TINY, stance, side, command, None, 3, 0.8)
    assert np.isfinite(v).any()


@pytest.mark.slow
def test_beam_of_the_whole_action_set_is_exact_at_horizon_two():
    n = SMALL.num_actions
    for seed in range(4):
        stance, side, command, swing_from = _decision(seed)
        terrain = _map(seed, True)
        options = ij.SelectOptions(method="lookahead", horizon=2)
        exact = ij.select_step(terrain, SMALL, stance, side, command, options, swing_from=swing_from)
        beam = ij.select_step(terrain, SMALL, stance, side, command, options.replace(beam=n), swing_from=swing_from)
        assert int(beam.index) == int(exact.index)
        np.testing.assert_array_equal(np.asarray(beam.pose), np.asarray(exact.pose))


@pytest.mark.slow
def test_horizon_one_is_the_exhaustive_selector_exactly():
    for seed in (1, 2, 3):
        stance, side, command, swing_from = _decision(seed)
        terrain = _map(seed, True)
        a = ij.select_step(terrain, SMALL, stance, side, command, swing_from=swing_from)
        b = ij.select_step(terrain, SMALL, stance, side, command, swing_from=swing_from,
                           options=ij.SelectOptions(method="lookahead", horizon=1))
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def _dead_end_map():
    """A 2D map whose only free cells are the footprints (grown by the 2 cm margin) of the standing feet and of
    two steps of the left foot from the right one: A = (0.2, 0.21, +20 deg), the lattice step nearest the
    forward-and-turn command, and B = (0.2, 0.21, 0). From A the right foot has nowhere to go (its own
    footprint is off the lattice relative to A, 6 cm beside the nearest action): a dead end. From B it can stay."""
    s0, f0 = np.array([0.5, 0.8, 0.0]), np.array([0.5, 0.99, 0.0])
    steps = [geometry.compose(jnp.asarray(s0, jnp.float32), jnp.asarray(r, jnp.float32))
             for r in ([0.2, 0.21, math.radians(20.0)], [0.2, 0.21, 0.0])]
    free = np.zeros((80, 80), bool)
    for p in (s0, f0, *np.asarray(steps, np.float64)):
        free |= testing.rect_touches_cells(p[0], p[1], p[2], 0.121 + 0.02, 0.065 + 0.02, RES, free.shape)
    return ij.terrain.from_arrays(None, free, RES), np.stack([f0, s0]), np.asarray(steps, np.float64)


@pytest.mark.slow
def test_on_the_dead_end_map_one_step_walks_in_and_stops_and_lookahead_does_not():
    terrain, start, (a, b) = _dead_end_map()
    command = [0.25, 0.0, 0.436]  # forward and turning left at the largest rate
    one = ij.rollout(terrain, HRP2, start, command, num_steps=4)
    assert np.allclose(one.footsteps[0], a, atol=1e-5)
    assert bool(one.taken[0]) and bool(one.stopped[1]) and not bool(one.valid[1])
    ahead = ij.rollout(terrain, HRP2, start, command, num_steps=4, options=ij.SelectOptions(method="lookahead",
                                                                                            horizon=2))
    assert not bool(ahead.stopped.any()) and bool(ahead.taken.all())
    assert np.allclose(ahead.footsteps[0], b, atol=1e-5)  # the step whose continuation exists
    # Refined after the lookahead, the steps leave the lattice (towards the commanded turn) but keep the plan's
    # next step valid, so the robot never stops either; refined alone, it walks into the dead end as before.
    fine = ij.rollout(terrain, HRP2, start, command, num_steps=4, options=ij.SelectOptions(method="lookahead",
                                                                                           refine=True))
    assert not bool(fine.stopped.any()) and float(fine.footsteps[0, 2]) > 1e-3
    assert bool(ij.rollout(terrain, HRP2, start, command, num_steps=4,
                           options=ij.SelectOptions(refine=True)).stopped[1])
    # The dead end is FootCost's verdict: no action of the right foot from A is valid, and there the lookahead
    # reports no step as the one-step selector does (index -1, the step-in-place pose, the robot stops).
    assert not np.isfinite(np.asarray(select.action_foot_costs(terrain, HRP2, a, ij.LEFT))).any()
    stuck = ij.select_step(terrain, HRP2, a, ij.LEFT, command, options=ij.SelectOptions(method="lookahead"),
                           swing_from=start[1])
    assert not bool(stuck.valid) and int(stuck.index) == -1 and math.isinf(float(stuck.cost))
    in_place = geometry.compose(jnp.asarray(a, jnp.float32), jnp.asarray([0.0, -0.19, 0.0], jnp.float32))
    np.testing.assert_allclose(np.asarray(stuck.pose), np.asarray(in_place), atol=1e-6)


def _table_robot(n: int):
    """A robot of n actions for the synthetic problems (w = 1)."""
    return ij.robots.make_robot(ij.robots.lattice_actions((n, 1, 1), drop_corners=False), foot_length=0.1,
                                foot_width=0.05, margin=0.0, step_time=1.0)


@functools.partial(jax.jit, static_argnames=("chunk",))
def _search_table(robot, c1, table, d1, d2, gamma, *, chunk):
    """The search on a synthetic problem: first action a's foothold has x = a, and the oracle returns row a of
    ``table`` (N, N) as the FootCosts of the second step."""
    n = c1.shape[0]
    steps = jnp.stack([jnp.arange(n, dtype=jnp.float32), jnp.zeros(n), jnp.zeros(n)], axis=1)

    def costs_from(stance, side, swing_from):
        return table[jnp.round(stance[0]).astype(jnp.int32)]

    return lookahead.search(c1, steps, jnp.zeros(3), -1, None, costs_from, robot, (d1, d2), gamma, horizon=2,
                            chunk=chunk)


@settings(max_examples=30, deadline=None)
@given(n=st.sampled_from([1, 5, 12]), data=st.data())
def test_branch_and_bound_matches_enumeration_with_ties_and_dead_ends(n, data):
    # Costs on a coarse grid (many exact ties) with +inf (invalid steps and dead ends).
    grid = st.sampled_from([0.0, 0.5, 1.0, 2.0, math.inf])
    c1 = np.array(data.draw(st.lists(grid, min_size=n, max_size=n)), np.float32)
    table = np.array(data.draw(st.lists(grid, min_size=n * n, max_size=n * n)), np.float32).reshape(n, n)
    d1 = np.array(data.draw(st.lists(st.sampled_from([0.0, 0.5, 1.0]), min_size=n, max_size=n)), np.float32)
    d2 = np.array(data.draw(st.lists(st.sampled_from([0.0, 0.5]), min_size=n, max_size=n)), np.float32)
    gamma = data.draw(st.sampled_from([0.0, 0.5, 1.0]))
    chunk = data.draw(st.sampled_from([1, 8]))
    c1_total = c1 + d1  # w = 1
    plan = _search_table(_table_robot(n), c1_total, table, d1, d2, np.float32(gamma), chunk=chunk)
    second = (table + d2[None, :]).min(axis=1)
    v = np.where(np.isfinite(c1_total) & np.isfinite(second), c1_total + gamma * np.where(np.isfinite(second),
                                                                                           second, 0.0), np.inf)
    order = sorted(range(n), key=lambda a: (v[a], d1[a], a))
    one_step = sorted(range(n), key=lambda a: (c1_total[a], d1[a], a))[0]
    if np.isfinite(v).any():
        assert int(plan.first) == order[0] and not bool(plan.dead_end)
        assert float(plan.score) == pytest.approx(float(v[order[0]]))
    elif np.isfinite(c1_total).any():
        assert int(plan.first) == one_step and bool(plan.dead_end) and math.isinf(float(plan.score))
    else:
        assert int(plan.first) == -1 and not bool(plan.dead_end)


def test_discount_is_traced_and_never_recompiles():
    terrain = _map(5, False)
    stance, side, command, _ = _decision(5)
    targets = ij.make_targets(SMALL)
    options = ij.SelectOptions(method="lookahead", horizon=2)
    ij.select_step(terrain, SMALL, stance, side, command, options.replace(discount=1.0), targets=targets)
    before = select.compiled_programs()
    for g in (0.0, 0.3, 2.0):
        ij.select_step(terrain, SMALL, stance, side, command, options.replace(discount=g), targets=targets)
    assert select.compiled_programs() == before
    # Nor in the rollout, which users call in loops.
    start = ij.robots.start_stance(SMALL, 0.25, 0.5)
    ij.rollout(terrain, SMALL, start, command, 3, options=ij.SelectOptions(method="lookahead", discount=1.0),
               targets=targets)
    before = control.compiled_programs()
    for g in (0.0, 0.7):
        ij.rollout(terrain, SMALL, start, command, 3, options=ij.SelectOptions(method="lookahead", discount=g),
                   targets=targets)
    assert control.compiled_programs() == before


def test_an_invalid_traced_discount_is_flagged_not_silent():
    terrain = _map(6, False)
    stance, side, command, _ = _decision(6)
    f = jax.jit(lambda g: ij.select_step(terrain, SMALL, stance, side, command,
                                         options=ij.SelectOptions(method="lookahead", discount=g)))
    for g in (jnp.nan, -1.0, jnp.inf):
        c = f(jnp.float32(g))
        assert not bool(c.valid) and bool(c.unsupported) and int(c.index) == -1 and math.isinf(float(c.cost))
    assert bool(f(jnp.float32(0.5)).valid)


def test_lookahead_under_vmap_over_terrains_is_each_terrain_alone():
    terrains = [_map(s, False) for s in (7, 8, 9)]
    stance, side, command, _ = _decision(7)
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *terrains)
    f = jax.jit(jax.vmap(lambda t: ij.select_step(t, SMALL, stance, side, command,
                                                  options=ij.SelectOptions(method="lookahead"))))
    out = f(batch)
    for i, t in enumerate(terrains):
        one = ij.select_step(t, SMALL, stance, side, command, options=ij.SelectOptions(method="lookahead"))
        assert int(out.index[i]) == int(one.index)
        np.testing.assert_allclose(np.asarray(out.pose[i]), np.asarray(one.pose), atol=1e-6)


@pytest.mark.parametrize("kwargs, match", [
    (dict(method="lookahead", horizon=0), "horizon must be >= 1"),
    (dict(method="lookahead", horizon=-2), "horizon must be >= 1"),
    (dict(method="lookahead", horizon=2.0), "horizon must be an int"),
    (dict(method="lookahead", horizon=True), "horizon must be an int"),
    (dict(method="lookahead", beam=0), r"beam must be in \[1, N\]"),  # refused as built, before N is known
    (dict(method="lookahead", beam=20), r"beam must be in \[1, 19\]"),
    (dict(method="lookahead", beam=4.5), "beam must be an int"),
    (dict(method="lookahed"), "method must be one of"),
    (dict(method="exhaustive", horizon=2), "options of method='lookahead'"),
    (dict(method="ordered", beam=4), "options of method='lookahead'"),
    (dict(method="lookahead", discount=-0.5), "discount must be finite and >= 0"),
    (dict(method="lookahead", discount=float("nan")), "discount must be finite and >= 0"),
    (dict(method="lookahead", discount=[1.0, 2.0]), "discount must be a scalar"),
    (dict(method="lookahead", chunk=0), "chunk must be an int >= 1"),
])
def test_hostile_lookahead_options_get_one_clear_error(kwargs, match):
    terrain = _map(0, False)
    with pytest.raises((ValueError, TypeError), match=match):
        ij.select_step(terrain, SMALL, [0.25, 0.5, 0.0], -1, [0.2, 0.0, 0.0], ij.SelectOptions(**kwargs))
    with pytest.raises((ValueError, TypeError), match=match):
        ij.rollout(terrain, SMALL, [[0.25, 0.6, 0.0], [0.25, 0.4, 0.0]], [0.2, 0.0, 0.0], 2, ij.SelectOptions(**kwargs))
