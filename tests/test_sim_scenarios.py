"""Some of the paper's experiments (tests/test_experiments.py) with the MJX biped in place of the perfect robot.

One vmapped, jitted MJX rollout over three 2D scenarios of the same map size
(about a minute on a CPU, most of it compile): walking up to a wall and
stepping in place, stepping over a 4 cm obstacle in the right foot's lane,
and turning on the spot. The selector is the same; the footholds are the
simulated robot's measured touch-downs. Obstacle cells are raised to
``BipedParams.obstacle_height`` (0.1 m) in the height field.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_experiments import HL, RES, SHAPE_2D, scenarios_2d

import ijoy_jax as ij
from ijoy_jax.sim import walker as W

NAMES = ("wall-m0.05-x1.44", "over-m0.02-b0.04-x1.0", "turn-1")
PLACEMENT_TOL = 0.03  # m (measured up to 0.6 cm on these scenarios)


@pytest.fixture(scope="module")
def runs():
    scs = scenarios_2d()
    scs = {k: scs[k] for k in NAMES}
    robot = ij.robots.hrp2()
    sim = W.make_sim(SHAPE_2D, RES, robot=robot)
    batch = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *[sc.terrain() for sc in scs.values()])
    robots = jax.tree_util.tree_map(lambda *a: jnp.stack(a),
                                    *[ij.robots.hrp2(margin=sc.margin, w=sc.w) for sc in scs.values()])
    starts = jnp.stack([jnp.asarray(sc.start) for sc in scs.values()])
    commands = jnp.stack([jnp.asarray(sc.commands) for sc in scs.values()])
    n = commands.shape[1]
    traj = jax.jit(jax.vmap(lambda t, r, s, c: W.rollout_core(sim, t, r, s, c, n)))(batch, robots, starts, commands)
    traj = jax.tree_util.tree_map(np.asarray, traj)
    return {k: (sc, jax.tree_util.tree_map(lambda a, i=i: a[i], traj)) for i, (k, sc) in enumerate(scs.items())}


@pytest.mark.parametrize("name", NAMES)
def test_no_fall_no_obstacle_touched(runs, name):
    _, traj = runs[name]
    assert traj.taken.all() and not traj.log.fallen.any()
    assert not traj.log.obstacle_contact.any()  # neither the soles nor the shins touched an obstacle cell
    assert traj.log.placement_error.max() < PLACEMENT_TOL, traj.log.placement_error


def test_wall_approach_then_step_in_place(runs):
    sc, traj = runs["wall-m0.05-x1.44"]
    front = traj.footsteps[:, 0] + HL  # the feet face +x (no turning command)
    assert front.max() < sc.info["wall_x"]  # never on the wall
    # but up close: within the margin, one cell and one lattice step (as the perfect robot), plus the placement error
    assert front.max() > sc.info["wall_x"] - sc.margin - (RES + 0.05) - PLACEMENT_TOL
    assert traj.in_place[-4:].all()  # and stepping in place there


def test_steps_over_the_obstacle(runs):
    sc, traj = runs["over-m0.02-b0.04-x1.0"]
    x1 = sc.info["obstacle"][1]
    assert traj.feet[:, 0].min() > x1 + HL  # both feet beyond the obstacle's far edge at the end


def test_turns_on_the_spot(runs):
    sc, traj = runs["turn-1"]
    heading = np.unwrap(traj.footsteps[:, 2])
    assert abs(heading[-1] - heading[0]) > 0.5 * abs(sc.info["rot"]) * (len(heading) - 1) / 2
    assert np.ptp(traj.footsteps[:, :2], axis=0).max() < 0.5  # on the spot: the feet stay within half a metre
