"""Robot models and action sets."""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import robots
from ijoy_jax.jit_cache import compiled_count


def test_hrp2_matches_the_paper():
    r = ij.robots.hrp2(margin=0.05)
    a = np.asarray(r.actions, np.float64)
    assert a.shape == (496, 3)
    assert np.abs(a[:, 0]).max() == pytest.approx(0.20) and a[:, 0].min() == pytest.approx(-0.20)
    assert a[:, 1].min() == pytest.approx(0.19) and a[:, 1].max() == pytest.approx(0.33)
    assert np.abs(a[:, 2]).max() == pytest.approx(math.radians(20), rel=1e-6)
    assert float(r.foot_length) == pytest.approx(0.242) and float(r.foot_width) == pytest.approx(0.13)
    assert float(r.margin) == pytest.approx(0.05)
    assert len(np.unique(a.round(6), axis=0)) == 496
    assert not robots.footprints_overlap(a, 0.242, 0.13).any()
    # Step in place is an action, straight steps (dtheta = 0) exist at every dx.
    assert np.any(np.all(np.isclose(a, np.asarray(r.p0)), axis=1))
    assert set(np.round(a[np.isclose(a[:, 2], 0)][:, 0], 3)) == set(np.round(np.linspace(-0.2, 0.2, 9), 3))


@pytest.mark.parametrize("name, factory", [("biped", robots.hrp2), ("g1", robots.g1)])
def test_each_simulated_robot_has_its_selector_robot(name, factory):
    # the walker's names (ijoy_jax.sim.bodies.MODELS, which needs MuJoCo) and the selector's robot for each
    from ijoy_jax.sim import bodies

    assert robots.MODELS == bodies.MODELS
    got, want = robots.for_model(name, margin=0.05, density=0.5), factory(margin=0.05, density=0.5)
    for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("name", ["G1", "atlas", "", None])
def test_an_unknown_robot_name_is_refused_naming_the_known(name):
    with pytest.raises(ValueError, match="model must be one of biped, g1, got"):
        robots.for_model(name)


@pytest.mark.parametrize("margin", [0.02, 0.05, 0.10])
def test_paper_margins_fit_the_default_window(margin):
    r = ij.robots.hrp2(margin=margin)
    assert 0.5 * math.hypot(0.242 + 2 * margin, 0.13 + 2 * margin) <= r.max_radius + 1e-12


def test_mirroring():
    r = ij.robots.hrp2()
    left, right = np.asarray(robots.side_actions(r, 1)), np.asarray(robots.side_actions(r, -1))
    np.testing.assert_allclose(right, left * [1, -1, -1])
    np.testing.assert_allclose(np.asarray(robots.side_p0(r, -1)), np.asarray(r.p0) * [1, -1, -1])


@pytest.mark.parametrize("density, size", [(0.1, 10), (0.25, 19), (0.5, 117), (1.0, 496), (2.0, 3307)])
def test_density_sweeps_size_over_the_same_ranges(density, size):
    a = np.asarray(ij.robots.hrp2(density=density).actions)
    assert a.shape == (size, 3)
    np.testing.assert_allclose([a[:, 0].min(), a[:, 0].max(), a[:, 1].min(), a[:, 1].max()],
                               [-0.2, 0.2, 0.19, 0.33], atol=1e-6)
    np.testing.assert_allclose(np.abs(a[:, 2]).max(), math.radians(20), rtol=1e-6)
    assert np.any(np.all(np.isclose(a, [0, 0.19, 0], atol=1e-7), axis=1)), "p0 must stay in S"


def test_footprint_overlap_reference():
    # Side by side 13 cm wide feet: overlap iff centres closer than 13 cm.
    assert robots.footprints_overlap([[0, 0.12, 0]], 0.242, 0.13)[0]
    assert not robots.footprints_overlap([[0, 0.13, 0]], 0.242, 0.13)[0]
    assert robots.footprints_overlap([[0.2, 0.0, 0]], 0.242, 0.13)[0]
    assert not robots.footprints_overlap([[0.25, 0.0, 0]], 0.242, 0.13)[0]


