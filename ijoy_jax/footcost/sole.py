"""How a rigid sole that touches the ground at a few points rests on it: its rest pose and contact polygon.

The sole touches the ground at its contact points (:func:`contact_points`: toe, middle and heel of each long edge,
``inset`` in from the edges; the simulated biped's sole spheres, :func:`ijoy_jax.sim.model.sole_points`). Put
down with the robot's weight on the ankle (above the sole's centre) and compliant ankles, it settles on the
plane through three of its points that stays above the ground at every point and lies lowest under the
ankle: the face of the points' upper convex hull above the centre (the footstep "snap" of humanoid planners).
As a linear program in the plane's height ``h`` at the centre and gradient ``g`` (sole frame)::

  minimise h  subject to  h + g . p_i >= z_i  for every contact point i

whose optimum is a vertex, a triple of points. Every triple is solved and checked (20 for six points; the
coefficients depend on the sole's size only, so per candidate a triple costs a few multiply-adds): the rest pose
is the lowest plane under the centre among those above every point. Where several are lowest (the sole rests on
an edge through its centre, such as the line of its middle points, and can turn about it), it takes the middle
of their range: the plane halfway between the two that touch a point on either side. It is exact, has no
iteration to converge, and uses only arithmetic and selects.

Two layouts of the same arithmetic. The XLA path (:mod:`ijoy_jax.footcost.xla`) stacks the points, triples and
point pairs on leading axes (:func:`rest_on_points`): a few dozen array operations instead of hundreds, which
XLA compiles far faster (the unrolled rested sole was a large part of a 2.5D selector program's compile). The
fused kernel (:mod:`ijoy_jax.footcost.pallas`) unrolls them into operations on its blocks
(``unrolled=True``): a Triton block holds power-of-two shapes only, and the kernel has no gathers. Both compute
every plane, check and edge with the same formulas in the same order; XLA may contract a multiply-add
differently in the two layouts, so they agree to float32 rounding (tests/test_sole.py compares them).

The contact polygon is the convex hull of the points within ``tol`` of the rested sole; its ``margin`` is the
distance from the centre (the ankle, where the centre of pressure sits at rest) to its nearest edge: how far the
centre of pressure can move, in any direction, before the sole rocks onto another face by more than ``tol``.
The whole sole's margin is ``min(half_length, half_width) - inset``; a sole resting on two diagonal corners, or
on the front half only with the heel hanging, has margin 0.
"""

from __future__ import annotations

import functools
import itertools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# m: a point counts as under (or on) a candidate plane, and as in contact, within this of it: float32 rounding of
# the plane through three heights of a few decimetres' relief, measured below 1e-7 m (tests/test_sole.py).
HEIGHT_EPS = 1e-6
# m^2: a point counts as on the inner side of a polygon edge within this cross product (a 1 um offset at 0.1 m).
SIDE_EPS = 1e-7
# m: a support metric below this is float32 rounding of two equal margins (measured ~2e-8 m) and reads 0.
SUPPORT_EPS = 1e-6


def contact_points(half_length, half_width, inset):
    """The sole's six contact points in its own frame (x along the foot, y to its left; m): toe, middle and heel
    of its left edge, then of its right edge, ``inset`` in from the edges. Returns (xs, ys), tuples of six
    (scalars or arrays, as given)."""
    a, b = half_length - inset, half_width - inset
    points = [(sa * a, sb * b) for sb in (1.0, -1.0) for sa in (1.0, 0.0, -1.0)]
    return tuple(p for p, _ in points), tuple(q for _, q in points)


def contact_offsets(half_length, half_width, inset, cos, sin):
    """:func:`contact_points` turned to a heading of cosine ``cos`` and sine ``sin``: offsets from the sole's
    centre in world axes (m). Returns (du, dv), tuples of six, broadcast from the inputs (NumPy or JAX)."""
    xs, ys = contact_points(half_length, half_width, inset)
    return tuple(p * cos - q * sin for p, q in zip(xs, ys, strict=True)), tuple(
        p * sin + q * cos for p, q in zip(xs, ys, strict=True))


