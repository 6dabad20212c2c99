"""The robots the walker drives, behind one interface: the project's biped and the Unitree G1.

``BipedParams.model`` names the robot (:data:`MODELS`): ``"biped"``, the project's HRP-2-like biped built from
the params' own geometry (:mod:`.model`, with Kajita's analytic leg inverse kinematics, :mod:`.kinematics`), or
``"g1"``, MuJoCo Menagerie's Unitree G1 (:mod:`.g1`, its legs solved by damped least squares on the chains read
from its MJCF, :mod:`.description`). Both have their 12 leg joints first in ``qpos[7:]`` (left leg, then right;
hip three, knee, ankle pitch, ankle roll last) and one position actuator per joint in that order, so
``ctrl = qpos[7:]`` and ``nq = 19`` for both (the G1's waist and arms are welded at their standing angles,
:mod:`.g1`).

What the walker asks of a robot, here: its model on a terrain (:func:`build_model`), the legs' inverse
kinematics (:func:`legs_ik`), the standing configuration over given soles (:func:`stand_pose`), its foot below
the ankle sensor (:func:`foot`) and how it walks by default (:func:`walk_defaults`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from ijoy_jax.sim import hfield, kinematics, model

__all__ = ["MODELS", "build_model", "build_spec", "foot", "legs_ik", "stand_pose", "walk_defaults"]

MODELS = model.MODELS
"""The robots the walker drives: ``"biped"`` (the project's) and ``"g1"`` (the Unitree G1)."""

_IK_POS_TOL, _IK_ROT_TOL = 1e-3, 1e-2
"""m, rad: a damped least-squares solution this close to its target counts as reached (:func:`legs_ik`)."""


def _g1():
    from ijoy_jax.sim import g1  # needs the robots extra only when the G1 is asked for

    return g1


def build_spec(params: model.BipedParams, shape=(200, 200), resolution: float = 0.02,
               origin=(0.0, 0.0), *, meshes: bool = False) -> mujoco.MjSpec:
    """The robot of ``params.model`` and a terrain height field as an ``mujoco.MjSpec`` (see
    :func:`ijoy_jax.sim.model.build_spec` for the grid's conventions; ``meshes``: the G1's visual meshes, for
    rendering only, :func:`ijoy_jax.sim.g1.walker_spec`; the project's biped has none)."""
    if params.model == "g1":
        return _g1().walker_spec(params, shape, resolution, origin, meshes=meshes)
    return model.build_spec(params, shape, resolution, origin)


def build_model(params: model.BipedParams, terrain, *, edit=None, meshes: bool = False) -> mujoco.MjModel:
    """The compiled robot of ``params.model`` on ``terrain`` (:func:`ijoy_jax.sim.model.build_model`'s contract:
    ``hfield_data`` is :func:`~ijoy_jax.sim.hfield.hfield_data`; ``edit`` changes the spec before compiling;
    ``meshes`` as :func:`build_spec`: the same joints, masses and contacts, so the physics' ``qpos`` replays on
    it)."""
    spec = build_spec(params, terrain.shape, terrain.resolution, np.asarray(terrain.origin), meshes=meshes)
    return hfield.compile_with_terrain(spec, params, terrain, edit=edit)


@functools.lru_cache(maxsize=8)
def foot(params: model.BipedParams) -> tuple[float, tuple[float, float, float]]:
    """The foot below each ankle's force/torque sensor: its mass (kg) and the sensor's point from the sole centre,
    in the sole's frame (m; the project's biped: ``(0, 0, ankle_height)``)."""
    if params.model == "g1":
        mass, offset = _g1().foot(params)
        return mass, tuple(float(v) for v in offset)
    return float(params.foot_mass), (0.0, 0.0, float(params.ankle_height))


def walk_defaults(params: model.BipedParams) -> dict[str, float]:
    """The ``WalkConfig`` fields the robot of ``params.model`` walks with by default (the rest are
    ``WalkConfig``'s own, which are the project's biped's): the G1's :data:`.g1.WALK` (its pelvis height, its
    0.5 s step time, capture-point stepping); none for the biped."""
    if params.model == "g1":
        return dict(_g1().WALK)
    return {}


def legs_ik(params: model.BipedParams, pelvis_pos, pelvis_rot, feet) -> tuple[jax.Array, jax.Array]:
    """Both legs' joint angles for soles at ``feet`` (2, 6) (x, y, z, roll, pitch, yaw; row 0 left) from the
    pelvis at ``pelvis_pos`` (3,) m with orientation ``pelvis_rot`` (3, 3).

    Returns:
      q: (12,) rad, left leg then right, in ``qpos`` order; reachable: () bool, both legs reach their soles
      (the biped: the hip-ankle distance within the leg's reach; the G1: the damped least squares ends within
      1 mm and 0.01 rad of the target, its joints inside their limits).
    """
    if params.model != "g1":
        legs = [kinematics.leg_ik(params, side, pelvis_pos, pelvis_rot, feet[row, :3],
                                  kinematics.rpy_to_rot(feet[row, 3:]))
                for row, side in enumerate((1, -1))]
        return jnp.concatenate([legs[0].q, legs[1].q]), legs[0].reachable & legs[1].reachable
    from ijoy_jax.sim.description import leg_ik

    desc = _g1().description(params)
    dt = jnp.result_type(pelvis_pos, pelvis_rot, feet, jnp.float32)
    pelvis_pos, pelvis_rot, feet = (jnp.asarray(x, dt) for x in (pelvis_pos, pelvis_rot, feet))
    qs, ok = [], jnp.bool_(True)
    for row in range(2):
        pos = pelvis_rot.T @ (feet[row, :3] - pelvis_pos)
        rot = pelvis_rot.T @ kinematics.rpy_to_rot(feet[row, 3:])
        sol = leg_ik(desc.legs[row], pos, rot, jnp.asarray(desc.stand_leg_q[row], dt))
        qs.append(sol.q)
        ok &= (sol.position_error < _IK_POS_TOL) & (sol.rotation_error < _IK_ROT_TOL)
    return jnp.concatenate(qs), ok


def stand_pose(params: model.BipedParams, feet, ground, pelvis_z, shift=None, *, tilt=None
               ) -> tuple[jax.Array, jax.Array]:
    """qpos (nq,) of the robot standing with its soles at ``feet`` (2, 3) (x, y, yaw) on ``ground`` (2,), and
    whether both legs reach (pure JAX: jit/vmap-able).

    :func:`ijoy_jax.sim.model.stand_pose`'s contract for every robot: the pelvis level, yawed to the feet's mean
    yaw, ``pelvis_z`` high, above the feet's midpoint (moved by ``shift`` (2,) m); ``tilt`` (2, 2) roll and pitch
    of each sole (rad).
    """
    if params.model != "g1":
        return model.stand_pose(params, feet, ground, pelvis_z, shift, tilt=tilt)
    feet = jnp.asarray(feet)
    dtype = jnp.result_type(feet, jnp.float32)
    feet = feet.astype(dtype)
    ground = jnp.asarray(ground, dtype)
    yaw = jnp.arctan2(jnp.sum(jnp.sin(feet[:, 2])), jnp.sum(jnp.cos(feet[:, 2])))
    xy = jnp.mean(feet[:, :2], axis=0) + (0.0 if shift is None else jnp.asarray(shift, dtype))
    pelvis = jnp.concatenate([xy, jnp.asarray(pelvis_z, dtype)[None]])
    tilt = jnp.zeros((2, 2), dtype) if tilt is None else jnp.asarray(tilt, dtype)
    soles = jnp.concatenate([feet[:, :2], ground[:, None], tilt, feet[:, 2:3]], axis=1)
    q, ok = legs_ik(params, pelvis, kinematics.rot_z(yaw), soles)
    zero = jnp.zeros_like(yaw)
    quat = jnp.stack([jnp.cos(yaw / 2), zero, zero, jnp.sin(yaw / 2)])
    return jnp.concatenate([pelvis, quat, q]), ok
