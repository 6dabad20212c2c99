"""Tests of ijoy_jax.sweep: validation, expansion, results against direct rollouts, no recompiles,
resume after SIGKILL, loading, and the ``ijoy sweep`` command line.

Sizes are tiny (tests/_sweep_util.py: 2D 60 x 50 map at 4 cm, 19 actions, 6 steps) and every in-process
sweep shares one static configuration, so the chunk function compiles once for the module (plus once for a
second density, on purpose).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import jax
import numpy as np
import pandas as pd
import pytest
import scipy.stats
from _sweep_util import (  # tests/ is on sys.path (pytest rootdir import)
    SPY_ON_DEVICES,
    kill_after_first_part,
    run_on_cpu_devices,
    tiny_sweep,
    write,
)
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import select, stats, sweep
from ijoy_jax.apps import cli
from ijoy_jax.footcost import pallas as footcost_kernel
from ijoy_jax.sweep import devices, folder, programs, sizing
from ijoy_jax.terrain import generators

# Float metrics from a vmapped chunk vs a single jitted rollout: same ops, possibly fused differently (m).
FLOAT_TOL = 1e-5
# t quantiles: the table has 6 decimals; the Cornish-Fisher expansion beyond df = 30 is within 1e-7.
T_TOL = 1e-6

BASE = tiny_sweep(margins=True)
CHUNK = 2  # 12 scenarios -> 6 chunks


@pytest.fixture(scope="module")
def base_file(tmp_path_factory) -> Path:
    return write(tmp_path_factory.mktemp("cfg"), BASE, "tiny.toml")


@pytest.fixture(scope="module")
def reference(base_file, tmp_path_factory):
    """One uninterrupted run of BASE: (output folder, stats)."""
    out = tmp_path_factory.mktemp("ref") / "tiny"
    stats = sweep.run(base_file, out, chunk_size=CHUNK, progress=False)
    return out, stats


# --------------------------------------------------------------------------- validation


BAD = [
    ("[nonsense]\nx = 1\n", "nonsense", "unknown key"),
    ("[sweep]\nnum_stepz = 4\n", "sweep.num_stepz", "unknown key"),
    ('[sweep]\nnum_steps = "ten"\n', "sweep.num_steps", "must be an integer"),
    ("[sweep]\nnum_steps = 0\n", "sweep.num_steps", "must be >= 1"),
    ("[sweep]\nscenarios_per_cell = 2.5\n", "sweep.scenarios_per_cell", "must be an integer"),
    ('[sweep]\nmethod = "greedy"\n', "sweep.method", "must be one of"),
    ('[sweep]\nkernel = "cuda"\n', "sweep.kernel", "must be one of"),
    ("[robot]\nmargin = -0.01\n", "robot.margin", "must be >= 0"),
    ("[robot]\nmax_sole_roll = -0.1\n", "robot.max_sole_roll", "must be >= 0"),
    ('[grid]\n"robot.max_sole_distance" = [0.5, nan]\n', "grid.robot.max_sole_distance[1]", "must be finite"),
    ("[robot]\nstep_time = 0\n", "robot.step_time", "must be > 0"),
    ("[robot]\nw = true\n", "robot.w", "must be a number"),
    ("[robot]\nmetrics.slope_wait = 1.0\n", "robot.metrics.slope_wait", "unknown key"),
    ('[terrain]\nfamily = "lava"\n', "terrain.family", "must be one of"),
    ("[terrain]\nshape = [60]\n", "terrain.shape", "must be [nx, ny]"),
    ("[terrain]\nresolution = -0.02\n", "terrain.resolution", "must be > 0"),
    ('[terrain]\nfamily = "slope"\nmax_count = 3\n', "terrain.max_count", "has no object slots"),
    ("[terrain.params]\ncount = 40\n", "terrain.params.count", "exceeds [terrain] max_count"),
    ("[terrain.params]\nheight = 1.0\n", "terrain.params.height", "unknown key"),
    ("[terrain.params]\nsize_min = 0.3\nsize_max = 0.1\n", "terrain.params.size_min", "impossible range"),
    ("[command]\nvx = [0.3, 0.1]\n", "command.vx", "impossible range: lo (0.3) > hi (0.1)"),
    ("[command]\nvx = [0.1, nan]\n", "command.vx[1]", "must be finite"),
    ("[command]\nspin = 1.0\n", "command.spin", "unknown key"),
    ('[grid]\n"robot.wiggle" = [1, 2]\n', "grid.robot.wiggle", "unknown parameter"),
    ('[grid]\n"robot.w" = []\n', "grid.robot.w", "non-empty list"),
    ('[grid]\n"robot.w" = [1, 1]\n', "grid.robot.w", "repeated values"),
    ('[grid]\n"robot.margin" = [0.02, -0.1]\n', "grid.robot.margin[1]", "must be >= 0"),
    ('[robot]\nw = 1.0\n[grid]\n"robot.w" = [1, 2]\n', "grid.robot.w", "also set as a fixed value"),
    ('[sweep]\nrandom_samples = 2\n[random]\n"robot.density" = [0.5, 1]\n', "random.robot.density",
     "changes array shapes"),
    ('[sweep]\nrandom_samples = 2\n[random]\n"robot.w" = [4, 1]\n', "random.robot.w", "impossible range"),
    ('[random]\n"robot.w" = [1, 4]\n', "sweep.random_samples", "must be >= 1"),
    ('[grid]\n"selector.horizon" = [1, 2]\n', "grid.selector.horizon", 'needs [sweep] method = "lookahead"'),
    ('[sweep]\nmethod = "lookahead"\n[grid]\n"selector.horizon" = [0, 2]\n', "grid.selector.horizon[0]",
     "must be >= 1"),
    ('[sweep]\nmethod = "lookahead"\nhorizon = 2\n[grid]\n"selector.horizon" = [1, 2]\n', "grid.selector.horizon",
     "also set as a fixed value in [sweep]"),
    ("[sweep]\nbeam = 4\n", "sweep.beam", 'an option of method = "lookahead"'),
    ('[sweep]\nmethod = "lookahead"\nbeam = 5000\n', "sweep.beam", "at most the action set's size"),
    ('[sweep]\nmethod = "naive"\nrefine = true\n', "sweep.refine", "refinement applies to the terrain-aware"),
    ('[sweep]\nmethod = "lookahead"\nrandom_samples = 2\n[random]\n"selector.horizon" = [1, 3]\n',
     "random.selector.horizon", "static"),
    ('[grid]\n"selector.refine" = [1, 0]\n', "grid.selector.refine[0]", "must be true or false"),
    ("[sweep]\ndiscount = -1\n", "sweep.discount", "must be >= 0"),
    ('[grid]\n"selector.beam" = [1, 2]\n', "grid.selector.beam", "unknown parameter"),
    ('[grid]\n"robot.reach" = [0.2, 0.3]\n', "grid.robot.reach", "fixed per sweep"),
    ('[sweep]\nrandom_samples = 2\n[random]\n"robot.reach" = [0.2, 0.3]\n', "random.robot.reach",
     "fixed per sweep"),
    ("[robot]\nreach = 0\n", "robot.reach", "must be > 0"),
    # hypot(0.45, 0.33) = 0.558 m > the default max_sole_distance 0.5 m; with a longer limit it is accepted
    ("[robot]\nreach = 0.45\n", "robot.reach", "0.558 m from the stance foot, beyond robot.max_sole_distance = 0.5"),
    ('[robot]\nreach = 0.45\n[grid]\n"robot.max_sole_distance" = [0.6, 0.55]\n', "robot.reach",
     "beyond robot.max_sole_distance = 0.55"),
    ("[robot]\nreach = 0.3\ndensity = 2.0\n", "robot.reach", "4867 actions at density 2, more than 3307"),
    ("[robot]\nreach = 1e30\n", "robot.reach", "more than 3307"),  # refused before the lattice is built
    ('[sweep]\nwalker = "mjx"\nmethod = "lookahead"\n', "sweep.method", 'walker = "mjx" runs the one-step'),
    ("[sweep\n", "<toml>", ""),
]


@pytest.mark.parametrize("text, key, reason", BAD, ids=[b[1] + ":" + b[2][:20] for b in BAD])
def test_bad_files_name_file_key_and_reason(tmp_path, text, key, reason):
    path = write(tmp_path, text, "bad_sweep.toml")
    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.load_config(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}: "), msg
    assert reason in msg


@pytest.mark.parametrize("text, key", [("[robot]\nmargin = -1.0\n", "robot.margin"),
                                       ('[grid]\n"robot.foot_width" = [0.13, 0.3]\n', "robot.foot_width")])
def test_bad_file_fails_before_any_compute(tmp_path, text, key):
    # The second is only found when the robot is built (its actions would overlap the stance foot).
    path = write(tmp_path, text)
    before = sweep.trace_count()
    with pytest.raises(sweep.SweepConfigError, match=key):
        sweep.run(path, tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()
    assert sweep.trace_count() == before


def test_missing_file(tmp_path):
    with pytest.raises(sweep.SweepConfigError, match="cannot read"):
        sweep.load_config(tmp_path / "nope.toml")


def test_robot_defaults_are_hrp2s():
    robot = ij.robots.hrp2()
    for name, value in sweep.ROBOT_DEFAULTS.items():
        if name == "density":
            assert robot.num_actions == 496
            continue
        if name == "reach":
            assert np.max(np.asarray(robot.actions)[:, 0]) == pytest.approx(value)
            continue
        obj = robot.metrics if name.startswith("metrics.") else robot
        assert float(getattr(obj, name.partition(".")[2] or name)) == pytest.approx(value, rel=1e-6), name


def test_defaults_are_fresh_and_not_shared():
    a, b = sweep.parse_config(""), sweep.parse_config("")
    assert a.command == b.command and a.command is not b.command
    assert a.robot is not b.robot and a.grid is not b.grid
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.seed = 4  # type: ignore[misc]


# --------------------------------------------------------------------------- expansion


def test_grid_expansion_order_and_pairing(base_file):
    cfg = sweep.load_config(base_file)
    assert cfg.num_cells == 4 and cfg.num_scenarios == 12
    c = sweep.cells(cfg)
    assert c[["robot.w", "robot.margin"]].values.tolist() == [[0.5, 0.0], [0.5, 0.05], [2.0, 0.0], [2.0, 0.05]]
    s = sweep.scenarios(cfg)
    assert s["scenario"].tolist() == list(range(12))
    assert s["replicate"].tolist() == [0, 1, 2] * 4
    assert (s["robot.density"] == 0.25).all() and (s["terrain.count"] == 6).all()
    assert s["terrain.count"].dtype == np.int64
    # Replicate r has the same command in every cell (paired design), drawn in range.
    per_rep = s.groupby("replicate")[["command.vx", "command.vy"]].nunique()
    assert (per_rep == 1).all().all()
    assert s["command.vx"].between(0.1, 0.3).all() and s["command.vy"].between(-0.05, 0.05).all()
    assert (s["command.wz"] == 0.0).all()
    assert len(sweep.scenarios(cfg, max_scenarios=5)) == 5


def test_random_samples_crossed_with_grid():
    cfg = sweep.parse_config('[sweep]\nrandom_samples = 3\nseed = 7\n[grid]\n"robot.w" = [1, 2]\n'
                             '[random]\n"robot.margin" = [0.01, 0.08]\n"terrain.size_max" = [0.1, 0.2]\n')
    c = sweep.cells(cfg)
    assert len(c) == cfg.num_cells == 6
    assert c["robot.margin"].between(0.01, 0.08).all() and c["terrain.size_max"].between(0.1, 0.2).all()
    # The same three draws under each w.
    np.testing.assert_array_equal(c["robot.margin"].values[:3], c["robot.margin"].values[3:])
    assert c["robot.margin"].nunique() == 3
    pd.testing.assert_frame_equal(c, sweep.cells(sweep.parse_config(cfg.text)))


def test_nested_tables_equal_dotted_keys():
    a = sweep.parse_config('[grid]\n"robot.w" = [1, 2]\n"robot.metrics.slope_weight" = [0.1, 0.2]\n')
    b = sweep.parse_config("[grid.robot]\nw = [1, 2]\nmetrics.slope_weight = [0.1, 0.2]\n")
    assert a.grid == b.grid


# --------------------------------------------------------------------------- execution and results


@pytest.mark.slow
def test_results_equal_direct_rollouts(reference, base_file):
    out, stats = reference
    df = sweep.load(out)
    cfg = sweep.load_config(base_file)
    for i in (1, 10):
        row = df.iloc[i]
        params = generators.ObstacleParams(count=int(row["terrain.count"]))
        key = jax.random.fold_in(jax.random.key(cfg.seed), int(row["replicate"]))
        terrain = generators.generate("obstacles", key, params, shape=(60, 50), resolution=0.04, max_count=8)
        robot = ij.robots.hrp2(margin=float(row["robot.margin"]), density=0.25, w=float(row["robot.w"]))
        c = np.asarray(generators.start_point(params, shape=(60, 50), resolution=0.04))
        start = np.array([[c[0], c[1] + 0.095, 0.0], [c[0], c[1] - 0.095, 0.0]])
        command = row[["command.vx", "command.vy", "command.wz"]].to_numpy(np.float64)
        want = ij.rollout(terrain, robot, start, command, num_steps=6).summary()
        for k, v in want.items():
            if np.issubdtype(np.asarray(v).dtype, np.floating):
                assert row[k] == pytest.approx(float(v), abs=FLOAT_TOL), k
            else:
                assert row[k] == v, k
    # Some scenario actually walked, so the comparison is not vacuous.
    assert df["distance_along"].max() > 0.2


@pytest.mark.slow
def test_pallas_kernel_gives_the_same_results(reference, tmp_path, monkeypatch):
    """``kernel = "pallas"`` (the fused FootCost kernel, interpreted on this CPU) walks the same steps: the
    same results as the XLA path's for the plan's first 4 scenarios (2 chunks: interpreting is slow)."""
    out, _ = reference
    traced = []

    def fused(*args, **kwargs):  # the kernel is what the chunk function traces
        traced.append(1)
        return footcost_kernel.foot_cost_fused(*args, **kwargs)

    monkeypatch.setattr(select, "foot_cost_fused", fused)
    text = BASE.replace('method = "exhaustive"', 'method = "exhaustive"\nkernel = "pallas"')
    s = sweep.run(write(tmp_path, text), tmp_path / "p", chunk_size=CHUNK, progress=False, max_scenarios=4)
    assert s.computed == 4 and s.compiles == 1 and traced
    got, want = sweep.load(tmp_path / "p"), sweep.load(out).iloc[:4]
    for k in ("robot.w", "robot.margin", "replicate", "command.vx", "steps_taken", "stopped", "steps_in_place",
              "footholds_on_obstacles", "distance_along", "distance_across", "mean_foot_cost"):
        np.testing.assert_allclose(got[k].to_numpy(float), want[k].to_numpy(float), atol=FLOAT_TOL, err_msg=k)
    assert want["distance_along"].max() > 0.1  # they walked


def test_parameter_values_do_not_recompile(reference, tmp_path):
    _, stats = reference
    assert stats.compiles <= 1  # 0 if an earlier test of this module compiled the same shapes
    cache = programs.compiled_programs()
    other = BASE.replace('"robot.w" = [0.5, 2.0]', '"robot.w" = [0.1, 7.0]').replace(
        '"robot.margin" = [0.0, 0.05]', '"robot.margin" = [0.02, 0.08]').replace(
        "count = 6", "count = 2").replace("vx = [0.1, 0.3]", "vx = 0.2").replace("seed = 3", "seed = 11")
    s = sweep.run(write(tmp_path, other), tmp_path / "o", chunk_size=CHUNK, progress=False)
    assert s.computed == 12 and s.compiles == 0
    assert programs.compiled_programs() == cache


def _log_chunk_events(monkeypatch) -> list:
    """Record the sweep's chunk loop as ("dispatch", rows) and ("write", chunk id) events."""
    events = []
    dispatch, write_part = devices.OnDevices.dispatch, folder.write_part

    def logged_dispatch(self, run, static, shared, batch):
        events.append(("dispatch", len(batch[0])))  # the rows dispatched
        return dispatch(self, run, static, shared, batch)

    def logged_write(df, path, plan_record):
        events.append(("write", int(df["chunk"].iloc[0])))
        write_part(df, path, plan_record)

    monkeypatch.setattr(devices.OnDevices, "dispatch", logged_dispatch)
    monkeypatch.setattr(folder, "write_part", logged_write)
    return events


