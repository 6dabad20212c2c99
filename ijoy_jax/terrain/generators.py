"""Procedural terrain generators: thousands of random terrains from one jitted call.

Eleven families, each a pure function ``family(key, params, *, shape, resolution,
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
  * ``corridor`` (:class:`CorridorParams`): a narrowing corridor with dead-end pockets and a closed or open end.
  * ``stone_path`` (:class:`StonePathParams`): two staggered rows of stepping stones, jittered spacing.

What is static and what is traced. Every number in a parameter pytree is a
leaf (a scalar per terrain; metres, radians, counts), so changing it never
recompiles and ``jax.vmap`` can batch it. Only the grid ``shape``,
``resolution``, the 2D/2.5D flag ``has_height`` and the maximum object count
``max_count`` are static. :func:`batch` vmaps a family over keys and
(optionally per-terrain) parameters; :data:`FAMILIES` and :func:`generate`
name families by string for sweeps; :func:`objects` returns the posed boxes and
cylinders of the object families (for a simulator), which the generators
rasterise with :func:`ijoy_jax.terrain.scene.rasterize`.

The registry. Each entry of :data:`FAMILIES` is a
:class:`~ijoy_jax.terrain.family.Family` that carries everything a caller
needs: generator, parameter class, default ``max_count``, posed objects,
the validation of parameter values (:meth:`~ijoy_jax.terrain.family.Family.check`,
:meth:`~ijoy_jax.terrain.family.Family.validate`) and its extra per-scenario
metrics (:meth:`~ijoy_jax.terrain.family.Family.metrics`; bars: whether the
robot got past them; all columns in :data:`METRIC_NAMES`). The families live
in :mod:`ijoy_jax.terrain.objects` (walls, obstacles, bars, platforms) and
:mod:`ijoy_jax.terrain.surfaces` (flat, stairs, stepping stones, slope,
rough) and :mod:`ijoy_jax.terrain.passages` (corridor, stone path); this module names them and re-exports
their public names.

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

import functools
from collections.abc import Mapping
from types import MappingProxyType

import jax
import numpy as np

from ijoy_jax.terrain.family import Family, make_grid
from ijoy_jax.terrain.grid import Terrain
from ijoy_jax.terrain.objects import BARS, OBSTACLES, PLATFORMS, WALLS
from ijoy_jax.terrain.objects import BarParams as BarParams
from ijoy_jax.terrain.objects import Objects as Objects
from ijoy_jax.terrain.objects import ObstacleParams as ObstacleParams
from ijoy_jax.terrain.objects import PlatformParams as PlatformParams
from ijoy_jax.terrain.objects import WallParams as WallParams
from ijoy_jax.terrain.objects import bars as bars
from ijoy_jax.terrain.objects import obstacles as obstacles
from ijoy_jax.terrain.objects import platforms as platforms
from ijoy_jax.terrain.objects import walls as walls
from ijoy_jax.terrain.passages import CORRIDOR, STONE_PATH
from ijoy_jax.terrain.passages import CorridorParams as CorridorParams
from ijoy_jax.terrain.passages import StonePathParams as StonePathParams
from ijoy_jax.terrain.passages import corridor as corridor
from ijoy_jax.terrain.passages import stone_path as stone_path
from ijoy_jax.terrain.surfaces import FLAT, ROUGH, SLOPE, STAIRS, STEPPING_STONES
from ijoy_jax.terrain.surfaces import FlatParams as FlatParams
from ijoy_jax.terrain.surfaces import RoughParams as RoughParams
from ijoy_jax.terrain.surfaces import SlopeParams as SlopeParams
from ijoy_jax.terrain.surfaces import StairParams as StairParams
from ijoy_jax.terrain.surfaces import SteppingStoneParams as SteppingStoneParams
from ijoy_jax.terrain.surfaces import flat as flat
from ijoy_jax.terrain.surfaces import rough as rough
from ijoy_jax.terrain.surfaces import slope as slope
from ijoy_jax.terrain.surfaces import stairs as stairs
from ijoy_jax.terrain.surfaces import stepping_stones as stepping_stones

__all__ = [
    "FAMILIES",
    "METRIC_NAMES",
    "BarParams",
    "CorridorParams",
    "Family",
    "FlatParams",
    "ObstacleParams",
    "Objects",
    "PlatformParams",
    "RoughParams",
    "SlopeParams",
    "StairParams",
    "SteppingStoneParams",
    "StonePathParams",
    "WallParams",
    "bars",
    "batch",
    "corridor",
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
    "stone_path",
    "walls",
]


# --------------------------------------------------------------------------- registry

FAMILIES: Mapping[str, Family] = MappingProxyType(
    {fam.name: fam for fam in (FLAT, WALLS, OBSTACLES, BARS, PLATFORMS, STAIRS, STEPPING_STONES, SLOPE, ROUGH,
                               CORRIDOR, STONE_PATH)}
)
"""Every family by name (see :class:`~ijoy_jax.terrain.family.Family`); read-only."""

METRIC_NAMES: tuple[str, ...] = tuple(dict.fromkeys(m for fam in FAMILIES.values() for m in fam.metric_names))
"""Every family's extra per-scenario metric columns (:attr:`Family.metric_names`), in registry order."""


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
      family: a family with objects: "walls", "obstacles", "bars" or "platforms".
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
    fam = FAMILIES.get(family) if isinstance(family, str) else None
    if fam is None or fam.objects is None:
        with_objects = sorted(name for name, f in FAMILIES.items() if f.objects is not None)
        raise ValueError(f"objects() takes one of {with_objects}, got {family!r}")
    n = fam.max_count if max_count is None else max_count
    return fam.objects(key, params, shape=shape, resolution=resolution, origin=origin, max_count=n)


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
    return make_grid(shape, resolution, origin, False).start(params)
