"""Planar poses and exact grid coverage of rotated rectangles.

Poses are ``(x, y, theta)`` in metres and radians. Grids follow the terrain
convention: cell ``(ix, iy)`` spans ``[ix * res, (ix + 1) * res) x
[iy * res, (iy + 1) * res)`` in map coordinates (metres from the map origin).

Coverage is *exact*: a cell is touched by a rectangle iff their interiors
overlap (positive area). It is computed column by column: the rectangle cut by
the vertical slab of one grid column is a convex polygon, and the rows it
touches are exactly the rows whose open interval meets that polygon's
y-extent. This costs O(columns) per rectangle instead of O(cells), and
never skips a cell at any position or rotation.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

MAX_ANGLE = 1024.0
"""rad: the largest heading a pose may have inside a jit. Poses are float32 there, whose spacing at 2**10 rad is
1.2e-4 rad (0.007 deg); at 2 pi 1e7 it is 4 rad, and a step's turn vanishes in the sum. Concrete poses beyond it
are reduced by whole turns in float64 at the public functions' boundary (:func:`reduce_turns`); traced ones
beyond it are flagged (:func:`pose_supported`)."""

MAX_HEADING = 2.0**39
"""rad: the largest concrete heading the boundary reduces by whole turns (:func:`reduce_turns`). Up to it the
float64 reduction lands within 1e-4 rad of the exact direction (float32's own rounding at :data:`MAX_ANGLE`);
beyond it the error grows with the heading (3e-3 rad at 2**45) until float64 holds no direction at all (its
spacing at 1e17 is 16 rad), so :func:`check_headings` refuses it rather than return a step turned anywhere."""


def wrap_angle(theta: jax.Array) -> jax.Array:
    """Wrap angles (radians) to ``[-pi, pi)``."""
    return (theta + jnp.pi) % (2.0 * jnp.pi) - jnp.pi


def reduce_turns(poses) -> np.ndarray:
    """Concrete ``(..., 3)`` poses in float64 with every heading beyond :data:`MAX_ANGLE` reduced by whole turns
    to ``[-pi, pi]`` (the same direction, one float64 operation); headings within it are kept as given."""
    out = np.array(poses, np.float64)
    yaw = out[..., 2]
    with np.errstate(invalid="ignore"):  # NaN and inf stay as they are, silently (the finite check names them)
        far = np.isfinite(yaw) & (np.abs(yaw) > MAX_ANGLE)
        out[..., 2] = np.where(far, yaw - 2.0 * np.pi * np.round(yaw / (2.0 * np.pi)), yaw)
    return out


def check_headings(name: str, poses) -> None:
    """Raise ValueError naming ``name`` if a concrete ``(..., 3)`` pose has a finite heading beyond
    :data:`MAX_HEADING` (one no reduction by whole turns can place); NaN and inf are left to the finite checks."""
    yaw = np.asarray(poses, np.float64)[..., 2]
    with np.errstate(invalid="ignore"):
        far = np.isfinite(yaw) & (np.abs(yaw) > MAX_HEADING)
    if far.any():
        raise ValueError(f"{name} heading {float(yaw[far].flat[0])!r} rad is beyond geometry.MAX_HEADING = 2**39 rad, "
                         f"where float64 no longer says which way it points: give it within a few turns")


def pose_supported(pose) -> jax.Array:
    """() bool: every ``(..., 3)`` pose is finite with ``|theta| <= MAX_ANGLE`` (traceable; the in-jit rule the
    boundary's checks and :func:`reduce_turns` apply to concrete poses)."""
    pose = jnp.asarray(pose)
    return jnp.all(jnp.isfinite(pose)) & jnp.all(jnp.abs(pose[..., 2]) <= MAX_ANGLE)


def safe_norm(x: jax.Array, y: jax.Array) -> jax.Array:
    """``sqrt(x^2 + y^2)`` with a zero (not NaN) gradient at the origin (double-where; STYLE.md rule 6).

    ``jnp.hypot`` differs from it in the last bit at some inputs; the exact
    selector keeps ``hypot`` (:func:`ijoy_jax.robots.dist`), what is differentiated uses this.

    Example:
      >>> import jax, jax.numpy as jnp
      >>> from ijoy_jax.geometry import safe_norm
      >>> float(safe_norm(3.0, 4.0)), [float(g) for g in jax.grad(safe_norm, (0, 1))(0.0, 0.0)]
      (5.0, [0.0, 0.0])
    """
    sq = x * x + y * y
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def compose(base: jax.Array, rel: jax.Array) -> jax.Array:
    """World pose of ``rel`` (3,) expressed in the frame of ``base`` (3,).

    ``compose(base, rel) = base (+) rel``: translate by ``rel[:2]`` rotated by
    ``base[2]``, then add the angles. Broadcasts over leading axes of ``rel``.
    """
    c, s = jnp.cos(base[..., 2]), jnp.sin(base[..., 2])
    x = base[..., 0] + c * rel[..., 0] - s * rel[..., 1]
    y = base[..., 1] + s * rel[..., 0] + c * rel[..., 1]
    return jnp.stack([x, y, base[..., 2] + rel[..., 2]], axis=-1)


def relative(base: jax.Array, pose: jax.Array) -> jax.Array:
    """Pose (3,) of ``pose`` in the frame of ``base``: inverse of :func:`compose`.

    The angle is wrapped to ``[-pi, pi)``.
    """
    c, s = jnp.cos(base[..., 2]), jnp.sin(base[..., 2])
    dx = pose[..., 0] - base[..., 0]
    dy = pose[..., 1] - base[..., 1]
    return jnp.stack(
        [c * dx + s * dy, -s * dx + c * dy, wrap_angle(pose[..., 2] - base[..., 2])],
        axis=-1,
    )


def rect_corners(cx, cy, theta, half_length, half_width) -> jax.Array:
    """Corners (4, 2) of a rectangle centred at (cx, cy), its length along angle theta.

    Counter-clockwise order: front-left, rear-left, rear-right, front-right.
    """
    c, s = jnp.cos(theta), jnp.sin(theta)
    lx = jnp.array([1.0, -1.0, -1.0, 1.0]) * half_length
    ly = jnp.array([1.0, 1.0, -1.0, -1.0]) * half_width
    return jnp.stack([cx + c * lx - s * ly, cy + s * lx + c * ly], axis=-1)


class ColumnSpans(NamedTuple):
    """Cells touched by one convex shape, one row range per grid column.

    Fields (K = number of columns in the window, static)::

      ix: (K,) int32 column index of each window column (``ix0 + arange(K)``).
      j0: (K,) int32 first touched row (inclusive).
      j1: (K,) int32 last touched row (inclusive).
      touched: (K,) bool, False where the column is not touched at all.
      overflow: () bool, True if the shape spans more than K columns, in which
        case the spans are incomplete and the caller must treat it as invalid.
    """

    ix: jax.Array
    j0: jax.Array
    j1: jax.Array
    touched: jax.Array
    overflow: jax.Array


def polygon_column_spans(corners: jax.Array, res, num_columns: int, ix0=None) -> ColumnSpans:
    """Exact per-column row spans of the cells whose interior a convex polygon overlaps.

    Args:
      corners: (V, 2) vertices of a convex polygon in map coordinates (metres
        from the grid origin), in order around the polygon.
      res: grid resolution (metres per cell), scalar.
      num_columns: static window width K in columns.
      ix0: first column of the window; default the column that holds the
        polygon's smallest x.

    Returns:
      ColumnSpans with (K,) arrays.
    """
    corners = jnp.asarray(corners)
    px, py = corners[:, 0], corners[:, 1]
    xmin, xmax = jnp.min(px), jnp.max(px)
    ix_first = jnp.floor(xmin / res).astype(jnp.int32)
    ix0 = ix_first if ix0 is None else jnp.asarray(ix0, jnp.int32)
    ix_last = (jnp.ceil(xmax / res) - 1).astype(jnp.int32)
    ix = ix0 + jnp.arange(num_columns, dtype=jnp.int32)
    # The polygon cut by slab [xa, xb] spans x in [a, b].
    a = jnp.maximum(ix * res, xmin)
    b = jnp.minimum((ix + 1) * res, xmax)
    has_width = a < b

    # Edges that are not vertical, as (V,) arrays.
    qx, qy = jnp.roll(px, -1), jnp.roll(py, -1)
    ex_lo, ex_hi = jnp.minimum(px, qx), jnp.maximum(px, qx)
    dx = qx - px
    slanted = dx != 0.0
    slope = (qy - py) / jnp.where(slanted, dx, 1.0)
    # y-extent over each slab: y of each edge at x = a and at x = b (edges that cross x), and the vertices
    # inside the slab. Unrolled over the (static, few) vertices, so every quantity is a (K,) array that XLA fuses
    # into one loop (min and max are exact, so the order does not matter). As (2, K, V) arrays reduced over V
    # (0f7ce45 to 2026-12-01) the program was a third of the ops but 2D FootCost ran 3.2x slower on a CPU and
    # 2D decisions 2.6x slower: a closed loop on rough ground then compiled 1.01x the issue-time program's
    # time, unrolled 1.13x, side by side on one H200 (BENCHMARKS.md).
    ylo = jnp.full(a.shape, jnp.inf, a.dtype)
    yhi = jnp.full(a.shape, -jnp.inf, a.dtype)
    for v in range(px.shape[0]):
        for x in (a, b):
            y = py[v] + (x - px[v]) * slope[v]
            ok = slanted[v] & (x >= ex_lo[v]) & (x <= ex_hi[v])
            ylo = jnp.minimum(ylo, jnp.where(ok, y, jnp.inf))
            yhi = jnp.maximum(yhi, jnp.where(ok, y, -jnp.inf))
        inside = (px[v] >= a) & (px[v] <= b)
        ylo = jnp.minimum(ylo, jnp.where(inside, py[v], jnp.inf))
        yhi = jnp.maximum(yhi, jnp.where(inside, py[v], -jnp.inf))

    touched = has_width & (yhi > ylo)
    j0 = jnp.floor(jnp.where(touched, ylo, 0.0) / res).astype(jnp.int32)
    j1 = (jnp.ceil(jnp.where(touched, yhi, 0.0) / res) - 1).astype(jnp.int32)
    touched = touched & (j1 >= j0)
    overflow = (ix_first < ix0) | ((ix_last - ix0 + 1) > num_columns)
    return ColumnSpans(ix=ix, j0=j0, j1=j1, touched=touched, overflow=overflow)


def rect_column_spans(cx, cy, theta, half_length, half_width, res, num_columns: int, ix0=None) -> ColumnSpans:
    """:func:`polygon_column_spans` of a rotated rectangle (map coordinates, metres)."""
    corners = rect_corners(cx, cy, theta, half_length, half_width)
    return polygon_column_spans(corners, res, num_columns, ix0)


def spans_mask(spans: ColumnSpans, iy0, num_rows: int) -> jax.Array:
    """(K, R) bool mask of touched cells in the window of rows ``iy0 + arange(R)``."""
    j = iy0 + jnp.arange(num_rows, dtype=jnp.int32)
    return spans.touched[:, None] & (j[None, :] >= spans.j0[:, None]) & (j[None, :] <= spans.j1[:, None])
