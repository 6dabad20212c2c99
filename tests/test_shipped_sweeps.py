"""The sweep files shipped in sweeps/ are valid, hold the grids their comments and sweeps/README.md describe,
and run: a tiny slice of each perfect-robot sweep through ``sweep.run`` gives the documented metrics. The physics
sweeps (``walker = "mjx"``) are validated and their tables built here; running one compiles MJX for its 200 x 100
map (about a minute on a CPU), so the physics path is run at tiny shapes in tests/test_sweep_physics.py."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

import ijoy_jax as ij
import ijoy_jax.sim.model  # noqa: F401  (ij.sim.model)
import ijoy_jax.sim.physics  # noqa: F401  (ij.sim.physics)
from ijoy_jax import sweep

DIR = Path(__file__).parents[1] / "sweeps"
SWEEPS = sorted(DIR.glob("*.toml"))

# What each file's comments and sweeps/README.md say it is: swept grid, family, sizes, scenario count.
EXPECTED = {
    "w_sweep.toml": dict(
        grid={"robot.w": (0.0, 0.1, 0.3, 1.0, 2.0, 3.0, 5.0, 10.0)}, family="rough", has_height=True,
        shape=(150, 100), resolution=0.02, scenarios_per_cell=64, num_steps=20, method="ordered",
        num_scenarios=512, extra_metrics=()),
    "action_set_size.toml": dict(
        grid={"robot.density": (0.4, 0.5, 0.75, 1.0, 1.5, 2.0)}, family="obstacles", has_height=False,
        shape=(150, 100), resolution=0.02, scenarios_per_cell=32, num_steps=16, method="ordered",
        num_scenarios=192, extra_metrics=()),
    "margin_stepping_over.toml": dict(
        grid={"robot.margin": (0.0, 0.02, 0.04, 0.06, 0.08, 0.10),
              "terrain.width": tuple(round(0.01 * i, 2) for i in range(1, 17))},
        family="bars", has_height=False, shape=(120, 60), resolution=0.02, scenarios_per_cell=40, num_steps=10,
        method="ordered", num_scenarios=6 * 16 * 40, extra_metrics=("bars_crossed", "crossed")),
    "margin_physics.toml": dict(
        grid={"robot.margin": tuple(round(0.01 * i, 2) for i in range(11))}, family="obstacles", has_height=False,
        shape=(200, 100), resolution=0.02, scenarios_per_cell=256, num_steps=16, method="ordered",
        num_scenarios=11 * 256, extra_metrics=(), walker="mjx"),
    "margin_vs_execution_error.toml": dict(
        grid={"robot.margin": (0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.10),
              "sim.stance_noise": (0.0, 0.01, 0.02, 0.04)}, family="obstacles", has_height=True,
        shape=(200, 100), resolution=0.02, scenarios_per_cell=128, num_steps=16, method="ordered",
        num_scenarios=9 * 4 * 128, extra_metrics=(), walker="mjx"),
    "stairs_physics.toml": dict(
        grid={"terrain.rise": (-0.15, -0.125, -0.10, -0.075, -0.05, 0.05, 0.075, 0.10, 0.125, 0.15),
              "terrain.run": (0.30, 0.40), "sim.stance_noise": (0.0, 0.005, 0.01)},
        family="stairs", has_height=True, shape=(300, 100), resolution=0.02, scenarios_per_cell=64, num_steps=16,
        method="ordered", num_scenarios=10 * 2 * 3 * 64, extra_metrics=(), walker="mjx"),
    "rough_robustness.toml": dict(
        grid={"terrain.amplitude": (0.01, 0.02, 0.03), "robot.w": (1.0, 2.0, 4.0),
              "robot.metrics.support_limit": (0.015, 0.025, 0.04)},
        family="rough", has_height=True, shape=(250, 100), resolution=0.02, scenarios_per_cell=256, num_steps=30,
        method="ordered", num_scenarios=27 * 256, extra_metrics=(), walker="mjx"),
}
_SELECTORS = {"selector.horizon": (1, 2, 3), "selector.refine": (False, True)}
for _fam, _family in (("stones", "stone_path"), ("corridor", "corridor"), ("clutter", "obstacles"),
                      ("walls", "walls")):
    # The lookahead comparisons (issue #25): only the stones' slice is run below (each is one more compile of a
    # 200 x 100 map; the four differ only in the terrain family).
    EXPECTED[f"lookahead_{_fam}.toml"] = dict(
        grid=_SELECTORS, family=_family, has_height=False, shape=(200, 100), resolution=0.02,
        scenarios_per_cell=64, num_steps=16, method="lookahead", num_scenarios=6 * 64, extra_metrics=(),
        run=_fam == "stones")
PERFECT = sorted(n for n, e in EXPECTED.items() if e.get("walker", "perfect") == "perfect" and e.get("run", True))
PHYSICS = sorted(n for n, e in EXPECTED.items() if e.get("walker") == "mjx" and "robot.margin" in e["grid"])


def test_every_shipped_sweep_is_described_here_and_in_the_readme():
    assert {p.name for p in SWEEPS} == set(EXPECTED)
    readme = (DIR / "README.md").read_text()
    for name in EXPECTED:
        assert f"`{name}`" in readme, name


# A sweep file's run line: its scenarios (what sweep.scenarios expands), steps per rollout, and what running it
# costs, which sweeps/README.md's row for the file states alike (the README's figures are the measured ones).
RUN_LINE = re.compile(r"^# Run: +ijoy sweep run sweeps/(?P<file>\S+) +\((?P<n>\d+) (?:simulated )?rollouts of "
                      r"(?P<steps>\d+) steps(?:; (?P<cost>[^)]+))?\)$", re.M)
# A run time stated anywhere else in a file's comments ("about a minute", "About 2 minutes", "~10 s").
OTHER_TIME = re.compile(r"(?i)(?:\babout|~) *(?:a|\d+(?:\.\d+)?) *(?:s|sec|seconds?|min|minutes?|h|hours?)\b")


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_shipped_sweeps_stated_size_and_run_time_are_the_readmes(name):
    """Each file's comments state its scenario count and steps as the sweep expands them, and its run time (if
    any) only on its run line, in the words of sweeps/README.md's row for it."""
    text = (DIR / name).read_text()
    comments = "\n".join(line for line in text.splitlines() if line.startswith("#"))
    runs = list(RUN_LINE.finditer(comments))
    assert len(runs) == 1, f"{name}: no '# Run: ijoy sweep run sweeps/{name}  (N rollouts of S steps; ...)' line"
    (run,) = runs
    cfg = sweep.load_config(DIR / name)
    assert run["file"] == name
    assert (int(run["n"]), int(run["steps"])) == (len(sweep.scenarios(cfg)), cfg.num_steps)
    assert OTHER_TIME.findall(RUN_LINE.sub("", comments)) == [], name
    (row,) = [line for line in (DIR / "README.md").read_text().splitlines()
              if line.startswith("|") and f"`{name}`" in line]
    assert f"{run['n']} rollouts of {run['steps']} steps" in row, name
    assert run["cost"] is None or run["cost"] in row, (name, run["cost"])
    assert run["cost"] is not None or not OTHER_TIME.findall(row), f"{name}: the README states a run time"


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_shipped_sweep_validates_with_its_documented_grid(name):
    want = EXPECTED[name]
    cfg = sweep.load_config(DIR / name)
    assert cfg.name == name.removesuffix(".toml") and cfg.description
    assert cfg.swept == tuple(want["grid"])
    for k, values in want["grid"].items():
        np.testing.assert_allclose(cfg.grid[k], values, rtol=1e-12, err_msg=k)
    for field in ("family", "has_height", "shape", "resolution", "scenarios_per_cell", "num_steps", "method",
                  "num_scenarios"):
        assert getattr(cfg, field) == want[field], field
    assert cfg.walker == want.get("walker", "perfect")
    assert cfg.kernel == "xla"  # runs on a CPU as shipped (the README says to add pallas on a GPU)
    if cfg.method == "lookahead":
        assert cfg.beam == 16 and cfg.discount == 1.0  # the three-step beam of docs/lookahead.md


