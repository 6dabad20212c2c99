"""The terrain as a MuJoCo height field: what any robot of the walker stands on.

A :class:`ijoy_jax.terrain.Terrain` becomes one height field whose samples sit at the cell centres (MuJoCo's
``nrow`` is the terrain's ``ny``, ``ncol`` its ``nx``). MuJoCo interpolates the surface linearly between
samples, so a raised cell is a plateau between its raised neighbours with walls one cell wide. Heights are
stored normalised, ``z = z_lo + data * (z_hi - z_lo)``, and a batch of terrains only swaps the traced
``hfield_data`` leaf of one compiled model (:func:`put_terrain`, :func:`put_terrains`).

The robots' specs add it with :func:`add_terrain` (the project's biped, :func:`ijoy_jax.sim.model.build_spec`;
any other, :func:`ijoy_jax.sim.scene.terrain_scene`) and compile with :func:`compile_with_terrain`. The
``params`` arguments are :class:`HeightFieldParams`: a robot's :class:`ijoy_jax.sim.model.BipedParams`.
"""

from __future__ import annotations

import math
from typing import Protocol

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

__all__ = ["HeightFieldParams", "add_terrain", "compile_with_terrain", "hfield_data", "physical_heights", "put_terrain",
           "put_terrains"]


class HeightFieldParams(Protocol):
    """What the height field reads of a robot's parameters (:class:`ijoy_jax.sim.model.BipedParams` has them)."""

    z_lo: float  # m, the height field's lowest elevation
    z_hi: float  # m, its highest
    base_depth: float  # m, the thickness of its base below z_lo (MuJoCo's fourth hfield size)
    friction: float  # the sliding friction of the ground
    obstacle_height: float  # m, how high a 2D map's obstacle cells stand (physical_heights)


def _hfield_geometry(p: HeightFieldParams, shape, resolution: float, origin) -> tuple[list, list]:
    """MuJoCo hfield size and geom position for a grid: sample (i, j) at cell (i, j)'s centre."""
    nx, ny = (int(v) for v in shape)
    rx, ry = (nx - 1) * resolution / 2, (ny - 1) * resolution / 2
    ox, oy = (float(v) for v in np.asarray(origin, np.float64))
    size = [rx, ry, p.z_hi - p.z_lo, p.base_depth]
    pos = [ox + resolution / 2 + rx, oy + resolution / 2 + ry, p.z_lo]
    return size, pos


def add_terrain(spec: mujoco.MjSpec, params: HeightFieldParams, shape, resolution: float, origin) -> None:
    """Add the terrain's height field (geom and asset "terrain", zero data) and a light to ``spec``, in place.

    The geom collides with geoms of ``contype`` 1 (the sole spheres) and is given ``params.friction``; its
    samples and elevation are those :func:`build_spec` describes. Any robot's spec can stand on it.
    """
    nx, ny = (int(v) for v in shape)
    if nx < 2 or ny < 2:
        raise ValueError(f"the terrain grid needs at least 2 x 2 cells for a height field, got {shape}")
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution must be a positive finite number of metres, got {resolution!r}")
    size, pos = _hfield_geometry(params, (nx, ny), float(resolution), origin)
    spec.add_hfield(name="terrain", nrow=ny, ncol=nx, size=size, userdata=[0.0] * (nx * ny))
    spec.worldbody.add_geom(name="terrain", type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname="terrain", pos=pos,
                            contype=0, conaffinity=1, condim=3, friction=[params.friction, 0.005, 0.0001],
                            rgba=[0.55, 0.6, 0.5, 1])
    spec.worldbody.add_light(name="sun", pos=[0, 0, 4], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)


def physical_heights(terrain, obstacle_height: float = 0.1) -> jax.Array:
    """(nx, ny) float32 surface heights (metres) the simulated robot meets.

    2D terrains (``has_height=False``): 0 on free cells, ``obstacle_height`` on
    obstacle cells (walls the robot must not touch). 2.5D terrains: their
    heights unchanged, also on non-free cells: a 2.5D map's heights already
    describe its obstacles (a 5 cm bar is 5 cm high), and ``free`` is a
    planning label (too steep, too rough), not extra geometry.
    """
    height = jnp.asarray(terrain.height, jnp.float32)
    if terrain.has_height:
        return height
    return jnp.where(terrain.free, height, jnp.float32(obstacle_height))


