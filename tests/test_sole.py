"""The rested sole (ijoy_jax.footcost.sole) against SciPy's linear program and convex hull, closed forms and
invariants."""


import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog
from scipy.spatial import ConvexHull

from ijoy_jax.footcost import sole
from ijoy_jax.testing import lowest_planes

HL, HW, INSET = 0.121, 0.065, 0.009  # HRP-2's sole (robots.hrp2) and its sphere inset
XS, YS = sole.contact_points(HL, HW, INSET)
A, B = HL - INSET, HW - INSET
P = np.stack([XS, YS], axis=1)  # (6, 2)


_REST = jax.jit(lambda z, tol: sole.rest_on_contacts(A, B, tuple(z.T), tol))


def _rest(z, tol=0.003):
    """rest_on_contacts on a batch (N, 6) of heights, float32 (one compile per batch size)."""
    return _REST(jnp.asarray(z, jnp.float32), jnp.float32(tol))


def test_the_kernels_unrolled_layout_rests_the_sole_as_the_stacked_one():
    """The fused kernel's layout (``unrolled=True``) and the XLA path's (the contact polygon's 15 point pairs
    stacked) on the same heights: the same contacts, and the rest pose, gap and margin equal to float32 rounding
    (XLA contracts multiply-adds differently in the two layouts). Gaussian ground at four scales, ground in whole
    centimetres (ties: the sole rests on an edge), steps and cliffs of half a metre."""
    rng = np.random.default_rng(11)
    z = np.concatenate([
        rng.normal(0.0, 1.0, (4, 500, 6)).reshape(-1, 6) * np.repeat([0.001, 0.01, 0.02, 0.05], 500)[:, None],
        np.round(rng.normal(0.0, 2.0, (1000, 6))) * 0.01,
        rng.choice([-0.5, 0.0, 0.02, 0.5], (1000, 6)),
    ])
    unrolled = jax.jit(lambda z, tol: sole.rest_on_contacts(A, B, tuple(z.T), tol, unrolled=True))
    for tol in (0.0, 0.003, 0.02):
        a = _rest(z, tol)
        b = unrolled(jnp.asarray(z, jnp.float32), jnp.float32(tol))
        np.testing.assert_array_equal(np.asarray(b.contacts), np.asarray(a.contacts))
        for name, atol in (("height", 1e-6), ("gap", 1e-6), ("margin", 1e-6), ("grad_along", 1e-5),
                           ("grad_across", 1e-5)):
            np.testing.assert_allclose(np.asarray(getattr(b, name)), np.asarray(getattr(a, name)), rtol=0,
                                       atol=atol, err_msg=name)


def _lp(z):
    """The reference rest pose (float64): minimise h s.t. h + g . p_i >= z_i, by SciPy's HiGHS."""
    res = linprog(c=[1.0, 0.0, 0.0], A_ub=-np.column_stack([np.ones(6), P]), b_ub=-np.asarray(z, np.float64),
                  bounds=[(None, None)] * 3, method="highs")
    assert res.status == 0
    return res.x


def _optima(z):
    """Every optimal plane (float64, by brute force over the triples: testing.lowest_planes): (h, gx, gy) rows.
    More than one distinct gradient: the sole rests on an edge through its centre (the middle points' line or a
    diagonal) and can turn about it."""
    return lowest_planes(P, np.asarray(z, np.float64))


def _unique(optima):
    return bool(np.all(np.abs(optima[:, 1:] - optima[0, 1:]) < 1e-6))


def _middle(optima):
    """The rested sole's plane where several are lowest: the middle of their range (h, gx, gy)."""
    g = 0.5 * (optima[:, 1:].min(axis=0) + optima[:, 1:].max(axis=0))
    return np.array([optima[0, 0], *g])


def _hull_margin(points):
    """Distance from the origin to the nearest edge of the points' convex hull (negative outside), by SciPy."""
    hull = ConvexHull(points)
    # equations: n . x + d <= 0 inside, |n| = 1: the origin's distance to the facet line is -d
    return float(np.min(-hull.equations[:, 2]))