@pytest.mark.slow
def test_density_compiles_once_per_size_and_the_host_writes_while_the_devices_compute(tmp_path, monkeypatch):
    text = BASE.replace("[robot]\ndensity = 0.25\n", "").replace(
        '"robot.margin" = [0.0, 0.05]', '"robot.density" = [0.25, 0.5]').replace("scenarios_per_cell = 3",
                                                                              "scenarios_per_cell = 4")
    s = sweep.run(write(tmp_path, text), tmp_path / "o", chunk_size=CHUNK, progress=False)
    df = sweep.load(tmp_path / "o")
    assert s.chunks == 8 and len(df) == 16
    assert s.compiles <= 2 and set(s.first_chunk_s) == {0.25, 0.5}  # 0.25 may be cached already
    events = _log_chunk_events(monkeypatch)
    again = sweep.run(write(tmp_path, text), tmp_path / "o2", chunk_size=CHUNK, progress=False)
    assert again.compiles == 0
    pd.testing.assert_frame_equal(sweep.load(tmp_path / "o2"), df)
    # Chunks 0-3 are density 0.25, 4-7 density 0.5 (a new program): within a density, chunk k+1 is dispatched
    # before chunk k is written; the first chunk of a density waits until the chunk before it is written.
    kinds = [k for k, _ in events]
    writes = [c for k, c in events if k == "write"]
    assert writes == list(range(8))
    assert kinds == ["dispatch", "dispatch", "write", "dispatch", "write", "dispatch", "write",
                     "write", "dispatch", "dispatch", "write", "dispatch", "write", "dispatch", "write", "write"]


