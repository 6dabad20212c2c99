"""How a rigid sole that touches the ground at a few points rests on it: its rest pose and contact polygon.

The sole touches the ground at its contact points (:func:`contact_points`: toe, middle and heel of each long edge,
``inset`` in from the edges; the simulated biped's sole spheres, :func:`ijoy_jax.sim.model.sole_points`). Put
down with the robot's weight on the ankle (above the sole's centre) and compliant ankles, it settles on the
plane through three of its points that stays above the ground at every point and lies lowest under the
ankle: the face of the points' upper convex hull above the centre (the footstep "snap" of humanoid planners).
As a linear program in the plane's height ``h`` at the centre and gradient ``g`` (sole frame)::

  minimise h  subject to  h + g . p_i >= z_i  for every contact point i

Its dual makes it a closed form: the lowest such plane is as high at the centre as the highest interpolation of
the heights at the centre among the points whose convex hull holds it. In the contact points' layout (two rows
of three, the centre halfway between the middle points) those are five: the three segments through the centre
(the middle points' line and the two long diagonals) and the two triangles of a row's ends and the other row's
middle. A triangle that reaches the highest fixes the plane. A segment leaves the sole free to turn about it,
between the two planes that touch a point on either side; the sole takes the middle one (the bounds of its
turn are differences of the heights). The rest pose costs a few dozen additions per candidate, is exact, has no
iteration to converge, and uses only arithmetic and selects.

The contact polygon's nearest edge is found the same way: which points lie on which side of the line through two
of them depends on the layout alone, so an edge of the polygon is a test of the contact set's bits, and the
centre's distance to its line one of four numbers of the sole's size. Two layouts of the edge test: the XLA
path (:mod:`ijoy_jax.footcost.xla`) stacks the 15 point pairs on a leading axis (a few array operations, which
XLA compiles fast), the fused kernel (:mod:`ijoy_jax.footcost.pallas`) unrolls them into operations on its
blocks (``unrolled=True``: a Triton block holds power-of-two shapes only, and the kernel has no gathers). They
give the same results (tests/test_sole.py compares them).

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

# m: a point counts as in contact within this (plus the tolerance) of the rested sole: float32 rounding of the
# rest plane over heights of a few decimetres' relief, measured below 1e-7 m (tests/test_sole.py).
HEIGHT_EPS = 1e-6
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
    """A rested sole (:func:`rest_on_contacts`; arrays of the heights' shape).

    The sole's plane is ``z = height + grad_along * x + grad_across * y`` in its own frame about its centre.
    """

    height: object  # the rested sole's height at its centre (m, in the frame of the given heights)
    grad_along: object  # dz/dx along the foot (m/m): the toe higher for > 0
    grad_across: object  # dz/dy across it (m/m): the left edge higher for > 0
    margin: object  # distance from the centre to the contact polygon's nearest edge (m; 0 or less: it rocks)
    contacts: object  # int32, how many points lie within the tolerance of the rested sole
    gap: object  # the largest gap between the rested sole and the ground at one of its points (m)


# The contact points in units of the grid's half extents (a, b): point i sits at (a * X[i], b * Y[i]), in
# contact_points' order (toe, middle, heel of the left edge, then of the right edge).
_X = (1, 0, -1, 1, 0, -1)
_Y = (1, 1, 1, -1, -1, -1)


def _rest_plane(z):
    """The rested sole's plane in grid units from the six heights ``z``: (height at the centre, rise per unit
    along ``GX``, per unit across ``GY``), elementwise.

    The linear program's dual: the lowest plane above the points, at the centre, is as high as the highest
    interpolation of the heights at the centre by points whose hull holds it. In this layout those are five:
    the three segments through the centre (the middle points 1-4 and the diagonals 0-5 and 2-3) and the two
    triangles 0-2-4 and 1-3-5, which hold it inside. A triangle that reaches the highest holds the one plane that
    does; a segment leaves the plane free to turn about it between the extreme planes that stay above the other
    four points, and the sole takes the middle one (in closed form below; the range is empty, to rounding, only
    where a triangle or another segment reaches as high, and then the plane is unique and both agree)."""
    z0, z1, z2, z3, z4, z5 = z
    cases = []  # (height, GX, GY), the triangles first: where several reach the highest, the first is taken
    cases.append((0.25 * (z0 + z2) + 0.5 * z4, 0.5 * (z0 - z2), 0.25 * (z0 + z2) - 0.5 * z4))  # 0-2-4
    cases.append((0.25 * (z3 + z5) + 0.5 * z1, 0.5 * (z3 - z5), 0.5 * z1 - 0.25 * (z3 + z5)))  # 1-3-5
    # 1-4: GY fixed by the two middle points; GX between the toes' and the heels' bounds.
    gx = 0.5 * (jnp.maximum(z0 - z1, z3 - z4) + jnp.minimum(z1 - z2, z4 - z5))
    cases.append((0.5 * (z1 + z4), gx, 0.5 * (z1 - z4)))
    # 0-5 (toe left, heel right): GX + GY = (z0 - z5) / 2, GX between the bounds of points 4, 3 and 1, 2.
    gx = 0.5 * (jnp.maximum(z4 - z5, 0.5 * (z3 - z5)) + jnp.minimum(z0 - z1, 0.5 * (z0 - z2)))
    cases.append((0.5 * (z0 + z5), gx, 0.5 * (z0 - z5) - gx))
    # 2-3 (heel left, toe right): GX - GY = (z3 - z2) / 2, GX between the bounds of points 0, 1 and 5, 4.
    gx = 0.5 * (jnp.maximum(0.5 * (z0 - z2), z1 - z2) + jnp.minimum(0.5 * (z3 - z5), z3 - z4))
    cases.append((0.5 * (z2 + z3), gx, gx - 0.5 * (z3 - z2)))
    best = functools.reduce(jnp.maximum, [h for h, _, _ in cases])
    _, big_x, big_y = cases[-1]
    for h, cx, cy in reversed(cases[:-1]):
        take = h >= best
        big_x, big_y = jnp.where(take, cx, big_x), jnp.where(take, cy, big_y)
    return best, big_x, big_y


@functools.cache
def _edges():
    """The 15 point pairs (i, j) as candidate edges of a contact polygon (static): per pair the bits of i and j,
    the bits of the points strictly to its right and strictly to its left (the sides depend on the layout only,
    a, b > 0), and the centre's signed distance to its line as weights (of a, of b, of
    ``a b / sqrt(a^2 + 4 b^2)``: every slanted pair that misses the centre has that length's direction)."""
    edges = []
    for i, j in itertools.combinations(range(6), 2):
        al, be = _X[j] - _X[i], _Y[j] - _Y[i]  # the edge is (al a, be b)
        sides = [al * (_Y[k] - _Y[i]) - be * (_X[k] - _X[i]) for k in range(6)]  # times a b
        right = sum(1 << k for k in range(6) if sides[k] < 0)
        left = sum(1 << k for k in range(6) if sides[k] > 0)
        inner = be * _X[i] - al * _Y[i]  # cross(edge, centre - p_i) / (a b): > 0 when the centre is on its left
        if be == 0:
            w = (0.0, inner / abs(al), 0.0)
        elif al == 0:
            w = (inner / abs(be), 0.0, 0.0)
        else:
            assert inner == 0 or (abs(al), abs(be)) == (1, 2), (i, j)
            w = (0.0, 0.0, float(inner))
        edges.append(((1 << i) | (1 << j), right, left, w))
    return tuple(edges)


