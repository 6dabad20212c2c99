"""The heading-hold turning mode (ijoy_jax.turning): the overshoot of the paper's rate mode in closed form (half a
step's turn, and a whole step per decision of latency), and the heading hold settling within half the lattice's
rotation spacing of the heading shown when the turn axis was let go (0.1 deg refined); the filter in rollouts,
traced options, hostile options.

HRP-2 at its largest turn rate turns each swing foot 20 deg past the stance foot, so the closed forms are exact
on its lattice (rotations 20/3 deg apart).
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax import control, turning

ROBOT = ij.robots.hrp2(margin=0.02)
STEP_TURN = 20.0  # deg: the action set's largest rotation per step
SPACING = 20.0 / 3.0  # deg: its rotation lattice
# deg: float32 headings of a few radians (~1e-5 deg), with room.
ANGLE_TOL = 1e-3
NUM = 8  # scenarios per study: one compiled program per (latency, mode, refine)


@pytest.mark.parametrize("latency", [0, 1])
def test_the_rate_mode_overshoots_half_a_step_and_a_step_per_decision_of_latency(latency):
    r = turning.overshoot_study(ROBOT, num=NUM, latency=latency, mode="rate", rate_range=(1.0, 1.0))
    assert np.all(r.shown >= r.goal)  # the operator lets go once the goal is shown
    np.testing.assert_allclose(r.overshoot, 0.5 * STEP_TURN + latency * STEP_TURN, atol=ANGLE_TOL)


@pytest.mark.slow
def test_heading_hold_settles_within_half_a_rotation_spacing_of_the_heading_shown():
    r = turning.overshoot_study(ROBOT, num=NUM, latency=1, mode="heading", rate_range=(0.5, 1.0))
    assert np.all(np.abs(r.overshoot) <= 0.5 * SPACING + ANGLE_TOL)
    rate = turning.overshoot_study(ROBOT, num=NUM, latency=1, mode="rate", rate_range=(0.5, 1.0))
    np.testing.assert_allclose(rate.goal, r.goal)  # the same scenarios
    assert np.all(rate.overshoot > 0.5 * SPACING + ANGLE_TOL)  # each of which the rate mode overshot


@pytest.mark.slow
def test_heading_hold_refined_reaches_the_heading_shown():
    r = turning.overshoot_study(ROBOT, num=NUM, latency=0, mode="heading", rate_range=(0.5, 1.0), refine=True)
    assert np.all(np.abs(r.overshoot) <= 0.2)  # deg: the refinement's last step is 0.2 deg


@pytest.mark.slow
def test_heading_hold_in_a_rollout_only_changes_steps_after_the_release():
    terrain = ij.terrain.flat((100, 100), 0.02)
    start = ij.robots.start_stance(ROBOT, 1.0, 1.0)
    turn = np.array([[0.1, 0.0, 0.436]] * 3 + [[0.1, 0.0, 0.0]] * 4)
    rate = ij.rollout(terrain, ROBOT, start, turn, num_steps=7)
    hold = ij.rollout(terrain, ROBOT, start, turn, num_steps=7, command_filter=turning.heading_hold())
    # While the axis is held, the same steps; once let go, the feet come back to the heading shown then.
    np.testing.assert_array_equal(np.asarray(rate.footsteps[:3]), np.asarray(hold.footsteps[:3]))
    shown = math.degrees(float(turning.body_heading(40.0 * math.pi / 180, 60.0 * math.pi / 180)))  # feet 40, 60
    feet = np.degrees(np.asarray(hold.feet[:, 2]))
    assert abs(feet[0] - feet[1]) < ANGLE_TOL and abs(feet[0] - shown) <= 0.5 * SPACING + ANGLE_TOL
    assert np.allclose(np.degrees(np.asarray(rate.feet[:, 2])), 60.0, atol=ANGLE_TOL)  # the rate mode: 60
    # The deadband and tolerance are traced: new values never recompile the rollout.
    before = control.compiled_programs()
    for deadband, tol in ((0.01, 0.4), (0.2, 0.6)):
        ij.rollout(terrain, ROBOT, start, turn, num_steps=7, command_filter=turning.heading_hold(deadband, tol))
    assert control.compiled_programs() == before


def test_a_non_finite_command_passes_through_and_is_flagged():
    f = turning.heading_hold().build(ROBOT)
    start = jnp.asarray(ij.robots.start_stance(ROBOT, 1.0, 1.0))
    state = f.init(start, jnp.float32(1.0))
    info = control.StanceInfo(start[1], jnp.float32(-1.0), start[0])
    _, out = f.apply(state, info, jnp.array([jnp.nan, 0.0, 0.0]))
    assert bool(jnp.isnan(out[0]))  # left as it is: the selector treats it as zero and flags it
    _, out = f.apply(state, info, jnp.array([0.2, 0.05, 0.3]))
    np.testing.assert_array_equal(np.asarray(out), np.float32([0.2, 0.05, 0.3]))  # a turn held: as given


@pytest.mark.parametrize("call, match", [
    (lambda: turning.heading_hold(deadband=-0.1), "deadband must be a finite scalar >= 0"),
    (lambda: turning.heading_hold(tolerance=float("nan")), "tolerance must be a finite scalar >= 0"),
    (lambda: turning.heading_hold(latency=-1), "latency must be an int >= 0"),
    (lambda: turning.heading_hold(latency=1.5), "latency must be an int >= 0"),
    (lambda: turning.overshoot_study(ROBOT, mode="spin"), "mode must be 'rate' or 'heading'"),
])
def test_hostile_turning_options(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_rollout_refuses_a_command_filter_without_build():
    terrain = ij.terrain.flat((50, 50), 0.02)
    with pytest.raises(TypeError, match="command_filter must be a filter spec"):
        ij.rollout(terrain, ROBOT, ij.robots.start_stance(ROBOT, 0.5, 0.5), [0.1, 0.0, 0.0], 2,
                   command_filter=object())

