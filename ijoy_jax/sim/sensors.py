"""What the simulated robot measures: its soles, its ankles' force/torque sensors and its centre of mass.

Each reader takes the MJX data of a :class:`~ijoy_jax.sim.walker.Sim`'s robot.
The physics steps of a control tick skip MuJoCo's sensor stage
(:func:`without_sensors`) and :func:`read_sensors` evaluates it once after the
last of them, from the state that step started at (:func:`step_start`), as
``mjx.step`` would have.

Implementation module of :mod:`ijoy_jax.sim.walker`, which exports its public names.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from ijoy_jax.sim.simulator import Sim


def measured_soles(sim: Sim, d: mjx.Data) -> jax.Array:
    """(2, 6) the measured soles x, y, z, roll, pitch, yaw (``R = Rz(yaw) Ry(pitch) Rx(roll)``), row 0 left."""
    pos = d.site_xpos[sim.index.sole_site]  # (2, 3)
    mat = d.site_xmat[sim.index.sole_site].reshape(2, 3, 3)
    yaw = jnp.arctan2(mat[:, 1, 0], mat[:, 0, 0])
    pitch = jnp.arctan2(-mat[:, 2, 0], jnp.hypot(mat[:, 2, 1], mat[:, 2, 2]))
    roll = jnp.arctan2(mat[:, 2, 1], mat[:, 2, 2])
    return jnp.concatenate([pos, roll[:, None], pitch[:, None], yaw[:, None]], axis=1)


def ankle_wrench(sim: Sim, d: mjx.Data) -> jax.Array:
    """(2, 6) the ankles' force/torque sensors (``d.sensordata``): force then torque that the shank exerts on the
    foot, in the foot frame at the ankle point (N, N m), row 0 left."""
    adr = np.asarray(sim.index.ankle_sensor)[:, :, None] + np.arange(3)
    return d.sensordata[adr].reshape(2, 6)


def centre_of_mass(sim: Sim, d: mjx.Data) -> tuple[jax.Array, jax.Array]:
    """The whole robot's centre of mass (3,) and its velocity (3,) (world frame; m, m/s), from the model's
    ``com`` and ``com_vel`` sensors (``d.sensordata``)."""
    adr = np.asarray(sim.index.com_sensor)[:, None] + np.arange(3)
    return d.sensordata[adr[0]], d.sensordata[adr[1]]


def without_sensors(m: mjx.Model) -> mjx.Model:
    """``m`` with MuJoCo's sensor stage disabled (``opt.disableflags``, a static field): a physics step that
    computes no ``sensordata`` and moves the robot exactly as ``m`` does."""
    return m.replace(opt=m.opt.replace(disableflags=m.opt.disableflags | mjx.DisableBit.SENSOR))


def step_start(d: mjx.Data) -> tuple[jax.Array, ...]:
    """The state a physics step integrates: ``(qpos, qvel, act, time)`` of ``d`` (for :func:`read_sensors`)."""
    return d.qpos, d.qvel, d.act, d.time


def read_sensors(m: mjx.Model, d: mjx.Data, start: tuple[jax.Array, ...]) -> mjx.Data:
    """``d`` with ``sensordata`` as ``mjx.step(m, .)`` would have filled it in the step that produced ``d``.

    MuJoCo computes sensors in ``forward``, at the state the step starts from (``start``, its
    :func:`step_start`), then integrates ``qpos``, ``qvel``, ``act`` and ``time``. Every other field the
    sensors read (poses, ``cvel``, ``qacc``, the contacts and their forces) is still the step's own, so the
    sensors are evaluated on ``d`` with the start state put back, and ``d`` keeps its integrated state. The
    physics steps of a control tick run :func:`without_sensors` and this once after the last of them
    (:func:`tick`): the ankles' force/torque sensors cost a second Newton-Euler pass.
    """
    qpos, qvel, act, time = start
    sensed = mjx.sensor_acc(
        m, mjx.sensor_vel(m, mjx.sensor_pos(m, d.replace(qpos=qpos, qvel=qvel, act=act, time=time)))
    )
    return sensed.replace(qpos=d.qpos, qvel=d.qvel, act=d.act, time=d.time)
