"""Constrained passages: a narrowing corridor with dead-end pockets, and a path of staggered stepping stones.

Families where one step is not enough (:mod:`ijoy_jax.lookahead`, :mod:`ijoy_jax.refine`), sampled at cell
centres like the surfaces of :mod:`ijoy_jax.terrain.surfaces` and registered in
:data:`ijoy_jax.terrain.generators.FAMILIES`:

* ``corridor`` (:class:`CorridorParams`): a corridor carved out of solid ground from the start point along
  ``direction``, narrowing linearly, with dead-end pockets in its walls and, optionally, a closed far end.
* ``stone_path`` (:class:`StonePathParams`): two rows of stepping stones along ``direction``, one per foot,
  staggered so that each step goes from a stone of one row to the next stone of the other, with the spacing
  jittered stone by stone. On the square lattice of ``stepping_stones`` both feet stand on stones of one
  column, and reaching the next column needs a step of gap + foot length + 2 margins beyond the other foot:
  never within HRP-2's 0.2 m reach. Here every step is reachable in principle; which footholds leave the next
  stone within reach is what a selector has to get right.

Every number is a traced leaf (a scalar per terrain), so sweeps vmap over them without recompiling; the
static ``max_count`` bounds the corridor's pockets. Conventions (start zone, 2D vs 2.5D, keys) are in
:mod:`ijoy_jax.terrain.generators`.
"""

from __future__ import annotations

import math
from typing import Any

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

__all__ = ["CORRIDOR", "STONE_PATH", "CorridorParams", "StonePathParams", "corridor", "stone_path"]

_MAX_POCKETS = 4  # default static pocket slots of the corridor (``max_count``)
_STONE_EPS = 1e-5  # m: a cell corner this close to a stone's edge counts as on it (float32 rounding)


def _frame(grid: Grid, params, direction):
    """(u, v) of every cell centre in the path frame: u along ``direction`` from the start point, v to its left."""
    d = grid.centres() - grid.start(params)
    c, s = jnp.cos(f32(direction)), jnp.sin(f32(direction))
    return c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]


@pytree_dataclass
class CorridorParams(StartZone):
    """Parameters of :func:`corridor`: a narrowing corridor with dead-end pockets.

    In the path frame (u along ``direction`` from the start point, v to its left) the corridor is free for
    ``-behind <= u <= length`` where ``|v| <= width(u) / 2``, ``width(u)`` going linearly from ``width_start``
    at u = 0 to ``width_end`` at u = length. Pocket k (k < count) is a rectangular recess ``pocket_width``
    along u and ``pocket_depth`` deep, in the left or right wall (a fair coin) at ``u_k`` uniform over
    ``[pocket_from, length - pocket_width / 2]``. Beyond ``length`` the ground is free (an open end) unless
    ``closed`` is 1 (a dead end). Everything else is an obstacle (a wall of height ``top`` on 2.5D maps, the
    floor at 0).

    Fields (metres, radians)::

      length: corridor length from the start point, metres.
      width_start, width_end: free width at u = 0 and u = length, metres.
      behind: how far the corridor reaches behind the start point, metres.
      count: number of pockets (int; clipped to ``[0, max_count]``).
      pocket_width, pocket_depth: pocket extent along and across the corridor, metres.
      pocket_from: nearest pocket centre to the start, metres along u.
      closed: 1 closes the far end (a dead end), 0 leaves it open.
      direction: the corridor's heading, radians (0 = +x).
      top: wall height, metres (2.5D).
      start_x, start_y, start_radius: start zone (free; keep it within the corridor's width, or 0).
    """

    length: Any = param(2.0, NONNEG)
    width_start: Any = param(0.8, NONNEG)
    width_end: Any = param(0.45, NONNEG)
    behind: Any = param(0.4, NONNEG)
    count: Any = param(2, COUNT)
    pocket_width: Any = param(0.35, NONNEG)
    pocket_depth: Any = param(0.3, NONNEG)
    pocket_from: Any = param(0.4, NONNEG)
    closed: Any = param(1.0, Rule(lo=0.0, hi=1.0))
    direction: Any = param(0.0)
    top: Any = param(0.5)
    start_radius: Any = param(0.0, NONNEG)