@pytest.mark.parametrize(
    "actions, kwargs, match",
    [
        (np.zeros((0, 3)), {}, "empty"),
        (np.zeros((4, 2)), {}, "shape"),
        ([[0.0, 0.2, np.nan]], {}, "finite"),
        ([[0.0, 0.05, 0.0]], {}, "overlap"),
        ([[0.0, 0.2, 0.0]], dict(foot_length=0.0), "foot_length"),
        ([[0.0, 0.2, 0.0]], dict(foot_width=-0.1), "foot_width"),
        ([[0.0, 0.2, 0.0]], dict(margin=-0.01), "margin"),
        ([[0.0, 0.2, 0.0]], dict(step_time=0.0), "step_time"),
        ([[0.0, 0.2, 0.0]], dict(w=float("inf")), "w must be finite"),
        ([[0.0, 0.2, 0.0]], dict(action_cost=-1.0), "action_cost"),
        ([[0.0, 0.2, 0.0]], dict(clearance=[0.1, 0.1]), "clearance"),
        ([[0.0, 0.2, 0.0]], dict(margin=0.2, max_margin=0.1), "max_margin"),
        ([[0.0, 0.2, 0.0]], dict(max_sole_pitch=-0.1), "max_sole_pitch must be >= 0"),
        ([[0.0, 0.2, 0.0]], dict(max_sole_roll=float("nan")), "max_sole_roll must be finite"),
        ([[0.0, 0.2, 0.0]], dict(max_sole_distance=float("inf")), "max_sole_distance must be finite"),
    ],
)
def test_make_robot_rejects_bad_input(actions, kwargs, match):
    base = dict(foot_length=0.242, foot_width=0.13, margin=0.02, step_time=0.8)
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        robots.make_robot(actions, **base)


def test_metrics_reject_negative_or_nan():
    with pytest.raises(ValueError, match="slope_limit"):
        robots.default_metrics(slope_limit=-0.1)
    with pytest.raises(ValueError, match="bump_weight"):
        robots.default_metrics(bump_weight=float("nan"))


def test_robot_is_a_pytree_with_static_sizes():
    r = ij.robots.hrp2()
    leaves, treedef = jax.tree_util.tree_flatten(r)
    assert all(hasattr(x, "shape") for x in leaves)
    r2 = jax.tree_util.tree_unflatten(treedef, leaves)
    assert r2.max_radius == r.max_radius and r2.num_actions == 496
    stacked = jax.tree_util.tree_map(lambda *x: np.stack(x), r, r.replace(margin=r.margin * 2))
    assert stacked.margin.shape == (2,)


def test_dotted_leaf_access():
    r = ij.robots.hrp2()
    r2 = robots.set_leaf(r, "metrics.slope_limit", 0.5)
    assert float(robots.get_leaf(r2, "metrics.slope_limit")) == 0.5
    assert float(robots.get_leaf(r, "metrics.slope_limit")) != 0.5  # the original is untouched
    assert float(robots.get_leaf(robots.set_leaf(r, "w", 3.0), "w")) == 3.0


def test_scalar_leaf_table_names_every_scalar_leaf():
    r = ij.robots.hrp2(density=0.25)
    body = ("foot_length", "foot_width", "step_time", "max_sole_pitch", "max_sole_roll", "max_sole_distance")
    scalars = {"margin", "w", "rotation_weight", *body}
    scalars |= {f"metrics.{f.name}" for f in dataclasses.fields(robots.TerrainMetrics)}
    assert set(robots.SCALAR_LEAVES) == scalars
    # every scalar leaf of the Robot pytree is listed (none forgotten when a leaf is added)
    per_action = {"actions", "p0", "action_cost", "clearance", "max_step_height"}
    tops = {f.name for f in dataclasses.fields(robots.Robot) if not f.metadata.get("static")} - per_action
    assert {n for n in scalars if not n.startswith("metrics.")} == tops - {"metrics"}
    for name, spec in robots.SCALAR_LEAVES.items():
        assert np.shape(robots.get_leaf(r, name)) == (), name
        assert spec.unit and isinstance(spec.positive, bool), name
    assert robots.SELECTOR_LEAVES == tuple(n for n in robots.SCALAR_LEAVES if n not in body)


