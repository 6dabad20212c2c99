"""Leg kinematics of the HRP-2-like biped: forward kinematics and Kajita's analytic inverse kinematics.

Each leg is the chain hip_yaw (z), hip_roll (x), hip_pitch (y), knee (y),
ankle_pitch (y), ankle_roll (x). The three hip axes meet at the hip point
``(0, side * hip_offset_y, 0)`` of the pelvis frame, the thigh (``thigh``
metres) and shank (``shank`` metres) hang along -z at q = 0, the two ankle
axes meet at the ankle point, and the sole centre lies ``ankle_height`` below
it. At q = 0 the leg is straight and every frame is parallel to the pelvis.
Positive knee angles bend the knee forward (the human way). Side: +1 left,
-1 right (or the strings ``"left"``/``"right"``).

All functions are pure JAX for one leg; batch them with ``jax.vmap``. They
keep the dtype of their inputs (float32 by default, float64 under
``jax.enable_x64``).

Reference: S. Kajita et al., Introduction to Humanoid Robotics, Springer 2014,
section 2.5 (``IK_leg``).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

__all__ = [
    "LegIK",
    "leg_fk",
    "leg_ik",
    "leg_sign",
    "rot_x",
    "rot_y",
    "rot_z",
    "rpy_to_rot",
    "yaw_rot",
]

# sqrt(x) counts as 0 for x below this, so its gradient stays finite at the straight knee
# (x = 1 - cos^2) and at a zero hip-ankle distance; the value error is below sqrt(1e-24) = 1e-12.
_STRAIGHT_EPS = 1e-24
# Slack on the reach test (metres): a target at exactly thigh + shank is reachable despite rounding.
_REACH_TOL = 1e-6


class LegIK(NamedTuple):
    """Result of :func:`leg_ik`.

    Fields::

      q: (6,) joint angles, radians (hip_yaw, hip_roll, hip_pitch, knee, ankle_pitch, ankle_roll).
      reachable: () bool, False when the hip-to-ankle distance is outside the
        leg's reach (straight leg, knee at its upper limit); then ``q`` points the leg at the target.
    """

    q: jax.Array
    reachable: jax.Array


def leg_sign(side: Any) -> float:
    """+1.0 for the left leg, -1.0 for the right (a leg named "left"/"right" or +1/-1), on the host; a traced side
    flag reads through :func:`ijoy_jax.robots.side_sign`."""
    if isinstance(side, str):
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        return 1.0 if side == "left" else -1.0
    if side in (1, 1.0):
        return 1.0
    if side in (-1, -1.0):
        return -1.0
    raise ValueError(f"side must be 'left'/'right' or +1/-1, got {side!r}")


def _dtype(*xs) -> Any:
    return jnp.result_type(*xs, jnp.float32)


def rot_x(a: jax.Array) -> jax.Array:
    """(3, 3) rotation by ``a`` radians about x."""
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack([jnp.stack([o, z, z]), jnp.stack([z, c, -s]), jnp.stack([z, s, c])])


def rot_y(a: jax.Array) -> jax.Array:
    """(3, 3) rotation by ``a`` radians about y."""
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack([jnp.stack([c, z, s]), jnp.stack([z, o, z]), jnp.stack([-s, z, c])])


def rot_z(a: jax.Array) -> jax.Array:
    """(3, 3) rotation by ``a`` radians about z."""
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


def yaw_rot(theta: jax.Array) -> jax.Array:
    """(3, 3) rotation of a foot pose's yaw ``theta`` (radians); alias of :func:`rot_z`."""
    return rot_z(jnp.asarray(theta, _dtype(theta)))


def rpy_to_rot(rpy: jax.Array) -> jax.Array:
    """(3, 3) rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` of ``rpy = (roll, pitch, yaw)`` radians."""
    rpy = jnp.asarray(rpy, _dtype(rpy))
    return rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])


def quat_to_rot(quat: jax.Array) -> jax.Array:
    """(3, 3) rotation of a quaternion ``(w, x, y, z)`` (MuJoCo's order; normalised first)."""
    quat = jnp.asarray(quat, _dtype(quat))
    w, x, y, z = quat / jnp.linalg.norm(quat)
    return jnp.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _leg_dims(params) -> tuple[float, float, float, float]:
    return float(params.hip_offset_y), float(params.thigh), float(params.shank), float(params.ankle_height)


def _reach(params) -> tuple[float, float]:
    """Hip-ankle distance range (metres): the knee bent to its upper joint limit, and straight."""
    _, a, b, _ = _leg_dims(params)
    knee_max = min(float(params.range_hi[3]), math.pi)
    return math.sqrt(a * a + b * b + 2.0 * a * b * math.cos(knee_max)), a + b


