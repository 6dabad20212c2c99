"""What a FootCost query may hold, and the checks at the boundary of both FootCost paths.

A query is a terrain, a robot, a stance, its side, candidate steps and optionally the swing foot's start
and the actions' indices. Where they are concrete, :func:`validate` and :func:`check_action_index` refuse
bad ones with a clear error (:func:`checked_query` is the boundary of :func:`~ijoy_jax.footcost.foot_cost_terms`
and :func:`~ijoy_jax.footcost.pallas.foot_cost_fused`); where they are traced, :func:`query_supported`,
:func:`poses_supported` and :func:`safe_action_index` flag the same values inside the program, and
:func:`safe_poses` gives finite stand-ins, so an unsupported query is +inf in its ``unsupported`` term
and never NaN. One set of rules, so the XLA path and the fused kernel accept and refuse alike.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import geometry
from ijoy_jax.footcost.index import TerrainIndex
from ijoy_jax.robots import Robot, check_robot, robot_supported
from ijoy_jax.struct import as_pose, check_numeric, is_traced
from ijoy_jax.terrain import Terrain, check_terrain, terrain_supported

MAX_COORDINATE = 8192.0
"""m: the largest world coordinate a map may reach (its origin and far corner). FootCost runs in float32 (also
under x64: poses are cast), whose spacing at 2**13 m is 2**-10 m (0.98 mm), so within it every coordinate rounds
by under half a millimetre; beyond, a footprint lands on the wrong cells (at a UTM northing of 5.2e6 m, y rounds
to 0.5 m). Such frames are refused, not shifted internally: the results are world poses in float32 too, and
would round the same way on the way out. Subtract your map's origin (in float64, on your side) from every pose
and add it back to the returned ones."""


def frame_extent(terrain: Terrain):
    """The largest absolute world coordinate of the map (origin or far corner, m): NumPy for a concrete origin, a
    jax scalar for a traced one (NaN if the origin is not finite)."""
    nx, ny = terrain.shape
    o = terrain.origin
    xp = jnp if isinstance(o, jax.core.Tracer) else np
    o = xp.asarray(o, xp.float64 if xp is np else o.dtype)
    far = o + xp.asarray([nx * terrain.resolution, ny * terrain.resolution], o.dtype)
    return xp.max(xp.abs(xp.concatenate([o, far])))


def check_frame(terrain: Terrain) -> None:
    """Raise ValueError if a concrete terrain lies where float32 loses millimetres (:data:`MAX_COORDINATE`).

    A traced origin is not checked here: inside a jit such a map flags every step ``unsupported``."""
    if isinstance(terrain.origin, jax.core.Tracer):
        return
    extent = float(frame_extent(terrain))
    if not np.isfinite(extent):
        raise ValueError(f"terrain origin must be finite, got {np.asarray(terrain.origin).tolist()}")
    nx, ny = terrain.shape
    size = max(nx, ny) * float(terrain.resolution)
    if size > MAX_COORDINATE:  # no frame shift helps: the map itself is wider than float32's millimetres
        raise ValueError(
            f"the map is {size:.6g} m across ({nx} x {ny} cells of {float(terrain.resolution):g} m), beyond the "
            f"{MAX_COORDINATE:g} m where float32 holds millimetres (ijoy_jax.footcost.MAX_COORDINATE): use a finer "
            "resolution or fewer cells"
        )
    if extent > MAX_COORDINATE:
        with np.errstate(over="ignore"):
            lost = float(np.spacing(np.float32(extent))) / 2  # inf beyond float32: say so, not nan
        raise ValueError(
            f"shift your world frame: the map reaches {extent:.6g} m from the origin, where float32 rounds "
            f"coordinates by up to {lost:.3g} m (millimetres hold within {MAX_COORDINATE:g} m); subtract the "
            f"map's origin {np.asarray(terrain.origin).tolist()} from every pose (float64, on your side), "
            "build the terrain at origin (0, 0) and add the origin back to the returned poses"
        )


def far_frame(terrain: Terrain) -> jax.Array:
    """() bool: the map reaches beyond :data:`MAX_COORDINATE` or its origin is not finite (flagged
    ``unsupported`` inside a jit, where :func:`check_frame` cannot see the origin's value)."""
    return ~(jnp.asarray(frame_extent(terrain)) <= MAX_COORDINATE)


def query_supported(terrain: Terrain, robot: Robot) -> jax.Array:
    """() bool: FootCost supports this robot on this terrain (traceable; the one rule of both paths).

    False when the robot's values break a rule of :func:`~ijoy_jax.robots.robot_supported` (NaN, a negative
    margin, weight or cost, a footprint beyond its static window, ...), the terrain's break
    :func:`~ijoy_jax.terrain.terrain_supported` (a non-finite origin or height), or the map reaches beyond
    :data:`MAX_COORDINATE` (:func:`far_frame`): the values the boundary checks refuse where they are
    concrete. Where False, every candidate of :func:`~ijoy_jax.footcost.foot_cost_terms` is +inf with its
    ``unsupported`` term set, and so is every total of :func:`~ijoy_jax.footcost.pallas.foot_cost_fused`;
    :func:`ijoy_jax.select_step` reports ``unsupported``.
    """
    return robot_supported(robot) & terrain_supported(terrain) & ~far_frame(terrain)


def poses_supported(stance, stance_side, swing_from=None) -> jax.Array:
    """() bool: a query's own traced values are ones FootCost supports (traceable; both paths' rule).

    False when ``stance`` or ``swing_from`` is not finite or turns beyond :data:`~ijoy_jax.geometry.MAX_ANGLE`
    (:func:`~ijoy_jax.geometry.pose_supported`), or ``stance_side`` is not exactly +1 or -1: the values the
    boundary checks refuse where they are concrete. Where False, every candidate is +inf with its
    ``unsupported`` term set, as for :func:`query_supported`; compute with :func:`safe_poses`' stand-ins.
    """
    side = jnp.asarray(stance_side)
    ok = geometry.pose_supported(stance) & ((side == 1) | (side == -1))
    return ok if swing_from is None else ok & geometry.pose_supported(swing_from)


def safe_poses(stance, swing_from=None):
    """``(stance, swing_from)`` as float32 with each non-finite pose replaced by zeros: the finite stand-ins an
    unsupported query (:func:`poses_supported`) computes with, so no NaN reaches a result."""

    def safe(pose):
        pose = jnp.asarray(pose, jnp.float32)
        return jnp.where(jnp.all(jnp.isfinite(pose)), pose, 0.0)

    return safe(stance), None if swing_from is None else safe(swing_from)


def check_action_index(robot: Robot, action_index, num: int) -> None:
    """Refuse an ``action_index`` argument that is not () or (num,) integers, or (where concrete) that indexes
    outside the action set ``[0, robot.num_actions)``. Traced values are flagged inside instead
    (:func:`safe_action_index`)."""
    if action_index is None:
        return
    shape = np.shape(action_index)
    if shape not in ((), (num,)):
        raise ValueError(f"action_index must be one int or ({num},) ints (one per step), got shape {shape}")
    dtype = action_index.dtype if hasattr(action_index, "dtype") else np.asarray(action_index).dtype
    if dtype.kind not in "iu":
        raise TypeError(f"action_index must hold integers, got dtype {dtype}")
    if not is_traced(action_index):
        a = np.asarray(action_index)
        bad = (a < 0) | (a >= robot.num_actions)
        if bad.any():
            raise ValueError(
                f"action_index must be in [0, {robot.num_actions}) (the robot's action set), got "
                f"{int(a[bad].ravel()[0])}"
            )


def safe_action_index(robot: Robot, action_index, num: int) -> tuple[jax.Array, jax.Array]:
    """``(index, ok)``: (num,) int32 action indices (one given index is broadcast) with every one outside
    ``[0, robot.num_actions)`` replaced by 0, and ``ok`` whether each was inside (a step with a bad index is
    flagged ``unsupported``, never another action's cost read silently: a gather clamps out-of-range indices)."""
    a = jnp.broadcast_to(jnp.asarray(action_index, jnp.int32), (num,))
    ok = (a >= 0) & (a < robot.num_actions)
    return jnp.where(ok, a, 0), ok


def _finite32(value) -> bool:
    """Whether a concrete value is finite once cast to the float32 it is computed in (1e39 is not)."""
    with np.errstate(over="ignore"):
        return bool(np.all(np.isfinite(np.asarray(value, np.float32))))


def validate(terrain, robot, stance, stance_side, steps, swing_from=None, index=None):
    """Check the arguments of :func:`~ijoy_jax.footcost.foot_cost_terms` (raises ValueError / TypeError).

    Values of tracers are not checked (their shapes are), so it costs nothing inside a trace.
    """
    if not isinstance(terrain, Terrain):
        raise TypeError(f"terrain must be an ijoy_jax.Terrain, got {type(terrain).__name__}")
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be an ijoy_jax.robots.Robot, got {type(robot).__name__}")
    if index is not None and not isinstance(index, TerrainIndex):
        raise TypeError(f"index must be an ijoy_jax.footcost.TerrainIndex, got {type(index).__name__}")
    if terrain.free.ndim != 2:
        raise ValueError(
            f"foot_cost takes one terrain (free of shape (nx, ny)), got {terrain.free.shape}; vmap over batches"
        )
    check_terrain(terrain)
    check_robot(robot)
    for name, value, shape in (("stance", stance, (3,)), ("swing_from", swing_from, (3,))):
        if value is None:
            continue
        check_numeric(name, value)
        if np.shape(value) != shape:
            raise ValueError(f"{name} must have shape {shape}, got {np.shape(value)}")
        if not isinstance(value, jax.core.Tracer) and not _finite32(value):
            raise ValueError(f"{name} must be finite, got {np.asarray(value).tolist()}")
    check_frame(terrain)
    check_numeric("steps", steps)
    s = np.shape(steps)
    if len(s) != 2 or s[1] != 3:
        raise ValueError(f"steps must have shape (N, 3) of (x, y, theta) world poses, got {s}")
    if not isinstance(stance_side, jax.core.Tracer):
        side = np.asarray(stance_side)
        if side.shape != () or side.dtype.kind not in "iuf" or float(side) not in (-1.0, 1.0):
            raise ValueError(f"stance_side must be +1 (left stance foot) or -1 (right), got {stance_side!r}")


def checked_query(terrain, robot, stance, stance_side, steps, swing_from=None, index=None):
    """The boundary of both FootCost paths: lists (of numbers or traced scalars) as float32 arrays
    (:func:`~ijoy_jax.struct.as_array`), then :func:`validate`; returns ``(stance, steps, swing_from)``."""
    stance, steps, swing_from = (
        as_pose(n, v) for n, v in (("stance", stance), ("steps", steps), ("swing_from", swing_from))
    )
    validate(terrain, robot, stance, stance_side, steps, swing_from, index)
    return stance, steps, swing_from
