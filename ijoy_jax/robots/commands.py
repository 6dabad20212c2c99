"""What drives a walk: the stance it starts from and the joystick commands the action set can realise.

A command ``j = (xdot, ydot, thetadot)`` (m/s, m/s, rad/s) asks for the step ``p_next = p0 + step_time * j``:
:func:`~ijoy_jax.robots.command_range` is the box of commands the action set spans,
:func:`~ijoy_jax.robots.random_commands` draws from it, and :func:`~ijoy_jax.robots.start_stance` places both
feet side by side to start from.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.prng import as_key
from ijoy_jax.robots.robot import Robot


def start_stance(robot: Robot, x, y, theta=0.0, *, width=None) -> jax.Array:
    """(2, 3) float32 world poses of the feet standing side by side: row 0 left, row 1 right (m, m, rad).

    Both feet face ``theta``; their midpoint is ``(x, y)`` and they stand
    ``width`` metres apart across that heading (default ``robot.p0[1]``, the
    step in place, so the first decision can step in place). Pure JAX: the
    arguments may be traced.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> np.asarray(ij.robots.start_stance(ij.robots.hrp2(), 0.3, 1.0), np.float64).round(3).tolist()
      [[0.3, 1.095, 0.0], [0.3, 0.905, 0.0]]
    """
    half = 0.5 * (robot.p0[1] if width is None else jnp.asarray(width, jnp.float32))
    x, y, theta = (jnp.asarray(v, jnp.float32) for v in (x, y, theta))
    dx, dy = -half * jnp.sin(theta), half * jnp.cos(theta)  # the half-width along the heading's left
    return jnp.stack([jnp.stack([x + dx, y + dy, theta]), jnp.stack([x - dx, y - dy, theta])])


def command_range(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (3,): the joystick commands (m/s, m/s, rad/s) the action set can realise.

    With p_next = p0 + dt j, the commands span the actions' extent around p0:
    xdot over [min dx - p0x, max dx - p0x] / dt, ydot over +-(max dy - p0y) / dt
    (the lateral room beyond the step in place, either way), thetadot over
    +-max ``|dtheta|`` / dt.
    """
    acts = np.asarray(robot.actions)
    p0, dt = np.asarray(robot.p0), float(robot.step_time)
    lo = np.array([acts[:, 0].min() - p0[0], -(acts[:, 1].max() - p0[1]), -np.abs(acts[:, 2]).max()]) / dt
    hi = np.array([acts[:, 0].max() - p0[0], acts[:, 1].max() - p0[1], np.abs(acts[:, 2]).max()]) / dt
    return lo, hi


def random_commands(key, robot: Robot, batch: int, num_steps: int, hold: int = 1) -> jax.Array:
    """(batch, num_steps, 3) joystick commands, uniform over :func:`command_range`.

    Each command is held for ``hold`` steps (1: a new one every step, the
    harshest joystick; ``num_steps``: one command per robot for the whole run).
    ``key``: PRNG key or int seed.
    """
    if hold < 1:
        raise ValueError(f"hold must be at least 1 step, got {hold}")
    lo, hi = command_range(robot)
    n = -(-num_steps // hold)
    u = jax.random.uniform(as_key(key), (batch, n, 3), jnp.float32)
    u = jnp.repeat(u, hold, axis=1)[:, :num_steps]
    return jnp.asarray(lo, jnp.float32) + u * jnp.asarray(hi - lo, jnp.float32)
