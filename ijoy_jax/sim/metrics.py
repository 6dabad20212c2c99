"""Per-rollout totals of a simulated walk: falls, obstacle contacts and touch-down errors beside progress.

:func:`summary` condenses a :class:`ijoy_jax.control.Trajectory` of
:func:`ijoy_jax.sim.walker.rollout` (its ``log`` a :class:`~ijoy_jax.sim.walker.StepLog`
per step) into the figures a sweep or a table reports, on top of the
trajectory's own summary.

Implementation module of :mod:`ijoy_jax.sim.walker`, which exports :func:`summary`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ijoy_jax import control
from ijoy_jax.sim.walk_step import StepLog


def summary(traj: control.Trajectory) -> dict[str, jax.Array]:
    """Per-rollout totals of a simulated rollout, on top of ``traj.summary()``.

    fell: the robot fell; obstacle_contacts: steps during which a foot (or
    shin) touched an obstacle cell; collided: any did (bool); placement_error_mean / _p95 (m): the
    touch-down error of the steps taken; yaw_error_mean (rad); tilt_error_p95 (rad): the angle between a
    landed sole's normal and the commanded foothold's; dynamics_invalid: a
    :class:`~ijoy_jax.sim.physics.Dynamics` value was out of bounds and simulated as its nominal one.
    """
    log: StepLog = traj.log
    taken = traj.taken
    n = jnp.maximum(jnp.sum(taken, axis=-1), 1)
    err = jnp.where(taken, log.placement_error, jnp.nan)
    out = dict(traj.summary())
    out.update(
        fell=jnp.any(log.fallen, axis=-1),
        obstacle_contacts=jnp.sum(log.obstacle_contact, axis=-1, dtype=jnp.int32),
        collided=jnp.any(log.obstacle_contact, axis=-1),
        placement_error_mean=jnp.sum(jnp.where(taken, log.placement_error, 0.0), axis=-1) / n,
        placement_error_p95=jnp.where(jnp.any(taken, axis=-1), jnp.nanpercentile(err, 95, axis=-1), 0.0),
        yaw_error_mean=jnp.sum(jnp.where(taken, log.yaw_error, 0.0), axis=-1) / n,
        tilt_error_p95=jnp.where(
            jnp.any(taken, axis=-1), jnp.nanpercentile(jnp.where(taken, log.tilt_error, jnp.nan), 95, axis=-1), 0.0
        ),
        dynamics_invalid=jnp.any(log.dynamics_invalid, axis=-1),
    )
    return out