def test_hrp2_defaults_are_hrp2s_leaves():
    d = robots.hrp2_defaults()
    r = ij.robots.hrp2()
    assert set(d) == set(robots.SCALAR_LEAVES) | {"density", "reach"}
    for name in robots.SCALAR_LEAVES:
        assert float(robots.get_leaf(r, name)) == pytest.approx(d[name], rel=1e-6), name
    assert r.num_actions == ij.robots.hrp2(density=d["density"], reach=d["reach"]).num_actions == 496
    assert np.max(np.asarray(r.actions)[:, 0]) == pytest.approx(d["reach"])


def test_set_leaves_sets_every_named_leaf_under_jit():
    r = ij.robots.hrp2(density=0.25)
    vals = {n: float(robots.get_leaf(r, n)) * 1.5 + 0.01 for n in robots.SCALAR_LEAVES}
    r2 = jax.jit(robots.set_leaves)(r, vals)
    for n, v in vals.items():
        assert float(robots.get_leaf(r2, n)) == pytest.approx(v, rel=1e-6), n
    assert float(r.w) == 1.0  # the original is untouched


def test_python_numbers_set_by_replace_keep_the_leaf_dtype_and_do_not_recompile():
    """A Python float set through replace/set_leaves was a weakly typed leaf: a jitted function of the robot
    compiled once for the preset and once more for every robot so changed (found in a physics variant run)."""
    r = ij.robots.hrp2()
    f = jax.jit(lambda robot: robot.w * robot.metrics.support_limit + robot.margin)
    f(r)
    changed = [robots.set_leaves(r, {"metrics.support_limit": 0.003, "w": 2}), r.replace(margin=0.05),
               r.replace(w=1e39)]  # beyond float32: inf, as the boundary checks see it
    for robot in changed:
        f(robot)
    assert compiled_count(f) == 1
    for robot in changed:
        leaves = (robot.w, robot.margin, robot.metrics.support_limit)
        assert all(jax.typeof(x) == jax.typeof(r.w) for x in leaves)
    assert float(changed[0].w) == 2.0 and np.isinf(float(changed[2].w))
    assert r.replace(w=True).w is True  # not a number: left for the boundary check to name

def test_command_range_spans_the_action_set_around_step_in_place():
    robot = robots.hrp2()
    lo, hi = robots.command_range(robot)
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
    lo, hi = robots.command_range(robot)
    cmds = np.asarray(robots.random_commands(jax.random.key(3), robot, 64, 30, hold))
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
        robots.random_commands(jax.random.key(0), robots.hrp2(), 2, 5, 0)


@pytest.mark.parametrize("theta", [0.0, 0.7, -2.5])
def test_start_stance_puts_the_feet_side_by_side_at_the_step_in_place_width(theta):
    robot = robots.hrp2()
    feet = np.asarray(robots.start_stance(robot, 1.5, -0.4, theta))
    assert feet.shape == (2, 3) and feet.dtype == np.float32
    np.testing.assert_allclose(feet[:, 2], theta, atol=1e-6)
    np.testing.assert_allclose(feet[:, :2].mean(0), [1.5, -0.4], atol=1e-6)
    # the right foot, in the left foot's frame, is the mirrored step in place: straight across, -p0[1] in y
    rel = np.asarray(ij.geometry.relative(feet[0], feet[1]))
    np.testing.assert_allclose(rel, [0.0, -float(robot.p0[1]), 0.0], atol=1e-6)
    wide = np.asarray(robots.start_stance(robot, 0.0, 0.0, theta, width=0.3))
    np.testing.assert_allclose(np.ptp(wide[:, :2], axis=0), 0.3 * np.abs([np.sin(theta), np.cos(theta)]), atol=1e-6)
    traced = jax.jit(lambda x, y, t: robots.start_stance(robot, x, y, t))(1.5, -0.4, theta)
    np.testing.assert_allclose(np.asarray(traced), feet, atol=1e-6)