def test_a_plane_under_every_point_is_found_exactly():
    """Ground that is itself a plane: the sole rests on it (its height at the centre and its gradient), every
    point touches and the margin is the whole sole's."""
    rng = np.random.default_rng(0)
    h, gx, gy = rng.normal(0, 0.1, 50), rng.normal(0, 0.3, 50), rng.normal(0, 0.3, 50)
    z = h[:, None] + gx[:, None] * P[:, 0] + gy[:, None] * P[:, 1]
    r = _rest(z)
    np.testing.assert_allclose(r.height, h, atol=2e-6)
    np.testing.assert_allclose(r.grad_along, gx, atol=2e-5)
    np.testing.assert_allclose(r.grad_across, gy, atol=2e-5)
    np.testing.assert_array_equal(r.contacts, 6)
    np.testing.assert_allclose(r.margin, min(A, B), atol=1e-6)
    assert float(sole.full_margin(HL, HW, INSET)) == pytest.approx(min(A, B))


def test_rest_pose_is_scipys_linear_program():
    """Random ground under the six points: the rested sole's height at the centre is the LP's optimum (SciPy's
    HiGHS in float64). Where the optimum is one plane, so is its gradient; where it is not (the sole rests on an
    edge through its centre: the middle points' line or a diagonal, often on such ground) the sole can turn
    about that edge between two planes, and takes the middle one (a brute force over the triples)."""
    rng = np.random.default_rng(1)
    z = rng.normal(0.0, 0.02, (400, 6))
    r = _rest(z)
    unique = 0
    for i in range(len(z)):
        h, gx, gy = _lp(z[i])
        assert float(r.height[i]) == pytest.approx(h, abs=1e-6)
        optima = _optima(z[i])
        if _unique(optima):
            unique += 1
        else:
            h, gx, gy = _middle(optima)
        assert float(r.grad_along[i]) == pytest.approx(gx, abs=2e-5)
        assert float(r.grad_across[i]) == pytest.approx(gy, abs=2e-5)
    assert 100 < unique < 400  # both kinds occur


def test_rested_sole_lies_on_the_ground_and_above_it():
    """Every point's ground lies under the rested sole (to float32 rounding), at least two touch it (two where
    it rests on an edge through its centre, turned to the middle of its range), and the largest gap is the one
    the heights give."""
    rng = np.random.default_rng(2)
    z = rng.normal(0.0, 0.03, (500, 6))
    r = _rest(z, tol=0.0)
    plane = np.asarray(r.height)[:, None] + np.asarray(r.grad_along)[:, None] * P[:, 0] \
        + np.asarray(r.grad_across)[:, None] * P[:, 1]
    gaps = plane - z
    assert gaps.min() > -2e-6  # float32 rounding of heights of a few centimetres
    touching = np.sum(gaps < 2e-6, axis=1)
    assert np.all(touching >= 2) and np.any(touching == 2) and np.any(touching >= 3)
    np.testing.assert_allclose(r.gap, gaps.max(axis=1), atol=2e-6)
    np.testing.assert_array_equal(r.contacts, touching)


def test_margin_is_the_contact_hulls_by_scipy():
    """The margin equals SciPy's convex hull of the points within the tolerance of the rested sole (the
    reference takes the contact set from the LP's plane, in float64), for random ground and tolerances."""
    rng = np.random.default_rng(3)
    z = rng.normal(0.0, 0.01, (300, 6))
    for tol in (0.0, 0.002, 0.005, 0.02):
        r = _rest(z, tol)
        checked = 0
        for i in range(len(z)):
            h, gx, gy = _middle(_optima(z[i]))
            gaps = h + gx * P[:, 0] + gy * P[:, 1] - z[i]
            near = (np.abs(gaps - tol) < 1e-5) & (gaps > 1e-7)
            if near.any():  # a point at the tolerance to rounding may go either way
                continue
            contact = gaps <= tol + 1e-9
            assert int(r.contacts[i]) == int(contact.sum())
            pts = P[contact]
            if np.linalg.matrix_rank(pts - pts[0]) < 2:  # a segment: minus the centre's distance to its line
                e = pts[-1] - pts[0]
                expected = -abs(e[0] * pts[0, 1] - e[1] * pts[0, 0]) / np.hypot(*e)
            else:
                expected = _hull_margin(pts)
            assert float(r.margin[i]) == pytest.approx(expected, abs=1e-6)
            checked += 1
        assert checked > 250


