"""The sweep files shipped in sweeps/ are valid and say what their comments claim."""

from pathlib import Path

import pytest

import ijoy_jax as ij
from ijoy_jax import sweep

SWEEPS = sorted((Path(__file__).parents[1] / "sweeps").glob("*.toml"))


def test_there_are_shipped_sweeps():
    assert {p.name for p in SWEEPS} >= {"w_sweep.toml", "action_set_size.toml"}


@pytest.mark.parametrize("path", SWEEPS, ids=[p.name for p in SWEEPS])
def test_shipped_sweep_validates(path):
    cfg = sweep.load_config(path)
    assert cfg.num_scenarios >= 100


def test_action_set_sizes_span_fifty_to_thousands_around_the_papers_496():
    cfg = sweep.load_config(Path(__file__).parents[1] / "sweeps" / "action_set_size.toml")
    assert cfg.swept == ("robot.density",)
    sizes = [ij.robots.hrp2(density=d).num_actions for d in cfg.grid["robot.density"]]
    assert sizes == [52, 117, 202, 496, 1279, 3307]