# The stance-frame helpers against NumPy (float64) re-derivations.
POSE_TOL = 1e-5  # m and rad: float32 sin/cos of angles up to ~10 rad times poses of a few metres
stance_pose = st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(-7, 7))


def np_compose(base, rel):
    c, s = np.cos(base[2]), np.sin(base[2])
    return np.stack([base[0] + c * rel[..., 0] - s * rel[..., 1], base[1] + s * rel[..., 0] + c * rel[..., 1],
                     base[2] + rel[..., 2]], -1)


def np_wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("side, sign", [(1, 1.0), (0, 1.0), (2.5, 1.0), (-1, -1.0), (-0.1, -1.0)])
def test_side_sign_reads_any_flag(side, sign):
    s = robots.side_sign(side)
    assert s.dtype == np.float32 and float(s) == sign
    np.testing.assert_array_equal(np.asarray(robots.side_sign(np.array([1, -1, 0]))), [1.0, -1.0, 1.0])


@given(st.lists(st.floats(-5, 5, allow_subnormal=False), min_size=3, max_size=3),  # XLA flushes subnormals
       st.sampled_from([1.0, -1.0]))
def test_mirror_flips_y_and_theta_for_the_right_foot_and_is_its_own_inverse(rel, side):
    rel = np.array(rel, np.float32)
    got = np.asarray(robots.mirror(side, rel))
    np.testing.assert_array_equal(got, rel if side > 0 else rel * [1, -1, -1])
    np.testing.assert_array_equal(np.asarray(robots.mirror(side, got)), rel)


@given(stance_pose, st.sampled_from([1, -1]))
def test_action_steps_compose_the_mirrored_actions_onto_the_stance(stance, stance_side):
    r = ij.robots.hrp2(density=0.25)
    acts = np.asarray(r.actions, np.float64) * ([1, 1, 1] if stance_side < 0 else [1, -1, -1])  # swing side
    want = np_compose(np.array(stance), acts)
    got = np.asarray(ij.action_steps(r, stance, stance_side), np.float64)
    assert got.shape == (r.num_actions, 3)
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=POSE_TOL)
    np.testing.assert_allclose(np_wrap(got[:, 2] - want[:, 2]), 0.0, atol=POSE_TOL)


@given(st.lists(st.floats(-4, 4), min_size=6, max_size=6), st.floats(0, 3))
def test_dist_is_planar_distance_plus_weighted_wrapped_rotation(ab, rw):
    a, b = np.array(ab[:3]), np.array(ab[3:])
    want = np.hypot(*(a[:2] - b[:2])) + rw * abs(np_wrap(a[2] - b[2]))
    got = float(robots.dist(jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32), rw))
    assert got == pytest.approx(want, abs=POSE_TOL * (1 + rw))


def test_dist_broadcasts():
    a = jnp.zeros((4, 1, 3))
    b = jnp.ones((5, 3))
    assert robots.dist(a, b, 0.5).shape == (4, 5)


