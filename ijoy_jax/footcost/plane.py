"""The least-squares plane under a footprint, its metrics, and the sole rested on the ground there.

Both FootCost paths score a 2.5D foothold from one fit: a plane through the heights of the cells the
footprint touches (slope, roughness, largest bump), the safety band's largest residual around it, and
the rested sole of :mod:`ijoy_jax.footcost.sole` (its height, pitch, roll and support). The XLA path
(:mod:`ijoy_jax.footcost.xla`) fits every candidate with :func:`plane_metrics`; the fused kernel
(:mod:`ijoy_jax.footcost.pallas`) computes the same sums in its own order and fits the stance and
swing-start feet with it; the selector's full foothold pose (:func:`ijoy_jax.select.foothold`) reads
the rested sole from it. The sums are fused reductions (one XLA:CPU kernel for several results) with
plain jnp derivatives.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from ijoy_jax import geometry
from ijoy_jax.footcost.index import TerrainIndex
from ijoy_jax.footcost.sole import contact_offsets, sole_on_ground, tilt
from ijoy_jax.robots import Robot
from ijoy_jax.terrain import Terrain


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
    return lax.reduce(
        (a, *bs),
        (z, *(z - jnp.inf for _ in bs)),
        lambda x, y: (x[0] + y[0], *(jnp.maximum(p, q) for p, q in zip(x[1:], y[1:], strict=True))),
        (0, 1),
    )


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
        jnp.where(m_foot, jnp.abs(resid), 0.0),
        jnp.where(m_foot, resid, -jnp.inf),
        jnp.where(m_band, jnp.abs(resid), 0.0),
    )
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
    return (1.0 - tx) * ((1.0 - ty) * (padded[i, j] - ref) + ty * (padded[i, j + 1] - ref)) + tx * (
        (1.0 - ty) * (padded[i + 1, j] - ref) + ty * (padded[i + 1, j + 1] - ref)
    )
