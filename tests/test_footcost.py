"""FootCost against brute-force references, symmetries, limits, and jit behaviour."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jax.test_util import check_grads

import ijoy_jax as ij
from ijoy_jax import footcost
from ijoy_jax.footcost.xla import sole_tilt
from ijoy_jax.sim.kinematics import rpy_to_rot
from ijoy_jax.testing import foot_metrics, rect_touches_cells, sole_rpy

RES = 0.02
ROBOT = ij.robots.hrp2(margin=0.02)
L, W = 0.242, 0.13
# float32 poses carry ~1e-7 m of rounding: a cell overlapped by a sliver thinner
# than this may go either way; anything clearer must be decided exactly.
SLIVER = 1e-5


def _flat2d(shape=(40, 40)):
    return ij.terrain.flat(shape, RES)


SHAPE = (60, 60)  # every 2.5D map of the eager queries below: with PAD poses, one compiled program per query kind
PAD = 496  # the action set's size: a query of N <= PAD poses is padded to it (:func:`_terms`)


def _terms(t, robot, stance, side, steps, *, swing_from=None, action_index=0):
    """``ij.foot_cost_terms`` of ``steps`` (N, 3) with their ``action_index`` (one or N), as NumPy arrays.

    The query is padded to :data:`PAD` poses with copies of the first (their terms are dropped), so the queries of
    this module on :data:`SHAPE` maps share one compiled program per kind (with or without ``swing_from``) instead
    of one per number of poses. A pose's terms do not depend on the others in its batch."""
    steps = np.asarray(steps, np.float32).reshape(-1, 3)
    n = len(steps)
    index = np.broadcast_to(np.asarray(action_index, np.int32), (n,))
    pad = PAD - n
    terms = ij.foot_cost_terms(t, robot, stance, side, np.concatenate([steps, np.repeat(steps[:1], pad, 0)]),
                               swing_from=swing_from, action_index=np.concatenate([index, np.repeat(index[:1], pad)]))
    return type(terms)(*(np.asarray(x)[:n] for x in terms))


def test_single_cell_obstacle_exact_at_many_poses():
    """2D validity equals a brute-force geometric check of the grown footprint, cell by cell."""
    rng = np.random.default_rng(0)
    shape = (40, 40)
    n_terrains, n_poses = 40, 60
    cells = rng.integers(14, 26, size=(n_terrains, 2))
    frees = np.ones((n_terrains,) + shape, bool)
    frees[np.arange(n_terrains), cells[:, 0], cells[:, 1]] = False
    terrains = jax.vmap(lambda f: ij.terrain.Terrain(jnp.zeros(shape), f, jnp.zeros(2), RES, False))(
        jnp.asarray(frees))
    poses = np.column_stack([rng.uniform(0.25, 0.55, (n_terrains * n_poses, 2)),
                             rng.uniform(-np.pi, np.pi, n_terrains * n_poses)]).reshape(n_terrains, n_poses, 3)
    stance = jnp.array([0.4, 0.4, 0.0])  # every pose within the legs' reach (max_sole_distance) of it
    cost = jax.jit(jax.vmap(lambda t, s: ij.foot_cost(t, ROBOT, stance, -1, s, action_index=0)))(
        terrains, jnp.asarray(poses, jnp.float32))
    cost = np.asarray(cost)
    hl, hw = L / 2 + 0.02, W / 2 + 0.02
    ambiguous = 0
    for t in range(n_terrains):
        for p in range(n_poses):
            x, y, th = poses[t, p]
            inner = rect_touches_cells(x, y, th, hl - SLIVER, hw - SLIVER, RES, shape)[tuple(cells[t])]
            outer = rect_touches_cells(x, y, th, hl + SLIVER, hw + SLIVER, RES, shape)[tuple(cells[t])]
            if inner:
                assert np.isinf(cost[t, p]), (t, p)
            elif not outer:
                assert cost[t, p] == 0.0, (t, p)
            else:
                ambiguous += 1
    assert ambiguous <= 3
    assert 0.2 < np.mean(np.isinf(cost)) < 0.8  # the poses really probe the obstacle


def test_off_map_counts_as_obstacle():
    t = _flat2d((40, 40))
    stance = jnp.array([0.4, 0.4, 0.0])
    # Grown half-length 0.141: a foot centred 0.14 m from the edge is inside, 0.145 m is not... and beyond.
    steps = jnp.array([[0.142, 0.4, 0.0], [0.14, 0.4, 0.0], [-0.3, 0.4, 0.0], [0.4, 0.79, 0.0], [0.4, 0.1, 0.0]])
    c = np.asarray(ij.foot_cost(t, ROBOT, stance, -1, steps, action_index=0))
    np.testing.assert_array_equal(np.isinf(c), [False, True, True, True, False])


HUGE = [1e4, 1e7, 3.3e9, 1e30, 3.4e38]  # 3.3e9: past int32 cells at 2 cm; 3.4e38: float32's largest