def test_action_set_sizes_span_fifty_to_thousands_around_the_papers_496():
    cfg = sweep.load_config(DIR / "action_set_size.toml")
    assert cfg.swept == ("robot.density",)
    sizes = [ij.robots.hrp2(density=d).num_actions for d in cfg.grid["robot.density"]]
    assert sizes == [52, 117, 202, 496, 1279, 3307]


def test_margin_sweep_brackets_the_papers_bound():
    """b_max(m) = 0.158 - 2 m: 11.8 cm at 2 cm, 0 from 7.9 cm; the bar lengths straddle it at every margin."""
    cfg = sweep.load_config(DIR / "margin_stepping_over.toml")
    assert sweep.b_max(0.02) == pytest.approx(0.118, abs=1e-3) and sweep.b_max(0.08) <= 0
    widths = np.array(cfg.grid["terrain.width"])
    for m in cfg.grid["robot.margin"]:
        b = sweep.b_max(m)
        assert widths.max() > b and (b <= 0 or widths.min() < b), m


@pytest.mark.parametrize("name", PHYSICS)
def test_physics_sweeps_cross_the_margin_with_the_simulated_robots_errors(name):
    """0 to 10 cm of margin (the paper's 2 cm and 10 cm included); every scenario's physics in its table: the
    nominal robot, except for the stance noise swept against the margin; the same map, command and noise draws
    for replicate r in every cell."""
    cfg = sweep.load_config(DIR / name)
    margins = cfg.grid["robot.margin"]
    assert margins[0] == 0.0 and margins[-1] == 0.10 and {0.02, 0.10} <= set(margins)
    table = sweep.scenarios(cfg)
    for k in ("friction", "mass_scale", "kp_scale", "latency", "push"):
        assert (table[f"sim.{k}"] == getattr(ij.sim.physics.NOMINAL, k)).all(), k
    noise = table["sim.stance_noise"].unique().tolist()
    assert noise == ([0.0] if name == "margin_physics.toml" else [0.0, 0.01, 0.02, 0.04])
    per_cell = cfg.scenarios_per_cell
    first, last = table.iloc[:per_cell], table.iloc[-per_cell:]
    for c in ("command.vx", "command.vy", "command.wz", "replicate"):
        assert first[c].tolist() == last[c].tolist(), c