def hfield_data(params: HeightFieldParams, terrain) -> jax.Array:
    """(ny * nx,) float32 height field data of a terrain, in MuJoCo's order, normalised to [0, 1].

    ``data[j * nx + i] = clip((h[i, j] - z_lo) / (z_hi - z_lo), 0, 1)`` with
    ``h = physical_heights(terrain, params.obstacle_height)``: row j runs along
    y, column i along x. Heights outside ``[z_lo, z_hi]`` are clipped to the
    range (the robot meets a surface at ``z_lo`` or ``z_hi`` there). Pure JAX:
    jit and vmap over terrains freely.
    """
    h = physical_heights(terrain, params.obstacle_height)
    data = jnp.clip((h - params.z_lo) / (params.z_hi - params.z_lo), 0.0, 1.0)
    return data.T.reshape(-1).astype(jnp.float32)


def compile_with_terrain(spec: mujoco.MjSpec, params: HeightFieldParams, terrain, *, edit=None) -> mujoco.MjModel:
    """Compile a robot's spec with its height field (added by :func:`add_terrain` for ``terrain``'s grid) and write
    ``terrain``'s heights into the compiled model (:func:`build_model`'s contract; ``edit`` changes the spec in
    place before it is compiled)."""
    if edit is not None:
        edit(spec)
    m = spec.compile()
    m.hfield_data[:] = np.asarray(hfield_data(params, terrain), np.float32)
    return m


def put_terrain(mjx_model, params: HeightFieldParams, terrain):
    """An ``mjx.Model`` with its height field data replaced by ``terrain``'s (same grid shape).

    Pure and jit-able; MJX reads ``hfield_data`` inside its collision functions,
    so the replaced data is what the robot meets. Vmapping this over terrains
    batches every model leaf; :func:`put_terrains` batches only the height field.
    """
    data = hfield_data(params, terrain)
    if data.shape != mjx_model.hfield_data.shape:
        raise ValueError(f"terrain grid {terrain.shape} does not match the model's height field "
                         f"({mjx_model.hfield_data.shape[0]} samples)")
    return mjx_model.replace(hfield_data=data.astype(mjx_model.hfield_data.dtype),
                             geom_pos=_terrain_geom_pos(mjx_model, params, terrain))


def _terrain_geom_pos(mjx_model, params: HeightFieldParams, terrain) -> jax.Array:
    """The model's geom positions with the height field's centred on ``terrain``'s grid (its origin may differ
    from the one the model was built with)."""
    gid = int(np.flatnonzero(np.asarray(mjx_model.geom_type) == int(mujoco.mjtGeom.mjGEOM_HFIELD))[0])
    centre = jnp.asarray(terrain.origin, jnp.float32) + 0.5 * terrain.resolution * jnp.asarray(terrain.shape,
                                                                                                jnp.float32)
    pos = jnp.concatenate([centre, jnp.full((1,), params.z_lo, jnp.float32)])
    return mjx_model.geom_pos.at[gid].set(pos.astype(mjx_model.geom_pos.dtype))


def put_terrains(mjx_model, params: HeightFieldParams, terrains):
    """A batch of terrains (a Terrain with a leading batch axis) in one ``mjx.Model``.

    Returns:
      (model, in_axes): the model with (B, ny * nx) ``hfield_data`` and (B, ngeom, 3)
      ``geom_pos`` (the height field placed on each terrain's grid) and its other
      leaves shared, and the matching ``in_axes`` pytree for ``jax.vmap``
      (0 for ``hfield_data``, None elsewhere), as in mujoco_playground's randomize.

    Example:
      >>> # m, axes = put_terrains(mjx.put_model(mj), p, batch)
      >>> # jax.vmap(mjx.step, in_axes=(axes, 0))(m, d)
    """
    data = jax.vmap(lambda t: hfield_data(params, t))(terrains)
    if data.shape[1:] != mjx_model.hfield_data.shape:
        raise ValueError(f"terrain grids do not match the model's height field ({mjx_model.hfield_data.shape[0]})")
    geom_pos = jax.vmap(lambda t: _terrain_geom_pos(mjx_model, params, t))(terrains)
    model = mjx_model.replace(hfield_data=data.astype(mjx_model.hfield_data.dtype), geom_pos=geom_pos)
    in_axes = jax.tree_util.tree_map(lambda _: None, mjx_model).replace(hfield_data=0, geom_pos=0)
    return model, in_axes
