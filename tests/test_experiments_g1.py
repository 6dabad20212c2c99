"""The paper's experiments (V.A.1 blockage and sidestepping, V.B stepping over) with the Unitree G1's action set.

tests/test_experiments.py replicates them with HRP-2's numbers; here the same maps and checks run with
``robots.g1(margin=...)``, every expectation derived from the G1's own geometry (its sole 0.18 x 0.06 m, its
lattice's +-0.2 m steps 0.24-0.38 m apart, its p0) rather than written down, so the paper's rules are shown to
hold for a second robot: the footholds stop as close to a wall as the margin allows, slide along an L-shaped
blockage, and step over an obstacle in one foot's lane exactly when ``b < 2 L - foot length - 2 m``. The paper's
metrics alone score the 2D maps (no heights). All scenarios run as one vmapped rollout of the paper's ordered
search (one compile); the footprints are checked in NumPy, cell by cell, independently of the library.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_experiments import (  # tests/ is on sys.path (pytest rootdir import)
    EPS,
    FORWARD,
    OVER_X,
    RES,
    SHAPE_2D,
    SIDE_COMMAND,
    SIDE_Y,
    STEPS_2D,
    THICK,
    TOL,
    WALL_XS,
    X0,
    _assert_walks_safely,
    _free,
    _lattice_predicts_crossing,
    _relative,
    _repeats,
    _stances,
    scenario,
)

import ijoy_jax as ij
from ijoy_jax.control import rollout

pytestmark = pytest.mark.slow  # the G1's own compiled rollout; its robot is tested fast in test_robots_g1.py

G1 = ij.robots.g1(margin=0.02)
HL, HW = 0.5 * float(G1.foot_length), 0.5 * float(G1.foot_width)
P0_Y = float(G1.p0[1])  # the step in place's lateral offset: the feet stand this far apart
L_MAX = float(np.max(np.asarray(G1.actions)[:, 0]))  # the longest forward step (m)
# The paper's commands are HRP-2's full stick (a 0.2 m step in its 0.8 s); the G1 steps every 0.5 s
# (robots.G1_STEP_TIME), so the same ideal steps take the commands scaled by the ratio of the step times.
HRP2_STEP_TIME = 0.8
G1_FORWARD = tuple(c * HRP2_STEP_TIME / float(G1.step_time) for c in FORWARD)
G1_SIDE = tuple(c * HRP2_STEP_TIME / float(G1.step_time) for c in SIDE_COMMAND)
LANE_Y = 1.0
MARGINS = (0.02, 0.05)
OVER_LENGTHS = (0.04, 0.10, 0.14, 0.16, 0.18, 0.22)


def b_max(margin):
    """Paper V.B with the G1's numbers: the longest obstacle a swing foot can step over."""
    return 2 * L_MAX - 2 * HL - 2 * margin


def _start(x=X0, y=LANE_Y):
    return np.asarray(ij.robots.start_stance(G1, x, y), np.float32)


@functools.cache
def scenarios():
    out = {}
    for m in MARGINS:
        for xw in WALL_XS:
            free = _free(SHAPE_2D, boxes=[(xw + 0.05, 1.0, 0.0, 0.1, 2.5)])
            out[f"wall-m{m}-x{xw}"] = scenario(free, start=_start(), command=G1_FORWARD, margin=m, wall_x=xw)
    ell = _free(SHAPE_2D, boxes=[(1.2 + THICK / 2, 0.4, 0.0, THICK, 1.2), (2.7, 1.0 - THICK / 2, 0.0, 3.0, THICK)])
    out["side-ell"] = scenario(ell, start=_start(y=SIDE_Y), command=G1_SIDE, corner_y=1.0, wall_x=1.2)
    m = 0.02  # an obstacle in the right foot's lane, from the map's edge to just below the left foot's footprint
    top = int(math.floor((LANE_Y + 0.5 * P0_Y - HW - m) / RES + 1e-6))
    for b in OVER_LENGTHS:
        for x in OVER_X[::2]:
            i0 = int(round(x / RES))
            i1 = i0 + int(round(b / RES))
            out[f"over-b{b}-x{x}"] = scenario(_free(SHAPE_2D, cells=[(i0, i1, 0, top)]), start=_start(),
                                              command=G1_FORWARD, margin=m,
                                              obstacle=(i0 * RES, i1 * RES), b=b)
    return out


@functools.partial(jax.jit, static_argnames=("num_steps",))
def _rollouts(terrains, margins, starts, commands, targets, num_steps):
    axes = jax.tree_util.tree_map(lambda _: None, G1).replace(margin=0)

    def run(t, r, s, c):
        return rollout(t, r, s, c, num_steps, options=ij.SelectOptions(method="ordered"), targets=targets)

    return jax.vmap(run, in_axes=(0, axes, 0, 0))(terrains, G1.replace(margin=margins), starts, commands)


