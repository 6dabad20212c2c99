"""World poses of the action set for a given stance foot."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ijoy_jax import geometry
from ijoy_jax.robots import Robot, side_actions


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
    swing_side = -jnp.where(jnp.asarray(stance_side) >= 0, 1.0, -1.0)
    return geometry.compose(stance, side_actions(robot, swing_side))
