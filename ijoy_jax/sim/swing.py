"""Swing-foot paths that rise over the terrain between lift-off and touch-down.

The paper's walking controller swung the foot along a default path that could
sweep through the edge of an obstacle it stepped onto or over. Here the path
is lift, transfer, lower:

1. ``s in [0, a]``: the foot rises vertically from its lift-off pose to the
   apex height (quintic in time, zero velocity and acceleration at both ends);
2. ``s in [a, 1 - a]``: it moves horizontally (x, y, yaw) at the apex height
   (quintic again);
3. ``s in [1 - a, 1]``: it descends vertically onto the touch-down pose.

The apex comes from the terrain: :func:`corridor_height` is the highest
terrain under the foot swept from lift-off to touch-down, and
:func:`swing_apex` adds a clearance. During the transfer the sole is at the
apex, so above every cell the swept foot covers (up to the sampling bound in
:func:`corridor_height`); during lift and descent the foot is over its own
start or end footprint and above the terrain it stands on.

Given the terrain's height *along* the path (:func:`corridor_profile`: the
footprint's height at evenly spaced points of the horizontal path) instead of
one apex, the foot gains height in stages: each rise ends as the foot reaches
the footprint that needs it, and each descent starts once the foot has passed
the footprint that held it up (:func:`swing_pose`). Climbing stairs, the foot
lifted from a lower tread clears the next riser first and the one after while
it moves forward, instead of rising two risers while it is still behind the
body (in MJX, robots that fell on stairs had their swing foot stopped short
against a riser, pitched 20-30 degrees; docs/walk_families.md).

Heights are read from ``terrain.height`` as they are: the caller passes a
terrain whose 2D obstacles are already raised to their physical height (as in
the simulator's height field). Cells off the map count as ``off_map_height``
(default 0, the simulator's floor). One pose, one terrain per call; batch with
``jax.vmap``.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import geometry
from ijoy_jax.footcost import window_cells
from ijoy_jax.sim import kinematics
from ijoy_jax.terrain import Terrain


def _window(foot_length, foot_width, margin, max_radius, resolution: float) -> int:
    """Static window width (cells) holding any footprint of the given half-diagonal."""
    if max_radius is None:
        try:
            hl = 0.5 * float(foot_length) + float(margin)
            hw = 0.5 * float(foot_width) + float(margin)
        except (TypeError, jax.errors.ConcretizationTypeError) as err:
            raise ValueError(
                "foot_length, foot_width and margin are traced: pass max_radius (a Python float, metres, "
                "the largest half-diagonal of the grown footprint) to fix the window"
            ) from err
        if not (math.isfinite(hl) and math.isfinite(hw)) or hl <= 0.0 or hw <= 0.0:
            raise ValueError(f"footprint half-sizes must be positive, got {hl}, {hw} (margin included)")
        max_radius = math.hypot(hl, hw)
    max_radius = float(max_radius)
    if not math.isfinite(max_radius) or max_radius <= 0.0:
        raise ValueError(f"max_radius must be a positive number of metres, got {max_radius}")
    return window_cells(max_radius, resolution)


def _footprint_height_impl(terrain: Terrain, pose, hl, hw, k: int, off_map_height, grad=None):
    """The largest ``height - grad . (cell centre - foot centre)`` over the cells the rectangle touches (grad
    (2,) the slope of a tilted sole's plane, m/m; None: level, the plain highest cell)."""
    res = terrain.resolution
    nx, ny = terrain.shape
    pose = jnp.asarray(pose)
    finite = jnp.all(jnp.isfinite(pose))
    pose = jnp.where(finite, pose, 0.0)
    cx = pose[0] - terrain.origin[0]
    cy = pose[1] - terrain.origin[1]
    corners = geometry.rect_corners(cx, cy, pose[2], hl, hw)
    spans = geometry.polygon_column_spans(corners, res, k)
    iy0 = jnp.floor(jnp.min(corners[:, 1]) / res).astype(jnp.int32)
    mask = geometry.spans_mask(spans, iy0, k)
    iy = iy0 + jnp.arange(k, dtype=jnp.int32)
    # The cell holding the centre always overlaps the footprint: keeps the max
    # finite for degenerate (zero-area) footprints.
    ic = jnp.floor(cx / res).astype(jnp.int32) - spans.ix[0]
    jc = jnp.floor(cy / res).astype(jnp.int32) - iy0
    mask = mask | ((jnp.arange(k)[:, None] == ic) & (jnp.arange(k)[None, :] == jc))
    on_map = ((spans.ix >= 0) & (spans.ix < nx))[:, None] & ((iy >= 0) & (iy < ny))[None, :]
    h = terrain.height[jnp.clip(spans.ix, 0, nx - 1)[:, None], jnp.clip(iy, 0, ny - 1)[None, :]]
    h = jnp.where(on_map, h, jnp.asarray(off_map_height, h.dtype))
    if grad is not None:
        grad = jnp.where(finite, jnp.asarray(grad, h.dtype), 0.0)
        du = (spans.ix.astype(h.dtype) + 0.5) * res - cx
        dv = (iy.astype(h.dtype) + 0.5) * res - cy
        h = h - grad[0] * du[:, None] - grad[1] * dv[None, :]
    top = jnp.max(jnp.where(mask, h, -jnp.inf))
    return jnp.where(finite, top, jnp.nan)


_footprint_height = jax.jit(_footprint_height_impl, static_argnums=4)


def footprint_height(
    terrain: Terrain,
    pose,
    foot_length,
    foot_width,
    margin=0.0,
    *,
    max_radius: float | None = None,
    off_map_height=0.0,
) -> jax.Array:
    """Highest terrain (m) under a foot's rectangle at ``pose``.

    Exact cell coverage (:func:`ijoy_jax.geometry.polygon_column_spans`): a cell
    counts iff its interior overlaps the rectangle grown by ``margin`` on every
    side, over a static square window of cells.

    Args:
      terrain: :class:`~ijoy_jax.terrain.Terrain` with physical heights (m).
      pose: (3,) world (x, y, yaw) of the foot centre (m, m, rad).
      foot_length: footprint length along the foot's x axis (m).
      foot_width: footprint width (m).
      margin: grows the rectangle on every side (m), >= 0.
      max_radius: static half-diagonal (m) of the grown rectangle that sizes
        the window; needed only when the sizes are traced (e.g. a ``Robot``'s
        array leaves); default from the sizes.
      off_map_height: height (m) of cells outside the map.

    Returns:
      () float: the largest height, NaN if ``pose`` is not finite.

    Raises:
      ValueError: non-positive sizes, or traced sizes without ``max_radius``.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> h = np.zeros((50, 50)); h[30:, :] = 0.05   # a 5 cm platform from x = 0.6 m
      >>> t = ij.terrain.from_arrays(h, resolution=0.02)
      >>> float(footprint_height(t, np.array([0.5, 0.5, 0.0]), 0.242, 0.13))
      0.05...
    """
    k = _window(foot_length, foot_width, margin, max_radius, terrain.resolution)
    hl = 0.5 * jnp.asarray(foot_length) + margin
    hw = 0.5 * jnp.asarray(foot_width) + margin
    return _footprint_height(terrain, pose, hl, hw, k, off_map_height)


def sole_plane_gradient(roll, pitch, yaw) -> jax.Array:
    """(2,) world slope (dz/dx, dz/dy) of the plane of a sole turned ``Rz(yaw) Ry(pitch) Rx(roll)`` (radians).

    The sole's normal is ``n = R e_z``; its plane rises ``-n_x / n_z`` per metre
    along x and ``-n_y / n_z`` along y.
    """
    n = kinematics.rpy_to_rot(jnp.stack([roll, pitch, yaw]))[:, 2]
    return -n[:2] / n[2]


@functools.partial(jax.jit, static_argnums=4)
def _resting_height(terrain, foothold, hl, hw, k: int, off_map_height):
    foothold = jnp.asarray(foothold)
    grad = sole_plane_gradient(foothold[3], foothold[4], foothold[5])
    return _footprint_height_impl(terrain, foothold[jnp.array([0, 1, 5])], hl, hw, k, off_map_height, grad)


@jax.jit
def _resting_height_on_points(terrain, foothold, points, off_map_height):
    foothold = jnp.asarray(foothold)
    finite = jnp.all(jnp.isfinite(foothold))
    foothold = jnp.where(finite, foothold, 0.0)
    grad = sole_plane_gradient(foothold[3], foothold[4], foothold[5])
    c, s = jnp.cos(foothold[5]), jnp.sin(foothold[5])
    d = jnp.stack([c * points[:, 0] - s * points[:, 1], s * points[:, 0] + c * points[:, 1]], axis=1)
    h = surface_height(terrain, foothold[:2] + d, off_map_height)
    return jnp.where(finite, jnp.max(h - d @ grad), jnp.nan)


def surface_height(terrain: Terrain, xy, off_map_height=0.0) -> jax.Array:
    """(K,) heights (m) of the surface through the cell-centre samples at world points ``xy`` (K, 2): bilinear
    between the four samples around each point (MuJoCo's height field, sampled at cell centres, is the same
    surface cut into two triangles per cell: they differ by less than a cell's height differences). Points
    beyond the outer cell centres take the edge value; off the map, ``off_map_height``."""
    res = terrain.resolution
    nx, ny = terrain.shape
    u = (xy - terrain.origin) / res - 0.5
    i0 = jnp.floor(u).astype(jnp.int32)
    f = u - i0
    hx = terrain.height

    def at(di, dj):
        return hx[jnp.clip(i0[:, 0] + di, 0, nx - 1), jnp.clip(i0[:, 1] + dj, 0, ny - 1)]

    h = ((1 - f[:, 0]) * (1 - f[:, 1]) * at(0, 0) + f[:, 0] * (1 - f[:, 1]) * at(1, 0)
         + (1 - f[:, 0]) * f[:, 1] * at(0, 1) + f[:, 0] * f[:, 1] * at(1, 1))
    cell = jnp.floor((xy - terrain.origin) / res)
    on_map = (cell[:, 0] >= 0) & (cell[:, 0] < nx) & (cell[:, 1] >= 0) & (cell[:, 1] < ny)
    return jnp.where(on_map, h, jnp.asarray(off_map_height, h.dtype))


def resting_height(terrain: Terrain, foothold, foot_length, foot_width, *, points=None,
                   max_radius: float | None = None, off_map_height=0.0) -> jax.Array:
    """Height (m) of the centre of a tilted sole resting on the terrain at ``foothold``.

    The sole is the foot's rectangle in the plane through its centre turned by
    the foothold's roll, pitch and yaw; lowered onto the ground, it stops on the
    cell that stands highest above that plane: the result is ``max over the
    cells the rectangle touches of (height - g . (cell centre - foot centre))``,
    g = :func:`sole_plane_gradient`. On a planar terrain with the plane's own
    tilt it is the plane's height at the centre; with roll = pitch = 0 it is
    :func:`footprint_height`. The heights are the simulator's samples at cell
    centres (MuJoCo's height field interpolates between them).

    A sole that touches the ground only at some points (the simulated biped's
    sole spheres) rests where the first of them touches: with ``points`` (K, 2)
    (x, y in the sole's frame, m) the result is ``max over the points of
    (surface height - g . offset)`` on the :func:`surface_height` through the
    samples, the surface MuJoCo collides them with. A plate sole resting on a
    bump between such points would otherwise be placed above points that hang
    in the air.

    Args:
      terrain: :class:`~ijoy_jax.terrain.Terrain` with physical heights (m).
      foothold: (6,) x, y, z, roll, pitch, yaw (m, rad; z is ignored).
      foot_length, foot_width: sole size (m).
      points: optional (K, 2) contact points of the sole (m, sole frame).
      max_radius, off_map_height: as in :func:`footprint_height`.

    Returns:
      () float: the sole centre's height, NaN if ``foothold`` is not finite.
    """
    if points is not None:
        return _resting_height_on_points(terrain, foothold, jnp.asarray(points, jnp.float32), off_map_height)
    k = _window(foot_length, foot_width, 0.0, max_radius, terrain.resolution)
    return _resting_height(terrain, foothold, 0.5 * jnp.asarray(foot_length), 0.5 * jnp.asarray(foot_width), k,
                           off_map_height)


def _lerp_pose(start, end, u):
    """Pose at fraction u along the straight path, yaw the short way round; exact at u = 0 and 1."""
    start = jnp.asarray(start)
    end = jnp.asarray(end)
    yaw_end = start[-1] + geometry.wrap_angle(end[-1] - start[-1])
    # The representative of end's yaw nearest start's, so u = 1 returns end exactly when |dyaw| < pi.
    yaw_end = jnp.where(jnp.abs(end[-1] - start[-1]) < jnp.pi, end[-1], yaw_end)
    target = end.at[-1].set(yaw_end)
    return (1.0 - u) * start + u * target


def corridor_height(
    terrain: Terrain,
    start,
    end,
    foot_length,
    foot_width,
    samples: int = 16,
    margin=0.0,
    *,
    max_radius: float | None = None,
    off_map_height=0.0,
) -> jax.Array:
    """Highest terrain (m) under the foot swept along the straight path from ``start`` to ``end``.

    The foot is placed at ``samples`` poses evenly spaced along the path (x, y
    linear, yaw along the shorter way round), both ends included, and
    :func:`footprint_height` is taken at each. Any point the continuously
    swept foot covers lies within ``delta = (|d| + R |dyaw|) / (2 (samples -
    1))`` of a sampled footprint (``d`` the xy displacement, ``R`` the foot's
    half-diagonal), so with ``margin >= delta`` the result bounds every cell
    the swept foot touches; with the default 16 samples and a 0.4 m step
    ``delta`` is 1.3 cm.

    Args:
      terrain: :class:`~ijoy_jax.terrain.Terrain` with physical heights (m).
      start: (3,) lift-off pose (x, y, yaw) (m, m, rad).
      end: (3,) touch-down pose (x, y, yaw).
      foot_length, foot_width: footprint sizes (m).
      samples: static number of poses, >= 2.
      margin: grows every footprint (m).
      max_radius, off_map_height: as in :func:`footprint_height`.

    Returns:
      () largest height (m).
    """
    return jnp.max(corridor_profile(terrain, start, end, foot_length, foot_width, samples, margin,
                                    max_radius=max_radius, off_map_height=off_map_height))


def corridor_profile(
    terrain: Terrain,
    start,
    end,
    foot_length,
    foot_width,
    samples: int = 16,
    margin=0.0,
    *,
    max_radius: float | None = None,
    off_map_height=0.0,
) -> jax.Array:
    """(samples,) highest terrain (m) under the foot at ``samples`` poses evenly spaced along the straight path
    from ``start`` to ``end`` (both included; :func:`corridor_height` is their maximum, and its sampling bound
    holds between neighbouring samples). Arguments as in :func:`corridor_height`; a pose that is not finite
    gives NaN."""
    samples = int(samples)
    if samples < 2:
        raise ValueError(f"samples must be >= 2, got {samples}")
    k = _window(foot_length, foot_width, margin, max_radius, terrain.resolution)
    hl = 0.5 * jnp.asarray(foot_length) + margin
    hw = 0.5 * jnp.asarray(foot_width) + margin
    return _corridor_profile(terrain, start, end, hl, hw, k, samples, off_map_height)


@functools.partial(jax.jit, static_argnums=(5, 6))
def _corridor_profile(terrain, start, end, hl, hw, k: int, samples: int, off_map_height):
    u = jnp.linspace(0.0, 1.0, samples)
    poses = jax.vmap(lambda ui: _lerp_pose(start, end, ui))(u)
    return jax.vmap(lambda p: _footprint_height_impl(terrain, p, hl, hw, k, off_map_height))(poses)


def swing_apex(
    terrain: Terrain,
    start,
    end,
    foot_length,
    foot_width,
    clearance,
    samples: int = 16,
    margin=0.0,
    **kwargs,
) -> jax.Array:
    """Apex height (m) for :func:`swing_pose`: ``max(corridor_height, start z, end z) + clearance``.

    Args:
      start, end: (4,) lift-off and touch-down poses (x, y, z, yaw); z is the
        sole height (m).
      clearance: () height (m) of the sole above the highest swept terrain. Others as in
        :func:`corridor_height`.
    """
    start = jnp.asarray(start)
    end = jnp.asarray(end)
    top = corridor_height(
        terrain,
        start[jnp.array([0, 1, 3])],
        end[jnp.array([0, 1, 3])],
        foot_length,
        foot_width,
        samples,
        margin,
        **kwargs,
    )
    return jnp.maximum(jnp.maximum(top, start[2]), end[2]) + clearance


def smoothstep(u):
    """Smoothstep 10u^3 - 15u^4 + 6u^5 on u clipped to [0, 1]: zero slope and curvature at both ends."""
    u = jnp.clip(u, 0.0, 1.0)
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


def swing_pose(start, end, apex, s, *, lift=0.25) -> tuple[jax.Array, jax.Array]:
    """Swing-foot position and yaw at phase ``s`` of a lift-transfer-lower path.

    With ``a = lift`` and ``q(u) = 10u^3 - 15u^4 + 6u^5`` (u clipped to [0, 1]):

    - horizontal: ``(x, y, yaw) = lerp(start, end, q((s - a) / (1 - 2a)))``,
      yaw the short way round: the foot moves only for ``a <= s <= 1 - a``;
    - vertical, with one ``apex`` height ``h``: ``z = z0 + (h - z0) q(s / a)``
      for ``s <= a``; ``h`` for ``a <= s <= 1 - a``; ``z = h + (z1 - h) q((s
      - 1 + a) / a)`` after, with ``h = max(apex, z0, z1)``: the foot rises
      and descends vertically and moves horizontally only at the apex;
    - vertical, with ``apex`` a profile ``h_0 .. h_{n-1}`` (the lowest heights
      allowed with the foot at the n evenly spaced points ``u_i = i / (n -
      1)`` of its horizontal path, e.g. :func:`corridor_profile` plus a
      clearance): the foot gains and loses height in stages of duration
      ``a``. Each rise the profile asks for (its running maximum from the
      start, which begins at z0) is complete when the foot reaches the point
      before the one that asks for it, each descent (the running maximum from
      the end, which ends at z1) begins once the foot has passed the point
      after the one that held it up. So between neighbouring points the sole
      is at least as high as both ask; with a constant profile at or above
      both soles the path is the one-apex path.

    Position, velocity and acceleration are continuous, and velocity and
    acceleration are zero at ``s = 0`` and ``s = 1``. Times: peak horizontal
    speed is ``1.875 |d| / ((1 - 2a) T)`` and peak acceleration ``5.77 |d| /
    ((1 - 2a) T)^2`` for a swing of duration T; each vertical stage uses
    ``a T``.

    Args:
      start: (4,) lift-off pose (x, y, z, yaw) of the sole centre (m, rad).
      end: (4,) touch-down pose (x, y, z, yaw).
      apex: () absolute sole height (m) during the transfer, e.g. from
        :func:`swing_apex`, raised to ``max(start z, end z)`` if lower; or
        (n,) n >= 2 such heights along the path (see above).
      s: () swing phase in [0, 1] (clipped), elapsed swing time over swing
        duration.
      lift: fraction ``a`` of the phase for the lift and for the descent (and
        for each stage between), in (0, 0.5]; a Python float is checked, a
        traced one is clipped.

    Returns:
      ``(pos (3,), yaw ())``: sole-centre position (m) and yaw (rad). At s = 0
      and 1 they equal ``start`` and ``end`` exactly (yaw exactly when ``|end
      yaw - start yaw| < pi``, otherwise modulo 2 pi; yaw is continuous, not
      wrapped).

    Example:
      >>> p, yaw = swing_pose(jnp.array([0., 0.1, 0., 0.]), jnp.array([0.3, 0.1, 0.05, 0.]), 0.1, 0.5)
      >>> p
      Array([0.15, 0.1 , 0.1 ], dtype=float32)
    """
    if isinstance(lift, (int, float)) and not (0.0 < float(lift) <= 0.5):
        raise ValueError(f"lift must be in (0, 0.5], got {lift}")
    if jnp.ndim(apex) > 1 or (jnp.ndim(apex) == 1 and jnp.shape(apex)[0] < 2):
        raise ValueError(f"apex must be a height () or a profile (n,) with n >= 2, got shape {jnp.shape(apex)}")
    return _swing_pose(start, end, apex, s, lift)


def _inverse_smoothstep(u: np.ndarray) -> np.ndarray:
    """x in [0, 1] with :func:`smoothstep` (x) = u, for u in [0, 1] (float64 bisection: it is increasing)."""
    lo, hi = np.zeros_like(u, np.float64), np.ones_like(u, np.float64)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = mid * mid * mid * (10.0 + mid * (-15.0 + 6.0 * mid)) < u
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def _staged_height(z0, z1, need, s, a):
    """The sole's height at phase s for the height profile ``need`` (n,) (see :func:`swing_pose`)."""
    n = need.shape[0]
    levels = jnp.concatenate([z0[None], need, z1[None]])  # the start, the n points, the end
    up = jax.lax.cummax(levels)
    down = jax.lax.cummax(levels, reverse=True)
    rise = up[1:] - up[:-1]  # (n + 1,) the gain each level asks for beyond those before it
    fall = down[:-1] - down[1:]  # (n + 1,) the loss each level allows once passed
    point = np.clip(np.arange(n + 2) - 1, 0, n - 1)  # the point of the path each level stands for
    reach = a + (1.0 - 2.0 * a) * jnp.asarray(_inverse_smoothstep(np.linspace(0.0, 1.0, n)), need.dtype)
    done = reach[np.clip(point[1:] - 1, 0, n - 1)]  # a rise ends as the foot reaches the point before
    begin = reach[np.clip(point[:-1] + 1, 0, n - 1)]  # a descent begins once it has passed the point after
    gained = smoothstep((s - done + a) / a)
    lost = smoothstep((s - begin) / a)
    # the same sum written from either end, so that s = 0 and s = 1 give z0 and z1 exactly
    from_start = z0 + jnp.sum(rise * gained) - jnp.sum(fall * lost)
    from_end = z1 + jnp.sum(fall * (1.0 - lost)) - jnp.sum(rise * (1.0 - gained))
    return jnp.where(s <= 0.5, from_start, from_end)


@jax.jit
def _swing_pose(start, end, apex, s, lift):
    start = jnp.asarray(start, jnp.result_type(float))
    end = jnp.asarray(end, start.dtype)
    a = jnp.clip(jnp.asarray(lift, start.dtype), 1e-3, 0.5)
    s = jnp.clip(jnp.asarray(s, start.dtype), 0.0, 1.0)
    need = jnp.asarray(apex, start.dtype).reshape(-1)
    if need.shape[0] == 1:  # one apex: the same height all along
        need = jnp.concatenate([need, need])
    z = _staged_height(start[2], end[2], need, s, a)
    # 1 - 2a may be 0 (lift = 0.5): then the transfer is a step at s = 0.5.
    span = 1.0 - 2.0 * a
    safe_span = jnp.where(span > 0, span, 1.0)
    u = jnp.where(span > 0, smoothstep((s - a) / safe_span), jnp.where(s >= 0.5, 1.0, 0.0))
    planar = _lerp_pose(start[jnp.array([0, 1, 3])], end[jnp.array([0, 1, 3])], u)
    return jnp.stack([planar[0], planar[1], z]), planar[2]


def swing_velocity(start, end, apex, s, *, lift=0.25) -> tuple[jax.Array, jax.Array]:
    """Derivatives of :func:`swing_pose` with respect to the phase s: ``(dpos/ds (3,), dyaw/ds ())``.

    Divide by the swing duration (s) for m/s and rad/s. Zero at s = 0 and 1.
    """
    s = jnp.asarray(s, jnp.result_type(float))
    _, tangent = jax.jvp(lambda si: swing_pose(start, end, apex, si, lift=lift), (s,), (jnp.ones_like(s),))
    return tangent
