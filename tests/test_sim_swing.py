"""Tests of ijoy_jax.sim.swing: footprint heights against brute force, swing path properties."""

from __future__ import annotations

import functools

import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings

import ijoy_jax as ij
from ijoy_jax.sim import swing as sw
from ijoy_jax.testing import enable_x64, rect_touches_cells

FOOT_L, FOOT_W = 0.242, 0.13  # HRP-2 footprint (m)
RES = 0.02
# Finite-difference derivative checks in float64 with step 1e-4: O(h^2) ~ 1e-7
# times the path's third derivative (~1e3 for a 0.4 m / 0.05 s quintic corner).
FD_TOL = 1e-5
# Heights are compared as the max of the same float32 cells: exact, but the
# clearance checks add float32 rounding of heights ~1 m.
HEIGHT_TOL = 1e-6


def np_footprint_height(height, origin, pose, hl, hw, off_map=0.0, pad=20):
    """Brute force: max height over every cell a separating-axis test says the rectangle overlaps."""
    hp = np.pad(np.asarray(height, np.float64), pad, constant_values=off_map)
    org = np.asarray(origin, np.float64) - pad * RES
    mask = rect_touches_cells(pose[0], pose[1], pose[2], hl, hw, RES, hp.shape, org)
    return hp[mask].max()


def random_terrain(rng, shape=(40, 30)):
    h = rng.uniform(0.0, 0.2, shape) * (rng.uniform(size=shape) < 0.3)
    origin = rng.uniform(-1, 1, 2)
    return ij.terrain.from_arrays(h.astype(np.float32), resolution=RES, origin=origin)


@pytest.mark.parametrize("margin", [0.0, 0.03])
def test_footprint_height_matches_brute_force(margin):
    rng = np.random.default_rng(int(margin * 100))
    fh = jax.jit(
        jax.vmap(
            functools.partial(sw.footprint_height, foot_length=FOOT_L, foot_width=FOOT_W, margin=margin), (None, 0)
        )
    )
    with enable_x64():
        for _ in range(3):
            t = random_terrain(rng)
            size = np.array(t.shape) * RES
            org = np.asarray(t.origin, np.float64)
            # Poses inside, across the edges and fully outside the map.
            xy = org + rng.uniform(-0.3, 1.0, (40, 2)) * size
            poses = np.concatenate([xy, rng.uniform(-np.pi, np.pi, (40, 1))], 1)
            got = np.asarray(fh(t, jnp.asarray(poses)))
            want = [np_footprint_height(t.height, org, p, FOOT_L / 2 + margin, FOOT_W / 2 + margin) for p in poses]
            np.testing.assert_array_equal(got, np.asarray(want, np.float32))


def test_footprint_height_off_map_and_degenerate():
    t = ij.terrain.from_arrays(np.full((20, 20), -0.1, np.float32), resolution=RES)
    # Half off the map: the off-map floor (0) is higher than the map (-0.1).
    assert float(sw.footprint_height(t, jnp.array([0.0, 0.2, 0.0]), FOOT_L, FOOT_W)) == 0.0
    low = sw.footprint_height(t, jnp.array([0.0, 0.2, 0.0]), FOOT_L, FOOT_W, off_map_height=-1.0)
    assert float(low) == pytest.approx(-0.1)
    assert float(sw.footprint_height(t, jnp.array([0.2, 0.2, 0.3]), FOOT_L, FOOT_W)) == pytest.approx(-0.1)
    # Tiny foot: still the cell under its centre, never -inf.
    assert float(sw.footprint_height(t, jnp.array([0.2, 0.2, 0.0]), 1e-6, 1e-6)) == pytest.approx(-0.1)
    with pytest.raises(ValueError, match="positive"):
        sw.footprint_height(t, jnp.zeros(3), 0.0, FOOT_W)
    with pytest.raises(ValueError, match="max_radius"):
        jax.jit(lambda fl: sw.footprint_height(t, jnp.zeros(3), fl, FOOT_W))(FOOT_L)
    # Traced sizes with a static window are fine (a Robot's array leaves).
    f = jax.jit(lambda fl: sw.footprint_height(t, jnp.array([0.2, 0.2, 0.3]), fl, FOOT_W, max_radius=0.15))
    assert float(f(FOOT_L)) == pytest.approx(-0.1)
    with pytest.raises(ValueError, match="samples"):
        sw.corridor_height(t, jnp.zeros(3), jnp.ones(3), FOOT_L, FOOT_W, samples=1)