def _edge_scale(a, b):
    """a b / sqrt(a^2 + 4 b^2) (m): the centre's distance to the slanted edges' lines, per unit of weight."""
    return a * b / jnp.sqrt(a * a + 4.0 * b * b)


def _margin(code, a, b, *, unrolled: bool = False):
    """Distance from the centre to the nearest edge of the convex hull of the contact points in ``code`` (int32,
    bit i: point i touches; any shape), negative when the centre lies outside, -inf with fewer than two points.

    An edge (i, j) of the hull has both ends touching and no touching point strictly on one side: on its right
    (the centre's distance counts with its sign), or on its left (with the opposite sign); a segment is both.
    ``unrolled``: each pair its own operations (the fused kernel's layout) instead of the pairs on a leading axis.
    """
    q = _edge_scale(a, b)
    edges = _edges()
    if unrolled:
        margin = None
        for ends, right, left, (wa, wb, wq) in edges:
            d = wa * a + wb * b + wq * q
            plus = (code & (ends | right)) == ends
            minus = (code & (ends | left)) == ends
            both = jnp.minimum(jnp.where(plus, d, jnp.inf), jnp.where(minus, -d, jnp.inf))
            margin = both if margin is None else jnp.minimum(margin, both)
    else:
        extra = (1,) * jnp.ndim(code)
        # Python weights of the sizes' scalars: the distances keep the sizes' dtype (also under x64)
        d = jnp.reshape(jnp.stack([wa * a + wb * b + wq * q for _, _, _, (wa, wb, wq) in edges]), (-1,) + extra)
        columns = list(zip(*edges, strict=True))[:3]  # the pairs' bits, those to their right, to their left
        ends, right, left = (np.reshape(np.array(v, np.int32), (-1,) + extra) for v in columns)
        plus = (code[None] & (ends | right)) == ends
        minus = (code[None] & (ends | left)) == ends
        margin = jnp.min(jnp.minimum(jnp.where(plus, d, jnp.inf), jnp.where(minus, -d, jnp.inf)), axis=0)
    return jnp.where(jnp.isfinite(margin), margin, -jnp.inf)


