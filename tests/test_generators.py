"""Procedural terrain generators: jit/vmap, no recompiles, determinism, geometry vs NumPy."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy import ndimage

from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.terrain import Terrain
from ijoy_jax.terrain import generators as gen
from ijoy_jax.testing import disc_touches_cells, rect_touches_cells

# One small grid for (almost) every test, so each family compiles once per mode:
# 48 x 40 cells of 5 cm = 2.4 m x 2.0 m; the default start point is (0.36, 1.0) m.
SHAPE = (48, 40)
RES = 0.05
ORIGIN = (0.3, -0.7)
GRID = dict(shape=SHAPE, resolution=RES, origin=ORIGIN)
BATCH = 3
# float32 cell centres and positions of a few metres are exact to ~1e-6 m; cells
# whose centre lies this close to a riser, edge or zone boundary may go either way.
GEOM_TOL = 1e-4
# Heights from a vmapped and a single call may differ by float32 rounding only.
HEIGHT_ATOL = 1e-6

# Parameters that exercise every random draw (jitters on) and fit the small grid.
BUSY = {
    "flat": gen.FlatParams(elevation=0.05),
    "walls": gen.WallParams(count=5, length_min=0.3, length_max=0.8, thickness_min=0.05, thickness_max=0.3),
    "obstacles": gen.ObstacleParams(count=10),
    "bars": gen.BarParams(count=2, first=0.5, spacing=0.6, width=0.07),
    "platforms": gen.PlatformParams(count=3, length_min=0.3, length_max=0.6, width_min=0.3, width_max=0.6),
    "stairs": gen.StairParams(rise=0.1, run=0.25, num_steps=4, first=0.4, rise_jitter=0.01, run_jitter=0.03),
    "stepping_stones": gen.SteppingStoneParams(
        size=0.25, spacing=0.35, jitter=0.03, yaw_jitter=0.2, top=0.1, top_jitter=0.02
    ),
    "slope": gen.SlopeParams(angle=0.2, direction=0.5),
    "rough": gen.RoughParams(amplitude=0.03, correlation_length=0.15, obstacle_above=0.05),
    "corridor": gen.CorridorParams(length=1.2, width_start=0.6, width_end=0.4, count=2, pocket_width=0.2,
                                   pocket_depth=0.15, pocket_from=0.2, start_radius=0.2),
    "stone_path": gen.StonePathParams(size=0.3, pitch=0.36, pitch_jitter=0.03, top=0.1, top_jitter=0.02),
}
RANDOM_FAMILIES = [f for f in gen.FAMILIES if f not in ("flat", "slope")]


def _other_values(params):
    """Same structure and leaf dtypes, different values (floats x 0.9, ints - 1)."""

    def change(x):
        if isinstance(x, int):
            return max(x - 1, 0)
        return x * 0.9 if math.isfinite(x) else x

    return jax.tree.map(change, params)


def _batched(params, b=BATCH):
    """Per-terrain parameters: every leaf a (b,) array, values varied per terrain."""

    def leaf(x):
        if isinstance(x, int):
            return np.maximum(np.full(b, x, np.int32) - np.arange(b, dtype=np.int32), 0)
        scale = 1.0 - 0.05 * np.arange(b)
        return (np.full(b, x, np.float32) * scale).astype(np.float32) if math.isfinite(x) else np.full(b, x)

    return jax.tree.map(leaf, params)


@functools.cache
def _counted(name: str, has_height: bool, batched: bool):
    """A jitted generator (single or vmapped) and a function returning how many times it was traced (the
    count lives in this closure)."""
    count = 0

    def fn(keys, params):
        nonlocal count
        count += 1  # runs once per trace
        if batched:
            return gen.batch(name, keys, params, in_axes=0, has_height=has_height, **GRID)
        return gen.generate(name, keys, params, has_height=has_height, **GRID)

    return jax.jit(fn), lambda: count


def compiled(name: str, has_height: bool, batched: bool = False):
    """The jitted generator (single or vmapped), one per family and flags for the whole file."""
    return _counted(name, has_height, batched)[0]


def traces(name: str, has_height: bool, batched: bool = False) -> int:
    """How many times :func:`compiled` of these arguments has been traced."""
    return _counted(name, has_height, batched)[1]()


def _np(t: Terrain):
    return np.asarray(t.height), np.asarray(t.free)


def _centres():
    ix, iy = np.meshgrid(np.arange(SHAPE[0]), np.arange(SHAPE[1]), indexing="ij")
    return np.asarray(ORIGIN[0]) + (ix + 0.5) * RES, np.asarray(ORIGIN[1]) + (iy + 0.5) * RES


def _start(params):
    return (
        ORIGIN[0] + float(params.start_x) * SHAPE[0] * RES,
        ORIGIN[1] + float(params.start_y) * SHAPE[1] * RES,
    )


# --------------------------------------------------------------------------- every family


def test_registry_and_defaults():
    assert set(gen.FAMILIES) == {
        "flat", "walls", "obstacles", "bars", "platforms", "stairs", "stepping_stones", "slope", "rough",
        "corridor", "stone_path",
    }  # fmt: skip
    for name, fam in gen.FAMILIES.items():
        p = fam.params()
        assert fam.params() == p and fam.params() is not p  # fresh defaults each call
        for f in dataclasses.fields(p):  # scalar leaves only, so vmap axes are unambiguous
            assert np.ndim(getattr(p, f.name)) == 0, (name, f.name)
        assert {"start_x", "start_y", "start_radius"} <= {f.name for f in dataclasses.fields(p)}
        out = jax.eval_shape(
            lambda k, name=name: gen.generate(name, k, None, shape=(6, 5)), jax.random.key(0)
        )
        assert out.height.shape == out.free.shape == (6, 5) and out.height.dtype == jnp.float32
        assert isinstance(BUSY[name], fam.params)


@pytest.mark.parametrize("has_height", [False, True], ids=["2d", "2.5d"])
@pytest.mark.parametrize("name", list(gen.FAMILIES))
def test_jit_no_recompile_determinism(name, has_height):
    """Single jitted calls: well-formed, deterministic per key, key-sensitive, and
    parameter changes (same dtypes) never retrace."""
    f = compiled(name, has_height)
    p = BUSY[name]
    a = f(jax.random.key(1), p)
    assert isinstance(a, Terrain) and a.shape == SHAPE and a.has_height == has_height
    assert a.resolution == RES
    h, free = _np(a)
    assert h.dtype == np.float32 and free.dtype == np.bool_ and np.all(np.isfinite(h))
    np.testing.assert_allclose(np.asarray(a.origin), ORIGIN, atol=1e-7)
    if not has_height:
        assert not h.any()
    # Determinism: the same key gives the same terrain.
    b = f(jax.random.key(1), p)
    np.testing.assert_array_equal(_np(a)[0], _np(b)[0])
    np.testing.assert_array_equal(_np(a)[1], _np(b)[1])
    # A different key gives a different terrain (for the families that use it; a 2D
    # stair is free up to its first riser, whose position is not jittered).
    d = f(jax.random.key(2), p)
    differs = not (np.array_equal(_np(d)[0], h) and np.array_equal(_np(d)[1], free))
    assert differs == (name in RANDOM_FAMILIES and (has_height or name != "stairs"))
    # New parameter values: no retrace (counted by a side effect in the traced function).
    before, cached = traces(name, has_height), compiled_count(f)
    f(jax.random.key(1), _other_values(p)).height.block_until_ready()
    assert traces(name, has_height) == before >= 1 and compiled_count(f) == cached == 1


@pytest.mark.parametrize("name", list(gen.FAMILIES))
def test_vmap_matches_single_calls(name):
    """gen.batch over keys and per-terrain parameters equals one call per terrain."""
    f1 = compiled(name, True)
    fb = compiled(name, True, batched=True)
    keys = jax.random.split(jax.random.key(7), BATCH)
    params = _batched(BUSY[name])
    out = fb(keys, params)
    assert out.height.shape == (BATCH, *SHAPE) and out.free.shape == (BATCH, *SHAPE)
    for i in range(BATCH):
        one = f1(keys[i], jax.tree.map(lambda x, i=i: x[i].item(), params))
        np.testing.assert_allclose(np.asarray(out.height[i]), np.asarray(one.height), atol=HEIGHT_ATOL)
        np.testing.assert_array_equal(np.asarray(out.free[i]), np.asarray(one.free))
    # Different parameter values, same shapes and dtypes: no retrace.
    fb(keys, _batched(_other_values(BUSY[name]))).height.block_until_ready()
    assert traces(name, True, True) == 1 and compiled_count(fb) == 1


def test_eager_and_int_seed_match_jit():
    # Eager dispatch compiles every op once, so only the cheapest family runs eagerly.
    p = BUSY["slope"]
    eager = gen.slope(jax.random.key(1), p, has_height=True, **GRID)
    jitted = compiled("slope", True)(jax.random.key(1), p)
    np.testing.assert_allclose(np.asarray(eager.height), np.asarray(jitted.height), atol=HEIGHT_ATOL)
    # An int seed is jax.random.key(seed) (it must be a Python int, so close over it).
    p = BUSY["stairs"]
    seeded = jax.jit(lambda: gen.generate("stairs", 1, p, has_height=True, **GRID))()
    keyed = compiled("stairs", True)(jax.random.key(1), p)
    np.testing.assert_allclose(np.asarray(seeded.height), np.asarray(keyed.height), atol=HEIGHT_ATOL)


def test_batch_infers_axes_for_partially_batched_params():
    keys = jax.random.split(jax.random.key(0), 4)
    rise = jnp.array([0.05, 0.1, -0.1, 0.2])
    fn = jax.jit(lambda k, p: gen.batch("stairs", k, p, has_height=True, **GRID))
    t = fn(keys, gen.StairParams(rise=rise, num_steps=2))
    np.testing.assert_allclose(np.asarray(t.height.max(axis=(1, 2)) + t.height.min(axis=(1, 2))),
                               2 * np.asarray(rise), atol=1e-6)  # fmt: skip
    shared = gen.batch("flat", keys, None, **GRID)  # default params, shared
    assert shared.free.shape == (4, *SHAPE) and bool(shared.free.all())


@pytest.mark.parametrize(
    "call, error, match",
    [
        (lambda: gen.generate("lava", 0), ValueError, "unknown terrain family"),
        (lambda: gen.walls(0, gen.StairParams()), TypeError, "expected WallParams"),
        (lambda: gen.walls(0, gen.WallParams(top=float("nan"))), ValueError, "WallParams.top"),
        (lambda: gen.stairs(0, gen.StairParams(rise=float("inf"))), ValueError, "finite"),
        (lambda: gen.rough(0, gen.RoughParams(obstacle_above=float("nan"))), ValueError, "finite"),
        (lambda: gen.flat(0, shape=(0, 4)), ValueError, "shape must be positive"),
        (lambda: gen.flat(0, shape=(4,)), ValueError, "shape must be two"),
        (lambda: gen.slope(0, resolution=0.0), ValueError, "resolution"),
        (lambda: gen.slope(0, origin=(0.0, float("inf"))), ValueError, "origin"),
        (lambda: gen.bars(0, max_count=-1), ValueError, "max_count"),
        (lambda: gen.objects("stairs", 0), ValueError, "objects"),
    ],
)
def test_rejects_bad_input(call, error, match):
    with pytest.raises(error, match=match):
        call()


# --------------------------------------------------------------------------- start zone


@pytest.mark.parametrize("has_height", [False, True], ids=["2d", "2.5d"])
@pytest.mark.parametrize("name", list(gen.FAMILIES))
def test_start_zone_is_free_ground(name, has_height):
    """Every cell whose centre lies within start_radius is free and at the family's
    ground level, for crowded maps and random start zones."""
    rng = np.random.default_rng(3)
    crowded = {
        "walls": dict(count=8, length_min=1.0, length_max=2.0, thickness_min=0.3, thickness_max=0.6),
        "obstacles": dict(count=16, size_min=0.1, size_max=0.3),
        "bars": dict(count=4, first=0.1, spacing=0.15, position_jitter=0.1, yaw_jitter=0.5, width=0.1),
        "platforms": dict(count=4, length_min=0.8, length_max=1.5, width_min=0.8, width_max=1.5),
        "stairs": dict(first=0.0, run=0.1),
        "stepping_stones": dict(size=0.1, spacing=0.3),
        "rough": dict(obstacle_above=-0.01),
    }.get(name, {})
    f = compiled(name, has_height)
    for trial in range(3):
        p = BUSY[name].replace(
            **crowded, start_x=float(rng.uniform(0.2, 0.8)), start_y=float(rng.uniform(0.2, 0.8)),
            start_radius=float(rng.uniform(0.1, 0.5)),
        )  # fmt: skip
        h, free = _np(f(jax.random.key(trial), p))
        x, y = _centres()
        sx, sy = _start(p)
        inside = np.hypot(x - sx, y - sy) <= float(p.start_radius) - GEOM_TOL
        assert inside.sum() > 10
        assert free[inside].all(), (name, trial)
        if has_height and name != "slope":
            ground = p.elevation if name == "flat" else p.top if name in ("stepping_stones", "stone_path") else 0.0
            np.testing.assert_allclose(h[inside], ground, atol=1e-6)
        if name in ("walls", "obstacles", "platforms") and not has_height:
            assert not free.all()  # the crowded maps do have objects


# --------------------------------------------------------------------------- object families


@pytest.mark.parametrize("name", ["walls", "obstacles", "platforms", "bars"])
def test_objects_match_map_and_params(name):
    """The 2D map equals a NumPy float64 rasterisation of ``objects()``; objects respect
    their parameter ranges, the count and the start zone."""
    p = BUSY[name]
    seeds = [0, 1, 2, 3]
    keys = jnp.stack([jax.random.key(s) for s in seeds])
    all_objs = jax.jit(jax.vmap(lambda k: gen.objects(name, k, p, **GRID)))(keys)
    assert all_objs.boxes.dtype == jnp.float32
    assert all_objs.boxes.shape == (len(seeds), gen.FAMILIES[name].max_count, 6)
    for i, seed in enumerate(seeds):
        boxes = np.asarray(all_objs.boxes[i], np.float64)
        cyls = np.asarray(all_objs.cylinders[i], np.float64)
        used_b, used_c = boxes[:, 3] > 0, cyls[:, 2] > 0
        assert 0 < used_b.sum() + used_c.sum() <= int(p.count)
        sx, sy = _start(p)
        r = float(p.start_radius)
        ref, ref_h = np.zeros(SHAPE, bool), np.zeros(SHAPE)
        for b in boxes[used_b]:
            cover = rect_touches_cells(b[0], b[1], b[2], b[3] / 2, b[4] / 2, RES, SHAPE, ORIGIN)
            ref, ref_h = ref | cover, np.where(cover, np.maximum(ref_h, b[5]), ref_h)
            c, s = np.cos(b[2]), np.sin(b[2])
            u, v = c * (sx - b[0]) + s * (sy - b[1]), -s * (sx - b[0]) + c * (sy - b[1])
            assert np.hypot(max(abs(u) - b[3] / 2, 0), max(abs(v) - b[4] / 2, 0)) >= r + RES - 1e-5
        for cy in cyls[used_c]:
            cover = disc_touches_cells(cy[0], cy[1], cy[2], RES, SHAPE, ORIGIN)
            ref, ref_h = ref | cover, np.where(cover, np.maximum(ref_h, cy[3]), ref_h)
            assert np.hypot(sx - cy[0], sy - cy[1]) - cy[2] >= r + RES - 1e-5
        lengths, widths, tops = boxes[used_b, 3], boxes[used_b, 4], boxes[used_b, 5]
        if name == "walls":
            assert np.all((lengths >= p.length_min - 1e-6) & (lengths <= p.length_max + 1e-6))
            assert np.all((widths >= p.thickness_min - 1e-6) & (widths <= p.thickness_max + 1e-6))
            np.testing.assert_allclose(tops, p.top, rtol=1e-6)
        if name == "obstacles":
            sizes = np.concatenate([lengths, widths, 2 * cyls[used_c, 2]])
            assert np.all((sizes >= p.size_min - 1e-6) & (sizes <= p.size_max + 1e-6))
        if name == "platforms":
            assert not np.asarray(all_objs.obstacle[i]).any()
            assert np.all((tops >= p.height_min - 1e-6) & (tops <= p.height_max + 1e-6))
        _, free = _np(compiled(name, False)(jax.random.key(seed), p))
        # Identical up to cells an object edge grazes within float32 rounding.
        assert np.sum(free != ~ref) <= 2, (seed, np.argwhere(free != ~ref))
        # 2.5D: the highest top over each cell; obstacles are not free, platforms are.
        h, free25 = _np(compiled(name, True)(jax.random.key(seed), p))
        same = free == ~ref
        np.testing.assert_allclose(h[same], ref_h[same], atol=1e-6)
        np.testing.assert_array_equal(free25, np.ones(SHAPE, bool) if name == "platforms" else free)


@settings(max_examples=15)
@given(
    width=st.floats(0.02, 0.3),
    first=st.floats(0.3, 0.8),
    spacing=st.floats(0.35, 0.6),
    count=st.integers(0, 4),
    start_x=st.floats(0.0, 0.3),
)
def test_bars_cover_their_width(width, first, spacing, count, start_x):
    """Jitter-free bars: the obstacle columns are exactly those whose open x-interval
    overlaps a bar, so each bar is ceil(w / res) or one more cells wide. A bar closer
    than start_radius + resolution to the start point is dropped."""
    p = gen.BarParams(
        count=count, first=first, spacing=spacing, width=width, position_jitter=0.0, start_x=start_x,
        start_radius=0.25,
    )  # fmt: skip
    _, free = _np(compiled("bars", False)(jax.random.key(0), p))
    assert (free == free[:, :1]).all()  # bars cross the whole map along y
    blocked = ~free[:, 0]
    xl = ORIGIN[0] + np.arange(SHAPE[0]) * RES
    ref = np.zeros(SHAPE[0], bool)
    near_edge = np.zeros(SHAPE[0], bool)
    sx, _ = _start(p)
    for k in range(count):
        lo, hi = sx + first + k * spacing - width / 2, sx + first + k * spacing + width / 2
        assume(abs(lo - sx - (0.25 + RES)) > GEOM_TOL)
        if lo - sx < 0.25 + RES:
            continue  # dropped: it would reach into the start zone
        ref |= (xl < hi) & (xl + RES > lo)
        near_edge |= (np.abs(xl - hi) < GEOM_TOL) | (np.abs(xl + RES - lo) < GEOM_TOL)
        cells = ((xl < hi) & (xl + RES > lo)).sum()
        inside_map = lo >= ORIGIN[0] and hi <= ORIGIN[0] + SHAPE[0] * RES
        if inside_map and not near_edge.any():
            assert cells in (math.ceil(width / RES), math.ceil(width / RES) + 1)
    np.testing.assert_array_equal(blocked[~near_edge], ref[~near_edge])


# --------------------------------------------------------------------------- surfaces


@settings(max_examples=20)
@given(
    rise=st.one_of(st.just(0.0), st.floats(-0.2, 0.2)),
    run=st.floats(0.1, 0.5),
    num_steps=st.integers(0, 16),
    first=st.floats(0.0, 1.0),
    direction=st.floats(-math.pi, math.pi),
    start_radius=st.floats(0.0, 0.5),
)
def test_stairs_closed_form(rise, run, num_steps, first, direction, start_radius):
    """Heights at cell centres equal rise * clip(ceil((d - first') / run), 0, n); in 2D
    the cells past the first riser are obstacles."""
    p = gen.StairParams(
        rise=rise, run=run, num_steps=num_steps, first=first, direction=direction, start_radius=start_radius
    )
    h, free = _np(compiled("stairs", True)(jax.random.key(0), p))
    _, free2d = _np(compiled("stairs", False)(jax.random.key(0), p))
    x, y = _centres()
    sx, sy = _start(p)
    d = (x - sx) * np.cos(direction) + (y - sy) * np.sin(direction)
    f = max(first, start_radius)
    steps = np.clip(np.ceil((d - f) / run), 0, num_steps)
    edges = f + run * np.arange(num_steps)
    ok = np.min(np.abs(d[..., None] - edges), axis=-1, initial=np.inf) > GEOM_TOL  # not on a riser
    np.testing.assert_allclose(h[ok], (rise * steps)[ok], atol=1e-5)
    assert free.all()
    np.testing.assert_array_equal(free2d[ok], ((steps == 0) | (np.float32(rise) == 0))[ok])


def test_stairs_jitter_ranges():
    """Jittered stairs: each rise within rise +- rise_jitter, each tread within run +-
    run_jitter (to a cell), and the steps are not all alike."""
    p = gen.StairParams(rise=0.1, run=0.3, num_steps=4, first=0.4, rise_jitter=0.03, run_jitter=0.05,
                        start_radius=0.3, start_x=0.0)  # fmt: skip
    all_treads = []
    for seed in range(4):
        h, _ = _np(compiled("stairs", True)(jax.random.key(seed), p))
        assert np.all(h == h[:, :1])  # along +x: constant in y
        levels, first_ix, counts = np.unique(h[:, 0], return_index=True, return_counts=True)
        order = np.argsort(first_ix)
        levels, counts = levels[order], counts[order]
        assert len(levels) == 5
        rises = np.diff(levels)
        assert np.all(np.abs(rises - 0.1) <= 0.03 + 1e-6) and np.ptp(rises) > 1e-3
        treads = counts[1:-1] * RES  # the inner treads (the top landing runs to the edge)
        assert np.all(np.abs(treads - 0.3) <= 0.05 + RES + 1e-6)
        all_treads.extend(treads)
    assert np.ptp(all_treads) > 0


@settings(max_examples=20)
@given(
    angle=st.floats(-0.6, 0.6), direction=st.floats(-math.pi, math.pi), sx=st.floats(0, 1), sy=st.floats(0, 1)
)
def test_slope_plane_fit(angle, direction, sx, sy):
    """A least-squares plane through the heights has gradient tan(angle) (cos, sin)(direction)
    and passes through 0 at the start point."""
    p = gen.SlopeParams(angle=angle, direction=direction, start_x=sx, start_y=sy)
    h, free = _np(compiled("slope", True)(jax.random.key(0), p))
    x, y = _centres()
    a = np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)
    (gx, gy, c), *_ = np.linalg.lstsq(a, h.ravel().astype(np.float64), rcond=None)
    np.testing.assert_allclose([gx, gy], np.tan(angle) * np.array([np.cos(direction), np.sin(direction)]),
                               atol=1e-5)  # fmt: skip
    px, py = _start(p)
    assert abs(gx * px + gy * py + c) < 1e-5
    assert free.all()
    _, free2d = _np(compiled("slope", False)(jax.random.key(0), p))
    assert free2d.all()


def test_slope_is_clipped_and_finite():
    h, _ = _np(gen.slope(0, gen.SlopeParams(angle=math.pi / 2), has_height=True, **GRID))
    assert np.all(np.isfinite(h)) and np.abs(np.diff(h, axis=0)).max() <= np.tan(np.radians(80)) * RES * 1.001


# Rough-noise statistics on a larger grid, 8 maps: 128 x 128 cells of 2 cm, l = 6 cm
# (3 cells). With ~pi l^2 / res^2 = 28 correlated cells per sample, the relative sd
# of the pooled variance is sqrt(2 * 28 / (8 * 128^2)) ~ 2%, of the RMS ~ 1%, and of
# the lag-l autocorrelation ~ 2%; the tolerances below are about 5 sd.
ROUGH_SHAPE, ROUGH_RES, ROUGH_MAPS = (128, 128), 0.02, 8
RMS_RTOL = 0.05
ACF_ATOL = 0.1


@pytest.mark.slow
def test_rough_statistics():
    amp, ell = 0.04, 0.06
    p = gen.RoughParams(amplitude=amp, correlation_length=ell, start_radius=0.0)
    keys = jax.random.split(jax.random.key(11), ROUGH_MAPS)
    fn = jax.jit(
        lambda k, q: gen.batch("rough", k, q, shape=ROUGH_SHAPE, resolution=ROUGH_RES, has_height=True)
    )
    h = np.asarray(fn(keys, p).height, np.float64)
    assert np.all(np.abs(h.mean(axis=(1, 2))) < 1e-3 * amp)  # the DC term is removed
    rms = np.sqrt(np.mean(h**2))
    assert abs(rms / amp - 1) < RMS_RTOL, rms
    lag = round(ell / ROUGH_RES)
    acf = np.mean(h * np.roll(h, lag, axis=1)) / np.mean(h**2)  # the field is periodic
    assert abs(acf - np.exp(-0.5)) < ACF_ATOL, acf
    # Linear in the amplitude for a fixed key; correlation length 0 is white noise.
    h2 = np.asarray(fn(keys, p.replace(amplitude=2 * amp)).height, np.float64)
    np.testing.assert_allclose(h2, 2 * h, atol=1e-6)
    w = np.asarray(fn(keys, p.replace(correlation_length=0.0)).height, np.float64)
    assert abs(np.sqrt(np.mean(w**2)) / amp - 1) < RMS_RTOL
    assert abs(np.mean(w * np.roll(w, 1, axis=1)) / np.mean(w**2)) < 0.02
    huge = np.asarray(fn(keys, p.replace(correlation_length=100.0)).height)  # no underflow to NaN
    assert np.all(np.isfinite(huge)) and abs(np.sqrt(np.mean(huge**2.0)) / amp - 1) < 0.5


def test_rough_obstacles_and_start_taper():
    p = BUSY["rough"]
    h, free = _np(compiled("rough", True)(jax.random.key(4), p))
    x, y = _centres()
    sx, sy = _start(p)
    dist = np.hypot(x - sx, y - sy)
    zone = dist <= float(p.start_radius) - GEOM_TOL
    outside = dist > float(p.start_radius) + GEOM_TOL
    np.testing.assert_array_equal(free[outside], (h <= p.obstacle_above)[outside])
    assert free[zone].all() and not free.all()
    # The taper: |h| grows at most linearly over one correlation length.
    ramp = np.clip((dist - float(p.start_radius)) / float(p.correlation_length), 0, 1)
    assert np.all(np.abs(h) <= ramp * 6 * float(p.amplitude) + 1e-6)
    _, free2d = _np(compiled("rough", False)(jax.random.key(4), p))
    np.testing.assert_array_equal(free2d, free)  # one mechanism for both


def _interval_cells(lo, hi, n, cell0, tol):
    """(n,) bool: cells [cell0 + k*RES, cell0 + (k+1)*RES] inside some [lo_i, hi_i], tol inward."""
    a = cell0 + np.arange(n) * RES
    return np.any((a[:, None] >= lo[None] + tol) & (a[:, None] + RES <= hi[None] - tol), axis=1)


@settings(max_examples=20)
@given(
    size=st.floats(0.1, 0.4),
    gap=st.floats(0.0, 0.3),
    sx=st.floats(0, 1),
    sy=st.floats(0, 1),
)
def test_stepping_stones_lattice_reference(size, gap, sx, sy):
    """Without jitter the free cells are exactly the cells lying wholly on a stone of the
    lattice centred on the start point (separable NumPy reference)."""
    spacing = size + gap
    p = gen.SteppingStoneParams(
        size=size, spacing=spacing, jitter=0.0, start_x=sx, start_y=sy, start_radius=0.0, top=0.1,
        gap_height=-0.3,
    )  # fmt: skip
    _, free = _np(compiled("stepping_stones", False)(jax.random.key(0), p))
    h, free25 = _np(compiled("stepping_stones", True)(jax.random.key(0), p))
    px, py = _start(p)
    ks = np.arange(-200, 201)
    cx, cy = px + ks * spacing, py + ks * spacing
    lo_x, hi_x, lo_y, hi_y = cx - size / 2, cx + size / 2, cy - size / 2, cy + size / 2
    sure = np.outer(
        _interval_cells(lo_x, hi_x, SHAPE[0], ORIGIN[0], GEOM_TOL),
        _interval_cells(lo_y, hi_y, SHAPE[1], ORIGIN[1], GEOM_TOL),
    )
    maybe = np.outer(
        _interval_cells(lo_x, hi_x, SHAPE[0], ORIGIN[0], -GEOM_TOL),
        _interval_cells(lo_y, hi_y, SHAPE[1], ORIGIN[1], -GEOM_TOL),
    )
    assert np.all(free[sure]) and not np.any(free[~maybe])
    assert free25.all()
    np.testing.assert_allclose(h, np.where(free, 0.1, -0.3), atol=1e-6)


def test_stepping_stones_fraction_exact():
    """Stones aligned with the cells: the free fraction is exactly (size / spacing)^2."""
    p = gen.SteppingStoneParams(
        size=0.2, spacing=0.4, jitter=0.0, start_x=0.25, start_y=0.5, start_radius=0.0
    )
    _, free = _np(compiled("stepping_stones", False)(jax.random.key(0), p))
    # Start (0.9, 0.3) on a cell corner: whole stones at x in [0.8 + 0.4 i, 1.0 + 0.4 i],
    # i = -1..4, and y in [0.2 + 0.4 j, 0.4 + 0.4 j], j = -2..2: 30 stones of 4 x 4 cells.
    assert free.sum() == 30 * 16


@settings(max_examples=6)
@given(seed=st.integers(0, 2**31 - 1), yaw_jitter=st.floats(0.0, 0.8), jitter=st.floats(0.0, 0.2))
def test_stepping_stones_jittered_are_separate_islands(seed, yaw_jitter, jitter):
    """Jittered, yawed stones stay inside their lattice cells: every island lies in one
    site, no island is larger than a stone, every site well inside the map has a stone,
    and each stone draws its own top (2.5D)."""
    size, spacing = 0.25, 0.35
    p = gen.SteppingStoneParams(size=size, spacing=spacing, jitter=jitter, yaw_jitter=yaw_jitter,
                                start_radius=0.0, top=0.1, top_jitter=0.05, gap_height=-1.0)  # fmt: skip
    _, free = _np(compiled("stepping_stones", False)(jax.random.key(seed), p))
    h, _ = _np(compiled("stepping_stones", True)(jax.random.key(seed), p))
    labels, n = ndimage.label(free)
    x, y = _centres()
    px, py = _start(p)
    site = np.floor((x - px) / spacing + 0.5) * 1000 + np.floor((y - py) / spacing + 0.5)
    areas = ndimage.sum(np.ones(SHAPE), labels, index=np.arange(1, n + 1))
    assert np.all(areas * RES**2 <= size**2 + 1e-9)
    tops = set()
    for i in range(1, n + 1):
        assert len(np.unique(site[labels == i])) == 1
        top = np.unique(h[labels == i])
        assert len(top) == 1 and abs(top[0] - 0.1) <= 0.05 + 1e-6
        tops.add(float(top[0]))
    assert len(tops) == n  # independent draws per stone
    np.testing.assert_array_equal(h[~free], np.float32(-1.0))
    interior = (x > ORIGIN[0] + spacing) & (x < ORIGIN[0] + SHAPE[0] * RES - spacing)
    interior &= (y > ORIGIN[1] + spacing) & (y < ORIGIN[1] + SHAPE[1] * RES - spacing)
    assert set(np.unique(site[interior])) <= set(np.unique(site[free]))


def test_platforms_and_flat_heights():
    p = gen.PlatformParams(count=3, height_min=0.12, height_max=0.12)
    h, free = _np(compiled("platforms", True)(jax.random.key(5), p))
    assert set(np.unique(h).tolist()) <= {0.0, float(np.float32(0.12))} and (h > 0).any() and free.all()
    _, free2d = _np(compiled("platforms", False)(jax.random.key(5), p))
    np.testing.assert_array_equal(free2d, h == 0)  # in 2D a platform is an obstacle
    h, free = _np(compiled("flat", True)(jax.random.key(0), gen.FlatParams(elevation=-0.25)))
    assert free.all() and np.all(h == np.float32(-0.25))


def test_start_point():
    p = gen.WallParams(start_x=0.5, start_y=0.25)
    np.testing.assert_allclose(np.asarray(gen.start_point(p, **GRID)), [0.3 + 1.2, -0.7 + 0.5], atol=1e-6)


# --------------------------------------------------------------------------- single-lane bars


@pytest.mark.parametrize("lane", [-1.0, 1.0])
@pytest.mark.parametrize("gap", [0.012, 0.12, 0.31])  # inner ends off the cell edges
def test_single_lane_bars_block_one_side_only(lane, gap):
    """lane = -1 (+1): the bar's columns are those of the full-width bar, but only on the cells
    whose open y-interval overlaps y < start_y - gap (y > start_y + gap), out to the map edge."""
    full = gen.BarParams(count=2, first=0.5, spacing=0.6, width=0.07, position_jitter=0.0)
    p = dataclasses.replace(full, lane=lane, lane_gap=gap)
    _, free_full = _np(compiled("bars", False)(jax.random.key(0), full))
    _, free = _np(compiled("bars", False)(jax.random.key(0), p))
    _, sy = _start(p)
    yl = ORIGIN[1] + np.arange(SHAPE[1]) * RES  # lower cell edges
    side = (yl < sy - gap) if lane < 0 else (yl + RES > sy + gap)
    assert np.all(np.abs(yl - (sy - gap)) > GEOM_TOL) and np.all(np.abs(yl - (sy + gap)) > GEOM_TOL)
    np.testing.assert_array_equal(free, free_full | ~side[None, :])
    assert (~free).any() and (free_full[:, side] == free[:, side]).all()


def test_single_lane_bar_defaults_and_tracing():
    """lane = 0 (the default) is the full-width bar; lane and lane_gap are traced leaves (vmap, no
    recompile), and objects() gives the rasterised boxes."""
    base = gen.BarParams(count=1, first=0.6, width=0.1)
    keys = jax.random.split(jax.random.key(3), 3)
    params = dataclasses.replace(base, lane=jnp.array([0.0, -1.0, 1.0]), lane_gap=jnp.array([0.0, 0.2, 0.2]))
    params = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x), (3,)), params)  # every leaf per terrain
    fn = compiled("bars", False, batched=True)
    free = np.asarray(fn(keys, params).free)
    full = np.asarray(gen.bars(keys[0], base, **GRID).free)
    np.testing.assert_array_equal(free[0], full)
    _, sy = _start(base)
    yc = ORIGIN[1] + (np.arange(SHAPE[1]) + 0.5) * RES
    assert (free[1][:, yc > sy - 0.2 + RES]).all() and not free[1][:, yc < sy - 0.2 - RES].all()
    assert (free[2][:, yc < sy + 0.2 - RES]).all() and not free[2][:, yc > sy + 0.2 + RES].all()
    before = traces("bars", False, True)
    fn(keys, dataclasses.replace(params, lane_gap=jnp.array([0.1, 0.3, 0.0])))
    assert traces("bars", False, True) == before
    objs = gen.objects("bars", keys[1], jax.tree.map(lambda x: x[1], params), **GRID)
    x, y, yaw, length = (float(v) for v in objs.boxes[0, :4])
    assert y + 0.5 * length == pytest.approx(sy - 0.2, abs=1e-5) and yaw == pytest.approx(math.pi / 2)


# --------------------------------------------------------------------------- unchanged by the registry split

# Seed 11, each family's defaults (stairs with jitter, rough with an obstacle threshold) on GRID:
# sha256 prefix of the 2D free mask, and the sum and sum of squares of the 2.5D heights, as
# produced by the single-module generators before the split into family/objects/surfaces
# (commit 3272893). The masks must match bit for bit; the height sums are float64 sums of
# float32 heights, equal to the last bit on one machine (a tolerance of 1e-12 relative leaves
# room for summation order only).
BEFORE_SPLIT = [
    ("walls", "3b930ac7f7e43914", 325.0, 325.0),
    ("obstacles", "bb071335034e2cd5", 4.691975601017475, 0.49647539919068684),
    ("bars", "ad72cf357da7c337", 8.00000011920929, 0.40000001192092904),
    ("platforms", "5b689a435626474a", 22.202828086912632, 2.0485290903575395),
    ("stairs", "a52d37851c787af9", 383.71531158685684, 142.38512673756432),
    ("stepping_stones", "c8c6cd0be667283f", -533.0, 266.5),
    ("rough", "16a2c1eb9efd1277", 1.6219200804316642, 0.6781256519344423),
]


@pytest.mark.parametrize("name, free_sha, h_sum, h_sq", BEFORE_SPLIT, ids=[b[0] for b in BEFORE_SPLIT])
def test_same_terrains_as_before_the_split(name, free_sha, h_sum, h_sq):
    p = gen.FAMILIES[name].params()
    if name == "stairs":
        p = p.replace(rise_jitter=0.02, run_jitter=0.05)
    if name == "rough":
        p = p.replace(obstacle_above=0.02)
    free = np.asarray(gen.generate(name, 11, p, has_height=False, **GRID).free)
    assert hashlib.sha256(free.tobytes()).hexdigest()[:16] == free_sha
    h = np.asarray(gen.generate(name, 11, p, has_height=True, **GRID).height, np.float64)
    assert float(h.sum()) == pytest.approx(h_sum, rel=1e-12, abs=1e-12)
    assert float((h * h).sum()) == pytest.approx(h_sq, rel=1e-12, abs=1e-12)
