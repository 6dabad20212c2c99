"""Tests of the walking controller (ijoy_jax.sim.controller).

Unit checks of the plan and the foot targets, and short walks with the JAX
controller in the loop and native MuJoCo for the physics (about 100x faster
than MJX on CPU; the MJX rollout runs the same controller functions).
"""

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import geometry, robots, select
from ijoy_jax import terrain as T
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.sim import controller, dynamics, kinematics, model, native
from ijoy_jax.sim import walker as W

ATOL = 1e-6  # float32 arithmetic on metre-sized numbers
PLACEMENT_TOL = 0.02  # m: touch-down error of a step in place (measured ~0.6 cm)
WALK_TOL = 0.03  # m: touch-down error of action-set steps (measured up to ~1.1 cm)

# soles: x, y, z, roll, pitch, yaw (m, rad)
STANCE = jnp.array([0.0, -0.095, 0.0, 0.0, 0.0, 0.0], jnp.float32)
SWING = jnp.array([0.0, 0.095, 0.0, 0.0, 0.0, 0.0], jnp.float32)
POSE = jnp.array([0.2, 0.095, 0.0, 0.0, 0.0, 0.1], jnp.float32)


def _plan(go=True, cfg=None):
    cfg = controller.WalkConfig() if cfg is None else cfg
    return controller.plan_step(jnp.zeros(2), STANCE, SWING, POSE, go, 1.0, 0.0, cfg.clearance)


def test_plan_step_walking():
    plan = _plan(True)
    np.testing.assert_allclose(plan.zmp, [[0, 0], [0, -0.095], [0.2, 0.095], [0.2, -0.095]], atol=ATOL)
    np.testing.assert_allclose(plan.swing_to, POSE, atol=ATOL)
    assert float(plan.apex) == pytest.approx(controller.WalkConfig().clearance)


def test_plan_step_standing_keeps_the_swing_foot():
    plan = _plan(False)
    np.testing.assert_allclose(plan.swing_to, SWING, atol=ATOL)
    np.testing.assert_allclose(plan.zmp[1:], np.zeros((3, 2)), atol=ATOL)  # the feet's midpoint
    assert float(plan.apex) == pytest.approx(0.0)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_foot_targets_ends(side):
    cfg = controller.WalkConfig()
    plan = controller.plan_step(jnp.zeros(2), STANCE, SWING, POSE, True, side, 0.0, cfg.clearance)
    row_sw, row_st = (0, 1) if side > 0 else (1, 0)
    for t, want in ((0.0, SWING), (cfg.ds_time, SWING), (cfg.step_time, POSE)):
        f = controller.foot_targets(cfg, plan, t)
        np.testing.assert_allclose(f[row_sw], want, atol=ATOL)
        np.testing.assert_allclose(f[row_st], STANCE, atol=ATOL)
    mid = controller.foot_targets(cfg, plan, 0.5 * (cfg.ds_time + cfg.step_time))
    assert float(mid[row_sw, 2]) == pytest.approx(cfg.clearance, abs=ATOL)  # at the apex half way


# ----------------------------------------------------------------------------------------------------------------
# Closed loop: JAX controller + native MuJoCo physics


@pytest.fixture(scope="module")
def sim():
    return W.make_sim((200, 200), 0.02, robot=robots.hrp2())  # 4 m x 4 m, centred on the start


class _Native:
    """:class:`ijoy_jax.sim.native.NativeBiped` (the library's native-MuJoCo robot) driven by actions of the
    action set, relative to the measured stance foot, instead of the selector's footholds.

    ``heights`` (the Sim's grid, m; flat by default, the grid centred on the start) is the ground. The
    robot stands its warm-up step at construction. ``min_knee`` keeps the least knee target sent (rad,
    either leg), ``tilt_error`` the last step's (rad).
    """

    def __init__(self, sim, heights=None):
        nx, ny = sim.shape
        origin = (-0.5 * nx * sim.resolution, -0.5 * ny * sim.resolution)
        heights = np.zeros(sim.shape) if heights is None else heights
        self.terr = T.from_arrays(heights, None, sim.resolution, origin=origin).replace(has_height=True)
        self.robot = robots.hrp2()
        start = np.array([[0.0, 0.095, 0.0], [0.0, -0.095, 0.0]], np.float32)
        self.biped = native.NativeBiped(sim, self.terr, self.robot, start, first_swing=1.0)
        self.sim, self.m, self.d = sim, self.biped.m, self.biped.d
        self.tick = self.biped.programs.tick
        self.min_knee = np.inf
        self._run(np.zeros(6, np.float32), False)  # the warm-up: stand one step

    @property
    def swing(self):
        return self.biped.swing

    def soles(self):
        return self.biped.soles()

    def _run(self, foothold, go):
        self.biped.begin(foothold, go)
        while self.biped.tick():
            self.min_knee = min(self.min_knee, float(self.d.ctrl[[3, 9]].min()))
        self.min_knee = min(self.min_knee, float(self.d.ctrl[[3, 9]].min()))
        return self.biped.end()

    def step(self, action):
        """Take one action (dx, dy, dtheta of the left swing foot, mirrored for the right): placement error, fell."""
        info = self.biped.stance()
        side = self.biped.swing
        rel = jnp.asarray([action[0], action[1] * side, action[2] * side], jnp.float32)
        pose = geometry.compose(jnp.asarray(info.stance), rel)
        log = self._run(np.asarray(select.foothold(self.terr, self.robot, pose)), True)
        self.tilt_error = float(log.tilt_error)
        return float(log.placement_error), bool(log.fallen)


@pytest.mark.slow
def test_control_tick_does_not_recompile(sim):
    walk = _Native(sim)
    walk.step((0.0, 0.19, 0.0))  # the state's weak types settle after the standing step's first tick
    before = compiled_count(walk.tick)
    walk.step((0.0, 0.19, 0.0))
    assert compiled_count(walk.tick) == before


def test_steps_in_place(sim):
    walk = _Native(sim)
    errs = []
    for _ in range(4):
        err, fell = walk.step(robots.hrp2().p0)
        assert not fell
        errs.append(err)
    assert max(errs) < PLACEMENT_TOL, errs


@pytest.mark.slow
def test_walks_random_action_set_steps(sim):
    """Ten random steps of the HRP-2 action set (forward, back, sideways, turning) without falling."""
    walk = _Native(sim)
    actions = np.asarray(robots.hrp2().actions)[np.random.default_rng(1).integers(0, 496, 10)]
    errs = []
    for a in actions:
        err, fell = walk.step(a)
        assert not fell, (len(errs), a)
        errs.append(err)
    assert max(errs) < WALK_TOL, errs


