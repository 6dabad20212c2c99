"""The control loop (Algorithm 1): rollout mechanics, metrics, batching and the Walker interface."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax import control
from ijoy_jax.testing import enable_x64

RES = 0.02
ROBOT = ij.robots.hrp2(margin=0.02)
START = np.array([[0.3, 0.695, 0.0], [0.3, 0.505, 0.0]])  # left, right: 19 cm apart
SHAPE = (120, 60)  # 2.4 m x 1.2 m
STEPS = 8


def test_flat_forward_walk_is_exact():
    t = ij.terrain.flat(SHAPE, RES)
    traj = ij.rollout(t, ROBOT, START, [0.25, 0.0, 0.0], STEPS)
    fs = np.asarray(traj.footsteps)
    # Full speed: each swing foot lands 0.2 m ahead of the stance foot, alternating from the left.
    np.testing.assert_array_equal(np.asarray(traj.sides), [1, -1] * (STEPS // 2))
    np.testing.assert_allclose(fs[:, 0], 0.3 + 0.2 * np.arange(1, STEPS + 1), atol=1e-5)
    np.testing.assert_allclose(fs[:, 1], [0.695, 0.505] * (STEPS // 2), atol=1e-5)
    s = {k: float(v) for k, v in traj.summary().items()}
    assert s["steps_taken"] == STEPS and s["footholds_on_obstacles"] == 0 and s["stopped"] == 0
    assert s["distance_along"] == pytest.approx(0.1 + 0.2 * (STEPS - 1), abs=1e-5)
    assert s["distance_across"] == pytest.approx(0.0, abs=1e-6) and s["mean_deviation"] < 1e-5
    np.testing.assert_allclose(np.asarray(traj.feet), fs[-2:][::1], atol=1e-6)


def test_zero_command_steps_in_place():
    t = ij.terrain.flat(SHAPE, RES)
    traj = ij.rollout(t, ROBOT, START, [0.0, 0.0, 0.0], STEPS)
    assert bool(np.all(traj.in_place)) and float(traj.summary()["distance_along"]) == 0.0
    np.testing.assert_allclose(np.asarray(traj.feet), START, atol=1e-6)


def test_right_foot_first_and_command_schedule():
    t = ij.terrain.flat(SHAPE, RES)
    cmds = np.zeros((STEPS, 3))
    cmds[4:, 0] = 0.25  # stand, then walk
    traj = ij.rollout(t, ROBOT, START, cmds, STEPS, first_swing=-1)
    np.testing.assert_array_equal(np.asarray(traj.sides), [-1, 1] * (STEPS // 2))
    assert bool(np.all(traj.in_place[:4])) and not bool(np.any(traj.in_place[4:]))


def test_stops_for_good_when_no_step_is_valid():
    # Boxed in: obstacles everywhere but a patch around the feet, too small for any step.
    boxed = np.zeros(SHAPE, bool)
    boxed[10:21, 22:40] = True
    tb = ij.terrain.from_arrays(None, boxed, RES)
    traj = ij.rollout(tb, ROBOT, START, [0.25, 0.0, 0.0], STEPS)
    assert not bool(traj.valid[0]) and bool(np.all(traj.stopped)) and not bool(np.any(traj.taken))
    np.testing.assert_allclose(np.asarray(traj.feet), START)  # nothing moved
    assert np.all(np.isfinite(np.asarray(traj.footsteps)))
    assert np.all(np.asarray(traj.index) == -1)


def test_nan_command_is_flagged_and_treated_as_no_command():
    t = ij.terrain.flat(SHAPE, RES)
    cmds = np.tile([0.25, 0.0, 0.0], (STEPS, 1))
    cmds[2] = [np.nan, 0.0, 0.0]
    traj = ij.rollout(t, ROBOT, START, cmds, STEPS)
    ok = np.asarray(traj.command_ok)
    assert not ok[2] and ok[[0, 1, 3]].all() and bool(traj.in_place[2])
    assert np.all(np.isfinite(np.asarray(traj.footsteps)))


@pytest.mark.slow
def test_vmaps_over_terrains_commands_starts_and_robot_parameters():
    rng = np.random.default_rng(0)
    n = 4
    frees = rng.random((n,) + SHAPE) > 0.01
    frees[:, 10:20, 20:40] = True  # the start area is clear
    terrains = jax.vmap(lambda f: ij.Terrain(jnp.zeros(SHAPE), f, jnp.zeros(2), RES, False))(jnp.asarray(frees))
    commands = jnp.asarray(rng.uniform([0.0, -0.1, -0.2], [0.25, 0.1, 0.2], (n, 3)), jnp.float32)
    starts = jnp.asarray(START[None] + rng.uniform(-0.02, 0.02, (n, 1, 3)) * [1, 1, 0], jnp.float32)
    robots = jax.vmap(lambda w, m: ROBOT.replace(w=w, margin=m))(jnp.array([0.5, 1.0, 2.0, 4.0]),
                                                                  jnp.array([0.02, 0.03, 0.04, 0.05]))
    f = jax.jit(jax.vmap(lambda t, r, s, c: ij.rollout(t, r, s, c, STEPS)))
    batch = f(terrains, robots, starts, commands)
    for i in range(n):
        one = ij.rollout(jax.tree_util.tree_map(lambda x, i=i: x[i], terrains),
                         jax.tree_util.tree_map(lambda x, i=i: x[i], robots), starts[i], commands[i], STEPS)
        np.testing.assert_array_equal(np.asarray(batch.index[i]), np.asarray(one.index))
        np.testing.assert_allclose(np.asarray(batch.footsteps[i]), np.asarray(one.footsteps), atol=1e-6)
    assert int(np.sum(batch.on_obstacle)) == 0


def test_rollout_does_not_recompile_for_new_values():
    t = ij.terrain.flat(SHAPE, RES)
    ij.rollout(t, ROBOT, START, [0.25, 0.0, 0.0], STEPS)
    n = control.compiled_programs()
    ij.rollout(t.replace(free=t.free.at[110, 30].set(False)), ROBOT.replace(w=jnp.float32(2.0)),
               START + 0.01, [0.1, 0.05, 0.1], STEPS)
    ij.rollout(t, ROBOT.replace(max_sole_pitch=jnp.float32(0.1), max_sole_roll=jnp.float32(0.05),
                                max_sole_distance=jnp.float32(0.3)), START, [0.1, 0.05, 0.1], STEPS)
    assert control.compiled_programs() == n


def test_custom_walker_replaces_the_robot_without_touching_the_selector():
    """A walker that lands every step 3 cm short: the loop decides from where the foot really is."""
    base = control.perfect_walker()

    def execute(state, foothold, go):
        planar = jnp.array([0, 1, 5])  # x, y, yaw of the (6,) foothold
        stance = base.stance(state).stance
        rel = ij.geometry.relative(stance, foothold[planar])
        short = ij.geometry.compose(stance, rel - jnp.array([0.03, 0.0, 0.0]))
        return base.execute(state, foothold.at[planar].set(short), go)

    walker = control.Walker(base.init, base.stance, execute, base.feet)
    t = ij.terrain.flat(SHAPE, RES)
    traj = ij.rollout(t, ROBOT, START, [0.25, 0.0, 0.0], 4, walker=walker)
    fs = np.asarray(traj.footsteps)
    # Each step lands 0.17 m ahead of the (real) stance foot: 0.47, 0.64, 0.81, 0.98.
    np.testing.assert_allclose(fs[:, 0], [0.47, 0.64, 0.81, 0.98], atol=1e-5)
    np.testing.assert_allclose(np.asarray(traj.deviation), 0.03, atol=1e-5)


def test_the_loop_runs_any_selector_stops_for_good_and_hands_each_step_its_key():
    """A selector that always steps 10 cm ahead of the stance foot, sendable while the command's x is positive:
    the loop (control.loop, also the relaxed rollout's) sends it, stops at the first unsendable step and stays
    stopped though later ones are sendable; each step's key is the one given for it."""
    walker = control.perfect_walker()

    def choose(info, command, key):
        pose = ij.geometry.compose(info.stance, jnp.array([0.1, 0.19 * -info.stance_side, 0.0]))
        foothold = jnp.concatenate([pose[:2], jnp.zeros(3), pose[2:]])
        return foothold, command[0] > 0, jax.random.key_data(key)

    def record(info, command, choice, go, stopped, before, after):
        return dict(go=go, stopped=stopped, key=choice, moved=jnp.max(jnp.abs(after - before)))

    keys = jax.random.split(jax.random.key(5), 5)
    commands = jnp.array([[0.1, 0, 0], [0.1, 0, 0], [0.0, 0, 0], [0.1, 0, 0], [0.1, 0, 0]], jnp.float32)
    state, rec = jax.jit(lambda c, k: control.loop(walker, control.Selector(choose, record), jnp.asarray(START),
                                                   jnp.float32(1), c, keys=k))(commands, keys)
    assert np.asarray(rec["go"]).tolist() == [True, True, False, False, False]
    assert np.asarray(rec["stopped"]).tolist() == [False, False, True, True, True]
    np.testing.assert_array_equal(rec["key"], jax.random.key_data(keys))
    np.testing.assert_allclose(rec["moved"], [0.1, 0.2, 0, 0, 0], atol=1e-6)  # each lands 10 cm past the other
    np.testing.assert_allclose(walker.feet(state)[:, 0], [0.4, 0.5], atol=1e-6)


@pytest.mark.slow
def test_the_walker_gets_the_full_foothold_and_the_trajectory_records_it():
    """On a 6 deg ramp along x, turning left: the walker is passed (x, y, z, roll, pitch, yaw) of each chosen step,
    the trajectory records what it was passed, and z, roll and pitch are the ramp's at each foothold (closed form
    of a sole on the plane z = tan(a) x with yaw theta: pitch = -atan(tan(a) cos(theta)),
    roll = atan2(-tan(a) sin(theta), sqrt(1 + (tan(a) cos(theta))^2)))."""
    base = control.perfect_walker()
    slope = np.tan(np.radians(6.0))

    def init(start, first_swing):
        return base.init(start, first_swing), jnp.zeros(6, jnp.float32)

    def execute(state, foothold, go):
        return base.execute(state[0], foothold, go), foothold

    walker = control.Walker(init, lambda s: base.stance(s[0]), execute, lambda s: base.feet(s[0]), lambda s: s[1])
    h = slope * (np.arange(SHAPE[0]) + 0.5)[:, None] * RES * np.ones((1, SHAPE[1]))
    t = ij.terrain.from_arrays(h, None, RES)
    traj = ij.rollout(t, ROBOT, START, [0.2, 0.0, 0.15], STEPS, walker=walker)
    fh = np.asarray(traj.footholds, np.float64)
    assert fh.shape == (STEPS, 6) and np.asarray(traj.taken).all()
    np.testing.assert_array_equal(np.asarray(traj.log), np.asarray(traj.footholds))  # what the walker was passed
    np.testing.assert_array_equal(fh[:, [0, 1, 5]], np.asarray(traj.commanded))
    np.testing.assert_array_equal(np.asarray(traj.footsteps), np.asarray(traj.commanded))  # a perfect walker
    yaw = fh[:, 5]
    assert np.ptp(yaw) > 0.3  # it turned: roll and pitch vary
    gf = slope * np.cos(yaw)
    np.testing.assert_allclose(fh[:, 2], slope * fh[:, 0], atol=2e-5)
    np.testing.assert_allclose(fh[:, 4], -np.arctan(gf), atol=2e-5)
    np.testing.assert_allclose(fh[:, 3], np.arctan2(-slope * np.sin(yaw), np.sqrt(1 + gf**2)), atol=2e-5)
    # The default walker is passed the same footholds (a 2D map: the poses, level at z = 0).
    plain = ij.rollout(ij.terrain.flat(SHAPE, RES), ROBOT, START, [0.2, 0.0, 0.15], STEPS)
    fh2 = np.asarray(plain.footholds)
    np.testing.assert_array_equal(fh2[:, [0, 1, 5]], np.asarray(plain.commanded))
    np.testing.assert_array_equal(fh2[:, 2:5], 0.0)


@pytest.mark.slow
def test_walker_warmup_iterations_settle_without_being_recorded():
    """warmup=2: two extra executes with go=False come first; the trajectory holds only the real steps."""
    base = control.perfect_walker()

    def init(start, first_swing):
        return base.init(start, first_swing), jnp.int32(0), jnp.int32(0)

    def execute(state, foothold, go):
        inner, calls, gos = state
        return base.execute(inner, foothold, go), calls + 1, gos + go.astype(jnp.int32)

    walker = control.Walker(lambda s, f: init(s, f), lambda s: base.stance(s[0]), execute,
                            lambda s: base.feet(s[0]), lambda s: jnp.stack([s[1], s[2]]), warmup=2)
    t = ij.terrain.flat(SHAPE, RES)
    traj = ij.rollout(t, ROBOT, START, [0.25, 0.0, 0.0], 4, walker=walker)
    plain = ij.rollout(t, ROBOT, START, [0.25, 0.0, 0.0], 4)
    np.testing.assert_array_equal(np.asarray(traj.log), [[3, 1], [4, 2], [5, 3], [6, 4]])  # (executes, with go)
    np.testing.assert_allclose(np.asarray(traj.footsteps), np.asarray(plain.footsteps), atol=1e-6)
    assert not np.asarray(traj.stopped).any() and np.asarray(traj.taken).all()


def test_bad_input_at_the_boundary():
    t = ij.terrain.flat(SHAPE, RES)
    with pytest.raises(ValueError, match="start"):
        ij.rollout(t, ROBOT, START[0], [0.1, 0, 0], 3)
    with pytest.raises(ValueError, match="commands"):
        ij.rollout(t, ROBOT, START, np.zeros((2, 3)), 3)
    with pytest.raises(ValueError, match="num_steps"):
        ij.rollout(t, ROBOT, START, [0.1, 0, 0], 0)
    with pytest.raises(ValueError, match="first_swing"):
        ij.rollout(t, ROBOT, START, [0.1, 0, 0], 3, first_swing=0)
    with pytest.raises(ValueError, match="start must be finite"):
        ij.rollout(t, ROBOT, START * np.nan, [0.1, 0, 0], 3)


def test_the_same_checks_run_inside_a_users_jit_and_vmap():
    """``ij.rollout`` is also the function to trace: shapes and static options are checked at trace time."""
    t = ij.terrain.flat(SHAPE, RES)
    with pytest.raises(ValueError, match="commands"):
        jax.jit(jax.vmap(lambda s: ij.rollout(t, ROBOT, s, jnp.zeros(2), 3)))(jnp.stack([START] * 2))
    with pytest.raises(ValueError, match="method"):
        jax.jit(lambda s: ij.rollout(t, ROBOT, s, jnp.zeros(3), 3, options=ij.SelectOptions(method="astar")))(START)
    with pytest.raises(ValueError, match="kernel"):
        jax.jit(lambda s: ij.rollout(t, ROBOT, s, jnp.zeros(3), 3, options=ij.SelectOptions(kernel="cuda")))(START)


@pytest.mark.slow
def test_python_lists_of_traced_values_work_inside_a_users_jit():
    """A command or stance written as a list of traced scalars (as a user's jitted code builds them) is taken
    like the array it stands for, by rollout and select_step alike; a ragged list is refused by name."""
    t = ij.terrain.flat(SHAPE, RES)
    want = ij.rollout(t, ROBOT, START, [0.25, 0.0, 0.0], 3).footsteps
    got = jax.jit(lambda v: ij.rollout(t, ROBOT, START, [v, 0.0, 0.0], 3).footsteps)(jnp.float32(0.25))
    np.testing.assert_array_equal(got, want)
    pick = lambda x: ij.select_step(t, ROBOT, [x, 0.6, 0.0], -1, [0.25, 0.0, 0.0]).index  # noqa: E731
    assert int(jax.jit(pick)(jnp.float32(0.5))) == int(pick(0.5))
    with pytest.raises(ValueError, match="commands must be an array of numbers"):
        ij.rollout(t, ROBOT, START, [0.25, [0.0], 0.0], 3)


def test_marking_time_with_staggered_feet_counts_as_stationary():
    """A 12 cm block in the right lane: the feet end up alternating between two footholds."""
    free = np.ones((200, 100), bool)
    free[50:56, :50] = False
    t = ij.terrain.from_arrays(None, free, RES)
    start = np.array([[0.3, 1.095, 0.0], [0.3, 0.905, 0.0]])
    traj = ij.rollout(t, ROBOT, start, [0.25, 0.0, 0.0], 16)
    s = traj.summary()
    assert int(s["steps_stationary"]) >= 8 and int(s["footholds_on_obstacles"]) == 0
    fs = np.asarray(traj.footsteps)
    np.testing.assert_allclose(fs[-1], fs[-3], atol=1e-6)  # the same foothold again and again
    assert fs[fs[:, 1] < 1.0, 0].max() < 1.0  # the right foot never gets past the block


COUNTS = ("steps_taken", "steps_in_place", "steps_stationary", "footholds_on_obstacles", "invalid_footholds",
          "commands_not_finite", "unsupported_decisions")


def test_summary_counts_are_int32_under_jit_and_vmap():
    t = ij.terrain.flat(SHAPE, RES)
    traj = ij.rollout(t, ROBOT, START, [0.25, 0.0, 0.0], STEPS)
    one = jax.jit(lambda tr: tr.summary())(traj)
    batched = jax.vmap(lambda tr: tr.summary())(jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), traj))
    for k in COUNTS:
        assert one[k].dtype == jnp.int32 and one[k].shape == (), k
        assert batched[k].dtype == jnp.int32 and batched[k].shape == (2,), k
    assert one["stopped"].dtype == jnp.bool_ and int(one["steps_taken"]) == STEPS
    with enable_x64():  # int32 also when x64 would make a plain sum int64
        assert traj.summary()["steps_taken"].dtype == jnp.int32