def test_corridor_height_sees_obstacle_between():
    h = np.zeros((60, 40), np.float32)
    h[30:32, :] = 0.12  # a 4 cm wide, 12 cm high bar at x = 0.60 .. 0.64 m
    t = ij.terrain.from_arrays(h, resolution=RES)
    start, end = jnp.array([0.35, 0.4, 0.0]), jnp.array([0.9, 0.4, 0.3])
    assert float(sw.footprint_height(t, start, FOOT_L, FOOT_W)) == 0.0
    assert float(sw.footprint_height(t, end, FOOT_L, FOOT_W)) == 0.0
    assert float(sw.corridor_height(t, start, end, FOOT_L, FOOT_W)) == pytest.approx(0.12)
    apex = sw.swing_apex(t, jnp.array([0.35, 0.4, 0.0, 0.0]), jnp.array([0.9, 0.4, 0.0, 0.3]), FOOT_L, FOOT_W, 0.05)
    assert float(apex) == pytest.approx(0.17)
    # the profile: the footprint's height at each of the evenly spaced poses (yaw the short way round)
    prof = np.asarray(sw.corridor_profile(t, start, end, FOOT_L, FOOT_W, samples=12))
    u = np.linspace(0.0, 1.0, 12)
    want = [float(sw.footprint_height(t, (1 - ui) * start + ui * end, FOOT_L, FOOT_W)) for ui in u]
    np.testing.assert_array_equal(prof, want)
    assert prof[0] == 0.0 and prof[-1] == 0.0 and prof.max() == pytest.approx(0.12)


def path(start, end, apex, s, lift=0.25):
    pos, yaw = sw.swing_pose(start, end, apex, s, lift=lift)
    return jnp.concatenate([pos, yaw[None]])


def test_swing_endpoints_and_smoothness():
    start = jnp.array([0.1, -0.2, 0.02, 3.0])
    end = jnp.array([0.4, -0.1, 0.07, -2.9])  # yaw across +-pi: the short way round
    apex = 0.15
    f = jax.jit(path)
    np.testing.assert_array_equal(f(start, end, apex, 0.0), start)
    p1 = np.asarray(f(start, end, apex, 1.0))
    np.testing.assert_array_equal(p1[:3], end[:3])
    assert np.isclose(np.mod(p1[3] - end[3] + np.pi, 2 * np.pi) - np.pi, 0.0, atol=1e-6)
    np.testing.assert_array_equal(f(start, end, apex, -0.3), start)
    np.testing.assert_array_equal(f(start, end, apex, 1.4), f(start, end, apex, 1.0))
    # Velocity (jvp) and acceleration (second jvp) vanish at the ends and at the corners.
    vel = jax.jit(lambda s: jax.jvp(lambda si: path(start, end, apex, si), (s,), (1.0,))[1])
    acc = jax.jit(lambda s: jax.jvp(vel, (s,), (1.0,))[1])
    for s in (0.0, 0.25, 0.75, 1.0):
        np.testing.assert_allclose(vel(jnp.float32(s)), 0.0, atol=1e-5)
        np.testing.assert_allclose(acc(jnp.float32(s)), 0.0, atol=1e-3)
    pos_v, yaw_v = sw.swing_velocity(start, end, apex, 0.5)
    np.testing.assert_allclose(jnp.concatenate([pos_v, yaw_v[None]]), vel(jnp.float32(0.5)), rtol=1e-6)
    # Continuity of velocity and acceleration through the whole phase (float64 finite differences).
    with enable_x64():
        s = jnp.linspace(0.0, 1.0, 2001)
        x = jax.vmap(lambda si: path(start, end, apex, si))(s)
        v = jax.vmap(vel)(s)
        fd = (x[2:] - x[:-2]) / (2 * (s[1] - s[0]))
        np.testing.assert_allclose(fd, v[1:-1], atol=FD_TOL * 100)
        a = jax.vmap(acc)(s)
        assert np.max(np.abs(np.diff(a, axis=0))) < 0.5  # no jumps in acceleration (peaks ~60 per unit s^2)


