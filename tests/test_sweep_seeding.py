"""ijoy_jax.sweep.seeding (NumPy's per-replicate generators, vectorised) and the plan built with it: bit for bit
what one ``np.random.default_rng`` per replicate gives, and a sweep's cells and scenarios equal to the
definition written out the slow way (itertools.product, one generator per replicate, scalar draws).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import sweep
from ijoy_jax.sweep import seeding

RANGES = [(0.1, 0.3), (-0.05, 0.05), (0.0, 0.0), (-2.5, 1e-3)]


@pytest.mark.parametrize("entropy", [[0, 2], [3, 2], [2**32 - 1, 2], [2**40 + 3, 2], [2**100 + 5, 2], [7]],
                         ids=["seed0", "seed3", "seed2^32-1", "seed2^40", "seed2^100", "one-word"])
def test_uniform_draws_equal_one_numpy_generator_per_replicate(entropy):
    """Entropy of 2 to 6 uint32 words (a seed beyond 2**96 is longer than SeedSequence's 4-word pool)."""
    n = 1500
    got = seeding.uniform_draws(entropy, RANGES, n)
    want = seeding.reference_draws(entropy, RANGES, range(n))
    assert got.shape == (n, len(RANGES))
    np.testing.assert_array_equal(got, want)  # bit for bit, also the signs of zeros
    np.testing.assert_array_equal(np.signbit(got), np.signbit(want))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**128), reps=st.lists(st.integers(0, 2**32 - 1), min_size=1, max_size=20),
       k=st.integers(1, 5))
def test_first_doubles_of_any_replicate_equal_pcg64s(seed, reps, k):
    """The vectorised SeedSequence -> PCG64 -> next_double at replicates over all of uint32 (uniform_draws only
    reaches its first num_reps; the same function serves every row)."""
    got = seeding.first_doubles([seed, 2], reps, k)
    for row, r in zip(got, reps, strict=True):
        rng = np.random.default_rng([seed, 2, r])
        np.testing.assert_array_equal(row, rng.random(k))


def test_a_numpy_that_draws_differently_falls_back_to_its_own_generators(monkeypatch):
    """Where the vectorised draws differ from NumPy's on a checked replicate (a changed NumPy, a fused
    multiply-add), every replicate is drawn by NumPy itself, with a warning: the plan stays NumPy's."""
    true = seeding.first_doubles

    def off_by_one_ulp(entropy, reps, count):
        out = true(entropy, reps, count)
        out[-1, 0] = np.nextafter(out[-1, 0], 2.0)  # the last replicate, which is always checked
        return out

    monkeypatch.setattr(seeding, "first_doubles", off_by_one_ulp)
    done = []
    with pytest.warns(RuntimeWarning, match="differ from NumPy's own"):
        got = seeding.uniform_draws([5, 2], RANGES, 40, on_replicate=done.append)
    np.testing.assert_array_equal(got, seeding.reference_draws([5, 2], RANGES, range(40)))
    assert done == list(range(40))


@pytest.mark.parametrize("bad", [-1, 2**32])
def test_uniform_draws_refuses_replicate_counts_beyond_uint32(bad):
    with pytest.raises(ValueError, match="num_reps"):
        seeding.uniform_draws([0, 2], RANGES, bad)


def test_no_replicates_is_an_empty_table():
    assert seeding.uniform_draws([0, 2], RANGES, 0).shape == (0, len(RANGES))


# --------------------------------------------------------------------------- a sweep's plan, the slow way


def _reference_cells(cfg):
    """cells() as the definition: itertools.product of the grid (first key slowest), each grid cell crossed with
    every random draw, the draws one scalar ``uniform`` after another from ``default_rng([seed, 1])``."""
    keys = list(cfg.grid)
    rows = [dict(zip(keys, c, strict=True)) for c in itertools.product(*(cfg.grid[k] for k in keys))]
    if cfg.random:
        rng = np.random.default_rng([cfg.seed, 1])
        draws = [{k: float(rng.uniform(lo, hi)) for k, (lo, hi) in cfg.random.items()}
                 for _ in range(cfg.random_samples)]
        rows = [{**r, **d} for r in rows for d in draws]
    return rows


PLANS = [
    '[sweep]\nscenarios_per_cell = 7\nseed = 11\n[command]\nvx = [0.1, 0.3]\nvy = [-0.05, 0.05]\nwz = [-0.4, 0.4]\n'
    '[grid]\n"robot.w" = [0.5, 2]\n"robot.density" = [0.5, 1.0]\n"terrain.count" = [3, 5, 8]\n',
    '[sweep]\nscenarios_per_cell = 4\nrandom_samples = 3\nseed = 12345678901\n[command]\nvx = [0.0, 0.25]\n'
    '[grid]\n"robot.margin" = [0.0, 0.05]\n[random]\n"robot.w" = [0.0, 4.0]\n"terrain.size_max" = [0.1, 0.2]\n',
    '[sweep]\nscenarios_per_cell = 5\n[command]\nvx = 0.2\nwz = -0.0\n',
]


@pytest.mark.parametrize("text", PLANS, ids=["grid", "grid-and-random", "fixed-command"])
@pytest.mark.parametrize("max_scenarios", [None, 1, 6, 13])
def test_scenarios_equal_the_definition_built_slowly(text, max_scenarios):
    cfg = sweep.parse_config(text)
    c = sweep.cells(cfg)
    ref = _reference_cells(cfg)
    assert c["cell"].tolist() == list(range(len(ref)))
    for k in (*cfg.grid, *cfg.random):
        np.testing.assert_array_equal(c[k].to_numpy(), [r[k] for r in ref])
    s = sweep.scenarios(cfg, max_scenarios)
    n = cfg.num_scenarios if max_scenarios is None else min(max_scenarios, cfg.num_scenarios)
    assert len(s) == n and s["scenario"].tolist() == list(range(n))
    per = cfg.scenarios_per_cell
    np.testing.assert_array_equal(s["cell"], np.arange(n) // per)
    np.testing.assert_array_equal(s["replicate"], np.arange(n) % per)
    for i in range(n):
        cell = ref[i // per]
        rng = np.random.default_rng([cfg.seed, 2, i % per])
        want = [rng.uniform(*cfg.command[k]) for k in sweep.COMMAND_KEYS]
        got = [s[f"command.{k}"].iat[i] for k in sweep.COMMAND_KEYS]
        assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))
        for k, v in cell.items():
            assert s[k].iat[i] == v, (i, k)
    for name, default in sweep.ROBOT_DEFAULTS.items():
        if f"robot.{name}" not in c:
            assert (s[f"robot.{name}"] == cfg.robot.get(name, default)).all(), name
    assert list(s.columns[:3]) == ["scenario", "cell", "replicate"]
    assert s["terrain.count"].dtype == np.int64 and s["robot.w"].dtype == np.float64
