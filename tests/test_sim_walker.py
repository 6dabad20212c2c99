"""The MJX biped in the joystick loop (ijoy_jax.sim.walker): one small jitted rollout, checked end to end.

MJX compiles slowly on a CPU (about a minute), so this file runs one rollout
(two steps in place, then four 0.2 m steps forward) and checks everything on
it; the controller's physics is tested with native MuJoCo in
test_sim_controller.py.
"""

import jax
import numpy as np
import pytest

from ijoy_jax import robots
from ijoy_jax import terrain as T
from ijoy_jax.sim import walker as W

PLACEMENT_TOL = 0.03  # m: touch-down error (measured up to ~1.1 cm for action-set steps with native MuJoCo)
COMMANDS = np.array([[0.0, 0.0, 0.0]] * 2 + [[0.25, 0.0, 0.0]] * 4, np.float32)  # in place twice, then 0.2 m steps


@pytest.fixture(scope="module")
def result():
    robot = robots.hrp2()
    shape = (150, 80)  # 3 m x 1.6 m, the feet well inside
    terrain = T.from_arrays(np.zeros(shape), None, 0.02, origin=(-1.0, -0.8)).replace(has_height=True)
    sim = W.make_sim(shape, 0.02, robot=robot)
    start = np.array([[0.0, 0.095, 0.0], [0.0, -0.095, 0.0]], np.float32)
    traj = W.rollout(sim, terrain, robot, start, COMMANDS, num_steps=len(COMMANDS))
    return jax.tree_util.tree_map(np.asarray, traj), sim


def test_steps_in_place_then_walks_forward_without_falling(result):
    traj, _ = result
    assert traj.taken.all() and traj.valid.all() and not traj.stopped.any()
    assert traj.in_place[:2].all()  # a zero command on flat ground: the step-in-place action p0
    np.testing.assert_allclose(np.diff(traj.commanded[2:, 0]), 0.2, atol=0.03)  # each 0.2 m ahead of the last
    assert traj.footsteps[-1, 0] > 0.7  # the measured feet went forward with them
    assert not traj.log.fallen.any()
    assert (traj.log.placement_error < PLACEMENT_TOL).all(), traj.log.placement_error
    assert not traj.log.obstacle_contact.any()


def test_footsteps_are_the_measured_touch_downs(result):
    traj, _ = result
    np.testing.assert_allclose(traj.footsteps, traj.log.landed[:, [0, 1, 3]], atol=1e-6)
    err = np.hypot(*(traj.footsteps[:, :2] - traj.commanded[:, :2]).T)
    np.testing.assert_allclose(err, traj.log.placement_error, atol=1e-5)
    assert traj.sides.tolist() == [1, -1] * 3


def test_summary(result):
    traj, _ = result
    s = {k: np.asarray(v) for k, v in W.summary(traj).items()}
    assert not s["fell"] and s["obstacle_contacts"] == 0 and s["steps_taken"] == len(COMMANDS)
    assert np.isfinite(s["placement_error_p95"]) and s["placement_error_p95"] < PLACEMENT_TOL


def test_bad_inputs_are_refused_before_compiling(result):
    _, sim = result
    robot = robots.hrp2()
    wrong = T.from_arrays(np.zeros((50, 50)), None, 0.02).replace(has_height=True)
    with pytest.raises(ValueError, match="does not match"):
        W.rollout(sim, wrong, robot, np.zeros((2, 3)), np.zeros(3), num_steps=1)
    with pytest.raises(ValueError, match="step_time"):
        W.rollout(sim, T.from_arrays(np.zeros(sim.shape), None, 0.02).replace(has_height=True),
                  robots.hrp2(step_time=0.6), np.zeros((2, 3)), np.zeros(3), num_steps=1)