# MuJoCo Playground's humanoid randomisation, as issue #48 and rough_robustness.toml's comments state it
PLAYGROUND = {"friction": (0.4, 1.0), "mass_scale": (0.9, 1.1), "kp_scale": (0.9, 1.1), "latency": (0.0, 0.02),
              "push": (0.0, 10.0)}


def test_the_robustness_sweep_draws_playgrounds_dynamics_per_replicate_alike_in_every_cell():
    cfg = sweep.load_config(DIR / "rough_robustness.toml")
    table = sweep.scenarios(cfg)
    assert len(table) == 27 * 256
    by_cell = table.sort_values(["cell", "replicate"])
    for k, (lo, hi) in PLAYGROUND.items():
        v = by_cell[f"sim.{k}"].to_numpy().reshape(27, 256)
        assert lo <= v.min() and v.max() <= hi, k
        assert v.max() - v.min() > 0.9 * (hi - lo), k  # spread over the range, not a fixed value
        np.testing.assert_array_equal(v, np.broadcast_to(v[0], v.shape), err_msg=k)  # replicate r alike
    assert (table["sim.stance_noise"] == 0).all()
    assert set(table["command.vx"]) == {0.25} and set(table["command.vy"]) == {0.0}


def test_the_robustness_sweeps_perfect_robot_copy_is_the_one_its_comment_describes():
    """rough_robustness.toml says the perfect robot walks the same maps in a copy with ``walker = "perfect"`` and
    no [sim] table: that copy loads and gives the same scenarios without the dynamics, and the copy with [sim]
    kept is refused, naming the walker (so the comment's recipe is the one that works)."""
    text = (DIR / "rough_robustness.toml").read_text()
    perfect = re.sub(r'^walker = "mjx"', 'walker = "perfect"', text, count=1, flags=re.M)
    assert perfect != text
    with pytest.raises(ValueError, match=r"sim\.friction.*walker = .mjx."):
        sweep.parse_config(perfect)
    no_sim = re.sub(r"^\[sim\].*?(?=^\[grid\])", "", perfect, count=1, flags=re.M | re.S)
    assert not re.search(r"^\[sim\]", no_sim, flags=re.M)
    mjx, copy = sweep.scenarios(sweep.load_config(DIR / "rough_robustness.toml")), sweep.scenarios(
        sweep.parse_config(no_sim))
    assert len(copy) == len(mjx) == 27 * 256
    shared = [c for c in mjx.columns if not c.startswith("sim.") and c in copy.columns]
    assert {"terrain.amplitude", "robot.w", "robot.metrics.support_limit", "replicate", "command.vx"} <= set(shared)
    for c in shared:
        assert mjx[c].tolist() == copy[c].tolist(), c
    assert not any(c.startswith("sim.") for c in copy.columns)  # no dynamics drawn for the perfect robot


