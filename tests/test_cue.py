"""The haptic cue (ijoy_jax.cue): the feasible command set, the force, reach and effects.

References: the selector itself (select_step on the same terrain), brute-force NumPy float64 geometry of
the action cells (hard min, hard clip), closed forms on a straight wall, exact grid rotations and
mirrors, and finite differences.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jax.test_util import check_grads

import ijoy_jax as ij
from ijoy_jax import cue, haptics, select
from ijoy_jax.robots import dist
from ijoy_jax.testing import NumpyFootCost

RES = 0.02
SHAPE = (100, 100)
ROBOT = ij.robots.hrp2(margin=0.02)
TARGETS = ij.make_targets(ROBOT)
N = ROBOT.num_actions
DT = float(ROBOT.step_time)
T = cue.DEFAULT_TEMPERATURE
PARAMS = cue.make_params()
STANCE = np.array([0.9, 1.0, 0.0])  # right foot; the left swings (stance_side -1)
# A wall across the map 0.22 m ahead of the stance foot: with the 2 cm margin a left step of dx <= 0.05 m
# keeps its front edge (dx + half the grown foot, rotated by up to 20 deg: at most 0.1616 m) before it, one
# of dx >= 0.10 m (0.241 m) does not: whatever the width or rotation, the valid commands are xdot <= 0.0625
# m/s, their cells end at 0.0625 + 0.05 / 2 / 0.8 = 0.09375 m/s.
WALL_X = 1.12
WALL_EDGE = 0.09375  # m/s: the forward edge of the last open cells
# Soft geometry against the hard one: each soft min is within T log(k) of the hard one for k near-equal
# cells, each excess within T / 8 of the hard excess; 3 T covers a handful of near ties.
DEPTH_TOL = 3 * T
TIE_TOL = 1e-4  # m of dist: equal to rounding (float32 angles, ~1e-7 rad, times the rotation weight 100)


def _free(wall_x=None):
    free = np.ones(SHAPE, bool)
    if wall_x is not None:
        free[int(round(wall_x / RES)):, :] = False
    return free


def _terrain(free):
    return ij.terrain.from_arrays(None, free, RES)


FLAT = _terrain(_free())
WALL = _terrain(_free(WALL_X))


def _clutter(seed):
    rng = np.random.default_rng(seed)
    free = _free()
    for _ in range(10):
        x, y = rng.integers(30, 80), rng.integers(20, 80)
        free[x:x + rng.integers(2, 9), y:y + rng.integers(2, 9)] = False
    return _terrain(free)


@jax.jit
def _forces(feasible, commands, params):
    return jax.vmap(cue.force_terms, in_axes=(None, 0, None))(feasible, commands, params)


def _mirror(v):
    return np.asarray(v) * np.array([1.0, -1.0, -1.0])


# --------------------------------------------------------------------------- NumPy float64 reference


def _reference(feasible, command, scales=(1.0, 1.0, 1.0)):
    """Hard geometry of the cells in float64: (depth, nearest feasible command, command clipped to the hull,
    distance to the nearest valid cell, that to the second nearest, distance to the nearest cell)."""
    a = np.asarray(feasible.commands, np.float64)
    valid = np.asarray(feasible.valid)
    u = np.asarray(feasible.unit, np.float64) * np.asarray(scales, np.float64)
    h = np.asarray(feasible.half_cell, np.float64)
    lo, hi = np.asarray(feasible.lo, np.float64), np.asarray(feasible.hi, np.float64)
    j = np.clip(np.asarray(command, np.float64), lo, hi)
    e = np.maximum(np.abs(j - a) - h, 0.0) / u
    d = np.hypot(e[:, 0], e[:, 1]) + e[:, 2]
    dv = np.sort(np.where(valid, d, np.inf))
    best = np.argmin(np.where(valid, d, np.inf))
    nearest = np.clip(j, a[best] - h, a[best] + h)
    return dv[0] - d.min(), nearest, j, dv[0], dv[1], d.min()


# --------------------------------------------------------------------------- the feasible command set


@pytest.mark.parametrize("side", [1, -1])
def test_action_commands_invert_the_ideal_step(side):
    acts = np.asarray(ROBOT.actions, np.float64)
    p0 = np.asarray(ROBOT.p0, np.float64)
    swing = -side
    flip = np.array([1.0, swing, swing])
    want = (acts * flip - p0 * flip) / DT  # NumPy: (a - p0) / dt, mirrored for a right swing foot
    got = cue.action_commands(ROBOT, side)
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-6)
    p_next, ok = jax.vmap(lambda j: select.ideal_step(ROBOT, side, j))(got)
    np.testing.assert_allclose(np.asarray(p_next), acts * flip, atol=1e-6)
    assert bool(ok.all())


def test_selecting_with_an_actions_command_takes_that_action_on_open_ground():
    index = ij.footcost.index_terrain(FLAT, ROBOT)

    @jax.jit
    def choose(commands, side):
        return jax.vmap(lambda j: ij.select_step(FLAT, ROBOT, STANCE, side, j, targets=TARGETS, index=index).index)(
            commands)

    for side in (1, -1):
        got = np.asarray(choose(cue.action_commands(ROBOT, side), side))
        np.testing.assert_array_equal(got, np.arange(N))


def test_feasible_set_is_the_footcost_of_every_action():
    terrain = _clutter(0)
    stance = np.array([1.0, 1.0, 0.3])
    f = cue.feasible_commands(terrain, ROBOT, stance, -1)
    ref = NumpyFootCost(terrain, ROBOT)  # independent NumPy float64 FootCost
    acts = np.asarray(ROBOT.actions, np.float64)
    for a in range(0, N, 7):
        c, s = np.cos(stance[2]), np.sin(stance[2])
        pose = np.array([stance[0] + c * acts[a, 0] - s * acts[a, 1], stance[1] + s * acts[a, 0] + c * acts[a, 1],
                         stance[2] + acts[a, 2]])
        want = ref.cost(stance, 0.0, 0.0, None, pose, a)
        assert np.isinf(want) == (not bool(f.valid[a])), a
    assert 0 < int(f.valid.sum()) < N and bool(f.any_valid) and not bool(f.unsupported)
    np.testing.assert_array_equal(np.asarray(f.valid), np.isfinite(np.asarray(f.cost)))
    # The hull, units and full scale from the action lattice (NumPy).
    acts = np.asarray(ROBOT.actions, np.float64)
    half = np.array([0.05, 0.02, math.radians(20) / 3]) / 2 / DT
    np.testing.assert_allclose(np.asarray(f.half_cell), half, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(f.full_scale), [0.25, 0.14 / DT, math.radians(20) / DT], rtol=1e-5)
    np.testing.assert_allclose(np.asarray(f.unit), [0.25, 0.25, 0.25 / float(ROBOT.rotation_weight)], rtol=1e-6)
    cmds = np.asarray(f.commands, np.float64)
    np.testing.assert_allclose(np.asarray(f.lo), cmds.min(0) - half, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(np.asarray(f.hi), cmds.max(0) + half, rtol=1e-5, atol=1e-7)
    assert acts.shape == (N, 3)


# --------------------------------------------------------------------------- the force


def test_open_flat_ground_gives_zero_force_for_every_command():
    lo, hi = ij.robots.command_range(ROBOT)
    grid = np.stack(np.meshgrid(*[np.linspace(1.5 * a, 1.5 * b, 13) for a, b in zip(lo, hi, strict=True)],
                                indexing="ij"), -1).reshape(-1, 3)
    for side in (1, -1):
        f = cue.feasible_commands(FLAT, ROBOT, STANCE, side)
        assert bool(f.valid.all())
        out = _forces(f, jnp.asarray(grid, jnp.float32), PARAMS)
        assert np.all(np.asarray(out.force) == 0.0) and not np.any(np.asarray(out.blocked))
        assert np.all(np.asarray(out.depth) <= 0.0)


@settings(max_examples=20)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False, width=32), min_size=3, max_size=3))
def test_open_ground_zero_force_for_any_finite_command(command):
    f = _flat_feasible()
    assert cue.force(f, command, c1=1.0, decay=0.01).tolist() == [0.0, 0.0, 0.0]


_CACHE = {}


def _flat_feasible():
    if "flat" not in _CACHE:
        _CACHE["flat"] = cue.feasible_commands(FLAT, ROBOT, STANCE, -1)
    return _CACHE["flat"]


def _wall_feasible(side=-1):
    if ("wall", side) not in _CACHE:
        _CACHE[("wall", side)] = cue.feasible_commands(WALL, ROBOT, STANCE, side)
    return _CACHE[("wall", side)]


@pytest.mark.parametrize("side", [-1, 1])
def test_wall_ahead_pushes_a_forward_command_back_harder_the_further_it_goes(side):
    f = _wall_feasible(side)
    cmds = np.asarray(f.commands)
    np.testing.assert_array_equal(np.asarray(f.valid), cmds[:, 0] <= 0.0625 + 1e-6)  # the wall's closed form
    x = np.linspace(0.1, 0.28, 19)
    out = _forces(f, jnp.asarray(np.stack([x, 0 * x, 0 * x], 1), jnp.float32), PARAMS)
    fx = np.asarray(out.force)
    assert np.all(fx[:, 0] < 0) and np.all(np.diff(fx[:, 0]) < 0)  # backwards, growing
    # Hardly sideways: the soft min blends in the cells beside the nearest (one side only at the hull's
    # edge), whose distance differs by ~h_y^2 / 2 depth, a few temperatures deep in the wall.
    assert np.all(np.abs(fx[:, 1:]) <= 0.03 * np.abs(fx[:, :1]))
    depth = (x - WALL_EDGE) / 0.25  # distance units: fractions of a full forward deflection
    np.testing.assert_allclose(np.asarray(out.depth), depth, atol=DEPTH_TOL)
    mag = 0.8 * (1 - np.exp(-(depth - T / 2) / 0.1))
    np.testing.assert_allclose(-fx[:, 0], mag, atol=0.8 * DEPTH_TOL / 0.1)
    np.testing.assert_allclose(np.asarray(out.nearest)[:, 0], WALL_EDGE, atol=T * 0.25)
    # Along the wall, or backing off from it: open, no force; diagonally into it: back, hardly sideways.
    y = 0.15 * -side
    along = _forces(f, jnp.asarray([[0.0, y, 0.0], [0.05, y / 2, 0.2], [-0.2, 0.0, 0.0]], jnp.float32), PARAMS)
    assert np.all(np.asarray(along.force) == 0.0)
    diag = np.asarray(cue.force(f, [0.2, y / 2, 0.0]))
    assert diag[0] < -0.5 and abs(diag[1]) < 0.01 * abs(diag[0]) and diag[2] == pytest.approx(0.0, abs=1e-6)


def test_force_against_numpy_geometry_on_clutter():
    rng = np.random.default_rng(3)
    checked = 0
    for seed in range(3):
        terrain = _clutter(seed)
        for _ in range(2):
            stance = np.array([rng.uniform(0.9, 1.2), rng.uniform(0.8, 1.2), rng.uniform(-0.5, 0.5)])
            side = int(rng.choice([-1, 1]))
            f = cue.feasible_commands(terrain, ROBOT, stance, side)
            lo, hi = np.asarray(f.lo), np.asarray(f.hi)
            cmds = rng.uniform(lo + 2 * T * np.asarray(f.unit), hi - 2 * T * np.asarray(f.unit), (200, 3))
            cmds[:, 2] = np.asarray(f.commands)[rng.integers(0, N, 200), 2]  # on a turn layer
            out = _forces(f, jnp.asarray(cmds, jnp.float32), PARAMS)
            for i, c in enumerate(cmds):
                depth, nearest, clipped, d1, d2, dmin = _reference(f, c)
                force = np.asarray(out.force[i])
                if depth <= 0 and dmin == 0:  # inside a valid cell: exactly no force
                    assert np.all(force == 0) and not bool(out.blocked[i])
                    continue
                if dmin > 0 or d2 - d1 < 20 * T or depth < 5 * T:
                    continue  # near a tie or a face: the soft geometry blends, checked by the bounds below
                checked += 1
                assert float(out.depth[i]) == pytest.approx(depth, abs=DEPTH_TOL)
                mag = 0.8 * -np.expm1(-(depth - T / 2) / 0.1)
                assert np.linalg.norm(force) == pytest.approx(mag, abs=0.8 * DEPTH_TOL / 0.1)
                np.testing.assert_allclose(np.asarray(out.nearest[i]), nearest, atol=2 * T * 0.25)
                n = (nearest - clipped) / np.asarray(f.full_scale)
                np.testing.assert_allclose(force / np.linalg.norm(force), n / np.linalg.norm(n), atol=0.02)
            # Everywhere: the soft depth within the soft min's bounds of the hard one, the force in range.
            assert np.all(np.abs(np.asarray(out.force)) <= 0.8 + 1e-6)
    assert checked > 100  # enough blocked, non-degenerate commands were compared


@jax.jit
def _choices(terrain, stance, side, index, foot_costs, commands):
    return jax.vmap(lambda j: ij.select_step(terrain, ROBOT, stance, side, j, targets=TARGETS, index=index,
                                             foot_costs=foot_costs))(commands)


def test_consistent_with_select_step():
    """Zero force: select_step takes one of the actions nearest its target (it follows the command). No
    valid step: a full force, flagged. A step that deviates from the command by more than a lattice spacing:
    a force."""
    rng = np.random.default_rng(7)
    lo, hi = ij.robots.command_range(ROBOT)
    counts = dict(zero=0, deviates=0, none=0)
    for seed in range(3):
        terrain = _clutter(seed + 10)
        index = ij.footcost.index_terrain(terrain, ROBOT)
        for _ in range(3):
            stance = np.array([rng.uniform(0.9, 1.2), rng.uniform(0.8, 1.2), rng.uniform(-np.pi, np.pi)])
            side = int(rng.choice([-1, 1]))
            f = cue.feasible_commands(terrain, ROBOT, stance, side, index=index)
            cmds = rng.uniform(lo, hi, (150, 3)).astype(np.float32)
            out = _forces(f, jnp.asarray(cmds), PARAMS)
            ch = _choices(terrain, jnp.asarray(stance, jnp.float32), side, index, f.cost, jnp.asarray(cmds))
            acts = np.asarray(ij.robots.side_actions(ROBOT, -side), np.float64)
            target = np.asarray(jax.vmap(lambda p, stance=stance: ij.geometry.relative(jnp.asarray(
                stance, jnp.float32), p))(ch.target), np.float64)
            all_d = np.asarray(dist(acts[None], target[:, None], float(ROBOT.rotation_weight)))  # (B, N)
            idx = np.asarray(ch.index)
            chosen_d = all_d[np.arange(len(idx)), np.maximum(idx, 0)]
            excess = chosen_d - all_d.min(1)
            zero = np.all(np.asarray(out.force) == 0, axis=1)
            assert np.all(np.asarray(ch.valid)[zero]) and np.all(excess[zero] <= TIE_TOL)
            none = ~np.asarray(ch.valid)
            assert np.all(np.asarray(out.no_valid)[none])
            deviates = np.asarray(ch.valid) & (excess > 0.05)
            assert not np.any(zero & deviates)
            counts["zero"] += zero.sum()
            counts["deviates"] += deviates.sum()
            counts["none"] += none.sum()
    assert counts["zero"] > 100 and counts["deviates"] > 50  # both sides of the property were exercised


_grad_command = jax.jit(jax.grad(lambda f, c, p: jnp.sum(cue.force_terms(f, c, p).force), argnums=1))
_grad_params = jax.jit(jax.grad(lambda f, c, p: jnp.sum(cue.force_terms(f, c, p).force), argnums=2))


def test_no_valid_action_is_a_flagged_full_force_towards_the_centre():
    blocked = _terrain(np.zeros(SHAPE, bool))
    f = cue.feasible_commands(blocked, ROBOT, STANCE, -1)
    assert not bool(f.any_valid)
    for command in ([0.2, 0.0, 0.0], [-0.1, 0.1, 0.3], [0.0, 0.0, -0.4]):
        out = cue.force_terms(f, command, c1=0.6)
        stick = np.asarray(command) / np.asarray(f.full_scale)
        assert bool(out.no_valid) and bool(out.blocked) and float(out.depth) == np.inf
        np.testing.assert_allclose(np.asarray(out.force), -0.6 * stick / np.linalg.norm(stick), atol=0.01)
        grad = _grad_command(f, jnp.asarray(command, jnp.float32), PARAMS)
        assert np.all(np.isfinite(np.asarray(grad)))
    assert np.all(np.asarray(cue.force(f, [0.0, 0.0, 0.0])) == 0.0)  # at the centre: nowhere to push
    # An unsupported robot (margin beyond its window, set inside a trace) blocks everything the same way.
    wide = ROBOT.replace(margin=jnp.float32(0.5))  # inside a trace the robot's values are not checked
    g = jax.jit(lambda robot: cue.feasible_commands(FLAT, robot, STANCE, -1))(wide)
    assert bool(g.unsupported) and not bool(g.any_valid)


def test_nonfinite_command_and_bad_params_inside_jit_give_a_flagged_zero_force():
    f = _wall_feasible()
    run = jax.jit(cue.force_terms)  # the checks skip traced values
    out = run(f, jnp.array([np.nan, 0.0, 0.0]), PARAMS)
    assert bool(out.nonfinite_command) and np.all(np.asarray(out.force) == 0)
    for bad in (dict(c1=jnp.float32(1.5)), dict(decay=jnp.float32(0.0)), dict(temperature=jnp.float32(np.nan)),
                dict(scales=jnp.array([1.0, -1.0, 1.0], jnp.float32)), dict(c1=jnp.float32(-np.inf))):
        out = run(f, jnp.array([0.25, 0.0, 0.0]), PARAMS.replace(**bad))
        assert bool(out.bad_params) and np.all(np.asarray(out.force) == 0), bad
        g = _grad_params(f, jnp.array([0.25, 0.0, 0.0]), PARAMS.replace(**bad))
        assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(g)), bad


def test_rotating_the_world_by_quarter_turns_leaves_the_force_unchanged():
    terrain = _clutter(21)
    free = np.asarray(terrain.free)
    centre = SHAPE[0] * RES / 2
    stance = np.array([1.02, 0.93, 0.4])
    cmds = jnp.asarray(np.random.default_rng(0).uniform([-0.3, -0.2, -0.5], [0.3, 0.2, 0.5], (64, 3)), jnp.float32)
    base = None
    for k in range(4):
        c, s = np.cos(k * np.pi / 2), np.sin(k * np.pi / 2)
        p = stance[:2] - centre
        rotated = np.array([centre + c * p[0] - s * p[1], centre + s * p[0] + c * p[1], stance[2] + k * np.pi / 2])
        f = cue.feasible_commands(_terrain(np.rot90(free, k)), ROBOT, rotated, 1)
        out = np.asarray(_forces(f, cmds, PARAMS).force)
        if base is None:
            base = (np.asarray(f.valid), out)
            assert 0 < base[0].sum() < N and np.any(out != 0)
        else:
            np.testing.assert_array_equal(np.asarray(f.valid), base[0])
            np.testing.assert_allclose(out, base[1], atol=1e-6)


@pytest.mark.slow
@settings(max_examples=3)
@given(st.floats(-math.pi, math.pi))
def test_rotating_the_world_by_any_angle_leaves_the_force_unchanged(angle):
    """A wall rasterised at any heading, 0.184 m ahead of the stance foot along it: 2.2 cm from the nearest
    valid footprint, 0.7 cm into the nearest invalid one, so a 1 cm grid (cells within 1.41 cm of the wall)
    cannot change any action's validity."""
    res, n = 0.01, 140
    c = n * res / 2
    stance = np.array([c, c, angle])
    wall = np.array([[c + 0.184 * np.cos(angle) + 0.25 * np.cos(angle), c + 0.184 * np.sin(angle) + 0.25 * np.sin(
        angle), angle, 0.5, 2.0, 1.0]])  # 0.5 m thick, 2 m long, its near face 0.184 m ahead
    terrain = ij.terrain.scene.rasterize(ij.terrain.flat((n, n), res), boxes=wall)
    f = cue.feasible_commands(terrain, ROBOT, stance, -1)
    valid = np.asarray(f.valid)
    np.testing.assert_array_equal(valid, np.asarray(ROBOT.actions)[:, 0] <= 0.0)  # the closed form
    cmds = jnp.asarray([[0.25, 0.0, 0.0], [0.15, 0.1, 0.2], [0.05, 0.0, -0.3], [0.0, 0.1, 0.0]], jnp.float32)
    got = np.asarray(_forces(f, cmds, PARAMS).force)
    ref = _CACHE.setdefault("any_angle", None)
    if ref is None:
        flat = cue.feasible_commands(ij.terrain.flat((n, n), res), ROBOT, [c, c, 0.0], -1)
        ref = np.asarray(_forces(flat.replace(valid=jnp.asarray(valid), any_valid=jnp.bool_(True)), cmds,
                                 PARAMS).force)
        _CACHE["any_angle"] = ref
    np.testing.assert_allclose(got, ref, atol=1e-6)
    assert got[0, 0] < -0.5