def test_naive_summary_does_not_average_invalid_footholds_away():
    """The naive joystick walks onto a block: its invalid footholds are counted and its mean FootCost is +inf
    (not the mean over the valid ones only); the intelligent joystick's is the mean over every step taken."""
    free = np.ones((200, 100), bool)
    free[50:56, :50] = False
    t = ij.terrain.from_arrays(None, free, RES)
    start = np.array([[0.3, 1.095, 0.0], [0.3, 0.905, 0.0]])
    naive = ij.rollout(t, ROBOT, start, [0.25, 0.0, 0.0], 16, options=ij.SelectOptions(method="naive"))
    s = naive.summary()
    taken, valid = np.asarray(naive.taken), np.asarray(naive.valid)
    assert int(s["invalid_footholds"]) == int(np.sum(taken & ~valid)) > 0
    assert int(s["footholds_on_obstacles"]) > 0 and float(s["mean_foot_cost"]) == np.inf
    smart = ij.rollout(t, ROBOT, start, [0.25, 0.0, 0.0], 16)
    s = smart.summary()
    taken, cost = np.asarray(smart.taken), np.asarray(smart.foot_cost, np.float64)
    assert int(s["invalid_footholds"]) == 0 and taken.sum() > 0
    assert float(s["mean_foot_cost"]) == pytest.approx(cost[taken].mean(), abs=1e-6)