class Rest(NamedTuple):
    """A rested sole (:func:`rest_on_points`; arrays of the heights' shape).

    The sole's plane is ``z = height + grad_along * x + grad_across * y`` in its own frame about its centre.
    """

    height: object  # the rested sole's height at its centre (m, in the frame of the given heights)
    grad_along: object  # dz/dx along the foot (m/m): the toe higher for > 0
    grad_across: object  # dz/dy across it (m/m): the left edge higher for > 0
    margin: object  # distance from the centre to the contact polygon's nearest edge (m; 0 or less: it rocks)
    contacts: object  # int32, how many points lie within the tolerance of the rested sole
    gap: object  # the largest gap between the rested sole and the ground at one of its points (m)


def _plane_through(p, q, r):
    """Coefficients of the plane through three sole-frame points: (cz, cx, cy), each three weights of the points'
    heights giving the plane's height at the centre, its gradient along and across; and the determinant (0 for
    collinear points)."""
    (x1, y1), (x2, y2), (x3, y3) = p, q, r
    det = (x2 - x1) * (y3 - y1) - (x3 - x1) * (y2 - y1)
    # Cramer's rule on [1 x y] [h gx gy]^T = z, as weights of (z1, z2, z3).
    cx = ((y2 - y3), (y3 - y1), (y1 - y2))
    cy = ((x3 - x2), (x1 - x3), (x2 - x1))
    cz = ((x2 * y3 - x3 * y2), (x3 * y1 - x1 * y3), (x1 * y2 - x2 * y1))
    return cz, cx, cy, det