def test_left_and_right_stance_feet_mirror():
    terrain = _clutter(5)
    free = np.asarray(terrain.free)
    y_c = SHAPE[1] * RES / 2
    stance = np.array([1.05, 1.07, 0.3])
    mirrored = np.array([1.05, 2 * y_c - 1.07, -0.3])
    f = cue.feasible_commands(terrain, ROBOT, stance, -1)
    g = cue.feasible_commands(_terrain(free[:, ::-1]), ROBOT, mirrored, 1)
    np.testing.assert_array_equal(np.asarray(f.valid), np.asarray(g.valid))
    assert 0 < int(f.valid.sum()) < N
    np.testing.assert_allclose(np.asarray(g.commands), _mirror(f.commands), atol=1e-7)
    cmds = np.random.default_rng(1).uniform([-0.3, -0.2, -0.5], [0.3, 0.2, 0.5], (128, 3)).astype(np.float32)
    a = np.asarray(_forces(f, jnp.asarray(cmds), PARAMS).force)
    b = np.asarray(_forces(g, jnp.asarray(_mirror(cmds), jnp.float32), PARAMS).force)
    np.testing.assert_allclose(b, _mirror(a), atol=1e-6)
    assert np.any(a != 0)


@pytest.mark.slow
def test_batched_over_thousands_of_stances_and_commands_matches_one_at_a_time():
    terrain = _clutter(2)
    rng = np.random.default_rng(11)
    stances = np.column_stack([rng.uniform(0.8, 1.2, 64), rng.uniform(0.8, 1.2, 64), rng.uniform(-3, 3, 64)])
    sides = rng.choice([-1, 1], 64)
    feas = jax.jit(jax.vmap(lambda s, sd: cue.feasible_commands(terrain, ROBOT, s, sd)))(
        jnp.asarray(stances, jnp.float32), jnp.asarray(sides))
    which = rng.integers(0, 64, 2048)
    cmds = jnp.asarray(rng.uniform([-0.3, -0.2, -0.5], [0.3, 0.2, 0.5], (2048, 3)), jnp.float32)
    batched = jax.jit(jax.vmap(lambda i, c: cue.force_terms(jax.tree_util.tree_map(lambda x: x[i], feas), c, PARAMS)))(
        jnp.asarray(which), cmds)
    assert np.asarray(batched.blocked).mean() > 0.1
    for k in rng.integers(0, 2048, 12):
        i = int(which[k])
        one = cue.feasible_commands(terrain, ROBOT, stances[i].astype(np.float32), int(sides[i]))
        np.testing.assert_array_equal(np.asarray(one.valid), np.asarray(feas.valid[i]))
        single = cue.force_terms(one, cmds[k])
        np.testing.assert_allclose(np.asarray(single.force), np.asarray(batched.force[k]), atol=1e-6)
        np.testing.assert_allclose(float(single.depth), float(batched.depth[k]), atol=1e-6)


