"""Rasterise posed object models (boxes, cylinders) into a terrain map.

The paper built its 2D obstacle maps and 2.5D height maps in real time from
registered 3D models of tracked objects; this is that step, in JAX, so a
batch of scenes (or a simulated scene) becomes the maps the selector sees in
one jitted call. A cell counts as covered by an object iff their interiors
overlap (positive area), the same exact rule FootCost uses, so an object
never slips between cells.

Object arrays (metres, radians), one row per object::

  boxes: (B, 6) ``x, y, yaw, length, width, top``: centre, heading of the
    length axis, full extents, and the world elevation of the top face.
  cylinders: (C, 4) ``x, y, radius, top``.

Rows with a zero extent (length, width or radius) cover nothing, so a
fixed-size array padded with zero rows holds a variable number of objects.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ijoy_jax.terrain.grid import Terrain


def _cell_bounds(terrain: Terrain):
    nx, ny = terrain.shape
    r = terrain.resolution
    x0 = terrain.origin[0] + jnp.arange(nx) * r
    y0 = terrain.origin[1] + jnp.arange(ny) * r
    return x0[:, None], (x0 + r)[:, None], y0[None, :], (y0 + r)[None, :]


def box_cover(terrain: Terrain, box: jax.Array) -> jax.Array:
    """(nx, ny) bool: cells whose interior overlaps the rotated box's footprint.

    Separating-axis test between the rectangle and each cell square, on the
    four candidate axes (x, y and the box's two axes); open intervals, so
    touching edges do not count.
    """
    x, y, yaw, length, width = box[0], box[1], box[2], box[3], box[4]
    xl, xh, yl, yh = _cell_bounds(terrain)
    c, s = jnp.abs(jnp.cos(yaw)), jnp.abs(jnp.sin(yaw))
    hl, hw = 0.5 * length, 0.5 * width
    ex = c * hl + s * hw  # half-extent of the box along world x
    ey = s * hl + c * hw
    sep = (xh <= x - ex) | (xl >= x + ex) | (yh <= y - ey) | (yl >= y + ey)
    # Box axes u = (cos, sin), v = (-sin, cos): project the cell's corners.
    cu, su = jnp.cos(yaw), jnp.sin(yaw)
    for ax, ay, half in ((cu, su, hl), (-su, cu, hw)):
        centre = ax * x + ay * y
        pa = jnp.minimum(ax * xl, ax * xh) + jnp.minimum(ay * yl, ay * yh)
        pb = jnp.maximum(ax * xl, ax * xh) + jnp.maximum(ay * yl, ay * yh)
        sep = sep | (pb <= centre - half) | (pa >= centre + half)
    return ~sep & (length > 0) & (width > 0)


def cylinder_cover(terrain: Terrain, cylinder: jax.Array) -> jax.Array:
    """(nx, ny) bool: cells whose interior overlaps the cylinder's disc."""
    x, y, radius = cylinder[0], cylinder[1], cylinder[2]
    xl, xh, yl, yh = _cell_bounds(terrain)
    dx = jnp.maximum(jnp.maximum(xl - x, x - xh), 0.0)
    dy = jnp.maximum(jnp.maximum(yl - y, y - yh), 0.0)
    return (dx * dx + dy * dy < radius * radius) & (radius > 0)


def rasterize(terrain: Terrain, boxes=None, cylinders=None, obstacle: bool | jax.Array = False) -> Terrain:
    """Add posed boxes and cylinders to a terrain.

    On a 2.5D terrain each covered cell's height becomes the highest top
    that covers it (``max(height, top)``); on a 2D terrain heights are not
    stored and every object is an obstacle.

    Args:
      terrain: the map to draw into (its shape, resolution and origin are kept).
      boxes: (B, 6) ``x, y, yaw, length, width, top`` rows, or None.
      cylinders: (C, 4) ``x, y, radius, top`` rows, or None.
      obstacle: bool, or (B + C,) bools (boxes first): objects that are
        obstacles (covered cells become not free). On 2.5D terrains the
        default False makes them surfaces to stand on.

    Returns:
      A new Terrain. Jit- and vmap-able (over terrains and object arrays).

    Example:
      >>> import ijoy_jax as ij
      >>> t = ij.terrain.flat((50, 50), 0.02, has_height=True)
      >>> t = ij.terrain.scene.rasterize(t, boxes=[[0.5, 0.5, 0.3, 0.4, 0.2, 0.05]])
      >>> float(t.height.max())
      0.05...
    """
    covers, tops = [], []
    if boxes is not None:
        boxes = jnp.asarray(boxes, jnp.float32).reshape(-1, 6)
        if boxes.shape[0]:
            covers.append(jax.vmap(lambda b: box_cover(terrain, b))(boxes))
            tops.append(boxes[:, 5])
    if cylinders is not None:
        cylinders = jnp.asarray(cylinders, jnp.float32).reshape(-1, 4)
        if cylinders.shape[0]:
            covers.append(jax.vmap(lambda c: cylinder_cover(terrain, c))(cylinders))
            tops.append(cylinders[:, 3])
    if not covers:
        return terrain
    cover = jnp.concatenate(covers)  # (M, nx, ny)
    top = jnp.concatenate(tops)  # (M,)
    if not terrain.has_height:
        return terrain.replace(free=terrain.free & ~jnp.any(cover, axis=0))
    obstacle = jnp.broadcast_to(jnp.asarray(obstacle, bool), top.shape)
    drawn = jnp.max(jnp.where(cover, top[:, None, None], -jnp.inf), axis=0)
    height = jnp.maximum(terrain.height, drawn)
    blocked = jnp.any(cover & obstacle[:, None, None], axis=0)
    return terrain.replace(height=height, free=terrain.free & ~blocked)
