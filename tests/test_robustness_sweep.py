"""Hostile sweep files (issue #22): every key of the TOML schema set to NaN, inf, huge, tiny, negative, empty, the
wrong type or the wrong shape.

Each case is one of two outcomes, decided before any compute: a :class:`~ijoy_jax.sweep.SweepConfigError` that
reads ``<file>: <key>: <reason>`` and names the key that was set (never another exception from deep inside:
an OverflowError, a MemoryError, a TypeError of NumPy's); or a config whose every number is finite in float32
and within the documented bounds, from which the scenario table builds.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import robots, sweep
from ijoy_jax.sweep import config as sweep_config
from ijoy_jax.terrain import generators

F32_MAX = float(np.finfo(np.float32).max)

# TOML literals a careless or hostile user writes: non-finite, huge, tiny, negative, zero, beyond 64 bits,
# empty, of the wrong type (string, bool, date, time, table) and of the wrong shape (lists where numbers belong,
# numbers where lists belong, nested and mixed lists).
LITERALS = ["nan", "inf", "-inf", "+inf", "1e308", "-1e308", "1e39", "3.5e38", "1e-300", "-1e-300", "-1", "-0.0",
            "0", "0.0", "1", "0.5", "2", "9223372036854775807", "-9223372036854775808", "9223372036854775808",
            "123456789012345678901234567890", "-99999999999999999999999", '""', '"abc"', '"1.0"', "true", "false",
            "1979-05-27", "07:32:00", "1979-05-27T07:32:00Z", "[]", "[1]", "[1, 2, 3]", "[[1, 2]]", "[0.1, nan]",
            "[nan, 0.1]", "[0.1, inf]", "[-1e308, 1e308]", "[1e308, 1e308]", "[1, 1e30]", "[0.3, 0.1]",
            "[1, 1]", '["a", "b"]', "[true, false]", "[0.01, 0.02]", "[3, 5]", "{}", "{a = 1}", "[{}, {}]"]


def _float_literal(x: float) -> str:
    return "nan" if math.isnan(x) else ("inf" if x == math.inf else "-inf" if x == -math.inf else repr(x))


literal = (st.sampled_from(LITERALS)
           | st.floats(allow_nan=True, allow_infinity=True).map(_float_literal)
           | st.integers(-(2**80), 2**80).map(str)
           | st.lists(st.floats(allow_nan=True, allow_infinity=True).map(_float_literal), max_size=3)
             .map(lambda xs: "[" + ", ".join(xs) + "]")
           | st.text(max_size=5).map(lambda s: '"' + s.encode("unicode_escape").decode().replace('"', '\\"') + '"'))

FAMILY = generators.FAMILIES["obstacles"]
TERRAIN_FIELDS = [f.name for f in dataclasses.fields(FAMILY.params)]
PARAMS = [f"robot.{k}" for k in sweep.ROBOT_DEFAULTS] + [f"terrain.{k}" for k in TERRAIN_FIELDS]

# (TOML text before the key, the key as written, the key the error must name)
MJX = '[sweep]\nwalker = "mjx"\n'
SIM = ("friction", "mass_scale", "kp_scale", "latency", "stance_noise", "push")
KEYS = ([("[sweep]\n", k, f"sweep.{k}") for k in ("name", "description", "seed", "scenarios_per_cell", "num_steps",
                                                  "method", "kernel", "random_samples", "walker")]
        + [("[terrain]\n", k, f"terrain.{k}") for k in ("family", "shape", "resolution", "has_height", "max_count")]
        + [("[terrain.params]\n", k, f"terrain.params.{k}") for k in TERRAIN_FIELDS]
        + [("[robot]\n", k, f"robot.{k}") for k in sweep.ROBOT_DEFAULTS]
        + [("[command]\n", k, f"command.{k}") for k in sweep.COMMAND_KEYS]
        + [("[grid]\n", f'"{p}"', f"grid.{p}") for p in PARAMS]
        + [("[sweep]\nrandom_samples = 2\n[random]\n", f'"{p}"', f"random.{p}") for p in PARAMS]
        # the physics of a walker = "mjx" sweep: [sim] values and ranges, grid axes, random ranges
        + [(f"{MJX}[sim]\n", k, f"sim.{k}") for k in SIM]
        + [(f"{MJX}[grid]\n", f'"sim.{k}"', f"grid.sim.{k}") for k in SIM]
        + [(f"{MJX}random_samples = 2\n[random]\n", f'"sim.{k}"', f"random.sim.{k}") for k in SIM])


def _check_accepted(cfg: sweep.SweepConfig) -> None:
    """An accepted config: every number finite in float32 and within its documented bound; the table builds."""
    numbers = [*cfg.robot.values(), *cfg.terrain_params.values(), cfg.resolution,
               *(v for lo_hi in cfg.command.values() for v in lo_hi),
               *(v for vs in cfg.grid.values() for v in vs), *(v for lo_hi in cfg.random.values() for v in lo_hi),
               *(v for lo_hi in cfg.sim.values() for v in lo_hi)]
    for v in numbers:
        assert isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and abs(v) <= F32_MAX, v
    assert 0 <= cfg.seed < 2**63 and 1 <= cfg.num_steps <= sweep_config.MAX_NUM_STEPS
    assert 1 <= cfg.num_scenarios <= sweep.MAX_SCENARIOS
    assert cfg.resolution >= sweep_config.MIN_RESOLUTION and math.prod(cfg.shape) <= sweep_config.MAX_MAP_CELLS
    for name in ("foot_length", "foot_width"):
        for v in [cfg.robot.get(name, 1.0), *cfg.grid.get(f"robot.{name}", ()), *cfg.random.get(f"robot.{name}", ())]:
            assert 0 < v <= robots.MAX_SIZE
    for v in [cfg.robot.get("density", 1.0), *cfg.grid.get("robot.density", ())]:
        assert 0 < v <= sweep_config.MAX_DENSITY
    if cfg.walker == "mjx":
        from ijoy_jax.sim import physics

        for k in SIM:
            for v in [*cfg.sim.get(k, ()), *cfg.grid.get(f"sim.{k}", ()), *cfg.random.get(f"sim.{k}", ())]:
                b = physics.BOUNDS[k]
                assert (v > b.lo if b.strict else v >= b.lo) and v <= b.hi, (k, v)
    table = sweep.scenarios(cfg, 4)
    assert 1 <= len(table) <= 4
    numeric = table.select_dtypes("number").to_numpy(np.float64)
    assert np.isfinite(numeric).all()


@settings(max_examples=400, deadline=None)
@given(where=st.sampled_from(KEYS), value=literal)
def test_every_key_with_a_hostile_value_is_refused_by_name_or_accepted_sane(tmp_path_factory, where, value):
    head, key, named = where
    path = tmp_path_factory.mktemp("cfg") / "hostile.toml"
    path.write_text(f"{head}{key} = {value}\n")
    try:
        cfg = sweep.load_config(path)
    except sweep.SweepConfigError as e:
        msg = str(e)
        m = re.match(rf"^{re.escape(str(path))}: (\S+): (.+)$", msg, re.S)
        assert m, msg
        err_key, reason = m.groups()
        # The key set (or an element of it), or the TOML parser for a literal that is not TOML at all; a start
        # zone that covers the map (set by its radius, its centre or the map's size) names its radius.
        assert (err_key == "<toml>" or err_key.startswith(named)
                or ("start zone" in reason and err_key.endswith("start_radius"))), msg
        assert reason.strip(), msg
        return
    _check_accepted(cfg)


@pytest.mark.parametrize("text, key, reason", [
    ("[sweep]\nseed = 9223372036854775808\n", "sweep.seed", "64 bits"),
    ("[sweep]\nseed = 123456789012345678901234567890\n", "sweep.seed", "64 bits"),
    ("[sweep]\nnum_steps = 100001\n", "sweep.num_steps", "<= 100000"),
    ("[robot]\nw = 1e39\n", "robot.w", "float32"),
    ("[robot]\nw = 123456789012345678901234567890\n", "robot.w", "64 bits"),
    ("[robot]\nfoot_length = 2.5\n", "robot.foot_length", "MAX_SIZE"),
    ("[robot]\ndensity = 50.0\n", "robot.density", "MAX_DENSITY"),
    ("[robot]\ndensity = 1e308\n", "robot.density", "float32"),
    ('[grid]\n"robot.density" = [0.5, 3.0]\n', "grid.robot.density[1]", "MAX_DENSITY"),
    ("[command]\nvx = [-1e308, 1e308]\n", "command.vx[0]", "float32"),
    ("[terrain]\nshape = [100000, 100000]\n", "terrain.shape", "MAX_MAP_CELLS"),
    ("[terrain]\nresolution = 1e-300\n", "terrain.resolution", "MIN_RESOLUTION"),
    ("[terrain]\nresolution = 100.0\n", "terrain.resolution", "MAX_COORDINATE"),
    ("[terrain]\nmax_count = 100000000\n", "terrain.max_count", "<= 1024"),
    ("[terrain.params]\nsize_min = 123456789012345678901234567890\n", "terrain.params.size_min", "64 bits"),
    ("[terrain.params]\nsize_min = 1e400\n", "terrain.params.size_min", "finite"),
])
def test_the_bounds_that_hostile_values_found(tmp_path, text, key, reason):
    """Each of these crashed or was accepted before (an OverflowError in jax.random.key, in float() or in the
    command draw; an action lattice of 1e308; a 1e10-cell map; a window of 1e300 cells)."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.load_config(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}: ") and reason in msg, msg