@pytest.mark.slow
def test_selector_options_sweep_match_direct_rollouts_and_compile_once_per_horizon(tmp_path):
    """``selector.horizon`` is static (one compile per value), ``selector.discount`` traced (none per value);
    each scenario equals ``ij.rollout`` with its options (refinement's are tests/test_refine.py's)."""
    text = (BASE.replace('method = "exhaustive"', 'method = "lookahead"')
            .replace('"robot.w" = [0.5, 2.0]\n"robot.margin" = [0.0, 0.05]',
                     '"selector.horizon" = [1, 2]\n"selector.discount" = [0.5, 1.0]'))
    s = sweep.run(write(tmp_path, text), tmp_path / "o", chunk_size=3, progress=False)
    df = sweep.load(tmp_path / "o")
    assert len(df) == 12 and s.compiles <= 2 and len(s.first_chunk_s) == 2
    assert {"selector.horizon", "selector.refine", "selector.discount"} <= set(df.columns)
    assert set(df["selector.refine"]) == {0} and "footholds_near_obstacles" in df
    cfg = sweep.load_config(tmp_path / "s.toml")
    for i in (10,):  # horizon 2, discount 1.0
        row = df.iloc[i]
        params = generators.ObstacleParams(count=int(row["terrain.count"]))
        key = jax.random.fold_in(jax.random.key(cfg.seed), int(row["replicate"]))
        terrain = generators.generate("obstacles", key, params, shape=(60, 50), resolution=0.04, max_count=8)
        robot = ij.robots.hrp2(margin=0.02, density=0.25)
        c = np.asarray(generators.start_point(params, shape=(60, 50), resolution=0.04))
        start = np.array([[c[0], c[1] + 0.095, 0.0], [c[0], c[1] - 0.095, 0.0]])
        command = row[["command.vx", "command.vy", "command.wz"]].to_numpy(np.float64)
        options = ij.SelectOptions(method="lookahead", horizon=int(row["selector.horizon"]),
                                   discount=float(row["selector.discount"]))
        want = ij.rollout(terrain, robot, start, command, num_steps=6, options=options).summary()
        for k, v in want.items():
            assert row[k] == pytest.approx(float(v), abs=FLOAT_TOL), k
    diffs = sweep.paired_differences(df, {"selector.horizon": 1, "selector.discount": 0.5})
    assert len(diffs) == 4 and np.all(diffs["n"] == 3)
    base = diffs[(diffs["selector.horizon"] == 1) & (diffs["selector.discount"] == 0.5)]
    assert float(base["distance_along.diff"].iloc[0]) == 0.0