@pytest.mark.slow
def test_gradients_match_finite_differences_in_float64():
    f32 = _wall_feasible()
    with jax.enable_x64(True):
        f = jax.tree_util.tree_map(lambda x: x.astype(jnp.float64) if x.dtype == jnp.float32 else x, f32)
        p = jax.tree_util.tree_map(lambda x: x.astype(jnp.float64), PARAMS)
        of_command = jax.jit(lambda c: cue.force_terms(f, c, p).force)
        of_params = jax.jit(lambda c, c1, decay, scales, t: cue.force_terms(f, c, p.replace(
            c1=c1, decay=decay, scales=scales, temperature=t)).force)
        for command in ([0.2, 0.05, 0.0], [0.27, 0.1, 0.1], [0.15, 0.17, -0.2]):
            c = jnp.asarray(command, jnp.float64)
            assert float(of_command(c)[0]) < -0.1
            check_grads(of_command, (c,), order=1, modes=("fwd", "rev"), eps=1e-6, atol=1e-5, rtol=1e-5)
            # Forward mode for the parameters (reverse mode is the same program's transpose, checked above).
            check_grads(lambda *q, c=c: of_params(c, *q), (p.c1, p.decay, p.scales, p.temperature), order=1,
                        modes=("fwd",), eps=1e-7, atol=1e-5, rtol=1e-5)
        # float64 gives the float32 numbers to float32 precision
        np.testing.assert_allclose(np.asarray(of_command(jnp.asarray([0.2, 0.05, 0.0], jnp.float64))),
                                   np.asarray(cue.force(f32, [0.2, 0.05, 0.0])), atol=1e-5)
    # Open commands: the gradient is exactly zero (the force is flat there), never NaN.
    assert np.all(np.asarray(_grad_command(f32, jnp.array([0.05, 0.1, 0.0]), PARAMS)) == 0)


