"""Procedural terrain generators: thousands of random terrains from one jitted call.

Nine families, each a pure function ``family(key, params, *, shape, resolution,
has_height, origin[, max_count]) -> Terrain`` with its own parameter pytree:

  * ``flat`` (:class:`FlatParams`): a level floor.
  * ``walls`` (:class:`WallParams`): walls and blockages (long or thick boxes).
  * ``obstacles`` (:class:`ObstacleParams`): small boxes and cylinders to step over or around.
  * ``bars`` (:class:`BarParams`): bars across the walking direction, to step over.
  * ``platforms`` (:class:`PlatformParams`): raised boxes of given height to step onto.
  * ``stairs`` (:class:`StairParams`): height steps of given rise and run along a direction.
  * ``stepping_stones`` (:class:`SteppingStoneParams`): stones on a jittered lattice among gaps.
  * ``slope`` (:class:`SlopeParams`): an inclined plane of given angle and direction.
  * ``rough`` (:class:`RoughParams`): a smoothed random height field of given RMS and correlation length.

What is static and what is traced. Every number in a parameter pytree is a
leaf (a scalar per terrain; metres, radians, counts), so changing it never
recompiles and ``jax.vmap`` can batch it. Only the grid ``shape``,
``resolution``, the 2D/2.5D flag ``has_height`` and the maximum object count
``max_count`` are static. :func:`batch` vmaps a family over keys and
(optionally per-terrain) parameters; :data:`FAMILIES` and :func:`generate`
name families by string for sweeps; :func:`objects` returns the posed boxes and
cylinders of the object families (for a simulator), which the generators
rasterise with :func:`ijoy_jax.terrain.scene.rasterize`.

Conventions.
  * The robot walks along world +x; bars run across it (along y), stairs and
    slopes rise along ``direction`` (0 = +x).
  * Start zone: every parameter pytree has ``start_x``, ``start_y`` (the start
    point as fractions of the map extent: 0 = the origin side, 1 = the far
    side; default (0.15, 0.5), the middle of the low-x side) and
    ``start_radius`` (metres, default 0.35, which holds HRP-2's double
    stance). Every cell whose *centre* lies within ``start_radius`` of the
    start point is free, and on 2.5D maps it is the family's ground: height 0
    (object families, stairs' bottom landing, rough's flat pad), the stone top
    (stepping stones), the plane (slope) or ``elevation`` (flat).
    :func:`start_point` gives the point in world coordinates.
  * 2D versus 2.5D (static ``has_height``), one mechanism for both: objects
    follow :func:`ijoy_jax.terrain.scene.rasterize` (on a 2D map every object is an
    obstacle, a platform included); a stair's steps are a blockage on a 2D map
    (free only on the bottom landing); stepping stones are free islands among
    obstacle cells in 2D and stones among deep gaps in 2.5D; a 2D slope is a
    free floor (a 2D map stores no elevation); rough noise marks cells above
    ``obstacle_above`` as obstacles in both.
  * Surfaces (stairs, slope, rough, stones) are sampled at cell centres;
    objects cover every cell their footprint overlaps (the conservative
    exact-overlap rule of :mod:`ijoy_jax.terrain.scene`). Stepping stones are the
    cells lying wholly on a stone (conservative for support).
  * Keys: a ``jax.random`` key (typed or raw uint32) or an int seed. Same key
    and parameters give the same terrain. ``flat``, ``slope`` and jitter-free
    ``stairs`` do not use the key (it is kept for a uniform signature).
  * Heights are float32 and finite; ``free`` is bool.

Example:
  >>> import jax, ijoy_jax.terrain.generators as gen
  >>> keys = jax.random.split(jax.random.key(0), 1000)
  >>> params = gen.WallParams(count=jax.numpy.arange(1000) % 5)   # per-terrain count
  >>> maps = jax.jit(lambda k, p: gen.batch("walls", k, p, shape=(100, 100)))(keys, params)
  >>> maps.free.shape
  (1000, 100, 100)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax._struct import pytree_dataclass
from ijoy_jax.prng import as_key
from ijoy_jax.terrain import scene
from ijoy_jax.terrain.grid import Terrain, grid_spec

__all__ = [
    "FAMILIES",
    "BarParams",
    "Family",
    "FlatParams",
    "ObstacleParams",
    "Objects",
    "PlatformParams",
    "RoughParams",
    "SlopeParams",
    "StairParams",
    "SteppingStoneParams",
    "WallParams",
    "bars",
    "batch",
    "flat",
    "generate",
    "objects",
    "obstacles",
    "platforms",
    "rough",
    "slope",
    "stairs",
    "start_point",
    "stepping_stones",
    "walls",
]

# Candidate centres tried per object before it is dropped for hitting the start zone.
_TRIES = 16
# Points within this distance (metres) of a stone's edge count as on it: absorbs
# float32 rounding of cell corners (1e-7 m at a few metres) so stones aligned
# with cell edges keep their edge cells; far below any physical tolerance.
_STONE_EPS = 1e-5
# Slopes are clipped to this inclination (radians, 80 deg) so heights stay finite.
_MAX_SLOPE = math.radians(80.0)


# --------------------------------------------------------------------------- parameters


@dataclasses.dataclass(frozen=True, kw_only=True)
class _StartZone:
    """Keep-clear start zone shared by every family (see the module docstring)."""

    start_x: Any = 0.15  # fraction of the map's x extent from the origin
    start_y: Any = 0.5  # fraction of the map's y extent from the origin
    start_radius: Any = 0.35  # metres; <= 0 disables the zone


@pytree_dataclass
class FlatParams(_StartZone):
    """Parameters of :func:`flat` (all leaves scalars per terrain).

    Fields:
      elevation: height of the floor, metres (2.5D only).
      start_x, start_y, start_radius: start zone (fractions, fractions, metres).
    """

    elevation: Any = 0.0


@pytree_dataclass
class WallParams(_StartZone):
    """Parameters of :func:`walls`: walls and blockages as tall obstacle boxes.

    Each of ``count`` boxes has a length along its yaw and a thickness across
    it, both uniform in their ranges, a yaw uniform in ``[yaw_min, yaw_max]``
    and a centre uniform over the map, kept clear of the start zone. A thin
    box is a wall, a thick one a blockage.

    Fields (metres, radians):
      count: number of boxes (int; clipped to ``[0, max_count]``).
      length_min, length_max: extent along the box's yaw, metres.
      thickness_min, thickness_max: extent across it, metres.
      yaw_min, yaw_max: heading of the length axis, radians.
      top: elevation of the top face, metres (2.5D; always an obstacle).
      start_x, start_y, start_radius: start zone.
    """

    count: Any = 3
    length_min: Any = 0.5
    length_max: Any = 1.5
    thickness_min: Any = 0.1
    thickness_max: Any = 0.4
    yaw_min: Any = 0.0
    yaw_max: Any = math.pi
    top: Any = 1.0


@pytree_dataclass
class ObstacleParams(_StartZone):
    """Parameters of :func:`obstacles`: small boxes and cylinders (obstacles).

    Each object is a cylinder with probability ``cylinder_fraction``, else a
    box; its size (box edges, each drawn separately, or cylinder diameter) is
    uniform in ``[size_min, size_max]`` and its top uniform in
    ``[top_min, top_max]``. Defaults suit HRP-2 (foot 24.2 x 13 cm, steps up
    to 20 cm): small enough to step over or around.

    Fields (metres, radians):
      count: number of objects (int; clipped to ``[0, max_count]``).
      size_min, size_max: box edge or cylinder diameter, metres.
      top_min, top_max: top elevation, metres (2.5D).
      cylinder_fraction: probability that an object is a cylinder, in [0, 1].
      yaw_min, yaw_max: box heading, radians.
      start_x, start_y, start_radius: start zone.
    """

    count: Any = 8
    size_min: Any = 0.04
    size_max: Any = 0.15
    top_min: Any = 0.02
    top_max: Any = 0.15
    cylinder_fraction: Any = 0.5
    yaw_min: Any = 0.0
    yaw_max: Any = math.pi


@pytree_dataclass
class BarParams(_StartZone):
    """Parameters of :func:`bars`: obstacle bars across the walking direction (+x).

    Bar k (k < count) runs along y through the whole map, its centre line at
    ``x = start + first + k * spacing + U(-position_jitter, position_jitter)``
    and tilted from the y axis by ``U(-yaw_jitter, yaw_jitter)``. A bar that
    would reach into the start zone is dropped.

    Single-lane bars (``lane`` = -1 or +1) block one foot's lane only, as in
    the paper's stepping-over experiment (V.B): the bar then runs from
    ``lane_gap`` beside the start point's y (measured along the bar from the
    point where its centre line crosses y = start y) out past the map edge on
    the robot's right (-1, lower y) or left (+1, higher y), so the other foot
    walks past beside it. ``lane = 0`` (default) spans the whole map.

    Fields (metres, radians)::

      count: number of bars (int; clipped to ``[0, max_count]``).
      first: distance along +x from the start point to the first bar, metres.
      spacing: distance between consecutive bars, metres.
      width: bar extent along x (what the foot must clear), metres.
      top: bar top elevation, metres (2.5D; always an obstacle).
      position_jitter: half-range of the uniform x offset, metres.
      yaw_jitter: half-range of the uniform tilt, radians.
      lane: 0 across the whole map (default); -1 only right of the start
        point (lower y), +1 only left of it (higher y); only its sign is used.
      lane_gap: for a single-lane bar, distance from the start point's y to
        the bar's inner end, metres (ignored when ``lane = 0``).
      start_x, start_y, start_radius: start zone.
    """

    count: Any = 2
    first: Any = 0.6
    spacing: Any = 0.8
    width: Any = 0.05
    top: Any = 0.05
    position_jitter: Any = 0.05
    yaw_jitter: Any = 0.0
    lane: Any = 0.0
    lane_gap: Any = 0.0


@pytree_dataclass
class PlatformParams(_StartZone):
    """Parameters of :func:`platforms`: raised boxes to step onto.

    On 2.5D maps platforms are surfaces (free, raised to their height); where
    they overlap the higher wins. On 2D maps they are obstacles.

    Fields (metres, radians):
      count: number of platforms (int; clipped to ``[0, max_count]``).
      length_min, length_max, width_min, width_max: extents, metres.
      height_min, height_max: top elevation, metres (set equal for a given height).
      yaw_min, yaw_max: heading, radians.
      start_x, start_y, start_radius: start zone.
    """

    count: Any = 2
    length_min: Any = 0.4
    length_max: Any = 1.0
    width_min: Any = 0.4
    width_max: Any = 1.0
    height_min: Any = 0.05
    height_max: Any = 0.15
    yaw_min: Any = 0.0
    yaw_max: Any = math.pi


@pytree_dataclass
class StairParams(_StartZone):
    """Parameters of :func:`stairs`: ``num_steps`` height steps along ``direction``.

    With ``d`` the signed distance of a cell centre from the start point along
    ``direction`` and riser j at ``e_j = first' + sum_{i<j} run_i``
    (``first' = max(first, start_radius)``, so the start zone is on the bottom
    landing), the height is ``sum_{j < num_steps, e_j < d} rise_j``; without
    jitter ``rise * clip(ceil((d - first') / run), 0, num_steps)``. After the
    last riser the top landing runs to the map's edge.

    Fields (metres, radians)::

      rise: step height, metres (negative: a descending stair).
      run: tread depth along ``direction``, metres.
      num_steps: number of risers (int; clipped to ``[0, max_count]``).
      first: distance from the start point to the first riser, metres.
      direction: ascent direction in the map plane, radians (0 = +x).
      rise_jitter, run_jitter: half-ranges of uniform per-step offsets, metres
        (runs are clipped at 0).
      start_x, start_y, start_radius: start zone.
    """

    rise: Any = 0.1
    run: Any = 0.3
    num_steps: Any = 5
    first: Any = 0.5
    direction: Any = 0.0
    rise_jitter: Any = 0.0
    run_jitter: Any = 0.0


@pytree_dataclass
class SteppingStoneParams(_StartZone):
    """Parameters of :func:`stepping_stones`: square stones on a jittered square lattice.

    Lattice sites are centred at ``start + (i, j) * spacing``; site (i, j)
    holds one square stone of edge ``size``, yawed by ``U(-yaw_jitter,
    yaw_jitter)`` and shifted per axis by ``U(-1, 1) * min(jitter, slack)``,
    where ``slack = (spacing - size * (|cos yaw| + |sin yaw|)) / 2`` (clipped
    at 0) keeps every stone inside its site, so stones never touch. Meant for
    ``size < spacing`` (a larger stone is cut to its site's square);
    ``spacing`` is clipped to at least the resolution. Without jitter the
    stone fraction is ``(size / spacing)**2``.

    Fields (metres, radians)::

      size: stone edge length, metres (HRP-2's foot with a 2 cm margin needs ~0.29).
      spacing: lattice pitch (centre to centre), metres.
      jitter: maximum centre offset per axis, metres.
      yaw_jitter: maximum stone yaw, radians.
      top, top_jitter: stone top elevation and half-range of its uniform
        per-stone offset, metres (2.5D).
      gap_height: elevation of the gaps between stones, metres (2.5D).
      start_x, start_y, start_radius: start zone (a free pad at ``top``).
    """

    size: Any = 0.3
    spacing: Any = 0.4
    jitter: Any = 0.03
    yaw_jitter: Any = 0.0
    top: Any = 0.0
    top_jitter: Any = 0.0
    gap_height: Any = -0.5


@pytree_dataclass
class SlopeParams(_StartZone):
    """Parameters of :func:`slope`: ``h(p) = tan(angle) * (p - start) . (cos direction, sin direction)``.

    Fields (radians)::

      angle: inclination, radians (positive rises along ``direction``;
        clipped to +-80 deg so heights stay finite).
      direction: direction of steepest ascent in the map plane, radians (0 = +x).
      start_x, start_y, start_radius: start zone (the plane is 0 at the start point).
    """

    angle: Any = 0.1
    direction: Any = 0.0


@pytree_dataclass
class RoughParams(_StartZone):
    """Parameters of :func:`rough`: a stationary Gaussian random height field.

    White noise filtered by a Gaussian in the Fourier domain (periodic over the
    map), its mean (DC term) removed and scaled so that its expected RMS is
    ``amplitude`` and its autocorrelation ``exp(-d**2 / (2 * correlation_length**2))``.
    Within ``start_radius`` the field is 0 and tapers in linearly over one
    correlation length (at least one cell) outside it.

    Fields (metres)::

      amplitude: RMS height, metres (before the start taper).
      correlation_length: ``l`` of the autocorrelation above, metres (0: white noise).
      obstacle_above: cells higher than this are obstacles (2D and 2.5D),
        metres; ``inf`` (default) for none. The start zone stays free.
      start_x, start_y, start_radius: start zone.
    """

    amplitude: Any = 0.02
    correlation_length: Any = 0.1
    obstacle_above: Any = math.inf


# --------------------------------------------------------------------------- grid helpers


class _Grid(NamedTuple):
    shape: tuple[int, int]
    res: float
    origin: jax.Array  # (2,) float32
    has_height: bool

    @property
    def size(self) -> jax.Array:
        return jnp.asarray(self.shape, jnp.float32) * self.res

    def centres(self) -> jax.Array:
        """(nx, ny, 2) world (x, y) of cell centres."""
        nx, ny = self.shape
        gx = self.origin[0] + (jnp.arange(nx, dtype=jnp.float32) + 0.5) * self.res
        gy = self.origin[1] + (jnp.arange(ny, dtype=jnp.float32) + 0.5) * self.res
        return jnp.stack(jnp.meshgrid(gx, gy, indexing="ij"), axis=-1)

    def start(self, params) -> jax.Array:
        frac = jnp.stack([jnp.asarray(params.start_x, jnp.float32), jnp.asarray(params.start_y, jnp.float32)])
        return self.origin + frac * self.size

    def in_start_zone(self, params) -> jax.Array:
        """(nx, ny) bool: cell centres within start_radius of the start point."""
        d = self.centres() - self.start(params)
        r = jnp.asarray(params.start_radius, jnp.float32)
        return (jnp.sum(d * d, axis=-1) <= r * r) & (r > 0)

    def terrain(self, height=None, free=None) -> Terrain:
        """A Terrain on this grid; heights are dropped (zeros) on a 2D grid."""
        if height is None or not self.has_height:
            height = jnp.zeros(self.shape, jnp.float32)
        if free is None:
            free = jnp.ones(self.shape, bool)
        height = jnp.broadcast_to(jnp.asarray(height, jnp.float32), self.shape)
        return Terrain(
            height=height,
            free=jnp.broadcast_to(free, self.shape),
            origin=self.origin,
            resolution=self.res,
            has_height=self.has_height,
        )


def _grid(shape, resolution, origin, has_height) -> _Grid:
    try:
        nx, ny = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape must be two integers (nx, ny), got {shape!r}") from None
    if nx < 1 or ny < 1:
        raise ValueError(f"shape must be positive, got {shape!r}")
    res, origin = grid_spec(resolution, origin)
    return _Grid((nx, ny), res, origin, bool(has_height))


def _check_max(max_count) -> int:
    n = int(max_count)
    if n < 0 or n != max_count:
        raise ValueError(f"max_count must be a non-negative integer, got {max_count!r}")
    return n


def _check_params(params, cls, allow_inf: tuple[str, ...] = ()):
    """Default, type-check and (when concrete) finiteness-check a parameter pytree."""
    if params is None:
        return cls()
    if not isinstance(params, cls):
        raise TypeError(f"expected {cls.__name__}, got {type(params).__name__}")
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if isinstance(value, jax.core.Tracer):
            continue
        a = np.asarray(value, dtype=np.float64)
        if np.any(np.isnan(a)) or (f.name not in allow_inf and not np.all(np.isfinite(a))):
            raise ValueError(f"{cls.__name__}.{f.name} must be finite, got {value!r}")
    return params


def _f32(x) -> jax.Array:
    return jnp.asarray(x, jnp.float32)


def _random(key, shape, normal: bool = False) -> jax.Array:
    """float32 U[0, 1) (or standard normal) draws of ``shape``, from one 1D draw.

    One flat draw per generator, reshaped: XLA on CPU compiles a multi-dimensional
    ``random_bits`` several times slower than a 1D one of the same size.
    """
    size = math.prod(shape)
    draw = jax.random.normal if normal else jax.random.uniform
    return draw(key, (size,), jnp.float32).reshape(shape)


def _lerp(u, lo, hi) -> jax.Array:
    """Map U[0, 1) draws ``u`` to [lo, hi)."""
    return _f32(lo) + (_f32(hi) - _f32(lo)) * u


def _rect_distance(rel, yaw, length, width) -> jax.Array:
    """Distance from a point to a rotated rectangle; ``rel`` (..., 2) is point minus centre."""
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    u = c * rel[..., 0] + s * rel[..., 1]
    v = -s * rel[..., 0] + c * rel[..., 1]
    du = jnp.maximum(jnp.abs(u) - 0.5 * length, 0.0)
    dv = jnp.maximum(jnp.abs(v) - 0.5 * width, 0.0)
    return jnp.sqrt(du * du + dv * dv)  # not differentiated: placement is random


def _place(u, grid: _Grid, params, distance: Callable[[jax.Array], jax.Array]):
    """Centres (n, 2) uniform over the map, each the first of _TRIES candidates clear of the start zone.

    ``u`` (n, _TRIES, 2) are U[0, 1) draws for the candidates.

    ``distance(rel)`` maps (n, T, 2) start-minus-centre offsets to (n, T)
    distances from the start point to the object. A candidate is clear if that
    distance is >= start_radius + resolution: then every cell the object
    overlaps has its centre (within resolution / sqrt 2 of the object) outside
    the start zone. Returns (centres, placed) with placed (n,) bool.
    """
    cand = grid.origin + u * grid.size
    r = _f32(params.start_radius)
    clear = (distance(grid.start(params) - cand) >= r + grid.res) | (r <= 0)
    first = jnp.argmax(clear, axis=1)
    centre = jnp.take_along_axis(cand, first[:, None, None], axis=1)[:, 0]
    return centre, jnp.any(clear, axis=1)


class Objects(NamedTuple):
    """Posed objects of one terrain, in :func:`ijoy_jax.terrain.scene.rasterize`'s format.

    Fields (metres, radians):
      boxes: (B, 6) float32 ``x, y, yaw, length, width, top``; unused rows are zero.
      cylinders: (C, 4) float32 ``x, y, radius, top``; unused rows are zero.
      obstacle: (B + C,) bool, boxes first: True for obstacles, False for surfaces.

    Bars are ``2 * (map width + map height)`` long so that they cross the map at
    any tilt; a simulator may clip them to the map.
    """

    boxes: jax.Array
    cylinders: jax.Array
    obstacle: jax.Array


def _boxes(centre, yaw, length, width, top, keep) -> jax.Array:
    """(n, 6) box rows; rows not kept are all zero (rasterise to nothing)."""
    rows = jnp.stack([centre[:, 0], centre[:, 1], yaw, length, width, top], axis=-1)
    return jnp.where(keep[:, None], rows, 0.0).astype(jnp.float32)


def _random_boxes(u, grid, params, count, length, width, yaw, top, obstacle: bool) -> Objects:
    """(n,) boxes with given sizes, placed clear of the start zone by draws ``u`` (n, _TRIES, 2)."""
    n = length.shape[0]

    def distance(rel):
        return _rect_distance(rel, yaw[:, None], length[:, None], width[:, None])

    centre, placed = _place(u, grid, params, distance)
    keep = placed & (jnp.arange(n) < count)
    return Objects(
        _boxes(centre, yaw, length, width, top, keep),
        jnp.zeros((0, 4), jnp.float32),
        jnp.full((n,), obstacle),
    )


def _walls_objects(key, params: WallParams, grid: _Grid, n: int) -> Objects:
    u = _random(key, (n, 3 + 2 * _TRIES))
    length = _lerp(u[:, 0], params.length_min, params.length_max)
    width = _lerp(u[:, 1], params.thickness_min, params.thickness_max)
    yaw = _lerp(u[:, 2], params.yaw_min, params.yaw_max)
    top = jnp.full((n,), _f32(params.top))
    where = u[:, 3:].reshape(n, _TRIES, 2)
    return _random_boxes(where, grid, params, params.count, length, width, yaw, top, obstacle=True)


def _platforms_objects(key, params: PlatformParams, grid: _Grid, n: int) -> Objects:
    u = _random(key, (n, 4 + 2 * _TRIES))
    length = _lerp(u[:, 0], params.length_min, params.length_max)
    width = _lerp(u[:, 1], params.width_min, params.width_max)
    yaw = _lerp(u[:, 2], params.yaw_min, params.yaw_max)
    top = _lerp(u[:, 3], params.height_min, params.height_max)
    where = u[:, 4:].reshape(n, _TRIES, 2)
    return _random_boxes(where, grid, params, params.count, length, width, yaw, top, obstacle=False)


def _obstacles_objects(key, params: ObstacleParams, grid: _Grid, n: int) -> Objects:
    u = _random(key, (n, 5 + 2 * _TRIES))
    is_cyl = u[:, 0] < _f32(params.cylinder_fraction)
    length = _lerp(u[:, 1], params.size_min, params.size_max)
    width = _lerp(u[:, 2], params.size_min, params.size_max)
    yaw = _lerp(u[:, 3], params.yaw_min, params.yaw_max)
    top = _lerp(u[:, 4], params.top_min, params.top_max)
    radius = 0.5 * length

    def distance(rel):
        disc = jnp.maximum(jnp.sqrt(jnp.sum(rel * rel, axis=-1)) - radius[:, None], 0.0)
        box = _rect_distance(rel, yaw[:, None], length[:, None], width[:, None])
        return jnp.where(is_cyl[:, None], disc, box)

    centre, placed = _place(u[:, 5:].reshape(n, _TRIES, 2), grid, params, distance)
    keep = placed & (jnp.arange(n) < params.count)
    boxes = _boxes(centre, yaw, length, width, top, keep & ~is_cyl)
    cyl = jnp.stack([centre[:, 0], centre[:, 1], radius, top], axis=-1)
    cyl = jnp.where((keep & is_cyl)[:, None], cyl, 0.0).astype(jnp.float32)
    return Objects(boxes, cyl, jnp.ones((2 * n,), bool))


def _bars_objects(key, params: BarParams, grid: _Grid, n: int) -> Objects:
    u = 2.0 * _random(key, (n, 2)) - 1.0  # U[-1, 1)
    start = grid.start(params)
    j = jnp.arange(n, dtype=jnp.float32)
    x = start[0] + _f32(params.first) + j * _f32(params.spacing) + u[:, 0] * _f32(params.position_jitter)
    yaw = 0.5 * jnp.pi + u[:, 1] * _f32(params.yaw_jitter)
    # Centred on the start's y, a bar this long crosses the whole map at any tilt.
    length = jnp.full((n,), 2.0 * jnp.sum(grid.size))
    # A single-lane bar slides along its axis by lane_gap + half its length, to one side only
    # (it still reaches past the map edge on that side).
    shift = jnp.sign(_f32(params.lane)) * (_f32(params.lane_gap) + 0.5 * length)
    axis = jnp.stack([jnp.cos(yaw), jnp.sin(yaw)], axis=-1)  # (n, 2); +y for an untilted bar
    centre = jnp.stack([x, jnp.full((n,), start[1])], axis=-1) + shift[:, None] * axis
    width = jnp.full((n,), _f32(params.width))
    top = jnp.full((n,), _f32(params.top))
    r = _f32(params.start_radius)
    clear = (_rect_distance(start - centre, yaw, length, width) >= r + grid.res) | (r <= 0)
    keep = clear & (jnp.arange(n) < params.count)
    return Objects(
        _boxes(centre, yaw, length, width, top, keep), jnp.zeros((0, 4), jnp.float32), jnp.ones((n,), bool)
    )


def _rasterize(grid: _Grid, objs: Objects) -> Terrain:
    return scene.rasterize(grid.terrain(), boxes=objs.boxes, cylinders=objs.cylinders, obstacle=objs.obstacle)


# --------------------------------------------------------------------------- object families

_OBJECT_FAMILIES = {
    "walls": (_walls_objects, WallParams),
    "obstacles": (_obstacles_objects, ObstacleParams),
    "bars": (_bars_objects, BarParams),
    "platforms": (_platforms_objects, PlatformParams),
}


def objects(
    family: str,
    key,
    params=None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    origin=(0.0, 0.0),
    max_count: int | None = None,
) -> Objects:
    """The posed boxes and cylinders of an object family (what its generator rasterises).

    For a simulator that needs the objects themselves: ``family(key, params,
    ...)`` equals ``scene.rasterize`` of these objects on a flat map.

    Args:
      family: "walls", "obstacles", "bars" or "platforms".
      key: PRNG key or int seed.
      params: the family's parameter pytree (None: defaults).
      shape, resolution, origin: the map's grid (nx, ny), cell size (metres)
        and lower corner (metres); static apart from origin.
      max_count: static number of object slots (None: the family's default).

    Returns:
      :class:`Objects`; walls/bars/platforms have ``max_count`` box rows and no
      cylinders, obstacles have ``max_count`` rows of each.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> objs = gen.objects("walls", 0, gen.WallParams(count=2), shape=(100, 100))
      >>> objs.boxes.shape, int((objs.boxes[:, 3] > 0).sum())
      ((8, 6), 2)
    """
    if family not in _OBJECT_FAMILIES:
        raise ValueError(f"objects() takes one of {sorted(_OBJECT_FAMILIES)}, got {family!r}")
    make, cls = _OBJECT_FAMILIES[family]
    params = _check_params(params, cls)
    n = _check_max(FAMILIES[family].max_count if max_count is None else max_count)
    return make(as_key(key), params, _grid(shape, resolution, origin, True), n)


def walls(
    key,
    params: WallParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
    max_count: int = 8,
) -> Terrain:
    """Walls and blockages: ``params.count`` random obstacle boxes, clear of the start zone.

    Args:
      key: PRNG key or int seed.
      params: :class:`WallParams` (None: defaults; 3 boxes 0.5-1.5 m long, 0.1-0.4 m thick).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; False for a 2D map, True for 2.5D (boxes raised to ``top``).
      origin: (2,) world (x, y) of the map's lower corner, metres.
      max_count: static number of box slots (``count`` is clipped to it).

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> t = gen.walls(0, gen.WallParams(count=4), shape=(150, 100))
      >>> t.free.shape, bool(t.free.all())
      ((150, 100), False)
    """
    params = _check_params(params, WallParams)
    grid = _grid(shape, resolution, origin, has_height)
    return _rasterize(grid, _walls_objects(as_key(key), params, grid, _check_max(max_count)))


def obstacles(
    key,
    params: ObstacleParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
    max_count: int = 16,
) -> Terrain:
    """Small obstacles: ``params.count`` boxes and cylinders, clear of the start zone.

    Args:
      key: PRNG key or int seed.
      params: :class:`ObstacleParams` (None: defaults; 8 objects 4-15 cm, 2-15 cm tall).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; 2.5D raises covered cells to the object's top (obstacles either way).
      origin: (2,) world (x, y) of the map's lower corner, metres.
      max_count: static number of object slots.

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> t = gen.obstacles(1, shape=(100, 100), has_height=True)
      >>> float(t.height.max()) <= 0.15
      True
    """
    params = _check_params(params, ObstacleParams)
    grid = _grid(shape, resolution, origin, has_height)
    return _rasterize(grid, _obstacles_objects(as_key(key), params, grid, _check_max(max_count)))


def bars(
    key,
    params: BarParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
    max_count: int = 4,
) -> Terrain:
    """Bars to step over: ``params.count`` obstacle bars across +x, ahead of the start point.

    Args:
      key: PRNG key or int seed.
      params: :class:`BarParams` (None: defaults; 2 bars 5 cm wide and high, 0.8 m apart).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; 2.5D raises bar cells to ``top`` (obstacles either way).
      origin: (2,) world (x, y) of the map's lower corner, metres.
      max_count: static number of bar slots.

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``. A bar of
      width w covers ``ceil(w / resolution)`` or one more cells along x.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> t = gen.bars(0, gen.BarParams(count=1, position_jitter=0.0), shape=(100, 50))
      >>> int((~t.free).any(axis=1).sum())   # x in (1.175, 1.225) m: columns 58-61
      4
    """
    params = _check_params(params, BarParams)
    grid = _grid(shape, resolution, origin, has_height)
    return _rasterize(grid, _bars_objects(as_key(key), params, grid, _check_max(max_count)))


def platforms(
    key,
    params: PlatformParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
    max_count: int = 4,
) -> Terrain:
    """Raised platforms of given height: ``params.count`` boxes, clear of the start zone.

    Args:
      key: PRNG key or int seed.
      params: :class:`PlatformParams` (None: defaults; 2 platforms 0.4-1 m, 5-15 cm high).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; 2.5D: free surfaces at their height; 2D: obstacles.
      origin: (2,) world (x, y) of the map's lower corner, metres.
      max_count: static number of platform slots.

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> p = gen.PlatformParams(height_min=0.1, height_max=0.1)
      >>> t = gen.platforms(0, p, shape=(150, 150), has_height=True)
      >>> round(float(t.height.max()), 3), bool(t.free.all())
      (0.1, True)
    """
    params = _check_params(params, PlatformParams)
    grid = _grid(shape, resolution, origin, has_height)
    return _rasterize(grid, _platforms_objects(as_key(key), params, grid, _check_max(max_count)))


# --------------------------------------------------------------------------- surface families


def flat(
    key,
    params: FlatParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
) -> Terrain:
    """A level, obstacle-free floor at ``params.elevation`` (the key is unused).

    Args:
      key: PRNG key or int seed (unused; kept for a uniform signature).
      params: :class:`FlatParams` (None: elevation 0).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static 2.5D flag; origin: (2,) lower corner, metres.

    Returns:
      Terrain, all free; height ``elevation`` (2.5D) or 0 (2D).

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> float(gen.flat(0, gen.FlatParams(elevation=0.1), shape=(4, 4), has_height=True).height[0, 0])
      0.1...
    """
    del key
    params = _check_params(params, FlatParams)
    grid = _grid(shape, resolution, origin, has_height)
    return grid.terrain(height=_f32(params.elevation))


def _along(grid: _Grid, params, direction) -> jax.Array:
    """(nx, ny) signed distance of cell centres from the start point along ``direction``, metres."""
    u = jnp.stack([jnp.cos(_f32(direction)), jnp.sin(_f32(direction))])
    return jnp.sum((grid.centres() - grid.start(params)) * u, axis=-1)


def stairs(
    key,
    params: StairParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
    max_count: int = 16,
) -> Terrain:
    """A staircase: ``params.num_steps`` risers of ``rise`` every ``run`` along ``direction``.

    Heights at cell centres follow the closed form in :class:`StairParams`;
    the key only drives ``rise_jitter`` / ``run_jitter``. The start zone lies
    on the bottom landing (height 0).

    Args:
      key: PRNG key or int seed.
      params: :class:`StairParams` (None: 5 steps, 10 cm rise, 30 cm run, along +x).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; 2.5D: all free, stepped heights; 2D: the stair is a
        blockage (cells past the first riser of nonzero rise are obstacles).
      origin: (2,) world (x, y) of the map's lower corner, metres.
      max_count: static maximum number of steps (``num_steps`` is clipped to it).

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> t = gen.stairs(0, gen.StairParams(num_steps=3), shape=(200, 40), has_height=True)
      >>> round(float(t.height.max()), 3)
      0.3
    """
    params = _check_params(params, StairParams)
    grid = _grid(shape, resolution, origin, has_height)
    n = _check_max(max_count)
    u = 2.0 * _random(as_key(key), (n, 2)) - 1.0  # U[-1, 1)
    rise = _f32(params.rise) + u[:, 0] * _f32(params.rise_jitter)
    run = jnp.maximum(_f32(params.run) + u[:, 1] * _f32(params.run_jitter), 0.0)
    first = jnp.maximum(_f32(params.first), _f32(params.start_radius))
    edges = first + jnp.concatenate([jnp.zeros((1,), jnp.float32), jnp.cumsum(run)[:-1]])  # (n,)
    d = _along(grid, params, params.direction)
    passed = (d[None] > edges[:, None, None]) & (jnp.arange(n) < params.num_steps)[:, None, None]
    height = jnp.sum(jnp.where(passed, rise[:, None, None], 0.0), axis=0)
    # A 2D map cannot hold a step: past the first (nonzero) riser the stair is a blockage.
    free = jnp.ones(grid.shape, bool) if has_height else ~jnp.any(passed & (rise != 0)[:, None, None], axis=0)
    return grid.terrain(height=height, free=free)


def slope(
    key,
    params: SlopeParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
) -> Terrain:
    """An inclined plane, 0 at the start point, rising at ``angle`` along ``direction`` (key unused).

    Args:
      key: PRNG key or int seed (unused; kept for a uniform signature).
      params: :class:`SlopeParams` (None: 0.1 rad up along +x).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; a 2D slope is a free floor (2D maps store no elevation).
      origin: (2,) world (x, y) of the map's lower corner, metres.

    Returns:
      Terrain, all free, ``height = tan(angle) * (centre - start) . (cos direction, sin direction)``.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> t = gen.slope(0, gen.SlopeParams(angle=0.1), shape=(100, 10), has_height=True)
      >>> round(float(t.height[1, 0] - t.height[0, 0]) / 0.02, 4)   # tan(0.1)
      0.1003
    """
    del key
    params = _check_params(params, SlopeParams)
    grid = _grid(shape, resolution, origin, has_height)
    angle = jnp.clip(_f32(params.angle), -_MAX_SLOPE, _MAX_SLOPE)
    return grid.terrain(height=jnp.tan(angle) * _along(grid, params, params.direction))


def _gaussian_field(key, grid: _Grid, correlation_length) -> jax.Array:
    """(nx, ny) zero-mean periodic Gaussian field with expected variance 1 and
    autocorrelation ``exp(-d^2 / (2 l^2))``: white noise times the Fourier
    amplitude ``exp(-pi^2 l^2 |f|^2)`` (whose square is the field's spectrum)."""
    nx, ny = grid.shape
    fx = jnp.fft.fftfreq(nx, d=grid.res).astype(jnp.float32)  # cycles per metre
    fy = jnp.fft.fftfreq(ny, d=grid.res).astype(jnp.float32)
    f2 = fx[:, None] ** 2 + fy[None, :] ** 2  # (nx, ny), full spectrum
    dc = f2 == 0.0
    # Relative to the lowest nonzero frequency, so a long correlation length
    # cannot underflow every mode to zero (the scale is normalised away below).
    f2min = jnp.min(jnp.where(dc, jnp.inf, f2)) if nx * ny > 1 else jnp.float32(0.0)
    a = (jnp.pi * _f32(correlation_length)) ** 2
    amp = jnp.where(dc, 0.0, jnp.exp(-a * (f2 - f2min)))
    # White noise of unit variance filtered by amp has variance mean(amp^2).
    norm = jnp.sqrt(jnp.mean(amp * amp))
    noise = _random(key, (nx, ny), normal=True)
    # Real FFT: amp is even in f, and rfft2 keeps the first ny // 2 + 1 columns.
    field = jnp.fft.irfft2(jnp.fft.rfft2(noise) * amp[:, : ny // 2 + 1], s=(nx, ny))
    return (field / jnp.maximum(norm, 1e-30)).astype(jnp.float32)


def rough(
    key,
    params: RoughParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
) -> Terrain:
    """Rough ground: a smoothed Gaussian random field of RMS ``amplitude`` (see :class:`RoughParams`).

    Deterministic given the key (FFT filtering of ``jax.random.normal`` noise).

    Args:
      key: PRNG key or int seed.
      params: :class:`RoughParams` (None: 2 cm RMS, 10 cm correlation length).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; on a 2D map only ``obstacle_above`` has an effect.
      origin: (2,) world (x, y) of the map's lower corner, metres.

    Returns:
      Terrain with (nx, ny) float32 ``height``; ``free`` False where the
      field exceeds ``obstacle_above`` outside the start zone.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> t = gen.rough(0, gen.RoughParams(amplitude=0.03, start_radius=0.0), shape=(128, 128),
      ...               has_height=True)
      >>> round(float(t.height.std()), 2)
      0.03
    """
    params = _check_params(params, RoughParams, allow_inf=("obstacle_above",))
    grid = _grid(shape, resolution, origin, has_height)
    field = _f32(params.amplitude) * _gaussian_field(as_key(key), grid, params.correlation_length)
    r = _f32(params.start_radius)
    dist = jnp.sqrt(jnp.sum((grid.centres() - grid.start(params)) ** 2, axis=-1))
    ramp = jnp.maximum(jnp.abs(_f32(params.correlation_length)), grid.res)
    taper = jnp.where(r > 0, jnp.clip((dist - r) / ramp, 0.0, 1.0), 1.0)
    height = taper * field
    free = (height <= _f32(params.obstacle_above)) | grid.in_start_zone(params)
    return grid.terrain(height=height, free=free)


def stepping_stones(
    key,
    params: SteppingStoneParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
) -> Terrain:
    """Stepping stones: square stones on a jittered lattice, a start pad, gaps elsewhere.

    A cell is on a stone iff all four of its corners are (cells lying wholly
    on a stone, the conservative rule for support). Stone jitter is drawn per
    lattice site from a table the size of the grid, so no static stone count
    is needed.

    Args:
      key: PRNG key or int seed.
      params: :class:`SteppingStoneParams` (None: 30 cm stones at 40 cm pitch).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; 2D: stones and start pad free, gaps obstacles;
        2.5D: all free, stones at their top, gaps at ``gap_height``.
      origin: (2,) world (x, y) of the map's lower corner, metres.

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> p = gen.SteppingStoneParams(size=0.2, spacing=0.4, jitter=0.0, start_radius=0.0)
      >>> t = gen.stepping_stones(0, p, shape=(80, 80), resolution=0.05, origin=(-0.7, -2.1))
      >>> float(t.free.mean())   # (0.2 / 0.4)**2
      0.25
    """
    params = _check_params(params, SteppingStoneParams)
    grid = _grid(shape, resolution, origin, has_height)
    nx, ny = grid.shape
    spacing = jnp.maximum(_f32(params.spacing), grid.res)
    size = _f32(params.size)
    start = grid.start(params)
    # Lattice site of each cell centre (site (0, 0) is centred on the start point);
    # x depends only on ix and y only on iy, so sites are computed per axis.
    cx = grid.origin[0] + (jnp.arange(nx, dtype=jnp.float32) + 0.5) * grid.res
    cy = grid.origin[1] + (jnp.arange(ny, dtype=jnp.float32) + 0.5) * grid.res
    sx = jnp.floor((cx - start[0]) / spacing + 0.5)
    sy = jnp.floor((cy - start[1]) / spacing + 0.5)
    # As spacing >= resolution a map holds at most nx x ny sites: one table entry each.
    ix = jnp.clip(sx - sx[0], 0, nx - 1).astype(jnp.int32)
    iy = jnp.clip(sy - sy[0], 0, ny - 1).astype(jnp.int32)
    table = 2.0 * _random(as_key(key), (nx, ny, 4)) - 1.0  # U[-1, 1)
    u = table[ix[:, None], iy[None, :]]  # (nx, ny, 4): x, y offsets, yaw, top
    yaw = u[..., 2] * _f32(params.yaw_jitter)
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    slack = jnp.maximum(0.5 * (spacing - size * (jnp.abs(c) + jnp.abs(s))), 0.0)
    shift = jnp.minimum(jnp.abs(_f32(params.jitter)), slack)
    stone_x = start[0] + sx[:, None] * spacing + u[..., 0] * shift
    stone_y = start[1] + sy[None, :] * spacing + u[..., 1] * shift
    half = 0.5 * size + _STONE_EPS
    on_stone = jnp.ones(grid.shape, bool)
    for ox in (-0.5, 0.5):
        for oy in (-0.5, 0.5):
            dx = cx[:, None] + ox * grid.res - stone_x
            dy = cy[None, :] + oy * grid.res - stone_y
            on_stone &= (jnp.abs(c * dx + s * dy) <= half) & (jnp.abs(-s * dx + c * dy) <= half)
    on_stone &= size > 0
    pad = grid.in_start_zone(params)
    top = _f32(params.top)
    height = jnp.where(on_stone, top + u[..., 3] * _f32(params.top_jitter), _f32(params.gap_height))
    height = jnp.where(pad, top, height)
    free = jnp.ones(grid.shape, bool) if has_height else on_stone | pad
    return grid.terrain(height=height, free=free)


# --------------------------------------------------------------------------- registry and batching


class Family(NamedTuple):
    """A registered terrain family.

    Fields:
      generator: ``generator(key, params, *, shape, resolution, has_height, origin[, max_count])``.
      params: the parameter pytree class; ``params()`` builds fresh defaults.
      max_count: default static object/step count, or None if the family takes no ``max_count``.
    """

    generator: Callable[..., Terrain]
    params: type
    max_count: int | None


FAMILIES: Mapping[str, Family] = MappingProxyType(
    {
        "flat": Family(flat, FlatParams, None),
        "walls": Family(walls, WallParams, 8),
        "obstacles": Family(obstacles, ObstacleParams, 16),
        "bars": Family(bars, BarParams, 4),
        "platforms": Family(platforms, PlatformParams, 4),
        "stairs": Family(stairs, StairParams, 16),
        "stepping_stones": Family(stepping_stones, SteppingStoneParams, None),
        "slope": Family(slope, SlopeParams, None),
        "rough": Family(rough, RoughParams, None),
    }
)
"""Every family by name (see :class:`Family`); read-only."""


def _family(family) -> Family:
    if isinstance(family, Family):
        return family
    if isinstance(family, str):
        if family not in FAMILIES:
            raise ValueError(f"unknown terrain family {family!r}; known: {sorted(FAMILIES)}")
        return FAMILIES[family]
    for fam in FAMILIES.values():
        if fam.generator is family:
            return fam
    raise ValueError(f"not a terrain family: {family!r}")


def generate(family, key, params=None, **static) -> Terrain:
    """Generate one terrain of a family named by string.

    Args:
      family: a name in :data:`FAMILIES` (or a :class:`Family` or generator function).
      key: PRNG key or int seed.
      params: that family's parameter pytree (None: defaults).
      **static: ``shape``, ``resolution``, ``has_height``, ``origin`` and, for
        families that have it, ``max_count`` (see each generator).

    Returns:
      Terrain.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> t = gen.generate("stairs", 0, shape=(100, 20), has_height=True)
      >>> t.height.dtype
      dtype('float32')
    """
    return _family(family).generator(key, params, **static)


def _auto_axes(params):
    return jax.tree.map(lambda x: 0 if np.ndim(x) > 0 else None, params)


def batch(family, keys, params=None, *, in_axes=None, **static) -> Terrain:
    """Many terrains of one family: ``jax.vmap`` of its generator over keys and parameters.

    Parameter leaves are scalars per terrain, so by default (``in_axes=None``)
    every leaf with a leading axis is batched (per terrain) and every scalar
    leaf is shared: ``WallParams(count=jnp.arange(B))`` varies only the count.
    Pass ``in_axes`` (0, None, or a params-shaped pytree of 0/None) to say it
    explicitly. Wrap the call in ``jax.jit`` (static keywords closed over) to
    compile once: changing parameter values then never recompiles.

    Args:
      family: a name in :data:`FAMILIES` (or a :class:`Family` or generator function).
      keys: (B,) typed PRNG keys or (B, 2) uint32 raw keys, e.g. ``jax.random.split(key, B)``.
      params: parameter pytree with scalar or (B,) leaves (None: shared defaults).
      in_axes: vmap axes for ``params`` (None: inferred as above).
      **static: grid keywords as in :func:`generate`.

    Returns:
      Terrain whose leaves carry a leading batch axis: height (B, nx, ny)
      float32, free (B, nx, ny) bool, origin (B, 2).

    Example:
      >>> import jax, jax.numpy as jnp, ijoy_jax.terrain.generators as gen
      >>> keys = jax.random.split(jax.random.key(0), 4)
      >>> p = gen.StairParams(rise=jnp.array([0.05, 0.1, 0.15, 0.2]))
      >>> t = gen.batch("stairs", keys, p, shape=(100, 20), has_height=True)
      >>> t.height.shape
      (4, 100, 20)
    """
    fam = _family(family)
    if params is None:
        params = fam.params()
    if in_axes is None:
        in_axes = _auto_axes(params)
    fn = functools.partial(fam.generator, **static)
    return jax.vmap(fn, in_axes=(0, in_axes))(keys, params)


def start_point(params, *, shape=(200, 200), resolution: float = 0.02, origin=(0.0, 0.0)) -> jax.Array:
    """(2,) float32 world (x, y) of the start zone's centre, metres.

    Args:
      params: any family's parameter pytree (uses ``start_x``, ``start_y``).
      shape, resolution, origin: the map's grid, as given to the generator.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> gen.start_point(gen.WallParams(), shape=(200, 100)).tolist()
      [0.6000000238418579, 1.0]
    """
    return _grid(shape, resolution, origin, False).start(params)
