"""Tests of the walking controller (ijoy_jax.sim.controller).

Unit checks of the plan and the foot targets, and short walks with the JAX
controller in the loop and native MuJoCo for the physics (about 100x faster
than MJX on CPU; the MJX rollout runs the same controller functions).
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from ijoy_jax import geometry, robots
from ijoy_jax import terrain as T
from ijoy_jax.sim import controller, dynamics, model
from ijoy_jax.sim import walker as W

ATOL = 1e-6  # float32 arithmetic on metre-sized numbers
PLACEMENT_TOL = 0.02  # m: touch-down error of a step in place (measured ~0.6 cm)

STANCE = jnp.array([0.0, -0.095, 0.0, 0.0], jnp.float32)
SWING = jnp.array([0.0, 0.095, 0.0, 0.0], jnp.float32)
POSE = jnp.array([0.2, 0.095, 0.0, 0.1], jnp.float32)


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
    return W.make_sim((120, 60), 0.02, robot=robots.hrp2())


class _Native:
    """The walker's step logic on host MuJoCo (one robot, flat ground)."""

    def __init__(self, sim):
        self.sim, self.cfg, self.params = sim, sim.cfg, sim.params
        terr = T.from_arrays(np.zeros(sim.shape), None, sim.resolution, origin=(-0.6, -0.6)).replace(has_height=True)
        self.m = model.build_model(self.params, terr)
        self.d = mujoco.MjData(self.m)
        feet = jnp.array([[0.0, 0.095, 0.0], [0.0, -0.095, 0.0]], jnp.float32)
        self.d.qpos[:] = np.asarray(W.standing_qpos(self.params, self.cfg, feet, jnp.zeros(2)))
        self.d.ctrl[:] = self.d.qpos[7:]
        mujoco.mj_forward(self.m, self.d)
        self.pg = controller.gains(self.cfg)
        params, cfg, pg = self.params, self.cfg, self.pg
        self.tick = jax.jit(lambda plan, cs: controller.control_tick(params, cfg, pg, plan, cs))
        self.sub = sim.substeps
        self.cs = controller.init_state(pg, self.d.subtree_com[sim.index.pelvis][:2])
        self.swing = 1.0
        s = self.soles()
        self.run_step(controller.prepare_plan(jnp.asarray(s[1]), jnp.asarray(s[0]), 1.0))
        self.anchor = 0.5 * (s[0, :2] + s[1, :2])

    def soles(self):
        idx = self.sim.index
        pos = self.d.site_xpos[idx.sole_site]
        mat = self.d.site_xmat[idx.sole_site].reshape(2, 3, 3)
        return np.concatenate([pos, np.arctan2(mat[:, 1, 0], mat[:, 0, 0])[:, None]], 1).astype(np.float32)

    def run_step(self, plan):
        d = self.d
        self.cs = self.cs._replace(t=jnp.float32(0))
        low = np.inf
        for _ in range(self.cfg.ticks_per_step):
            q, self.cs, _ = self.tick(plan, self.cs)
            d.ctrl[:] = np.asarray(q)
            for _ in range(self.sub):
                mujoco.mj_step(self.m, d)
            low = min(low, d.qpos[2])
        return low

    def step(self, action):
        """Take one action (dx, dy, dtheta of the left swing foot, mirrored for the right): placement error, fell."""
        s = self.soles()
        st, sw = (s[1], s[0]) if self.swing > 0 else (s[0], s[1])
        rel = jnp.asarray([action[0], action[1] * self.swing, action[2] * self.swing], jnp.float32)
        pose = np.asarray(geometry.compose(jnp.asarray(st[[0, 1, 3]]), rel))
        target = jnp.asarray([pose[0], pose[1], 0.0, pose[2]], jnp.float32)
        plan = controller.plan_step(self.anchor, st, sw, target, True, self.swing, 0.0, self.cfg.clearance)
        low = self.run_step(plan)
        landed = self.soles()[0 if self.swing > 0 else 1]
        self.anchor = np.asarray(st[:2])
        self.swing = -self.swing
        return float(np.hypot(*(landed[:2] - np.asarray(target[:2])))), low < self.sim.fall_height


def test_control_tick_does_not_recompile(sim):
    walk = _Native(sim)
    walk.step((0.0, 0.19, 0.0))  # the state's weak types settle after the standing step's first tick
    before = walk.tick._cache_size()
    walk.step((0.0, 0.19, 0.0))
    assert walk.tick._cache_size() == before


def test_steps_in_place(sim):
    walk = _Native(sim)
    errs = []
    for _ in range(4):
        err, fell = walk.step(robots.hrp2().p0)
        assert not fell
        errs.append(err)
    assert max(errs) < PLACEMENT_TOL, errs


def test_dynamics_filter_brings_the_patterns_zmp_to_its_reference(sim):
    """A forward 0.2 m step: the multibody ZMP of the corrected pattern is much closer to the reference."""
    cfg, params = sim.cfg, sim.params
    pg = controller.gains(cfg)
    stance = jnp.array([0.0, -0.095, 0.0, 0.0], jnp.float32)
    swing_from = jnp.array([0.0, 0.095, 0.0, 0.0], jnp.float32)
    target = jnp.array([0.2, 0.095, 0.0, 0.0], jnp.float32)
    plan = controller.plan_step(jnp.zeros(2), stance, swing_from, target, True, 1.0, 0.0, cfg.clearance)
    cs = controller.init_state(pg, jnp.array([cfg.com_offset, 0.0], jnp.float32))
    prepare = controller.prepare_plan(stance, swing_from, 1.0)  # from rest, as the walker starts
    cs = jax.jit(lambda cs: jax.lax.scan(lambda c, _: (controller.control_tick(params, cfg, pg, prepare, c)[1], None),
                                         cs, None, length=cfg.ticks_per_step)[0])(cs)
    cs = cs._replace(t=jnp.zeros((), jnp.float32))
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
