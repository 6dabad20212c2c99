"""ijoy_jax.terrain.scene: posed boxes and cylinders rasterised into terrain maps.

References: :func:`ijoy_jax.testing.rect_touches_cells` and :func:`disc_touches_cells` (float64 brute force
over every cell). The library works in float32, so for random poses a cell may differ from the reference
only where the float64 answer flips within ``EDGE_TOL`` of the object's edge: the rasterised cover is
checked to lie between the reference of the object shrunk by ``EDGE_TOL`` and grown by it.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.terrain import scene
from ijoy_jax.testing import disc_touches_cells, rect_touches_cells

RES = 0.05
SHAPE = (24, 20)  # 1.2 m x 1.0 m
ORIGIN = (-0.2, 0.1)
EDGE_TOL = 1e-5  # m: float32 rounding of poses of about 1 m (eps 1.2e-7 per metre) times a few operations

coord = st.floats(-0.4, 1.3, allow_nan=False)
yaw = st.floats(-4.0, 4.0, allow_nan=False)
extent = st.floats(0.001, 0.6, allow_nan=False)


def terrain(has_height=True):
    return ij.terrain.flat(SHAPE, RES, origin=ORIGIN, has_height=has_height)


def box_ref(x, y, t, length, width, grow=0.0):
    return rect_touches_cells(x, y, t, max(length / 2 + grow, 0.0), max(width / 2 + grow, 0.0), RES, SHAPE, ORIGIN)


@given(coord, coord, yaw, extent, extent)
def test_box_cover_matches_brute_force(x, y, t, length, width):
    got = np.asarray(scene.box_cover(terrain(), jnp.array([x, y, t, length, width, 0.1], jnp.float32)))
    inner, outer = box_ref(x, y, t, length, width, -EDGE_TOL), box_ref(x, y, t, length, width, EDGE_TOL)
    assert got.shape == SHAPE and got.dtype == bool
    assert np.all(got >= inner) and np.all(got <= outer)


@given(coord, coord, st.floats(0.001, 0.4, allow_nan=False))
def test_cylinder_cover_matches_brute_force(x, y, r):
    got = np.asarray(scene.cylinder_cover(terrain(), jnp.array([x, y, r, 0.1], jnp.float32)))
    inner = disc_touches_cells(x, y, max(r - EDGE_TOL, 0.0), RES, SHAPE, ORIGIN)
    outer = disc_touches_cells(x, y, r + EDGE_TOL, RES, SHAPE, ORIGIN)
    assert np.all(got >= inner) and np.all(got <= outer)


def test_aligned_box_covers_exactly_its_cells_and_touching_edges_do_not_count():
    # Dyadic numbers (exact in float32): 1/16 m cells, the box spans x in [1/16, 6/16], y in [7/16, 12/16],
    # its sides on cell edges.
    res = 1 / 16
    t = ij.terrain.flat(SHAPE, res)
    box = [3.5 * res, 9.5 * res, 0.0, 5 * res, 5 * res, 1.0]
    got = np.asarray(scene.box_cover(t, jnp.array(box)))
    want = np.zeros(SHAPE, bool)
    want[1:6, 7:12] = True  # the neighbours of these cells only touch an edge
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got, rect_touches_cells(*box[:3], 2.5 * res, 2.5 * res, res, SHAPE))
    # A quarter turn of a (slightly smaller: cos(pi/2) is not 0 in float32) square covers the same cells.
    turned = np.asarray(scene.box_cover(t, jnp.array([*box[:2], np.pi / 2, 4.99 * res, 4.99 * res, 1.0])))
    np.testing.assert_array_equal(turned, want)


def test_zero_extent_rows_cover_nothing():
    t = terrain()
    assert not scene.box_cover(t, jnp.array([0.5, 0.5, 0.3, 0.0, 0.2, 0.1])).any()
    assert not scene.box_cover(t, jnp.array([0.5, 0.5, 0.3, 0.2, 0.0, 0.1])).any()
    assert not scene.cylinder_cover(t, jnp.array([0.5, 0.5, 0.0, 0.1])).any()
    out = scene.rasterize(t, boxes=np.zeros((3, 6)), cylinders=np.zeros((2, 4)), obstacle=True)
    assert bool(out.free.all()) and float(out.height.max()) == 0.0


def test_platforms_raise_the_height_and_obstacles_block():
    """2.5D: every covered cell takes the highest top over it (never lower than the ground); only objects
    flagged as obstacles make their cells not free."""
    ground = np.full(SHAPE, 0.02, np.float32)
    ground[0, 0] = 0.5  # a high cell that a low object must not lower
    t = ij.terrain.from_arrays(ground, None, RES, ORIGIN)
    boxes = np.array([[0.1, 0.4, 0.4, 0.5, 0.3, 0.08],    # platform
                      [0.31, 0.51, 0.0, 0.3, 0.3, 0.15],  # obstacle, overlaps the platform
                      [-0.15, 0.15, 0.0, 0.2, 0.2, 0.05]])  # platform over the high cell (0, 0)
    cyl = np.array([[0.8, 0.8, 0.12, 0.2]])  # obstacle
    out = scene.rasterize(t, boxes=boxes, cylinders=cyl, obstacle=np.array([False, True, False, True]))
    covers = [box_ref(*b[:5]) for b in boxes] + [disc_touches_cells(0.8, 0.8, 0.12, RES, SHAPE, ORIGIN)]
    tops = np.concatenate([boxes[:, 5], cyl[:, 3]])
    want_h = ground.astype(np.float64)
    for c, top in zip(covers, tops, strict=True):
        want_h = np.where(c, np.maximum(want_h, top), want_h)
    want_blocked = covers[1] | covers[3]
    assert all(c.any() for c in covers) and (covers[0] & covers[1]).any() and covers[2][0, 0]
    np.testing.assert_allclose(np.asarray(out.height), want_h, atol=1e-7)
    np.testing.assert_array_equal(~np.asarray(out.free), want_blocked)
    assert float(out.height[0, 0]) == pytest.approx(0.5)
    # The default: every object a surface to stand on, nothing blocked.
    assert bool(scene.rasterize(t, boxes=boxes, cylinders=cyl).free.all())


def test_2d_objects_are_obstacles_whatever_the_flag():
    t = terrain(has_height=False)
    box = np.array([[0.4, 0.5, 0.7, 0.3, 0.1, 0.05]])
    for flag in (False, True):
        out = scene.rasterize(t, boxes=box, obstacle=flag)
        np.testing.assert_array_equal(~np.asarray(out.free), box_ref(*box[0, :5]))
        assert not out.has_height


def test_no_objects_returns_the_terrain():
    t = terrain()
    assert scene.rasterize(t) is t
    assert scene.rasterize(t, boxes=np.zeros((0, 6)), cylinders=np.zeros((0, 4))) is t


def test_new_object_values_do_not_recompile():
    f = jax.jit(scene.rasterize)  # jit wrappers of one function share a cache: count entries from the first call
    t = terrain()
    rng = np.random.default_rng(0)
    sizes = []
    for _ in range(3):
        boxes = np.column_stack([rng.uniform(0, 1, 2), rng.uniform(0.2, 1, 2), rng.uniform(-3, 3, 2),
                                 rng.uniform(0.05, 0.3, (2, 2)), rng.uniform(0.01, 0.2, 2)]).astype(np.float32)
        out = f(t, boxes, None, True)
        assert (~np.asarray(out.free)).sum() > 0
        sizes.append(compiled_count(f))
    assert sizes[0] >= 1 and sizes == [sizes[0]] * 3