def leg_fk(params, side: Any, q: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Pose of the sole centre frame in the pelvis frame.

    Args:
      params: :class:`ijoy_jax.sim.model.BipedParams` (static leg dimensions, metres).
      side: "left"/"right" or +1/-1 (static).
      q: (6,) joint angles in radians, order hip_yaw, hip_roll, hip_pitch, knee,
        ankle_pitch, ankle_roll.

    Returns:
      pos: (3,) sole centre in the pelvis frame, metres.
      rot: (3, 3) sole frame's axes (columns) in the pelvis frame.

    Example:
      >>> import jax.numpy as jnp
      >>> from ijoy_jax.sim import model, kinematics
      >>> pos, rot = kinematics.leg_fk(model.BipedParams(), "left", jnp.zeros(6))
      >>> [round(float(v), 3) for v in pos]
      [0.0, 0.06, -0.705]
    """
    s = leg_sign(side)
    hip_y, a, b, h = _leg_dims(params)
    q = jnp.asarray(q, _dtype(q))
    dt = q.dtype
    r_hip = rot_z(q[0]) @ rot_x(q[1]) @ rot_y(q[2])
    r_knee = r_hip @ rot_y(q[3])
    rot = r_knee @ rot_y(q[4]) @ rot_x(q[5])
    down = jnp.array([0.0, 0.0, -1.0], dt)
    pos = jnp.array([0.0, s * hip_y, 0.0], dt) + a * (r_hip @ down) + b * (r_knee @ down) + h * (rot @ down)
    return pos, rot


def _safe_sqrt(x: jax.Array) -> jax.Array:
    """sqrt(max(x, 0)) with a finite (zero) gradient at and below 0 (the double-where trick)."""
    ok = x > _STRAIGHT_EPS
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, x, 1.0)), 0.0)


def _safe_norm(v: jax.Array) -> jax.Array:
    """Euclidean norm with a finite gradient at 0."""
    return _safe_sqrt(jnp.sum(v * v))


def leg_ik(params, side: Any, pelvis_pos, pelvis_rot, sole_pos, sole_rot) -> LegIK:
    """Analytic inverse kinematics of one leg (Kajita's ``IK_leg``).

    The knee comes from the hip-ankle distance, the ankle roll and pitch from
    the hip seen in the foot frame, the hip yaw/roll/pitch from the remaining
    rotation ``Rz(yaw) Rx(roll) Ry(pitch)``. The solution branch is the
    walking one: knee in [0, pi], hip roll and ankle roll in (-pi/2, pi/2), and
    the hip above the ankle in the ankle-pitch frame. Out-of-reach targets
    (hip-ankle distance above ``thigh + shank``, or below the distance at the
    knee's upper joint limit ``params.range_hi[3]``) give the straightened (or
    fully bent) leg pointing at the target and ``reachable = False``; ``q``
    stays finite, and so do gradients (also at the straight knee, where
    ``acos`` is singular). Joint ranges other than the knee's upper limit are
    NOT enforced (clip ``q`` to :meth:`BipedParams.joint_range` if needed).

    Args:
      params: :class:`ijoy_jax.sim.model.BipedParams` (static leg dimensions, metres).
      side: "left"/"right" or +1/-1 (static).
      pelvis_pos: (3,) world position of the pelvis frame (the hips' height), metres.
      pelvis_rot: (3, 3) world orientation of the pelvis.
      sole_pos: (3,) world position of the sole centre, metres.
      sole_rot: (3, 3) world orientation of the sole (foot) frame.

    Returns:
      :class:`LegIK` ``(q (6,) radians, reachable () bool)``.

    Example:
      >>> import jax.numpy as jnp
      >>> from ijoy_jax.sim import model, kinematics as kin
      >>> p = model.BipedParams()
      >>> q = jnp.array([0.1, 0.05, -0.4, 0.8, -0.4, -0.05])
      >>> pos, rot = kin.leg_fk(p, "left", q)
      >>> q2, ok = kin.leg_ik(p, "left", jnp.zeros(3), jnp.eye(3), pos, rot)
      >>> bool(ok), bool(jnp.allclose(q, q2, atol=1e-4))
      (True, True)
    """
    s = leg_sign(side)
    hip_y, a, b, h = _leg_dims(params)
    dt = _dtype(pelvis_pos, pelvis_rot, sole_pos, sole_rot)
    pelvis_pos = jnp.asarray(pelvis_pos, dt)
    pelvis_rot = jnp.asarray(pelvis_rot, dt)
    sole_pos = jnp.asarray(sole_pos, dt)
    sole_rot = jnp.asarray(sole_rot, dt)

    hip = pelvis_pos + pelvis_rot @ jnp.array([0.0, s * hip_y, 0.0], dt)
    ankle = sole_pos + sole_rot @ jnp.array([0.0, 0.0, h], dt)
    r = sole_rot.T @ (hip - ankle)  # ankle -> hip, in the foot frame
    dist = _safe_norm(r)
    lo, hi = _reach(params)
    reachable = (dist <= hi + _REACH_TOL) & (dist >= lo - _REACH_TOL)

    # Knee: law of cosines on the distance clipped to the reach (straight leg beyond it, fully bent inside it).
    c_max = (lo * lo - a * a - b * b) / (2.0 * a * b)  # cos of the largest knee angle
    c = jnp.clip((dist * dist - a * a - b * b) / (2.0 * a * b), c_max, 1.0)
    knee = jnp.arctan2(_safe_sqrt(1.0 - c * c), c)  # acos(c), finite gradient at c = +-1

    # Ankle roll, then pitch: r = Rx(-roll) Ry(-pitch) (v_x, 0, v_z), v = thigh+shank in the shank frame.
    roll = jnp.arctan2(r[1], r[2])
    w_z = r[1] * jnp.sin(roll) + r[2] * jnp.cos(roll)
    alpha = jnp.arctan2(a * jnp.sin(knee), a * jnp.cos(knee) + b)
    pitch = -jnp.arctan2(r[0], w_z) - alpha

    # Hip: Rz(q0) Rx(q1) Ry(q2) = pelvis_rot^T sole_rot Rx(-roll) Ry(-(knee + pitch)).
    rh = pelvis_rot.T @ sole_rot @ rot_x(-roll) @ rot_y(-(knee + pitch))
    q0 = jnp.arctan2(-rh[0, 1], rh[1, 1])
    q1 = jnp.arctan2(rh[2, 1], -rh[0, 1] * jnp.sin(q0) + rh[1, 1] * jnp.cos(q0))
    q2 = jnp.arctan2(-rh[2, 0], rh[2, 2])
    q = jnp.stack([q0, q1, q2, knee, pitch, roll])
    return LegIK(q=q, reachable=reachable)
