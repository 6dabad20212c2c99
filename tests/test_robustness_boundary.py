"""Hostile input at the API boundary (issue #22): terrain and robot constructors, ``replace``, select_step,
rollout and foot_cost_terms.

Every case asserts one of two outcomes: a clear ValueError / TypeError that names the argument, at the
boundary; or, inside a jit (where no check can raise), a flagged result that is finite and safe (no NaN pose,
no negative cost, the reason set). Small maps, few examples and shared compiled functions keep it fast.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import robots

pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")  # 1e39 -> float32

RES = 0.02
SHAPE = (40, 40)  # 0.8 m x 0.8 m
ROBOT = robots.hrp2(density=0.1)  # 10 actions: small programs
TARGETS = ij.make_targets(ROBOT)
STANCE = np.array([0.4, 0.3, 0.0])  # a right foot, the left one swings to y ~ 0.5
TERRAIN_2D = ij.terrain.flat(SHAPE, RES)
TERRAIN_25D = ij.terrain.flat(SHAPE, RES, has_height=True)

HOSTILE = [math.nan, math.inf, -math.inf, 1e30, -1e30, 1e-30, -1e-30, -1.0, 0.0, -0.0, 1e39]
"""Float values a careless or hostile user passes (1e39 overflows float32 to inf)."""

hostile = st.sampled_from(HOSTILE) | st.floats(allow_nan=True, allow_infinity=True, width=32)
EXAMPLES = settings(max_examples=15, deadline=None)
ERRORS = (ValueError, TypeError)


def _beyond_max_heading(pose) -> bool:
    """A finite heading beyond geometry.MAX_HEADING: the boundary refuses it (no reduction by whole turns places
    it), as it refuses a pose that is not finite."""
    yaw = float(np.asarray(pose, np.float64)[2])
    return bool(np.isfinite(yaw) and abs(yaw) > ij.geometry.MAX_HEADING)


def _names(err: Exception, *names: str) -> bool:
    return any(n in str(err) for n in names)


# ----- terrain constructors -----

@EXAMPLES
@given(resolution=hostile, origin=st.tuples(hostile, hostile), h=hostile)
def test_from_arrays_refuses_or_builds_a_checked_terrain(resolution, origin, h):
    height = np.zeros((6, 5), np.float64)
    height[2, 3] = h
    try:
        t = ij.terrain.from_arrays(height, None, resolution, origin)
    except ERRORS as e:
        assert _names(e, "resolution", "origin", "height"), e
        return
    ij.terrain.check_terrain(t)  # what the constructor built passes the boundary check
    assert np.all(np.isfinite(np.asarray(t.height))) and np.all(np.isfinite(np.asarray(t.origin)))
    assert t.resolution > 0 and math.isfinite(t.resolution)


@pytest.mark.parametrize("kwargs, name", [
    (dict(height=np.zeros((0, 4))), "empty"),
    (dict(height=np.zeros(4)), "height"),
    (dict(height=np.zeros((2, 3, 4))), "height"),
    (dict(height=None, free=np.ones((4, 4), object)), "free"),
    (dict(height=None, free=np.full((4, 4), "1")), "free"),
    (dict(height=None, free=np.full((4, 4), 2)), "free"),
    (dict(height=np.zeros((4, 4)), free=np.ones((4, 5), bool)), "same shape"),
    (dict(height=np.zeros((4, 4)), origin=(0.0, 0.0, 0.0)), "origin"),
    (dict(height=np.zeros((4, 4)), origin="00"), "origin"),
    (dict(height=np.zeros((4, 4)), resolution=None), "resolution"),
    (dict(height=None), "height, free"),
])
def test_from_arrays_wrong_shapes_and_dtypes(kwargs, name):
    with pytest.raises(ERRORS, match=name):
        ij.terrain.from_arrays(**kwargs)


@EXAMPLES
@given(field=st.sampled_from(["origin", "height", "free", "resolution"]), v=hostile)
def test_terrain_replace_is_checked_at_the_boundary_and_flagged_inside_jit(field, v):
    t = TERRAIN_25D
    if field == "origin":
        bad = t.replace(origin=jnp.array([v, 0.0], jnp.float32))
    elif field == "height":
        bad = t.replace(height=t.height.at[7, 7].set(v))
    elif field == "free":
        bad = t.replace(free=jnp.full(t.shape, v, jnp.float32))  # a float mask: wrong dtype
    else:
        bad = t.replace(resolution=v)
    try:
        ij.terrain.check_terrain(bad)
    except ERRORS as e:
        assert _names(e, f"terrain.{field}"), e
        with pytest.raises(ERRORS, match=f"terrain.{field}"):
            ij.select_step(bad, ROBOT, STANCE, -1, [0.1, 0.0, 0.0], targets=TARGETS)
        refused = True
    else:
        refused = False
        if field == "origin":  # finite, yet maybe beyond where float32 holds millimetres: FootCost's frame check
            try:
                ij.footcost.xla.check_frame(bad)
            except ValueError as e:
                assert "world frame" in str(e), e
                refused = True
    if field in ("origin", "height"):  # the terrain values a trace can carry: flagged, never a valid step
        traced = (TERRAIN_2D if field == "origin" else TERRAIN_25D).replace(**{field: getattr(bad, field)})
        c = _select_jit(traced, ROBOT, jnp.asarray(STANCE), jnp.zeros(3))
        assert bool(c.unsupported) == refused and np.all(np.isfinite(np.asarray(c.pose)))
        assert not (bool(c.valid) and refused) and not np.isnan(float(c.cost))


# ----- robot constructors and replace -----

@EXAMPLES
@given(name=st.sampled_from(["margin", "foot_length", "foot_width", "step_time", "w", "rotation_weight",
                             "max_sole_pitch", "max_sole_roll", "max_sole_distance", "reach"]),
       v=hostile)
def test_hrp2_refuses_or_builds_a_checked_robot(name, v):
    try:
        robot = robots.hrp2(density=0.1, **{name: v})
    except ERRORS as e:
        assert _names(e, name, "overlap", "max_margin"), e
        return
    robots.check_robot(robot)
    assert bool(robots.robot_supported(robot))


@pytest.mark.parametrize("kwargs, name", [
    (dict(actions=np.zeros((0, 3))), "empty"),
    (dict(actions=np.zeros((4, 2))), "actions"),
    (dict(actions=[[0.0, 0.2, np.nan]]), "finite"),
    (dict(actions=[[0.0, 0.2, 0.0]], action_cost=[1.0, 2.0]), "action_cost"),
    (dict(actions=[[0.0, 0.2, 0.0]], clearance=-0.1), "clearance"),
    (dict(actions=[[0.0, 0.2, 0.0]], p0=[0.0, 0.2]), "p0"),
    (dict(actions=[[0.0, 0.2, 0.0]], margin=0.2, max_margin=0.1), "max_margin"),
])
def test_make_robot_wrong_shapes_and_values(kwargs, name):
    base = dict(foot_length=0.242, foot_width=0.13, margin=0.02, step_time=0.8)
    with pytest.raises(ERRORS, match=name):
        robots.make_robot(**{**base, **kwargs})


@pytest.mark.parametrize("name", ["foot_length", "foot_width", "margin", "max_margin"])
@pytest.mark.parametrize("value", [robots.MAX_SIZE + 0.01, 50.0, 1e30])
def test_make_robot_refuses_absurd_sizes_naming_the_field(name, value):
    """An absurd footprint or margin (a unit mistake: 240 for 0.24) would size the static windows, and every
    terrain index's padding, from it: refused above MAX_SIZE, naming the argument."""
    base = dict(actions=[[0.0, 3.0, 0.0]], foot_length=0.242, foot_width=0.13, margin=0.02, step_time=0.8)
    with pytest.raises(ValueError, match=rf"^{name} must be <= 2 m \(robots.MAX_SIZE"):
        robots.make_robot(**{**base, name: value})
    robots.make_robot(**{**base, name: robots.MAX_SIZE})  # the maximum itself is accepted