def corridor(
    key,
    params: CorridorParams | None = None,
    *,
    shape=(200, 100),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
    max_count: int = _MAX_POCKETS,
) -> Terrain:
    """A corridor narrowing from the start point, with dead-end pockets in its walls (:class:`CorridorParams`).

    Args:
      key: PRNG key or int seed (the pockets' places and sides).
      params: :class:`CorridorParams` (None: 2 m from 0.8 to 0.45 m wide, 2 pockets, closed).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; 2D: walls are obstacle cells; 2.5D: walls of height ``top`` (obstacles too).
      origin: (2,) world (x, y) of the map's lower corner, metres.
      max_count: static pocket slots (``count`` is clipped to it; default 4).

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> p = gen.CorridorParams(count=0, width_start=0.62, width_end=0.62, start_x=0.1)
      >>> t = gen.corridor(0, p, shape=(100, 50), resolution=0.04)
      >>> int(t.free[50].sum())   # the cells whose centres lie within 0.31 m of the corridor's axis
      16
    """
    params = check_params(params, CorridorParams)
    grid = make_grid(shape, resolution, origin, has_height)
    n = check_max(max_count)
    u, v = _frame(grid, params, params.direction)
    length = jnp.maximum(f32(params.length), 0.0)
    frac = jnp.clip(u / jnp.maximum(length, grid.res), 0.0, 1.0)
    half = 0.5 * (f32(params.width_start) + frac * (f32(params.width_end) - f32(params.width_start)))
    inside = (u >= -f32(params.behind)) & (u <= length) & (jnp.abs(v) <= half)
    draw = uniform(as_key(key), (max(n, 1), 2))[:n]
    pw, depth = f32(params.pocket_width), f32(params.pocket_depth)
    lo = f32(params.pocket_from)
    hi = jnp.maximum(length - 0.5 * pw, lo)
    centre = lo + draw[:, 0] * (hi - lo)  # (n,)
    side = jnp.where(draw[:, 1] < 0.5, -1.0, 1.0)
    used = jnp.arange(n) < params.count
    sv = side[:, None, None] * v[None]
    in_pocket = (used[:, None, None] & (jnp.abs(u[None] - centre[:, None, None]) <= 0.5 * pw)
                 & (sv >= 0.0) & (sv <= half[None] + depth))
    beyond = (u > length) & (f32(params.closed) < 0.5)
    free = inside | jnp.any(in_pocket, axis=0) | beyond | grid.in_start_zone(params)
    height = jnp.where(free, 0.0, f32(params.top))
    return grid.terrain(height=height, free=free)


@pytree_dataclass
class StonePathParams(StartZone):
    """Parameters of :func:`stone_path`: two staggered rows of stepping stones, one per foot.

    In the path frame (u along ``direction`` from the start point, v to its left) the left row's centre line
    is ``v = +row_gap / 2`` and the right row's ``v = -row_gap / 2``. Stone k of the left row is centred at
    ``u = first + k pitch + shift``, of the right row at ``u = first + stagger + k pitch + shift`` (k >= 0),
    each ``shift`` uniform in ``+-min(pitch_jitter, (pitch - size) / 2)`` per stone, so stones of a row never
    touch and every gap between them is ``pitch - size`` plus the two shifts. Stones are ``size`` along u and
    ``width`` across. The start zone is a pad at the stones' top (default radius 0.23 m: HRP-2's two grown
    footprints standing side by side at the step-in-place width, and little more).

    Fields (metres, radians)::

      size, width: stone extent along and across the path, metres.
      pitch: centre spacing within a row, metres (clipped to at least the resolution).
      pitch_jitter: half-range of each stone's shift along the path, metres.
      stagger: the right row's offset along the path, metres.
      row_gap: lateral distance between the rows' centre lines, metres.
      first: u of the left row's first stone centre, metres.
      direction: the path's heading, radians (0 = +x).
      top, top_jitter: stone top and half-range of its uniform per-stone offset, metres (2.5D).
      gap_height: elevation of the gaps, metres (2.5D).
      start_x, start_y, start_radius: start zone (the pad).
    """

    size: Any = param(0.36, NONNEG)
    width: Any = param(0.22, NONNEG)
    pitch: Any = param(0.40, NONNEG)
    pitch_jitter: Any = param(0.02, NONNEG)
    stagger: Any = param(0.2)
    row_gap: Any = param(0.25, NONNEG)
    first: Any = param(0.2)
    direction: Any = param(0.0)
    top: Any = param(0.0)
    top_jitter: Any = param(0.0, NONNEG)
    gap_height: Any = param(-0.5)
    start_radius: Any = param(0.23, NONNEG)