@pytest.mark.slow
@pytest.mark.parametrize("has_height", [False, True])
def test_off_map_is_an_obstacle_at_every_magnitude(has_height):
    """A footprint beyond the map is an obstacle however far it is: float32 keeps no footprint width at 1e7 m
    (the rectangle collapses to a line touching no cell) and cells past 2**31 overflow int32."""
    t = ij.terrain.flat((40, 40), RES, has_height=has_height)
    stance = jnp.array([0.4, 0.4, 0.0])
    far = [[s * v, 0.4, 0.0] for v in HUGE for s in (1, -1)] + [[0.4, s * v, 0.3] for v in HUGE for s in (1, -1)]
    terms = ij.foot_cost_terms(t, ROBOT, stance, -1, np.array(far), swing_from=stance if has_height else None,
                               action_index=0)
    assert np.all(np.isinf(np.asarray(terms.obstacle)) | np.isinf(np.asarray(terms.unsupported)))
    assert np.all(np.isinf(np.asarray(terms.obstacle)))
    assert not np.any(np.isnan(np.asarray(terms.total)))
    # Inside a jit a non-finite pose is flagged unsupported (at the boundary it is refused).
    bad = jnp.array([[jnp.inf, 0.4, 0.0], [-jnp.inf, 0.4, 0.0], [0.4, jnp.inf, 0.0], [jnp.nan, 0.4, 0.0]])
    terms = jax.jit(lambda s: ij.foot_cost_terms(t, ROBOT, stance, -1, s, action_index=0))(bad)
    assert np.all(np.isinf(np.asarray(terms.unsupported))) and np.all(np.isinf(np.asarray(terms.total)))


@pytest.mark.slow
@pytest.mark.parametrize("x", [1e7, -1e7, 1e30])
def test_a_stance_far_off_the_map_has_no_valid_step_and_the_rollout_stops(x):
    t = ij.terrain.flat((40, 40), RES)
    c = ij.select_step(t, ROBOT, [x, 0.4, 0.0], -1, [0.2, 0.0, 0.0])
    assert not bool(c.valid) and int(c.index) == -1
    start = np.array([[x, 0.495, 0.0], [x, 0.305, 0.0]])
    traj = ij.rollout(t, ROBOT, start, [0.25, 0.0, 0.0], 3)
    assert not np.any(np.asarray(traj.taken)) and bool(np.all(traj.stopped))


@pytest.mark.slow
def test_a_world_frame_float32_cannot_resolve_is_refused_or_flagged():
    """A map at UTM scale (origin 5e5, 5.2e6 m): float32 rounds y there to 0.5 m, so FootCost would score the
    wrong cells. Refused at the boundary with the fix named; inside a jit (traced origin) flagged unsupported."""
    robot = ij.robots.hrp2(margin=0.02)
    for has_height in (False, True):
        utm = ij.terrain.flat((40, 40), RES, origin=(5e5, 5.2e6), has_height=has_height)
        stance = np.array([5e5 + 0.4, 5.2e6 + 0.4, 0.0])
        with pytest.raises(ValueError, match="shift your world frame"):
            ij.foot_cost_terms(utm, robot, stance, -1, stance[None], action_index=0)
    near = ij.terrain.flat((40, 40), RES, origin=(0.0, 0.0), has_height=True)

    @jax.jit
    def at(origin, stance):
        t = near.replace(origin=origin)
        return ij.foot_cost_terms(t, robot, stance, -1, stance[None] + jnp.array([0.0, 0.19, 0.0]), action_index=0)

    ok = at(jnp.array([0.0, 0.0]), jnp.array([0.4, 0.3, 0.0]))
    assert float(ok.total[0]) == 0.0
    bad = at(jnp.array([5e5, 5.2e6]), jnp.array([5e5 + 0.4, 5.2e6 + 0.3, 0.0]))
    assert np.isinf(bad.unsupported[0]) and np.isinf(bad.total[0])
    with pytest.raises(ValueError, match="the map is 10000 m across"):  # the far corner counts too; no shift helps
        ij.foot_cost_terms(ij.terrain.flat((10, 10), 1000.0), robot, [0.4, 0.4, 0.0], -1, [[0.4, 0.6, 0.0]])


def _rot90(terrain):
    nx, ny = terrain.shape
    ox, oy = np.asarray(terrain.origin)
    return ij.terrain.from_arrays(np.rot90(np.asarray(terrain.height)) if terrain.has_height else None,
                                  np.rot90(np.asarray(terrain.free)), terrain.resolution,
                                  (-(oy + ny * terrain.resolution), ox))


def _rot_pose(p):
    p = np.asarray(p, np.float64)
    return np.stack([-p[..., 1], p[..., 0], p[..., 2] + np.pi / 2], -1)


def _mirror(terrain):
    nx, ny = terrain.shape
    ox, oy = np.asarray(terrain.origin)
    return ij.terrain.from_arrays(np.asarray(terrain.height)[:, ::-1] if terrain.has_height else None,
                                  np.asarray(terrain.free)[:, ::-1], terrain.resolution,
                                  (ox, -(oy + ny * terrain.resolution)))


def _mirror_pose(p):
    p = np.asarray(p, np.float64)
    return np.stack([p[..., 0], -p[..., 1], -p[..., 2]], -1)