@pytest.mark.parametrize("name, value, field", [
    ("foot_length", 2.5, "robot.foot_length"),  # beyond MAX_SIZE
    ("margin", 3.0, "robot.margin"),
    ("foot_width", 0.6, "robot.foot_length/foot_width"),  # within MAX_SIZE, beyond the robot's static window
    ("margin", 0.3, "robot.margin"),  # the footprint fits, the margin does not
])
def test_replace_beyond_the_static_windows_names_the_field_and_is_flagged_inside_jit(name, value, field):
    bad = robots.set_leaf(ROBOT, name, jnp.float32(value))
    with pytest.raises(ValueError, match=field):
        robots.check_robot(bad)
    with pytest.raises(ValueError, match=field):
        ij.select_step(TERRAIN_25D, bad, STANCE, -1, [0.1, 0.0, 0.0], targets=TARGETS)
    assert not bool(robots.robot_supported(bad))
    c = _select_jit(TERRAIN_25D, bad, jnp.asarray(STANCE), jnp.array([0.1, 0.0, 0.0]))
    assert bool(c.unsupported) and not bool(c.valid) and np.all(np.isfinite(np.asarray(c.pose)))


def _one(robot, terrain, stance, command):
    return ij.select_step(terrain, robot, stance, -1, command, swing_from=stance + jnp.array([0.0, 0.19, 0.0]),
                          targets=TARGETS, options=ij.SelectOptions(method="ordered"))


_select_jit = jax.jit(lambda t, r, s, c: _one(r, t, s, c))