def test_swing_degenerate_inputs_no_nan():
    f = jax.jit(jax.vmap(path, (None, None, None, 0)))
    s = jnp.array([-1.0, 0.0, 0.2, 0.5, 1.0, 2.0, jnp.inf, -jnp.inf])
    p = jnp.array([0.3, 0.1, 0.0, 1.0])
    for apex in (0.0, -1.0, 0.1):
        out = f(p, p, apex, s)
        assert np.all(np.isfinite(out))
    out = jax.jit(jax.vmap(lambda si: path(p, p, 0.1, si, lift=0.5)))(s)
    assert np.all(np.isfinite(out))
    g = jax.grad(lambda si: jnp.sum(path(p, p + 0.1, 0.1, si)))(jnp.float32(0.3))
    assert np.isfinite(g)
    gv = jax.vmap(jax.grad(lambda si: jnp.sum(path(p, p, 0.1, si, lift=0.5))))(jnp.array([0.0, 0.5, 1.0]))
    assert np.all(np.isfinite(gv))
    with pytest.raises(ValueError, match="lift"):
        sw.swing_pose(p, p, 0.1, 0.5, lift=0.0)
    # Apex below both ends is raised to the higher end: never dips below the ends.
    z = f(p, p.at[2].set(0.05), -1.0, jnp.linspace(0, 1, 8))[:, 2]
    assert np.all(z >= -1e-7) and np.all(np.diff(z) >= -1e-7)



def test_constant_profile_is_the_one_apex_path():
    start = jnp.array([0.1, -0.2, 0.02, 0.3])
    end = jnp.array([0.5, -0.1, 0.07, 0.1])
    f = jax.jit(jax.vmap(path, (None, None, None, 0, None)))
    s = jnp.linspace(-0.1, 1.1, 121)
    for apex, lift in ((0.15, 0.25), (0.07, 0.2), (0.3, 0.5)):  # at or above both soles
        one = f(start, end, apex, s, lift)
        for n in (2, 16):
            np.testing.assert_allclose(f(start, end, jnp.full(n, apex), s, lift), one, atol=1e-6)
    with pytest.raises(ValueError, match="profile"):
        sw.swing_pose(start, end, jnp.zeros(1), 0.5)
    with pytest.raises(ValueError, match="profile"):
        sw.swing_pose(start, end, jnp.zeros((2, 3)), 0.5)


def _progress(s, lift):
    """The horizontal progress u(s) of swing_pose (its closed form, float64)."""
    return np.asarray(sw.smoothstep(np.clip((np.asarray(s, np.float64) - lift) / (1 - 2 * lift), 0, 1)))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-0.2, 0.35, allow_subnormal=False), min_size=2, max_size=20),
       st.floats(-0.1, 0.1, allow_subnormal=False), st.floats(-0.1, 0.1, allow_subnormal=False), st.floats(0.05, 0.45))
def test_staged_path_stays_above_the_profile_between_its_points(need, z0, z1, lift):
    """Between the profile's points i and i + 1 the sole is at least as high as both ask; it never rises
    above the highest level (profile and ends); it starts and ends exactly at the soles, at rest."""
    need = np.asarray(need, np.float64)
    n = len(need)
    with enable_x64():
        start = jnp.array([0.0, 0.0, z0, 0.0], jnp.float64)
        end = jnp.array([0.6, 0.1, z1, 0.2], jnp.float64)
        s = jnp.linspace(0.0, 1.0, 4001)
        z = np.asarray(jax.vmap(lambda si: sw.swing_pose(start, end, jnp.asarray(need), si, lift=lift)[0][2])(s))
        vel = jax.vmap(lambda si: sw.swing_velocity(start, end, jnp.asarray(need), si, lift=lift)[0][2])(
            jnp.array([0.0, 1.0]))
    u = _progress(np.asarray(s), lift) * (n - 1)  # in units of the profile's spacing
    below = np.floor(u).astype(int)
    ask = np.maximum(need[np.clip(below, 0, n - 1)], need[np.clip(below + 1, 0, n - 1)])
    moving = (u > 0) & (u < n - 1)
    assert np.all(z[moving] >= ask[moving] - 1e-9)
    assert np.all(z <= max(need.max(), z0, z1) + 1e-9)
    assert z[0] == z0 and z[-1] == z1
    np.testing.assert_allclose(vel, 0.0, atol=1e-9)