@pytest.mark.slow
def test_walks_fast_backward_sidesteps_while_turning(sim):
    """The corner of the command space where the MJX robots fell (BENCHMARKS.md): full speed backward, a wide
    sidestep to the right and a turn to the left, held. At the old pelvis height (0.68 m) the legs straightened
    out of reach (knee target 0) before the swing foot was down, the weight moved onto it in the air, it slipped,
    and this walk fell at the sixth step; with the knees kept bent the feet reach the ground."""
    walk = _Native(sim)
    errs = []
    for k in range(8):  # left: back 0.2, in its lane, +20 deg; right: back 0.2, 0.31 to the right, +20 deg
        err, fell = walk.step((-0.2, 0.19, 0.349) if walk.swing > 0 else (-0.2, 0.31, -0.349))
        assert not fell, k
        errs.append(err)
    assert max(errs) < WALK_TOL, errs
    assert walk.min_knee > 0.3, walk.min_knee  # measured 0.55 (0.0 at the old height)


@pytest.mark.slow
def test_walks_with_one_foot_on_a_raised_lane(sim):
    """Forward 0.2 m steps with the left foot climbing onto an 8 cm lane (the paper's low platform,
    in one lane as in tests/test_experiments.py) while the right foot stays on the ground. The pelvis
    holds its height above the lower foot: above the feet's mean, the lower leg straightened (knee
    0.11 rad at 4.6 cm, 0 beyond) and the robot fell (measured in MJX)."""
    nx, ny = sim.shape
    x = (np.arange(nx) + 0.5) * sim.resolution - 0.5 * nx * sim.resolution
    y = (np.arange(ny) + 0.5) * sim.resolution - 0.5 * ny * sim.resolution
    lane = 0.08 * ((x[:, None] > 0.35) & (y[None, :] > 0.0))  # the left foot's side (y = +0.095) from x = 0.35
    walk = _Native(sim, heights=lane)
    errs, left_z = [], []
    for k in range(6):  # left to 0.2 (ground), right to 0.4, left to 0.6 (on the lane), ...
        err, fell = walk.step((0.2, 0.19, 0.0))
        assert not fell, k
        errs.append(err)
        if k % 2 == 0:
            left_z.append(float(walk.soles()[0, 2]))
    assert max(errs) < WALK_TOL, errs
    np.testing.assert_allclose(left_z, [0.0, 0.08, 0.08], atol=0.01)  # up on the lane from the second left step
    assert abs(float(walk.soles()[1, 2])) < 0.01  # the right foot still on the ground



@pytest.mark.slow
@pytest.mark.parametrize("direction", [1, -1])
def test_climbs_and_descends_stairs_two_risers_per_swing(sim, direction):
    """Five 12 cm risers, 30 cm treads, one tread per 0.3 m step: each swing foot rises (or drops) two risers
    past the stance foot's tread. The swing path gains height in stages as the terrain along it asks, and the
    pelvis moves smoothly between the soles' heights: with the one-apex swing and the pelvis height following
    the swing sole linearly (kinked where the soles' heights cross) this descent fell at its third step (in MJX,
    1024 stairs each: 19 % of the robots fell going up and 54 % going down then, 10.6 and 2.4 % with these
    changes, 0 and 4.1 % with the dynamics filter held to two steps too, docs/walk_families.md). The soles
    land 1 cm behind the treads' centres, their toes 3.9 cm from the next riser's cell: with 2.9 cm (centred)
    the climb falls at its last step under the suite's XLA flags, its toe on the riser after a landing 2 cm
    long (MuJoCo's height field ramps over the cell next to a riser: the toe's real room is a centimetre less
    than the cells say)."""
    nx, ny = sim.shape
    x = (np.arange(nx) + 0.5) * sim.resolution - 0.5 * nx * sim.resolution
    risers = 0.16 + 0.3 * np.arange(5)  # treads of 0.3 m from x = 0.16, 0.46, ..., 1.36 (the top)
    climbed = (x[:, None] >= risers[None, :]).sum(axis=1)
    heights = 0.12 * (climbed if direction > 0 else 5 - climbed)
    walk = _Native(sim, heights=np.broadcast_to(heights[:, None], (nx, ny)).astype(np.float32))
    errs, tilts = [], []
    for k, dx in enumerate((0.30, 0.30, 0.30, 0.30, 0.30, 0.30)):  # left, right, ...: the last two on the top
        err, fell = walk.step((dx, 0.19, 0.0))
        assert not fell, k
        errs.append(err)
        tilts.append(walk.tilt_error)
    assert max(errs) < WALK_TOL, errs
    assert max(tilts) < np.radians(2.0), tilts
    np.testing.assert_allclose(walk.soles()[:, 2], 0.6 if direction > 0 else 0.0, atol=0.01)
    assert walk.soles()[:, 0].min() - 0.5 * sim.params.foot_length > risers[-1]  # both wholly past the last riser

@pytest.mark.slow
@pytest.mark.parametrize("drop", [0.0, 0.15, 0.3])
def test_descent_drop_lowers_the_pelvis_on_steps_down_only(sim, drop):
    """``WalkConfig.descent_drop``: stepping down 14 cm onto the next tread and again, the pelvis stands
    ``pelvis_height`` above the lower sole less ``drop`` times the drop, at both ends of each step, so the
    height is the same where one step ends and the next begins; stepping up it is the lower sole's, as
    without it (0 compiles the old pattern exactly). Standing straddled between the two treads (the swing
    side stays, so every standing step has the same roles) the pelvis holds the height the last step ended
    at, through one standing step and the next."""
    cfg = dataclasses.replace(sim.cfg, descent_drop=drop)
    params, pg, h = sim.params, controller.gains(sim.cfg), 0.14
    dt, T = cfg.control_dt, cfg.step_time

    def sole(x, y, z):
        return jnp.array([x, y, z, 0.0, 0.0, 0.0], jnp.float32)

    def plan(stance, swing_from, target, side, go=True):
        return controller.plan_step(stance[:2], stance, swing_from, target, go, side, jnp.maximum(
            swing_from[2], target[2]), cfg.clearance)

    def height(p, t):
        cs = controller.init_state(pg, p.stance[:2])._replace(t=jnp.float32(t - dt))  # pattern() adds a period
        return float(controller.pattern(params, cfg, pg, p, cs)[0][2])

    def pelvis_z(stance, swing_from, target, side, t, go=True):
        return height(plan(stance, swing_from, target, side, go), t)

    a, b, c = sole(0.0, 0.095, h), sole(0.3, -0.095, 0.0), sole(0.6, 0.095, -h)  # down, tread after tread
    d = sole(0.9, -0.095, -2 * h)
    start, end = pelvis_z(b, a, c, 1.0, dt), pelvis_z(b, a, c, 1.0, T)
    np.testing.assert_allclose(start, cfg.pelvis_height + 0.0 - drop * h, atol=1e-4)
    np.testing.assert_allclose(end, cfg.pelvis_height - h - drop * h, atol=1e-4)
    np.testing.assert_allclose(pelvis_z(c, b, d, -1.0, dt), end, atol=1e-4)  # the next step starts there
    for t in (dt, 0.5 * T, T):  # or it stands on c with b behind, step after step, at that height
        np.testing.assert_allclose(pelvis_z(c, b, d, -1.0, t, go=False), end, atol=1e-4)
    walked = controller.next_plan(cfg, plan(b, a, c, 1.0))  # after a step taken the other foot swings
    np.testing.assert_array_equal(np.stack([walked.stance, walked.swing_from]), np.stack([c, b]))
    assert float(walked.swing_side) == -1.0 and bool(walked.go)
    np.testing.assert_allclose(height(walked, dt), end, atol=1e-4)
    # the dynamics filter's assumed next step (next_plan) stands too, in the same roles, at the same height
    after = controller.next_plan(cfg, plan(c, b, d, -1.0, go=False))
    np.testing.assert_array_equal(np.stack([after.stance, after.swing_from]), np.stack([c, b]))
    assert float(after.swing_side) == -1.0 and not bool(after.go)
    np.testing.assert_allclose([height(after, dt), height(after, T)], [end, end], atol=1e-4)
    up = pelvis_z(b, c, a, 1.0, T)  # the same treads climbed: stance b, landing on a, 14 cm up
    np.testing.assert_allclose(up, cfg.pelvis_height + 0.0, atol=1e-4)