def test_parameters_are_traced_leaves_no_recompile():
    f = _wall_feasible()
    cue.force(f, [0.25, 0.0, 0.0])
    n_force = cue.forces.compiled_programs()
    for kw in (dict(c1=0.3), dict(decay=0.02), dict(c2=0.5), dict(scales=[1.0, 2.0, 0.5]), dict(temperature=0.01)):
        cue.force(f, [0.2, 0.1, 0.0], **kw)
        cue.force(f, [0.2, 0.1, 0.0], cue.make_params(**kw))
    assert cue.forces.compiled_programs() == n_force
    cue.feasible_commands(WALL, ROBOT, STANCE, -1)
    n_feas = cue.feasible.compiled_programs()
    for stance, side, robot in (([1.0, 1.1, 0.3], 1, ROBOT), (STANCE, -1, ROBOT.replace(margin=jnp.float32(0.05))),
                                (STANCE, 1, ROBOT.replace(w=jnp.float32(3.0), step_time=jnp.float32(0.6)))):
        cue.feasible_commands(WALL, robot, stance, side)
    assert cue.feasible.compiled_programs() == n_feas
    cue.reach(f, 8)
    n_reach = cue.reachable.compiled_programs()
    cue.reach(_flat_feasible(), 8, turn_rate=0.3)
    assert cue.reachable.compiled_programs() == n_reach