def test_stairs_sweep_walks_the_longer_reach_past_the_top_riser_and_within_the_map():
    """What stairs_physics.toml's comments say: HRP-2 at reach 0.30 (720 actions, 15 cm risers), refined, held
    forward at one 0.30 m step per 0.8 s; 16 steps carry it past the top riser of every stair (two steps per
    0.40 m tread), and its front foot stays clear of the map's far end; treads jittered per replicate (64
    different stairs per cell)."""
    cfg = sweep.load_config(DIR / "stairs_physics.toml")
    assert cfg.robot == {"reach": 0.30} and cfg.refine and cfg.terrain_params["run_jitter"] == 0.01
    robot = sweep.scenario(cfg, 0).robot
    assert robot.num_actions == 720 and float(np.max(robot.max_step_height)) == pytest.approx(0.15)
    assert cfg.command["vx"] == (0.375, 0.375) and 0.375 * 0.8 == pytest.approx(0.30)
    start = cfg.terrain_params["start_x"] * cfg.shape[0] * cfg.resolution
    p = cfg.terrain_params
    last_riser = p["first"] + (p["num_steps"] - 1) * (max(cfg.grid["terrain.run"]) + p["run_jitter"])
    farthest = cfg.num_steps * 0.30 + robot.foot_length / 2  # the front of a foot after 12 of the longest steps
    # before the first riser at most 0.30 m a step, then two steps per 0.40 m tread, and one onto the top
    steps_needed = math.ceil(p["first"] / 0.30) + 2 * p["num_steps"] + 1
    assert steps_needed <= cfg.num_steps and last_riser < cfg.num_steps * 0.30
    assert start + farthest < cfg.shape[0] * cfg.resolution - 0.35
    # 15 cm x 6 risers stay inside the simulated height field
    assert max(cfg.grid["terrain.rise"]) * p["num_steps"] <= ij.sim.model.BipedParams.z_hi


# Each shipped file compiles its own program: the fast tier runs one, the slow tier the others.
FAST_SLICE = "margin_stepping_over.toml"
assert FAST_SLICE in PERFECT, "the fast tier runs one shipped sweep: name one that runs"


@pytest.mark.parametrize("name", [n if n == FAST_SLICE else pytest.param(n, marks=pytest.mark.slow) for n in PERFECT])
def test_a_tiny_slice_of_the_shipped_sweep_runs(name, tmp_path):
    cfg = sweep.load_config(DIR / name)
    stats = sweep.run(cfg, tmp_path / "o", chunk_size=2, max_scenarios=2, progress=False)
    assert (stats.computed, stats.chunks) == (2, 1)
    df = sweep.load(tmp_path / "o", partial=True)
    assert len(df) == 2
    for m in sweep.METRICS + EXPECTED[name]["extra_metrics"]:
        assert m in df.columns and df[m].notna().all(), m
    assert (df["steps_taken"] > 0).all() and (df["distance_along"] > 0).all()  # they walked
    assert (df["steps_taken"] <= cfg.num_steps).all()


# --------------------------------------------------------------------------------------------- the walk sweeps

WALK_SWEEPS = sorted((DIR / "walk").glob("*.toml"))


