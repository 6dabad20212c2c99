"""What a described biped's legs reach in double support: the derivation of a selector robot's limits.

A selector robot (:class:`ijoy_jax.robots.Robot`) carries an action set and the sole tilts and sole distance its
FootCost accepts. For a robot read from its MJCF (:class:`~ijoy_jax.sim.description.BipedDescription`) these
come from its legs: a stance is realisable when both legs' inverse kinematics
(:func:`~ijoy_jax.sim.description.leg_ik`) put the soles where the step puts them, with every joint at least
:data:`LIMIT_MARGIN` inside its range, in the double-support posture the walking controller holds (pelvis level,
midway between the feet, yawed to their mean heading, ``height`` above the soles).

:func:`feasible` answers that for a batch of actions (the swing foot's displacement from the stance foot, the
selector's convention: LEFT swing foot from a RIGHT stance foot); :func:`realisable_tilt` finds the largest sole
pitch or roll realisable in every stance of an action set; :func:`radial_reach` the farthest sole distance along
a direction. Pure JAX inside (jit, vmap); the searches run on the host.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.sim import kinematics
from ijoy_jax.sim.description import BipedDescription, leg_ik

__all__ = ["LIMIT_MARGIN", "feasible", "radial_reach", "realisable_tilt"]

LIMIT_MARGIN = 0.02
"""rad: a realisable stance keeps every leg joint this far inside its range (room for the balance control)."""

_POS_TOL, _ROT_TOL = 1e-4, 1e-3  # m, rad: the IK reached the sole pose
_IK_ITERATIONS = 24


def _stance_ok(legs, stand_q, action, height, tilt) -> jax.Array:
    """Both legs realise the LEFT sole at ``action`` (dx, dy, dtheta) from a RIGHT sole at the origin, the left
    sole tilted by ``tilt`` (roll, pitch; rad), the pelvis level at ``height`` above the soles."""
    dt = jnp.float32
    feet = jnp.stack([action, jnp.zeros(3, dt)])
    mid, yaw = 0.5 * action[:2], 0.5 * action[2]
    pelvis_rot = kinematics.rot_z(yaw)
    ok = jnp.array(True)
    for row, sole_tilt in ((0, tilt), (1, jnp.zeros(2, dt))):
        chain = legs[row]
        pos = pelvis_rot.T @ jnp.concatenate([feet[row, :2] - mid, -height[None]])
        rot = pelvis_rot.T @ kinematics.rpy_to_rot(jnp.stack([sole_tilt[0], sole_tilt[1], feet[row, 2]]))
        sol = leg_ik(chain, pos, rot, stand_q[row], iterations=_IK_ITERATIONS)
        inside = jnp.all((sol.q >= chain.lower + LIMIT_MARGIN) & (sol.q <= chain.upper - LIMIT_MARGIN))
        ok &= (sol.position_error < _POS_TOL) & (sol.rotation_error < _ROT_TOL) & inside
    return ok


_stances_ok = jax.jit(jax.vmap(_stance_ok, in_axes=(None, None, 0, None, 0)))


def feasible(desc: BipedDescription, actions, height: float, tilt=(0.0, 0.0)) -> np.ndarray:
    """(N,) bool: whether each stance is realisable (see the module docstring).

    Args:
      desc: the biped.
      actions: (N, 3) LEFT swing-foot displacements (dx, dy, dtheta; m, rad) from a RIGHT stance foot.
      height: the pelvis (the description's root) above the soles, m.
      tilt: (2,) or (N, 2) roll and pitch of the swing sole, rad.
    """
    actions = np.asarray(actions, np.float32).reshape(-1, 3)
    tilt = np.broadcast_to(np.asarray(tilt, np.float32), (len(actions), 2))
    legs = tuple(type(c)(*(np.asarray(x, np.float32) for x in c)) for c in desc.legs)
    return np.asarray(_stances_ok(legs, np.asarray(desc.stand_leg_q, np.float32), actions, np.float32(height), tilt))


def realisable_tilt(desc: BipedDescription, actions, height: float, axis: str, *, upper: float = 1.0,
                    tol: float = math.radians(0.25)) -> float:
    """The largest tilt (rad) of the swing sole about ``axis`` ("roll" or "pitch"), both ways, realisable in
    every stance of ``actions`` (bisection to ``tol``; 0.0 when even the level sole is not)."""
    if axis not in ("roll", "pitch"):
        raise ValueError(f"axis must be 'roll' or 'pitch', got {axis!r}")
    k = 0 if axis == "roll" else 1
    actions = np.asarray(actions, np.float32).reshape(-1, 3)
    both = np.concatenate([actions, actions])
    sign = np.repeat([1.0, -1.0], len(actions))

    def every(t: float) -> bool:
        tilt = np.zeros((len(both), 2), np.float32)
        tilt[:, k] = sign * t
        return bool(feasible(desc, both, height, tilt).all())

    if not every(0.0):
        return 0.0
    lo, hi = 0.0, float(upper)
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if every(mid) else (lo, mid)
    return lo


def radial_reach(desc: BipedDescription, height: float, direction: float, *, start: float = 0.2,
                 upper: float = 1.0, step: float = 0.01) -> float:
    """The farthest distance (m) of the LEFT sole from the RIGHT, along ``direction`` (rad from the stance foot's
    x axis; pi/2 is straight to the left), up to which every stance from ``start`` on is realisable (level soles,
    no turn), on a grid of ``step``."""
    rs = np.arange(start, upper + step / 2, step)
    acts = np.stack([rs * math.cos(direction), rs * math.sin(direction), np.zeros_like(rs)], axis=1)
    ok = feasible(desc, acts, height)
    if not ok[0]:
        return 0.0
    bad = np.flatnonzero(~ok)
    return float(rs[bad[0] - 1] if len(bad) else rs[-1])