@given(stance_pose, st.sampled_from([1, -1]), st.integers(0, 2**31 - 1))
def test_nearest_actions_is_the_brute_force_argmin(stance, stance_side, seed):
    r = ij.robots.hrp2(density=0.25)
    rng = np.random.default_rng(seed)
    acts = np.asarray(r.actions, np.float64) * ([1, 1, 1] if stance_side < 0 else [1, -1, -1])
    # Every action exactly, and random steps near the action set.
    picks = rng.integers(0, r.num_actions, 8)
    rel = np.concatenate([acts, acts[picks] + rng.normal(0, [0.03, 0.03, 0.1], (8, 3))])
    steps = np_compose(np.array(stance), rel)
    got = np.asarray(robots.nearest_actions(r, stance, stance_side, steps))
    assert got.dtype == np.int32
    np.testing.assert_array_equal(got[: r.num_actions], np.arange(r.num_actions))
    rw = float(r.rotation_weight)
    d = np.hypot(rel[:, None, 0] - acts[None, :, 0], rel[:, None, 1] - acts[None, :, 1]) + rw * np.abs(
        np_wrap(rel[:, None, 2] - acts[None, :, 2]))
    best = d.min(1)
    # float32 ties: the chosen action is within the tolerance of the brute-force minimum.
    np.testing.assert_array_less(d[np.arange(len(rel)), got] - best, POSE_TOL * (1 + rw) * 4)


# What replace (or set_leaves) can set that a constructor refuses: checked where concrete, flagged when traced.
REPLACED = [
    (dict(margin=-0.1), "margin"),
    (dict(margin=0.15), "static window"),  # above hrp2()'s max_margin of 0.10: the windows do not cover it
    (dict(w=-1.0), "w"),
    (dict(foot_length=0.40), "overlap"),  # fits a window built for it, but the stance footprint overlaps
    (dict(foot_width=float("nan")), "foot_width"),
    (dict(step_time=0.0), "step_time"),
    (dict(max_sole_pitch=-0.1), "max_sole_pitch"),
    (dict(max_sole_roll=float("nan")), "max_sole_roll"),
    (dict(max_sole_distance=-1.0), "max_sole_distance"),
]


@pytest.mark.parametrize("changes, match", REPLACED)
def test_check_robot_refuses_what_replace_set(changes, match):
    robot = robots.hrp2()
    robots.check_robot(robot)  # the constructor's robot passes
    bad = robot.replace(**{k: jnp.float32(v) for k, v in changes.items()})
    if "foot_length" in changes:  # a window large enough, so that only the overlap is wrong
        bad = dataclasses.replace(bad, max_radius=1.0)
    with pytest.raises(ValueError, match=match):
        robots.check_robot(bad)


def test_check_robot_refuses_wrong_shapes_and_dtypes_and_skips_tracers():
    robot = robots.hrp2(density=0.1)
    with pytest.raises(ValueError, match=r"robot.w must have shape \(\)"):
        robots.check_robot(robot.replace(w=jnp.ones(2)))
    with pytest.raises(ValueError, match="robot.action_cost"):
        robots.check_robot(robot.replace(action_cost=-jnp.ones(robot.num_actions)))
    with pytest.raises(TypeError, match="robot.margin"):
        robots.check_robot(robot.replace(margin=np.array("x")))
    with pytest.raises(TypeError, match="Robot"):
        robots.check_robot("hrp2")
    jax.jit(lambda m: robots.check_robot(robot.replace(margin=m)) or m)(-1.0)  # traced: not checked, no error


@pytest.mark.parametrize("changes, match", REPLACED)
def test_robot_supported_flags_the_same_values_inside_jit(changes, match):
    robot = robots.hrp2()
    flag = jax.jit(lambda r: robots.robot_supported(r))
    assert bool(flag(robot))
    assert not bool(flag(robot.replace(**{k: jnp.float32(v) for k, v in changes.items()})))