@pytest.mark.parametrize("raised, margin", [
    # the middle points raised (a dome or ridge across the sole): it rests on them and rocks about that line
    ((1, 4), 0.0),
    # two diagonal corners raised: it rests on the diagonal, which passes the centre
    ((0, 5), 0.0),
    # the whole left edge raised: the sole rolls onto both edges, every point touches (the ankle's roll limit
    # is FootCost's business)
    ((0, 1, 2), B),
    # one corner dropped (a hole under the right toe): five points, the nearest edge from toe-left to mid-right
    ((0, 1, 2, 4, 5), A * B / np.hypot(A, 2 * B)),
])
def test_closed_forms(raised, margin):
    """Shapes the walker met, with their margins in closed form (the points listed 1 cm higher than the rest)."""
    z = np.zeros(6)
    z[list(raised)] = 0.01
    r = _rest(z[None], tol=0.001)
    assert float(r.margin[0]) == pytest.approx(margin, abs=1e-6)
    assert float(r.height[0]) >= 0.005 - 1e-6  # it rests on the raised points, half a centimetre or more up


def test_heights_shift_and_mirror():
    """Adding c to every height lifts the sole by c; mirroring the ground left-right mirrors the sole's roll and
    keeps its height and margin."""
    rng = np.random.default_rng(4)
    z = rng.normal(0.0, 0.02, (200, 6))
    r = _rest(z)
    up = _rest(z + 0.5)
    np.testing.assert_allclose(up.height, np.asarray(r.height) + 0.5, atol=2e-6)
    np.testing.assert_allclose(up.margin, r.margin, atol=1e-6)
    mirror = [3, 4, 5, 0, 1, 2]  # left edge <-> right edge
    m = _rest(z[:, mirror])
    np.testing.assert_allclose(m.height, r.height, atol=2e-6)
    np.testing.assert_allclose(m.margin, r.margin, atol=1e-6)
    np.testing.assert_allclose(m.grad_across, -np.asarray(r.grad_across), atol=2e-5)
    np.testing.assert_allclose(m.grad_along, r.grad_along, atol=2e-5)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.floats(-0.5, 0.5, allow_nan=False, width=32), min_size=6, max_size=6),
       st.floats(0.0, 0.05))
def test_hostile_heights_give_a_finite_rest_above_the_ground(z, tol):
    """Any heights within half a metre (steps, cliffs, repeated values): finite results, the sole above every
    point to rounding, at least two contacts, and a margin no larger than the whole sole's."""
    r = _rest(np.asarray(z)[None], tol)
    vals = [float(np.asarray(v)[0]) for v in (r.height, r.grad_along, r.grad_across, r.margin, r.gap)]
    assert all(np.isfinite(vals))
    plane = vals[0] + vals[1] * P[:, 0] + vals[2] * P[:, 1]
    assert np.all(plane - np.asarray(z, np.float32) > -1e-5)
    assert int(r.contacts[0]) >= 2
    assert vals[3] <= min(A, B) + 1e-6
    assert vals[3] >= -1e-6  # the contact polygon holds the centre (on its edge where it rests on two points)


def test_the_closed_forms_height_is_the_brute_force_over_every_triple():
    """The rested height (the linear program's dual: the highest of five interpolations at the centre) is the
    lowest centre height over the triples whose plane lies above all six points (testing.lowest_planes: an
    independent float64 loop over the 20 triples)."""
    rng = np.random.default_rng(5)
    z = rng.normal(0.0, 0.02, (200, 6))
    r = _rest(z)
    for i in range(len(z)):
        assert float(r.height[i]) == pytest.approx(_optima(z[i])[0, 0], abs=1e-6)