def stone_path(
    key,
    params: StonePathParams | None = None,
    *,
    shape=(200, 100),
    resolution: float = 0.02,
    has_height: bool = False,
    origin=(0.0, 0.0),
) -> Terrain:
    """Two staggered rows of stepping stones along a path (:class:`StonePathParams`).

    A cell is on a stone iff all four of its corners are (cells lying wholly on a stone, the conservative
    rule for support, as :func:`ijoy_jax.terrain.generators.stepping_stones`). Stone shifts and tops are
    drawn per stone from a table sized by the map (the map's diagonal in cells per row), so no static stone
    count is needed.

    Args:
      key: PRNG key or int seed.
      params: :class:`StonePathParams` (None: 36 x 22 cm stones at 40 cm pitch, +-2 cm jitter, rows 25 cm apart).
      shape: static grid shape (nx, ny); resolution: static cell size, metres.
      has_height: static; 2D: stones and pad free, gaps obstacles; 2.5D: all free, gaps at ``gap_height``.
      origin: (2,) world (x, y) of the map's lower corner, metres.

    Returns:
      Terrain with (nx, ny) float32 ``height`` and bool ``free``.

    Example:
      >>> from ijoy_jax.terrain import generators as gen
      >>> p = gen.StonePathParams(pitch_jitter=0.0, start_x=0.1)
      >>> t = gen.stone_path(0, p, shape=(150, 50), resolution=0.02)
      >>> bool(t.free[int((0.3 + 0.2) / 0.02), int((1.0 / 2 + 0.125) / 0.02)])   # the left row's first stone
      True
    """
    params = check_params(params, StonePathParams)
    grid = make_grid(shape, resolution, origin, has_height)
    nx, ny = grid.shape
    slots = int(math.ceil(math.hypot(nx, ny))) + 2  # stones per row: at most one per cell along the diagonal
    pitch = jnp.maximum(f32(params.pitch), grid.res)
    size, width = f32(params.size), f32(params.width)
    shift_max = jnp.minimum(jnp.abs(f32(params.pitch_jitter)), jnp.maximum(0.5 * (pitch - size), 0.0))
    table = 2.0 * uniform(as_key(key), (2, slots, 2)) - 1.0  # per row and stone: shift, top offset
    c, s = jnp.cos(f32(params.direction)), jnp.sin(f32(params.direction))
    centre = grid.centres() - grid.start(params)
    on = jnp.zeros(grid.shape, bool)
    top = jnp.zeros(grid.shape, jnp.float32)
    for row, (offset, lateral) in enumerate(((0.0, 0.5), (1.0, -0.5))):
        first = f32(params.first) + offset * f32(params.stagger)
        mid = lateral * f32(params.row_gap)
        uc = c * centre[..., 0] + s * centre[..., 1]
        k0 = jnp.floor((uc - first) / pitch + 0.5).astype(jnp.int32)
        for dk in (-1, 0, 1):  # a shifted stone may reach a cell nearer its neighbour's site
            k = k0 + dk
            kk = jnp.clip(k, 0, slots - 1)
            u_stone = first + k.astype(jnp.float32) * pitch + table[row, kk, 0] * shift_max
            all_on = k >= 0
            for ox in (-0.5, 0.5):
                for oy in (-0.5, 0.5):
                    dx = centre[..., 0] + ox * grid.res
                    dy = centre[..., 1] + oy * grid.res
                    du = c * dx + s * dy - u_stone
                    dv = -s * dx + c * dy - mid
                    all_on &= (jnp.abs(du) <= 0.5 * size + _STONE_EPS) & (jnp.abs(dv) <= 0.5 * width + _STONE_EPS)
            on |= all_on
            top = jnp.where(all_on, table[row, kk, 1] * f32(params.top_jitter), top)
    pad = grid.in_start_zone(params)
    height = jnp.where(pad, f32(params.top), jnp.where(on, f32(params.top) + top, f32(params.gap_height)))
    free = jnp.ones(grid.shape, bool) if has_height else on | pad
    return grid.terrain(height=height, free=free)


CORRIDOR = Family(name="corridor", generator=corridor, params=CorridorParams, max_count=_MAX_POCKETS)
STONE_PATH = Family(name="stone_path", generator=stone_path, params=StonePathParams)
