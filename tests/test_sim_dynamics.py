"""Tests of the multibody ZMP (ijoy_jax.sim.dynamics) against closed forms."""

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from ijoy_jax.sim import dynamics, model

G = 9.81
ZMP_TOL = 2e-3  # m: float32 inverse dynamics of a 58 kg robot, accelerations from differences at 10 ms


def _robot_model(params):
    """The robot over a small flat height field: its masses and kinematics, no terrain to speak of."""
    return model.build_spec(params, (2, 2), 1.0).compile()


@pytest.fixture(scope="module")
def setup():
    params = model.biped_params()
    mj_model = _robot_model(params)
    qpos = model.standing_qpos(params)
    data = mujoco.MjData(mj_model)
    data.qpos[:] = qpos
    mujoco.mj_forward(mj_model, data)
    pelvis = model.model_index(mj_model).pelvis
    com = data.subtree_com[pelvis].copy()
    mass = float(mj_model.body_subtreemass[pelvis])
    return dynamics.no_contact_model(mj_model), qpos, com, mass


@pytest.fixture(scope="module")
def zmp_fn():
    return jax.jit(dynamics.motion_zmp, static_argnames="dt")


def test_standing_still_puts_the_zmp_under_the_com(setup, zmp_fn):
    m, qpos, com, mass = setup
    traj = jnp.tile(jnp.asarray(qpos, jnp.float32), (5, 1))
    zmp, fz = zmp_fn(m, traj, dt=0.01)
    np.testing.assert_allclose(zmp, np.tile(com[:2], (3, 1)), atol=ZMP_TOL)
    np.testing.assert_allclose(fz, mass * G, rtol=1e-3)


@pytest.mark.slow
@pytest.mark.parametrize("acc", [(1.0, 0.0), (0.0, -0.8), (0.5, 0.5)])
def test_rigid_acceleration_shifts_the_zmp_by_the_cart_table_law(setup, zmp_fn, acc):
    """The whole robot translating rigidly with acceleration a: zmp = com - z_com a / g (no angular momentum)."""
    m, qpos, com, mass = setup
    dt = 0.01
    t = np.arange(7) * dt
    traj = np.tile(qpos, (7, 1))
    traj[:, 0] += 0.5 * acc[0] * t**2
    traj[:, 1] += 0.5 * acc[1] * t**2
    zmp, fz = zmp_fn(m, jnp.asarray(traj, jnp.float32), dt=dt)
    want = com[:2] + np.outer(0.5 * t[1:-1] ** 2, acc) - com[2] * np.asarray(acc) / G
    np.testing.assert_allclose(zmp, want, atol=ZMP_TOL)
    np.testing.assert_allclose(fz, mass * G, rtol=1e-3)


