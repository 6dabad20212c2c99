"""The multibody ZMP of a planned motion: how far the walking pattern is from what the LIPM promised.

The preview controller plans the CoM of a linear inverted pendulum; the
biped's legs and upper body move differently (the swing leg, the pelvis that
compensates it, the lift and descent), so the real robot's ZMP for the same
joint trajectory differs. :func:`motion_zmp` measures that: it takes a joint
trajectory (qpos at a fixed period), differentiates it twice, runs the
recursive Newton-Euler algorithm of MuJoCo XLA on it (no contacts), and reads
the ground-reaction wrench the free joint would need, whose centre of pressure
on the ground is the ZMP. Without correction the pattern's ZMP lies up to 19 cm
(rms 6 cm) off the reference on forward 0.2 m steps, toe and heel in turn,
enough to fall: the error that :func:`ijoy_jax.sim.controller.zmp_correction`
(a dynamics filter, Kajita et al. 2003, second preview stage) removes.
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from ijoy_jax.sim import model


def no_contact_model(mj_model: mujoco.MjModel) -> mjx.Model:
    """The MJX model with constraints (contacts, joint limits) disabled, for inverse dynamics of free motion.

    Raises ValueError for a model whose free joint :func:`motion_zmp` would misread: one that is not the
    first joint, or passive forces on its rows that it leaves out (a spring on the free joint, gravity
    compensation, fluid forces, tendon springs or dampers). Springs on the other joints act on their own rows
    only, and damping is modelled (:func:`motion_zmp`), so both are allowed.
    """
    if mj_model.njnt < 1 or mj_model.jnt_type[0] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError("the robot's first joint must be its free joint")
    leaves_out = [what for what, present in (
        ("a spring on the free joint", mj_model.jnt_stiffness[0] != 0),
        ("gravity compensation", np.any(mj_model.body_gravcomp != 0)),
        ("fluid forces", mj_model.opt.density != 0 or mj_model.opt.viscosity != 0),
        ("tendon springs or dampers", np.any(mj_model.tendon_stiffness != 0) or np.any(mj_model.tendon_damping != 0)),
    ) if present]
    if leaves_out:
        raise ValueError(f"motion_zmp leaves out passive forces on the free joint's rows; this model has "
                         f"{', '.join(leaves_out)}")
    m = copy.copy(mj_model)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT) | int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    return model.put_model(m)


def _quat_mul(a, b):
    w1, x1, y1, z1 = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    w2, x2, y2, z2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return jnp.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                      w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=-1)


def free_velocity(q0, q1, dt) -> jax.Array:
    """(6 + n,) qvel taking qpos q0 to q1 in dt: world linear velocity, body-frame angular velocity, joint rates.

    The finite difference :func:`motion_zmp` differentiates a trajectory with, for a robot whose qpos is a
    free joint (position m, unit quaternion wxyz) followed by n hinges (rad): what MuJoCo's
    ``mj_differentiatePos`` gives for such a model, in JAX (jit/vmap/grad-able; the shortest rotation).

    Args:
      q0, q1: (7 + n,) qpos at the start and end of the interval.
      dt: the interval (s).

    Returns:
      (6 + n,) linear velocity (m/s, world frame), angular velocity (rad/s, body frame), joint rates (rad/s).

    Example:
      >>> import math, jax.numpy as jnp
      >>> from ijoy_jax.sim import dynamics
      >>> q0 = jnp.array([0.0, 0.0, 0.7, 1.0, 0.0, 0.0, 0.0, 0.1])
      >>> q1 = jnp.array([0.01, 0.0, 0.7, math.cos(0.005), 0.0, 0.0, math.sin(0.005), 0.12])  # yaw 0.01 rad
      >>> [round(float(v), 3) for v in dynamics.free_velocity(q0, q1, 0.01)]
      [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0]
    """
    lin = (q1[:3] - q0[:3]) / dt
    conj = q0[3:7] * jnp.array([1.0, -1.0, -1.0, -1.0], q0.dtype)
    rel = _quat_mul(conj, q1[3:7])
    rel = jnp.where(rel[0] < 0, -rel, rel)
    vec = rel[1:]
    s = jnp.sqrt(jnp.sum(vec**2) + 1e-30)
    angle = 2.0 * jnp.arctan2(s, rel[0])
    ang = jnp.where(s > 1e-12, angle / s, 2.0) * vec / dt
    return jnp.concatenate([lin, ang, (q1[7:] - q0[7:]) / dt])


def motion_zmp(m: mjx.Model, qpos: jax.Array, dt: float, ground=None) -> tuple[jax.Array, jax.Array]:
    """Multibody ZMP of a trajectory of a free-floating robot, on the horizontal plane of the support.

    Args:
      m: an MJX model whose first joint is the free joint, with constraints off
        (:func:`no_contact_model`).
      qpos: (T, nq) positions at period ``dt`` (T >= 3).
      dt: period (s).
      ground: (T - 2,) height (m) of the plane the ZMP is taken on at samples
        1 .. T - 2 (the support's; default 0). With the ground-reaction force
        f and moment tau about the origin, ``zmp = ((z f_x - tau_y) / f_z,
        (z f_y + tau_x) / f_z)``: on a stair 30 cm up, the plane z = 0 would
        misplace the ZMP by ``0.3 f_x / f_z``, centimetres while the body
        accelerates.

    Returns:
      ``(zmp (T - 2, 2), fz (T - 2,))``: the ZMP (m, world x, y) and the vertical
      ground force (N) at samples 1 .. T - 2, from central differences.
    """
    ground = jnp.zeros(qpos.shape[0] - 2, qpos.dtype) if ground is None else jnp.asarray(ground, qpos.dtype)
    v = jax.vmap(lambda a, b: free_velocity(a, b, dt))(qpos[:-1], qpos[1:])  # (T - 1, nv), at half samples
    qvel = 0.5 * (v[1:] + v[:-1])
    qacc = (v[1:] - v[:-1]) / dt

    def one(q, qv, qa, z):
        # The free joint's rows of mjx.inverse, without what they never need (the mass matrix and its
        # factor, sensors, constraints, a second Newton-Euler pass): the bias forces with the inertial
        # term, plus the armature's, minus the passive forces (inverse dynamics subtracts qfrc_passive):
        # of those no_contact_model allows on these rows, the damping -dof_damping * qvel. The same to
        # float32 rounding (4.5e-8 m of ZMP, test_sim_dynamics), at two thirds of the time.
        d = mjx.make_data(m).replace(qpos=q, qvel=qv, qacc=qa)
        d = mjx.rne(m, mjx.com_vel(m, mjx.com_pos(m, mjx.kinematics(m, d))), flg_acc=True)
        qfrc = d.qfrc_bias + m.dof_armature * qa + m.dof_damping * qv
        f = qfrc[0:3]
        # The free joint's torque is in the floating body's frame; kinematics computed its pose.
        tau = d.xmat[1].reshape(3, 3) @ qfrc[3:6] + jnp.cross(q[0:3], f)
        fz = f[2]
        safe = jnp.where(jnp.abs(fz) > 1e-6, fz, 1.0)
        return jnp.stack([(z * f[0] - tau[1]) / safe, (z * f[1] + tau[0]) / safe]), fz

    return jax.vmap(one)(qpos[1:-1], qvel, qacc, ground)