def test_staged_path_climbs_a_stair_in_two_stages():
    """A foot lifted from a lower tread over the stance tread onto the next one (two 10 cm risers, 5 cm
    clearance): it clears the first riser, and gains the second while it moves forward; the one-apex path
    rises both before it moves."""
    n = 16
    u = np.linspace(0.0, 1.0, n)
    terrain = np.where(u < 0.05, 0.0, np.where(u < 0.55, 0.1, 0.2))  # the footprint's highest cell along the path
    need = jnp.asarray(terrain + 0.05, jnp.float32)
    start = jnp.array([0.0, 0.0, 0.0, 0.0])
    end = jnp.array([0.6, 0.0, 0.2, 0.0])
    lift = 0.2
    z_at = lambda apex, s: float(sw.swing_pose(start, end, apex, s, lift=lift)[0][2])  # noqa: E731
    assert z_at(need, lift) == pytest.approx(0.15, abs=1e-6)  # the transfer starts one riser up
    assert z_at(jnp.max(need), lift) == pytest.approx(0.25, abs=1e-6)
    # the second riser is cleared by the time the foot reaches the point before the first that asks for it
    grid = np.linspace(0.0, 1.0, 20001)
    s_there = grid[np.argmax(_progress(grid, lift) >= 8 / 15)]
    assert z_at(need, s_there) >= 0.25 - 1e-6
    assert z_at(need, 0.5 * (lift + s_there)) < 0.25 - 0.01  # and not long before


_TERRAIN = ij.terrain.from_arrays(
    (
        np.random.default_rng(7).uniform(0, 0.15, (40, 40)) * (np.random.default_rng(8).uniform(size=(40, 40)) < 0.2)
    ).astype(np.float32),
    resolution=RES,
)
SAMPLES = 16
R_FOOT = float(np.hypot(FOOT_L / 2, FOOT_W / 2))


@functools.partial(jax.jit, static_argnums=(3,))
def _clearance_case(start, end, clearance, margin):
    """Apex, and along 101 phases: sole height, terrain under the foot, transfer flag."""
    apex = sw.swing_apex(_TERRAIN, start, end, FOOT_L, FOOT_W, clearance, SAMPLES, margin)

    def at(s):
        pos, yaw = sw.swing_pose(start, end, apex, s)
        under = sw.footprint_height(_TERRAIN, jnp.array([pos[0], pos[1], yaw]), FOOT_L, FOOT_W)
        return pos[2], under

    s = jnp.linspace(0.0, 1.0, 101)
    z, under = jax.vmap(at)(s)
    return apex, z, under, (s >= 0.25) & (s <= 0.75)


@settings(max_examples=25)
@given(
    xy0=st.tuples(st.floats(0.2, 0.6), st.floats(0.2, 0.6)),
    d=st.tuples(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2)),
    yaw0=st.floats(-np.pi, np.pi),
    dyaw=st.floats(-0.6, 0.6),
    clearance=st.floats(0.0, 0.1),
)
def test_swing_clears_swept_terrain(xy0, d, yaw0, dyaw, clearance):
    """During the transfer the sole is at the apex >= corridor + clearance, above every footprint it passes.

    The corridor uses the margin of corridor_height's sampling bound, a static
    0.03 m here: (|d| + R |dyaw|) / (2 * 15) <= (0.283 + 0.138 * 0.6) / 30 = 0.0122 m.
    """
    start_xy = np.array(xy0)
    end_xy = start_xy + np.array(d)
    sz = float(sw.footprint_height(_TERRAIN, jnp.array([*start_xy, yaw0]), FOOT_L, FOOT_W))
    ez = float(sw.footprint_height(_TERRAIN, jnp.array([*end_xy, yaw0 + dyaw]), FOOT_L, FOOT_W))
    start = jnp.array([*start_xy, sz, yaw0], jnp.float32)
    end = jnp.array([*end_xy, ez, yaw0 + dyaw], jnp.float32)
    apex, z, under, transfer = (np.asarray(a) for a in _clearance_case(start, end, jnp.float32(clearance), 0.03))
    corridor = float(
        sw.corridor_height(_TERRAIN, start[jnp.array([0, 1, 3])], end[jnp.array([0, 1, 3])], FOOT_L, FOOT_W, SAMPLES)
    )
    assert apex >= corridor + clearance - HEIGHT_TOL
    assert np.all(z[transfer] >= apex - HEIGHT_TOL)
    # Every footprint the foot passes during the transfer is clear by the clearance...
    assert np.all(z[transfer] - under[transfer] >= clearance - HEIGHT_TOL)
    # ... and outside it the foot is over its own start or end footprint, never below it.
    assert np.all(z - under >= -HEIGHT_TOL)