@pytest.mark.slow
def test_turning_in_place_keeps_the_zmp_near_the_com(setup, zmp_fn):
    """Yaw accelerating at 2 rad/s^2 about the vertical through the pelvis: the ZMP stays within a centimetre."""
    m, qpos, com, mass = setup
    traj = np.tile(qpos, (6, 1))
    yaw = 0.5 * 2.0 * (0.01 * np.arange(6)) ** 2
    traj[:, 3], traj[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    zmp, fz = zmp_fn(m, jnp.asarray(traj, jnp.float32), dt=0.01)
    assert bool(jnp.all(jnp.isfinite(zmp)))
    np.testing.assert_allclose(zmp, np.tile(com[:2], (4, 1)), atol=0.01)


@pytest.mark.slow
def test_zmp_on_a_raised_support_plane(setup, zmp_fn):
    """The ZMP on the plane z = g: the free robot accelerating horizontally (a ramp of the pelvis position) has
    its ZMP moved by -(h - g) a / g_grav from the CoM; raising the plane by g moves it by g f_x / f_z."""
    m, qpos, com, mass = setup
    acc = 1.0  # m/s^2 along x
    dt = 0.01
    t = np.arange(7) * dt
    traj = np.tile(np.asarray(qpos, np.float32), (7, 1))
    traj[:, 0] += 0.5 * acc * t**2
    flat, fz = zmp_fn(m, jnp.asarray(traj), dt=dt)
    raised, _ = zmp_fn(m, jnp.asarray(traj), dt=dt, ground=jnp.full(5, 0.3, jnp.float32))
    np.testing.assert_allclose(np.asarray(raised - flat)[:, 0], 0.3 * mass * acc / np.asarray(fz), atol=ZMP_TOL)
    np.testing.assert_allclose(np.asarray(raised - flat)[:, 1], 0.0, atol=ZMP_TOL)
    np.testing.assert_allclose(np.asarray(flat)[:, 0] - (com[0] + traj[1:-1, 0] - qpos[0]),
                               -com[2] * acc / G, atol=ZMP_TOL)


def _inverse_dynamics_zmp(m, qpos, dt):
    """The reference: the ZMP from the free joint's rows of ``mjx.inverse`` (the full inverse dynamics)."""
    from mujoco import mjx

    v = jax.vmap(lambda a, b: dynamics.free_velocity(a, b, dt))(qpos[:-1], qpos[1:])
    qvel, qacc = 0.5 * (v[1:] + v[:-1]), (v[1:] - v[:-1]) / dt

    def one(q, qv, qa):
        d = mjx.inverse(m, mjx.make_data(m).replace(qpos=q, qvel=qv, qacc=qa))
        f = d.qfrc_inverse[0:3]
        tau = d.xmat[1].reshape(3, 3) @ d.qfrc_inverse[3:6] + jnp.cross(q[0:3], f)
        return jnp.stack([-tau[1] / f[2], tau[0] / f[2]]), f[2]

    return jax.vmap(one)(qpos[1:-1], qvel, qacc)


def _with_passive_forces(mj_model):
    """The robot with every passive force motion_zmp models on the free joint's rows, and some on other rows:
    damping and armature on the free joint's six dofs, springs on every hinge (their own rows only)."""
    mj_model = copy.copy(mj_model)
    mj_model.dof_damping[:6] = [30.0, 20.0, 40.0, 5.0, 8.0, 3.0]
    mj_model.dof_armature[:6] = [0.5, 0.2, 0.4, 0.05, 0.08, 0.03]
    mj_model.jnt_stiffness[1:] = 20.0
    return mj_model


@pytest.mark.slow
@pytest.mark.parametrize("passive", [False, True], ids=["as built", "free-joint damping and armature, hinge springs"])
def test_the_zmp_matches_full_inverse_dynamics_on_a_swinging_turning_motion(setup, zmp_fn, passive):
    """Every joint swinging, the body translating, rolling and turning: motion_zmp's Newton-Euler pass gives
    the ZMP and vertical force of MuJoCo's full inverse dynamics (the one it replaced) to float32 rounding,
    also with the passive forces no_contact_model allows (damping enters with mjx.inverse's sign)."""
    m, qpos, com, mass = setup
    if passive:
        m = dynamics.no_contact_model(_with_passive_forces(_robot_model(model.biped_params())))
    rng = np.random.default_rng(3)
    n = 30
    t = np.arange(n) * 0.01
    traj = np.tile(np.asarray(qpos, np.float64), (n, 1))
    traj[:, 0] += 0.3 * t + 0.2 * t**2
    traj[:, 1] += 0.05 * np.sin(6 * t)
    yaw, roll = 0.3 * t**2, 0.05 * np.sin(5 * t)
    traj[:, 3:7] = np.stack([np.cos(yaw / 2) * np.cos(roll / 2), np.cos(yaw / 2) * np.sin(roll / 2),
                             np.sin(yaw / 2) * np.sin(roll / 2), np.sin(yaw / 2) * np.cos(roll / 2)], axis=1)
    nj = traj.shape[1] - 7
    traj[:, 7:] += 0.3 * np.sin(np.outer(t, rng.uniform(2, 8, nj)) + rng.uniform(0, 6, nj))
    traj = jnp.asarray(traj, jnp.float32)
    zmp, fz = zmp_fn(m, traj, dt=0.01)
    want_zmp, want_fz = jax.jit(_inverse_dynamics_zmp, static_argnames="dt")(m, traj, dt=0.01)
    assert float(np.ptp(np.asarray(want_zmp)[:, 0])) > 0.01  # the motion moves the ZMP (1.6 cm): a real comparison
    np.testing.assert_allclose(zmp, want_zmp, atol=1e-5)  # m; measured 4.5e-8
    np.testing.assert_allclose(fz, want_fz, rtol=1e-5)


_TENDON_XML = """<mujoco><worldbody><body><freejoint/><geom size="0.1" mass="1"/>
  <body pos="0 0 -0.2"><joint name="h1" axis="0 1 0"/><geom size="0.05" mass="0.5"/>
  <body pos="0 0 -0.2"><joint name="h2" axis="0 1 0"/><geom size="0.05" mass="0.5"/></body></body></body>
  </worldbody><tendon><fixed stiffness="3"><joint joint="h1" coef="1"/><joint joint="h2" coef="-1"/></fixed>
  </tendon></mujoco>"""


@pytest.mark.parametrize("change, match", [
    (lambda mm: mm.jnt_stiffness.__setitem__(0, 5.0), "a spring on the free joint"),
    (lambda mm: mm.body_gravcomp.__setitem__(1, 1.0), "gravity compensation"),
    (lambda mm: setattr(mm.opt, "density", 1.2), "fluid forces"),
    (lambda mm: mm.jnt_type.__setitem__(0, mujoco.mjtJoint.mjJNT_BALL), "first joint must be its free joint"),
])
def test_no_contact_model_refuses_forces_the_zmp_leaves_out(change, match):
    mj_model = _robot_model(model.biped_params())
    change(mj_model)
    with pytest.raises(ValueError, match=match):
        dynamics.no_contact_model(mj_model)


def test_no_contact_model_refuses_tendon_springs_and_names_every_force_left_out():
    mj_model = mujoco.MjModel.from_xml_string(_TENDON_XML)
    with pytest.raises(ValueError, match="tendon springs or dampers$"):
        dynamics.no_contact_model(mj_model)
    mj_model.tendon_stiffness[:] = 0.0
    dynamics.no_contact_model(mj_model)  # the same model without the tendon's spring is accepted
    mj_model.body_gravcomp[1] = 1.0
    mj_model.tendon_damping[:] = 2.0
    with pytest.raises(ValueError, match="gravity compensation, tendon springs or dampers"):
        dynamics.no_contact_model(mj_model)