def rest_on_contacts(a, b, z, tol, *, unrolled: bool = False) -> Rest:
    """The rest pose of a rigid sole on the ground heights ``z`` under its contact points (see the module's
    docstring).

    Args:
      a, b: the contact points' half extents along and across the sole (m, > 0): ``half_length - inset`` and
        ``half_width - inset`` (:func:`contact_points`).
      z: a tuple of six arrays of one shape: the ground's height under each point, in :func:`contact_points`'
        order (m, any common reference).
      tol: the contact tolerance (m): points within it of the rested sole form the contact polygon.
      unrolled: the fused kernel's layout (each edge of the contact polygon its own operations) instead of the
        edges on a leading axis; the same results.

    Returns:
      :class:`Rest` of arrays of ``z``'s shape; finite wherever the heights are.
    """
    height, big_x, big_y = _rest_plane(z)
    gaps = []
    for zi, xi, yi in zip(z, _X, _Y, strict=True):
        g = height - zi
        g = g + big_x if xi > 0 else (g - big_x if xi < 0 else g)
        gaps.append(g + big_y if yi > 0 else g - big_y)
    touches = [g <= tol + HEIGHT_EPS for g in gaps]
    code = sum(jnp.where(t, jnp.int32(1 << i), jnp.int32(0)) for i, t in enumerate(touches))
    count = sum(t.astype(jnp.int32) for t in touches)
    ok_a, ok_b = a > 0, b > 0  # a degenerate sole (flagged at the API boundary and by robot_supported): level
    return Rest(height=height, grad_along=jnp.where(ok_a, big_x, 0.0) / jnp.where(ok_a, a, 1.0),
                grad_across=jnp.where(ok_b, big_y, 0.0) / jnp.where(ok_b, b, 1.0),
                margin=_margin(code, a, b, unrolled=unrolled), contacts=count,
                gap=jnp.maximum(functools.reduce(jnp.maximum, gaps), 0.0))


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
    (:func:`rest_on_contacts`)."""
    r = rest_on_contacts(half_length - inset, half_width - inset, ground, tol, unrolled=unrolled)
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
    r = rest_on_contacts(half_length - inset, half_width - inset, ground, tol)
    n = len(xs)
    p = jnp.stack([jax.nn.sigmoid((tol - (r.height + r.grad_along * xs[i] + r.grad_across * ys[i] - ground[i]))
                                  / temp + 2.0) for i in range(n)], axis=-1)  # (..., n)
    full = full_margin(half_length, half_width, inset)
    codes = np.arange(1 << n, dtype=np.int32)  # every contact set, bit i: point i touches
    sets = jnp.asarray((codes[:, None] >> np.arange(n)) & 1 == 1)  # (2^n, n)
    # each set's margin depends on the sole's size alone
    margins = jnp.clip(_margin(jnp.asarray(codes), half_length - inset, half_width - inset), -full, full)
    weights = jnp.prod(jnp.where(sets, p[..., None, :], 1.0 - p[..., None, :]), axis=-1)  # (..., 2^n)
    expected = jnp.sum(weights * margins, axis=-1)
    pitch, roll = tilt(r.grad_along, r.grad_across)
    return SoleOnGround(height=r.height, pitch=pitch, roll=roll, support=full - expected)