def test_jit_vmap_batch_and_no_recompile():
    traces = []

    def f(start, end, s):
        traces.append(1)
        apex = sw.swing_apex(_TERRAIN, start, end, FOOT_L, FOOT_W, 0.05)
        return sw.swing_pose(start, end, apex, s)

    bf = jax.jit(jax.vmap(f))
    rng = np.random.default_rng(3)
    for _ in range(2):
        starts = jnp.asarray(np.c_[rng.uniform(0.2, 0.6, (5, 2)), np.zeros(5), rng.uniform(-3, 3, 5)], jnp.float32)
        ends = starts + jnp.asarray(rng.uniform(-0.2, 0.2, (5, 4)), jnp.float32)
        pos, yaw = bf(starts, ends, jnp.asarray(rng.uniform(0, 1, 5), jnp.float32))
        assert pos.shape == (5, 3) and yaw.shape == (5,)
    assert len(traces) == 1


# ----------------------------------------------------------------------------------------------------------------
# A tilted sole resting on the ground


def _plane_terrain(b, c, h0=0.1, shape=(60, 50), origin=(-0.6, -0.5)):
    """The plane z = h0 + b x + c y sampled at the cell centres of a map."""
    x = origin[0] + (np.arange(shape[0]) + 0.5) * RES
    y = origin[1] + (np.arange(shape[1]) + 0.5) * RES
    h = h0 + b * x[:, None] + c * y[None, :]
    return ij.terrain.from_arrays(h.astype(np.float32), resolution=RES, origin=origin).replace(has_height=True)


@settings(max_examples=20, deadline=None)
@given(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2), st.floats(-np.pi, np.pi), st.floats(-0.1, 0.1), st.floats(-0.1, 0.1))
def test_sole_parallel_to_a_plane_rests_at_the_planes_height(b, c, yaw, x, y):
    """Closed form: a sole turned to the plane's own tilt rests with its centre on the plane (every cell of the
    footprint then lies exactly on the sole's plane), and sole_plane_gradient gives back (b, c)."""
    t = _plane_terrain(b, c)
    gf, gl = b * np.cos(yaw) + c * np.sin(yaw), -b * np.sin(yaw) + c * np.cos(yaw)
    pitch, roll = -np.arctan(gf), np.arctan2(gl, np.sqrt(1 + gf * gf))
    np.testing.assert_allclose(sw.sole_plane_gradient(jnp.float32(roll), jnp.float32(pitch), jnp.float32(yaw)),
                               [b, c], atol=1e-5)
    z = sw.resting_height(t, jnp.array([x, y, 0.0, roll, pitch, yaw], jnp.float32), FOOT_L, FOOT_W)
    np.testing.assert_allclose(z, 0.1 + b * x + c * y, atol=1e-5)  # float32 heights ~0.1 m


def test_resting_height_matches_brute_force_on_rough_ground():
    """Brute force: the largest height above the sole's plane over every cell the rectangle overlaps."""
    rng = np.random.default_rng(3)
    with enable_x64():
        for _ in range(20):
            t = random_terrain(rng)
            org = np.asarray(t.origin, np.float64)
            foothold = np.concatenate([org + rng.uniform(0.3, 0.5, 2), [0.0], rng.uniform(-0.25, 0.25, 2),
                                       rng.uniform(-np.pi, np.pi, 1)])
            g = np.asarray(sw.sole_plane_gradient(*(jnp.float64(v) for v in foothold[3:6])))
            hp = np.asarray(t.height, np.float64)
            mask = rect_touches_cells(foothold[0], foothold[1], foothold[5], FOOT_L / 2, FOOT_W / 2, RES, hp.shape, org)
            ix, iy = np.nonzero(mask)
            cx, cy = org[0] + (ix + 0.5) * RES, org[1] + (iy + 0.5) * RES
            want = np.max(hp[ix, iy] - g[0] * (cx - foothold[0]) - g[1] * (cy - foothold[1]))
            got = float(sw.resting_height(t, jnp.asarray(foothold), FOOT_L, FOOT_W))
            np.testing.assert_allclose(got, want, atol=1e-6)  # float32 heights and cell offsets


