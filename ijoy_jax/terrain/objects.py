"""Object families: walls, obstacles, bars and platforms, as posed boxes and cylinders.

Each object family is a builder ``build(key, params, grid, n) -> Objects``
(where its objects go) and a parameter class; :func:`object_family` turns the
pair into a registered :class:`~ijoy_jax.terrain.family.Family` whose
generator rasterises the objects with
:func:`ijoy_jax.terrain.scene.rasterize` and whose ``objects`` returns them
(for a simulator or a metric). Bars add the per-scenario metric
:func:`bar_crossings` (did the robot get past them). Conventions (start zone,
2D vs 2.5D, keys) are in :mod:`ijoy_jax.terrain.generators`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ijoy_jax.prng import as_key
from ijoy_jax.struct import pytree_dataclass
from ijoy_jax.terrain import scene
from ijoy_jax.terrain.family import (
    ANY,
    COUNT,
    NONNEG,
    Family,
    Grid,
    Rule,
    StartZone,
    check_max,
    check_params,
    f32,
    lerp,
    make_grid,
    param,
    uniform,
)
from ijoy_jax.terrain.grid import Terrain

__all__ = [
    "BARS",
    "OBSTACLES",
    "PLATFORMS",
    "WALLS",
    "BarParams",
    "ObstacleParams",
    "Objects",
    "PlatformParams",
    "WallParams",
    "bar_crossings",
    "bars",
    "object_family",
    "obstacles",
    "platforms",
    "walls",
]

# Candidate centres tried per object before it is dropped for hitting the start zone.
_TRIES = 16


# --------------------------------------------------------------------------- parameters


@pytree_dataclass
class WallParams(StartZone):
    """Parameters of :func:`walls`: walls and blockages as tall obstacle boxes.

    Each of ``count`` boxes has a length along its yaw and a thickness across
    it, both uniform in their ranges, a yaw uniform in ``[yaw_min, yaw_max]``
    and a centre uniform over the map, kept clear of the start zone. A thin
    box is a wall, a thick one a blockage.

    Fields (metres, radians)::

      count: number of boxes (int; clipped to ``[0, max_count]``).
      length_min, length_max: extent along the box's yaw, metres.
      thickness_min, thickness_max: extent across it, metres.
      yaw_min, yaw_max: heading of the length axis, radians.
      top: elevation of the top face, metres (2.5D; always an obstacle).
      start_x, start_y, start_radius: start zone.
    """

    count: Any = param(3, COUNT)
    length_min: Any = param(0.5, Rule(lo=0.0, at_most="length_max"))
    length_max: Any = param(1.5, NONNEG)
    thickness_min: Any = param(0.1, Rule(lo=0.0, at_most="thickness_max"))
    thickness_max: Any = param(0.4, NONNEG)
    yaw_min: Any = param(0.0, Rule(at_most="yaw_max"))
    yaw_max: Any = param(math.pi)
    top: Any = param(1.0)


@pytree_dataclass
class ObstacleParams(StartZone):
    """Parameters of :func:`obstacles`: small boxes and cylinders (obstacles).

    Each object is a cylinder with probability ``cylinder_fraction``, else a
    box; its size (box edges, each drawn separately, or cylinder diameter) is
    uniform in ``[size_min, size_max]`` and its top uniform in
    ``[top_min, top_max]``. Defaults suit HRP-2 (foot 24.2 x 13 cm, steps up
    to 20 cm): small enough to step over or around.

    Fields (metres, radians)::

      count: number of objects (int; clipped to ``[0, max_count]``).
      size_min, size_max: box edge or cylinder diameter, metres.
      top_min, top_max: top elevation, metres (2.5D).
      cylinder_fraction: probability that an object is a cylinder, in [0, 1].
      yaw_min, yaw_max: box heading, radians.
      start_x, start_y, start_radius: start zone.
    """

    count: Any = param(8, COUNT)
    size_min: Any = param(0.04, Rule(lo=0.0, at_most="size_max"))
    size_max: Any = param(0.15, NONNEG)
    top_min: Any = param(0.02, Rule(lo=0.0, at_most="top_max"))
    top_max: Any = param(0.15, NONNEG)
    cylinder_fraction: Any = param(0.5, Rule(lo=0.0, hi=1.0))
    yaw_min: Any = param(0.0, Rule(at_most="yaw_max"))
    yaw_max: Any = param(math.pi)


@pytree_dataclass
class BarParams(StartZone):
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

    count: Any = param(2, COUNT)
    first: Any = param(0.6)
    spacing: Any = param(0.8, NONNEG)
    width: Any = param(0.05, NONNEG)
    top: Any = param(0.05)
    position_jitter: Any = param(0.05, NONNEG)
    yaw_jitter: Any = param(0.0, NONNEG)
    lane: Any = param(0.0, Rule(lo=-1.0, hi=1.0))
    lane_gap: Any = param(0.0, NONNEG)


@pytree_dataclass
class PlatformParams(StartZone):
    """Parameters of :func:`platforms`: raised boxes to step onto.

    On 2.5D maps platforms are surfaces (free, raised to their height); where
    they overlap the higher wins. On 2D maps they are obstacles.

    Fields (metres, radians)::

      count: number of platforms (int; clipped to ``[0, max_count]``).
      length_min, length_max, width_min, width_max: extents, metres.
      height_min, height_max: top elevation, metres (set equal for a given height).
      yaw_min, yaw_max: heading, radians.
      start_x, start_y, start_radius: start zone.
    """

    count: Any = param(2, COUNT)
    length_min: Any = param(0.4, Rule(lo=0.0, at_most="length_max"))
    length_max: Any = param(1.0, NONNEG)
    width_min: Any = param(0.4, Rule(lo=0.0, at_most="width_max"))
    width_max: Any = param(1.0, NONNEG)
    height_min: Any = param(0.05, Rule(lo=0.0, at_most="height_max"))
    height_max: Any = param(0.15, NONNEG)
    yaw_min: Any = param(0.0, Rule(at_most="yaw_max"))
    yaw_max: Any = param(math.pi, ANY)


# --------------------------------------------------------------------------- posed objects


class Objects(NamedTuple):
    """Posed objects of one terrain, in :func:`ijoy_jax.terrain.scene.rasterize`'s format.

    Fields (metres, radians)::

      boxes: (B, 6) float32 ``x, y, yaw, length, width, top``; unused rows are zero.
      cylinders: (C, 4) float32 ``x, y, radius, top``; unused rows are zero.
      obstacle: (B + C,) bool, boxes first: True for obstacles, False for surfaces.

    Bars are ``2 * (map width + map height)`` long so that they cross the map at
    any tilt; a simulator may clip them to the map.
    """

    boxes: jax.Array
    cylinders: jax.Array
    obstacle: jax.Array


def _rect_distance(rel, yaw, length, width) -> jax.Array:
    """Distance from a point to a rotated rectangle; ``rel`` (..., 2) is point minus centre."""
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    u = c * rel[..., 0] + s * rel[..., 1]
    v = -s * rel[..., 0] + c * rel[..., 1]
    du = jnp.maximum(jnp.abs(u) - 0.5 * length, 0.0)
    dv = jnp.maximum(jnp.abs(v) - 0.5 * width, 0.0)
    return jnp.sqrt(du * du + dv * dv)  # not differentiated: placement is random


def _place(u, grid: Grid, params, distance: Callable[[jax.Array], jax.Array]):
    """Centres (n, 2) uniform over the map, each the first of _TRIES candidates clear of the start zone.

    ``u`` (n, _TRIES, 2) are U[0, 1) draws for the candidates.

    ``distance(rel)`` maps (n, T, 2) start-minus-centre offsets to (n, T)
    distances from the start point to the object. A candidate is clear if that
    distance is >= start_radius + resolution: then every cell the object
    overlaps has its centre (within resolution / sqrt 2 of the object) outside
    the start zone. Returns (centres, placed) with placed (n,) bool.
    """
    cand = grid.origin + u * grid.size
    r = f32(params.start_radius)
    clear = (distance(grid.start(params) - cand) >= r + grid.res) | (r <= 0)
    first = jnp.argmax(clear, axis=1)
    centre = jnp.take_along_axis(cand, first[:, None, None], axis=1)[:, 0]
    return centre, jnp.any(clear, axis=1)


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


def _walls_objects(key, params: WallParams, grid: Grid, n: int) -> Objects:
    u = uniform(key, (n, 3 + 2 * _TRIES))
    length = lerp(u[:, 0], params.length_min, params.length_max)
    width = lerp(u[:, 1], params.thickness_min, params.thickness_max)
    yaw = lerp(u[:, 2], params.yaw_min, params.yaw_max)
    top = jnp.full((n,), f32(params.top))
    where = u[:, 3:].reshape(n, _TRIES, 2)
    return _random_boxes(where, grid, params, params.count, length, width, yaw, top, obstacle=True)


def _platforms_objects(key, params: PlatformParams, grid: Grid, n: int) -> Objects:
    u = uniform(key, (n, 4 + 2 * _TRIES))
    length = lerp(u[:, 0], params.length_min, params.length_max)
    width = lerp(u[:, 1], params.width_min, params.width_max)
    yaw = lerp(u[:, 2], params.yaw_min, params.yaw_max)
    top = lerp(u[:, 3], params.height_min, params.height_max)
    where = u[:, 4:].reshape(n, _TRIES, 2)
    return _random_boxes(where, grid, params, params.count, length, width, yaw, top, obstacle=False)


def _obstacles_objects(key, params: ObstacleParams, grid: Grid, n: int) -> Objects:
    u = uniform(key, (n, 5 + 2 * _TRIES))
    is_cyl = u[:, 0] < f32(params.cylinder_fraction)
    length = lerp(u[:, 1], params.size_min, params.size_max)
    width = lerp(u[:, 2], params.size_min, params.size_max)
    yaw = lerp(u[:, 3], params.yaw_min, params.yaw_max)
    top = lerp(u[:, 4], params.top_min, params.top_max)
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


def _bars_objects(key, params: BarParams, grid: Grid, n: int) -> Objects:
    u = 2.0 * uniform(key, (n, 2)) - 1.0  # U[-1, 1)
    start = grid.start(params)
    j = jnp.arange(n, dtype=jnp.float32)
    x = start[0] + f32(params.first) + j * f32(params.spacing) + u[:, 0] * f32(params.position_jitter)
    yaw = 0.5 * jnp.pi + u[:, 1] * f32(params.yaw_jitter)
    # Centred on the start's y, a bar this long crosses the whole map at any tilt.
    length = jnp.full((n,), 2.0 * jnp.sum(grid.size))
    # A single-lane bar slides along its axis by lane_gap + half its length, to one side only
    # (it still reaches past the map edge on that side).
    shift = jnp.sign(f32(params.lane)) * (f32(params.lane_gap) + 0.5 * length)
    axis = jnp.stack([jnp.cos(yaw), jnp.sin(yaw)], axis=-1)  # (n, 2); +y for an untilted bar
    centre = jnp.stack([x, jnp.full((n,), start[1])], axis=-1) + shift[:, None] * axis
    width = jnp.full((n,), f32(params.width))
    top = jnp.full((n,), f32(params.top))
    r = f32(params.start_radius)
    clear = (_rect_distance(start - centre, yaw, length, width) >= r + grid.res) | (r <= 0)
    keep = clear & (jnp.arange(n) < params.count)
    return Objects(
        _boxes(centre, yaw, length, width, top, keep), jnp.zeros((0, 4), jnp.float32), jnp.ones((n,), bool)
    )


# --------------------------------------------------------------------------- one wrapper for every object family

_ARGS_DOC = """
    Args:
      key: PRNG key or int seed.
      params: :class:`{params}` (None: defaults; {defaults}).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; {has_height}
      origin: (2,) world (x, y) of the map's lower corner, metres.
      max_count: static number of {slots} slots (``count`` is clipped to it; default {max_count}).

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``.{returns}

    Example:
      >>> from ijoy_jax.terrain import generators as gen
{example}
"""


def object_family(name: str, params_cls: type, max_count: int, build: Callable[..., Objects], *, summary: str,
                  doc: dict[str, str], metric_names: tuple[str, ...] = (),
                  scenario_metrics: Callable[..., dict[str, jax.Array]] | None = None) -> Family:
    """A :class:`~ijoy_jax.terrain.family.Family` from an object builder: one wrapper for every object family.

    Args:
      name: the family's name.
      params_cls: its parameter pytree class (with a ``count`` field and a start zone).
      max_count: default static number of object slots (written here once).
      build: ``build(key, params, grid, n) -> Objects`` with ``n`` slots.
      summary: the generator's one-line docstring; doc: the fields of its Args
        section (``defaults``, ``has_height``, ``slots``, ``returns``, ``example``).
      metric_names, scenario_metrics: as in :class:`~ijoy_jax.terrain.family.Family`.

    Returns:
      The family; its ``generator`` rasterises ``build``'s objects with
      :func:`ijoy_jax.terrain.scene.rasterize` and its ``objects`` returns them.
    """

    def generator(key, params=None, *, shape=(200, 200), resolution: float = 0.02, has_height: bool = False,
                  origin=(0.0, 0.0), max_count: int = max_count) -> Terrain:
        params = check_params(params, params_cls)
        grid = make_grid(shape, resolution, origin, has_height)
        objs = build(as_key(key), params, grid, check_max(max_count))
        return scene.rasterize(grid.terrain(), boxes=objs.boxes, cylinders=objs.cylinders, obstacle=objs.obstacle)

    def posed(key, params=None, *, shape=(200, 200), resolution: float = 0.02, origin=(0.0, 0.0),
              max_count: int = max_count) -> Objects:
        params = check_params(params, params_cls)
        return build(as_key(key), params, make_grid(shape, resolution, origin, True), check_max(max_count))

    generator.__name__ = generator.__qualname__ = name
    generator.__module__ = __name__
    generator.__doc__ = summary + "\n" + _ARGS_DOC.format(params=params_cls.__name__, max_count=max_count, **doc)
    posed.__name__ = posed.__qualname__ = f"{name}_objects"
    posed.__module__ = __name__
    posed.__doc__ = f"The posed :class:`Objects` that :func:`{name}` rasterises (same key, params and grid)."
    return Family(name=name, generator=generator, params=params_cls, max_count=max_count, objects=posed,
                  metric_names=metric_names, scenario_metrics=scenario_metrics)


# --------------------------------------------------------------------------- bars: crossing metric


def bar_crossings(boxes, feet, foot_length, foot_width) -> dict[str, jax.Array]:
    """Which bars the robot has got past: both feet wholly beyond the bar's far face at the end.

    A bar is a box row ``(x, y, yaw, length, width, top)`` of
    :func:`ijoy_jax.terrain.generators.objects` (``length == 0``: an empty slot). Its
    far face (the side at larger x) is the line
    ``x_far(y) = x + (y - y_bar) cot(yaw) + (width / 2) / |sin(yaw)|``
    (an untilted bar has yaw = pi/2: ``x_far = x + width / 2``), extended
    over the whole map even for a single-lane bar. A foot at pose
    ``(fx, fy, theta)`` is beyond it when the rear of its footprint
    rectangle, ``fx - (L |cos theta| + W |sin theta|) / 2``, is at or past
    ``x_far`` anywhere over the foot's y extent ``fy +- (L |sin theta| + W |cos theta|) / 2``.

    Args:
      boxes: (n, 6) bar rows, metres and radians.
      feet: (2, 3) final foot poses (world x, y, theta).
      foot_length, foot_width: footprint L x W without margin, metres.

    Returns:
      ``{"bars_crossed": () int32 number of bars crossed by both feet,
      "crossed": () bool, every present bar crossed (True when there is none)}``.
    """
    boxes = jnp.asarray(boxes, jnp.float32)
    feet = jnp.asarray(feet, jnp.float32)
    x, y, yaw, length, width = (boxes[:, i] for i in range(5))
    present = length > 0
    s, c = jnp.sin(yaw), jnp.cos(yaw)
    s = jnp.where(jnp.abs(s) < 1e-6, 1e-6, s)  # a bar along x has no far face across the walk
    cot = c / s
    th = feet[:, 2]
    hx = 0.5 * (foot_length * jnp.abs(jnp.cos(th)) + foot_width * jnp.abs(jnp.sin(th)))
    hy = 0.5 * (foot_length * jnp.abs(jnp.sin(th)) + foot_width * jnp.abs(jnp.cos(th)))
    rear = feet[:, 0] - hx  # (2,)
    far = (x[:, None] + (feet[None, :, 1] - y[:, None]) * cot[:, None] + jnp.abs(cot)[:, None] * hy[None, :]
           + 0.5 * width[:, None] / jnp.abs(s)[:, None])  # (n, 2)
    past = jnp.all(rear[None, :] >= far, axis=1) & present
    return {"bars_crossed": jnp.sum(past).astype(jnp.int32), "crossed": jnp.all(past | ~present)}


def _bar_metrics(key, params, feet, foot_length, foot_width, *, shape, resolution, origin, max_count):
    """:func:`bar_crossings` of the bars the generator rasterised for ``key`` and ``params``."""
    objs = BARS.objects(key, params, shape=shape, resolution=resolution, origin=origin, max_count=max_count)
    return bar_crossings(objs.boxes, feet, foot_length, foot_width)


# --------------------------------------------------------------------------- the four families

WALLS = object_family(
    "walls", WallParams, 8, _walls_objects,
    summary="Walls and blockages: ``params.count`` random obstacle boxes, clear of the start zone.",
    doc=dict(
        defaults="3 boxes 0.5-1.5 m long, 0.1-0.4 m thick",
        has_height="False for a 2D map, True for 2.5D (boxes raised to ``top``).",
        slots="box", returns="",
        example="      >>> t = gen.walls(0, gen.WallParams(count=4), shape=(150, 100))\n"
                "      >>> t.free.shape, bool(t.free.all())\n"
                "      ((150, 100), False)",
    ),
)
OBSTACLES = object_family(
    "obstacles", ObstacleParams, 16, _obstacles_objects,
    summary="Small obstacles: ``params.count`` boxes and cylinders, clear of the start zone.",
    doc=dict(
        defaults="8 objects 4-15 cm, 2-15 cm tall",
        has_height="2.5D raises covered cells to the object's top (obstacles either way).",
        slots="object", returns="",
        example="      >>> t = gen.obstacles(1, shape=(100, 100), has_height=True)\n"
                "      >>> float(t.height.max()) <= 0.15\n"
                "      True",
    ),
)
BARS = object_family(
    "bars", BarParams, 4, _bars_objects,
    summary="Bars to step over: ``params.count`` obstacle bars across +x, ahead of the start point.",
    doc=dict(
        defaults="2 bars 5 cm wide and high, 0.8 m apart",
        has_height="2.5D raises bar cells to ``top`` (obstacles either way).",
        slots="bar",
        returns=" A bar of\n      width w covers ``ceil(w / resolution)`` or one more cells along x.",
        example="      >>> t = gen.bars(0, gen.BarParams(count=1, position_jitter=0.0), shape=(100, 50))\n"
                "      >>> int((~t.free).any(axis=1).sum())   # x in (1.175, 1.225) m: columns 58-61\n"
                "      4",
    ),
    metric_names=("bars_crossed", "crossed"),
    scenario_metrics=_bar_metrics,
)
PLATFORMS = object_family(
    "platforms", PlatformParams, 4, _platforms_objects,
    summary="Raised platforms of given height: ``params.count`` boxes, clear of the start zone.",
    doc=dict(
        defaults="2 platforms 0.4-1 m, 5-15 cm high",
        has_height="2.5D: free surfaces at their height; 2D: obstacles.",
        slots="platform", returns="",
        example="      >>> p = gen.PlatformParams(height_min=0.1, height_max=0.1)\n"
                "      >>> t = gen.platforms(0, p, shape=(150, 150), has_height=True)\n"
                "      >>> round(float(t.height.max()), 3), bool(t.free.all())\n"
                "      (0.1, True)",
    ),
)

walls = WALLS.generator
obstacles = OBSTACLES.generator
bars = BARS.generator
platforms = PLATFORMS.generator