def test_c2_is_aldurós_factor_per_unit_of_depth():
    f = _wall_feasible()
    a = cue.force(f, [0.25, 0.0, 0.0], c2=0.2)
    b = cue.force(f, [0.25, 0.0, 0.0], decay=-1 / math.log(0.2))
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-7)
    out = cue.force_terms(f, [0.25, 0.0, 0.0], c2=0.2)
    depth = float(out.depth)
    assert float(out.magnitude) == pytest.approx(0.8 * (1 - 0.2 ** (depth - T / 2)), abs=1e-6)  # C1 - C1 C2^d


# --------------------------------------------------------------------------- reach


def test_reach_on_open_ground_is_the_sticks_box_and_a_wall_cuts_it():
    flat = cue.reach(_flat_feasible(), 8)
    phi = 2 * np.pi * np.arange(8) / 8
    box = 1 / np.maximum(np.abs(np.cos(phi)) / 0.25, np.abs(np.sin(phi)) / 0.175)
    np.testing.assert_allclose(np.asarray(flat), box, rtol=1e-5)
    wall = np.asarray(cue.reach(_wall_feasible(), 4))
    np.testing.assert_allclose(wall, [WALL_EDGE, 0.175, 0.25, 0.175], atol=0.25 / 63 / 2 ** 10)


