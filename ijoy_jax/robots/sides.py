"""Left and right: the side flags, the LEFT foot's actions mirrored onto either swing foot, and the paper's dist.

``Robot.actions`` and ``Robot.p0`` are the LEFT swing foot's; the right foot's are their mirror
``(dx, -dy, -dtheta)`` (:func:`~ijoy_jax.robots.mirror`). From them: the world step of each action from a stance
(:func:`~ijoy_jax.robots.action_steps`), and the action nearest a world step by the paper's dist
(:func:`~ijoy_jax.robots.dist`, :func:`~ijoy_jax.robots.nearest_actions`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ijoy_jax import geometry
from ijoy_jax.robots.robot import Robot

LEFT = 1
RIGHT = -1


def side_sign(side) -> jax.Array:
    """() float32 +1 for a side >= 0 (left), -1 otherwise (right): the one reading of a side flag."""
    return jnp.where(jnp.asarray(side) >= 0, 1.0, -1.0).astype(jnp.float32)


def mirror(swing_side, rel) -> jax.Array:
    """(..., 3) a left-foot pose or action ``(dx, dy, dtheta)`` as seen by the foot on ``swing_side``.

    Left (+1): unchanged; right (-1): ``(dx, -dy, -dtheta)``. Its own inverse.
    """
    sign = jnp.asarray(swing_side, jnp.float32)
    return rel * jnp.stack([jnp.ones_like(sign), sign, sign])


def side_actions(robot: Robot, swing_side) -> jax.Array:
    """(N, 3) actions of the swing foot on ``swing_side`` (+1 left, -1 right).

    Left: ``robot.actions``; right: their mirror (dx, -dy, -dtheta).
    """
    return mirror(swing_side, robot.actions)


def side_p0(robot: Robot, swing_side) -> jax.Array:
    """(3,) step-in-place action for the swing foot on ``swing_side`` (+1 left, -1 right)."""
    return mirror(swing_side, robot.p0)


def action_steps(robot: Robot, stance, stance_side) -> jax.Array:
    """(N, 3) world poses of the swing foot for every action of S.

    Args:
      robot: the robot model (N = robot.num_actions).
      stance: (3,) world pose of the stance foot (m, rad).
      stance_side: +1 for a left stance foot (the right foot swings, with the
        mirrored actions), -1 for a right stance foot.

    Example:
      >>> import ijoy_jax as ij
      >>> ij.action_steps(ij.robots.hrp2(), [0.0, 0.0, 0.0], -1).shape
      (496, 3)
    """
    stance = jnp.asarray(stance, jnp.float32)
    return geometry.compose(stance, side_actions(robot, -side_sign(stance_side)))


def dist(a: jax.Array, b: jax.Array, rotation_weight, *, grad_safe: bool = False) -> jax.Array:
    """The paper's dist between poses in one frame: ``|dxy| + rotation_weight * |wrap(dtheta)|``.

    Args:
      a, b: (..., 3) poses (x, y, theta) in one frame (m, rad); broadcast.
      rotation_weight: cost units per radian (``Robot.rotation_weight``).
      grad_safe: static. False (the exact selector): ``|dxy|`` by ``jnp.hypot``.
        True (what is differentiated, :mod:`ijoy_jax.tune`): by
        :func:`ijoy_jax.geometry.safe_norm`, whose gradient at dxy = 0 is 0, not NaN.

    Returns:
      (...) float32 distances (cost units before ``w``).

    Example:
      >>> import jax.numpy as jnp
      >>> from ijoy_jax.robots import dist
      >>> round(float(dist(jnp.array([0.3, 0.4, 0.1]), jnp.zeros(3), 2.0)), 6)
      0.7
    """
    d = a - b
    norm = geometry.safe_norm if grad_safe else jnp.hypot
    return norm(d[..., 0], d[..., 1]) + rotation_weight * jnp.abs(geometry.wrap_angle(d[..., 2]))


def nearest_actions(robot: Robot, stance, stance_side, steps) -> jax.Array:
    """(N,) int32 index of the action of S nearest each world step (:func:`dist` in the stance frame).

    Args:
      robot: the robot model.
      stance: (3,) world pose of the stance foot; stance_side: +1 left, -1 right.
      steps: (N, 3) world poses of the swing foot.
    """
    stance, steps = jnp.asarray(stance, jnp.float32), jnp.asarray(steps, jnp.float32)
    rel = geometry.relative(stance, steps)  # (N, 3)
    acts = side_actions(robot, -side_sign(stance_side))
    return jnp.argmin(dist(rel[:, None, :], acts[None, :, :], robot.rotation_weight), axis=1).astype(jnp.int32)