WALK_FIELDS = [f.name for f in dataclasses.fields(controller.WalkConfig)]


@pytest.mark.parametrize("name", WALK_FIELDS)
def test_walk_config_checks_every_field(name):
    """A NaN in any field is refused with the field's name, directly and through ``dataclasses.replace``."""
    with pytest.raises(ValueError, match=rf"WalkConfig\.{name} "):
        controller.WalkConfig(**{name: float("nan")})
    with pytest.raises(ValueError, match=rf"WalkConfig\.{name} "):
        dataclasses.replace(controller.WalkConfig(), **{name: float("inf")})


@pytest.mark.parametrize("name, bad", [
    ("step_time", 0.0), ("step_time", -0.8), ("control_dt", 0.0), ("ds_fraction", 1.0), ("ds_fraction", -0.1),
    ("preview_time", 0.0), ("preview_time", 0.005), ("com_height", 0.0), ("pelvis_height", -0.65),
    ("clearance", -0.01), ("swing_lift", 0.0), ("swing_lift", 0.6), ("leg_share", 1.0), ("leg_share", -0.1),
    ("preview_q", -1.0), ("preview_r", 0.0), ("land_gain", -0.5), ("land_ramp", 0.0), ("land_ramp", 1.5),
    ("land_decay", 0.0), ("ankle_delay", 0.0), ("ankle_delay", -0.01), ("stance_gain", -0.1),
    ("ankle_damping", -150.0), ("ankle_leak", 0.0), ("cop_edge", -0.01),
    ("contact_force", 0.0), ("dcm_gain", -3.0), ("descent_drop", -0.1), ("descent_drop", 1.5),
    ("descent_drop", "0.3"), ("descent_drop", True), ("filter_passes", -1), ("filter_passes", 1.5),
    ("filter_passes", True), ("com_offset", None), ("step_time", jnp.float32(0.8)), ("capture_gain", -1.0),
    ("capture_gain", 4.5), ("capture_max", 0.0), ("capture_max", -0.05), ("swing_adjust", -0.5),
    ("swing_adjust", 4.5),
])
def test_walk_config_refuses_values_outside_their_range(name, bad):
    with pytest.raises(ValueError, match=rf"WalkConfig\.{name} "):
        controller.WalkConfig(**{name: bad})


def test_walk_config_accepts_the_ends_its_fields_document():
    """The "0 = off" settings, the closed ends of the fractions, NumPy scalars, a preview of one period."""
    cfg = controller.WalkConfig(ds_fraction=0.0, swing_lift=0.5, land_ramp=1.0, descent_drop=np.float64(1.0),
                                ankle_damping=0, dcm_gain=0.0, stance_gain=0.0, land_gain=0.0, clearance=0.0,
                                cop_edge=0.0, leg_share=0.0, preview_q=0.0, filter_passes=np.int64(0),
                                com_offset=-0.02, preview_time=0.01, capture_gain=4.0)
    assert cfg.horizon == 1 and cfg.descent_drop == 1.0 and cfg.filter_passes == 0 and cfg.capture_gain == 4.0


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(WALK_FIELDS), st.one_of(st.none(), st.text(max_size=3), st.complex_numbers(),
                                               st.lists(st.floats(), max_size=2), st.booleans()))
def test_walk_config_refuses_hostile_values_by_name(name, bad):
    with pytest.raises(ValueError, match=rf"WalkConfig\.{name} "):
        controller.WalkConfig(**{name: bad})


def test_pelvis_stays_above_the_lower_foot(sim):
    """One foot 8 cm up: both knees stay bent (the flat stance's knee is 0.57 rad)."""
    cfg, params = sim.cfg, sim.params
    pg = controller.gains(cfg)
    stance = jnp.array([0.0, 0.095, 0.08, 0.0, 0.0, 0.0], jnp.float32)  # left foot up
    swing_from = jnp.array([0.0, -0.095, 0.0, 0.0, 0.0, 0.0], jnp.float32)  # beside it, on the ground
    target = jnp.array([0.2, -0.095, 0.0, 0.0, 0.0, 0.0], jnp.float32)
    plan = controller.plan_step(jnp.zeros(2), stance, swing_from, target, True, -1.0, 0.08, cfg.clearance)
    cs = controller.init_state(pg, jnp.array([0.0, 0.0], jnp.float32))
    q, _, _ = controller.control_tick(params, cfg, pg, plan, cs)
    knees = np.asarray(q)[[3, 9]]  # rows: left, right; columns: model.JOINTS
    assert knees.min() > 0.4, knees
    assert knees[0] > knees[1]  # the leg on the lane bends more


def _pelvis(qpos):
    """(position, rotation) of the pelvis in a planned qpos (19,): the ``base`` control_tick takes."""
    return qpos[:3], kinematics.quat_to_rot(qpos[3:7])


def _swing_plan(cfg, side=1.0):
    stance, swing_from = (STANCE, SWING) if side > 0 else (SWING, STANCE)
    target = swing_from + jnp.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.1], jnp.float32)
    return controller.plan_step(jnp.zeros(2), stance, swing_from, target, True, side, 0.0, cfg.clearance)


