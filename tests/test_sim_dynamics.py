"""Tests of the multibody ZMP (ijoy_jax.sim.dynamics) against closed forms."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from ijoy_jax.sim import dynamics, model

G = 9.81
ZMP_TOL = 2e-3  # m: float32 inverse dynamics of a 58 kg robot, accelerations from differences at 10 ms


@pytest.fixture(scope="module")
def setup():
    params = model.biped_params()
    mj_model = model._robot_model(params)
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


def test_turning_in_place_keeps_the_zmp_near_the_com(setup, zmp_fn):
    """Yaw accelerating at 2 rad/s^2 about the vertical through the pelvis: the ZMP stays within a centimetre."""
    m, qpos, com, mass = setup
    traj = np.tile(qpos, (6, 1))
    yaw = 0.5 * 2.0 * (0.01 * np.arange(6)) ** 2
    traj[:, 3], traj[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    zmp, fz = zmp_fn(m, jnp.asarray(traj, jnp.float32), dt=0.01)
    assert bool(jnp.all(jnp.isfinite(zmp)))
    np.testing.assert_allclose(zmp, np.tile(com[:2], (4, 1)), atol=0.01)


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
