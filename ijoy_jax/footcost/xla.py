"""FootCost: how well a terrain location serves as a foothold, plus the cost of the action.

2D (occupancy grid): a step is valid iff every cell touched by the footprint
grown by the safety margin is free and inside the map (exact coverage, see
:mod:`ijoy_jax.geometry`) and the swing sole centre is within the legs' reach
of the stance one (``robot.max_sole_distance``); FootCost is then the
action's cost, else +inf.

2.5D (height map): additionally a plane is fitted to the heights of the cells
the footprint touches, and slope, roughness, largest bump, step height from
the stance foothold, and the safety band (cells touched only by the grown
footprint) are scored against :class:`ijoy_jax.robots.TerrainMetrics`: beyond
a limit the cost is +inf, below it ``weight * metric`` is added. The sole
rests on the ground under its contact points (:mod:`ijoy_jax.footcost.sole`:
the plane through three of them above the others, lowest under the ankle);
the ``support`` term asks its contact polygon to hold the ankle with room to
spare, the rested sole must tilt no further than the ankles realise
(``robot.max_sole_pitch`` along the foot, ``robot.max_sole_roll`` across it),
and step height and reach count the height change between the rested soles. With
``swing_from`` given, terrain in the swing corridor (the foot-wide rectangle
between the start and end foot centres) higher than the action's clearance
above the higher of the two footholds invalidates the step.

FootCost is never negative and invalid is +inf, never a large finite number:
the paper's early-exit rule for the ordered search relies on both.

Limits follow one rule on both paths (this one and the fused kernel of
:mod:`ijoy_jax.footcost.pallas`): a metric rejects a step when it exceeds its
limit by more than :data:`LIMIT_TOL` (:func:`exceeds`). The two paths sum in
different orders, so their metrics differ by float32 rounding, measured up to
~8e-6 rad for slopes and ~1e-6 m for the height metrics (plus one float32 ulp
of the terrain's altitude for step heights and the swing corridor; see
LIMIT_TOL's comment in the source): a decision whose metric lies within that
band of limit + LIMIT_TOL may differ between the paths; any other decision is
the same on both.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ijoy_jax import geometry
from ijoy_jax._struct import as_pose, check_numeric, is_traced
from ijoy_jax.footcost.index import (
    TerrainIndex,
    centre_off_map,
    column_has_obstacle,
    column_max_height,
    index_terrain,
    swing_corridor,
)
from ijoy_jax.footcost.sole import contact_offsets, sole_on_ground, tilt
from ijoy_jax.limits import check_window
from ijoy_jax.robots import Robot, check_robot, nearest_actions, robot_supported, side_sign
from ijoy_jax.terrain import Terrain, check_terrain, terrain_supported

SLACK = 1e-6  # m: float32 rounding allowed above the robot's float64 static window sizes
# m: the largest world coordinate a map may reach (its origin and far corner). FootCost runs in float32
# (also under x64: poses are cast), whose spacing at 2**13 m is 2**-10 m (0.98 mm), so within it every
# coordinate rounds by under half a millimetre; beyond, a footprint lands on the wrong cells (at a UTM
# northing of 5.2e6 m, y rounds to 0.5 m). Such frames are refused, not shifted internally: the results are
# world poses in float32 too, and would round the same way on the way out. Subtract your map's origin (in
# float64, on your side) from every pose and add it back to the returned ones.
MAX_COORDINATE = 8192.0
# rad or m (the metric's unit): how far a metric may exceed its limit and still pass (:func:`exceeds`). The
# XLA path and the fused kernel sum the plane fit in different orders (the kernel from prefix sums over windows
# of 2B rows, whose rounding grows with the relief within a window), so one metric differs between them by
# float32 rounding: the *band*. Measured (tests/test_footcost_kernel.py, ...differ_by_less_than_limit_tol...;
# 1000 hostile maps of 496 steps, CPU, interpreted kernel): slope 7.7e-6 rad on ramps up to 45 deg (5.0e-6 on
# 20 deg ramps), roughness 4.9e-7 m, bump 8.7e-7 m, safety band 1.2e-6 m; step height (and the swing corridor's
# height, both from absolute plane heights) 1.2e-7 m plus one float32 ulp of the terrain's altitude (3.8e-6 m
# at 50 m, 6.1e-5 m at 1000 m). A decision can differ between the paths only for a metric within the band of
# limit + LIMIT_TOL: near a limit, trust neither path to within the band. A metric exactly at its limit (a
# 20 deg ramp, a step as high as the limit: what a constructed map gives) is accepted by both wherever the band
# is below LIMIT_TOL: every metric on maps below 128 m of altitude (beyond, the step height's ulp exceeds it:
# subtract the altitude, as for MAX_COORDINATE). 1e-5 is above every band measured there and physically
# nothing (10 micrometres, 10 microradians: 1e-3 of the smallest default limit, 1 cm roughness).
LIMIT_TOL = 1e-5


def frame_extent(terrain: Terrain):
    """The largest absolute world coordinate of the map (origin or far corner, m): NumPy for a concrete origin, a
    jax scalar for a traced one (NaN if the origin is not finite)."""
    nx, ny = terrain.shape
    o = terrain.origin
    xp = jnp if isinstance(o, jax.core.Tracer) else np
    o = xp.asarray(o, xp.float64 if xp is np else o.dtype)
    far = o + xp.asarray([nx * terrain.resolution, ny * terrain.resolution], o.dtype)
    return xp.max(xp.abs(xp.concatenate([o, far])))


def check_frame(terrain: Terrain) -> None:
    """Raise ValueError if a concrete terrain lies where float32 loses millimetres (:data:`MAX_COORDINATE`).

    A traced origin is not checked here: inside a jit such a map flags every step ``unsupported``."""
    if isinstance(terrain.origin, jax.core.Tracer):
        return
    extent = float(frame_extent(terrain))
    if not np.isfinite(extent):
        raise ValueError(f"terrain origin must be finite, got {np.asarray(terrain.origin).tolist()}")
    if extent > MAX_COORDINATE:
        lost = float(np.spacing(np.float32(extent))) / 2
        raise ValueError(
            f"shift your world frame: the map reaches {extent:.6g} m from the origin, where float32 rounds "
            f"coordinates by up to {lost:.3g} m (millimetres hold within {MAX_COORDINATE:g} m); subtract the "
            f"map's origin {np.asarray(terrain.origin).tolist()} from every pose (float64, on your side), "
            "build the terrain at origin (0, 0) and add the origin back to the returned poses")


class FootCostTerms(NamedTuple):
    """FootCost of N candidate steps, as a total and as named terms (all (N,) float32).

    Cost terms (cost units; +inf marks the term that rejected a step)::

      total: sum of the terms below; +inf iff the step is invalid.
      action: the action's own cost.
      obstacle: 0, or +inf if the grown footprint touches an obstacle or
        leaves the map.
      slope, roughness, bump, step, band, support: ``weight * metric``,
        or +inf beyond the metric's limit (0 on 2D terrains).
      swing_path: 0, or +inf if the swing corridor is too high (or leaves the
        map) for the action's clearance.
      ankle: 0, or +inf if the rested sole would tilt beyond what the ankles
        realise: ``|sole_pitch_rad|`` above ``robot.max_sole_pitch``
        or ``|sole_roll_rad|`` above ``robot.max_sole_roll`` (0 on 2D terrains).
      reach: 0, or +inf if the stance and swing sole centres are farther apart
        (``sole_distance_m``) than ``robot.max_sole_distance``.
      unsupported: 0, or +inf if the pose is not finite, the footprint,
        margin or swing is larger than the robot's static windows cover, a
        plane fit overflows float32 (heights beyond ~1e35 m), or the robot's
        or terrain's values are ones FootCost does not support
        (:func:`query_supported`: a negative margin, weight or cost, NaN, a
        non-finite origin or height, a map beyond :data:`MAX_COORDINATE`,
        set by ``replace`` or vmap inside a jit). The total is then +inf,
        and a term such a value makes NaN (a NaN weight) reads +inf: no
        cost term is ever NaN.

    Raw metrics (for plots and tests)::

      slope_angle (rad), roughness_m, bump_m, step_height_m (signed, up is
      positive, between the rested soles), band_m, support_m, path_height_m
      (corridor height above the higher foothold; -inf if no check),
      foot_height_m (the rested sole's height at the foot centre),
      sole_pitch_rad and sole_roll_rad (the rested sole's orientation with the
      step's heading, ``R = Rz(yaw) Ry(pitch) Rx(roll)``: :func:`sole_tilt`'s
      convention; 0 on 2D terrains), sole_distance_m (3D
      distance from the stance sole centre: the horizontal step and
      step_height_m), action_index (int32, the action whose cost/limits were
      used).
    """

    total: jax.Array
    action: jax.Array
    obstacle: jax.Array
    slope: jax.Array
    roughness: jax.Array
    bump: jax.Array
    step: jax.Array
    band: jax.Array
    support: jax.Array
    swing_path: jax.Array
    ankle: jax.Array
    reach: jax.Array
    unsupported: jax.Array
    slope_angle: jax.Array
    roughness_m: jax.Array
    bump_m: jax.Array
    step_height_m: jax.Array
    band_m: jax.Array
    support_m: jax.Array
    path_height_m: jax.Array
    foot_height_m: jax.Array
    sole_pitch_rad: jax.Array
    sole_roll_rad: jax.Array
    sole_distance_m: jax.Array
    action_index: jax.Array



COST_TERMS: tuple[str, ...] = FootCostTerms._fields[: FootCostTerms._fields.index("unsupported") + 1]
"""The names of :class:`FootCostTerms`' cost terms: ``total`` first, then the terms it sums, ``unsupported``
last (the raw metrics after them are left out)."""


class Plane(NamedTuple):
    """The least-squares plane under a footprint, its metrics and the rested sole (:func:`plane_metrics`; ()
    float32 each).

    The plane is ``z = height + grad_x (x - cx) + grad_y (y - cy)`` in world axes about the foot centre
    ``(cx, cy)``.
    """

    height: jax.Array  # plane height at the foot centre (m)
    slope: jax.Array  # angle from horizontal (rad)
    roughness: jax.Array  # mean |residual| under the foot (m)
    bump: jax.Array  # largest residual under the foot (m)
    band: jax.Array  # largest |residual| in the safety band (m)
    support: jax.Array  # how much nearer the ankle the rested sole's contact polygon's edge is than the sole's (m)
    fitted: jax.Array  # () bool: the fit is finite (False: heights beyond float32's range; metrics then 0)
    grad_x: jax.Array  # dz/dx of the plane along world x (m/m)
    grad_y: jax.Array  # dz/dy of the plane along world y (m/m)
    rest_height: jax.Array  # the rested sole's height at the foot centre (m; footcost.sole)
    rest_pitch: jax.Array  # the rested sole's pitch and roll with the pose's yaw (rad; sole_tilt's convention)
    rest_roll: jax.Array


def sole_tilt(grad_x, grad_y, yaw):
    """(pitch, roll) of a sole lying on the plane of gradient ``(grad_x, grad_y)`` (m/m) with heading ``yaw``.

    The sole's orientation is ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (as
    :func:`ijoy_jax.sim.kinematics.rpy_to_rot`): its x axis (the foot's
    length) lies in the plane along the heading and its z axis is the plane's
    upward normal. With ``gf`` and ``gl`` the plane's slopes along and across
    the foot::

      gf = grad_x cos(yaw) + grad_y sin(yaw),  gl = -grad_x sin(yaw) + grad_y cos(yaw),
      pitch = -atan(gf),  roll = atan2(gl, sqrt(1 + gf^2))      (rad)

    Ground rising ahead of the foot lifts its toe: pitch < 0; ground rising
    to its left lifts its left edge: roll > 0. Elementwise (any broadcastable
    shapes); jnp only, so both FootCost paths use it.
    """
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    return tilt(grad_x * c + grad_y * s, grad_y * c - grad_x * s)


def sole_distance(dx, dy, dz):
    """3D distance between two sole centres ``sqrt(dx^2 + dy^2 + dz^2)`` (m): the ``reach`` metric, one formula
    for both FootCost paths (plain products and a square root, as the fused kernel lowers them)."""
    return jnp.sqrt(dx * dx + dy * dy + dz * dz)


def solve3(a00, a01, a02, a11, a12, a22, r0, r1, r2):
    """Solve the symmetric 3x3 system [[a00 a01 a02] [a01 a11 a12] [a02 a12 a22]] x = r (Cramer's rule).

    Cheaper than a batched LU for millions of tiny systems; a singular
    system gives non-finite values, which the caller replaces.
    """
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    x0 = (r0 * c00 + r1 * c01 + r2 * c02) / det
    x1 = (r0 * c01 + r1 * (a00 * a22 - a02 * a02) + r2 * (a01 * a02 - a00 * a12)) / det
    x2 = (r0 * c02 + r1 * (a01 * a02 - a00 * a12) + r2 * (a00 * a11 - a01 * a01)) / det
    return x0, x1, x2


def _fused_reduction(reference):
    """Decorator: the decorated function computes several reductions as ONE variadic ``lax.reduce`` (one
    XLA:CPU kernel instead of one per result); its derivatives come from ``reference``, the same reductions
    as plain jnp calls (JAX cannot differentiate a variadic reduce with symbolic-zero tangents)."""

    def wrap(fused):
        f = jax.custom_jvp(fused)
        f.defjvp(lambda primals, tangents: (fused(*primals), jax.jvp(reference, primals, tangents)[1]))
        return f

    return wrap


def _add(x, y):
    return tuple(p + q for p, q in zip(x, y, strict=True))


@_fused_reduction(lambda a, b: (jnp.sum(a, axis=1), jnp.sum(b, axis=1)))
def _row_sums(a, b):
    """Sums of two (K, R) arrays along rows, ((K,), (K,))."""
    return lax.reduce((a, b), (jnp.zeros((), a.dtype),) * 2, _add, (1,))


@_fused_reduction(lambda *xs: tuple(jnp.sum(x) for x in xs))
def _totals(*xs):
    """Sums of several (K,) arrays, one scalar each."""
    return lax.reduce(xs, (jnp.zeros((), xs[0].dtype),) * len(xs), _add, (0,))


@_fused_reduction(lambda a, *bs: (jnp.sum(a), *(jnp.max(b) for b in bs)))
def _sum_and_maxima(a, *bs):
    """(sum(a), max(b_1), ..., max(b_n)) of (K, R) arrays, one fused reduction."""
    z = jnp.zeros((), a.dtype)
    return lax.reduce((a, *bs), (z, *(z - jnp.inf for _ in bs)),
                      lambda x, y: (x[0] + y[0], *(jnp.maximum(p, q) for p, q in zip(x[1:], y[1:], strict=True))),
                      (0, 1))


def far_frame(terrain: Terrain) -> jax.Array:
    """() bool: the map reaches beyond :data:`MAX_COORDINATE` or its origin is not finite (flagged
    ``unsupported`` inside a jit, where :func:`check_frame` cannot see the origin's value)."""
    return ~(jnp.asarray(frame_extent(terrain)) <= MAX_COORDINATE)


def query_supported(terrain: Terrain, robot: Robot) -> jax.Array:
    """() bool: FootCost supports this robot on this terrain (traceable; the one rule of both paths).

    False when the robot's values break a rule of :func:`~ijoy_jax.robots.robot_supported` (NaN, a negative
    margin, weight or cost, a footprint beyond its static window, ...), the terrain's break
    :func:`~ijoy_jax.terrain.terrain_supported` (a non-finite origin or height), or the map reaches beyond
    :data:`MAX_COORDINATE` (:func:`far_frame`): the values the boundary checks refuse where they are
    concrete. Where False, every candidate of :func:`foot_cost_terms` is +inf with its ``unsupported`` term
    set, and so is every total of :func:`~ijoy_jax.footcost.pallas.foot_cost_fused`;
    :func:`ijoy_jax.select_step` reports ``unsupported``.
    """
    return robot_supported(robot) & terrain_supported(terrain) & ~far_frame(terrain)


def poses_supported(stance, stance_side, swing_from=None) -> jax.Array:
    """() bool: a query's own traced values are ones FootCost supports (traceable; both paths' rule).

    False when ``stance`` or ``swing_from`` is not finite or turns beyond :data:`~ijoy_jax.geometry.MAX_ANGLE`
    (:func:`~ijoy_jax.geometry.pose_supported`), or ``stance_side`` is not exactly +1 or -1: the values the
    boundary checks refuse where they are concrete. Where False, every candidate is +inf with its
    ``unsupported`` term set, as for :func:`query_supported`; compute with :func:`safe_poses`' stand-ins.
    """
    side = jnp.asarray(stance_side)
    ok = geometry.pose_supported(stance) & ((side == 1) | (side == -1))
    return ok if swing_from is None else ok & geometry.pose_supported(swing_from)


def safe_poses(stance, swing_from=None):
    """``(stance, swing_from)`` as float32 with each non-finite pose replaced by zeros: the finite stand-ins an
    unsupported query (:func:`poses_supported`) computes with, so no NaN reaches a result."""

    def safe(pose):
        pose = jnp.asarray(pose, jnp.float32)
        return jnp.where(jnp.all(jnp.isfinite(pose)), pose, 0.0)

    return safe(stance), None if swing_from is None else safe(swing_from)


def plane_metrics(terrain: Terrain, index: TerrainIndex, robot: Robot, pose: jax.Array) -> Plane:
    """Least-squares plane under the footprint at ``pose`` (3,) (world x, y, yaw), the metrics around it, and the
    rested sole.

    The fit is over the centres and heights of the cells the footprint touches; the safety band is the
    cells the footprint grown by the robot's margin touches besides. A degenerate fit (no cells: a pose
    far off the map) gives the height of the cell under the foot centre and zero gradient and metrics.
    The rested sole (:mod:`ijoy_jax.footcost.sole`) stands on the ground under its contact points
    (``robot.metrics.contact_inset``), interpolated bilinearly between cell centres as a height field's
    surface is; its contact polygon holds the points within ``robot.metrics.contact_tol`` of it.

    Returns:
      :class:`Plane` of () float32 values.
    """
    res = terrain.resolution
    k = index.pad
    origin = jnp.asarray(terrain.origin, jnp.float32)  # float32 also under x64 (an origin may be float64)
    cx = pose[0] - origin[0]
    cy = pose[1] - origin[1]
    hl, hw = 0.5 * robot.foot_length, 0.5 * robot.foot_width
    grown = geometry.rect_column_spans(cx, cy, pose[2], hl + robot.margin, hw + robot.margin, res, k)
    foot = geometry.rect_column_spans(cx, cy, pose[2], hl, hw, res, k, ix0=grown.ix[0])
    iy0 = jnp.min(jnp.where(grown.touched, grown.j0, jnp.iinfo(jnp.int32).max))
    iy0 = jnp.where(jnp.any(grown.touched), iy0, 0)
    nx, ny = terrain.shape
    sx = jnp.clip(grown.ix[0] + k, 0, nx + k)
    sy = jnp.clip(iy0 + k, 0, ny + k)
    window = lax.dynamic_slice(index.height_padded, (sx, sy), (k, k))
    m_foot = geometry.spans_mask(foot, iy0, k)  # (K, K) bool; stays bool: XLA:CPU converts it to float slowly
    m_band = geometry.spans_mask(grown, iy0, k) & ~m_foot
    u = (grown.ix + 0.5) * res - cx  # (K,) column centres relative to the foot centre
    v = (iy0 + jnp.arange(k, dtype=jnp.int32) + 0.5) * res - cy  # (K,) row centres
    # Heights relative to the cell under the foot centre, for float32 conditioning.
    ic = jnp.clip(jnp.floor(cx / res).astype(jnp.int32) - grown.ix[0], 0, k - 1)
    jc = jnp.clip(jnp.floor(cy / res).astype(jnp.int32) - iy0, 0, k - 1)
    h_ref = window[ic, jc]
    hrel = window - h_ref
    # Per column: the foot covers rows lo..hi of the window, so its cell count and the sums of v and v^2
    # over them are closed forms (O(K)); only the height sums need a pass over the window.
    lo = jnp.maximum(foot.j0, iy0)
    hi = jnp.minimum(foot.j1, iy0 + k - 1)
    cnt = jnp.where(foot.touched, jnp.maximum(hi - lo + 1, 0), 0)
    c0 = cnt.astype(window.dtype)
    v_mid = 0.5 * (lo + hi + 1).astype(window.dtype) * res - cy  # mean of v over the column's rows
    cv = c0 * v_mid
    cvv = c0 * v_mid * v_mid + (res * res / 12.0) * c0 * (c0 * c0 - 1.0)
    mh = jnp.where(m_foot, hrel, 0.0)
    c1, cvh = _row_sums(mh, mh * v[None, :])
    cols = (c0, c0 * u, c0 * u * u, cv, cv * u, cvv, c1, c1 * u, cvh)
    n, su, suu, sv, suv, svv, sh, suh, svh = _totals(*cols)
    n = jnp.maximum(n, 1.0)
    ridge = 1e-6 * n * res * res  # keeps a one-column footprint well-posed (slope -> 0)
    a, b, c = solve3(n, su, sv, suu + ridge, suv, svv + ridge, sh, suh, svh)
    resid = hrel - (a + b * u[:, None] + c * v[None, :])
    slope = jnp.arctan(jnp.sqrt(b * b + c * c))
    abs_sum, top, band = _sum_and_maxima(
        jnp.where(m_foot, jnp.abs(resid), 0.0), jnp.where(m_foot, resid, -jnp.inf),
        jnp.where(m_band, jnp.abs(resid), 0.0))
    roughness = abs_sum / n
    bump = jnp.maximum(top, 0.0)
    # The rested sole (footcost.sole): the ground under its contact points, between cell centres as a height
    # field meets a sphere, relative to h_ref.
    cos, sin = jnp.cos(pose[2]), jnp.sin(pose[2])
    metrics = robot.metrics
    du, dv = contact_offsets(hl, hw, metrics.contact_inset, cos, sin)
    ground = bilinear_height(index.height_padded, k, cx + jnp.stack(du), cy + jnp.stack(dv), res, h_ref)
    # Fenced off from the program around it: XLA fused the rest's arithmetic with its neighbours differently in
    # different programs (select_step and foot_cost_terms in one jit, as the footstep server runs them, against
    # foot_cost_terms alone), and the sole's roll came out an ulp apart; fenced, it is the same in every program.
    ground, inset, tol = lax.optimization_barrier((ground, metrics.contact_inset, metrics.contact_tol))
    rest = lax.optimization_barrier(sole_on_ground(tuple(ground), hl, hw, inset, tol))
    ok = jnp.isfinite(a) & jnp.isfinite(b) & jnp.isfinite(c)
    rested = jnp.isfinite(rest.height)
    z = jnp.float32(0.0)
    return Plane(
        height=jnp.where(ok, a + h_ref, h_ref),
        slope=jnp.where(ok, slope, z),
        roughness=jnp.where(ok, roughness, z),
        bump=jnp.where(ok, bump, z),
        band=jnp.where(ok, band, z),
        support=jnp.where(rested, rest.support, z),
        fitted=ok & rested,
        grad_x=jnp.where(ok, b, z),
        grad_y=jnp.where(ok, c, z),
        rest_height=jnp.where(rested, rest.height + h_ref, h_ref),
        rest_pitch=jnp.where(rested, rest.pitch, z),
        rest_roll=jnp.where(rested, rest.roll, z),
    )


def bilinear_height(padded, pad: int, x, y, res, ref):
    """Heights between cell centres (bilinear) at map coordinates ``x``, ``y`` (m, arrays of one shape) from the
    map edge-padded by ``pad`` cells, less ``ref`` (m; subtracted from each cell first, for float32 conditioning);
    beyond the padding the edge cells' (such poses are flagged off the map)."""
    gx, gy = x / res - 0.5, y / res - 0.5
    fx, fy = jnp.floor(gx), jnp.floor(gy)
    tx, ty = gx - fx, gy - fy
    i = jnp.clip(fx.astype(jnp.int32) + pad, 0, padded.shape[0] - 2)
    j = jnp.clip(fy.astype(jnp.int32) + pad, 0, padded.shape[1] - 2)
    return ((1.0 - tx) * ((1.0 - ty) * (padded[i, j] - ref) + ty * (padded[i, j + 1] - ref))
            + tx * ((1.0 - ty) * (padded[i + 1, j] - ref) + ty * (padded[i + 1, j + 1] - ref)))


def exceeds(metric, limit):
    """The one rule for limits, on both paths: a metric rejects a step when it exceeds its limit by more than
    :data:`LIMIT_TOL` (slope, roughness, bump, step height, band, the swing corridor's height against the
    action's clearance, the sole's pitch and roll and the distance between the soles)."""
    return metric > limit + LIMIT_TOL


def metric_term(weight, metric, limit):
    """``weight * metric``, or +inf when the metric :func:`exceeds` its limit."""
    return jnp.where(exceeds(metric, limit), jnp.inf, weight * metric)


def _inf_if(flag):
    return jnp.where(flag, jnp.inf, 0.0).astype(jnp.float32)


def footprint_blocked(terrain: Terrain, index: TerrainIndex, pose: jax.Array, half_length,
                      half_width) -> tuple[geometry.ColumnSpans, jax.Array]:
    """FootCost's obstacle test of one footprint: a rectangle of half sizes ``half_length`` x ``half_width`` (m;
    a margin already added) at world ``pose`` (3,) (x, y, yaw; finite).

    Returns its exact column spans in the index's window (``index.pad`` columns) and a () bool: the rectangle
    overlaps an obstacle cell, leaves the map, or has its centre off the map (the ``obstacle`` term is +inf
    where True). Spans that ``overflow`` the window are incomplete; the caller decides what that means.
    """
    res = terrain.resolution
    origin = jnp.asarray(terrain.origin, jnp.float32)  # float32 also under x64 (an origin may be float64)
    cx = pose[0] - origin[0]
    cy = pose[1] - origin[1]
    spans = geometry.rect_column_spans(cx, cy, pose[2], half_length, half_width, res, index.pad)
    blocked = jnp.any(column_has_obstacle(index, spans, terrain.shape)) | centre_off_map(cx, cy, terrain.shape, res)
    return spans, blocked


def _step_terms(terrain, index, robot, stance, stance_plane, start_plane, swing_from, step,
                action_index, query_ok=True) -> FootCostTerms:
    """FootCost terms of one candidate step (world pose (3,)) executing ``action_index`` from ``stance`` (3,);
    ``query_ok`` False (:func:`poses_supported`) flags it unsupported."""
    res = terrain.resolution
    finite = jnp.all(jnp.isfinite(step))
    step = jnp.where(finite, step, 0.0)
    origin = jnp.asarray(terrain.origin, jnp.float32)  # float32 also under x64 (an origin may be float64)
    cx = step[0] - origin[0]
    cy = step[1] - origin[1]
    grown, blocked = footprint_blocked(terrain, index, step, 0.5 * robot.foot_length + robot.margin,
                                       0.5 * robot.foot_width + robot.margin)
    # The robot's and terrain's values (query_supported: a footprint beyond max_radius among them) and this
    # candidate's own: its grown footprint, swing corridor or plane fit beyond what the windows or float32 hold.
    too_big = grown.overflow | ~query_supported(terrain, robot) | ~jnp.asarray(query_ok)
    metrics = robot.metrics
    zero = jnp.float32(0.0)
    neg_inf = jnp.float32(-jnp.inf)
    if terrain.has_height:
        plane = plane_metrics(terrain, index, robot, step)
        dh = plane.rest_height - stance_plane.rest_height
        slope = metric_term(metrics.slope_weight, plane.slope, metrics.slope_limit)
        rough = metric_term(metrics.roughness_weight, plane.roughness, metrics.roughness_limit)
        bump = metric_term(metrics.bump_weight, plane.bump, metrics.bump_limit)
        stepc = metric_term(metrics.step_weight, jnp.abs(dh), robot.max_step_height[action_index])
        band = metric_term(metrics.band_weight, plane.band, metrics.band_limit)
        support = metric_term(metrics.support_weight, plane.support, metrics.support_limit)
        raw = (plane.slope, plane.roughness, plane.bump, dh, plane.band, plane.rest_height, plane.support)
        too_big = too_big | ~plane.fitted | ~stance_plane.fitted
        pitch, roll = plane.rest_pitch, plane.rest_roll
    else:
        slope = rough = bump = stepc = band = support = zero
        raw = (zero,) * 7
        pitch = roll = zero
    ankle_bad = exceeds(jnp.abs(pitch), robot.max_sole_pitch) | exceeds(jnp.abs(roll), robot.max_sole_roll)
    distance = sole_distance(step[0] - stance[0], step[1] - stance[1], raw[3])
    reach_bad = exceeds(distance, robot.max_sole_distance)
    path_height = neg_inf
    path_bad = jnp.bool_(False)
    if terrain.has_height and swing_from is not None:
        kp = check_window(0.5 * robot.max_swing, res, "swing path")
        sx = swing_from[0] - origin[0]
        sy = swing_from[1] - origin[1]
        corridor, length = swing_corridor(sx, sy, cx, cy, 0.5 * robot.foot_width, res, kp)
        top, off_map = column_max_height(index, corridor, terrain.shape)
        path_height = top - jnp.maximum(start_plane.rest_height, raw[5])
        path_bad = off_map | exceeds(path_height, robot.clearance[action_index])
        too_big = (too_big | corridor.overflow | (length + robot.foot_width > robot.max_swing + SLACK)
                   | ~start_plane.fitted)
    action = robot.action_cost[action_index]
    obstacle = _inf_if(blocked)
    swing = _inf_if(path_bad)
    ankle = _inf_if(ankle_bad)
    reach = _inf_if(reach_bad)
    flagged = too_big | ~finite
    unsupported = _inf_if(flagged)
    # +inf where flagged, whatever the other terms hold; a term that an unsupported value (a NaN weight, cost
    # or limit) makes NaN cannot be evaluated, and reads +inf too: no cost term is ever NaN.
    action, slope, rough, bump, stepc, band, support = (
        jnp.where(jnp.isnan(t), jnp.inf, t) for t in (action, slope, rough, bump, stepc, band, support))
    total = jnp.where(flagged, jnp.inf, action + obstacle + slope + rough + bump + stepc + band + support
                      + swing + ankle + reach)
    return FootCostTerms(
        total=total,
        action=action,
        obstacle=obstacle,
        slope=slope,
        roughness=rough,
        bump=bump,
        step=stepc,
        band=band,
        support=support,
        swing_path=swing,
        ankle=ankle,
        reach=reach,
        unsupported=unsupported,
        slope_angle=raw[0],
        roughness_m=raw[1],
        bump_m=raw[2],
        step_height_m=raw[3],
        band_m=raw[4],
        support_m=raw[6],
        path_height_m=path_height,
        foot_height_m=raw[5],
        sole_pitch_rad=pitch,
        sole_roll_rad=roll,
        sole_distance_m=distance,
        action_index=jnp.asarray(action_index, jnp.int32),
    )


def check_action_index(robot: Robot, action_index, num: int) -> None:
    """Refuse an ``action_index`` argument that is not () or (num,) integers, or (where concrete) that indexes
    outside the action set ``[0, robot.num_actions)``. Traced values are flagged inside instead
    (:func:`safe_action_index`)."""
    if action_index is None:
        return
    shape = np.shape(action_index)
    if shape not in ((), (num,)):
        raise ValueError(f"action_index must be one int or ({num},) ints (one per step), got shape {shape}")
    dtype = action_index.dtype if hasattr(action_index, "dtype") else np.asarray(action_index).dtype
    if dtype.kind not in "iu":
        raise TypeError(f"action_index must hold integers, got dtype {dtype}")
    if not is_traced(action_index):
        a = np.asarray(action_index)
        bad = (a < 0) | (a >= robot.num_actions)
        if bad.any():
            raise ValueError(f"action_index must be in [0, {robot.num_actions}) (the robot's action set), got "
                             f"{int(a[bad].ravel()[0])}")


def safe_action_index(robot: Robot, action_index, num: int) -> tuple[jax.Array, jax.Array]:
    """``(index, ok)``: (num,) int32 action indices (one given index is broadcast) with every one outside
    ``[0, robot.num_actions)`` replaced by 0, and ``ok`` whether each was inside (a step with a bad index is
    flagged ``unsupported``, never another action's cost read silently: a gather clamps out-of-range indices)."""
    a = jnp.broadcast_to(jnp.asarray(action_index, jnp.int32), (num,))
    ok = (a >= 0) & (a < robot.num_actions)
    return jnp.where(ok, a, 0), ok


def _foot_cost_terms(terrain, robot, stance, stance_side, steps, swing_from, action_index, index) -> FootCostTerms:
    """The body of :func:`foot_cost_terms` (always run through :data:`_foot_cost_terms_jit`)."""
    if index is None:
        index = index_terrain(terrain, robot)
    steps = jnp.asarray(steps, jnp.float32).reshape(-1, 3)
    query_ok = poses_supported(stance, stance_side, swing_from)
    stance, swing_from = safe_poses(stance, swing_from)
    if action_index is None:
        action_index = nearest_actions(robot, stance, stance_side, steps)
    action_index, index_ok = safe_action_index(robot, action_index, steps.shape[0])
    stance_plane = start_plane = None
    if terrain.has_height and swing_from is None:
        stance_plane = plane_metrics(terrain, index, robot, stance)
    elif terrain.has_height:  # both feet's planes as one batched fit: one copy of it in the program, not two
        planes = jax.vmap(lambda pose: plane_metrics(terrain, index, robot, pose))(jnp.stack([stance, swing_from]))
        stance_plane = jax.tree_util.tree_map(lambda x: x[0], planes)
        start_plane = jax.tree_util.tree_map(lambda x: x[1], planes)

    def one(step, a, a_ok):
        return _step_terms(terrain, index, robot, stance, stance_plane, start_plane, swing_from, step, a,
                           query_ok & a_ok)

    return jax.vmap(one)(steps, action_index, index_ok)


_foot_cost_terms_jit = jax.jit(_foot_cost_terms)


def _finite32(value) -> bool:
    """Whether a concrete value is finite once cast to the float32 it is computed in (1e39 is not)."""
    with np.errstate(over="ignore"):
        return bool(np.all(np.isfinite(np.asarray(value, np.float32))))


def validate(terrain, robot, stance, stance_side, steps, swing_from=None, index=None):
    """Check the arguments of :func:`foot_cost_terms` (raises ValueError / TypeError).

    Values of tracers are not checked (their shapes are), so it costs nothing inside a trace.
    """
    if not isinstance(terrain, Terrain):
        raise TypeError(f"terrain must be an ijoy_jax.Terrain, got {type(terrain).__name__}")
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be an ijoy_jax.robots.Robot, got {type(robot).__name__}")
    if index is not None and not isinstance(index, TerrainIndex):
        raise TypeError(f"index must be an ijoy_jax.footcost.TerrainIndex, got {type(index).__name__}")
    if terrain.free.ndim != 2:
        raise ValueError(
            f"foot_cost takes one terrain (free of shape (nx, ny)), got {terrain.free.shape}; vmap over batches"
        )
    check_terrain(terrain)
    check_robot(robot)
    for name, value, shape in (("stance", stance, (3,)), ("swing_from", swing_from, (3,))):
        if value is None:
            continue
        check_numeric(name, value)
        if np.shape(value) != shape:
            raise ValueError(f"{name} must have shape {shape}, got {np.shape(value)}")
        if not isinstance(value, jax.core.Tracer) and not _finite32(value):
            raise ValueError(f"{name} must be finite, got {np.asarray(value).tolist()}")
    check_frame(terrain)
    check_numeric("steps", steps)
    s = np.shape(steps)
    if len(s) != 2 or s[1] != 3:
        raise ValueError(f"steps must have shape (N, 3) of (x, y, theta) world poses, got {s}")
    if not isinstance(stance_side, jax.core.Tracer):
        side = np.asarray(stance_side)
        if side.shape != () or side.dtype.kind not in "iuf" or float(side) not in (-1.0, 1.0):
            raise ValueError(f"stance_side must be +1 (left stance foot) or -1 (right), got {stance_side!r}")


def checked_query(terrain, robot, stance, stance_side, steps, swing_from=None, index=None):
    """The boundary of both FootCost paths: lists (of numbers or traced scalars) as float32 arrays
    (:func:`~ijoy_jax._struct.as_array`), then :func:`validate`; returns ``(stance, steps, swing_from)``."""
    stance, steps, swing_from = (as_pose(n, v) for n, v in (("stance", stance), ("steps", steps),
                                                            ("swing_from", swing_from)))
    validate(terrain, robot, stance, stance_side, steps, swing_from, index)
    return stance, steps, swing_from


def foot_cost_terms(
    terrain: Terrain,
    robot: Robot,
    stance,
    stance_side,
    steps,
    *,
    swing_from=None,
    action_index=None,
    index: TerrainIndex | None = None,
) -> FootCostTerms:
    """FootCost of candidate swing-foot poses, with every named term and raw metric.

    The public entry point and the function to call inside your own jit, vmap
    or grad: the checks below skip traced values, and the work runs through
    one module-level jit (an eager loop compiles once; inside your jit it is
    inlined into your program).

    Args:
      terrain: one :class:`~ijoy_jax.Terrain` (vmap for batches).
      robot: a :class:`~ijoy_jax.robots.Robot`.
      stance: (3,) world pose (x, y, theta) of the stance foot (m, rad).
      stance_side: +1 for a left stance foot, -1 for a right one (the swing
        foot is the other one; its actions are mirrored accordingly).
      steps: (N, 3) candidate world poses of the swing foot centre; the
        footprint's length runs along the foot's own x axis.
      swing_from: (3,) current world pose of the swing foot, for the swing-path
        check (2.5D only); None: no path check.
      action_index: (N,) (or one) int indices into the action set, in
        ``[0, robot.num_actions)``: whose cost, clearance and height limit
        apply to each step. None: the nearest action of S to each step in the
        stance frame (:func:`nearest_actions`). A traced index outside the set
        flags its step ``unsupported``.
      index: the terrain's prebuilt :class:`TerrainIndex`
        (:func:`~ijoy_jax.footcost.index_terrain` of this terrain and robot),
        for many queries on one terrain; None: built inside.

    Returns:
      :class:`FootCostTerms` of (N,) arrays.

    Raises:
      ValueError: wrong shapes, non-finite poses or a stance_side that is not
        +-1 (values are checked when concrete; a traced non-finite step gets
        +inf in the ``unsupported`` term), or a map that reaches beyond
        :data:`MAX_COORDINATE` (e.g. a UTM origin), where float32 cannot
        resolve millimetres: shift your world frame (a traced origin there
        flags every step ``unsupported``).
      TypeError: an argument of the wrong type.
    """
    stance, steps, swing_from = checked_query(terrain, robot, stance, stance_side, steps, swing_from, index)
    check_action_index(robot, action_index, steps.shape[0])
    return _foot_cost_terms_jit(terrain, robot, stance, side_sign(stance_side), steps, swing_from, action_index,
                                index)


def foot_cost(
    terrain: Terrain,
    robot: Robot,
    stance,
    stance_side,
    steps,
    *,
    swing_from=None,
    action_index=None,
    index: TerrainIndex | None = None,
) -> jax.Array:
    """(N,) FootCost of candidate swing-foot poses: +inf where invalid, else >= 0.

    Same arguments as :func:`foot_cost_terms`, which also returns the named
    terms. Jit- and vmap-able (over terrains, poses and robot parameters).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> free = np.ones((100, 100), bool); free[60:, :] = False  # obstacle beyond x = 1.2 m
      >>> terrain = ij.terrain.from_arrays(None, free, resolution=0.02)
      >>> robot = ij.robots.hrp2(margin=0.02)
      >>> stance = np.array([0.8, 1.0, 0.0])                       # right foot
      >>> steps = np.array([[0.8, 1.19, 0.0], [1.15, 1.19, 0.0]])  # in place; into the obstacle
      >>> ij.foot_cost(terrain, robot, stance, -1, steps)
      Array([ 0., inf], dtype=float32)
    """
    return foot_cost_terms(terrain, robot, stance, stance_side, steps, swing_from=swing_from,
                           action_index=action_index, index=index).total
