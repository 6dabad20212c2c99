"""Joystick forces (paper section 2.2) as standard force-feedback effects.

Two kinds of force reach the operator's hand (the paper's Fig. 4):

* device-originating, depending only on the joystick deflection: auto-centring
  (back to the centre) and straight-ahead (back onto the forward axis), each
  linear in the deflection or constant in magnitude;
* kinematics-originating: the robot's state, e.g. the non-linear repulsive force
  of the linearised workspace, reduced from 3D to the joystick's two force axes
  by projection or folding.

They add (near the centre the linear device force dominates, near a workspace
limit the non-linear one does) and the sum saturates at the device's maximum
force. Every term maps one-to-one onto a standard effect a driver can play
(DirectInput / USB HID PID / Linux ``ff_effect``):

* :class:`SpringEffect` = a spring *condition*: per axis a centre (offset),
  positive/negative coefficients, positive/negative saturations and a dead band.
  A linear term is a spring; a constant-magnitude term is a spring whose
  coefficient is steep enough to reach its saturation within ``ramp`` (a
  constant force that flips sign at the centre would chatter).
* :class:`ConstantEffect` = a constant force: magnitude and direction, refreshed
  every control tick with the kinematic force.

Joystick axes: x = forward deflection, y = left deflection (metres of stick
travel, or any deflection unit used consistently with the coefficients);
forces in newtons along the same axes.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.struct import pytree_dataclass, static_field


@pytree_dataclass
class SpringEffect:
    """A spring condition on the joystick's two axes (each field (2,), per axis x, y).

    Attributes:
      center: deflection at the centre of the dead band (m).
      positive_coefficient: stiffness for deflections above the dead band (N/m).
      negative_coefficient: stiffness below it (N/m).
      positive_saturation: largest force magnitude on the positive side (N, >= 0).
      negative_saturation: same on the negative side (N, >= 0).
      deadband: half-width of the dead band around ``center`` (m, >= 0).
    """

    center: jax.Array
    positive_coefficient: jax.Array
    negative_coefficient: jax.Array
    positive_saturation: jax.Array
    negative_saturation: jax.Array
    deadband: jax.Array


@pytree_dataclass
class ConstantEffect:
    """A constant force: ``magnitude * (cos direction, sin direction)`` in joystick axes.

    Attributes:
      magnitude: () N, >= 0.
      direction: () rad, angle of the force from the joystick's x (forward) axis
        towards y (left).
    """

    magnitude: jax.Array
    direction: jax.Array


def spring_force(effect: SpringEffect, position) -> jax.Array:
    """Force (2,) (N) a device plays for a spring condition at deflection ``position`` (2,) (m).

    Per axis, with ``s = position - center``: 0 inside the dead band,
    ``-clip(k+ (s - deadband), -sat+, sat+)`` above it and
    ``-clip(k- (s + deadband), -sat-, sat-)`` below it (restoring for k > 0).

    Example:
      >>> e = spring(coefficient=10.0, saturation=1.0)
      >>> spring_force(e, jnp.array([0.05, 0.3])).tolist()  # y saturates at 1 N
      [-0.5, -1.0]
    """
    s = jnp.asarray(position) - effect.center
    above = s - effect.deadband
    below = s + effect.deadband
    f_pos = -jnp.clip(effect.positive_coefficient * above, -effect.positive_saturation, effect.positive_saturation)
    f_neg = -jnp.clip(effect.negative_coefficient * below, -effect.negative_saturation, effect.negative_saturation)
    return jnp.where(above > 0, f_pos, jnp.where(below < 0, f_neg, 0.0))


def constant_force(effect: ConstantEffect) -> jax.Array:
    """Force (2,) (N) of a constant effect."""
    return effect.magnitude * jnp.stack([jnp.cos(effect.direction), jnp.sin(effect.direction)])


def spring(coefficient, saturation, deadband=0.0, center=0.0) -> SpringEffect:
    """A symmetric spring: ``coefficient`` (2,) N/m, ``saturation`` (2,) N, dead band (m), centre (m)."""
    k = jnp.broadcast_to(jnp.asarray(coefficient, jnp.result_type(float)), (2,))
    return SpringEffect(
        center=jnp.broadcast_to(jnp.asarray(center, k.dtype), (2,)),
        positive_coefficient=k,
        negative_coefficient=k,
        positive_saturation=jnp.broadcast_to(jnp.asarray(saturation, k.dtype), (2,)),
        negative_saturation=jnp.broadcast_to(jnp.asarray(saturation, k.dtype), (2,)),
        deadband=jnp.broadcast_to(jnp.asarray(deadband, k.dtype), (2,)),
    )


def _safe_norm(v):
    sq = jnp.sum(v * v, axis=-1)
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def constant(force) -> ConstantEffect:
    """The constant effect that plays the force (2,) (N); direction 0 for a zero force."""
    f = jnp.asarray(force)
    mag = _safe_norm(f)
    nz = mag > 0
    direction = jnp.arctan2(jnp.where(nz, f[1], 0.0), jnp.where(nz, f[0], 1.0))
    return ConstantEffect(magnitude=mag, direction=direction)


def saturate(force, max_force) -> jax.Array:
    """Scale ``force`` (2,) down to magnitude ``max_force`` (N) if larger, keeping its direction."""
    mag = _safe_norm(force)
    return force * jnp.where(mag > max_force, max_force / jnp.where(mag > 0, mag, 1.0), 1.0)


def project(force3, axes) -> jax.Array:
    """3D-to-2D reduction by projection: ``axes @ force3``.

    Args:
      force3: (3,) force in the robot frame (N).
      axes: (2, 3) unit robot-frame directions of the joystick's x and y force axes.
    """
    return jnp.asarray(axes) @ force3


def fold(force3, axes, fold_direction) -> jax.Array:
    """3D-to-2D reduction by folding: the component normal to the axes' plane is hinged into it.

    ``axes @ f + (nrm . f) * fold_direction``, with ``nrm = axes[0] x axes[1]``: a
    rotation of the normal onto the unit joystick direction ``fold_direction`` (2,).
    Nothing is lost for a force normal to the plane (projection would drop it):
    e.g. with the default axes, a downward force on a leg becomes a push along
    ``-fold_direction``.

    Example:
      >>> fold(jnp.array([0.0, 0.0, -2.0]), jnp.eye(3)[:2], jnp.array([1.0, 0.0]))
      Array([-2.,  0.], dtype=float32)
    """
    axes = jnp.asarray(axes)
    nrm = jnp.cross(axes[0], axes[1])
    return axes @ force3 + (nrm @ force3) * jnp.asarray(fold_direction)


@pytree_dataclass
class JoystickForceConfig:
    """Joystick force settings (numbers are traced leaves; the reduction mode is static).

    Tuning any number reuses the compiled :func:`joystick_forces` as long as the
    leaves keep their dtype (build them with ``jnp.float32(...)`` or the helpers
    below, not weakly-typed ``jnp.asarray(python_float)``).

    Attributes:
      centring: SpringEffect pulling the stick back to its centre.
      straight_ahead: SpringEffect pulling the stick back onto the forward axis
        (coefficients zero on x).
      max_force: () device's maximum force (N); the sum saturates here.
      axes: (2, 3) robot-frame directions of the joystick's force axes.
      fold_direction: (2,) unit joystick direction the out-of-plane force folds onto.
      reduction: "project" or "fold" (static).
    """

    centring: SpringEffect
    straight_ahead: SpringEffect
    max_force: jax.Array
    axes: jax.Array
    fold_direction: jax.Array
    reduction: str = static_field(default="project")


def linear_centring(stiffness, max_force, deadband=0.0) -> SpringEffect:
    """Auto-centring linear in the deflection: ``-stiffness * s`` (N/m), up to ``max_force`` (N)."""
    return spring(stiffness, max_force, deadband)


def constant_centring(force, ramp, deadband=0.0) -> SpringEffect:
    """Auto-centring of constant magnitude ``force`` (N) beyond a ramp of ``ramp`` (m) around the centre."""
    return spring(jnp.asarray(force) / jnp.asarray(ramp), force, deadband)


def straight_ahead(stiffness, max_force, deadband=0.0) -> SpringEffect:
    """Straight-ahead: a spring on the lateral (y) axis only, ``-stiffness * y`` (N/m) up to ``max_force`` (N).

    For a constant-magnitude version use ``straight_ahead(force / ramp, force)``, as in
    :func:`constant_centring`.
    """
    k = jnp.asarray(stiffness, jnp.result_type(float))
    return spring(jnp.stack([jnp.zeros_like(k), k]), max_force, deadband)


def default_config(reduction: str = "project") -> JoystickForceConfig:
    """A fresh default configuration (a consumer joystick: ~5 N peak, ~6 cm stick travel).

    Linear centring 40 N/m (2 N at 5 cm) with a 2 mm dead band, straight-ahead
    60 N/m up to 2 N, device limit 5 N, joystick x/y along robot x/y, folding
    the vertical onto forward (+z pushes forward).
    """
    if reduction not in ("project", "fold"):
        raise ValueError(f"reduction must be 'project' or 'fold', got {reduction!r}")
    f32 = jnp.result_type(float)
    return JoystickForceConfig(
        centring=linear_centring(40.0, 2.0, 0.002),
        straight_ahead=straight_ahead(60.0, 2.0),
        max_force=jnp.asarray(5.0, f32),
        axes=jnp.eye(3, dtype=f32)[:2],
        fold_direction=jnp.array([1.0, 0.0], f32),
        reduction=reduction,
    )


class JoystickForces(NamedTuple):
    """The joystick's force terms and what to send to the device.

    Fields (forces (2,) in N along the joystick axes)::

      centring, straight_ahead: the device-originating terms.
      kinematic: the reduced kinematics-originating term.
      total: their sum, saturated at ``max_force``.
      saturated: () bool, True if the sum exceeded ``max_force``.
      kinematic_effect: ConstantEffect playing ``kinematic`` (limited to ``max_force``).
      nonfinite_input: () bool, True if a deflection or kinematic-force entry was
        not finite (that entry counted as 0: the stick at its centre, no force).
      bad_max_force: () bool, True if ``max_force`` was NaN or negative: then ``total``
        and ``kinematic_effect`` are zero (a negative limit would flip the force's
        direction; ``+inf`` is allowed and means no limit).
    """

    centring: jax.Array
    straight_ahead: jax.Array
    kinematic: jax.Array
    total: jax.Array
    saturated: jax.Array
    kinematic_effect: ConstantEffect
    nonfinite_input: jax.Array
    bad_max_force: jax.Array


@jax.jit
def joystick_forces(config: JoystickForceConfig, position, kinematic_force3) -> JoystickForces:
    """Blend device- and kinematics-originating forces (Fig. 4) and saturate.

    Args:
      config: JoystickForceConfig.
      position: (2,) joystick deflection (m).
      kinematic_force3: (3,) robot-frame force, e.g. a repulsive force (N);
        non-finite entries count as 0.

    Returns:
      JoystickForces (terms, saturated total, and the constant effect to play).
      Always finite: non-finite inputs count as 0 (``nonfinite_input``), and a
      ``max_force`` that is NaN or negative sends no force (``bad_max_force``).

    Example:
      >>> cfg = default_config()
      >>> out = joystick_forces(cfg, jnp.array([0.03, 0.01]), jnp.array([0.0, 0.0, -1.0]))
      >>> [round(v, 2) for v in out.total.tolist()]  # projection drops the vertical force
      [-1.12, -0.92]
    """
    f3 = jnp.asarray(kinematic_force3)
    position = jnp.asarray(position)
    nonfinite = ~jnp.all(jnp.isfinite(f3)) | ~jnp.all(jnp.isfinite(position))
    f3 = jnp.where(jnp.isfinite(f3), f3, 0.0)
    # A force beyond finfo.max ** (1/4) (1.4e9 N in float32) keeps its direction but is scaled down to that
    # size, so the reduction and the norms below cannot overflow; any device saturates far below it.
    cap = float(jnp.finfo(f3.dtype).max) ** 0.25 if jnp.issubdtype(f3.dtype, jnp.floating) else jnp.inf
    big = jnp.max(jnp.abs(f3))
    f3 = f3 * jnp.where(big > cap, cap / jnp.where(big > cap, big, 1.0), 1.0)
    position = jnp.where(jnp.isfinite(position), position, config.centring.center)
    max_force = jnp.asarray(config.max_force)
    bad_max = ~(max_force >= 0)  # NaN or negative
    max_force = jnp.where(bad_max, 0.0, max_force)
    if config.reduction == "project":
        kin = project(f3, config.axes)
    else:
        kin = fold(f3, config.axes, config.fold_direction)
    centring = spring_force(config.centring, position)
    ahead = spring_force(config.straight_ahead, position)
    raw = centring + ahead + kin
    total = saturate(raw, max_force)
    return JoystickForces(
        centring=centring,
        straight_ahead=ahead,
        kinematic=kin,
        total=total,
        saturated=_safe_norm(raw) > max_force,
        kinematic_effect=constant(saturate(kin, max_force)),
        nonfinite_input=nonfinite,
        bad_max_force=bad_max,
    )


# ---------------------------------------------------------------------------
# Host-side conversion to Linux force-feedback structures (struct ff_effect).

FF_CONSTANT = 0x52
FF_SPRING = 0x53


def _s16(x):
    return int(np.clip(np.round(x), -0x7FFF, 0x7FFF))


def _u16(x):
    return int(np.clip(np.round(x), 0, 0xFFFF))


def linux_spring(effect: SpringEffect, max_force: float, max_deflection: float) -> dict:
    """A spring condition as Linux ``struct ff_effect`` fields (type FF_SPRING), a plain dict.

    ``u.condition[0]`` is the device's X axis, ``[1]`` its Y axis. Scaling (drivers
    map these linearly onto their own ranges): positions and the dead band are
    fractions of ``max_deflection`` (m) times 0x7FFF; saturations are fractions of
    ``max_force`` (N) times 0xFFFF; coefficients are ``k * max_deflection / max_force``
    times 0x7FFF (full-scale force at full deflection = 0x7FFF).

    Joystick (x forward, y left) to evdev (X right, Y towards the operator):
    ``X = -y``, ``Y = -x``; the two sides of each axis swap accordingly.
    """
    e = jax.tree_util.tree_map(np.asarray, effect)
    conds = []
    # evdev X = -joystick y, evdev Y = -joystick x: an axis flip swaps the positive/negative sides.
    for ax in (1, 0):
        conds.append(
            {
                "right_saturation": _u16(e.negative_saturation[ax] / max_force * 0xFFFF),
                "left_saturation": _u16(e.positive_saturation[ax] / max_force * 0xFFFF),
                "right_coeff": _s16(e.negative_coefficient[ax] * max_deflection / max_force * 0x7FFF),
                "left_coeff": _s16(e.positive_coefficient[ax] * max_deflection / max_force * 0x7FFF),
                "deadband": _u16(e.deadband[ax] / max_deflection * 0x7FFF),
                "center": _s16(-e.center[ax] / max_deflection * 0x7FFF),
            }
        )
    return {"type": FF_SPRING, "direction": 0, "u": {"condition": conds}}


def linux_constant(effect: ConstantEffect, max_force: float) -> dict:
    """A constant force as Linux ``struct ff_effect`` fields (type FF_CONSTANT), a plain dict.

    ``level`` is the magnitude as a fraction of ``max_force`` (N) times 0x7FFF. The
    direction follows the kernel's ff-memless convention: a constant effect of
    direction ``theta = 2 pi direction / 0x10000`` pushes along evdev
    ``(X, Y) = (sin theta, -cos theta)`` (0x0000 "down", 0x4000 "left" in
    linux/input.h). With evdev ``X = -y``, ``Y = -x`` that is joystick
    ``(x, y) = (cos theta, -sin theta)``, so ``theta = -direction``.
    """
    mag = float(np.asarray(effect.magnitude))
    theta = (-float(np.asarray(effect.direction))) % (2 * np.pi)
    return {
        "type": FF_CONSTANT,
        "direction": int(round(theta / (2 * np.pi) * 0x10000)) % 0x10000,
        "u": {"constant": {"level": _s16(min(mag / max_force, 1.0) * 0x7FFF)}},
    }
