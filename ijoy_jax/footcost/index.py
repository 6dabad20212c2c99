"""The per-terrain tables FootCost reads: obstacle prefix counts, a sparse table of column maxima, padded heights
and the fused kernel's window sums, built once per terrain (:func:`index_terrain`) and shared by the XLA path
(:mod:`ijoy_jax.footcost.xla`) and the fused kernel (:mod:`ijoy_jax.footcost.pallas`); and the queries both
paths make of them (a column's obstacle count, a span's highest cell, the swing corridor's cells).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from ijoy_jax import geometry
from ijoy_jax.limits import check_window
from ijoy_jax.robots import Robot
from ijoy_jax.struct import pytree_dataclass, static_field
from ijoy_jax.terrain import Terrain


@pytree_dataclass
class TerrainIndex:
    """Per-terrain tables that make FootCost O(columns) per candidate.

    Fields::

      obstacles_before: (nx, ny + 1) int32, number of obstacle cells in column
        ix with row index < j (prefix counts along y).
      height_max: (levels, nx, ny) float32 sparse table; ``height_max[k, ix, j]``
        is the largest height in rows ``j .. j + 2**k - 1`` of column ix.
      height_padded: (nx + 2P, ny + 2P) float32 heights, edge-padded by P cells.
      height_sums: (nx + 2P, blocks, 2B + 1, 2) float32 prefix sums of the
        padded map's columns over overlapping windows of 2B rows, for the fused
        kernel's plane fits (:func:`block_sums`; B: a power of two >= P;
        blocks = 0 on 2D maps).
      height_block_first: (nx + 2P, blocks) float32, each window's first height.
      pad: P (static).
    """

    obstacles_before: jax.Array
    height_max: jax.Array
    height_padded: jax.Array
    height_sums: jax.Array
    height_block_first: jax.Array
    pad: int = static_field()


def index_terrain(terrain: Terrain, robot: Robot) -> TerrainIndex:
    """Build the :class:`TerrainIndex` of a terrain (once per terrain, reused across steps)."""
    occ = (~terrain.free).astype(jnp.int32)
    counts = jnp.cumsum(occ, axis=-1, dtype=jnp.int32)  # int32 also under x64
    before = jnp.concatenate([jnp.zeros(occ.shape[:-1] + (1,), jnp.int32), counts], -1)
    # A non-finite height (only possible traced: check_terrain refuses it) flags every step unsupported
    # (terrain_supported); as 0 in the tables it leaves every term finite instead of NaN.
    h = jnp.where(jnp.isfinite(terrain.height), terrain.height, jnp.zeros((), terrain.height.dtype))
    ny = h.shape[-1]
    levels = [h]
    span = 1
    while 2 * span <= ny:
        prev = levels[-1]
        shifted = jnp.concatenate([prev[:, span:], jnp.full((h.shape[0], span), -jnp.inf, h.dtype)], axis=1)
        levels.append(jnp.maximum(prev, shifted))
        span *= 2
    pad = check_window(robot.max_radius, terrain.resolution, "footprint")
    padded = jnp.pad(h, pad, mode="edge")
    block = 1 << max(pad - 1, 1).bit_length()
    if terrain.has_height:
        sums, first = block_sums(padded, block)
    else:  # a 2D map's kernel pass reads no heights: empty tables of the right rank and block size
        sums = jnp.zeros((padded.shape[0], 0, 2 * block + 1, 2), h.dtype)
        first = jnp.zeros((padded.shape[0], 0), h.dtype)
    return TerrainIndex(before, jnp.stack(levels), padded, sums, first, pad)


def block_sums(height, block: int) -> tuple[jax.Array, jax.Array]:
    """Prefix sums of each column of a height map over overlapping windows: a column's sum over any span of
    <= ``block`` rows in two reads (the fused kernel's plane fits, :mod:`ijoy_jax.footcost.pallas`).

    Window b holds rows ``b block .. b block + 2 block - 1`` (beyond the map, its edge row), so a span of at
    most ``block`` rows starting in rows ``b block .. b block + block - 1`` lies in window b. Heights are
    taken from each window's first height h_b, so the sums' rounding scales with the relief within a window
    (as the XLA path's does with the relief under a foot), not with the terrain's altitude or overall relief.
    ``sums[ix, b, t]`` holds, over the first t rows of window b in column ix, the sum of (h - h_b) and of
    (h - h_b) (row - b block - (block - 1/2)) (rows from the window's middle: smaller terms).

    Args:
      height: (nx, ny) float32 heights (m).
      block: rows per window step (static, a power of two >= the longest span).

    Returns:
      ``sums`` (nx, blocks, 2 block + 1, 2) float32, blocks = ceil(ny / block), and ``first`` (nx, blocks)
      float32: h_b (m).
    """
    num_x, num_y = height.shape
    blocks = -(-num_y // block)
    h = jnp.pad(height, ((0, 0), (0, (blocks + 1) * block - num_y)), mode="edge").reshape(num_x, blocks + 1, block)
    window = jnp.concatenate([h[:, :-1], h[:, 1:]], axis=2)  # (nx, blocks, 2 block)
    first = window[:, :, 0]
    rel = window - first[:, :, None]  # a stored height, subtracted as the kernel will (h_b - h_ref)
    terms = jnp.stack([rel, rel * (jnp.arange(2 * block, dtype=h.dtype) - (block - 0.5))], -1)
    return jnp.concatenate([jnp.zeros_like(terms[:, :, :1]), jnp.cumsum(terms, axis=2)], axis=2), first


def swing_corridor(sx, sy, cx, cy, half_width, res, num_columns: int) -> tuple[geometry.ColumnSpans, jax.Array]:
    """Cells of the swing corridor from (sx, sy) to (cx, cy) (map coordinates, m): the rectangle of half width
    ``half_width`` between the two foot centres, as exact column spans (:func:`geometry.rect_column_spans`, a
    window of ``num_columns``), and its length (m). A zero-length corridor lies along x."""
    dx, dy = cx - sx, cy - sy
    length = jnp.sqrt(dx * dx + dy * dy)
    theta = jnp.arctan2(jnp.where(length > 0, dy, 0.0), jnp.where(length > 0, dx, 1.0))
    spans = geometry.rect_column_spans(0.5 * (cx + sx), 0.5 * (cy + sy), theta, 0.5 * length, half_width, res,
                                       num_columns)
    return spans, length


def centre_off_map(cx, cy, shape, res) -> jax.Array:
    """Bool (shape of cx): a foot centre (map coordinates, m) not strictly inside the map, so its footprint
    leaves the map. Both paths flag it as an obstacle besides the exact cell spans, which at a coordinate
    float32 cannot resolve (a footprint at 1e7 m collapses to a line touching no cell; cells past 2**31
    overflow int32) would miss it. NaN compares false: off the map too."""
    nx, ny = shape
    return ~((cx > 0.0) & (cx < nx * res) & (cy > 0.0) & (cy < ny * res))


def column_has_obstacle(index: TerrainIndex, spans: geometry.ColumnSpans, shape) -> jax.Array:
    """(K,) bool: touched columns holding an obstacle cell or leaving the map."""
    nx, ny = shape
    ix = jnp.clip(spans.ix, 0, nx - 1)
    j0 = jnp.clip(spans.j0, 0, ny)
    j1 = jnp.clip(spans.j1 + 1, 0, ny)
    count = index.obstacles_before[ix, j1] - index.obstacles_before[ix, j0]
    off_map = (spans.ix < 0) | (spans.ix >= nx) | (spans.j0 < 0) | (spans.j1 >= ny)
    return spans.touched & (off_map | (count > 0))


def rows_max(height_max, ix, j0, j1):
    """The highest height in rows j0..j1 (on the map; if j1 < j0, of rows j0 and j1) of column ix: two reads of the
    sparse table (:attr:`TerrainIndex.height_max`, an array or the fused kernel's ref) at level floor(log2(span)),
    taken from the exponent of the span as a float (exact below 2**24; Triton lowers no count of leading zeros)
    and capped at the table's top level."""
    span = jnp.maximum(j1 - j0 + 1, 1)
    # int32 throughout (explicit, so that it also holds under jax_enable_x64, where a bare 23 is int64).
    lvl = lax.shift_right_logical(lax.bitcast_convert_type(span.astype(jnp.float32), jnp.int32), jnp.int32(23))
    lvl = jnp.minimum(lvl - 127, height_max.shape[0] - 1).astype(jnp.int32)
    return jnp.maximum(height_max[lvl, ix, j0], height_max[lvl, ix, j1 - (1 << lvl) + 1])


def column_max_height(index: TerrainIndex, spans: geometry.ColumnSpans, shape) -> tuple[jax.Array, jax.Array]:
    """Largest height over the touched cells, and whether any touched cell is off the map."""
    nx, ny = shape
    ix = jnp.clip(spans.ix, 0, nx - 1)
    j0 = jnp.clip(spans.j0, 0, ny - 1)
    j1 = jnp.clip(spans.j1, 0, ny - 1)
    hi = rows_max(index.height_max, ix, j0, j1)
    off_map = (spans.ix < 0) | (spans.ix >= nx) | (spans.j0 < 0) | (spans.j1 >= ny)
    return jnp.max(jnp.where(spans.touched, hi, -jnp.inf)), jnp.any(spans.touched & off_map)


def update_columns(index: TerrainIndex, terrain: Terrain, robot: Robot, start, width: int) -> TerrainIndex:
    """The index of ``terrain`` when only its columns ``start .. start + width - 1`` (along x) changed since
    ``index`` was built: those columns rebuilt, the others kept. Equal to ``index_terrain(terrain, robot)``
    bit for bit: every table is computed column by column (prefix counts and span maxima along y, edge
    padding, window sums per padded column), so a column's entries depend on that column alone (and the
    padding's copies of the first and last columns are copied again).

    Args:
      index: the terrain's index before the change (:func:`index_terrain` of the same grid and robot).
      terrain: the changed terrain (same shape, resolution and ``has_height``).
      robot: the robot the index was built for (its static ``max_radius`` sizes the padding).
      start: first changed column (int, may be traced; ``0 <= start <= nx - width``).
      width: number of columns rebuilt (static: one program per width).

    Returns:
      :class:`TerrainIndex`.
    """
    return _update_columns_jit(index, terrain, robot, start, width=width)


def _update_columns(index: TerrainIndex, terrain: Terrain, robot: Robot, start, width: int) -> TerrainIndex:
    nx = terrain.shape[0]
    start = jnp.asarray(start, jnp.int32)
    cols = lambda a: lax.dynamic_slice_in_dim(a, start, width, 0)  # noqa: E731
    part = index_terrain(terrain.replace(height=cols(terrain.height), free=cols(terrain.free)), robot)
    p = index.pad

    def put(old, new, at, axis=0):
        return lax.dynamic_update_slice_in_dim(old, new, at, axis)

    def edges(a):  # the edge padding along x: copies of the first and last map columns
        left = jnp.broadcast_to(a[p:p + 1], (p,) + a.shape[1:])
        right = jnp.broadcast_to(a[p + nx - 1:p + nx], (p,) + a.shape[1:])
        return jnp.concatenate([left, a[p:p + nx], right], 0)

    mid = lambda a: a[p:p + width]  # noqa: E731  the part's padded columns that are map columns
    return TerrainIndex(
        obstacles_before=put(index.obstacles_before, part.obstacles_before, start),
        height_max=put(index.height_max, part.height_max, start, axis=1),
        height_padded=edges(put(index.height_padded, mid(part.height_padded), start + p)),
        height_sums=edges(put(index.height_sums, mid(part.height_sums), start + p)),
        height_block_first=edges(put(index.height_block_first, mid(part.height_block_first), start + p)),
        pad=p,
    )


_update_columns_jit = jax.jit(_update_columns, static_argnames=("width",))
