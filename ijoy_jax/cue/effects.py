"""The cue force as force-feedback effects: what a device driver plays (a constant force, or a spring).

A cue force (:mod:`ijoy_jax.cue.forces`) is a fraction of the device's maximum on the stick's three axes;
a force-feedback joystick has two force axes and plays standard effects (:mod:`ijoy_jax.haptics.effects`).
:func:`device_effects` reduces the force onto the device's axes as the joystick's configuration says, and
gives it both as a constant force to refresh every tick and as a spring centred on the nearest feasible
command that keeps pulling between updates.

Units: newtons on the device's axes; metres of stick deflection.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.cue.feasible import MIN_UNIT, FeasibleCommands, check_command, check_feasible
from ijoy_jax.cue.forces import CueForce
from ijoy_jax.haptics import effects as fx
from ijoy_jax.struct import as_array, check_numeric, is_traced

DEFAULT_TRAVEL = 0.03
"""m: stick deflection at full scale for :func:`device_effects` (half of a consumer stick's ~6 cm travel)."""


class CueEffects(NamedTuple):
    """A cue force as the standard force-feedback effects of :mod:`ijoy_jax.haptics.effects`.

    Fields::

      constant: :class:`~ijoy_jax.haptics.ConstantEffect` playing ``planar`` (refresh it every tick).
      spring: :class:`~ijoy_jax.haptics.SpringEffect` centred on the nearest feasible command (forward
        and sideways axes), with the stiffness that plays the cue's planar force magnitude at the current
        stick position and that magnitude as its saturation: between two updates it keeps pulling the
        stick back towards the feasible command; zero stiffness and saturation where the command is open.
      planar: (2,) N, the cue force on the device's two force axes: ``force * max_force`` reduced by the
        configuration's projection or folding (the turn component is dropped or folded), saturated.
    """

    constant: fx.ConstantEffect
    spring: fx.SpringEffect
    planar: jax.Array


def device_effects(
    cue: CueForce, feasible: FeasibleCommands, command, config: fx.JoystickForceConfig, *, travel=DEFAULT_TRAVEL
) -> CueEffects:
    """Map a cue force onto the effects a force-feedback driver plays (constant force, or spring).

    The stick's deflection along the device's axes is ``config.axes @ (command / full_scale) * travel``
    (m); the force ``cue.force * config.max_force`` (N) reaches the device's two axes by the
    configuration's ``reduction`` (:func:`ijoy_jax.haptics.project` or :func:`ijoy_jax.haptics.fold`)
    and is saturated at ``config.max_force``, as :func:`ijoy_jax.haptics.joystick_forces` does with a
    kinematic force. Traceable.

    Args:
      cue: :func:`force_terms` at ``command``.
      feasible: the feasible set it came from (for the stick's full scale).
      command: (3,) the command the cue was evaluated at (m/s, m/s, rad/s).
      config: the joystick's :class:`~ijoy_jax.haptics.JoystickForceConfig` (max force, axes, reduction).
      travel: stick deflection at full scale (m, > 0).

    Returns:
      :class:`CueEffects`.

    Raises:
      TypeError, ValueError: arguments of the wrong type or shape, a concrete non-finite command, a travel
      that is not a finite scalar > 0 (traced values are not checked).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax import cue, haptics
      >>> free = np.ones((100, 100), bool); free[55:, :] = False
      >>> f = cue.feasible_commands(ij.terrain.from_arrays(None, free, 0.02), ij.robots.hrp2(), [0.8, 1.0, 0.0], -1)
      >>> out = cue.force_terms(f, [0.25, 0.0, 0.0])
      >>> e = cue.device_effects(out, f, [0.25, 0.0, 0.0], haptics.default_joystick_config())
      >>> round(float(e.constant.magnitude), 2), round(float(e.constant.direction), 2)  # N, rad: backwards
      (2.85, 3.14)
    """
    if not isinstance(cue, CueForce) or np.shape(cue.force) != (3,):
        raise TypeError(f"cue must be one command's ijoy_jax.cue.CueForce (force_terms), got {type(cue).__name__}")
    check_feasible(feasible)
    command = as_array("command", command)
    check_command(command)
    if not isinstance(config, fx.JoystickForceConfig):
        raise TypeError(f"config must be an ijoy_jax.haptics.JoystickForceConfig, got {type(config).__name__}")
    check_numeric("travel", travel)
    if np.shape(travel) != () or (not is_traced(travel) and not (np.isfinite(float(travel)) and float(travel) > 0)):
        raise ValueError(f"travel must be a finite scalar > 0 (m of stick deflection at full scale), got {travel!r}")
    config_max = jnp.asarray(config.max_force, jnp.float32)
    max_force = jnp.where(config_max >= 0, config_max, 0.0)
    f3 = cue.force * max_force
    if config.reduction == "project":
        planar = fx.project(f3, config.axes)
    else:
        planar = fx.fold(f3, config.axes, config.fold_direction)
    planar = fx.saturate(planar, max_force)
    command = jnp.asarray(command, jnp.float32)
    command = jnp.where(jnp.isfinite(command), command, 0.0)
    per_unit = jnp.asarray(travel, jnp.float32) / jnp.maximum(feasible.full_scale, MIN_UNIT)
    stick = config.axes @ (jnp.clip(command, feasible.lo, feasible.hi) * per_unit)
    centre = config.axes @ (cue.nearest * per_unit)
    gap_sq = jnp.sum((stick - centre) ** 2)
    mag_sq = jnp.sum(planar * planar)
    pos = (gap_sq > 0) & (mag_sq > 0)
    stiffness = jnp.where(pos, jnp.sqrt(jnp.where(pos, mag_sq, 1.0) / jnp.where(pos, gap_sq, 1.0)), 0.0)
    spring = fx.spring(stiffness, jnp.minimum(cue.magnitude, 1.0) * max_force, 0.0, centre)
    return CueEffects(constant=fx.constant(planar), spring=spring, planar=planar)
