"""The safety margin vs. stepping-over sweep (sweeps/margin_stepping_over.toml, paper V.B).

The shipped file validates and declares the paper's geometry (a bar in the right foot's lane only,
full speed forward); a tiny run of it at m = 2 cm crosses short bars and stops at long ones, in
agreement with the bound b_max = 2 L - foot length - 2 m; the crossing metric and the plot.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from ijoy_jax import sweep
from ijoy_jax.terrain import generators
from ijoy_jax.terrain.objects import bar_crossings

FILE = Path(__file__).parents[1] / "sweeps" / "margin_stepping_over.toml"
HL, HW = 0.121, 0.065  # HRP-2's half foot length and width (m)


def test_shipped_file_declares_the_papers_stepping_over_geometry():
    cfg = sweep.load_config(FILE)
    assert cfg.family == "bars" and not cfg.has_height and cfg.swept == ("robot.margin", "terrain.width")
    assert cfg.terrain_params["lane"] == -1 and cfg.terrain_params["count"] == 1
    assert cfg.command == {"vx": (0.25, 0.25), "vy": (0.0, 0.0), "wz": (0.0, 0.0)}  # a 0.2 m target step
    margins, widths = cfg.grid["robot.margin"], cfg.grid["terrain.width"]
    assert {0.0, 0.02, 0.10} <= set(margins) and min(widths) <= 0.02 and max(widths) >= 0.16
    # The bar's cells span the right foot's whole lateral reach (its footprint, at most 0.19 m right
    # of the left foot's line, ends below start_y - 0.03 and starts below start_y - 0.16) down to the
    # map edge, and stay clear of the left foot's footprint grown by the largest margin.
    params = cfg.params_class(**cfg.terrain_params, width=0.1)
    t = generators.bars(0, params, shape=cfg.shape, resolution=cfg.resolution, max_count=cfg.static_max_count)
    rows = np.flatnonzero((~np.asarray(t.free)).any(axis=0))
    sy = float(generators.start_point(params, shape=cfg.shape, resolution=cfg.resolution)[1])
    assert rows.min() == 0 and (rows == np.arange(rows.max() + 1)).all()
    top = (rows.max() + 1) * cfg.resolution  # upper edge of the bar's cells
    assert sy - 0.16 < top <= sy + 0.095 - HW - max(margins) - 1e-6, (top, sy)
    # Jitter of +-5 cm: the bar's edge meets the 5 cm foothold lattice at every phase of the 2 cm grid.
    assert 2 * cfg.terrain_params["position_jitter"] >= 0.10
    assert cfg.num_scenarios >= 1000
    assert sweep.b_max(0.02) == pytest.approx(0.118) and sweep.b_max(0.10) < 0


def test_bar_crossings_metric():
    bar = np.array([[1.0, -3.0, np.pi / 2, 7.0, 0.1, 0.05], [0, 0, 0, 0, 0, 0]], np.float32)  # far face x = 1.05
    feet = lambda xl, xr: np.array([[xl, 0.7, 0.0], [xr, 0.5, 0.0]], np.float32)  # noqa: E731
    got = lambda f: {k: int(v) for k, v in bar_crossings(bar, f, 0.242, 0.13).items()}  # noqa: E731
    assert got(feet(1.2, 1.2)) == {"bars_crossed": 1, "crossed": 1}
    assert got(feet(1.05 + HL + 1e-3, 1.4)) == {"bars_crossed": 1, "crossed": 1}
    assert got(feet(1.4, 1.05 + HL - 1e-3)) == {"bars_crossed": 0, "crossed": 0}  # one foot's heel on it
    assert got(feet(0.6, 0.8)) == {"bars_crossed": 0, "crossed": 0}
    tilted = bar.copy()
    tilted[0, 2] = np.pi / 2 - 0.3  # the face recedes by tan(0.3) per metre of y below the bar's centre
    shift = (0.5 - (-3.0)) * np.tan(0.3)
    assert got(feet(1.4, 1.2))["crossed"] == 1
    assert bar_crossings(tilted, feet(1.4 + shift, 1.2 + shift), 0.242, 0.13)["crossed"]
    assert not bar_crossings(tilted, feet(1.4, 1.2), 0.242, 0.13)["crossed"]
    empty = np.zeros((2, 6), np.float32)
    assert bool(bar_crossings(empty, feet(0, 0), 0.242, 0.13)["crossed"])  # no bar: nothing to cross


@pytest.mark.slow
def test_short_bars_are_crossed_and_long_ones_are_not_at_a_2cm_margin(tmp_path):
    text = FILE.read_text()
    grid = '[grid]\n"terrain.width" = [0.02, 0.04, 0.12, 0.16]\n'
    text = re.sub(r"\[grid\].*", grid, text, flags=re.S)
    text = text.replace("[sweep]\n", "[robot]\nmargin = 0.02\n\n[sweep]\n", 1)
    text = re.sub(r"scenarios_per_cell = \d+", "scenarios_per_cell = 5", text)
    cfg = sweep.parse_config(text, str(tmp_path / "margin_small.toml"))
    stats = sweep.run(cfg, tmp_path / "out", progress=False)
    assert stats.scenarios == 20
    df = sweep.load(tmp_path / "out")
    assert {"crossed", "bars_crossed"} <= set(df.columns)
    assert set(generators.FAMILIES["bars"].metric_names) == {"crossed", "bars_crossed"}  # the registry's columns
    assert (df["footholds_on_obstacles"] == 0).all()
    bound = sweep.b_max(0.02)  # 0.118 m
    by_b = df.groupby("terrain.width")["crossed"].mean()
    # b + one cell of rasterisation + a full lattice step below the bound: always crossed.
    assert (by_b[[0.02, 0.04]] == 1.0).all(), by_b
    # above the bound: never (0.12 covers at least 12 cm of cells > 11.8 cm).
    assert (by_b[[0.12, 0.16]] == 0.0).all(), by_b
    assert bound < 0.12
    stuck = df[~df["crossed"]]
    assert (stuck["steps_stationary"] >= 4).all() and (stuck["distance_along"] < 0.8).all()
    agg = sweep.load_aggregates(tmp_path / "out")
    assert "crossed.mean" in agg and "crossed.ci95" in agg
    png = tmp_path / "summary.png"
    sweep.plot(agg, png, title="margin")
    assert Path(png).stat().st_size > 10_000