@pytest.mark.parametrize("start, match", [
    (np.array([[0.3, 0.65, 0.0], [0.3, 0.55, 0.0]]), "overlap"),  # 10 cm apart: 13 cm wide feet overlap
    (np.array([[0.5, 0.6, 0.0], [0.3, 0.6, 0.2]]), "overlap"),  # one behind the other, touching
    (START[::-1], "crossed"),  # rows swapped: the left foot stands on the right
    (np.array([[0.3, 0.505, 0.0], [0.6, 0.695, 0.0]]), "crossed"),
])
def test_start_feet_overlapping_or_crossed_are_refused(start, match):
    t = ij.terrain.flat(SHAPE, RES)
    with pytest.raises(ValueError, match=match):
        ij.rollout(t, ROBOT, start, [0.1, 0.0, 0.0], 3)
    ij.rollout(t, ROBOT, START, [0.1, 0.0, 0.0], 3)  # apart and uncrossed: accepted
    jax.jit(lambda s: ij.rollout(t, ROBOT, s, [0.1, 0.0, 0.0], 3))(start)  # traced: not checked, no error


def test_bools_and_strings_for_numbers_get_clear_errors():
    t = ij.terrain.flat(SHAPE, RES)
    with pytest.raises(ValueError, match="num_steps must be a positive int"):
        ij.rollout(t, ROBOT, START, [0.1, 0, 0], True)  # was: one step
    with pytest.raises(ValueError, match=r"first_swing must be \+1 \(left\) or -1 \(right\)"):
        ij.rollout(t, ROBOT, START, [0.1, 0, 0], 3, first_swing="left")


def test_summary_counts_non_finite_commands_and_unsupported_decisions():
    """A NaN in the command stream is stepped in place; the summary says how often, so it is not silent. A robot
    made unsupported inside a trace stops the walk, and the summary says why."""
    t = ij.terrain.flat(SHAPE, RES)
    commands = np.tile([0.2, 0.0, 0.0], (STEPS, 1))
    commands[[2, 5]] = np.nan
    s = ij.rollout(t, ROBOT, START, commands, STEPS).summary()
    assert int(s["commands_not_finite"]) == 2 and int(s["unsupported_decisions"]) == 0
    assert int(s["steps_taken"]) == STEPS
    run = jax.jit(lambda m: ij.rollout(t, ROBOT.replace(margin=m), START, commands[0], STEPS).summary())
    s = run(jnp.float32(-0.05))
    assert int(s["unsupported_decisions"]) >= 1 and bool(s["stopped"]) and int(s["steps_taken"]) == 0
    assert int(s["commands_not_finite"]) == 0 and int(run(jnp.float32(0.02))["unsupported_decisions"]) == 0