LEAVES = ["margin", "foot_length", "foot_width", "step_time", "w", "rotation_weight", "metrics.slope_weight",
          "metrics.band_limit", "max_sole_pitch", "max_sole_roll", "max_sole_distance"]


@EXAMPLES
@given(name=st.sampled_from(LEAVES), v=hostile)
def test_robot_replace_refused_at_the_boundary_iff_flagged_inside_jit(name, v):
    """The one rule list: a value the concrete check refuses is the value the traced check flags, and the
    flagged decision is invalid with a reason, with a finite pose and no negative cost."""
    bad = robots.set_leaf(ROBOT, name, jnp.float32(v))
    try:
        robots.check_robot(bad)
    except ValueError as e:
        assert _names(e, f"robot.{name}", "static window", "overlap"), e
        refused = True
        with pytest.raises(ValueError, match=r"robot\.|static window|overlap"):
            _one(bad, TERRAIN_25D, STANCE, np.zeros(3))
    else:
        refused = False
    c = _select_jit(TERRAIN_25D, bad, jnp.asarray(STANCE), jnp.array([0.1, 0.0, 0.0]))
    assert bool(c.unsupported) == refused
    assert np.all(np.isfinite(np.asarray(c.pose))) and not np.isnan(float(c.cost))
    assert np.all(np.isfinite(np.asarray(c.foothold)))
    assert float(c.cost) >= 0 and float(c.foot_cost) >= 0
    if refused:
        assert not bool(c.valid) and float(c.cost) == np.inf and int(c.index) == -1


@pytest.mark.parametrize("changes, err", [
    (dict(w=jnp.ones(2)), ValueError),
    (dict(p0=jnp.zeros(2)), ValueError),
    (dict(actions=jnp.zeros((ROBOT.num_actions, 2))), ValueError),
    (dict(clearance=jnp.zeros(3)), ValueError),
    (dict(margin=np.array("0.02")), TypeError),
    (dict(metrics=None), TypeError),
])
def test_robot_replace_wrong_shapes_and_dtypes(changes, err):
    with pytest.raises(err, match=r"robot\.\w+"):
        ij.select_step(TERRAIN_2D, ROBOT.replace(**changes), STANCE, -1, [0.1, 0.0, 0.0], targets=TARGETS)


# ----- select_step and foot_cost_terms arguments -----

POSES = st.tuples(hostile, hostile, hostile)


@EXAMPLES
@given(stance=POSES, command=POSES)
def test_select_step_refuses_or_flags_hostile_poses_and_commands(stance, command):
    stance, command = np.array(stance, np.float64), np.array(command, np.float64)
    try:
        c = _one(ROBOT, TERRAIN_25D, stance, command)
    except ValueError as e:  # not finite in float32, or a heading no whole-turn reduction places
        assert (not np.all(np.isfinite(stance.astype(np.float32))) or _beyond_max_heading(stance)) and _names(
            e, "stance", "swing_from"), e
        return
    assert np.all(np.isfinite(np.asarray(c.pose))) and float(c.cost) >= 0 and not np.isnan(float(c.cost))
    assert np.all(np.isfinite(np.asarray(c.foothold)))
    assert bool(c.command_ok) == bool(np.all(np.isfinite(command.astype(np.float32))))
    c = _select_jit(TERRAIN_25D, ROBOT, jnp.asarray(stance, jnp.float32), jnp.asarray(command, jnp.float32))
    assert np.all(np.isfinite(np.asarray(c.pose))) and float(c.cost) >= 0


@pytest.mark.parametrize("kwargs, name", [
    (dict(stance=[0.4, 0.3]), "stance"),
    (dict(stance=np.zeros((1, 3))), "stance"),
    (dict(stance=np.array(["0.4", "0.3", "0"])), "stance"),
    (dict(command=[]), "command"),
    (dict(command=np.array(["fast", "0", "0"])), "command"),
    (dict(command=[0.1, [0.0], 0.0]), "command"),
    (dict(stance_side="left"), "stance_side"),
    (dict(stance_side=0), "stance_side"),
    (dict(stance_side=[1, -1]), "stance_side"),
    (dict(swing_from=[np.nan, 0.0, 0.0]), "swing_from"),
    (dict(method="astar"), "method"),
    (dict(targets=np.zeros(3)), "targets"),
])
def test_select_step_wrong_arguments(kwargs, name):
    args = dict(stance=STANCE, stance_side=-1, command=[0.1, 0.0, 0.0])
    args.update(kwargs)
    stance, side, command = args.pop("stance"), args.pop("stance_side"), args.pop("command")
    with pytest.raises(ERRORS, match=name):
        options = {k: args.pop(k) for k in ("method",) if k in args}  # the search's options are one value
        ij.select_step(TERRAIN_25D, ROBOT, stance, side, command, ij.SelectOptions(**options), **args)


