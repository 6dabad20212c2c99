"""A smooth relaxation of FootCost and of step selection, for tuning by gradient.

The exact selector (:mod:`ijoy_jax.select`) is an argmin over the action set of
``FootCost + w * dist`` where FootCost is +inf for invalid steps: piecewise
constant in every parameter, so its gradient is useless. This module replaces

* exact cell coverage by *soft coverage*: each window cell's membership in a
  rectangle is the separating-axis test made smooth, a product of four
  "boxes" ``sigmoid(k (h - x)) sigmoid(k (h + x))`` over the two cell axes and
  the two rectangle axes, with ``k = sharpness / resolution``. As
  ``sharpness -> inf`` it tends to the exact "interiors overlap" indicator of
  :mod:`ijoy_jax.geometry` everywhere except on the measure-zero boundary;
* the obstacle check by a linear barrier ``barrier_weight * sharpness * mass``
  on the soft obstacle mass (cells off the map count as obstacles);
* each metric limit by a softplus barrier
  ``barrier_weight * softplus(sharpness * (metric - limit) / limit)``, which
  tends to 0 below the limit and to +inf above it;
* the least-squares plane under the foot by a fit weighted by soft membership;
  max/abs in the metrics by log-sum-exp and ``sqrt(x^2 + e^2) - e`` with a
  height scale ``e = resolution / sharpness`` (metres);
* the swing-path check (``swing_from``, 2.5D only): the corridor (the
  foot-wide rectangle between the swing foot's start and end centres) gets soft
  coverage m_i, its height above the higher of the two soft foothold planes is
  the soft max of gated heights ``e log(1 + sum_i exp(m_i (h_i - h_ref) / e))``
  (a soft ``max(0, top - h_ref)``; clipping at 0 changes no decision since
  clearances are >= 0), and the clearance check is the softplus barrier above;
  corridor cells off the map count like obstacles, and a swing longer than the
  path window (``max_swing``) gets a softplus barrier.
* the rested sole (:mod:`ijoy_jax.footcost.sole`) stands on the ground under
  its contact points interpolated with rounded tents; its rest pose is exact
  (continuous, piecewise linear in the heights) and its contact polygon's
  margin an expectation over soft contacts
  (:func:`ijoy_jax.footcost.sole.soft_sole_on_ground`);
* the ankle-tilt and reach limits (the rested sole's pitch and roll, the 3D
  distance of the soles) by the same softplus barriers;
* the argmin by a Boltzmann distribution ``p_i ~ exp(-cost_i / tau)``.

Every output is finite for finite inputs and differentiable with respect to
every Robot leaf (w, rotation_weight, margin, foot size, step_time, action
costs, step-height limits, clearances, metric weights and limits, ankle-tilt
and reach limits) and the
poses. Not relaxed: the static-window ``unsupported`` check of the footprint
(a window that leaves the padded map gets a constant finite barrier instead).

Units: metres, radians, seconds; costs in the cost units of FootCost.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ijoy_jax import geometry
from ijoy_jax.footcost import foot_cost_terms, window_cells
from ijoy_jax.footcost.sole import contact_offsets, soft_sole_on_ground
from ijoy_jax.robots import Robot, dist, side_actions, side_p0, side_sign
from ijoy_jax.targets import Targets, make_targets
from ijoy_jax.terrain import Terrain

_EXTRA_CELLS = 2  # window border (cells each side) that holds the soft-coverage tails
_ABS_EPS = 1e-3  # smoothing of |cos|, |sin| in projected half-extents (dimensionless; <= 1e-3 res bias)
_RIDGE = 1e-6  # plane-fit ridge per (cell count + 1), in cell units, as footcost's


def _smooth_abs(x, eps):
    """|x| smoothed at 0: ``sqrt(x^2 + eps^2) - eps`` (within eps of |x|, smooth gradient)."""
    return jnp.sqrt(x * x + eps * eps) - eps


def _box(x, half, k):
    """Soft indicator of |x| < half: sigmoid(k (half - x)) * sigmoid(k (half + x))."""
    return jax.nn.sigmoid(k * (half - x)) * jax.nn.sigmoid(k * (half + x))


def soft_coverage(dx, dy, theta, half_length, half_width, resolution: float, sharpness):
    """Soft membership in (0, 1) of grid cells in a rotated rectangle.

    The separating-axis test of an axis-aligned cell (edge ``resolution``)
    against the rectangle, with each of its four 1D overlap tests replaced by
    a product of sigmoids of slope ``sharpness / resolution``. Tends to the
    exact "interiors overlap" indicator as ``sharpness -> inf``.

    Args:
      dx, dy: (...) cell-centre offsets from the rectangle centre (m).
      theta: () rectangle angle (rad); its length runs along theta.
      half_length, half_width: () half sizes (m), >= 0 (zero gives a point).
      resolution: cell edge (m), Python float.
      sharpness: () dimensionless, > 0.

    Returns:
      (...) membership, same dtype as ``dx``.

    Example:
      >>> import jax.numpy as jnp
      >>> m = soft_coverage(jnp.array([0.0, 0.5]), jnp.array([0.0, 0.0]), 0.0, 0.1, 0.05, 0.02, 50.0)
      >>> [round(float(v), 3) for v in m]
      [1.0, 0.0]
    """
    return _soft_coverage_cs(dx, dy, jnp.cos(theta), jnp.sin(theta), half_length, half_width, resolution, sharpness)


def _soft_coverage_cs(dx, dy, c, s, half_length, half_width, resolution: float, sharpness):
    """:func:`soft_coverage` with the rectangle's direction given as (cos, sin) (need not be unit).

    A direction shorter than unit (a corridor of almost zero length, see
    :func:`_swing_path`) shrinks the projections smoothly instead of taking an
    ill-defined angle.
    """
    k = sharpness / resolution
    ac, as_ = _smooth_abs(c, _ABS_EPS), _smooth_abs(s, _ABS_EPS)
    r = 0.5 * resolution
    du = c * dx + s * dy
    dv = -s * dx + c * dy
    return (
        _box(du, half_length + r * (ac + as_), k)
        * _box(dv, half_width + r * (ac + as_), k)
        * _box(dx, r + half_length * ac + half_width * as_, k)
        * _box(dy, r + half_length * as_ + half_width * ac, k)
    )


class SoftFootCostTerms(NamedTuple):
    """Relaxed FootCost of N candidate steps: total, named terms and raw metrics (all (N,)).

    Cost terms (cost units; finite): total (their sum), action, obstacle
    (barrier on the soft obstacle mass), slope, roughness, bump, step, band,
    support (each ``weight * metric + barrier``; 0 on 2D terrains), swing_path
    (clearance barrier on the swing corridor plus its off-map and length
    barriers; 0 without ``swing_from`` or on 2D terrains), ankle (barriers on
    the size of the rested sole's pitch and roll against the
    robot's ``max_sole_pitch`` and ``max_sole_roll``; 0 on 2D terrains), reach
    (barrier on the 3D distance of the soles against ``max_sole_distance``).
    Raw: obstacle_mass (cells, soft count of obstacle or off-map cells under
    the grown footprint), slope_angle (rad), roughness_m, bump_m,
    step_height_m (signed, between the rested soles), band_m, foot_height_m
    (m, the rested sole's), support_m (m; the expected contact polygon's,
    :func:`ijoy_jax.footcost.sole.soft_sole_on_ground`), path_height_m (m, soft
    ``max(0, corridor top - higher foothold)``; 0 when not checked),
    sole_pitch_rad, sole_roll_rad (the rested sole's on the soft ground),
    sole_distance_m (m).
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
    obstacle_mass: jax.Array
    slope_angle: jax.Array
    roughness_m: jax.Array
    bump_m: jax.Array
    step_height_m: jax.Array
    band_m: jax.Array
    foot_height_m: jax.Array
    support_m: jax.Array
    swing_path: jax.Array
    path_height_m: jax.Array
    ankle: jax.Array
    reach: jax.Array
    sole_pitch_rad: jax.Array
    sole_roll_rad: jax.Array
    sole_distance_m: jax.Array


class _Patch(NamedTuple):
    du: jax.Array  # (K,) column-centre x offsets from the pose (m)
    dv: jax.Array  # (K,) row-centre y offsets (m)
    free: jax.Array  # (K, K) 1.0 where free, 0.0 for obstacles / off the map
    height: jax.Array  # (K, K) heights (m)
    outside: jax.Array  # () bool: the window was clipped (pose far off the map)


def _window_size(robot: Robot, res: float) -> int:
    return window_cells(robot.max_radius, res) + 2 * _EXTRA_CELLS


def _patch(terrain: Terrain, free_pad, h_pad, k: int, pose) -> _Patch:
    res = terrain.resolution
    nx, ny = terrain.shape
    cx = pose[0] - terrain.origin[0]
    cy = pose[1] - terrain.origin[1]
    i0 = jnp.floor(cx / res).astype(jnp.int32) - k // 2
    j0 = jnp.floor(cy / res).astype(jnp.int32) - k // 2
    si = jnp.clip(i0 + k, 0, nx + k)
    sj = jnp.clip(j0 + k, 0, ny + k)
    outside = (si != i0 + k) | (sj != j0 + k)
    free = jax.lax.dynamic_slice(free_pad, (si, sj), (k, k))
    height = jax.lax.dynamic_slice(h_pad, (si, sj), (k, k))
    ar = jnp.arange(k, dtype=pose.dtype)
    du = (si - k + ar + 0.5) * res - cx
    dv = (sj - k + ar + 0.5) * res - cy
    return _Patch(du, dv, free.astype(pose.dtype), height.astype(pose.dtype), outside)


class _SoftPlane(NamedTuple):
    height: jax.Array
    slope: jax.Array
    roughness: jax.Array
    bump: jax.Array
    band: jax.Array
    grad_x: jax.Array  # dz/dx (m/m, world axes)
    grad_y: jax.Array  # dz/dy (m/m)


def _soft_max0(values, weights, temp):
    """Soft max(0, max over weighted values): temp * log(1 + sum_i w_i exp(v_i / temp))."""
    a = jnp.concatenate([jnp.zeros((1,), values.dtype), (values / temp).ravel()])
    b = jnp.concatenate([jnp.ones((1,), values.dtype), weights.ravel()])
    return temp * jax.nn.logsumexp(a, b=b)


def _soft_plane(patch: _Patch, m_foot, m_grown, res: float, temp) -> _SoftPlane:
    """Membership-weighted least-squares plane and its metrics (coordinates in cells)."""
    u = patch.du / res
    v = patch.dv / res
    k = u.shape[0]
    h_ref = patch.height[k // 2, k // 2]
    h = patch.height - h_ref
    n = jnp.sum(m_foot)
    n_safe = n + 1e-6
    mu = jnp.sum(m_foot, axis=1) @ u / n_safe
    mv = jnp.sum(m_foot, axis=0) @ v / n_safe
    mh = jnp.sum(m_foot * h) / n_safe
    uc = (u - mu)[:, None]
    vc = (v - mv)[None, :]
    hc = h - mh
    ridge = _RIDGE * (n + 1.0)
    suu = jnp.sum(m_foot * uc * uc) + ridge
    svv = jnp.sum(m_foot * vc * vc) + ridge
    suv = jnp.sum(m_foot * uc * vc)
    suh = jnp.sum(m_foot * uc * hc)
    svh = jnp.sum(m_foot * vc * hc)
    det = suu * svv - suv * suv
    b = (suh * svv - svh * suv) / det  # metres per cell along x
    c = (svh * suu - suh * suv) / det
    resid = hc - (b * uc + c * vc)
    height = h_ref + mh - b * mu - c * mv  # plane height at the pose (m)
    slope = jnp.arctan(geometry.safe_norm(b, c) / res)
    roughness = jnp.sum(m_foot * _smooth_abs(resid, temp)) / n_safe
    # Memberships scale the values, not the log-sum-exp weights: a weight m only shifts a value by
    # temp * log(m), about minus the cell's distance outside the foot, which never vanishes as the
    # sharpness grows, so cells near the foot would leak into bump and band.
    ones = jnp.ones_like(m_foot)
    bump = _soft_max0(m_foot * resid, ones, temp)
    m_band = m_grown * (1.0 - m_foot)
    band = _soft_max0(m_band * _smooth_abs(resid, temp), ones, temp)
    return _SoftPlane(height, slope, roughness, bump, band, b / res, c / res)


def _memberships(patch: _Patch, robot: Robot, theta, res: float, sharpness):
    du, dv = patch.du[:, None], patch.dv[None, :]
    hl, hw = 0.5 * robot.foot_length, 0.5 * robot.foot_width
    m_foot = soft_coverage(du, dv, theta, hl, hw, res, sharpness)
    m_grown = soft_coverage(du, dv, theta, hl + robot.margin, hw + robot.margin, res, sharpness)
    return m_foot, m_grown


_TENT_CELLS = 6  # cells per axis under a soft tent: the ones dropped as a point moves on weigh ~exp(-2 sharpness)


def _soft_ground(h_pad, k: int, x, y, res: float, ref, sharpness):
    """(P,) heights less ``ref`` at map coordinates ``x``, ``y`` (P,) (m) from the map edge-padded by ``k``: the
    bilinear interpolation of :func:`ijoy_jax.footcost.xla.bilinear_height` with its tents' corners rounded
    over ``1 / sharpness`` cells (weights ``softplus(s (1 - sqrt(d^2 + 1/s^2))) / s`` of the distance d in cells,
    normalised), so that the ground's gradient along a moving point is continuous; bilinear as s grows."""
    def weights(g):
        first = jnp.floor(g).astype(jnp.int32) - (_TENT_CELLS // 2 - 1)
        d = g[:, None] - (first[:, None] + jnp.arange(_TENT_CELLS)).astype(g.dtype)
        w = jax.nn.softplus(sharpness * (1.0 - jnp.sqrt(d * d + 1.0 / sharpness**2))) / sharpness
        return first, w / jnp.sum(w, axis=1, keepdims=True)

    fi, wi = weights(x / res - 0.5)
    fj, wj = weights(y / res - 0.5)
    i = jnp.clip(fi[:, None] + k + jnp.arange(_TENT_CELLS), 0, h_pad.shape[0] - 1)
    j = jnp.clip(fj[:, None] + k + jnp.arange(_TENT_CELLS), 0, h_pad.shape[1] - 1)
    return jnp.einsum("pi,pj,pij->p", wi, wj, h_pad[i[:, :, None], j[:, None, :]] - ref)


def _soft_rest(h_pad, k: int, terrain: Terrain, robot: Robot, pose, temp, sharpness):
    """The soft rested sole (:func:`ijoy_jax.footcost.sole.soft_sole_on_ground`) at ``pose`` on the soft ground
    (:func:`_soft_ground`) under its contact points: height (m), pitch, roll (rad) and support (m)."""
    m = robot.metrics
    hl, hw = 0.5 * robot.foot_length, 0.5 * robot.foot_width
    du, dv = contact_offsets(hl, hw, m.contact_inset, jnp.cos(pose[2]), jnp.sin(pose[2]))
    du, dv = jnp.stack(du).astype(pose.dtype), jnp.stack(dv).astype(pose.dtype)
    ground = _soft_ground(h_pad, k, pose[0] - terrain.origin[0] + du, pose[1] - terrain.origin[1] + dv,
                          terrain.resolution, 0.0, sharpness)
    return soft_sole_on_ground(tuple(ground), hl, hw, m.contact_inset, m.contact_tol, temp)


def _barrier(metric, limit, sharpness, barrier_weight):
    scale = jnp.maximum(limit, 1e-6)
    return barrier_weight * jax.nn.softplus(sharpness * (metric - limit) / scale)


def _padded(terrain: Terrain, k: int):
    free_pad = jnp.pad(terrain.free, k, constant_values=False)
    h_pad = jnp.pad(terrain.height, k, mode="edge")
    return free_pad, h_pad


def _swing_path(terrain: Terrain, robot: Robot, on_pad, h_pad, kp: int, start, step, h_ref, a, sharpness, bw, temp):
    """Soft swing-path check of one step: ``(barrier (), soft path height () m)``.

    The corridor runs from ``start`` to ``step`` (world poses (3,)), foot-wide.
    Its direction is ``(dx, dy) / sqrt(dx^2 + dy^2 + e^2)`` with
    ``e = resolution / sharpness`` (m): no angle, so the gradient stays finite
    when the swing has zero length (bias O(e^2 / length), vanishing as
    sharpness grows).
    """
    res = terrain.resolution
    dx, dy = step[0] - start[0], step[1] - start[1]
    eps = res / sharpness
    smooth_len = jnp.sqrt(dx * dx + dy * dy + eps * eps)
    length = geometry.safe_norm(dx, dy)
    mid = 0.5 * (start + step)
    patch = _patch(terrain, on_pad, h_pad, kp, mid)
    m = _soft_coverage_cs(
        patch.du[:, None], patch.dv[None, :], dx / smooth_len, dy / smooth_len, 0.5 * length,
        0.5 * robot.foot_width, res, sharpness,
    )
    # Gated values m_i (h_i - h_ref), not weights m_i: a weight enters as temp log m_i ~ -distance (m) at
    # any sharpness (temp and the coverage slope both scale with it), so tall cells just outside the
    # corridor would never drop out; a gated value of a cell outside tends to 0 (bias <= temp log K^2).
    top = _soft_max0(m * (patch.height - h_ref), jnp.ones_like(m), temp)  # soft max(0, corridor top - h_ref)
    off_map = jnp.sum(m * (1.0 - patch.free)) + jnp.where(patch.outside, float(kp * kp), 0.0)
    barrier = (
        _barrier(top, robot.clearance[a], sharpness, bw)
        + bw * sharpness * off_map
        + _barrier(length + robot.foot_width, robot.max_swing, sharpness, bw)
    )
    return barrier, top


def soft_foot_cost_terms(
    terrain: Terrain,
    robot: Robot,
    stance,
    steps,
    action_index,
    *,
    sharpness,
    barrier_weight=1.0,
    swing_from=None,
) -> SoftFootCostTerms:
    """Relaxed FootCost of candidate swing-foot poses, with named terms.

    Args:
      terrain: one Terrain (2D or 2.5D; vmap for batches).
      robot: the Robot; every leaf used is differentiable.
      stance: (3,) world pose of the stance foot (m, rad); its soft plane is
        the reference of the step-height metric (2.5D).
      steps: (N, 3) world poses of the swing foot centre.
      action_index: (N,) int, the action whose cost and step-height limit apply.
      sharpness: () > 0, dimensionless; larger is closer to exact FootCost.
        Soft coverage has slope sharpness / resolution per metre; height
        smoothing scale is resolution / sharpness (m).
      barrier_weight: () cost units per unit of barrier (see module docstring).
      swing_from: (3,) world pose the swing foot starts from, for the relaxed
        swing-path check on 2.5D terrains (None: no check, as FootCost).

    Returns:
      :class:`SoftFootCostTerms` of (N,) arrays, finite; dtype of ``steps``.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax.tune import relax
      >>> free = np.ones((60, 60), bool); free[40:, :] = False
      >>> t = ij.terrain.from_arrays(None, free, resolution=0.02)
      >>> robot = ij.robots.hrp2(margin=0.02, density=0.25)
      >>> steps = np.array([[0.5, 0.6, 0.0], [0.78, 0.6, 0.0]])
      >>> c = relax.soft_foot_cost_terms(t, robot, np.array([0.5, 0.4, 0.0]), steps, [0, 0], sharpness=50.0)
      >>> bool(c.total[0] < 1e-3), bool(c.total[1] > 100.0)
      (True, True)
    """
    steps = jnp.asarray(steps)
    dtype = jnp.result_type(steps.dtype, jnp.float32)
    steps = steps.astype(dtype).reshape(-1, 3)
    stance = jnp.asarray(stance, dtype)
    action_index = jnp.broadcast_to(jnp.asarray(action_index, jnp.int32), steps.shape[:1])
    sharpness = jnp.asarray(sharpness, dtype)
    res = terrain.resolution
    k = _window_size(robot, res)
    free_pad, h_pad = _padded(terrain, k)
    temp = res / sharpness
    metrics = robot.metrics
    stance_rest = None
    if terrain.has_height:
        stance_rest = _soft_rest(h_pad, k, terrain, robot, stance, temp, sharpness)
    check_path = terrain.has_height and swing_from is not None
    if check_path:
        swing_from = jnp.asarray(swing_from, dtype)
        kp = window_cells(0.5 * robot.max_swing, res) + 2 * _EXTRA_CELLS
        on_pad = jnp.pad(jnp.ones(terrain.shape, dtype), kp)
        hp_pad = jnp.pad(terrain.height.astype(dtype), kp, mode="edge")
        start_height = _soft_rest(h_pad, k, terrain, robot, swing_from, temp, sharpness).height

    def one(step, a):
        patch = _patch(terrain, free_pad, h_pad, k, step)
        m_foot, m_grown = _memberships(patch, robot, step[2], res, sharpness)
        mass = jnp.sum(m_grown * (1.0 - patch.free))
        obstacle = barrier_weight * sharpness * (mass + jnp.where(patch.outside, float(k * k), 0.0))
        zero = jnp.zeros((), dtype)
        action = robot.action_cost[a].astype(dtype)
        if terrain.has_height:
            pl = _soft_plane(patch, m_foot, m_grown, res, temp)
            rest = _soft_rest(h_pad, k, terrain, robot, step, temp, sharpness)
            dh = rest.height - stance_rest.height
            adh = _smooth_abs(dh, temp)

            def term(weight, metric, limit):
                return weight * metric + _barrier(metric, limit, sharpness, barrier_weight)

            slope = term(metrics.slope_weight, pl.slope, metrics.slope_limit)
            rough = term(metrics.roughness_weight, pl.roughness, metrics.roughness_limit)
            bump = term(metrics.bump_weight, pl.bump, metrics.bump_limit)
            stepc = term(metrics.step_weight, adh, robot.max_step_height[a])
            band = term(metrics.band_weight, pl.band, metrics.band_limit)
            support = term(metrics.support_weight, rest.support, metrics.support_limit)
            raw = (pl.slope, pl.roughness, pl.bump, dh, pl.band, rest.height, rest.support)
            pitch, roll = rest.pitch, rest.roll
            angle_eps = temp / res  # rad: 1 / sharpness
            ankle = (_barrier(_smooth_abs(pitch, angle_eps), robot.max_sole_pitch, sharpness, barrier_weight)
                     + _barrier(_smooth_abs(roll, angle_eps), robot.max_sole_roll, sharpness, barrier_weight))
        else:
            slope = rough = bump = stepc = band = support = ankle = zero
            raw = (zero,) * 7
            pitch = roll = zero
        distance = geometry.safe_norm(geometry.safe_norm(step[0] - stance[0], step[1] - stance[1]), raw[3])
        reach = _barrier(distance, robot.max_sole_distance, sharpness, barrier_weight)
        swing = path_height = zero
        if check_path:
            h_ref = temp * jnp.logaddexp(start_height / temp, raw[5] / temp)  # soft max of the two footholds
            swing, path_height = _swing_path(
                terrain, robot, on_pad, hp_pad, kp, swing_from, step, h_ref, a, sharpness, barrier_weight, temp
            )
        total = action + obstacle + slope + rough + bump + stepc + band + support + swing + ankle + reach
        return SoftFootCostTerms(
            total, action, obstacle, slope, rough, bump, stepc, band, support, mass, *raw, swing, path_height,
            ankle, reach, pitch, roll, distance
        )

    return jax.vmap(one)(steps, action_index)


class RelaxedChoice(NamedTuple):
    """Result of :func:`relaxed_select` (one decision).

    Fields::

      probs: (N,) Boltzmann probabilities ``softmax(-cost / tau)`` over S.
      log_probs: (N,) their logarithms (for likelihoods).
      cost: (N,) relaxed cost, soft FootCost + w * dist (cost units).
      terms: :class:`SoftFootCostTerms` of (N,) arrays.
      expected_pose: (3,) world pose sum_i p_i step_i (m, rad; angles averaged
        linearly, fine for a set spanning well under pi).
      expected_cost: () sum_i p_i cost_i.
      mode: () int32 most probable action (argmin of the relaxed cost).
      invalid_mass: () probability on steps whose exact FootCost is +inf
        (NaN when ``exact=False``); no gradient (a constant indicator).
      exact_valid: (N,) bool exact validity (all True when ``exact=False``).
      target: (3,) world pose the costs were scored against.
    """

    probs: jax.Array
    log_probs: jax.Array
    cost: jax.Array
    terms: SoftFootCostTerms
    expected_pose: jax.Array
    expected_cost: jax.Array
    mode: jax.Array
    invalid_mass: jax.Array
    exact_valid: jax.Array
    target: jax.Array


def relaxed_select(
    terrain: Terrain,
    robot: Robot,
    stance,
    stance_side,
    command,
    *,
    sharpness,
    tau,
    barrier_weight=1.0,
    quantize: bool = False,
    targets: Targets | None = None,
    exact: bool = True,
    swing_from=None,
) -> RelaxedChoice:
    """Boltzmann (softmin) relaxation of :func:`ijoy_jax.select_step`.

    ``p_i = softmax(-(softFootCost_i + w dist(s_i, target)) / tau)`` over the
    action set; the most probable action tends to the exact exhaustive choice
    as sharpness grows, and the probability mass concentrates on it as tau
    falls.

    Args:
      terrain, robot, stance, stance_side, command: as :func:`ijoy_jax.select_step`
        (stance (3,) world pose; stance_side +1 left / -1 right; command (3,)
        xdot m/s, ydot m/s, thetadot rad/s).
      sharpness: () > 0 (see :func:`soft_foot_cost_terms`).
      tau: () > 0 temperature (cost units).
      barrier_weight: () barrier scale (cost units).
      quantize: static; True scores against the nearest target f_i of F like
        the exact selector's default (then the choice is piecewise constant in
        step_time and the command); False (default) scores against p_next, so
        step_time and the command get gradients.
      targets: prebuilt :func:`ijoy_jax.targets.make_targets` (quantize only).
      exact: static; also compute exact FootCost validity for ``invalid_mass``.
      swing_from: (3,) world pose of the swing foot, for the (relaxed and
        exact) swing-path check on 2.5D terrains, as :func:`ijoy_jax.select_step`;
        None: no check.

    Returns:
      :class:`RelaxedChoice`.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax.tune import relax
      >>> free = np.ones((60, 60), bool); free[38:, :] = False     # wall at x = 0.76 m
      >>> t = ij.terrain.from_arrays(None, free, resolution=0.02)
      >>> robot = ij.robots.hrp2(margin=0.02, density=0.5)
      >>> r = relax.relaxed_select(t, robot, np.array([0.45, 0.5, 0.0]), -1, np.array([0.25, 0.0, 0.0]),
      ...                          sharpness=50.0, tau=0.05)
      >>> e = ij.select_step(t, robot, [0.45, 0.5, 0.0], -1, [0.25, 0.0, 0.0], ij.SelectOptions(quantize=False))
      >>> int(r.mode) == int(e.index), float(r.invalid_mass) < 1e-3
      (True, True)
    """
    command = jnp.asarray(command)
    dtype = jnp.result_type(command.dtype, robot.step_time.dtype, jnp.float32)
    command = command.astype(dtype)
    stance = jnp.asarray(stance, dtype)
    side = side_sign(stance_side).astype(dtype)
    swing = -side
    acts = side_actions(robot, swing).astype(dtype)  # (N, 3) stance frame
    p_next = side_p0(robot, swing).astype(dtype) + robot.step_time * command
    mirror = jnp.stack([jnp.ones_like(swing), swing, swing])
    if quantize:
        if targets is None:
            targets = make_targets(robot)
        fi = targets.nearest(jax.lax.stop_gradient(mirror * p_next))
        target_rel = mirror * targets.point(fi).astype(dtype)
    else:
        target_rel = p_next
    n = acts.shape[0]
    idx = jnp.arange(n, dtype=jnp.int32)
    steps = geometry.compose(stance, acts)
    if swing_from is not None:
        swing_from = jnp.asarray(swing_from, dtype)
    terms = soft_foot_cost_terms(
        terrain, robot, stance, steps, idx, sharpness=sharpness, barrier_weight=barrier_weight, swing_from=swing_from
    )
    cost = terms.total + robot.w * dist(acts, target_rel, robot.rotation_weight, grad_safe=True)
    log_probs = jax.nn.log_softmax(-cost / tau)
    probs = jnp.exp(log_probs)
    if exact:
        fc = foot_cost_terms(
            terrain,
            jax.lax.stop_gradient(robot),
            jax.lax.stop_gradient(stance),
            side,
            jax.lax.stop_gradient(steps),
            swing_from=None if swing_from is None else jax.lax.stop_gradient(swing_from),
            action_index=idx,
        ).total
        valid = jnp.isfinite(fc)
        invalid_mass = jnp.sum(jnp.where(valid, 0.0, jax.lax.stop_gradient(probs)))
    else:
        valid = jnp.ones((n,), bool)
        invalid_mass = jnp.full((), jnp.nan, dtype)
    return RelaxedChoice(
        probs=probs,
        log_probs=log_probs,
        cost=cost,
        terms=terms,
        expected_pose=probs @ steps,
        expected_cost=jnp.sum(probs * cost),
        mode=jnp.argmax(log_probs).astype(jnp.int32),
        invalid_mass=invalid_mass,
        exact_valid=valid,
        target=geometry.compose(stance, target_rel),
    )


relaxed_select_jit = jax.jit(relaxed_select, static_argnames=("quantize", "exact"))
relaxed_select_jit.__doc__ = "``jax.jit(relaxed_select)`` (quantize and exact static)."
