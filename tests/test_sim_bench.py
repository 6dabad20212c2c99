"""The MJX benchmark's random joystick: commands inside what the action set can realise, held as asked."""

import jax
import numpy as np
import pytest

from ijoy_jax import robots
from ijoy_jax.sim import bench


def test_command_range_spans_the_action_set_around_step_in_place():
    robot = robots.hrp2()
    lo, hi = bench.command_range(robot)
    acts, p0, dt = np.asarray(robot.actions), np.asarray(robot.p0), robot.step_time
    # p0 + dt * j reaches the action set's extremes exactly at the range's ends (x both ways, y and theta outward)
    np.testing.assert_allclose(p0[0] + dt * lo[0], acts[:, 0].min(), atol=1e-6)
    np.testing.assert_allclose(p0[0] + dt * hi[0], acts[:, 0].max(), atol=1e-6)
    np.testing.assert_allclose(p0[1] + dt * hi[1], acts[:, 1].max(), atol=1e-6)
    np.testing.assert_allclose(dt * hi[2], np.abs(acts[:, 2]).max(), atol=1e-6)
    np.testing.assert_allclose(lo[1:], -hi[1:])


@pytest.mark.parametrize("hold", [1, 4, 7, 30])
def test_random_commands_stay_in_range_and_are_held(hold):
    robot = robots.hrp2()
    lo, hi = bench.command_range(robot)
    cmds = np.asarray(bench.random_commands(jax.random.key(3), robot, 64, 30, hold))
    assert cmds.shape == (64, 30, 3)
    assert np.all(cmds >= lo - 1e-6) and np.all(cmds <= hi + 1e-6)
    starts = np.arange(0, 30, hold)
    for k in range(30):  # every step repeats its block's first command ...
        np.testing.assert_array_equal(cmds[:, k], cmds[:, starts[starts <= k][-1]])
    if len(starts) > 1:  # ... and the blocks draw new ones
        assert np.all(np.any(cmds[:, starts[1:]] != cmds[:, starts[:-1]], axis=-1))
    # uniform over the range: each axis covers it (64 robots x blocks draws)
    draws = cmds[:, starts].reshape(-1, 3)
    u = (draws - lo) / (hi - lo)
    assert np.all(u.min(0) < 0.1) and np.all(u.max(0) > 0.9)


def test_random_commands_rejects_a_hold_below_one_step():
    with pytest.raises(ValueError, match="hold"):
        bench.random_commands(jax.random.key(0), robots.hrp2(), 2, 5, 0)