@functools.cache
def runs():
    names = list(scenarios())
    sc = [scenarios()[n] for n in names]
    traj = _rollouts(jax.tree_util.tree_map(lambda *x: jnp.stack(x), *[s.terrain() for s in sc]),
                     jnp.asarray([s.margin for s in sc], jnp.float32), jnp.asarray(np.stack([s.start for s in sc])),
                     jnp.asarray(np.stack([s.commands for s in sc])), ij.make_targets(G1), STEPS_2D)
    traj = jax.tree_util.tree_map(np.asarray, traj)
    return {n: jax.tree_util.tree_map(lambda x, i=i: x[i], traj) for i, n in enumerate(names)}


def test_the_g1s_numbers_are_its_own():
    """What every expectation below derives from: the G1's lattice and sole, not HRP-2's."""
    assert (HL, HW) == pytest.approx((0.09, 0.03)) and P0_Y == pytest.approx(0.24) and L_MAX == pytest.approx(0.2)
    assert float(G1.step_time) * G1_FORWARD[0] == pytest.approx(L_MAX)
    assert float(ij.robots.hrp2().step_time) == pytest.approx(HRP2_STEP_TIME)
    assert float(G1.step_time) == pytest.approx(ij.robots.G1_STEP_TIME)
    assert b_max(0.02) == pytest.approx(0.18)


@pytest.mark.parametrize("name", [f"wall-m{m}-x{xw}" for m in MARGINS for xw in WALL_XS])
def test_walks_up_to_a_wall_as_close_as_the_margin_allows_then_steps_in_place(name):
    sc, traj = scenarios()[name], runs()[name]
    m, wall = sc.margin, sc.info["wall_x"]
    _assert_walks_safely(name, sc, traj, half=(HL, HW))
    assert np.all(wall - (traj.footsteps[:, 0] + HL) >= m - EPS)  # never closer than the margin
    final = traj.feet[:, 0] + HL
    assert np.all(wall - final >= m - EPS) and np.all(wall - final < m + TOL), (final, wall, m)
    k = int(np.argmax(traj.in_place))
    assert traj.in_place[k] and traj.in_place[k:].all() and k <= STEPS_2D - 6, traj.in_place


def test_sidesteps_along_an_l_shaped_blockage():
    """Forward and left into an L: stopped by its wall while beside it, past the corner it walks on along the
    leg; the left foot gains ground to the left at every step."""
    sc, traj = scenarios()["side-ell"], runs()["side-ell"]
    m, corner, wall = sc.margin, sc.info["corner_y"], sc.info["wall_x"]
    _assert_walks_safely("side-ell", sc, traj, half=(HL, HW))
    np.testing.assert_allclose(traj.footsteps[:, 2], 0.0, atol=EPS)  # no rotation was commanded
    left = traj.footsteps[traj.sides > 0]
    assert np.all(np.diff(left[:, 1]) >= 0.07), left
    beside = traj.footsteps[:, 1] - HW - m < corner
    assert beside.sum() >= 4 and np.all(traj.footsteps[beside, 0] + HL + m <= wall + EPS)
    rel = _relative(_stances(sc, traj), traj.footsteps)
    assert (rel[beside, 0] < L_MAX - EPS).sum() >= 2  # steps cut short by the wall
    assert np.all(traj.feet[:, 0] - HL - m > wall + THICK), traj.feet
    assert np.all(traj.feet[:, 1] - HW - m >= corner - EPS), traj.feet


def test_steps_over_an_obstacle_in_one_lane_only_below_the_length_limit():
    bound = b_max(0.02)
    crossed_lengths = []
    for name in [n for n in scenarios() if n.startswith("over-")]:
        sc, traj = scenarios()[name], runs()[name]
        _assert_walks_safely(name, sc, traj, half=(HL, HW))
        c0, c1 = sc.info["obstacle"]
        right = traj.footsteps[traj.sides < 0]
        past = right[:, 0] - HL >= c1 - EPS
        assert np.all(past | (right[:, 0] + HL <= c0 + EPS)), (name, right)  # before it or past it, never on it
        crossed = bool(past.any())
        assert crossed == _lattice_predicts_crossing(c0, c1, sc.margin, hl=HL, l_max=L_MAX), (name, crossed)
        if sc.info["b"] <= bound - TOL:
            assert crossed and traj.feet[:, 0].min() - HL > c1, (name, traj.feet)
        if sc.info["b"] > bound:
            assert not crossed and _repeats(traj), name  # stuck behind it, walking in place
        if crossed:
            crossed_lengths.append(sc.info["b"])
    assert max(crossed_lengths) >= bound - RES, crossed_lengths  # the limit is tight: 16 cm of 18 is crossed