def test_rotation_weight_and_metrics_sweep_match_direct_rollout(tmp_path):
    # rotation_weight swept: each scenario builds its own targets (a second, separate compile).
    text = BASE.replace('"robot.margin" = [0.0, 0.05]', '"robot.rotation_weight" = [0.5, 100.0]').replace(
        '"robot.w" = [0.5, 2.0]', "").replace("density = 0.25", "density = 0.25\nmetrics.band_weight = 2.0")
    text = text.replace("vy = [-0.05, 0.05]\nwz = 0.0", "vy = 0.0\nwz = [-0.3, 0.3]")
    cfg = sweep.load_config(write(tmp_path, text))
    sweep.run(cfg, tmp_path / "o", chunk_size=CHUNK, max_scenarios=4, progress=False)
    df = sweep.load(tmp_path / "o")
    assert (df["robot.metrics.band_weight"] == 2.0).all() and len(df) == 4
    row = df.iloc[3]
    params = generators.ObstacleParams(count=6)
    key = jax.random.fold_in(jax.random.key(cfg.seed), int(row["replicate"]))
    terrain = generators.generate("obstacles", key, params, shape=(60, 50), resolution=0.04, max_count=8)
    robot = ij.robots.hrp2(density=0.25, rotation_weight=float(row["robot.rotation_weight"]),
                           metrics=ij.robots.default_metrics(band_weight=2.0))
    c = np.asarray(generators.start_point(params, shape=(60, 50), resolution=0.04))
    start = np.array([[c[0], c[1] + 0.095, 0.0], [c[0], c[1] - 0.095, 0.0]])
    command = row[["command.vx", "command.vy", "command.wz"]].to_numpy(np.float64)
    want = ij.rollout(terrain, robot, start, command, num_steps=6).summary()
    for k, v in want.items():
        assert row[k] == pytest.approx(float(v), abs=FLOAT_TOL), k


@pytest.mark.slow
def test_reach_sweep_matches_direct_rollouts_of_the_longer_reach(tmp_path):
    """``[robot] reach = 0.30`` (issue #20's stairs option, ``robots.hrp2(reach=0.30)``): every scenario equals
    ``ij.rollout`` with that robot, and not with the paper's reach; the aggregates keep the reach, and the
    action counts follow it."""
    text = (tiny_sweep(margins=False).replace("density = 0.25", "density = 0.25\nreach = 0.30")
            .replace("vx = [0.1, 0.3]", "vx = 0.375").replace("vy = [-0.05, 0.05]", "vy = 0.0"))
    cfg = sweep.load_config(write(tmp_path, text))
    sweep.run(cfg, tmp_path / "o", chunk_size=CHUNK, progress=False)
    df = sweep.load(tmp_path / "o")
    assert len(df) == 6 and (df["robot.reach"] == 0.30).all()
    assert float(np.max(np.asarray(sweep.scenario(cfg, 0).robot.actions)[:, 0])) == pytest.approx(0.30)
    differs = 0
    for i in range(len(df)):
        row = df.iloc[i]
        params = generators.ObstacleParams(count=6)
        key = jax.random.fold_in(jax.random.key(cfg.seed), int(row["replicate"]))
        terrain = generators.generate("obstacles", key, params, shape=(60, 50), resolution=0.04, max_count=8)
        c = np.asarray(generators.start_point(params, shape=(60, 50), resolution=0.04))
        start = np.array([[c[0], c[1] + 0.095, 0.0], [c[0], c[1] - 0.095, 0.0]])
        command = row[["command.vx", "command.vy", "command.wz"]].to_numpy(np.float64)
        runs = {reach: ij.rollout(terrain, ij.robots.hrp2(density=0.25, reach=reach, w=float(row["robot.w"])), start,
                                  command, num_steps=6).summary() for reach in (0.30, ij.robots.PAPER_REACH)}
        for k, v in runs[0.30].items():
            assert row[k] == pytest.approx(float(v), abs=FLOAT_TOL), (i, k)
        differs += float(runs[ij.robots.PAPER_REACH]["distance_along"]) != pytest.approx(row["distance_along"])
    assert differs >= 1
    # the longer steps were taken: 6 steps of at most 0.20 m cannot carry the robot 1.2 m (here 1.65 m)
    assert df["distance_along"].max() > 6 * ij.robots.PAPER_REACH
    agg = sweep.aggregate(df)
    assert (agg["robot.reach"] == 0.30).all()
    assert sweep.action_counts([0.25, 1.0], reach=0.30).tolist() == [37, 720]