def test_the_bounds_admit_the_shipped_sweeps_and_their_extremes(tmp_path):
    text = ("[sweep]\nseed = 9223372036854775807\nnum_steps = 100000\n[robot]\nfoot_length = 2.0\nw = 3.4e38\n"
            "[terrain]\nshape = [2048, 2048]\nresolution = 0.005\nmax_count = 1024\n"
            '[grid]\n"robot.density" = [0.25, 2.0]\n')
    path = tmp_path / "edge.toml"
    path.write_text(text)
    cfg = sweep.load_config(path)
    _check_accepted(cfg)


@pytest.mark.parametrize("text, key", [
    ("[terrain.params]\nsize_max = 0.01\n", "terrain.params.size_max"),  # the other end of size_min's range
    ('[grid]\n"terrain.size_max" = [0.01, 0.02]\n', "grid.terrain.size_max"),
    ('[sweep]\nrandom_samples = 2\n[random]\n"terrain.top_max" = [0.01, 0.02]\n', "random.terrain.top_max"),
    ('[grid]\n"robot.w" = {}\n', "grid.robot.w"),  # an empty table is a value, not an absent key
    ("[robot]\nw = {}\n", "robot.w"),
])
def test_errors_name_the_key_the_file_sets(tmp_path, text, key):
    """A range whose upper end is set too low names that end (the key in the file), not its unset lower end;
    an empty inline table is refused where it stands instead of vanishing."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.load_config(path)
    assert str(e.value).startswith(f"{path}: {key}"), str(e.value)