def test_stabiliser_is_silent_while_the_body_follows_the_plan(sim):
    cfg, params = sim.cfg, sim.params
    pg = controller.gains(cfg)
    plan = _swing_plan(cfg)
    cs = controller.init_state(pg, jnp.zeros(2))._replace(t=jnp.float32(0.6))  # mid-swing: full feedback weight
    qpos, _, _ = controller.pattern(params, cfg, pg, plan, cs)
    q, cs1, _ = controller.control_tick(params, cfg, pg, plan, cs, None, _pelvis(qpos))
    np.testing.assert_allclose(q, qpos[7:], atol=1e-5)  # float32 IK of the same pose twice
    np.testing.assert_allclose(cs1.offset, 0.0, atol=1e-5)


def test_swing_foot_lands_level_under_a_tilted_body(sim):
    """The body rolled 6 degrees outward over the stance sole's outer edge and pitched 3 degrees forward: with
    the full gain the swing leg's targets put the sole at its touch-down pose, level, from the measured pelvis;
    half the gain moves the joints half way; the stance leg keeps the pattern's targets."""
    params = sim.params
    cfg = dataclasses.replace(sim.cfg, land_gain=1.0)
    pg = controller.gains(cfg)
    plan = _swing_plan(cfg)
    cs = controller.init_state(pg, jnp.zeros(2))._replace(t=jnp.float32(cfg.step_time - cfg.control_dt))
    qpos, _, _ = controller.pattern(params, cfg, pg, plan, cs)  # the touch-down tick
    pos, rot = _pelvis(qpos)
    tilt = kinematics.rpy_to_rot(jnp.array([np.radians(-6), np.radians(3), 0.0], jnp.float32))
    pivot = plan.stance[:3] + jnp.array([0.0, -0.065, 0.0], jnp.float32)  # the stance sole's outer edge
    base = (pivot + tilt @ (pos - pivot), tilt @ rot)
    q, cs1, _ = controller.control_tick(params, cfg, pg, plan, cs, None, base)
    sole_pos, sole_rot = kinematics.leg_fk(params, "left", q[:6])
    np.testing.assert_allclose(base[0] + base[1] @ sole_pos, plan.swing_to[:3], atol=1e-4)
    np.testing.assert_allclose(base[1] @ sole_rot, kinematics.rpy_to_rot(plan.swing_to[3:]), atol=1e-4)
    np.testing.assert_allclose(q[6:], qpos[13:], atol=1e-6)  # the stance leg: the pattern's
    assert np.abs(np.asarray(q[:6] - qpos[7:13])).max() > 0.05  # the compensation is not small
    half = dataclasses.replace(cfg, land_gain=0.5)
    q_half, _, _ = controller.control_tick(params, half, pg, plan, cs, None, base)
    np.testing.assert_allclose(q_half - qpos[7:], 0.5 * (q - qpos[7:]), atol=1e-5)
    # A known control delay lowers the gain: 1 / (1 + L / land_delay), half at L = land_delay, a third at twice.
    for latency, scale in ((cfg.land_delay, 0.5), (2 * cfg.land_delay, 1 / 3)):
        q_late, _, _ = controller.control_tick(params, cfg, pg, plan, cs, None, base, None, None,
                                               jnp.float32(latency))
        np.testing.assert_allclose(q_late - qpos[7:], scale * (q - qpos[7:]), atol=1e-5)
    # Next step: the leg that landed carries the body and its offset fades; the new swing leg starts with none.
    nxt = _swing_plan(cfg, side=-1.0)
    cs2 = cs1._replace(t=jnp.float32(0))
    q2, cs3, _ = controller.control_tick(params, cfg, pg, nxt, cs2, None, base)
    decay = np.exp(-cfg.control_dt / cfg.land_decay)
    np.testing.assert_allclose(cs3.offset[:6], decay * cs1.offset[:6], atol=1e-6)
    np.testing.assert_allclose(cs3.offset[6:], 0.0, atol=1e-6)  # in double support: no feedback yet


def test_stance_gain_holds_the_carrying_sole_partly_level(sim):
    """With ``stance_gain`` g the legs that carry the body low-pass toward g times the compensation the swing
    leg gets at full weight; the swing leg starts its swing from the same g (no jump at lift-off)."""
    params = sim.params
    cfg = dataclasses.replace(sim.cfg, land_gain=1.0, stance_gain=0.3)
    pg = controller.gains(cfg)
    plan = _swing_plan(cfg)
    cs = controller.init_state(pg, jnp.zeros(2))._replace(t=jnp.float32(0.0))  # double support: s = 0
    qpos, _, _ = controller.pattern(params, cfg, pg, plan, cs)
    pos, rot = _pelvis(qpos)
    tilt = kinematics.rpy_to_rot(jnp.array([np.radians(-4), np.radians(2), 0.0], jnp.float32))
    base = (pos, tilt @ rot)
    feet = controller.foot_targets(cfg, plan, cs.t + cfg.control_dt)
    delta = controller.legs_ik(params, *base, feet) - qpos[7:]  # the full compensation
    _, cs1, _ = controller.control_tick(params, cfg, pg, plan, cs, None, base)
    decay = np.exp(-cfg.control_dt / cfg.land_decay)
    np.testing.assert_allclose(cs1.offset[:6], 0.3 * delta[:6], atol=1e-5)  # the swing leg (left) at s = 0
    np.testing.assert_allclose(cs1.offset[6:], (1 - decay) * 0.3 * delta[6:], atol=1e-5)  # the stance leg
    assert np.abs(np.asarray(delta[6:])).max() > 0.02


@pytest.mark.slow
def test_stabiliser_rights_the_body_after_a_sideways_push(sim):
    """A 30 N sideways push on the pelvis for one whole step (24 N s). With the stabiliser alone (stiff ankles)
    the body rolls 3 degrees at the next touch-down and is upright (0.2) two steps later; without it the robot
    keeps rolling, further at every touch-down (each swing foot lands on its edge, tilted with the body), and
    falls. Measured since the walk starts with its CoM above the soles and an unfiltered warm-up (75d2fb9): a
    20 N push no longer tells them apart (0.5 degrees without the stabiliser, 3-6 before), and the default
    ankles' damping control, which yields to the push, falls at 30 N."""

    def tilts(cfg, force):
        """Pelvis tilt (deg) after each step from the push on; +inf from the step at which the robot fell."""
        walk = _Native(W.make_sim(sim.shape, sim.resolution, cfg=cfg, robot=robots.hrp2()))
        out = []
        for n in range(6):
            walk.d.xfrc_applied[walk.sim.index.pelvis, 1] = force if n == 2 else 0.0
            _, fell = walk.step((0.1, 0.19, 0.0))
            if fell:
                out += [np.inf] * (6 - n)
                break
            m = walk.d.xmat[walk.sim.index.pelvis].reshape(3, 3)
            out.append(np.degrees(np.arccos(np.clip(m[2, 2], -1, 1))))
        return np.array(out[2:])  # from the push on

    stiff = dataclasses.replace(sim.cfg, ankle_damping=0.0)  # the stabiliser alone, stiff ankles
    with_it = tilts(stiff, 30.0)
    without = tilts(dataclasses.replace(stiff, land_gain=0.0), 30.0)
    assert np.all(np.isfinite(with_it)) and with_it[-2:].max() < 1.0, with_it  # standing, and upright again
    assert without.max() > 2.0, without  # the test can tell: it rolls, or falls
    # With the ankles' damping control (the default) the yielding ankles let a 20 N push roll the body further
    # (1.4 degrees measured at the next touch-down), and the stabiliser rights it within a step.
    default = tilts(sim.cfg, 20.0)
    assert default[1:].max() < 1.0, default


