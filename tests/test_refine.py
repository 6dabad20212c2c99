"""Continuous refinement (ijoy_jax.refine through select_step / rollout): never costlier than its lattice step,
always valid by the exact FootCost (and by the independent NumPy one), within its box and trust region, off
the stance foot; it reaches footholds between lattice points; traced options; hostile options.

Small maps (1 m x 1 m at 2 cm) and HRP-2's lattice at density 0.25 (19 actions) keep the compiles short; the
footholds between lattice points use the paper's 496 actions.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import geometry, refine, robots, select, testing

SMALL = ij.robots.hrp2(margin=0.02, density=0.25)
HRP2 = ij.robots.hrp2(margin=0.02)
SHAPE = (50, 50)
RES = 0.02
# Cost units: the refined cost and the lattice step's, both float32 sums of FootCost (a few cost units) and
# w * dist (up to ~100 with rotation weight 100); float32 rounds such sums by ~1e-5.
COST_TOL = 1e-4
# m and rad: float32 rounding of a composed pose a few metres from the origin.
POSE_TOL = 1e-5
EXAMPLES = settings(max_examples=8, deadline=None)


def _map(seed: int, has_height: bool):
    rng = np.random.default_rng(seed)
    free = np.ones(SHAPE, bool)
    for _ in range(rng.integers(4, 12)):
        i, j = rng.integers(0, SHAPE[0] - 3, 2)
        a, b = rng.integers(1, 4, 2)
        free[i:i + a, j:j + b] = False
    free[:18, 15:35] = True
    h = None
    if has_height:
        x = np.arange(SHAPE[0])[:, None] * RES
        h = (0.03 * np.sin(3.0 * x) + 0.004 * rng.standard_normal(SHAPE)).astype(np.float32)
    return ij.terrain.from_arrays(h, free, RES)


def _decision(seed: int):
    rng = np.random.default_rng(seed)
    stance = np.array([0.25 + rng.uniform(-0.03, 0.03), 0.5 + rng.uniform(-0.03, 0.03), rng.uniform(-0.2, 0.2)])
    command = np.array([rng.uniform(-0.1, 0.3), rng.uniform(-0.15, 0.15), rng.uniform(-0.5, 0.5)])
    side = ij.RIGHT if rng.random() < 0.5 else ij.LEFT
    swing_from = np.asarray(geometry.compose(jnp.asarray(stance, jnp.float32),
                                             jnp.asarray([0.0, 0.19 * -side, 0.0], jnp.float32)), np.float64)
    return stance, side, command, swing_from


def _cost_against_p_next(terrain, robot, stance, side, command, pose, action, swing_from):
    """The exact cost of a world pose taken as ``action``: FootCost (JAX) + w * dist to p_next (NumPy float64)."""
    fc = float(ij.foot_cost(terrain, robot, stance, side, np.asarray(pose)[None], swing_from=swing_from,
                            action_index=np.array([action]))[0])
    p_next = np.asarray(select.ideal_step(robot, side, command)[0], np.float64)
    rel = np.asarray(geometry.relative(jnp.asarray(stance, jnp.float32), jnp.asarray(pose, jnp.float32)), np.float64)
    d = math.hypot(*(rel[:2] - p_next[:2])) + float(robot.rotation_weight) * abs(
        math.remainder(rel[2] - p_next[2], 2 * math.pi))
    return fc + float(robot.w) * d, fc, rel


@pytest.mark.slow
@EXAMPLES
@given(seed=st.integers(0, 2**31 - 1))
def test_refinement_is_never_costlier_than_its_lattice_step_and_always_valid(seed):
    # After a lookahead the refinement also keeps the plan valid: tests/test_lookahead.py's dead-end map.
    method = "exhaustive"
    has_height = True  # 2.5D: every FootCost term (2D adds nothing a 2.5D map does not exercise)
    terrain = _map(seed, has_height)
    stance, side, command, swing_from = _decision(seed)
    sf = swing_from if has_height else None
    lattice = ij.select_step(terrain, SMALL, stance, side, command, options=ij.SelectOptions(method=method),
                             swing_from=sf)
    fine = ij.select_step(terrain, SMALL, stance, side, command, options=ij.SelectOptions(method=method, refine=True),
                          swing_from=sf)
    if bool(lattice.valid):
        start, _, _ = _cost_against_p_next(terrain, SMALL, stance, side, command, lattice.pose,
                                           int(lattice.index), sf)
        assert bool(fine.valid)
        assert float(fine.cost) <= start + COST_TOL
    if not bool(fine.valid):
        assert int(fine.index) == -1 and math.isinf(float(fine.cost))
        return
    # Valid by the exact FootCost, re-evaluated at the refined pose as the lattice action it started from ...
    cost, fc, rel = _cost_against_p_next(terrain, SMALL, stance, side, command, fine.pose, int(fine.index), sf)
    assert math.isfinite(fc)
    assert cost == pytest.approx(float(fine.cost), abs=COST_TOL)
    assert fc == pytest.approx(float(fine.foot_cost), abs=COST_TOL)
    # ... and by the independent NumPy FootCost (float64 coverage, planes by lstsq).
    ref = testing.NumpyFootCost(terrain, SMALL)
    sh = ref.plane(stance)[0] if has_height else 0.0
    st_h = ref.plane(sf)[0] if sf is not None else 0.0
    assert math.isfinite(ref.cost(stance, sh, st_h, sf, np.asarray(fine.pose, np.float64), int(fine.index)))
    # Off the stance foot, within the action set's box and one lattice spacing of its start.
    assert not robots.footprints_overlap(rel, float(SMALL.foot_length), float(SMALL.foot_width))[0]
    acts = np.asarray(robots.side_actions(SMALL, -side), np.float64)
    assert np.all(rel >= acts.min(0) - POSE_TOL) and np.all(rel <= acts.max(0) + POSE_TOL)
    spacing = np.asarray(refine.lattice_spacing(SMALL))
    assert np.all(np.abs(rel - acts[int(fine.index)]) <= spacing + POSE_TOL)


@pytest.mark.slow
def test_a_step_between_lattice_points_up_to_a_wall():
    free = np.ones((80, 80), bool)  # the island map's grid: the same compiled programs
    free[55:, :] = False  # a wall at x = 1.1 m: the grown foot's front may reach it
    terrain = ij.terrain.from_arrays(None, free, RES)
    args = (terrain, HRP2, [0.77, 0.8, 0.0], ij.RIGHT, [0.25, 0.0, 0.0])
    lattice = ij.select_step(*args, swing_from=[0.77, 0.99, 0.0])
    fine = ij.select_step(*args, swing_from=[0.77, 0.99, 0.0], options=ij.SelectOptions(refine=True))
    assert bool(fine.valid) and int(fine.index) == int(lattice.index)
    # The lattice stops 5 cm steps short (0.92 m); the refined foot's grown front (0.141 m ahead) is within a
    # cell of the wall, the closest the conservative cell coverage allows.
    assert float(lattice.pose[0]) == pytest.approx(0.92, abs=POSE_TOL)
    assert 1.1 - 0.02 - 1e-3 <= float(fine.pose[0]) + 0.141 <= 1.1 + 1e-6


def _island_map():
    """2D: the standing feet, the left one 0.2 m behind the right one, and one island exactly the left foot's
    grown footprint 0.175 m ahead of the right foot: between the lattice's 0.15 and 0.2 m, neither of which
    fits (their grown footprints reach a cell beyond the island's at either end)."""
    s0, f0 = np.array([0.5, 0.8, 0.0]), np.array([0.3, 0.99, 0.0])
    free = np.zeros((80, 80), bool)
    for p in (s0, f0, np.array([0.675, 0.99, 0.0])):
        free |= testing.rect_touches_cells(p[0], p[1], p[2], 0.141, 0.085, RES, free.shape)
    return ij.terrain.from_arrays(None, free, RES), s0, f0


@pytest.mark.slow
def test_a_foothold_no_lattice_step_reaches_is_found():
    terrain, s0, f0 = _island_map()
    command = [0.25, 0.0, 0.0]  # p_next: 0.2 m ahead
    lattice = ij.select_step(terrain, HRP2, s0, ij.RIGHT, command, swing_from=f0)
    fine = ij.select_step(terrain, HRP2, s0, ij.RIGHT, command, swing_from=f0, options=ij.SelectOptions(refine=True))
    # The lattice's only valid step puts the left foot back where it stands (0.2 m behind): it marks time.
    assert bool(lattice.valid) and np.allclose(np.asarray(lattice.pose), f0, atol=POSE_TOL)
    assert bool(fine.valid) and float(fine.pose[0]) == pytest.approx(0.675, abs=0.011)
    # No action of S puts the foot on the island.
    ahead = np.asarray(ij.action_steps(HRP2, s0, ij.RIGHT))[:, 0] > 0.55
    assert not np.isfinite(np.asarray(select.action_foot_costs(terrain, HRP2, s0, ij.RIGHT))[ahead]).any()
    # The rollout walks onto it and records the refined pose with the lattice action it started from.
    traj = ij.rollout(terrain, HRP2, np.stack([f0, s0]), command, num_steps=4, options=ij.SelectOptions(refine=True))
    assert float(traj.footsteps[0, 0]) == pytest.approx(float(fine.pose[0]), abs=POSE_TOL)
    assert int(traj.index[0]) == int(fine.index) and not bool(traj.in_place[0])
    assert int(traj.summary()["footholds_on_obstacles"]) == 0


def test_refine_options_are_traced_and_never_recompile():
    terrain = _map(1, False)
    stance, side, command, _ = _decision(1)
    targets = ij.make_targets(SMALL)
    ij.select_step(terrain, SMALL, stance, side, command, targets=targets,
                   options=ij.SelectOptions(refine=refine.params()))
    before = select.compiled_programs()
    for span, gain in ((0.5, 0.0), (1.0, 1e-3), (0.25, 1e-6)):
        c = ij.select_step(terrain, SMALL, stance, side, command, targets=targets,
                           options=ij.SelectOptions(refine=refine.params(span=span, min_gain=gain)))
        assert bool(c.valid)
    assert select.compiled_programs() == before


@pytest.mark.slow
def test_traced_invalid_refine_options_are_flagged():
    terrain = _map(2, False)
    stance, side, command, _ = _decision(2)
    p = refine.params()
    f = jax.jit(lambda s: ij.select_step(terrain, SMALL, stance, side, command,
                                         options=ij.SelectOptions(refine=p.replace(span=s))))
    for bad in (jnp.nan, -1.0, 0.0):
        c = f(jnp.float32(bad))
        assert not bool(c.valid) and bool(c.unsupported) and int(c.index) == -1
    assert bool(f(jnp.float32(1.0)).valid)


@pytest.mark.slow
def test_refinement_under_vmap_inside_a_users_jit_is_each_decision_alone():
    terrains = [_map(s, False) for s in (3, 4)]
    stance, side, command, _ = _decision(3)
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *terrains)
    f = jax.jit(jax.vmap(lambda t: ij.select_step(t, SMALL, stance, side, command,
                                                  options=ij.SelectOptions(refine=True))))
    out = f(batch)
    for i, t in enumerate(terrains):
        one = ij.select_step(t, SMALL, stance, side, command, options=ij.SelectOptions(refine=True))
        assert int(out.index[i]) == int(one.index)
        np.testing.assert_allclose(np.asarray(out.pose[i]), np.asarray(one.pose), atol=POSE_TOL)