def test_level_sole_rests_on_the_highest_cell():
    t = random_terrain(np.random.default_rng(4))
    pose = jnp.asarray(np.asarray(t.origin) + 0.4)
    foothold = jnp.array([pose[0], pose[1], 0.0, 0.0, 0.0, 0.3])
    assert float(sw.resting_height(t, foothold, FOOT_L, FOOT_W)) == float(
        sw.footprint_height(t, jnp.array([pose[0], pose[1], 0.3]), FOOT_L, FOOT_W))
    assert np.isnan(float(sw.resting_height(t, foothold.at[3].set(jnp.nan), FOOT_L, FOOT_W)))


def test_surface_height_is_the_bilinear_surface_through_the_cell_centres():
    """Independent reference: SciPy's linear interpolation on the grid of cell centres (edge values beyond the
    outer centres); off the map, off_map_height."""
    from scipy.interpolate import RegularGridInterpolator

    rng = np.random.default_rng(5)
    t = random_terrain(rng)
    org = np.asarray(t.origin, np.float64)
    nx, ny = t.shape
    xc, yc = org[0] + (np.arange(nx) + 0.5) * RES, org[1] + (np.arange(ny) + 0.5) * RES
    ref = RegularGridInterpolator((xc, yc), np.asarray(t.height, np.float64))
    xy = org + rng.uniform(0.0, 1.0, (200, 2)) * np.array([nx, ny]) * RES
    want = ref(np.clip(xy, [xc[0], yc[0]], [xc[-1], yc[-1]]))
    got = np.asarray(sw.surface_height(t, jnp.asarray(xy, jnp.float32)))
    np.testing.assert_allclose(got, want, atol=1e-5)  # float32 weights of heights up to 0.2 m
    off = np.asarray(sw.surface_height(t, jnp.asarray(org[None] - 0.5, jnp.float32), off_map_height=-0.3))
    np.testing.assert_allclose(off, [-0.3])


def test_resting_height_on_contact_points():
    """On a plane with the sole turned to its tilt every point touches at once: the plane's height at the centre.
    On rough ground: the largest surface height above the sole's plane over the points (brute force)."""
    pts = np.array([[0.11, 0.05], [0.11, -0.05], [-0.11, 0.05], [-0.11, -0.05], [0.0, 0.05], [0.0, -0.05]])
    b, c, yaw = 0.12, -0.08, 0.4
    t = _plane_terrain(b, c)
    gf, gl = b * np.cos(yaw) + c * np.sin(yaw), -b * np.sin(yaw) + c * np.cos(yaw)
    pitch, roll = -np.arctan(gf), np.arctan2(gl, np.sqrt(1 + gf * gf))
    fh = jnp.array([0.05, -0.02, 0.0, roll, pitch, yaw], jnp.float32)
    np.testing.assert_allclose(sw.resting_height(t, fh, FOOT_L, FOOT_W, points=pts), 0.1 + b * 0.05 - c * 0.02,
                               atol=1e-5)
    rough = random_terrain(np.random.default_rng(6))
    fh = jnp.asarray(np.concatenate([np.asarray(rough.origin) + 0.4, [0.0, 0.1, -0.05, 1.0]]), jnp.float32)
    g = np.asarray(sw.sole_plane_gradient(fh[3], fh[4], fh[5]))
    cs, sn = np.cos(1.0), np.sin(1.0)
    d = np.stack([cs * pts[:, 0] - sn * pts[:, 1], sn * pts[:, 0] + cs * pts[:, 1]], 1)
    h = np.asarray(sw.surface_height(rough, jnp.asarray(np.asarray(fh[:2]) + d, jnp.float32)))
    np.testing.assert_allclose(sw.resting_height(rough, fh, FOOT_L, FOOT_W, points=pts), np.max(h - d @ g),
                               atol=1e-6)