def test_reach_is_where_the_force_starts():
    terrain = _clutter(4)
    f = cue.feasible_commands(terrain, ROBOT, [1.0, 1.0, 0.2], -1)
    r = np.asarray(cue.reach(f, 32, turn_rate=0.1))
    phi = 2 * np.pi * np.arange(32) / 32
    box = 1 / np.maximum(np.abs(np.cos(phi)) / 0.25, np.abs(np.sin(phi)) / 0.175)
    assert np.all((r >= 0) & (r <= box + 1e-6)) and np.any(r < box - 0.01)
    inside = np.stack([0.999 * r * np.cos(phi), 0.999 * r * np.sin(phi), np.full(32, 0.1)], 1)
    beyond = np.stack([(r + 0.01) * np.cos(phi), (r + 0.01) * np.sin(phi), np.full(32, 0.1)], 1)
    hard_in = cue.is_open(f, jnp.asarray(inside, jnp.float32))
    hard_out = cue.is_open(f, jnp.asarray(beyond, jnp.float32))
    assert np.all(np.asarray(hard_in)[r > 0])
    short = r < box - 0.01
    assert np.all(~np.asarray(hard_out)[short])  # the first blocked speed follows the largest open one
    forces = np.asarray(_forces(f, jnp.asarray(beyond, jnp.float32), PARAMS).force)
    assert np.all(np.linalg.norm(forces[short], axis=1) > 0)