def test_carry_correction_moves_on_by_one_step():
    cfg = controller.WalkConfig()
    n = controller.correction_length(cfg)
    corr = jnp.arange(2 * n, dtype=jnp.float32).reshape(n, 2)
    out = controller.carry_correction(cfg, corr)
    steps = cfg.ticks_per_step
    np.testing.assert_array_equal(out[: n - steps], corr[steps:])  # period k of the next step = k + steps of this
    np.testing.assert_array_equal(out[n - steps:], 0.0)


def _stood_up(sim, stance, swing_from):
    """The controller's state after the warm-up step the walker starts with (both feet down, the left to swing
    next), from rest with the CoM at the model's offset."""
    cfg, params = sim.cfg, sim.params
    pg = controller.gains(cfg)
    prepare = controller.prepare_plan(stance, swing_from, 1.0)
    cs = controller.init_state(pg, jnp.array([cfg.com_offset, 0.0], jnp.float32))
    return jax.jit(lambda cs: jax.lax.scan(lambda c, _: (controller.control_tick(params, cfg, pg, prepare, c)[1], None),
                                           cs, None, length=cfg.ticks_per_step)[0])(cs)


@pytest.mark.slow
def test_dynamics_filter_brings_the_patterns_zmp_to_its_reference(sim):
    """A forward 0.2 m step: the multibody ZMP of the corrected pattern is much closer to the reference."""
    cfg, params = sim.cfg, sim.params
    pg = controller.gains(cfg)
    stance = jnp.array([0.0, -0.095, 0.0, 0.0, 0.0, 0.0], jnp.float32)
    swing_from = jnp.array([0.0, 0.095, 0.0, 0.0, 0.0, 0.0], jnp.float32)
    target = jnp.array([0.2, 0.095, 0.0, 0.0, 0.0, 0.0], jnp.float32)
    plan = controller.plan_step(jnp.zeros(2), stance, swing_from, target, True, 1.0, 0.0, cfg.clearance)
    cs = _stood_up(sim, stance, swing_from)._replace(t=jnp.zeros((), jnp.float32))
    length = cfg.ticks_per_step

    @jax.jit
    def rms_error(corr):
        qpos, zref = controller.predict(params, cfg, pg, plan, cs, corr, length)
        zmp, _ = dynamics.motion_zmp(sim.mjx_free, qpos, cfg.control_dt)
        return jnp.sqrt(jnp.mean(jnp.sum((zmp - zref[2:length]) ** 2, axis=1)))

    corr = jax.jit(lambda: controller.zmp_correction(sim.mjx_free, params, cfg, pg, plan, cs, 2))()
    assert corr.shape == (cfg.ticks_per_step + 2 * cfg.horizon, 2)
    before = float(rms_error(jnp.zeros_like(corr)))
    after = float(rms_error(corr))
    assert before > 0.02  # the uncorrected pattern's ZMP is centimetres off
    assert after < 0.5 * before, (before, after)


@pytest.mark.slow
def test_dynamics_filter_stays_bounded_up_a_flight_of_stairs(sim):
    """Six steps up 12 cm risers, 0.3 m each, the filter warm-started from step to step as the walker runs it
    (the pattern played kinematically, no physics): the correction settles. Corrected also over the periods
    after the assumed next step (where the played pattern takes no step), it fed itself through the carry
    (measured here: 0.43, 1.4, 6.3, 8.4 m at the second to fifth step; on native MuJoCo the LIPM's plan then
    ran off at the end of a step and the robot fell)."""
    cfg, params = sim.cfg, sim.params
    pg = controller.gains(cfg)
    rise, run = 0.12, 0.30

    def sole(i, side):  # the i-th landing (i = -1, -2: the standing feet), left side +1
        i = max(i, -1)
        return jnp.array([run * (i + 1), 0.095 * side, rise * (i + 1), 0.0, 0.0, 0.0], jnp.float32)

    @jax.jit
    def step(anchor, stance, swing_from, target, side, cs, corr):
        plan = controller.plan_step(anchor, stance, swing_from, target, True, side, target[2], cfg.clearance)
        cs = cs._replace(t=jnp.zeros((), jnp.float32))
        corr = controller.zmp_correction(sim.mjx_free, params, cfg, pg, plan, cs,
                                         init=controller.carry_correction(cfg, corr))

        def tick(c, k):
            window = jax.lax.dynamic_slice_in_dim(corr, k, cfg.horizon)
            return controller.control_tick(params, cfg, pg, plan, c, window)[1], None

        cs = jax.lax.scan(tick, cs, jnp.arange(cfg.ticks_per_step))[0]
        return cs, corr

    feet = {1.0: sole(-2, 1.0), -1.0: sole(-2, -1.0)}
    cs = _stood_up(sim, feet[-1.0], feet[1.0])
    corr = jnp.zeros((controller.correction_length(cfg), 2), jnp.float32)
    anchor, side, peaks = 0.5 * (feet[1.0][:2] + feet[-1.0][:2]), 1.0, []
    for i in range(6):
        target = sole(i, side)
        cs, corr = step(anchor, feet[-side], feet[side], target, jnp.float32(side), cs, corr)
        anchor, feet[side], side = feet[-side][:2], target, -side
        peaks.append(float(jnp.abs(corr[2:controller.filtered_length(cfg)]).max()))
    # peaks[0] holds the cold start's spike at the first measured period (the walker warm-starts from its standing
    # step); from the second step on the correction repeats itself (0.26 m at most, measured, near the end of the
    # assumed next step)
    assert np.all(np.isfinite(peaks)) and max(peaks[1:]) < 0.3 and peaks[-1] < peaks[1] + 0.01, peaks


# ----------------------------------------------------------------------------------------------------------------
# Sloped ground, the ankles' sensors and their damping control

COP_TOL = 0.005  # m: the sensors' CoP neglects the foot's own weight (1.7 kg) and inertia