_terms_jit = jax.jit(lambda r, steps: ij.foot_cost_terms(TERRAIN_25D, r, STANCE, -1, steps,
                                                           action_index=jnp.zeros(steps.shape[0], jnp.int32)))


@EXAMPLES
@given(step=POSES)
def test_foot_cost_terms_of_hostile_steps_are_flagged_finite_and_never_negative(step):
    steps = np.array([step, [0.4, 0.49, 0.0]], np.float32)
    calls = [lambda: _terms_jit(ROBOT, jnp.asarray(steps))]  # traced: flagged inside the program, never refused
    if _beyond_max_heading(steps[0]):  # concrete: refused at the boundary, naming the argument
        with pytest.raises(ValueError, match="steps heading"):
            ij.foot_cost_terms(TERRAIN_25D, ROBOT, STANCE, -1, steps, action_index=[0, 0])
    else:
        calls.append(lambda: ij.foot_cost_terms(TERRAIN_25D, ROBOT, STANCE, -1, steps, action_index=[0, 0]))
    for terms in (call() for call in calls):
        total = np.asarray(terms.total)
        assert not np.isnan(total).any() and np.all(total >= 0)
        if not np.all(np.isfinite(steps[0])):
            assert np.isinf(terms.unsupported[0])
        assert np.isfinite(total[1])  # its neighbour in the batch is unaffected


@pytest.mark.parametrize("steps, err, name", [
    (np.zeros(3), ValueError, "steps"),
    (np.zeros((2, 2)), ValueError, "steps"),
    (np.full((2, 3), "x"), TypeError, "steps"),
])
def test_foot_cost_terms_wrong_steps(steps, err, name):
    with pytest.raises(err, match=name):
        ij.foot_cost_terms(TERRAIN_25D, ROBOT, STANCE, -1, steps)


def test_foot_cost_terms_of_no_steps_is_empty():
    terms = ij.foot_cost_terms(TERRAIN_2D, ROBOT, STANCE, -1, np.zeros((0, 3)))
    assert terms.total.shape == (0,)


# ----- rollout arguments -----

START = np.array([[0.3, 0.495, 0.0], [0.3, 0.305, 0.0]])


@pytest.mark.parametrize("kwargs, name", [
    (dict(num_steps=True), "num_steps"),
    (dict(num_steps=0), "num_steps"),
    (dict(num_steps=-3), "num_steps"),
    (dict(num_steps=2.5), "num_steps"),
    (dict(num_steps="3"), "num_steps"),
    (dict(num_steps=None), "num_steps"),
    (dict(start=START[:1]), "start"),
    (dict(start=START * np.nan), "start"),
    (dict(start=START + [[0.0, -0.15, 0.0], [0.0, 0.0, 0.0]]), "overlap"),
    (dict(start=START[::-1]), "crossed"),
    (dict(start=np.full((2, 3), "a")), "start"),
    (dict(commands=np.zeros((5, 3))), "commands"),
    (dict(commands=np.full(3, "go")), "commands"),
    (dict(first_swing="left"), "first_swing"),
    (dict(first_swing=0), "first_swing"),
    (dict(method="fast"), "method"),
])
def test_rollout_wrong_arguments(kwargs, name):
    args = dict(start=START, commands=[0.1, 0.0, 0.0], num_steps=3)
    args.update(kwargs)
    with pytest.raises(ERRORS, match=name):
        options = {k: args.pop(k) for k in ("method",) if k in args}  # the search's options are one value
        ij.rollout(TERRAIN_2D, ROBOT, args.pop("start"), args.pop("commands"), args.pop("num_steps"),
                   ij.SelectOptions(**options), targets=TARGETS, **args)


_rollout_jit = jax.jit(lambda r, c: ij.rollout(TERRAIN_2D, r, START, c, 4, targets=TARGETS).summary())


@EXAMPLES
@given(cmd=st.lists(POSES, min_size=4, max_size=4), margin=hostile)
def test_rollout_of_hostile_commands_and_robots_counts_what_it_flagged(cmd, margin):
    commands = np.array(cmd, np.float32)
    robot = ROBOT.replace(margin=jnp.float32(margin))
    s = {k: np.asarray(v) for k, v in _rollout_jit(robot, commands).items()}
    bad_commands = int(np.sum(~np.all(np.isfinite(commands), axis=1)))
    try:
        robots.check_robot(robot)
    except ValueError:
        assert int(s["unsupported_decisions"]) >= 1 and bool(s["stopped"]) and int(s["steps_taken"]) == 0
        return
    assert int(s["unsupported_decisions"]) == 0
    assert int(s["commands_not_finite"]) == bad_commands  # every decision's command is counted
    for k in ("distance_along", "distance_across", "mean_deviation"):
        assert np.isfinite(s[k]), k