# --------------------------------------------------------------------------- effects


@pytest.mark.parametrize("reduction", ["project", "fold"])
def test_device_effects_play_the_cue_force(reduction):
    f = _wall_feasible()
    cfg = haptics.default_joystick_config(reduction)
    command = jnp.array([0.25, 0.05, 0.2])
    out = cue.force_terms(f, command)
    e = cue.device_effects(out, f, command, cfg)
    f3 = np.asarray(out.force) * 5.0
    planar = f3[:2] if reduction == "project" else f3[:2] + f3[2] * np.array([1.0, 0.0])
    np.testing.assert_allclose(np.asarray(e.planar), planar, atol=1e-5)
    np.testing.assert_allclose(np.asarray(haptics.constant_force(e.constant)), planar, atol=1e-5)
    # The spring at the stick's deflection plays the planar force's size, towards the nearest command.
    per = 0.03 / np.asarray(f.full_scale)
    stick = (np.asarray(command) * per)[:2]
    centre = (np.asarray(out.nearest) * per)[:2]
    np.testing.assert_allclose(np.asarray(e.spring.center), centre, atol=1e-7)
    sf = np.asarray(haptics.spring_force(e.spring, stick))
    assert np.linalg.norm(sf) == pytest.approx(np.linalg.norm(np.asarray(e.planar)), rel=1e-4)
    np.testing.assert_allclose(sf / np.linalg.norm(sf), (centre - stick) / np.linalg.norm(centre - stick), atol=1e-6)
    assert haptics.linux_constant(e.constant, 5.0)["u"]["constant"]["level"] > 0
    # Open: nothing to play.
    open_ = cue.force_terms(f, [0.0, 0.1, 0.0])
    e = cue.device_effects(open_, f, [0.0, 0.1, 0.0], cfg)
    assert float(e.constant.magnitude) == 0 and np.all(np.asarray(e.spring.positive_coefficient) == 0)


# --------------------------------------------------------------------------- the boundary


@pytest.mark.parametrize("kwargs, match", [
    (dict(c1=1.5), "c1"), (dict(c1=-0.1), "c1"), (dict(c1=np.nan), "c1"), (dict(decay=0.0), "decay"),
    (dict(decay=np.inf), "decay"), (dict(c2=1.0), "c2"), (dict(c2=0.0), "c2"), (dict(c2=np.nan), "c2"),
    (dict(scales=[1.0, 0.0, 1.0]), "scales"), (dict(scales=[1.0, 1.0]), "scales"), (dict(temperature=-1.0),
                                                                                      "temperature"),
    (dict(decay=0.1, c2=0.5), "not both"), (dict(c1="a"), "numbers"),
])
def test_bad_parameters_are_refused_naming_them(kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        cue.make_params(**kwargs)
    with pytest.raises((ValueError, TypeError), match=match):
        cue.force(_wall_feasible(), [0.2, 0.0, 0.0], **kwargs)


@settings(max_examples=30)
@given(st.one_of(
    st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=3, max_size=3).filter(
        lambda v: not np.all(np.isfinite(v))),
    st.lists(st.floats(-1.0, 1.0), min_size=0, max_size=5).filter(lambda v: len(v) != 3),
    st.just("fwd"), st.just([["a", "b", "c"]]), st.just([1e39, 0.0, 0.0])))