def _contact_cop(walk):
    """Independent reference: each foot's ground force (N) and centre of pressure (m, in the sole's frame, from
    its centre) summed from MuJoCo's contact forces on the sole spheres (mj_contactForce)."""
    m, d, idx = walk.m, walk.d, walk.sim.index
    fz, moment = np.zeros(2), np.zeros((2, 2))
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        for row in range(2):
            if c.geom1 in idx.sole_geoms[row] or c.geom2 in idx.sole_geoms[row]:
                mujoco.mj_contactForce(m, d, i, f6)
                world = c.frame.reshape(3, 3).T @ f6[:3]
                rot = d.site_xmat[idx.sole_site[row]].reshape(3, 3)
                local = rot.T @ world
                lever = rot.T @ (c.pos - d.site_xpos[idx.sole_site[row]])
                fz[row] += abs(local[2])
                moment[row] += abs(local[2]) * lever[:2]
    return fz, moment / np.maximum(fz, 1e-9)[:, None]


def test_ankle_sensors_give_the_contacts_centre_of_pressure(sim):
    """After a step in place: each foot's ground force and CoP read from the ankle force/torque sensors match
    the ones summed from the contact forces (the independent reference)."""
    walk = _Native(sim)
    walk.step((0.0, 0.19, 0.0))
    for _ in range(100):
        mujoco.mj_step(walk.m, walk.d)
    f, cop = controller.ground_cop(sim.params, jnp.asarray(W.ankle_wrench(sim, walk.d), jnp.float32))
    fz_ref, cop_ref = _contact_cop(walk)
    np.testing.assert_allclose(np.asarray(f[:, 2]), fz_ref, atol=0.01 * sim.params.total_mass * 9.81)
    loaded = fz_ref > 50.0
    assert loaded.any()
    np.testing.assert_allclose(np.asarray(cop)[loaded], cop_ref[loaded], atol=COP_TOL)