# ---------------------------------------------------------------------------------------------
# A longer reach for stairs (issue 20)
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("reach, n_dx, size", [(0.20, 9, 496), (0.30, 13, 720), (0.25, 11, 608), (0.10, 5, 272)])
def test_reach_widens_the_dx_lattice_keeping_its_5cm_spacing(reach, n_dx, size):
    r = ij.robots.hrp2(reach=reach)
    a = np.asarray(r.actions, np.float64)
    assert a.shape == (size, 3) and size == n_dx * 8 * 7 - 8
    np.testing.assert_allclose(np.unique(np.round(a[:, 0], 6)), np.linspace(-reach, reach, n_dx), atol=1e-6)
    np.testing.assert_allclose(np.diff(np.unique(np.round(a[:, 0], 6))), 0.05, atol=1e-6)
    np.testing.assert_allclose([a[:, 1].min(), a[:, 1].max()], [0.19, 0.33], atol=1e-6)
    assert np.any(np.all(np.isclose(a, [0, 0.19, 0], atol=1e-7), axis=1)), "p0 must stay in S"
    assert not robots.footprints_overlap(a, 0.242, 0.13).any()
    # The static windows follow the action set: the swing window covers the longest swing, F spans S.
    assert r.max_swing == pytest.approx(2 * np.hypot(a[:, 0], a[:, 1]).max() + 0.13)
    lo, step, counts = r.target_grid
    assert lo[0] == pytest.approx(-reach - 0.05) and lo[0] + step[0] * (counts[0] - 1) == pytest.approx(reach + 0.05)
    # Beyond the paper's reach the step-height limit admits 15 cm stair risers; the rest is HRP-2's.
    want_dh = 0.10 if reach <= 0.20 else robots.STAIR_STEP_HEIGHT
    np.testing.assert_allclose(np.asarray(r.max_step_height), want_dh, atol=1e-7)
    np.testing.assert_allclose(np.asarray(r.clearance), 0.10, atol=1e-7)
    base = ij.robots.hrp2()
    for name in robots.SCALAR_LEAVES:
        assert float(robots.get_leaf(r, name)) == float(robots.get_leaf(base, name)), name


def test_reach_keeps_the_paper_default_and_overrides_win():
    a, b = ij.robots.hrp2(), ij.robots.hrp2(reach=0.20)
    np.testing.assert_array_equal(np.asarray(a.actions), np.asarray(b.actions))
    assert robots.hrp2_defaults() == robots.hrp2_defaults()  # fresh each call
    r = ij.robots.hrp2(reach=0.30, max_step_height=0.12)
    np.testing.assert_allclose(np.asarray(r.max_step_height), 0.12, atol=1e-7)
    assert ij.robots.hrp2(reach=0.30, density=0.5).num_actions == ij.robots.hrp2(density=0.5).num_actions + 2 * 5 * 5


@pytest.mark.parametrize("reach, match", [
    (0.0, "positive finite"), (-0.1, "positive finite"), (float("nan"), "positive finite"),
    (float("inf"), "positive finite"), ("0.3", "must be a number"), (True, "must be a number"),
    (None, "must be a number"), (0.45, "beyond max_sole_distance"),
])
def test_bad_reach_is_refused_naming_it(reach, match):
    with pytest.raises(ValueError, match=match):
        ij.robots.hrp2(reach=reach)
    # a larger leg reach admits the longer step
    assert ij.robots.hrp2(reach=0.45, max_sole_distance=0.6).num_actions == 19 * 8 * 7 - 8


def test_density_counts_at_the_papers_reach_are_unchanged():
    for density in (0.1, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 1.0, 1.5, 2.0, 3.0):
        n = 1 + 2 * max(1, round(4 * density))  # the formula before reach existed
        assert robots.density_counts(density)[0] == n == robots.density_counts(density, 0.20)[0], density
    assert robots.density_counts(1.0, 0.30) == (13, 8, 7)


# ---------------------------------------------------------------------------------------------
# HRP-2's ankle-tilt limits against the MJX biped's kinematics (issue 20)
# ---------------------------------------------------------------------------------------------

PELVIS_HEIGHT = 0.65  # m above the soles: the MJX controller's (sim.controller.WalkConfig.pelvis_height)