def test_hostile_commands_are_refused_with_a_clear_error(command):
    with pytest.raises((ValueError, TypeError), match="command"):
        cue.force(_wall_feasible(), command)


def test_bad_feasible_sets_and_reach_arguments_are_refused():
    f = _wall_feasible()
    with pytest.raises(TypeError, match="FeasibleCommands"):
        cue.force({"commands": f.commands}, [0.1, 0.0, 0.0])
    with pytest.raises(ValueError, match="one stance"):
        cue.force(jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), f), [0.1, 0.0, 0.0])
    with pytest.raises(ValueError, match="feasible.valid"):
        cue.force(f.replace(valid=f.valid[:10]), [0.1, 0.0, 0.0])
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="num_directions"):
            cue.reach(f, bad)
    with pytest.raises(ValueError, match="samples"):
        cue.reach(f, 8, samples=1)
    with pytest.raises(ValueError, match="turn_rate"):
        cue.reach(f, 8, turn_rate=np.nan)
    with pytest.raises(ValueError, match="turn_rate"):
        cue.reach(f, 8, turn_rate=[0.1, 0.2])
    with pytest.raises(TypeError, match="params"):
        cue.force(f, [0.1, 0.0, 0.0], params=(0.8, 0.1))
    with pytest.raises(ValueError, match="stance"):
        cue.feasible_commands(WALL, ROBOT, [0.9, 1.0], -1)
    with pytest.raises(ValueError, match="foot_costs"):
        ij.select_step(WALL, ROBOT, STANCE, -1, [0.1, 0.0, 0.0], foot_costs=f.cost[:5])
    with pytest.raises(ValueError, match="exhaustive"):
        ij.select_step(WALL, ROBOT, STANCE, -1, [0.1, 0.0, 0.0], foot_costs=f.cost,
                       options=ij.SelectOptions(method="ordered"))
    with pytest.raises(ValueError, match="foot_costs"):
        ij.select_step(WALL, ROBOT, STANCE, -1, [0.1, 0.0, 0.0], foot_costs=np.full(N, -1.0))
    out, cfg = cue.force_terms(f, [0.2, 0.0, 0.0]), haptics.default_joystick_config()
    with pytest.raises(TypeError, match="CueForce"):
        cue.device_effects(out.force, f, [0.2, 0.0, 0.0], cfg)
    with pytest.raises(TypeError, match="JoystickForceConfig"):
        cue.device_effects(out, f, [0.2, 0.0, 0.0], {"max_force": 5.0})
    for travel in (0.0, -0.01, np.inf, [0.03, 0.03]):
        with pytest.raises(ValueError, match="travel"):
            cue.device_effects(out, f, [0.2, 0.0, 0.0], cfg, travel=travel)
    with pytest.raises(ValueError, match="command"):
        cue.device_effects(out, f, [0.2, np.nan, 0.0], cfg)


def test_the_prepared_tick_is_the_force_split_at_the_rate_boundary():
    f = _wall_feasible()
    rng = np.random.default_rng(5)
    cmds = rng.uniform([-0.3, -0.2, -0.5], [0.3, 0.2, 0.5], (200, 3)).astype(np.float32)
    p = cue.make_params(c1=0.6, decay=0.05, scales=[1.0, 2.0, 0.5])
    tick = cue.prepare_tick(f, p)
    assert tick.cells.shape == (4, N) and tick.consts.shape == (20,)
    got = np.asarray(jax.jit(jax.vmap(cue.tick_force, in_axes=(None, 0)))(tick, jnp.asarray(cmds)))
    want = np.asarray(_forces(f, jnp.asarray(cmds), p).force)
    np.testing.assert_array_equal(got, want)
    assert np.any(want != 0)
    cue.tick_force(tick, cmds[0])
    n = cue.forces.compiled_programs()
    for kw in (dict(c1=0.1), dict(decay=0.3), dict(temperature=0.003)):
        cue.tick_force(cue.prepare_tick(f, **kw), cmds[1])
    assert cue.forces.compiled_programs() == n  # the parameters live in the tick's arrays: no recompile
    with pytest.raises(TypeError, match="CueTick"):
        cue.tick_force(f, cmds[0])
    with pytest.raises(ValueError, match="command"):
        cue.tick_force(tick, [np.nan, 0.0, 0.0])
    out = jax.jit(cue.tick_force)(tick, jnp.array([np.inf, 0.0, 0.0]))  # traced: flagged as zero force
    assert np.all(np.asarray(out) == 0)