def test_padding_rows_are_dropped(tmp_path, base_file):
    # 12 scenarios in chunks of 5: the last chunk has 2 rows padded to 5 (a new shape: one compile).
    s = sweep.run(base_file, tmp_path / "o", chunk_size=5, progress=False)
    df = sweep.load(tmp_path / "o")
    assert s.chunks == 3 and df["scenario"].tolist() == list(range(12))
    assert df.groupby("chunk").size().tolist() == [5, 5, 2]


def test_resume_after_sigkill(reference, base_file, tmp_path):
    ref_out, _ = reference
    out = tmp_path / "killed"
    parts = out / "parts"
    kill_after_first_part(base_file, out, chunk=CHUNK, hold_s=0.5, timeout_s=120, poll_s=0.01)
    done = sorted(p.name for p in parts.glob("part-*.parquet"))
    assert 1 <= len(done) < 6, done
    (parts / "part-00005.parquet.tmp").write_bytes(b"half a file")  # a write cut short by a kill
    stats = sweep.run(base_file, out, chunk_size=CHUNK, progress=False)
    assert stats.skipped == len(done) and stats.computed == 12 - CHUNK * len(done)
    got, want = sweep.load(out), sweep.load(ref_out)
    assert got["scenario"].tolist() == list(range(12))
    pd.testing.assert_frame_equal(got, want)
    # A third run has nothing left to do.
    again = sweep.run(base_file, out, chunk_size=CHUNK, progress=False)
    assert again.computed == 0 and again.skipped == 6
    pd.testing.assert_frame_equal(sweep.load(out), want)


def test_a_chunk_dispatched_before_an_error_is_still_written(reference, base_file, tmp_path, monkeypatch):
    ref_out, _ = reference
    events = _log_chunk_events(monkeypatch)
    logged = devices.OnDevices.dispatch

    def fail_fourth(self, *args):
        if sum(k == "dispatch" for k, _ in events) == 3:
            raise RuntimeError("device lost")
        return logged(self, *args)

    monkeypatch.setattr(devices.OnDevices, "dispatch", fail_fourth)
    out = tmp_path / "broken"
    with pytest.raises(RuntimeError, match="device lost"):
        sweep.run(base_file, out, chunk_size=CHUNK, progress=False)
    # Chunk 2 was in flight when chunk 3's dispatch failed: its results are kept, and a resume skips it.
    assert sorted(p.name for p in (out / "parts").glob("part-*.parquet")) == [
        f"part-{i:05d}.parquet" for i in range(3)]
    monkeypatch.undo()
    stats = sweep.run(base_file, out, chunk_size=CHUNK, progress=False)
    assert stats.skipped == 3 and stats.computed == 12 - 3 * CHUNK
    pd.testing.assert_frame_equal(sweep.load(out), sweep.load(ref_out))


def test_resume_refuses_a_different_plan(reference, base_file):
    out, _ = reference
    with pytest.raises(ValueError, match="different sweep or chunk plan"):
        sweep.run(base_file, out, chunk_size=3, progress=False)


def test_load_round_trip_and_aggregates(reference, base_file):
    out, _ = reference
    df = sweep.load(out)
    assert len(df) == 12 and df["scenario"].is_unique
    for m in sweep.METRICS:
        assert m in df.columns
    assert {"robot.w", "robot.margin", "terrain.count", "command.vx", "cell", "replicate", "chunk"} <= set(df.columns)
    assert not set(sweep.EXTRA_METRICS) & set(df.columns)  # obstacles adds no metric (its registry entry has none)
    agg = sweep.load_aggregates(out)
    pd.testing.assert_frame_equal(agg, pd.read_parquet(out / "aggregates.parquet"))
    assert list(agg["robot.w"]) == [0.5, 0.5, 2.0, 2.0] and (agg["n"] == 3).all()
    g = df[df["cell"] == 2]["distance_along"].to_numpy(np.float64)
    row = agg[agg["cell"] == 2].iloc[0]
    assert row["distance_along.mean"] == pytest.approx(g.mean())
    half = scipy.stats.t.ppf(0.975, 2) * scipy.stats.sem(g)
    assert row["distance_along.ci95"] == pytest.approx(half, rel=T_TOL, abs=1e-12)
    man = __import__("json").loads((out / "manifest.json").read_text())
    assert man["sweep_text"] == base_file.read_text() and (out / "sweep.toml").read_text() == BASE
    assert man["versions"]["jax"] == jax.__version__ and man["plan"]["chunks"] == 6
    assert man["sessions"][-1]["complete"] and man["sessions"][-1]["device"]


@pytest.mark.parametrize("df", [1, 2, 3, 4, 5, 9, 30, 31, 100, 10_000])
def test_t_quantile_against_scipy(df):
    assert stats.t_quantile(df) == pytest.approx(scipy.stats.t.ppf(0.975, df), abs=T_TOL)
    assert math.isnan(stats.t_quantile(0))


# --------------------------------------------------------------------------- command line