@functools.cache
def _combinations(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k-subsets of n points in ``itertools.combinations`` order, (C, k) int, and (C, n) bool: point j lies
    outside subset c (static, NumPy)."""
    sets = np.array(list(itertools.combinations(range(n), k)), np.int32).reshape(-1, k)
    return sets, ~np.any(sets[:, :, None] == np.arange(n), axis=1)


def _lead(a, ndim: int):
    """(K,) or (K, M) coefficients reshaped to broadcast against (K, ...) or (K, M, ...) arrays of ``ndim``
    trailing axes."""
    return jnp.reshape(a, jnp.shape(a) + (1,) * ndim)


def _margin(x, y, flags):
    """Distance from the origin to the nearest edge of the convex hull of the points (``x``, ``y``: (n,) arrays)
    flagged in ``flags`` (an (n, ...) bool array), negative when the origin lies outside, -inf with fewer than two
    points. The stacked layout of :func:`_margin_unrolled`: pairs (i, j) and the other points k on leading axes."""
    n = x.shape[0]
    extra = flags.ndim - 1
    pairs, others = _combinations(n, 2)
    xi, yi, xj, yj = x[pairs[:, 0]], y[pairs[:, 0]], x[pairs[:, 1]], y[pairs[:, 1]]
    ex, ey = xj - xi, yj - yi
    length = jnp.sqrt(ex * ex + ey * ey)
    inner = ex * (-yi) - ey * (-xi)  # cross(e, origin - p_i): > 0 when the origin lies left of i -> j
    side = _lead(ex[:, None] * (y[None, :] - yi[:, None]) - ey[:, None] * (x[None, :] - xi[:, None]), extra)
    ignore = _lead(jnp.asarray(others), extra) & ~flags[None]  # (pairs, n, ...): not a touching other point
    plus = flags[pairs[:, 0]] & flags[pairs[:, 1]]
    minus = plus & jnp.all(ignore | (side <= SIDE_EPS), axis=1)
    plus = plus & jnp.all(ignore | (side >= -SIDE_EPS), axis=1)
    d = _lead(inner / length, extra)
    margin = jnp.min(jnp.minimum(jnp.where(plus, d, jnp.inf), jnp.where(minus, -d, jnp.inf)), axis=0)
    return jnp.where(jnp.isfinite(margin), margin, -jnp.inf)


def _margin_unrolled(xs, ys, contact):
    """:func:`_margin` unrolled over the pairs and points (the fused kernel's layout); ``contact``: a tuple of n
    bool arrays."""
    n = len(xs)
    margin = None
    for i, j in itertools.combinations(range(n), 2):
        ex, ey = xs[j] - xs[i], ys[j] - ys[i]
        length = jnp.sqrt(ex * ex + ey * ey)
        inner = ex * (-ys[i]) - ey * (-xs[i])  # cross(e, origin - p_i): > 0 when the origin lies left of i -> j
        plus = contact[i] & contact[j]
        minus = plus
        for k in range(n):
            if k in (i, j):
                continue
            side = ex * (ys[k] - ys[i]) - ey * (xs[k] - xs[i])
            plus = plus & (~contact[k] | (side >= -SIDE_EPS))
            minus = minus & (~contact[k] | (side <= SIDE_EPS))
        d = inner / length
        both = jnp.minimum(jnp.where(plus, d, jnp.inf), jnp.where(minus, -d, jnp.inf))
        margin = both if margin is None else jnp.minimum(margin, both)
    return jnp.where(jnp.isfinite(margin), margin, -jnp.inf)


def rest_on_points(xs, ys, z, tol, *, unrolled: bool = False) -> Rest:
    """The rest pose of a rigid sole on the ground heights ``z`` under its points (see the module's docstring).

    Args:
      xs, ys: the points in the sole's frame (m; tuples of P scalars, :func:`contact_points`; any values whose
        convex hull holds the centre).
      z: a tuple of P arrays of one shape: the ground's height under each point (m, any common reference).
      tol: the contact tolerance (m): points within it of the rested sole form the contact polygon.
      unrolled: the fused kernel's layout (every triple, point and edge its own operations) instead of the
        stacked one; the same results to float32 rounding.

    Returns:
      :class:`Rest` of arrays of ``z``'s shape; finite wherever the heights are.
    """
    if unrolled:
        return _rest_unrolled(xs, ys, z, tol)
    n = len(xs)
    x, y = jnp.stack(xs), jnp.stack(ys)  # (n,)
    heights = jnp.stack(z)  # (n, ...)
    extra = heights.ndim - 1
    triples, outside = _combinations(n, 3)
    corners = [(x[triples[:, j]], y[triples[:, j]]) for j in range(3)]
    cz, cx, cy, det = _plane_through(*corners)  # each a (T,) array per point of the triples
    ok_det = jnp.abs(det) > 1e-9  # collinear points define no plane (m^2; a real triple spans ~1e-2)
    inv = _lead(1.0 / jnp.where(ok_det, det, 1.0), extra)
    zt = [heights[triples[:, j]] for j in range(3)]  # (T, ...) the heights under each triple's points
    h = (_lead(cz[0], extra) * zt[0] + _lead(cz[1], extra) * zt[1] + _lead(cz[2], extra) * zt[2]) * inv
    gx = (_lead(cx[0], extra) * zt[0] + _lead(cx[1], extra) * zt[1] + _lead(cx[2], extra) * zt[2]) * inv
    gy = (_lead(cy[0], extra) * zt[0] + _lead(cy[1], extra) * zt[1] + _lead(cy[2], extra) * zt[2]) * inv
    over = h[:, None] + gx[:, None] * _lead(x[None, :], extra) + gy[:, None] * _lead(y[None, :], extra)
    above = ~_lead(jnp.asarray(outside), extra) | (over >= heights[None] - HEIGHT_EPS)  # (T, n, ...)
    valid = _lead(ok_det, extra) & jnp.all(above, axis=1)
    h = jnp.where(valid, h, jnp.inf)  # +inf where the triple's plane passes under a point
    best = jnp.min(h, axis=0)
    # Ties: as in the unrolled layout, the middle of the lowest planes' gradients.
    tie = h <= best + HEIGHT_EPS
    lo_x, hi_x = jnp.min(jnp.where(tie, gx, jnp.inf), axis=0), jnp.max(jnp.where(tie, gx, -jnp.inf), axis=0)
    lo_y, hi_y = jnp.min(jnp.where(tie, gy, jnp.inf), axis=0), jnp.max(jnp.where(tie, gy, -jnp.inf), axis=0)
    found = jnp.isfinite(best) & jnp.isfinite(lo_x + hi_x + lo_y + hi_y)
    height = jnp.where(found, best, jnp.max(heights, axis=0))
    gx = jnp.where(found, 0.5 * (lo_x + hi_x), 0.0)
    gy = jnp.where(found, 0.5 * (lo_y + hi_y), 0.0)
    gaps = height[None] + gx[None] * _lead(x, extra) + gy[None] * _lead(y, extra) - heights  # (n, ...)
    contact = gaps <= tol + HEIGHT_EPS
    return Rest(height=height, grad_along=gx, grad_across=gy, margin=_margin(x, y, contact),
                contacts=jnp.sum(contact.astype(jnp.int32), axis=0), gap=jnp.maximum(jnp.max(gaps, axis=0), 0.0))


def _rest_unrolled(xs, ys, z, tol) -> Rest:
    """:func:`rest_on_points` unrolled over the triples and points (the fused kernel's layout)."""
    n = len(xs)
    planes = []  # (h, gx, gy) of each triple, h = +inf where its plane passes under a point
    for t in itertools.combinations(range(n), 3):
        cz, cx, cy, det = _plane_through(*((xs[i], ys[i]) for i in t))
        ok_det = jnp.abs(det) > 1e-9  # collinear points define no plane (m^2; a real triple spans ~1e-2)
        inv = 1.0 / jnp.where(ok_det, det, 1.0)
        h = sum(c * z[i] for c, i in zip(cz, t, strict=True)) * inv
        gx = sum(c * z[i] for c, i in zip(cx, t, strict=True)) * inv
        gy = sum(c * z[i] for c, i in zip(cy, t, strict=True)) * inv
        valid = ok_det
        for k in range(n):
            if k not in t:
                valid = valid & (h + gx * xs[k] + gy * ys[k] >= z[k] - HEIGHT_EPS)
        planes.append((jnp.where(valid, h, jnp.inf), gx, gy))
    best = planes[0][0]
    for h, _, _ in planes[1:]:
        best = jnp.minimum(best, h)
    # Ties: where the lowest planes rest on an edge through the centre (the middle points' line, a diagonal),
    # they turn about it between two extremes; the sole takes the middle one (mirrored ground, mirrored sole).
    lo_x = lo_y = jnp.inf
    hi_x = hi_y = -jnp.inf
    for h, gx, gy in planes:
        tie = h <= best + HEIGHT_EPS
        lo_x, hi_x = jnp.minimum(lo_x, jnp.where(tie, gx, jnp.inf)), jnp.maximum(hi_x, jnp.where(tie, gx, -jnp.inf))
        lo_y, hi_y = jnp.minimum(lo_y, jnp.where(tie, gy, jnp.inf)), jnp.maximum(hi_y, jnp.where(tie, gy, -jnp.inf))
    # No valid triple only through rounding or non-finite heights: a level sole on the highest point (above all).
    found = jnp.isfinite(best) & jnp.isfinite(lo_x + hi_x + lo_y + hi_y)
    top = z[0]
    for zi in z[1:]:
        top = jnp.maximum(top, zi)
    height = jnp.where(found, best, top)
    gx = jnp.where(found, 0.5 * (lo_x + hi_x), 0.0)
    gy = jnp.where(found, 0.5 * (lo_y + hi_y), 0.0)
    gaps = [height + gx * xs[i] + gy * ys[i] - z[i] for i in range(n)]
    contact = tuple(g <= tol + HEIGHT_EPS for g in gaps)
    gap = gaps[0]
    count = contact[0].astype(jnp.int32)
    for i in range(1, n):
        gap = jnp.maximum(gap, gaps[i])
        count = count + contact[i].astype(jnp.int32)
    return Rest(height=height, grad_along=gx, grad_across=gy, margin=_margin_unrolled(xs, ys, contact),
                contacts=count,
                gap=jnp.maximum(gap, 0.0))


def full_margin(half_length, half_width, inset):
    """The margin of a sole resting on all of its points (m): ``min(half_length, half_width) - inset``."""
    return jnp.minimum(half_length, half_width) - inset


def tilt(grad_along, grad_across):
    """(pitch, roll) (rad) of a sole whose plane rises ``grad_along`` along it and ``grad_across`` to its left
    (m/m), ``R = Rz(yaw) Ry(pitch) Rx(roll)``: its toe up for pitch < 0, its left edge up for roll > 0
    (:func:`ijoy_jax.footcost.xla.sole_tilt` in the sole's own axes). Elementwise, jnp only."""
    return -jnp.arctan(grad_along), jnp.arctan2(grad_across, jnp.sqrt(1.0 + grad_along * grad_along))


class SoleOnGround(NamedTuple):
    """What FootCost takes from a rested sole (:func:`sole_on_ground`; arrays of the heights' shape)."""

    height: object  # its height at the centre (m, in the frame of the given heights)
    pitch: object  # its pitch and roll (rad; :func:`tilt`)
    roll: object
    support: object  # the whole sole's margin less the contact polygon's (m, >= 0; +inf with no polygon)


def sole_on_ground(ground, half_length, half_width, inset, tol, *, unrolled: bool = False) -> SoleOnGround:
    """The rested sole of FootCost's ``support`` term and of the footholds, from the ground ``ground`` (a tuple
    of six arrays, m) under its :func:`contact_points` (half sizes and inset in m, tol: the contact tolerance,
    m). The one code both FootCost paths run, in the fused kernel's layout where ``unrolled``
    (:func:`rest_on_points`)."""
    xs, ys = contact_points(half_length, half_width, inset)
    r = rest_on_points(xs, ys, ground, tol, unrolled=unrolled)
    pitch, roll = tilt(r.grad_along, r.grad_across)
    support = full_margin(half_length, half_width, inset) - r.margin
    # a sole on all of its points: the margins differ by rounding (~1e-8 m); 0, so that level ground costs nothing
    support = jnp.where(support < SUPPORT_EPS, 0.0, support)
    return SoleOnGround(height=r.height, pitch=pitch, roll=roll, support=support)


def soft_sole_on_ground(ground, half_length, half_width, inset, tol, temp) -> SoleOnGround:
    """A smooth :func:`sole_on_ground`, for tuning by gradient (:mod:`ijoy_jax.tune.relax`).

    The rest pose is the exact one (the linear program's optimum is continuous and piecewise linear in the
    heights). The contact polygon is relaxed: point i touches with probability
    ``sigmoid((tol - gap_i) / temp + 2)`` (``temp`` m; tends to the exact ``gap_i <= tol`` as it shrinks), the
    points independently, and the margin is its expectation over the 2^6 contact sets (each set's margin a
    function of the sole's size, clamped to plus or minus the whole sole's). Returns :class:`SoleOnGround`.
    """
    xs, ys = contact_points(half_length, half_width, inset)
    r = rest_on_points(xs, ys, ground, tol)
    n = len(xs)
    p = jnp.stack([jax.nn.sigmoid((tol - (r.height + r.grad_along * xs[i] + r.grad_across * ys[i] - ground[i]))
                                  / temp + 2.0) for i in range(n)], axis=-1)  # (..., n)
    full = full_margin(half_length, half_width, inset)
    sets = jnp.asarray(list(itertools.product((False, True), repeat=n)))  # (2^n, n), every contact set
    # each set's margin depends on the sole's size alone: one traced copy, vmapped over the sets
    x, y = jnp.stack(xs), jnp.stack(ys)
    margins = jnp.clip(jax.vmap(lambda flags: _margin(x, y, flags))(sets), -full, full)
    weights = jnp.prod(jnp.where(sets, p[..., None, :], 1.0 - p[..., None, :]), axis=-1)  # (..., 2^n)
    expected = jnp.sum(weights * margins, axis=-1)
    pitch, roll = tilt(r.grad_along, r.grad_across)
    return SoleOnGround(height=r.height, pitch=pitch, roll=roll, support=full - expected)
