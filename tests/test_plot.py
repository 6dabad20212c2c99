"""ijoy_jax.plot: the drawn footprints are the footprint rectangles, the drawn images are the terrain arrays."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402

import ijoy_jax as ij  # noqa: E402
from ijoy_jax import plot  # noqa: E402
from ijoy_jax.testing import rect_corners  # noqa: E402

TOL = 1e-9  # float64 throughout


@pytest.fixture
def ax():
    fig, ax = plt.subplots()
    yield ax
    plt.close(fig)


@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(-7, 7), st.floats(0.01, 1), st.floats(0.01, 1))
def test_footprint_polygon_is_the_rotated_rectangle(x, y, t, length, width):
    p = plot.footprint_polygon((x, y, t), length, width)
    assert p.shape == (4, 2)
    np.testing.assert_allclose(p, rect_corners(x, y, t, length / 2, width / 2), atol=TOL)
    np.testing.assert_allclose(p.mean(0), [x, y], atol=TOL)
    edges = np.roll(p, -1, axis=0) - p
    np.testing.assert_allclose(np.hypot(*edges.T), [length, width, length, width], atol=TOL)
    # Corners front-left, rear-left, rear-right, front-right: the first edge runs backwards along the heading,
    # the second from the left side to the right one.
    heading = np.array([np.cos(t), np.sin(t)])
    np.testing.assert_allclose(edges[0], -length * heading, atol=TOL)
    np.testing.assert_allclose(edges[1], -width * np.array([-heading[1], heading[0]]), atol=TOL)


def test_draw_footsteps_draws_the_masked_footprints_coloured_by_side(ax):
    steps = np.array([[0.2, 0.3, 0.0], [0.4, 0.1, 0.5], [0.6, 0.3, -0.4], [0.8, 0.1, 1.0]])
    sides = np.array([1, -1, 1, -1])
    mask = np.array([True, True, False, True])
    bad = np.array([False, True, True, False])
    plot.draw_footsteps(ax, steps, sides, 0.24, 0.13, mask=mask, bad=bad, label="taken")
    drawn = ax.patches
    assert len(drawn) == mask.sum()
    for poly, k in zip(drawn, np.flatnonzero(mask), strict=True):
        np.testing.assert_allclose(poly.get_xy()[:4], plot.footprint_polygon(steps[k], 0.24, 0.13), atol=1e-12)
        assert poly.get_edgecolor() == to_rgba("tab:blue" if sides[k] > 0 else "tab:red")
    assert drawn[0].get_label() == "taken" and not any(p.get_label() == "taken" for p in drawn[1:])  # one entry
    # One black x per step that is both drawn and bad: step 1 only (step 2 is masked out).
    crosses = [line for line in ax.lines if line.get_marker() == "x"]
    assert len(crosses) == 1
    np.testing.assert_allclose(np.c_[crosses[0].get_xdata(), crosses[0].get_ydata()], steps[1:2, :2])


@pytest.mark.parametrize("has_height", [False, True])
def test_draw_terrain_shows_the_arrays(ax, has_height):
    rng = np.random.default_rng(0)
    height = rng.uniform(0, 0.1, (12, 8)).astype(np.float32) if has_height else None
    free = rng.uniform(size=(12, 8)) > 0.2
    t = ij.terrain.from_arrays(height, free, resolution=0.05, origin=(-0.1, 0.2))
    plot.draw_terrain(ax, t)
    images = ax.get_images()
    assert len(images) == (2 if has_height else 1)
    extent = (-0.1, -0.1 + 12 * 0.05, 0.2, 0.2 + 8 * 0.05)
    for im in images:
        np.testing.assert_allclose(im.get_extent(), extent, atol=1e-6)
        assert im.origin == "lower"
    obstacles = images[-1].get_array()  # (ny, nx): rows are y, masked where free
    np.testing.assert_array_equal(~np.ma.getmaskarray(obstacles), ~free.T)
    if has_height:
        np.testing.assert_array_equal(np.asarray(images[0].get_array()), height.T)
    np.testing.assert_allclose(ax.get_xlim(), extent[:2], atol=1e-6)
    np.testing.assert_allclose(ax.get_ylim(), extent[2:], atol=1e-6)
