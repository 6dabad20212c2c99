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

The parts both paths share live beside this one: the plane fit and the rested sole in
:mod:`ijoy_jax.footcost.plane`, what a query may hold and its boundary checks in
:mod:`ijoy_jax.footcost.query`. This module holds the named terms and their evaluation.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ijoy_jax import geometry
from ijoy_jax.footcost.index import (
    TerrainIndex,
    centre_off_map,
    column_has_obstacle,
    column_max_height,
    index_terrain,
    swing_corridor,
)
from ijoy_jax.footcost.plane import Plane as Plane
from ijoy_jax.footcost.plane import bilinear_height as bilinear_height
from ijoy_jax.footcost.plane import plane_metrics as plane_metrics
from ijoy_jax.footcost.plane import sole_tilt as sole_tilt
from ijoy_jax.footcost.plane import solve3 as solve3
from ijoy_jax.footcost.query import MAX_COORDINATE as MAX_COORDINATE
from ijoy_jax.footcost.query import check_action_index as check_action_index
from ijoy_jax.footcost.query import check_frame as check_frame
from ijoy_jax.footcost.query import checked_query as checked_query
from ijoy_jax.footcost.query import far_frame as far_frame
from ijoy_jax.footcost.query import frame_extent as frame_extent
from ijoy_jax.footcost.query import poses_supported as poses_supported
from ijoy_jax.footcost.query import query_supported as query_supported
from ijoy_jax.footcost.query import safe_action_index as safe_action_index
from ijoy_jax.footcost.query import safe_poses as safe_poses
from ijoy_jax.footcost.query import validate as validate
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.limits import check_window
from ijoy_jax.robots import Robot, nearest_actions, side_sign
from ijoy_jax.terrain import Terrain

SLACK = 1e-6  # m: float32 rounding allowed above the robot's float64 static window sizes
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
        (:func:`~ijoy_jax.footcost.query_supported`: a negative margin, weight
        or cost, NaN, a non-finite origin or height, a map beyond
        :data:`~ijoy_jax.footcost.MAX_COORDINATE`,
        set by ``replace`` or vmap inside a jit). The total is then +inf,
        and a term such a value makes NaN (a NaN weight) reads +inf: no
        cost term is ever NaN.

    Raw metrics (for plots and tests)::

      slope_angle (rad), roughness_m, bump_m, step_height_m (signed, up is
      positive, between the rested soles), band_m, support_m, path_height_m
      (corridor height above the higher foothold; -inf if no check),
      foot_height_m (the rested sole's height at the foot centre),
      sole_pitch_rad and sole_roll_rad (the rested sole's orientation with the
      step's heading, ``R = Rz(yaw) Ry(pitch) Rx(roll)``: :func:`~ijoy_jax.footcost.plane.sole_tilt`'s
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


def sole_distance(dx, dy, dz):
    """3D distance between two sole centres ``sqrt(dx^2 + dy^2 + dz^2)`` (m): the ``reach`` metric, one formula
    for both FootCost paths (plain products and a square root, as the fused kernel lowers them)."""
    return jnp.sqrt(dx * dx + dy * dy + dz * dz)


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
        :data:`~ijoy_jax.footcost.MAX_COORDINATE` (e.g. a UTM origin), where float32 cannot
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


def compiled_programs() -> int:
    """How many programs :func:`foot_cost_terms` and :func:`foot_cost` hold compiled (in this process).

    Read it before and after a loop of calls to learn how many compiles the loop caused: each new input
    shape (the number of steps, a ``swing_from``, ``action_index`` or ``index`` given or not) or static field
    of the robot or terrain compiles once; new terrain values, robot parameters and poses reuse the program.
    """
    return compiled_count(_foot_cost_terms_jit)
