"""Exact grid coverage and pose algebra against brute-force NumPy references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from ijoy_jax import geometry
from ijoy_jax.testing import enable_x64, rect_touches_cells

RES = 0.02
SHAPE = (40, 40)
K = 20  # columns: enough for a rectangle of half-diagonal <= 0.18 m at 2 cm


def _mask_from_spans(spans, shape):
    m = np.zeros(shape, bool)
    for ix, j0, j1, t in zip(*(np.asarray(a) for a in (spans.ix, spans.j0, spans.j1, spans.touched)),
                             strict=True):
        if t and 0 <= ix < shape[0]:
            m[ix, max(j0, 0):min(j1, shape[1] - 1) + 1] = True
    return m


def _random_poses(n, seed):
    rng = np.random.default_rng(seed)
    cx = rng.uniform(0.25, 0.55, n)
    cy = rng.uniform(0.25, 0.55, n)
    th = rng.uniform(-np.pi, np.pi, n)
    hl = rng.uniform(0.01, 0.141, n)
    hw = rng.uniform(0.005, 0.085, n)
    return cx, cy, th, hl, hw


def test_coverage_exact_in_float64():
    """With x64 the column method marks exactly the cells a separating-axis test says are touched."""
    with enable_x64():
        f = jax.jit(jax.vmap(lambda *a: geometry.rect_column_spans(*a, RES, K)))
        poses = _random_poses(600, 0)
        spans = f(*(jnp.asarray(p, jnp.float64) for p in poses))
        for i in range(600):
            one = jax.tree_util.tree_map(lambda a, i=i: a[i], spans)
            assert not bool(one.overflow)
            ref = rect_touches_cells(*(p[i] for p in poses), RES, SHAPE)
            np.testing.assert_array_equal(_mask_from_spans(one, SHAPE), ref, err_msg=f"pose {i}")


# float32 coordinates carry ~1e-7 m of rounding; a cell overlapped by less than
# this sliver may go either way, never more.
SLIVER = 1e-5


def test_coverage_float32_exact_up_to_rounding():
    f = jax.jit(jax.vmap(lambda *a: geometry.rect_column_spans(*a, RES, K)))
    poses = _random_poses(1500, 1)
    spans = f(*(jnp.asarray(p, jnp.float32) for p in poses))
    for i in range(1500):
        one = jax.tree_util.tree_map(lambda a, i=i: a[i], spans)
        cx, cy, th, hl, hw = (p[i] for p in poses)
        got = _mask_from_spans(one, SHAPE)
        inner = rect_touches_cells(cx, cy, th, hl - SLIVER, hw - SLIVER, RES, SHAPE)
        outer = rect_touches_cells(cx, cy, th, hl + SLIVER, hw + SLIVER, RES, SHAPE)
        assert np.all(got[inner]), f"pose {i}: a clearly touched cell was skipped"
        assert not np.any(got & ~outer), f"pose {i}: a cell not touched was marked"


@pytest.mark.parametrize("theta", [0.0, np.pi / 2, np.pi, -np.pi / 2, np.pi / 4])
def test_axis_aligned_and_diagonal_rectangles(theta):
    """Vertical edges (theta multiple of 90 deg) and 45 deg corners are handled."""
    with enable_x64():
        cx, cy, hl, hw = 0.4013, 0.3987, 0.121, 0.065
        spans = geometry.rect_column_spans(cx, cy, theta, hl, hw, RES, K)
        ref = rect_touches_cells(cx, cy, theta, hl, hw, RES, SHAPE)
        np.testing.assert_array_equal(_mask_from_spans(spans, SHAPE), ref)


def test_overflow_is_flagged():
    spans = geometry.rect_column_spans(0.4, 0.4, 0.3, 0.3, 0.1, RES, 10)
    assert bool(spans.overflow)


finite = st.floats(-3.0, 3.0, allow_nan=False)


@given(st.tuples(finite, finite, finite), st.tuples(finite, finite, finite))
def test_relative_inverts_compose(base, rel):
    base, rel = np.array(base, np.float32), np.array(rel, np.float32)
    back = geometry.relative(jnp.asarray(base), geometry.compose(jnp.asarray(base), jnp.asarray(rel)))
    np.testing.assert_allclose(back[:2], rel[:2], atol=2e-5)  # float32 on |values| <= ~10
    dtheta = np.asarray(geometry.wrap_angle(back[2] - rel[2]))
    assert abs(dtheta) < 2e-5