def _rough_terrain(seed, has_height=True, shape=SHAPE):
    rng = np.random.default_rng(seed)
    h = 0.002 * rng.standard_normal(shape)
    h[20:35, 25:40] += 0.04  # a low platform
    h += 0.05 * np.linspace(0, 1, shape[0])[:, None]  # a gentle ramp
    free = rng.random(shape) > 0.002
    return ij.terrain.from_arrays(h if has_height else None, free, RES, (0.3, -0.2))


@pytest.mark.slow
@pytest.mark.parametrize("has_height", [False, True])
def test_invariant_under_rotation_by_90_degrees(has_height):
    t = _rough_terrain(1, has_height)
    stance = np.array([0.8, 0.35, 0.3])
    steps = np.asarray(ij.action_steps(ROBOT, stance, -1))
    swing_from = np.array([0.6, 0.18, 0.25])
    kw = dict(swing_from=swing_from, action_index=np.arange(496))
    a = ij.foot_cost_terms(t, ROBOT, stance, -1, steps, **kw)
    kw["swing_from"] = _rot_pose(swing_from)
    b = ij.foot_cost_terms(_rot90(t), ROBOT, _rot_pose(stance), -1, _rot_pose(steps), **kw)
    _assert_same_costs(a, b)


@pytest.mark.parametrize("has_height", [False, True])
def test_left_right_mirror_symmetry(has_height):
    t = _rough_terrain(2, has_height)
    stance = np.array([0.8, 0.35, 0.3])  # a right stance foot; the left foot swings
    steps = np.asarray(ij.action_steps(ROBOT, stance, -1))
    swing_from = np.array([0.6, 0.18, 0.25])
    a = ij.foot_cost_terms(t, ROBOT, stance, -1, steps, swing_from=swing_from, action_index=np.arange(496))
    m_steps = _mirror_pose(steps)
    np.testing.assert_allclose(m_steps, ij.action_steps(ROBOT, _mirror_pose(stance), +1), atol=1e-5)
    b = ij.foot_cost_terms(_mirror(t), ROBOT, _mirror_pose(stance), +1, m_steps,
                           swing_from=_mirror_pose(swing_from), action_index=np.arange(496))
    _assert_same_costs(a, b)


def _assert_same_costs(a, b):
    ta, tb = np.asarray(a.total), np.asarray(b.total)
    # Transformed float32 poses differ by ~1e-7 m; a cell decision may flip only
    # for a sliver-thin overlap, which these fixed poses do not produce.
    np.testing.assert_array_equal(np.isinf(ta), np.isinf(tb))
    assert 0 < np.isinf(ta).sum() < len(ta)
    np.testing.assert_allclose(ta[np.isfinite(ta)], tb[np.isfinite(tb)], rtol=1e-4, atol=1e-5)