def test_ankle_damping_turns_the_sole_toward_the_wanted_cop():
    """Signs of :func:`controller.comply`: a loaded left sole whose CoP lies ahead of and left of the wanted one
    turns its toe up (pitch offset < 0) and its left edge up (roll offset > 0) at (error x force) / damping; the
    unloaded right foot only leaks. The CoP helper inverts the sensor model (ground force at the CoP)."""
    params = model.biped_params()
    cfg = controller.WalkConfig(ankle_damping=500.0)
    pg = controller.gains(cfg)
    plan = controller.plan_step(jnp.zeros(2), SWING, STANCE, STANCE + jnp.array([0.2, 0, 0, 0, 0, 0]), True, -1.0,
                                0.0, cfg.clearance)  # the left foot (SWING) stands, the right one swings
    cs = controller.init_state(pg, jnp.zeros(2))._replace(ankle=jnp.array([[0.0, 0.0], [0.01, -0.02]]))
    fz, cop = 500.0, np.array([0.05, 0.02])  # ground force at a CoP 5 cm ahead, 2 cm left of the sole centre
    h = params.ankle_height
    ground_moment = np.cross([cop[0], cop[1], -h], [0.0, 0.0, fz])  # about the ankle
    weight = params.foot_mass * 9.81  # the sensor carries the foot: the ground pushes its weight more
    wrench = jnp.array([[0.0, 0.0, -(fz - weight), *(-ground_moment)], [0.0, 0.0, weight, 0, 0, 0]], jnp.float32)
    f, got = controller.ground_cop(params, wrench)
    np.testing.assert_allclose(got[0], cop, atol=1e-6)
    zref = SWING[:2]  # wanted: the sole centre
    out = controller.comply(params, cfg, plan, cs, zref, wrench)
    leak = np.exp(-cfg.control_dt / cfg.ankle_leak)
    np.testing.assert_allclose(out.ankle[0], cfg.control_dt * np.array([-0.05, 0.02]) * fz / cfg.ankle_damping,
                               rtol=1e-5)
    np.testing.assert_allclose(out.ankle[1], leak * np.array([0.01, -0.02]), rtol=1e-6)
    # Through a known control delay L the same error moves the sole slower, at 1 / (1 + L / ankle_delay) of the
    # rate: half at L = ankle_delay, a third at twice it; the unloaded foot's leak does not depend on it.
    for latency, scale in ((cfg.ankle_delay, 0.5), (2 * cfg.ankle_delay, 1 / 3), (0.0, 1.0)):
        late = controller.comply(params, cfg, plan, cs, zref, wrench, jnp.float32(latency))
        np.testing.assert_allclose(late.ankle[0], scale * np.asarray(out.ankle[0]), rtol=1e-5)
        np.testing.assert_allclose(late.ankle[1], out.ankle[1], rtol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("deg, axis", [(10.0, 0), (-10.0, 0), (6.0, 1), (-6.0, 1)])
def test_walks_on_a_slope(sim, deg, axis):
    """Up and down a 10 degree slope, across a 6 degree one: the soles land parallel to the ground (the plane
    fitted under them) without a fall. Level soles toppled the robot within its first step on 3 degrees.
    Across 10 degrees the tilt error grows step by step (a rocking that 5 % of 1024 MJX robots did not
    survive: BENCHMARKS.md), so that case is measured there, not asserted here."""
    nx, ny = sim.shape
    x = (np.arange(nx) + 0.5) * sim.resolution - 0.5 * nx * sim.resolution
    y = (np.arange(ny) + 0.5) * sim.resolution - 0.5 * ny * sim.resolution
    g = np.tan(np.radians(deg))
    heights = np.broadcast_to((g * x)[:, None] if axis == 0 else (g * y)[None, :], sim.shape)
    walk = _Native(sim, heights=heights)
    errs, tilts = [], []
    for k in range(5):
        err, fell = walk.step((0.2, 0.19, 0.0))
        assert not fell, k
        errs.append(err)
        tilts.append(walk.tilt_error)
    assert max(errs) < WALK_TOL, errs
    assert max(tilts) < np.radians(3.0), np.degrees(tilts)  # measured up to ~2.4 deg


# ------------------------------------------------------------------ capture-point stepping


def _sensed(sim, com, vel):
    """Stand-in data holding only what :func:`W.centre_of_mass` reads: the com and com_vel sensors."""
    from types import SimpleNamespace

    data = np.zeros(sim.mj_model.nsensordata, np.float32)
    adr = np.asarray(sim.index.com_sensor)
    data[adr[0]:adr[0] + 3], data[adr[1]:adr[1] + 3] = com, vel
    return SimpleNamespace(sensordata=jnp.asarray(data))


class SimpleCtrl:
    """The controller's state as :func:`W.balance_shift` reads it (the LIPM's rows)."""

    def __init__(self, lipm):
        self.lipm = jnp.asarray(lipm)


@pytest.mark.parametrize("gain, limit", [(1.0, 0.5), (2.5, 0.5), (2.5, 0.03)])
def test_balance_shift_is_the_capture_points_lead_in_the_world_frame(sim, gain, limit):
    """The next step moves by gain x (measured - planned capture point), rotated from the plan's frame (its yaw
    differs from the measured soles' by the stance's drift) back to the world, at most ``capture_max`` long
    (then along the same direction). Reference: the capture point's closed form in NumPy."""
    s = dataclasses.replace(sim, cfg=dataclasses.replace(sim.cfg, capture_gain=gain, capture_max=limit))
    stance = np.array([1.0, 2.0, 0.02, 0.0, 0.0, 0.4], np.float32)  # measured: x, y, z, roll, pitch, yaw
    planned = np.array([0.3, -0.1, 0.0, 0.0, 0.0, 0.25], np.float32)  # as commanded, the controller's frame
    com, vel = np.array([1.05, 1.97, 0.8]), np.array([0.31, -0.12, 0.01])
    lipm = np.array([[0.33, -0.14], [0.2, 0.05], [0.0, 0.0]], np.float32)
    cs = SimpleCtrl(lipm)
    got = np.asarray(W.balance_shift(s, _sensed(sim, com, vel), cs, jnp.asarray(stance), jnp.asarray(planned)))
    yaw = planned[5] - stance[5]
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    omega = np.sqrt(9.81 / sim.cfg.com_height)
    measured = rot @ (com[:2] - stance[:2]) + planned[:2], rot @ vel[:2]
    lead = (measured[0] - lipm[0]) + (measured[1] - lipm[1]) / omega  # the plan's frame
    want = gain * (rot.T @ lead)
    if np.linalg.norm(want) > limit:
        want = want * limit / np.linalg.norm(want)
    np.testing.assert_allclose(got, want, atol=2e-5)  # float32 of centimetres
    assert np.linalg.norm(got) <= limit + 1e-6


def test_the_exact_selector_measures_its_candidates_from_the_stance_moved_by_balance():
    """A stance info with ``balance`` (dx, dy) chooses the same action on flat ground, its foothold moved by
    exactly (dx, dy) (None, every rollout's default walker, is the stance as reported)."""
    from ijoy_jax import control

    field = T.flat((80, 80), 0.02)  # 2D: the smaller program; the shift does not depend on heights
    robot = robots.hrp2(margin=0.02)
    stance = jnp.array([0.6, 0.7, 0.0], jnp.float32)
    swing = geometry.compose(stance, jnp.array([0.0, 0.19, 0.0], jnp.float32))
    cmd = jnp.array([0.25, 0.0, 0.0], jnp.float32)
    # one compiled program for both (a zero balance measures from the stance itself, as None does)
    choose = jax.jit(lambda b: control.exact_selector(field, robot).choose(
        control.StanceInfo(stance, jnp.float32(-1), swing, b), cmd, None))
    base, ok, c0 = choose(jnp.zeros(2, jnp.float32))
    moved, ok2, c1 = choose(jnp.array([0.03, -0.02], jnp.float32))
    assert bool(ok) and bool(ok2) and int(c0.index) == int(c1.index)
    np.testing.assert_allclose(np.asarray(moved[:2]) - np.asarray(base[:2]), [0.03, -0.02], atol=1e-5)
    np.testing.assert_allclose(np.asarray(moved[2:]), np.asarray(base[2:]), atol=1e-6)


@pytest.mark.parametrize("step_time, ds, lift, want", [(0.8, 0.1, 0.2, 22), (0.5, 0.1, 0.2, 14), (0.8, 0.99, 0.5, 79)])
def test_the_step_adjustment_acts_at_the_end_of_the_lift(step_time, ds, lift, want):
    """``ds_time + swing_lift * swing time`` in control ticks (0.224 s -> 22; the G1's 0.14 s -> 14), never past
    the step's last tick."""
    cfg = controller.WalkConfig(step_time=step_time, ds_fraction=ds, swing_lift=lift)
    assert controller.adjust_tick(cfg) == want


def test_shift_plan_moves_the_touch_down_and_the_zmp_on_it_and_after():
    """The touch-down moves by (dx, dy) and comes down at z; the ZMP waypoints of the previous support and the
    stance stay, the two on and after the moved foot move alike; the apex stays ``clearance`` above the new
    touch-down (a profile: its last entry). A standing plan keeps its apex."""
    cfg = controller.WalkConfig()
    stance = jnp.array([0.0, -0.1, 0.0, 0.0, 0.0, 0.0])
    swing_from = jnp.array([-0.2, 0.1, 0.0, 0.0, 0.0, 0.0])
    pose = jnp.array([0.2, 0.1, 0.01, 0.0, 0.0, 0.0])
    adjust = jnp.array([0.03, -0.02, 0.2])
    for top in (jnp.float32(0.0), jnp.zeros(5, jnp.float32)):
        plan = controller.plan_step(jnp.zeros(2), stance, swing_from, pose, True, 1.0, top, cfg.clearance)
        moved = controller.shift_plan(cfg, plan, adjust)
        np.testing.assert_allclose(moved.swing_to, [0.23, 0.08, 0.2, 0.0, 0.0, 0.0], atol=1e-7)
        np.testing.assert_allclose(moved.zmp[:2], plan.zmp[:2])
        np.testing.assert_allclose(moved.zmp[2:], plan.zmp[2:] + jnp.array([0.03, -0.02]), atol=1e-7)
        np.testing.assert_allclose(jnp.ravel(moved.apex)[-1], 0.2 + cfg.clearance, atol=1e-7)
        np.testing.assert_allclose(jnp.ravel(moved.apex)[:-1], jnp.ravel(plan.apex)[:-1])
        assert moved.stance is plan.stance and moved.swing_from is plan.swing_from
    standing = controller.plan_step(jnp.zeros(2), stance, swing_from, pose, False, 1.0, 0.0, cfg.clearance)
    np.testing.assert_allclose(controller.shift_plan(cfg, standing, adjust).apex, standing.apex)


@pytest.mark.parametrize("go", [True, False])
def test_swing_shift_is_the_capture_points_lead_at_the_moved_soles_rest_height(sim, go):
    """``WalkConfig.swing_adjust`` x (measured - LIPM capture point), at most ``capture_max``, in the plan's frame
    (NumPy's closed form); the foot comes down at the rest height of the sole moved there in the world, whose
    yaw differs from the plan's: the plan's +x is the world's -y here, and only a move toward -y reaches the
    4 cm block beside the foothold (the terrain arrays say where it is). A standing step does not move."""
    s = dataclasses.replace(sim, cfg=dataclasses.replace(sim.cfg, swing_adjust=3.0, capture_max=0.1))
    heights = np.zeros(sim.shape, np.float32)
    heights[:, :90] = 0.04  # y < 1.8 m (cell centres up to 1.79 m)
    world = W.make_world(s, T.from_arrays(heights, resolution=0.02))
    target = jnp.array([2.0, 1.886, 0.0, 0.0, 0.0, 0.0], jnp.float32)  # sole sides at y 1.83, 1.942: on the low part
    yaw = np.pi / 2  # world -> plan
    to_plan = kinematics.rot_z(jnp.float32(yaw))
    plan = controller.plan_step(jnp.zeros(2), target, target, target, go, 1.0, 0.0, s.cfg.clearance)
    lipm = np.array([[0.3, -0.1], [0.2, 0.05], [0.0, 0.0]], np.float32)
    com = (jnp.asarray(lipm[0] + [0.01, 0.0]), jnp.asarray(lipm[1] + [0.0583, 0.0]))
    got = np.asarray(W.swing_shift(s, world.phys, plan, target, to_plan, SimpleCtrl(lipm), com))
    omega = np.sqrt(9.81 / s.cfg.com_height)
    want = 3.0 * np.array([0.01 + 0.0583 / omega, 0.0])  # 8 cm along the plan's x, within the 10 cm cap
    if go:
        np.testing.assert_allclose(got[:2], want, atol=2e-5)
        assert got[2] == pytest.approx(0.04, abs=1e-6)  # moved 8 cm toward -y: its sides at 1.75, 1.862 m
    else:
        np.testing.assert_allclose(got, [0.0, 0.0, float(plan.swing_to[2])], atol=1e-7)


@pytest.mark.slow
def test_the_native_robot_moves_a_pushed_swing_foot_as_the_mjx_walker(sim):
    """The native robot makes ``WalkConfig.swing_adjust``'s move too (:attr:`native.Programs.adjust`, at the MJX
    walker's tick): pushed forward (50 N on the pelvis through one step) its swing foot comes down further ahead
    than the same robot's without the adjustment, by at most ``capture_max``, away from the foothold it was
    sent to, where the robot without it lands within PLACEMENT_TOL of its foothold; neither falls."""
    adjusted = dataclasses.replace(sim, cfg=dataclasses.replace(sim.cfg, swing_adjust=2.0))

    def pushed(s):
        walk = _Native(s)
        walk.step((0.1, 0.19, 0.0))
        walk.d.xfrc_applied[s.index.pelvis, 0] = 50.0  # 11 N s by the adjustment's tick (0.224 s)
        err, fell = walk.step((0.1, 0.19, 0.0))  # the right foot swings
        walk.d.xfrc_applied[s.index.pelvis, 0] = 0.0
        _, fell_after = walk.step((0.1, 0.19, 0.0))
        return float(walk.soles()[1][0]), err, fell or fell_after

    x_plain, err_plain, fell_plain = pushed(sim)
    x_moved, err_moved, fell_moved = pushed(adjusted)
    assert not fell_plain and not fell_moved
    assert err_plain < PLACEMENT_TOL < err_moved <= sim.cfg.capture_max + PLACEMENT_TOL
    assert 0.02 < x_moved - x_plain <= sim.cfg.capture_max + PLACEMENT_TOL  # measured: 4.0 cm ahead


_finite = st.floats(-5.0, 5.0, allow_nan=False, width=32)


@settings(max_examples=40, deadline=None)
@given(st.lists(_finite, min_size=3, max_size=3), st.lists(_finite, min_size=6, max_size=6),
       st.lists(_finite, min_size=6, max_size=6))
def test_plan_frame_position_moves_the_point_with_the_stance_horizontally_and_keeps_the_worlds_height(p, st_, pst):
    """Horizontally the rigid planar motion that takes the measured stance sole onto the planned one (NumPy's
    rotation about z by the yaw difference); the height is the point's own world height, whatever the measured
    stance's height: a stance sole measured hovering or sunk by millimetres moves nothing up or down (anchored
    on it, the G1 turning in place landed 1.3 mm higher with each step and fell)."""
    p, st_, pst = (np.asarray(a, np.float32) for a in (p, st_, pst))
    to_plan = kinematics.rot_z(jnp.float32(pst[5] - st_[5]))
    got = np.asarray(W.plan_frame_position(jnp.asarray(p), jnp.asarray(st_), jnp.asarray(pst), to_plan))
    c, s = np.cos(float(pst[5]) - float(st_[5])), np.sin(float(pst[5]) - float(st_[5]))
    d = p[:2].astype(np.float64) - st_[:2]
    want = np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]]) + pst[:2]
    np.testing.assert_allclose(got[:2], want, atol=1e-5)  # float32 sums of |terms| <= 20 m: 1e-5 m
    assert got[2] == p[2]
    moved = np.asarray(W.plan_frame_position(jnp.asarray(p), jnp.asarray(st_).at[2].add(0.005), jnp.asarray(pst),
                                             to_plan))
    np.testing.assert_array_equal(moved, got)
    # the native robot's host-side tick passes NumPy arrays and gets NumPy back, the same values
    host = W.plan_frame_position(p.astype(np.float64), st_.astype(np.float64), pst.astype(np.float64),
                                 np.asarray(to_plan, np.float64))
    assert isinstance(host, np.ndarray)
    np.testing.assert_allclose(host, got, atol=1e-5)
    # anchored (WalkConfig.stance_anchor 1, the biped's): exactly the rigid motion in all three axes, the height
    # measured from the stance sole and carried onto the planned one's (the controller before the G1's fix);
    # halfway: the mean of both heights
    rigid = to_plan @ (jnp.asarray(p) - jnp.asarray(st_)[:3]) + jnp.asarray(pst)[:3]
    anchored = W.plan_frame_position(jnp.asarray(p), jnp.asarray(st_), jnp.asarray(pst), to_plan, 1.0)
    np.testing.assert_array_equal(np.asarray(anchored), np.asarray(rigid))
    np.testing.assert_allclose(float(rigid[2]), float(p[2]) - float(st_[2]) + float(pst[2]), atol=1e-5)
    half = W.plan_frame_position(jnp.asarray(p), jnp.asarray(st_), jnp.asarray(pst), to_plan, 0.5)
    np.testing.assert_allclose(np.asarray(half)[2], 0.5 * (float(p[2]) + float(rigid[2])), atol=1e-5)
    np.testing.assert_array_equal(np.asarray(half)[:2], got[:2])
    host = W.plan_frame_position(p.astype(np.float64), st_.astype(np.float64), pst.astype(np.float64),
                                 np.asarray(to_plan, np.float64), 1.0)
    np.testing.assert_allclose(host, np.asarray(rigid), atol=1e-5)


def test_the_biped_measures_its_pelvis_from_the_stance_sole_and_the_g1_at_its_world_height():
    """WalkConfig.stance_anchor: the biped's default anchors (it walks down stairs better so), the G1's settings
    take the world's height (anchored, it landed ever higher turning in place); outside [0, 1] refused."""
    from ijoy_jax.sim import g1

    assert controller.WalkConfig().stance_anchor == 1.0
    assert controller.WalkConfig(**g1.WALK).stance_anchor == 0.0
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="WalkConfig.stance_anchor"):
            controller.WalkConfig(stance_anchor=bad)
