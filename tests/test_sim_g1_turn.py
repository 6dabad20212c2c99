"""The G1 in MJX turning in place at the stick's full turn rate, both ways (slow tier: one compile, about two
minutes on a CPU).

Turning in place is where the plan's frame once drifted: its heights were anchored on the stance sole as
measured at each step's start, each touch-down came about 1.3 mm higher than the last, and after 8-10 steps the
G1 landed in the air and fell (``walker.plan_frame_position`` keeps the world's height now).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax.sim import walker as W

pytestmark = pytest.mark.slow

SHAPE, RES = (100, 100), 0.02  # 2 m x 2 m of flat ground at height 0
STEPS = 14  # the heading passes pi on the 9th step either way
RATE = 0.7  # rad/s: 0.35 rad a 0.5 s step, the G1's largest turn in place (robots.g1's lattice)
GROUND_TOL = 0.004  # m: a loaded sole sinks 2-4 mm into the soft contact; hovering ones measured up to 13 mm


@pytest.fixture(scope="module")
def turned():
    robot = ij.robots.g1(margin=0.02)
    sim = W.make_sim(SHAPE, RES, robot=robot, model="g1")
    terrain = ij.terrain.flat(SHAPE, RES, has_height=True)
    terrains = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), terrain)
    robots = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), robot)
    starts = jnp.stack([ij.robots.start_stance(robot, 1.0, 1.0)] * 2)
    cmd = jnp.stack([jnp.broadcast_to(jnp.array([0.0, 0.0, r], jnp.float32), (STEPS, 3)) for r in (RATE, -RATE)])
    traj = W.rollout_batch(sim, terrains, robots, starts, cmd, num_steps=STEPS)
    return terrain, jax.tree_util.tree_map(np.asarray, traj)


def test_the_g1_turns_in_place_both_ways_without_falling_its_soles_on_the_ground(turned):
    terrain, traj = turned
    assert not traj.log.fallen.any() and traj.taken.all()
    # every touch-down on the ground the terrain arrays hold (all 0 here), not above it
    ground = float(np.asarray(terrain.height).max())
    assert np.abs(traj.log.landed[..., 2] - ground).max() < GROUND_TOL, traj.log.landed[..., 2]
    # it turned as the selector chose, both ways: the soles' headings follow the footholds to within 3 deg
    assert np.abs(traj.log.yaw_error).max() < np.radians(3)
    turn = np.unwrap(traj.footsteps[..., 2], axis=1)
    assert turn[0, -1] - turn[0, 0] > 0.8 * RATE * 0.5 * (STEPS - 1)
    assert turn[1, -1] - turn[1, 0] < -0.8 * RATE * 0.5 * (STEPS - 1)
    # in place: the feet stay within a step of where they started
    centre = traj.footsteps[..., :2].mean(axis=1, keepdims=True)
    assert np.hypot(*np.moveaxis(traj.footsteps[..., :2] - centre, -1, 0)).max() < 0.3