def test_height_metrics_match_numpy_reference():
    rng = np.random.default_rng(5)
    shape = SHAPE
    xs = np.arange(shape[0])[:, None] * RES
    h = 0.1 * xs * 0.3 + 0.003 * rng.standard_normal(shape) + np.zeros(shape)
    h[30:, 28:] += 0.015
    t = ij.terrain.from_arrays(h, None, RES)
    n = 150
    poses = np.column_stack([rng.uniform(0.35, 0.65, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    stance = np.array([0.5, 0.3, 0.0])
    terms = _terms(t, ROBOT, stance, -1, poses)
    ref_stance = foot_metrics(h, RES, (0, 0), stance, L, W, 0.02)["rest"]
    checked = supports = 0
    shortfalls = []
    tol = float(ROBOT.metrics.contact_tol)
    for i, p in enumerate(poses):
        hl, hw = L / 2, W / 2
        amb = False
        for a, b in ((hl, hw), (hl + 0.02, hw + 0.02)):
            amb |= np.any(rect_touches_cells(*p, a - SLIVER, b - SLIVER, RES, shape)
                          != rect_touches_cells(*p, a + SLIVER, b + SLIVER, RES, shape))
        if amb:
            continue
        ref = foot_metrics(h, RES, (0, 0), p, L, W, 0.02)
        rest = ref["rest"]
        # float32 least squares on heights <= 0.1 m over ~100 cells: ~1e-6 m errors.
        assert float(terms.slope_angle[i]) == pytest.approx(ref["slope"], abs=2e-4)
        assert float(terms.roughness_m[i]) == pytest.approx(ref["roughness"], abs=2e-5)
        assert float(terms.bump_m[i]) == pytest.approx(ref["bump"], abs=2e-5)
        assert float(terms.band_m[i]) == pytest.approx(ref["band"], abs=2e-5)
        # The rested sole on the ground under its six points (bilinear, an independent loop over the map; every
        # triple in float64) and its contact polygon (a support function), unless a point lies at the contact
        # tolerance to rounding.
        assert float(terms.foot_height_m[i]) == pytest.approx(rest["height"], abs=2e-5)
        if not np.any(np.abs(rest["gaps"] - tol) < 2e-5):
            assert float(terms.support_m[i]) == pytest.approx(rest["support"], abs=2e-5)
            supports += 1
            shortfalls.append(rest["support"])
        assert float(terms.step_height_m[i]) == pytest.approx(rest["height"] - ref_stance["height"], abs=3e-5)
        # The rested sole's orientation (an independent construction from its plane's normal) and the 3D distance
        # of the soles.
        roll, pitch, _ = sole_rpy(*rest["grad"], p[2])
        assert float(terms.sole_pitch_rad[i]) == pytest.approx(pitch, abs=2e-4)
        assert float(terms.sole_roll_rad[i]) == pytest.approx(roll, abs=2e-4)
        dz = rest["height"] - ref_stance["height"]
        reach = math.sqrt((p[0] - stance[0]) ** 2 + (p[1] - stance[1]) ** 2 + dz**2)
        assert float(terms.sole_distance_m[i]) == pytest.approx(reach, abs=3e-5)
        checked += 1
    assert checked > 0.9 * n
    assert supports > 0.85 * n
    shortfalls = np.asarray(shortfalls)
    assert (shortfalls < 1e-6).any() and (shortfalls > 0.01).any()  # soles on all six points and partial ones


def test_slope_of_a_ramp_and_its_limit():
    alpha = math.radians(12.0)
    xs = (np.arange(60) + 0.5) * RES
    h = np.tan(alpha) * xs[:, None] * np.ones((1, 60))
    t = ij.terrain.from_arrays(h, None, RES)
    pose = np.array([[0.6, 0.6, 0.4]])
    terms = _terms(t, ROBOT, pose[0], -1, pose)
    assert float(terms.slope_angle[0]) == pytest.approx(alpha, abs=1e-4)
    assert float(terms.roughness_m[0]) < 1e-5
    assert float(terms.slope[0]) == pytest.approx(float(ROBOT.metrics.slope_weight) * alpha, rel=1e-3)  # weight / rad
    steep = ROBOT.replace(metrics=ROBOT.metrics.replace(slope_limit=jnp.float32(math.radians(10))))
    assert np.isinf(_terms(t, steep, pose[0], -1, pose).slope[0])


def test_step_height_term_and_per_action_limit():
    h = np.zeros(SHAPE)
    h[30:, :] = 0.05
    t = ij.terrain.from_arrays(h, None, RES)
    stance = np.array([0.45, 0.6, 0.0])  # on the low side, within the legs' reach of the step onto the high one
    onto = np.array([[0.9, 0.6, 0.0]])
    terms = _terms(t, ROBOT, stance, -1, onto)
    assert float(terms.step_height_m[0]) == pytest.approx(0.05, abs=1e-6)
    assert float(terms.total[0]) == pytest.approx(0.05, abs=1e-5)  # step weight 1 / m, all else zero
    low = ROBOT.replace(max_step_height=jnp.full(496, 0.04, jnp.float32))
    assert np.isinf(_terms(t, low, stance, -1, onto).step[0])
    # Near the edge the safety band sees the 5 cm drop: invalid by the band, not by the obstacle flag.
    edge = np.array([[0.6 + 0.121 + 0.01, 0.6, 0.0]])
    e = _terms(t, ROBOT, stance, -1, edge)
    assert np.isinf(e.band[0]) and e.obstacle[0] == 0 and float(e.band_m[0]) == pytest.approx(0.05, abs=1e-6)


# float32 rotation entries of angles from float32 gradients: a few ulps of 1 (measured < 3e-7).
ROT_TOL = 2e-6
grads = st.floats(-3.0, 3.0, allow_subnormal=False)  # up to 72 deg each way


@given(gx=grads, gy=grads, yaw=st.floats(-7.0, 7.0, allow_subnormal=False))
def test_sole_tilt_puts_the_sole_on_the_plane_through_rpy_to_rot(gx, gy, yaw):
    """R = Rz(yaw) Ry(pitch) Rx(roll) of sole_tilt's angles (the MJX walker's rpy_to_rot): its z axis is the plane's
    upward normal, its x axis lies in the plane with the heading's horizontal direction; and the angles equal
    those read off a frame built from the normal and the heading (testing.sole_rpy, float64)."""
    pitch, roll = sole_tilt(jnp.float32(gx), jnp.float32(gy), jnp.float32(yaw))
    r = np.asarray(rpy_to_rot(jnp.stack([roll, pitch, jnp.float32(yaw)])), np.float64)
    normal = np.array([-gx, -gy, 1.0]) / math.sqrt(1.0 + gx * gx + gy * gy)
    np.testing.assert_allclose(r[:, 2], normal, atol=ROT_TOL)
    x = r[:, 0]
    assert x[2] == pytest.approx(gx * x[0] + gy * x[1], abs=ROT_TOL)  # in the plane
    heading = np.array([math.cos(yaw), math.sin(yaw)])
    assert x[:2] @ heading > 0 and abs(x[0] * heading[1] - x[1] * heading[0]) < ROT_TOL  # along the heading
    want_roll, want_pitch, _ = sole_rpy(gx, gy, yaw)
    assert float(pitch) == pytest.approx(want_pitch, abs=ROT_TOL)
    assert float(roll) == pytest.approx(want_roll, abs=ROT_TOL)


def _ramp(alpha, shape=SHAPE):
    """A plane rising at ``alpha`` rad along +x (heights at cell centres)."""
    xs = (np.arange(shape[0]) + 0.5) * RES
    return ij.terrain.from_arrays(np.tan(alpha) * xs[:, None] * np.ones((1, shape[1])), None, RES)


def _lenient(robot):
    """The robot with every terrain limit but the ankles' out of the way: the ankle term alone decides."""
    return robot.replace(metrics=robot.metrics.replace(slope_limit=jnp.float32(1.2)),
                         max_step_height=jnp.full(robot.num_actions, 1.0, jnp.float32))


@pytest.mark.parametrize("across", [False, True])
def test_a_sole_tilted_beyond_the_ankles_is_refused_by_the_ankle_term(across):
    """A ramp along the foot pitches the sole, across it rolls it: beyond max_sole_pitch (along) or max_sole_roll
    (across) by 2 deg the ankle term (alone) refuses the foothold; 2 deg within, it is accepted."""
    robot = _lenient(ROBOT)
    limit = float(robot.max_sole_roll if across else robot.max_sole_pitch)
    yaw = math.pi / 2 if across else 0.0  # the foot faces across the ramp (+y) or up it (+x)
    pose = np.array([[0.6, 0.6, yaw]])
    for alpha, refused in ((limit + math.radians(2.0), True), (limit - math.radians(2.0), False)):
        terms = _terms(_ramp(alpha), robot, [0.6, 0.41, 0.0], -1, pose)
        want_pitch, want_roll = (0.0, -alpha) if across else (-alpha, 0.0)  # up the ramp: toe up; across: right side up
        assert float(terms.sole_pitch_rad[0]) == pytest.approx(want_pitch, abs=1e-4)
        assert float(terms.sole_roll_rad[0]) == pytest.approx(want_roll, abs=1e-4)
        assert np.isinf(terms.ankle[0]) == refused and np.isinf(terms.total[0]) == refused
        others = sum(float(getattr(terms, k)[0]) for k in ("action", "obstacle", "slope", "roughness", "bump", "step",
                                                           "band", "swing_path", "reach", "unsupported"))
        assert np.isfinite(others)  # the ankle term is the one that names the reason


def test_the_default_ankle_limits_roll_tighter_than_they_pitch():
    """HRP-2's ankles (make_robot's defaults): a slope between the two limits is a foothold along it, not across."""
    robot = _lenient(ROBOT)
    pitch, roll = float(robot.max_sole_pitch), float(robot.max_sole_roll)
    assert roll < pitch <= float(ROBOT.metrics.slope_limit) + 1e-7  # pitch never refuses what the slope limit accepts
    t = _ramp(0.5 * (pitch + roll))
    terms = _terms(t, robot, [0.6, 0.41, 0.0], -1, [[0.6, 0.6, 0.0], [0.6, 0.6, math.pi / 2]])
    assert np.isfinite(terms.total[0]) and np.isinf(terms.ankle[1])


@pytest.mark.parametrize("has_height", [False, True])
def test_soles_farther_apart_than_the_legs_reach_are_refused_by_the_reach_term(has_height):
    """The reach term: the 3D distance of the sole centres against max_sole_distance (0.50 m for HRP-2). On a
    2.5D map the height change counts: 0.45 m ahead and 0.25 m up is 0.515 m away."""
    limit = float(ROBOT.max_sole_distance)
    h = np.zeros(SHAPE)
    if has_height:
        h[35:, :] = 0.25  # a platform from x = 0.7 m
    t = ij.terrain.from_arrays(h, None, RES) if has_height else ij.terrain.flat(h.shape, RES)
    robot = _lenient(ROBOT)
    stance = np.array([0.4, 0.6, 0.0])
    steps = np.array([[0.4 + limit - 0.01, 0.6, 0.0], [0.4 + limit + 0.01, 0.6, 0.0], [0.85, 0.6, 0.0]])
    terms = _terms(t, robot, stance, -1, steps)
    dz = np.asarray(terms.step_height_m)
    np.testing.assert_allclose(np.asarray(terms.sole_distance_m), np.hypot(steps[:, 0] - 0.4, dz), atol=1e-5)
    assert np.isinf(np.asarray(terms.reach)).tolist() == [has_height, True, has_height]
    np.testing.assert_array_equal(np.isinf(np.asarray(terms.total)), np.isinf(np.asarray(terms.reach)))
    if has_height:
        np.testing.assert_allclose(dz, 0.25, atol=1e-5)


@pytest.mark.parametrize("bar, valid", [(0.08, True), (0.12, False)])
def test_swing_path_clearance(bar, valid):
    h = np.zeros(SHAPE)
    h[29:31, :] = bar  # a 4 cm wide bar across the map at x = 0.58..0.62
    t = ij.terrain.from_arrays(h, None, RES)
    stance = np.array([0.6, 0.5, 0.0])
    start, end = np.array([0.42, 0.69, 0.0]), np.array([[0.78, 0.69, 0.0]])
    terms = _terms(t, ROBOT, stance, -1, end, swing_from=start)
    assert float(terms.path_height_m[0]) == pytest.approx(bar, abs=1e-6)
    assert np.isinf(terms.swing_path[0]) != valid
    # Without the start pose there is no path check.
    assert _terms(t, ROBOT, stance, -1, end).swing_path[0] == 0


def test_action_cost_is_added_and_nearest_action_is_used():
    robot = ij.robots.hrp2(action_cost=np.linspace(0, 1, 496))
    t = ij.terrain.flat((60, 60), RES)
    stance = jnp.array([0.6, 0.5, 0.2])
    steps = ij.action_steps(robot, stance, -1)
    c = ij.foot_cost(t, robot, stance, -1, steps[::37])  # no action_index: nearest action
    np.testing.assert_allclose(np.asarray(c), np.linspace(0, 1, 496)[::37], rtol=1e-6)


@pytest.mark.slow
@given(st.integers(0, 2**31 - 1), st.floats(0.0, 0.1))
def test_never_negative_and_inf_means_invalid(seed, margin):
    rng = np.random.default_rng(seed)
    h = 0.02 * rng.standard_normal((30, 30)).cumsum(0).cumsum(1) / 30
    t = ij.terrain.from_arrays(h, rng.random((30, 30)) > 0.05, RES)
    robot = ROBOT.replace(margin=jnp.float32(margin))
    poses = np.column_stack([rng.uniform(-0.1, 0.7, (32, 2)), rng.uniform(-4, 4, 32)])
    terms = ij.foot_cost_terms(t, robot, np.array([0.3, 0.3, 0.0]), 1, poses,
                               swing_from=np.array([0.3, 0.1, 0.0]))
    total = np.asarray(terms.total)
    assert not np.isnan(total).any() and (total >= 0).all()
    finite_terms = np.stack([np.asarray(getattr(terms, k)) for k in
                             ("action", "obstacle", "slope", "roughness", "bump", "step", "band",
                              "swing_path", "ankle", "reach", "unsupported")])
    np.testing.assert_array_equal(np.isinf(total), np.isinf(finite_terms).any(0))
    assert np.all(total[np.isfinite(total)] < 1e3)  # valid costs are small; invalid is inf, not "big"


def test_unsupported_margin_and_nan_pose_are_flagged_inside_jit():
    t = ij.terrain.flat((60, 60), RES, has_height=True)
    too_wide = ROBOT.replace(margin=jnp.float32(0.2))  # beyond the 10 cm the windows were built for
    steps = jnp.array([[0.6, 0.6, 0.0], [jnp.nan, 0.6, 0.0]])
    f = jax.jit(lambda r, s: ij.foot_cost_terms(t, r, jnp.array([0.6, 0.4, 0.0]), -1, s, action_index=[0, 0]))
    a = f(ROBOT, steps)
    assert float(a.total[0]) == 0.0 and np.isinf(a.unsupported[1]) and not np.isnan(np.asarray(a.total)).any()
    b = f(too_wide, steps)
    assert np.isinf(b.unsupported).all()


@pytest.mark.slow
@pytest.mark.parametrize("has_height", [False, True])
def test_windows_sized_exactly_for_the_margin_give_the_same_costs(has_height):
    """max_margin == margin: the footprint fills the static window exactly (float64 sizes, float32 poses).
    Without slack every step was flagged unsupported; the costs must equal those with roomy windows."""
    t = _rough_terrain(3, has_height)
    stance = np.array([0.8, 0.35, 0.3])
    tight = ij.robots.hrp2(margin=0.02, max_margin=0.02)
    steps = np.asarray(ij.action_steps(tight, stance, -1))
    far = steps[np.argmax(np.hypot(*(steps[:, :2] - stance[:2]).T))]  # the longest step, as the swing's start
    swing_from = 2 * stance - far
    kw = dict(swing_from=swing_from, action_index=np.arange(496))
    a = ij.foot_cost_terms(t, ROBOT, stance, -1, steps, **kw)
    b = ij.foot_cost_terms(t, tight, stance, -1, steps, **kw)
    assert not np.isinf(np.asarray(b.unsupported)).any()
    ta, tb = np.asarray(a.total), np.asarray(b.total)
    np.testing.assert_array_equal(np.isinf(ta), np.isinf(tb))
    # the plane fit sums a smaller window: float32 sums in another order (measured 6e-8)
    np.testing.assert_allclose(ta[np.isfinite(ta)], tb[np.isfinite(tb)], rtol=1e-5, atol=1e-6)


def test_bad_input_at_the_boundary():
    t = ij.terrain.flat((20, 20), RES)
    with pytest.raises(ValueError, match="stance_side"):
        ij.foot_cost(t, ROBOT, [0.2, 0.2, 0.0], 0, [[0.2, 0.4, 0.0]])
    with pytest.raises(ValueError, match="steps must have shape"):
        ij.foot_cost(t, ROBOT, [0.2, 0.2, 0.0], 1, [0.2, 0.4, 0.0])
    with pytest.raises(ValueError, match="stance must be finite"):
        ij.foot_cost(t, ROBOT, [0.2, np.nan, 0.0], 1, [[0.2, 0.4, 0.0]])
    with pytest.raises(TypeError, match="Terrain"):
        ij.foot_cost(np.zeros((3, 3)), ROBOT, [0.2, 0.2, 0.0], 1, [[0.2, 0.4, 0.0]])


def test_no_recompile_when_parameters_or_terrain_values_change():
    t = _rough_terrain(3)
    stance = np.array([0.8, 0.35, 0.0])
    steps = np.asarray(ij.action_steps(ROBOT, stance, -1))
    kw = dict(swing_from=np.array([0.6, 0.18, 0.0]), action_index=np.arange(496))
    ij.foot_cost(t, ROBOT, stance, -1, steps, **kw)
    n = footcost.xla.compiled_programs()
    variants = [
        ROBOT.replace(margin=jnp.float32(0.05)),
        ROBOT.replace(w=jnp.float32(3.0), rotation_weight=jnp.float32(5.0)),
        ROBOT.replace(foot_length=jnp.float32(0.2), step_time=jnp.float32(0.6)),
        ROBOT.replace(metrics=ROBOT.metrics.replace(bump_limit=jnp.float32(0.05))),
        ROBOT.replace(max_sole_pitch=jnp.float32(0.1), max_sole_roll=jnp.float32(0.05),
                      max_sole_distance=jnp.float32(0.3)),
    ]
    for r in variants:
        ij.foot_cost(t, r, stance, -1, steps, **kw)
    ij.foot_cost(t.replace(height=t.height * 2), ROBOT, stance + 0.01, 1, steps, **kw)
    assert footcost.xla.compiled_programs() == n


@pytest.mark.slow
def test_vmaps_over_terrains_and_robot_parameters():
    ts = [_rough_terrain(s) for s in range(3)]
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *ts)
    margins = jnp.array([0.02, 0.05, 0.10])
    robots = jax.vmap(lambda m: ROBOT.replace(margin=m))(margins)
    stance = jnp.array([0.8, 0.35, 0.0])
    steps = ij.action_steps(ROBOT, stance, -1)
    f = jax.vmap(lambda t, r: ij.foot_cost(t, r, stance, -1, steps, action_index=jnp.arange(496)))
    out = f(batch, robots)
    for i in range(3):
        ref = np.asarray(ij.foot_cost(ts[i], ROBOT.replace(margin=margins[i]), stance, -1, steps,
                                      action_index=np.arange(496)))
        got = np.asarray(out[i])
        # The same steps are valid; the costs agree to float32 rounding: XLA compiles the batched program on
        # its own and need not round alike (with its classic CPU emitters 3 of 496 costs differ in the last bit).
        np.testing.assert_array_equal(np.isinf(got), np.isinf(ref))
        np.testing.assert_allclose(got, ref, rtol=1e-6, atol=0)
    # A larger margin never makes an invalid step valid (monotone in the margin on this terrain).
    inf = np.isinf(np.asarray(f(jax.tree_util.tree_map(lambda x: jnp.stack([x[0]] * 3), batch), robots)))
    assert (inf[0] <= inf[1]).all() and (inf[1] <= inf[2]).all() and inf[2].sum() > inf[0].sum()


@pytest.mark.slow
def test_plane_metrics_are_differentiable_in_the_terrain_heights():
    """The plane fit (fused reductions) keeps JAX's derivatives, forward and reverse, w.r.t. the heights (its
    slope; the foot height is the rested sole's, piecewise linear in the heights)."""
    x, y = np.meshgrid(np.arange(50) * RES, np.arange(60) * RES, indexing="ij")
    t = ij.terrain.from_arrays(0.05 * x + 0.02 * np.sin(3 * y), None, RES, (0.3, -0.2))
    stance = jnp.array([0.8, 0.35, 0.0])
    steps = ij.action_steps(ROBOT, stance, -1)[::40]
    swing = jnp.array([0.75, 0.55, 0.0])

    def plane(height):  # linear and smooth in the heights (roughness, bump, band have kinks)
        terms = ij.foot_cost_terms(t.replace(height=height), ROBOT, stance, -1, steps, swing_from=swing,
                                   action_index=jnp.arange(len(steps)))
        return terms.slope_angle

    check_grads(jax.jit(plane), (t.height,), order=1, modes=("fwd", "rev"), eps=1e-3)


@pytest.mark.parametrize("name", ["_row_sums", "_totals", "_sum_and_maxima"])
def test_fused_reductions_have_the_plain_reductions_derivatives(name):
    """Each variadic reduction equals its plain-jnp reference, values and derivatives (jvp and vjp)."""
    rng = np.random.default_rng(3)
    shape = (13,) if name == "_totals" else (7, 9)
    count = {"_row_sums": 3, "_totals": 9, "_sum_and_maxima": 7}[name]  # plane_metrics' 1 sum and 6 maxima
    args = tuple(jnp.asarray(rng.standard_normal(shape), jnp.float32) for _ in range(count))
    fused = getattr(footcost.plane, name)
    plain = {"_row_sums": lambda a, b, c: (jnp.sum(a, 1), jnp.sum(b, 1)),
             "_totals": lambda *xs: tuple(jnp.sum(x) for x in xs),
             "_sum_and_maxima": lambda a, *bs: (jnp.sum(a), *(jnp.max(b) for b in bs))}[name]
    f = (lambda a, b, c: fused(a, b)) if name == "_row_sums" else fused
    tangents = tuple(jnp.asarray(rng.standard_normal(shape), jnp.float32) for _ in args)
    (v1, t1), (v2, t2) = jax.jvp(f, args, tangents), jax.jvp(plain, args, tangents)
    np.testing.assert_allclose(np.array(v1), np.array(v2), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(np.array(t1), np.array(t2), rtol=1e-5, atol=1e-5)
    g1 = jax.grad(lambda *a: sum(jnp.sum(o) for o in f(*a)), argnums=tuple(range(len(args))))(*args)
    g2 = jax.grad(lambda *a: sum(jnp.sum(o) for o in plain(*a)), argnums=tuple(range(len(args))))(*args)
    np.testing.assert_allclose(np.array(g1), np.array(g2), rtol=1e-5, atol=1e-5)


@pytest.mark.slow
@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**16), altitude=st.sampled_from([0.0, 50.0, -300.0]), block=st.sampled_from([4, 8, 32]))
def test_block_sums_against_float64_sums(seed, altitude, block):
    """footcost.block_sums: entry [ix, b, t] is the sum over rows b*block .. b*block + t - 1 (window b: 2 block
    rows, the map edge-padded beyond its last row) of (h - h_b) and of (h - h_b)(row - b*block - (block - 1/2)),
    h_b the window's first height. Against float64 sums of the same float32 heights: within float32 rounding
    of a window's relief (16 ulps of 2 block x relief), whatever the altitude; and any span of at most ``block``
    rows starting in rows b*block .. b*block + block - 1 lies in window b."""
    rng = np.random.default_rng(seed)
    nx, ny = 5, int(rng.integers(1, 3 * block))
    h = (altitude + 0.3 * rng.standard_normal((nx, ny))).astype(np.float32)
    sums, first = (np.asarray(a) for a in footcost.block_sums(jnp.asarray(h), block))
    blocks = -(-ny // block)
    assert sums.shape == (nx, blocks, 2 * block + 1, 2) and first.shape == (nx, blocks)
    padded = np.concatenate([h, np.repeat(h[:, -1:], (blocks + 1) * block - ny, 1)], 1).astype(np.float64)
    rows = np.stack([padded[:, b * block:(b + 2) * block] for b in range(blocks)], 1)
    np.testing.assert_array_equal(first, rows[:, :, 0])
    rel = rows - rows[:, :, :1]
    offset = np.arange(2 * block) - (block - 0.5)
    want = np.zeros((nx, blocks, 2 * block + 1, 2))
    want[:, :, 1:, 0] = np.cumsum(rel, 2)
    want[:, :, 1:, 1] = np.cumsum(rel * offset, 2)
    relief = np.abs(rel).max() + 1e-30
    np.testing.assert_allclose(sums[..., 0], want[..., 0], rtol=0, atol=16 * 6e-8 * 2 * block * relief)
    np.testing.assert_allclose(sums[..., 1], want[..., 1], rtol=0, atol=16 * 6e-8 * 4 * block * block * relief)
    # The kernel's read of a span: rows j .. j + n - 1 (n <= block) from window j // block.
    j = int(rng.integers(0, ny))
    n = int(rng.integers(0, block + 1))
    b, t = divmod(j, block)
    got = sums[:, b, t + n, 0] - sums[:, b, t, 0]  # the kernel adds n (h_b - h_ref) to it
    want_span = (padded[:, j:j + n] - first[:, b:b + 1].astype(np.float64)).sum(1)
    np.testing.assert_allclose(got, want_span, rtol=0, atol=32 * 6e-8 * 2 * block * relief)


def test_total_is_the_sum_of_the_cost_terms_and_the_named_terms_are_all_of_them():
    """COST_TERMS (the live record's names too) holds every term the total sums: on a rough map with steps both
    valid and refused by each kind of term, a finite total equals the sum of the others, and an infinite one has
    an infinite term among them."""
    rng = np.random.default_rng(9)
    h = 0.004 * rng.standard_normal(SHAPE) + np.arange(SHAPE[0])[:, None] * RES * 0.2
    h[30:, :] += 0.06
    t = ij.terrain.from_arrays(h.astype(np.float32), None, RES)
    stance = np.array([0.5, 0.5, 0.3])
    terms = ij.foot_cost_terms(t, ROBOT, stance, -1, ij.action_steps(ROBOT, stance, -1),
                               swing_from=np.array([0.45, 0.7, 0.3]), action_index=np.arange(PAD))
    names = footcost.COST_TERMS
    assert names[0] == "total" and names[-1] == "unsupported" and {"support", "ankle"} <= set(names)
    assert not any(n.endswith(("_m", "_rad", "_angle")) or n == "action_index" for n in names)
    parts = np.stack([np.asarray(getattr(terms, n), np.float64) for n in names[1:]])
    total = np.asarray(terms.total, np.float64)
    finite = np.isfinite(total)
    assert 20 < finite.sum() < len(total) - 20
    np.testing.assert_allclose(parts[:, finite].sum(0), total[finite], rtol=1e-5, atol=1e-6)
    assert np.isinf(parts[:, ~finite]).any(0).all()
    assert np.isinf(np.asarray(terms.support)).any()  # the contact polygon refuses some of these steps
