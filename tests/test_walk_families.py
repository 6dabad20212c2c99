"""The walking benchmark's terrain families (:mod:`ijoy_jax.terrain.walk_families`): every family draws the same
maps for the same key as when the families lived in ``ijoy_jax/apps/bench_walk.py`` (checksums of those maps,
captured from that code before the move), and the benchmark still names them where users import them.
"""

import hashlib

import jax
import numpy as np
import pytest

from ijoy_jax import robots
from ijoy_jax.apps import bench_walk
from ijoy_jax.sim import model
from ijoy_jax.terrain import walk_families as WF

KEY = 7
BATCH = 2
SUM_TOL = 1e-6
"""Relative: float64 sums of float32 maps drawn by the same ops."""
CELL_TOL = 1e-7
"""m per cell: float32 rounding of heights under 1 m, which XLA's CPU kernels may round differently from one
process to the next; summed over the cells it bounds the sums' absolute error (a near-zero sum, such as a cross
slope's, is all rounding), while a real change of the maps moves them by centimetres per cell."""

# name: (sha256 of the (BATCH, 250, 100) bool free mask, first 16 hex digits; sum of heights (m); sum of squared
# heights (m^2); sum of heights times sin(flat cell index) (m)), from ``fam.make(jax.random.key(7), 2,
# shape=(250, 100), resolution=0.02)`` of the families as bench_walk.py defined them.
CHECKSUMS = {
    "flat": ("793060f4a877d835", 0.0, 0.0, 0.0),
    "clutter2d": ("9602a5247c5efb1d", 82.40000122785568, 8.240000245571139, -3.1619135083313528),
    "uphill": ("793060f4a877d835", 13517.670681583695, 5706.699791307878, -0.024385229172300182),
    "downhill": ("793060f4a877d835", -13517.670686945436, 5706.6997930301795, 0.024384899073209565),
    "cross": ("793060f4a877d835", -0.0004425510996952653, 312.66632700104014, 0.2520133457945295),
    "rough": ("793060f4a877d835", -25.636279056588563, 18.638018104134108, 0.1562358343460459),
    "stones": ("793060f4a877d835", -4654.145155661128, 2321.7763641378624, 5.559221931778152),
    "platforms": ("793060f4a877d835", 325.115157853812, 22.73979733100694, -0.20037377196526163),
    "stairs_up": ("793060f4a877d835", 22903.8240686059, 15360.411151543532, 0.3759873866975656),
    "stairs_down": ("793060f4a877d835", -22903.8240686059, 15360.411151543532, -0.3759873866975656),
    "image": ("793060f4a877d835", -299.4711716291684, 16.14636018287088, 0.23721228235595926),
    # added after the move (captured from walk_families.natural when it was written)
    "natural": ("793060f4a877d835", 444.44517074423356, 7.8861613911247535, 0.6283986325473397),
}


def checksum(t) -> tuple:
    h = np.asarray(t.height, np.float64)
    weights = np.sin(np.arange(h.size, dtype=np.float64)).reshape(h.shape)
    free = hashlib.sha256(np.asarray(t.free).tobytes()).hexdigest()[:16]
    return free, float(h.sum()), float((h * h).sum()), float((h * weights).sum())


def test_the_families_are_the_benchmarks_in_table_order():
    assert list(WF.FAMILIES) == list(CHECKSUMS)


@pytest.mark.parametrize("name", list(CHECKSUMS))
def test_same_maps_for_the_same_key(name):
    fam = WF.FAMILIES[name]
    t = fam.make(jax.random.key(KEY), BATCH, shape=WF.grid_shape(), resolution=WF.RESOLUTION)
    assert t.height.shape == (BATCH, 250, 100) and t.has_height
    free, *sums = checksum(t)
    want_free, *want_sums = CHECKSUMS[name]
    assert free == want_free, name
    np.testing.assert_allclose(sums, want_sums, rtol=SUM_TOL, atol=CELL_TOL * t.height.size, err_msg=name)


def test_the_benchmark_names_the_families_where_it_did():
    """``ijoy_jax.apps.bench_walk`` re-exports every public name the module had when it moved (the same
    objects); names added since live in ``walk_families`` only."""
    assert bench_walk.FAMILIES is WF.FAMILIES
    added = {"NATURAL_RANGE", "NATURAL_SEED", "natural"}
    for name in sorted(set(WF.__all__) - added):
        assert getattr(bench_walk, name) is getattr(WF, name), name


def test_the_robot_and_simulator_numbers_are_theirs():
    """The constants the terrain layer keeps instead of importing the robot and the simulator equal theirs."""
    assert WF.PLATFORM_HEIGHT_MAX == float(np.max(np.asarray(robots.hrp2().max_step_height)))
    assert WF.CLUTTER_HEIGHT == model.BipedParams().obstacle_height
    got = bench_walk.family_robot(WF.FAMILIES["stairs_up"])
    want = robots.hrp2(reach=WF.STAIR_REACH)
    assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(want)
    for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_natural_maps_span_their_range_from_a_flat_start_pad():
    """Each natural map is a window of the seed-1 ground image scaled to span NATURAL_RANGE exactly, level
    (height 0) on the start pad where the standing feet rest."""
    t = WF.natural(jax.random.key(3), 3, shape=WF.grid_shape(), resolution=WF.RESOLUTION)
    h = np.asarray(t.height, np.float64)
    np.testing.assert_allclose(h.max(axis=(1, 2)) - h.min(axis=(1, 2)), WF.NATURAL_RANGE, rtol=1e-5)
    centres = np.asarray(WF.grid.flat(WF.grid_shape(), WF.RESOLUTION, has_height=True).cell_centres())
    pad = np.linalg.norm(centres - np.asarray(WF.START), axis=-1) <= WF.START_RADIUS
    assert pad.sum() > 100 and np.all(h[:, pad] == 0.0)
    assert np.asarray(t.free).all()
    # the same windows as the image family's on the seed-1 image, up to each map's scale
    ground = WF.grid.from_image(WF.write_ground_png(str(WF.tempfile.mkdtemp()) + "/g.png", seed=WF.NATURAL_SEED),
                                WF.RESOLUTION, height_scale=WF.IMAGE_SCALE)
    raw = np.asarray(WF.image(jax.random.key(3), 3, shape=WF.grid_shape(), resolution=WF.RESOLUTION,
                              ground=ground).height, np.float64)
    scale = WF.NATURAL_RANGE / (raw.max(axis=(1, 2)) - raw.min(axis=(1, 2)))
    np.testing.assert_allclose(h, raw * scale[:, None, None], atol=1e-7)
