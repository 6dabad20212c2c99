"""The constrained-passage families (ijoy_jax.terrain.passages): corridor and stone path against NumPy float64
evaluations of their definitions, pockets and jittered gaps within their parameters.

The registry-wide properties (jit, vmap, no recompile, determinism, start zone) run for these families in
tests/test_generators.py and tests/test_family.py like for every other.
"""

import jax
import numpy as np
import pytest

from ijoy_jax.terrain import generators as gen

SHAPE = (120, 60)
RES = 0.02


def _frame(p, shape=SHAPE, res=RES):
    """Path-frame (u, v) of every cell centre, float64."""
    x = (np.arange(shape[0]) + 0.5) * res
    y = (np.arange(shape[1]) + 0.5) * res
    sx, sy = p.start_x * shape[0] * res, p.start_y * shape[1] * res
    dx, dy = x[:, None] - sx, y[None, :] - sy
    c, s = np.cos(p.direction), np.sin(p.direction)
    return c * dx + s * dy, -s * dx + c * dy


@pytest.mark.parametrize("closed, direction", [(1.0, 0.0), (0.0, 0.3)])
def test_corridor_without_pockets_is_its_definition(closed, direction):
    p = gen.CorridorParams(count=0, length=1.5, width_start=0.7, width_end=0.4, closed=closed, direction=direction,
                           start_x=0.2)
    t = jax.jit(lambda k: gen.corridor(k, p, shape=SHAPE, resolution=RES, has_height=True))(jax.random.key(0))
    u, v = _frame(p)
    half = 0.5 * (0.7 + np.clip(u / 1.5, 0, 1) * (0.4 - 0.7))
    want = ((u >= -p.behind) & (u <= 1.5) & (np.abs(v) <= half)) | ((u > 1.5) & (closed < 0.5))
    # Cells within float32 rounding of an edge may fall either way.
    edge = (np.abs(np.abs(v) - half) < 1e-5) | (np.abs(u - 1.5) < 1e-5) | (np.abs(u + p.behind) < 1e-5)
    np.testing.assert_array_equal(np.asarray(t.free)[~edge], want[~edge])
    np.testing.assert_array_equal(np.asarray(t.height), np.where(np.asarray(t.free), 0.0, p.top))


def test_corridor_pockets_are_recesses_of_their_size_in_one_wall():
    base = gen.CorridorParams(count=0, length=1.8, width_start=0.6, width_end=0.6, start_x=0.15)
    p = base.replace(count=1, pocket_width=0.3, pocket_depth=0.2)
    for seed in range(4):
        plain = np.asarray(gen.corridor(seed, base, shape=SHAPE, resolution=RES).free)
        with_pocket = np.asarray(gen.corridor(seed, p, shape=SHAPE, resolution=RES).free)
        assert not (plain & ~with_pocket).any()  # a pocket only adds free cells
        extra = with_pocket & ~plain
        u, v = _frame(p)
        assert np.all(np.abs(v[extra]) > 0.3) and np.all(np.abs(v[extra]) <= 0.3 + 0.2 + 1e-5)
        assert len(np.unique(np.sign(v[extra]))) == 1  # one wall
        assert u[extra].max() - u[extra].min() <= 0.3 + 1e-5
        # 0.3 m x 0.2 m of 2 cm cells, give or take a row and a column at the edges.
        assert 14 * 9 <= extra.sum() <= 16 * 11


def _stones_reference(p, shape=SHAPE, res=RES):
    """2D free cells of a jitter-free stone path, float64: cells whose four corners lie on a stone, and the pad."""
    sx, sy = p.start_x * shape[0] * res, p.start_y * shape[1] * res
    x0 = np.arange(shape[0])[:, None] * res - sx
    y0 = np.arange(shape[1])[None, :] * res - sy
    free = np.zeros(shape, bool)
    for first, mid in ((p.first, 0.5 * p.row_gap), (p.first + p.stagger, -0.5 * p.row_gap)):
        for k in range(int(shape[0] * res / p.pitch) + 2):
            c = first + k * p.pitch
            on = np.ones(shape, bool)
            for ox in (0.0, res):
                for oy in (0.0, res):
                    on &= (np.abs(x0 + ox - c) <= p.size / 2 + 1e-9) & (np.abs(y0 + oy - mid) <= p.width / 2 + 1e-9)
            free |= on
    cx, cy = x0 + res / 2, y0 + res / 2
    return free | (np.hypot(cx, cy) <= p.start_radius)


def test_stone_path_without_jitter_is_its_definition():
    p = gen.StonePathParams(pitch_jitter=0.0, size=0.32, width=0.2, start_x=0.1, first=0.3, stagger=0.18)
    t = gen.stone_path(0, p, shape=SHAPE, resolution=RES)
    np.testing.assert_array_equal(np.asarray(t.free), _stones_reference(p))
    h = gen.stone_path(0, p.replace(top=0.1), shape=SHAPE, resolution=RES, has_height=True)
    free2d = np.asarray(t.free)
    np.testing.assert_allclose(np.asarray(h.height)[free2d], 0.1, atol=1e-6)
    np.testing.assert_allclose(np.asarray(h.height)[~free2d], p.gap_height, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stone_path_gaps_vary_within_the_jitter_and_stones_never_touch(seed):
    size, pitch, jitter = 0.3, 0.4, 0.04
    p = gen.StonePathParams(size=size, pitch=pitch, pitch_jitter=jitter, start_x=0.05, start_radius=0.0)
    free = np.asarray(gen.stone_path(seed, p, shape=(200, 60), resolution=RES).free)
    gaps = []
    for lateral in (0.5, -0.5):
        row = free[:, int(round((p.start_y * 60 * RES + lateral * p.row_gap) / RES))]
        edges = np.flatnonzero(np.diff(row.astype(int)))
        runs = np.diff(edges)[::2] if row[0] == 0 else np.diff(edges)[1::2]
        stones = runs[:-1] * RES  # the last may be cut by the map's edge
        assert np.all(np.abs(stones - size) <= RES + 1e-9)  # whole cells lying on a 0.3 m stone
        gaps += list(np.diff(edges)[1::2 if row[0] == 0 else 2][:-1] * RES)
    gaps = np.asarray(gaps)
    lo, hi = pitch - size - 2 * min(jitter, (pitch - size) / 2), pitch - size + 2 * jitter
    assert np.all(gaps >= lo - RES - 1e-9) and np.all(gaps <= hi + RES + 1e-9) and np.all(gaps > 0)
    assert np.ptp(gaps) > RES  # jittered: the gaps are not all alike