def test_cli_run_and_summarize(base_file, tmp_path, capsys):
    out = tmp_path / "cli"
    assert cli.main(["sweep", "run", str(base_file), "--out", str(out), "--chunk", str(CHUNK),
                     "--max-scenarios", "4"]) == 0
    printed = capsys.readouterr()
    assert '"computed": 4' in printed.out and "scenarios/s" in printed.err and "ETA" in printed.err
    row = json.loads(printed.out)
    assert row["chunks"] == 4 // CHUNK and row["scenarios_per_s"] > 0  # timed on the chunks after the first
    assert len(sweep.load(out)) == 4
    assert cli.main(["sweep", "run", str(base_file), "--out", str(tmp_path / "one"), "--chunk", "4",
                     "--max-scenarios", "4"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["chunks"] == 1 and row["scenarios_per_s"] is None  # one chunk: its time includes the compile
    assert cli.main(["sweep", "summarize", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "robot.w" in printed and "distance_along (m)" in printed
    png = out / "summary.png"
    assert png.exists() and png.stat().st_size > 10_000
    # the panels a user picks, and one line naming a metric the sweep does not have
    picked = tmp_path / "picked.png"
    assert cli.main(["sweep", "summarize", str(out), "--png", str(picked), "--metrics", "stopped, distance_along"]) == 0
    assert picked.exists() and picked.stat().st_size > 10_000
    capsys.readouterr()
    assert cli.main(["sweep", "summarize", str(out), "--metrics", "fell"]) == 2
    printed = capsys.readouterr()
    err = printed.err.strip()
    assert len(err.splitlines()) == 1 and "--metrics: 'fell' is not a metric of this sweep" in err, err
    assert printed.out == ""  # refused before the table is printed
    # the price of safety: one metric against another, one point per cell
    assert cli.main(["sweep", "summarize", str(out), "--tradeoff", "stopped,distance_along"]) == 0
    assert (out / "tradeoff.png").stat().st_size > 10_000 and "tradeoff.png" in capsys.readouterr().out
    for bad in ("fell", "fell,distance_along", "stopped,distance_along,mean_deviation"):
        assert cli.main(["sweep", "summarize", str(out), "--tradeoff", bad]) == 2
        printed = capsys.readouterr()
        assert "--tradeoff takes two metrics of this sweep" in printed.err and printed.out == ""


def test_cli_bad_file_exits_2(tmp_path, capsys):
    path = write(tmp_path, "[sweep]\nmethod = 'greedy'\n")
    assert cli.main(["sweep", "run", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{path}: sweep.method: must be one of" in err
    assert not (tmp_path / "o").exists()


def test_shipped_w_sweep_is_valid():
    cfg = sweep.load_config(Path(__file__).parents[1] / "sweeps" / "w_sweep.toml")
    assert cfg.swept == ("robot.w",) and cfg.num_scenarios >= 100


# --------------------------------------------------------------------------- several devices

_SHARDED_CHILD = """
import sys
import jax
from ijoy_jax import sweep
assert jax.local_device_count() == 4, jax.devices()
""" + SPY_ON_DEVICES + """
stats = sweep.run(sys.argv[1], sys.argv[2], chunk_size=3, max_scenarios=10, progress=False)
assert (stats.devices, stats.chunk_size, stats.chunks) == (4, 4, 3), stats
four = sorted(str(d) for d in jax.local_devices())
assert seen == [four] * 3, seen  # every chunk: one slice on each device
"""


@pytest.mark.slow
def test_four_cpu_devices_give_the_single_device_result(reference, base_file, tmp_path):
    # chunk_size 3 is rounded up to 4 (one scenario per device); 10 scenarios make chunks of 4, 4 and 2,
    # the last padded to 4. Compared with the in-process single-device reference (chunks of 2).
    ref_out, _ = reference
    out = tmp_path / "four"
    run_on_cpu_devices(_SHARDED_CHILD, str(base_file), str(out), devices=4, timeout_s=120)
    man = json.loads((out / "manifest.json").read_text())["sessions"][-1]
    assert man["devices"] == 4 and man["device_count"] == 4 and man["chunk_size"] == 4 and man["complete"]
    assert man["sharding"].startswith("rows split evenly over 4 devices"), man["sharding"]
    one = json.loads((ref_out / "manifest.json").read_text())["sessions"][-1]
    assert one["devices"] == 1 and one["sharding"] is None
    got = sweep.load(out)
    want = sweep.load(ref_out).iloc[:10]
    assert got.groupby("chunk").size().tolist() == [4, 4, 2]
    assert list(got.columns) == list(want.columns) and got["scenario"].tolist() == list(range(10))
    # Each scenario is computed independently, so the split over devices should not change a bit (it does
    # not, on CPU); floats get 1e-6 only in case XLA fuses a per-device batch of 1 unlike one of 2.
    for c in got.columns.drop("chunk"):
        if np.issubdtype(got[c].dtype, np.floating):
            np.testing.assert_allclose(got[c], want[c], rtol=0, atol=1e-6, err_msg=c)
        else:
            np.testing.assert_array_equal(got[c], want[c], err_msg=c)


def test_bad_device_count(base_file, tmp_path):
    for n in (0, len(jax.local_devices()) + 1, 1.0):
        with pytest.raises(ValueError, match="devices must be"):
            sweep.run(base_file, tmp_path / "o", devices=n, progress=False)
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- chunk size from device memory

MiB = 2**20


@pytest.mark.parametrize("per, mem, ndev, want", [
    (1 * MiB, 40 * MiB, 1, 16),        # 0.5 * 40 / 1 = 20 -> 16 (a power of two per device)
    (1 * MiB, 64 * MiB, 1, 32),        # exactly a power of two
    (1 * MiB, 40 * MiB, 4, 64),        # per device, times the devices
    (100 * MiB, 80 * 2**30, 1, 256),   # 100 MiB per scenario on an 80 GiB GPU: 409 -> 256
    (1 * MiB, 80 * 2**30, 1, sizing.MAX_AUTO_CHUNK),   # capped
    (1 * MiB, 80 * 2**30, 3, 3 * sizing.MAX_AUTO_CHUNK),   # the cap is per device: each runs what it would alone
    (10 * 2**30, 16 * 2**30, 2, 2),    # a scenario larger than half the memory: still one per device
])
def test_auto_chunk_size(per, mem, ndev, want):
    got = sweep.auto_chunk_size(per, mem, ndev)
    assert got == want and got % ndev == 0


def test_auto_chunk_size_leaves_room_for_the_shared_tables():
    # 40 MiB, half usable, 4 MiB of shared target tables: (20 - 4) / 1 = 16 scenarios; 10 MiB shared -> 8.
    assert sweep.auto_chunk_size(MiB, 40 * MiB, shared_bytes=4 * MiB) == 16
    assert sweep.auto_chunk_size(MiB, 40 * MiB, shared_bytes=10 * MiB) == 8
    assert sweep.auto_chunk_size(MiB, 40 * MiB, shared_bytes=30 * MiB) == 1  # nothing fits: one per device


@settings(max_examples=200, deadline=None, derandomize=True)
@given(cap_per_device=st.integers(1, 1000), total=st.integers(1, 20_000), ndev=st.integers(1, 8))
def test_balanced_chunk_size_keeps_the_chunk_count_and_pads_least(cap_per_device, total, ndev):
    """Against the brute force: of the chunk sizes (multiples of the device count, at most ``cap``) that need
    as few chunks as ``cap``, the smallest."""
    cap = cap_per_device * ndev
    got = sweep.balanced_chunk_size(cap, total, ndev)
    chunks = -(-total // cap)
    fits = [c for c in range(ndev, cap + 1, ndev) if -(-total // c) == chunks]
    assert got == min(fits) and got % ndev == 0 and got <= cap
    assert got * chunks - total < chunks * ndev  # padding under one device-row per chunk


def test_balanced_chunk_size_refuses_nonsense():
    for bad in ((0, 10, 1), (10, 0, 1), (10, 10, 0)):
        with pytest.raises(ValueError, match="need cap"):
            sweep.balanced_chunk_size(*bad)


def test_default_chunk_size_is_the_cpu_default_here(base_file):
    cfg = sweep.load_config(base_file)
    assert sizing.device_memory(jax.local_devices()[0]) is None  # CPU reports no memory limit
    assert sweep.default_chunk_size(cfg, sweep.scenarios(cfg), {}, jax.local_devices()) == sweep.DEFAULT_CHUNK


def test_scenario_bytes_from_the_compiled_chunk(base_file):
    cfg = sweep.load_config(base_file)
    table = sweep.scenarios(cfg)
    traces = sweep.trace_count()
    base = programs.base_robot(cfg, table, 0.25)
    per, shared = sweep.scenario_bytes(cfg, table, base)
    assert sweep.trace_count() == traces + 1  # lowered and compiled ahead of time, not run
    assert 1_000 < per < 10**8, per
    # The shared part (base robot, target tables, as kept by jit) is at most their leaves' bytes.
    _, targets = programs.shared_inputs(table, base)
    assert 0 < shared <= sum(np.asarray(x).nbytes for x in jax.tree.leaves((base, targets)))


def test_run_sizes_chunks_from_a_fake_device_memory(base_file, tmp_path, monkeypatch):
    # As on a GPU reporting 40 MiB with 1 MiB per scenario: 16 per chunk, and a resume keeps it.
    monkeypatch.setattr(sizing, "device_memory", lambda device: 40 * MiB)
    monkeypatch.setattr(sizing, "scenario_bytes", lambda cfg, table, base, sim=None: (1 * MiB, 0))
    s = sweep.run(base_file, tmp_path / "o", max_scenarios=4, progress=False)
    assert (s.chunk_size, s.chunks) == (16, 1)
    monkeypatch.setattr(sizing, "device_memory", lambda device: 400 * MiB)  # another GPU on resume
    again = sweep.run(base_file, tmp_path / "o", max_scenarios=4, progress=False)
    assert (again.chunk_size, again.computed, again.skipped) == (16, 0, 1)
    man = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert man["plan"]["chunk_size"] == 16


# --------------------------------------------------------------------------- action-set size plot


def test_density_axis_is_drawn_in_action_counts_with_the_papers_496(tmp_path):
    dens = [0.4, 0.5, 0.75, 1.0, 1.5, 2.0]
    assert sweep.action_counts(dens).tolist() == [52, 117, 202, 496, 1279, 3307]
    agg = pd.DataFrame({"cell": range(6), "robot.density": dens, "n": 4})
    for m in ("distance_along", "mean_deviation"):
        agg[f"{m}.mean"], agg[f"{m}.ci95"] = np.linspace(1, 2, 6), 0.1
    fig = sweep.plot(agg, tmp_path / "size.png", metrics=("distance_along", "mean_deviation"), title="size")
    assert (tmp_path / "size.png").stat().st_size > 10_000
    for ax in fig.axes:
        assert ax.get_xscale() == "log" and "actions" in ax.get_xlabel()
        assert ax.lines[0].get_xdata().tolist() == [52, 117, 202, 496, 1279, 3307]
        marks = [ln for ln in ax.lines if "496" in str(ln.get_label())]
        assert len(marks) == 1 and marks[0].get_xdata()[0] == sweep.PAPER_ACTIONS
        assert "496" in [t.get_text() for t in ax.get_xticklabels()]
    # A sweep at a longer reach (its aggregates keep robot.reach): the same densities are larger action sets
    fig = sweep.plot(agg.assign(**{"robot.reach": 0.30}), tmp_path / "reach.png", metrics=("distance_along",))
    want = sweep.action_counts(dens, reach=0.30).tolist()
    assert want[3] == 720 and fig.axes[0].lines[0].get_xdata().tolist() == want
    assert fig.axes[0].containers[0].get_label() == "reach = 0.3"  # the line says which reach


def test_the_tradeoff_plot_puts_each_cell_at_its_price_and_safety(tmp_path):
    """Falls against progress, one point per cell: coloured by the first swept column, labelled by the others,
    each point at the cell's means with its CIs (a rate's clipped to [0, 1])."""
    amp, w = np.repeat([0.01, 0.03], 3), np.tile([1.0, 2.0, 4.0], 2)
    agg = pd.DataFrame({"cell": range(6), "terrain.amplitude": amp, "robot.w": w, "n": 64,
                        "fell.mean": amp * w, "fell.ci95": 0.05, "distance_along.mean": w / amp / 100,
                        "distance_along.ci95": 0.1})
    fig = sweep.plot_tradeoff(agg, tmp_path / "t.png", title="rough")
    assert (tmp_path / "t.png").stat().st_size > 0
    (ax,) = fig.axes
    assert len(ax.containers) == 2  # one per amplitude
    for container, a in zip(ax.containers, (0.01, 0.03), strict=True):
        xy = container.lines[0].get_xydata()
        want = agg[agg["terrain.amplitude"] == a]
        np.testing.assert_allclose(xy[:, 0], want["distance_along.mean"])
        np.testing.assert_allclose(xy[:, 1], want["fell.mean"])
        lower = container.lines[2][1].get_segments()  # the y error bars: fell within [0, 1]
        assert all(seg[0][1] >= 0 and seg[1][1] <= 1 for seg in lower)
    assert [t.get_text() for t in ax.texts] == [f"w {v:g}" for v in w]
    assert {t.get_text() for t in ax.get_legend().get_texts()} == {"amplitude = 0.01", "amplitude = 0.03"}
    assert ax.get_xlabel() == "distance along (m)" and ax.get_ylabel().startswith("fall rate")
    with pytest.raises(ValueError, match="'collided' is not a metric of this sweep"):
        sweep.plot_tradeoff(agg, tmp_path / "u.png", safety="collided")


def test_the_tradeoff_plot_gives_a_third_swept_column_the_labels_and_the_second_the_markers(tmp_path):
    """rough_robustness.toml's grid (amplitude x w x support limit): colour by amplitude, a marker per w, the
    support limit as each point's label; each (amplitude, w) pair one set of points at its cells' means."""
    amp, w, lim = (g.ravel() for g in np.meshgrid([0.01, 0.03], [1.0, 4.0], [0.015, 0.04], indexing="ij"))
    agg = pd.DataFrame({"cell": range(8), "terrain.amplitude": amp, "robot.w": w,
                        "robot.metrics.support_limit": lim, "n": 256, "fell.mean": amp * w + lim,
                        "fell.ci95": 0.02, "distance_along.mean": w / amp / 100 - lim, "distance_along.ci95": 0.1})
    fig = sweep.plot_tradeoff(agg, tmp_path / "t.png")
    (ax,) = fig.axes
    assert len(ax.containers) == 4  # one per (amplitude, w)
    for container, (a, ww) in zip(ax.containers, [(0.01, 1.0), (0.01, 4.0), (0.03, 1.0), (0.03, 4.0)],
                                  strict=True):
        want = agg[(agg["terrain.amplitude"] == a) & (agg["robot.w"] == ww)]
        np.testing.assert_allclose(container.lines[0].get_xydata(),
                                   want[["distance_along.mean", "fell.mean"]].to_numpy())
        assert container.lines[0].get_marker() == {1.0: "o", 4.0: "s"}[ww]
    assert [t.get_text() for t in ax.texts] == [f"support_limit {v:g}" for v in lim]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "amplitude = 0.01", "amplitude = 0.03", "w = 1", "w = 4"]


def test_summary_plot_is_a_grid_of_distinct_panels(tmp_path):
    """The default six metrics: 2 rows x 3 columns (not one 2772 px row), each panel titled with its metric
    and unit, one line per value of the other swept parameter."""
    from PIL import Image

    from ijoy_jax.sweep import plots

    metrics = plots.PLOT_METRICS
    w = [0.0, 0.3, 1.0, 3.0, 10.0]
    agg = pd.DataFrame({"cell": range(10), "robot.w": w * 2, "robot.margin": [0.0] * 5 + [0.04] * 5, "n": 8})
    for i, m in enumerate(metrics):
        agg[f"{m}.mean"], agg[f"{m}.ci95"] = np.linspace(0, 1, 10) + i, 0.1
    png = tmp_path / "summary.png"
    fig = sweep.plot(agg, png, title="w sweep")
    assert len(fig.axes) == 6
    assert [ax.get_subplotspec().get_geometry()[:2] for ax in fig.axes] == [(2, 3)] * 6
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == [f"{m.replace('_', ' ')} ({sweep.UNITS[m]})" for m in metrics] and len(set(titles)) == 6
    for ax in fig.axes:
        assert ax.get_xlabel() == "w (cost units per m)" and len(ax.containers) == 2  # margin 0 and 0.04
    legend = {t.get_text() for t in fig.axes[0].get_legend().get_texts()}
    assert legend == {"margin = 0", "margin = 0.04", "library default (1)"}
    width, height = Image.open(png).size
    assert width <= 1600 and height >= 0.45 * width


# What each walker kind's aggregates hold beside its metrics: the swept column that makes it that kind.
KIND_COLUMN = {"perfect": ("robot.w", [0.3, 1.0, 3.0]), "selector": ("selector.horizon", [1, 2, 3]),
               "mjx": ("sim.stance_noise", [0.0, 0.01, 0.02])}


@pytest.mark.parametrize("near", [True, False], ids=["near", "no_near"])
@pytest.mark.parametrize("kind", sorted(KIND_COLUMN))
def test_summary_plot_panels_are_the_tables_metric_columns(kind, near, tmp_path, monkeypatch, capsys):
    """``ijoy sweep summarize`` draws, panel by panel and in order, the metrics its table prints, for every
    walker kind, and for results written before ``footholds_near_obstacles`` existed (``near`` False); a
    physics sweep's fall rate and collision rate stand beside progress."""
    from ijoy_jax.sweep import plots

    metrics = sweep.METRICS + (sweep.PHYSICS_METRICS if kind == "mjx" else ())
    metrics = tuple(m for m in metrics if near or m != "footholds_near_obstacles")
    column, values = KIND_COLUMN[kind]
    agg = pd.DataFrame({"cell": range(3), column: values, "n": 8})
    for m in metrics:
        agg[f"{m}.mean"], agg[f"{m}.ci95"] = [0.2, 0.4, 0.6], 0.05  # within [0, 1]: rates among them
    (tmp_path / "manifest.json").write_text(json.dumps({"name": kind, "plan": {"scenarios": 24}}))
    monkeypatch.setattr(sweep, "load_aggregates", lambda path, **kw: agg)
    figs = []
    draw = sweep.plot
    monkeypatch.setattr(sweep, "plot", lambda *a, **kw: figs.append(draw(*a, **kw)) or figs[-1])  # what it drew
    assert cli.main(["sweep", "summarize", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    header = next(line for line in printed.splitlines() if "distance_along (m)" in line)
    table = re.findall(r"(\w+) \(([^()]*)\)", header)  # the metric columns, "name (unit)"
    assert all(unit == sweep.UNITS[m] for m, unit in table), table
    columns = [m for m, _ in table]
    (fig,) = figs
    titles = [ax.get_title() for ax in fig.axes]
    rates = {"collided": "collision rate (rollouts touching an obstacle)", "fell": "fall rate (rollouts that fell)"}
    assert titles == [rates.get(m, f"{m.replace('_', ' ')} ({sweep.UNITS[m]})") for m in columns]
    assert columns == list(plots.summary_metrics(agg))
    assert ("footholds_near_obstacles" in columns) == near
    if kind == "mjx":
        assert columns[:3] == ["fell", "distance_along", "collided"]  # falls and contacts beside progress
