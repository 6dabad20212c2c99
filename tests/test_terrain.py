"""Terrain construction, conventions, validation, and scene rasterisation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax.testing import disc_touches_cells, rect_touches_cells


def test_from_arrays_conventions():
    h = np.arange(12, dtype=np.float32).reshape(4, 3)
    t = ij.terrain.from_arrays(h, None, resolution=0.5, origin=(1.0, -2.0))
    assert t.shape == (4, 3) and t.has_height and t.resolution == 0.5
    centres = np.asarray(t.cell_centres())
    np.testing.assert_allclose(centres[0, 0], [1.25, -1.75])
    np.testing.assert_allclose(centres[3, 2], [1.0 + 3.5 * 0.5, -2.0 + 2.5 * 0.5])
    assert np.asarray(t.free).all()
    t2 = ij.terrain.from_arrays(None, np.eye(3, dtype=bool), 0.1)
    assert not t2.has_height and float(jnp.abs(t2.height).max()) == 0.0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(height=np.zeros((3, 3)), free=np.ones((3, 4), bool)), "same shape"),
        (dict(height=np.zeros(5)), "height must be 2D"),
        (dict(height=np.zeros((3, 3)), resolution=0.0), "resolution"),
        (dict(height=np.zeros((3, 3)), resolution=-1.0), "resolution"),
        (dict(height=np.zeros((3, 3)), resolution=float("nan")), "resolution"),
        (dict(height=np.zeros((3, 3)), resolution=1e-300), r"resolution must be .* >= MIN_RESOLUTION"),
        (dict(height=np.zeros((3, 3)), resolution=5e-324), r"resolution must be .* >= MIN_RESOLUTION"),
        (dict(height=np.full((3, 3), np.inf)), "finite"),
        (dict(height=np.zeros((3, 3)), origin=(0.0, np.nan)), "origin must be finite"),
        (dict(height=np.zeros((3, 3)), origin=(0.0,)), "origin must have shape"),
        (dict(height=None, free=None), "needs height"),
        (dict(height=None, free=np.full((2, 2), 3)), "boolean"),
        (dict(height=np.zeros((0, 3))), "empty"),
    ],
)
def test_from_arrays_rejects_bad_input(kwargs, match):
    kwargs.setdefault("free", None)
    with pytest.raises(ValueError, match=match):
        ij.terrain.from_arrays(**kwargs)


def test_a_resolution_set_by_replace_is_checked_as_from_arrays_checks_it():
    t = ij.terrain.from_arrays(np.zeros((3, 3), np.float32), None, ij.terrain.grid.MIN_RESOLUTION)  # the finest
    with pytest.raises(ValueError, match="terrain.resolution must be"):
        ij.terrain.check_terrain(t.replace(resolution=1e-300))


def test_from_image_orientation(tmp_path):
    """Image row 0 is the top (largest y), column 0 the left (smallest x)."""
    img = np.zeros((3, 5), np.uint8)  # 3 rows (y), 5 columns (x)
    img[0, 4] = 255  # top-right pixel -> largest x, largest y
    t = ij.terrain.from_image(img, resolution=0.1, height_scale=0.2 / 255, obstacle_above=0.1)
    assert t.shape == (5, 3)
    assert np.isclose(float(t.height[4, 2]), 0.2) and float(t.height.sum()) == pytest.approx(0.2)
    assert not bool(t.free[4, 2]) and int(np.asarray(t.free).sum()) == 14
    from PIL import Image

    Image.fromarray(img).save(tmp_path / "map.png")
    t2 = ij.terrain.from_image(tmp_path / "map.png", resolution=0.1, height_scale=0.2 / 255)
    np.testing.assert_array_equal(np.asarray(t2.height), np.asarray(t.height))


def test_from_image_reads_a_palette_images_colours_not_its_indices(tmp_path):
    """A palette PNG's pixels are indices; its heights are the colours they stand for (here index i is grey
    255 - 2 i, so reading the indices would give an upside-down, halved map)."""
    from PIL import Image

    idx = np.arange(15, dtype=np.uint8).reshape(3, 5)
    im = Image.fromarray(idx, mode="P")
    im.putpalette([v for i in range(256) for v in (255 - 2 * min(i, 127),) * 3])
    im.save(tmp_path / "palette.png")
    assert Image.open(tmp_path / "palette.png").mode == "P"
    t = ij.terrain.from_image(tmp_path / "palette.png", resolution=0.1, height_scale=1.0)
    grey = (255 - 2 * idx).astype(np.float32)
    np.testing.assert_array_equal(np.asarray(t.height), np.flipud(grey).T)


@pytest.mark.parametrize("kwargs, match", [
    (dict(obstacle_above=float("nan")), "obstacle_above must be a height"),
    (dict(obstacle_above="0.1"), "obstacle_above must be a height"),
    (dict(image=np.zeros((40, 60, 0))), r"channels >= 1"),
    (dict(image=np.full((4, 4), "a")), "must hold numbers"),
])
def test_from_image_refuses_what_it_cannot_read(kwargs, match):
    kwargs = {"image": np.zeros((4, 6), np.uint8), **kwargs}
    with pytest.raises(ValueError, match=match):
        ij.terrain.from_image(resolution=0.1, **kwargs)


def test_rasterize_matches_brute_force():
    rng = np.random.default_rng(3)
    base = ij.terrain.flat((60, 50), 0.02, origin=(-0.3, 0.1), has_height=True)
    boxes = np.column_stack([rng.uniform(-0.2, 0.8, 5), rng.uniform(0.2, 1.0, 5), rng.uniform(-3, 3, 5),
                             rng.uniform(0.01, 0.3, 5), rng.uniform(0.01, 0.2, 5), rng.uniform(0.01, 0.3, 5)])
    cyl = np.column_stack([rng.uniform(-0.2, 0.8, 3), rng.uniform(0.2, 1.0, 3), rng.uniform(0.005, 0.1, 3),
                           rng.uniform(0.01, 0.3, 3)])
    t = jax.jit(ij.terrain.scene.rasterize)(base, boxes, cyl, jnp.array([True, False, False, True, False, False,
                                                                   True, False]))
    ref_h = np.zeros(base.shape)
    ref_blocked = np.zeros(base.shape, bool)
    for i, b in enumerate(boxes):
        m = rect_touches_cells(b[0], b[1], b[2], b[3] / 2, b[4] / 2, 0.02, base.shape, (-0.3, 0.1))
        ref_h = np.where(m, np.maximum(ref_h, b[5]), ref_h)
        ref_blocked |= m & (i in (0, 3))
    for i, c in enumerate(cyl):
        m = disc_touches_cells(c[0], c[1], c[2], 0.02, base.shape, (-0.3, 0.1))
        ref_h = np.where(m, np.maximum(ref_h, c[3]), ref_h)
        ref_blocked |= m & (i == 1)
    np.testing.assert_allclose(np.asarray(t.height), ref_h, atol=1e-7)
    np.testing.assert_array_equal(~np.asarray(t.free), ref_blocked)


def test_rasterize_2d_objects_are_obstacles_and_zero_rows_are_empty():
    base = ij.terrain.flat((30, 30), 0.05)
    boxes = np.array([[0.7, 0.7, 0.0, 0.2, 0.1, 0.3], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    t = ij.terrain.scene.rasterize(base, boxes)
    ref = rect_touches_cells(0.7, 0.7, 0.0, 0.1, 0.05, 0.05, (30, 30))
    np.testing.assert_array_equal(~np.asarray(t.free), ref)
    assert not t.has_height and float(jnp.abs(t.height).max()) == 0.0


def test_rasterize_vmaps_over_scenes():
    base = ij.terrain.flat((20, 20), 0.05, has_height=True)
    boxes = jnp.stack([jnp.array([[0.5, 0.5, 0.0, 0.2, 0.2, h]]) for h in (0.1, 0.2, 0.3)])
    ts = jax.vmap(lambda b: ij.terrain.scene.rasterize(base, b))(boxes)
    np.testing.assert_allclose(np.asarray(ts.height.max(axis=(1, 2))), [0.1, 0.2, 0.3], rtol=1e-6)


def test_check_terrain_refuses_what_replace_set():
    t = ij.terrain.flat((20, 20), 0.02, has_height=True)
    ij.terrain.check_terrain(t)
    for bad, err, match in [
        (t.replace(origin=jnp.array([jnp.nan, 0.0])), ValueError, "origin"),
        (t.replace(origin=jnp.zeros(3)), ValueError, "origin"),
        (t.replace(height=t.height.at[3, 3].set(jnp.inf)), ValueError, "height"),
        (t.replace(free=t.free.astype(jnp.float32)), TypeError, "free"),
        (t.replace(resolution=0.0), ValueError, "resolution"),
        (t.replace(resolution=float("nan")), ValueError, "resolution"),
    ]:
        with pytest.raises(err, match=match):
            ij.terrain.check_terrain(bad)
    flag = jax.jit(ij.terrain.terrain_supported)
    assert bool(flag(t)) and not bool(flag(t.replace(origin=jnp.array([0.0, jnp.inf]))))


@pytest.mark.parametrize("kwargs, match", [
    (dict(height=None, free=np.full((4, 4), "yes")), "free"),
    (dict(height=np.full((4, 4), "1.0")), "height"),
    (dict(height=np.zeros((4, 4)), origin=("a", "b")), "origin"),
    (dict(height=np.zeros((4, 4)), resolution="0.02"), "resolution"),
])
def test_from_arrays_refuses_strings_with_a_clear_error(kwargs, match):
    with pytest.raises(TypeError, match=match):
        ij.terrain.from_arrays(**kwargs)