def test_the_walk_sweeps_are_one_per_family_and_command_kind_and_in_the_readme():
    """``ijoy bench walk`` runs sweeps/walk/<family>_<commands>.toml: one per walk family and command kind."""
    from ijoy_jax.terrain import walk_families

    want = {f"{f}_{c}.toml" for f in walk_families.FAMILIES for c in ("random", "forward")}
    assert {p.name for p in WALK_SWEEPS} == want
    assert "`walk/<family>_<commands>.toml`" in (DIR / "README.md").read_text()



def test_the_walk_sweeps_ship_inside_the_package():
    """``ijoy bench walk`` finds its files in an installed package, not only in a checkout: they are package data
    (the wheel's ``ijoy_jax/apps/walk_sweeps``, declared in pyproject's package-data), and the checkout's
    sweeps/walk is that same folder."""
    import tomllib

    from ijoy_jax.apps import bench_walk

    package = Path(bench_walk.__file__).resolve().parent
    assert bench_walk.SWEEPS.resolve().parent == package
    # the checkout's sweeps/walk and the imported package's files are the same (an installed copy included)
    assert sorted(p.name for p in bench_walk.SWEEPS.glob("*.toml")) == [p.name for p in WALK_SWEEPS]
    assert all((bench_walk.SWEEPS / p.name).read_bytes() == p.read_bytes() for p in WALK_SWEEPS)
    assert (DIR / "walk").is_symlink()
    pyproject = tomllib.loads((DIR.parent / "pyproject.toml").read_text())
    globs = pyproject["tool"]["setuptools"]["package-data"]["ijoy_jax.apps"]
    assert any(Path(bench_walk.SWEEPS.name, "x.toml").match(g) for g in globs)
    assert bench_walk.sweep_file("flat", "random") == bench_walk.SWEEPS / "flat_random.toml"

@pytest.mark.parametrize("path", WALK_SWEEPS, ids=lambda p: p.stem)
def test_walk_sweep_says_what_ijoy_bench_walk_runs(path):
    """The family's maps at 2 cm, 1024 robots x 30 steps of the ordered selector with the MJX biped, the random or
    held forward command (the family's own speed and reach where it has them), nothing swept."""
    from ijoy_jax.apps import bench_walk
    from ijoy_jax.terrain import walk_families

    family, _, kind = path.stem.rpartition("_")
    fam = walk_families.FAMILIES[family]
    cfg = sweep.load_config(path)
    assert cfg.name == f"walk_{path.stem}" and cfg.description and cfg.walk == family and cfg.walker == "mjx"
    assert (cfg.scenarios_per_cell, cfg.num_steps, cfg.method, cfg.seed, cfg.kernel, cfg.refine) == (
        1024, 30, "ordered", 0, "xla", False)
    assert cfg.shape == walk_families.grid_shape() and cfg.resolution == walk_families.RESOLUTION
    assert cfg.robot == ({} if fam.reach is None else {"reach": fam.reach})
    assert cfg.grid == {} and cfg.random == {} and cfg.sim == {} and cfg.num_scenarios == 1024
    if kind == "random":
        assert cfg.random_commands and cfg.command == {}
    else:
        speed = bench_walk.FORWARD if fam.forward is None else fam.forward
        assert not cfg.random_commands and cfg.command == {"vx": (speed, speed), "vy": (0.0, 0.0), "wz": (0.0, 0.0)}


@pytest.mark.slow
@pytest.mark.parametrize("path", [p for p in WALK_SWEEPS if p.stem.endswith("_random")], ids=lambda p: p.stem)
def test_a_tiny_slice_of_each_walk_sweep_runs(path, tmp_path):
    """One robot, two steps, the perfect robot (each family's chunk program compiles once: the slow tier; the MJX
    biped on two of them runs in tests/test_bench_walk.py)."""
    text = sweep.set_values(path.read_text(), {"sweep.walker": "perfect", "sweep.num_steps": 2,
                                               "sweep.scenarios_per_cell": 1})
    stats = sweep.run(sweep.parse_config(text, str(path)), tmp_path / "o", progress=False)
    assert stats.complete and stats.computed == 1
    df = sweep.load(tmp_path / "o")
    for m in sweep.METRICS + sweep.WALK_METRICS:
        assert m in df.columns and df[m].notna().all(), m
    assert (df["steps_made"] <= 2).all() and (df["steps_made"] == df["steps_taken"]).all()