@pytest.mark.parametrize("kwargs, match", [
    (dict(method="naive", refine=True), "refine applies to the terrain-aware methods"),
    (dict(refine="yes"), "refine must be a bool or an ijoy_jax.refine.RefineParams"),
    (dict(refine=refine.RefineParams(jnp.float32(0.0), jnp.float32(0.0), 5, 4)), "refine span must be finite"),
    (dict(refine=refine.RefineParams(jnp.float32(1.0), jnp.float32(-1.0), 5, 4)), "refine min_gain must be"),
    (dict(refine=refine.RefineParams(jnp.float32(1.0), jnp.float32(0.0), 5, 40)), "refine starts must be at most"),
])
def test_hostile_refine_options_get_one_clear_error(kwargs, match):
    terrain = _map(0, False)
    with pytest.raises((ValueError, TypeError), match=match):
        ij.select_step(terrain, SMALL, [0.25, 0.5, 0.0], -1, [0.2, 0.0, 0.0], ij.SelectOptions(**kwargs))
    with pytest.raises((ValueError, TypeError), match=match):
        ij.rollout(terrain, SMALL, [[0.25, 0.6, 0.0], [0.25, 0.4, 0.0]], [0.2, 0.0, 0.0], 2, ij.SelectOptions(**kwargs))


@pytest.mark.parametrize("kwargs, match", [
    (dict(span=float("nan")), "refine span must be finite and > 0"),
    (dict(span=0.0), "refine span must be finite and > 0"),
    (dict(min_gain=float("inf")), "refine min_gain must be finite and >= 0"),
    (dict(levels=0), "levels must be an int >= 1"),
    (dict(starts=2.5), "starts must be an int >= 1"),
])
def test_hostile_refine_params(kwargs, match):
    with pytest.raises(ValueError, match=match):
        refine.params(**kwargs)
