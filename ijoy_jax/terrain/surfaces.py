"""Surface families: flat, stairs, slope, rough ground and stepping stones, sampled at cell centres.

Each family is a generator ``family(key, params, *, shape, resolution,
has_height, origin[, max_count]) -> Terrain``, its parameter class and its
registry record (:data:`FLAT`, :data:`STAIRS`, :data:`SLOPE`, :data:`ROUGH`,
:data:`STEPPING_STONES`). Conventions (start zone, 2D vs 2.5D, keys) are in
:mod:`ijoy_jax.terrain.generators`.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp

from ijoy_jax.prng import as_key
from ijoy_jax.struct import pytree_dataclass
from ijoy_jax.terrain.family import (
    COUNT,
    NONNEG,
    Family,
    Grid,
    Rule,
    StartZone,
    check_max,
    check_params,
    f32,
    make_grid,
    param,
    uniform,
)
from ijoy_jax.terrain.grid import Terrain

__all__ = [
    "FLAT",
    "ROUGH",
    "SLOPE",
    "STAIRS",
    "STEPPING_STONES",
    "FlatParams",
    "RoughParams",
    "SlopeParams",
    "StairParams",
    "SteppingStoneParams",
    "flat",
    "rough",
    "slope",
    "stairs",
    "stepping_stones",
]

# Points within this distance (metres) of a stone's edge count as on it: absorbs
# float32 rounding of cell corners (1e-7 m at a few metres) so stones aligned
# with cell edges keep their edge cells; far below any physical tolerance.
_STONE_EPS = 1e-5
# Slopes are clipped to this inclination (radians, 80 deg) so heights stay finite.
_MAX_SLOPE = math.radians(80.0)
# Default static number of stair steps (``max_count``).
_MAX_STEPS = 16


@pytree_dataclass
class FlatParams(StartZone):
    """Parameters of :func:`flat` (all leaves scalars per terrain).

    Fields::

      elevation: height of the floor, metres (2.5D only).
      start_x, start_y, start_radius: start zone (fractions, fractions, metres).
    """

    elevation: Any = param(0.0)



@pytree_dataclass
class StairParams(StartZone):
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

    rise: Any = param(0.1)
    run: Any = param(0.3, NONNEG)
    num_steps: Any = param(5, COUNT)
    first: Any = param(0.5)
    direction: Any = param(0.0)
    rise_jitter: Any = param(0.0, NONNEG)
    run_jitter: Any = param(0.0, NONNEG)



@pytree_dataclass
class SteppingStoneParams(StartZone):
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

    size: Any = param(0.3, NONNEG)
    spacing: Any = param(0.4, NONNEG)
    jitter: Any = param(0.03, NONNEG)
    yaw_jitter: Any = param(0.0, NONNEG)
    top: Any = param(0.0)
    top_jitter: Any = param(0.0, NONNEG)
    gap_height: Any = param(-0.5)



@pytree_dataclass
class SlopeParams(StartZone):
    """Parameters of :func:`slope`: ``h(p) = tan(angle) * (p - start) . (cos direction, sin direction)``.

    Fields (radians)::

      angle: inclination, radians (positive rises along ``direction``;
        clipped to +-80 deg so heights stay finite).
      direction: direction of steepest ascent in the map plane, radians (0 = +x).
      start_x, start_y, start_radius: start zone (the plane is 0 at the start point).
    """

    angle: Any = param(0.1)
    direction: Any = param(0.0)



@pytree_dataclass
class RoughParams(StartZone):
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

    amplitude: Any = param(0.02, NONNEG)
    correlation_length: Any = param(0.1, NONNEG)
    obstacle_above: Any = param(math.inf, Rule(allow_inf=True))


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
    params = check_params(params, FlatParams)
    grid = make_grid(shape, resolution, origin, has_height)
    return grid.terrain(height=f32(params.elevation))


def _along(grid: Grid, params, direction) -> jax.Array:
    """(nx, ny) signed distance of cell centres from the start point along ``direction``, metres."""
    u = jnp.stack([jnp.cos(f32(direction)), jnp.sin(f32(direction))])
    return jnp.sum((grid.centres() - grid.start(params)) * u, axis=-1)


def stairs(
    key,
    params: StairParams | None = None,
    *,
    shape=(200, 200),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
    max_count: int = _MAX_STEPS,
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
    params = check_params(params, StairParams)
    grid = make_grid(shape, resolution, origin, has_height)
    n = check_max(max_count)
    u = 2.0 * uniform(as_key(key), (n, 2)) - 1.0  # U[-1, 1)
    rise = f32(params.rise) + u[:, 0] * f32(params.rise_jitter)
    run = jnp.maximum(f32(params.run) + u[:, 1] * f32(params.run_jitter), 0.0)
    first = jnp.maximum(f32(params.first), f32(params.start_radius))
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
    params = check_params(params, SlopeParams)
    grid = make_grid(shape, resolution, origin, has_height)
    angle = jnp.clip(f32(params.angle), -_MAX_SLOPE, _MAX_SLOPE)
    return grid.terrain(height=jnp.tan(angle) * _along(grid, params, params.direction))


def _gaussian_field(key, grid: Grid, correlation_length) -> jax.Array:
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
    a = (jnp.pi * f32(correlation_length)) ** 2
    amp = jnp.where(dc, 0.0, jnp.exp(-a * (f2 - f2min)))
    # White noise of unit variance filtered by amp has variance mean(amp^2).
    norm = jnp.sqrt(jnp.mean(amp * amp))
    noise = uniform(key, (nx, ny), normal=True)
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
    params = check_params(params, RoughParams)
    grid = make_grid(shape, resolution, origin, has_height)
    field = f32(params.amplitude) * _gaussian_field(as_key(key), grid, params.correlation_length)
    r = f32(params.start_radius)
    dist = jnp.sqrt(jnp.sum((grid.centres() - grid.start(params)) ** 2, axis=-1))
    ramp = jnp.maximum(jnp.abs(f32(params.correlation_length)), grid.res)
    taper = jnp.where(r > 0, jnp.clip((dist - r) / ramp, 0.0, 1.0), 1.0)
    height = taper * field
    free = (height <= f32(params.obstacle_above)) | grid.in_start_zone(params)
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
    params = check_params(params, SteppingStoneParams)
    grid = make_grid(shape, resolution, origin, has_height)
    nx, ny = grid.shape
    spacing = jnp.maximum(f32(params.spacing), grid.res)
    size = f32(params.size)
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
    table = 2.0 * uniform(as_key(key), (nx, ny, 4)) - 1.0  # U[-1, 1)
    u = table[ix[:, None], iy[None, :]]  # (nx, ny, 4): x, y offsets, yaw, top
    yaw = u[..., 2] * f32(params.yaw_jitter)
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    slack = jnp.maximum(0.5 * (spacing - size * (jnp.abs(c) + jnp.abs(s))), 0.0)
    shift = jnp.minimum(jnp.abs(f32(params.jitter)), slack)
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
    top = f32(params.top)
    height = jnp.where(on_stone, top + u[..., 3] * f32(params.top_jitter), f32(params.gap_height))
    height = jnp.where(pad, top, height)
    free = jnp.ones(grid.shape, bool) if has_height else on_stone | pad
    return grid.terrain(height=height, free=free)



# --------------------------------------------------------------------------- registry records

FLAT = Family(name="flat", generator=flat, params=FlatParams)
STAIRS = Family(name="stairs", generator=stairs, params=StairParams, max_count=_MAX_STEPS)
STEPPING_STONES = Family(name="stepping_stones", generator=stepping_stones, params=SteppingStoneParams)
SLOPE = Family(name="slope", generator=slope, params=SlopeParams)
ROUGH = Family(name="rough", generator=rough, params=RoughParams)