def _stances_realisable(actions, roll, pitch, tilted_row):
    """(N,) bool: with the right foot at the origin and the left at each action (dx, dy, dtheta), the pelvis level
    midway between them at PELVIS_HEIGHT and yawed halfway, the sole of one foot (row 0 left, 1 right) tilted by
    (roll, pitch) in its own frame: do both legs' analytic IK solutions reach and stay within the joint ranges?"""
    from ijoy_jax.sim import kinematics, model

    params = model.BipedParams()

    def leg_ok(side, pos, rot, pelvis, pelvis_rot):
        q, reachable = kinematics.leg_ik(params, side, pelvis, pelvis_rot, pos, rot)
        lo, hi = (jnp.asarray(v, jnp.float32) for v in params.joint_range(side))
        return reachable & jnp.all(q >= lo - 1e-5) & jnp.all(q <= hi + 1e-5)

    def one(a):
        tilt = kinematics.rpy_to_rot(jnp.stack([jnp.float32(roll), jnp.float32(pitch), jnp.float32(0.0)]))
        left_rot = kinematics.rot_z(a[2]) @ (tilt if tilted_row == 0 else jnp.eye(3))
        right_rot = tilt if tilted_row == 1 else jnp.eye(3)
        pelvis = jnp.stack([0.5 * a[0], 0.5 * a[1], jnp.float32(PELVIS_HEIGHT)])
        pelvis_rot = kinematics.rot_z(0.5 * a[2])
        return (leg_ok(1, jnp.stack([a[0], a[1], 0.0]), left_rot, pelvis, pelvis_rot)
                & leg_ok(-1, jnp.zeros(3), right_rot, pelvis, pelvis_rot))

    return np.asarray(jax.jit(jax.vmap(one))(jnp.asarray(actions, jnp.float32)))


@pytest.mark.slow
@pytest.mark.parametrize("reach", [0.20, 0.30])
def test_hrp2_ankle_limits_are_realisable_by_the_biped(reach):
    """make_robot's defaults (HRP-2's ankles) against the MJX biped's leg IK and joint ranges, in the controller's
    double-support posture: a sole pitched by +-max_sole_pitch is realisable in every stance of the action set
    (either foot tilted); one rolled by +-max_sole_roll in every stance at the step-in-place width (0.19 m, any
    step length and rotation). Wider stances lean the legs outward, which leaves the ankle roll less room: at the
    widest (0.33 m) the largest roll realisable in every stance is smaller (the docstring's 6 deg), the one thing
    a scalar roll limit does not capture."""
    robot = ij.robots.hrp2(reach=reach)
    acts = np.asarray(robot.actions)
    pitch, roll = float(robot.max_sole_pitch), float(robot.max_sole_roll)
    for row in (0, 1):
        for sign in (1.0, -1.0):
            assert _stances_realisable(acts, 0.0, sign * pitch, row).all(), (row, sign)
            nominal = np.isclose(acts[:, 1], float(robot.p0[1]))
            ok = _stances_realisable(acts, sign * roll, 0.0, row)
            assert ok[nominal].all(), (row, sign, acts[nominal & ~ok])
    # The allowance is small: 4 deg more roll (14 deg) is not realisable even standing straight, 0.19 m apart.
    straight = acts[np.all(np.isclose(acts, robot.p0), axis=1)]
    assert not (_stances_realisable(straight, -roll - math.radians(4.0), 0.0, 0).all()
                and _stances_realisable(straight, roll + math.radians(4.0), 0.0, 0).all())


def test_the_contact_inset_must_leave_each_point_on_its_own_side():
    """The sole's contact points lie ``contact_inset`` in from its edges, on both sides of its centre: an inset of
    half the width (or length) or more (set directly, or a narrower foot under the default) is refused naming it,
    flagged when traced."""
    robot = robots.hrp2()
    inside = robots.set_leaf(robot, "metrics.contact_inset", 0.06)  # hrp2's sole is 13 cm wide
    robots.check_robot(inside)
    assert bool(jax.jit(robots.robot_supported)(inside))
    for bad in (robots.set_leaf(robot, "metrics.contact_inset", 0.065),
                robot.replace(foot_width=jnp.float32(0.018))):  # half of it is the default 9 mm inset
        with pytest.raises(ValueError, match="contact_inset must be under half the foot's width and length"):
            robots.check_robot(bad)
        assert not bool(jax.jit(robots.robot_supported)(bad))
