"""``[sweep] model`` (ijoy_jax/sweep/models.py): the robot a sweep walks, HRP-2 ("biped") or the Unitree G1 ("g1").

The schema refuses any other model and the keys of HRP-2's options with the G1, naming the file, the key and the
reason (as every sweep key's refusals do, tests/test_sweep.py); a G1 sweep's scenarios hold the G1's values and
rebuild ``robots.g1()`` leaf for leaf; a run walks it and records it (``sweep.toml``, the manifest's robot). The
runs compile the perfect robot's chunk program (a few seconds on a CPU); the MJX one compiles the G1's
simulated rollout (slow tier, about a minute).
"""

import json
import re

import numpy as np
import pytest
from _sweep_util import refused_by  # tests/ is on sys.path (pytest rootdir import)
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import robots, sweep
from ijoy_jax.sweep import models

BASE = """[sweep]
model = "g1"
scenarios_per_cell = 2
num_steps = 3
method = "ordered"

[terrain]
family = "obstacles"
shape = [100, 80]

[command]
vx = 0.25
"""
LEAF_TOL = 1e-6
"""A robot leaf is float32: the table's float64 value, rounded once."""


def parse(text, source="g1.toml"):
    return sweep.parse_config(text, source)


def refused(text, key, reason):
    return refused_by("g1.toml", text, key, reason)


# --------------------------------------------------------------------------------------------- the schema


def test_the_model_is_read_and_biped_is_the_default():
    assert parse(BASE).model == "g1"
    assert parse(BASE.replace('model = "g1"', 'model = "biped"')).model == "biped"
    assert parse(BASE.replace('model = "g1"\n', "")).model == "biped" == sweep.SweepConfig.model
    assert sweep.MODELS == ("biped", "g1")


def test_the_models_are_the_simulators():
    """The sweep's model names are those make_sim takes (``BipedParams.model``)."""
    from ijoy_jax.sim import model

    assert sweep.MODELS == model.MODELS


@pytest.mark.parametrize("value, reason", [
    ('"hrp2"', "must be one of biped, g1, got 'hrp2'"),
    ('"G1"', "must be one of biped, g1, got 'G1'"),
    ('""', "must be one of biped, g1, got ''"),
    ("1", "must be a string, got int 1"),
    ("true", "must be a string, got bool True"),
    ('["g1"]', "must be a string, got list"),
])
def test_a_bad_model_is_refused_naming_the_allowed_ones(value, reason):
    refused(BASE.replace('model = "g1"', f"model = {value}"), "sweep.model", re.escape(reason))


@settings(max_examples=40, deadline=None)
@given(name=st.text(st.characters(blacklist_categories=("Cs",)), max_size=12).filter(lambda n: n not in sweep.MODELS))
def test_any_other_model_name_is_refused_by_name(name):
    refused(sweep.set_values(BASE, {"sweep.model": name}), "sweep.model", "must be one of biped, g1")


HRP2_REACH = r"reach is an option of HRP-2's action set \(robots\.hrp2\(reach=\.\.\.\)\), not the G1's"


@pytest.mark.parametrize("extra, key", [
    ("[robot]\nreach = 0.3\n", "robot.reach"),
    ("[robot]\nreach = 0.2\n", "robot.reach"),  # even the G1's own dx range: the key is HRP-2's
    ('[grid]\n"robot.reach" = [0.2, 0.3]\n', "grid.robot.reach"),
    ('[random]\n"robot.reach" = [0.2, 0.3]\n', "random.robot.reach"),
])
def test_hrp2s_options_are_refused_with_the_g1(extra, key):
    text = BASE.replace("num_steps = 3", "num_steps = 3\nrandom_samples = 2") if "random" in extra else BASE
    refused(text + extra, key, HRP2_REACH)


def test_hrp2_takes_its_reach():
    cfg = parse(BASE.replace('model = "g1"', 'model = "biped"') + "[robot]\nreach = 0.3\n")
    assert cfg.robot == {"reach": 0.3} and sweep.scenario(cfg, 0).robot.actions.shape == (720, 3)


def test_the_simulated_g1_keeps_its_own_feet():
    """With walker = "mjx" the G1 walks on its MJCF's foot boxes: another footprint is refused, its own accepted;
    the perfect robot may take any."""
    mjx = BASE.replace('model = "g1"', 'model = "g1"\nwalker = "mjx"')
    refused(mjx + "[robot]\nfoot_length = 0.2\n", "robot.foot_length", r"must be the G1's 0\.18 m with model")
    refused(mjx + "[robot]\nfoot_width = 0.13\n", "robot.foot_width", r"must be the G1's 0\.06 m with model")
    assert parse(mjx + "[robot]\nfoot_length = 0.18\nfoot_width = 0.06\n").walker == "mjx"
    assert parse(BASE + "[robot]\nfoot_length = 0.2\n").robot == {"foot_length": 0.2}


def test_the_simulated_g1_must_stand_on_the_map_at_its_own_width():
    """The start check stands the simulated robot at its model's step in place, the G1's 0.24 m: on a 0.28 m wide
    map the G1 (0.30 m of ground across its soles) is refused, the biped with the same feet at HRP-2's 0.19 m
    (0.25 m) is not."""
    assert models.step_in_place("g1") == robots.G1_P0[1] == 0.24 and models.step_in_place("biped") == 0.19
    text = """[sweep]
model = "g1"
walker = "mjx"

[terrain]
family = "flat"
shape = [100, 14]
has_height = true

[terrain.params]
start_radius = 0.05

[robot]
foot_length = 0.18
foot_width = 0.06
"""
    refused(text, "terrain.shape", r"needs \[0\.21, 0\.39\] x \[-0\.01, 0\.29\] m of ground, beyond the 2 x 0\.28 m")
    assert parse(text.replace('model = "g1"', 'model = "biped"')).model == "biped"


# --------------------------------------------------------------------------------------------- the robot


def test_a_g1_sweeps_scenarios_hold_the_g1s_values_and_rebuild_robots_g1():
    cfg = parse(BASE)
    table = sweep.scenarios(cfg)
    defaults = robots.g1_defaults()
    for k, v in models.robot_defaults("g1").items():
        assert (table[f"robot.{k}"] == v).all(), k
        assert v == defaults.get(k, robots.PAPER_REACH), k
    assert table["robot.foot_length"].iloc[0] == 0.18 and table["robot.max_sole_distance"].iloc[0] == 0.48
    want = robots.g1()
    for sid in range(cfg.num_scenarios):
        s = sweep.scenario(cfg, sid)
        np.testing.assert_array_equal(np.asarray(s.robot.actions), np.asarray(want.actions))
        np.testing.assert_array_equal(np.asarray(s.robot.p0), np.asarray(want.p0))
        for name in robots.SCALAR_LEAVES:
            np.testing.assert_allclose(float(robots.get_leaf(s.robot, name)), float(robots.get_leaf(want, name)),
                                       atol=LEAF_TOL, err_msg=name)
        assert abs(s.start[0, 1] - s.start[1, 1] - robots.G1_P0[1]) < LEAF_TOL  # side by side at its width
    hrp2 = sweep.scenarios(parse(BASE.replace('model = "g1"\n', "")))
    assert hrp2["robot.foot_length"].iloc[0] == 0.242  # HRP-2's as before


def test_the_models_actions_and_robots_are_the_robots_modules():
    for density in (0.5, 1.0, 2.0):
        np.testing.assert_array_equal(models.actions("g1", density), robots.g1_actions(density))
        np.testing.assert_array_equal(models.actions("biped", density, 0.3), robots.hrp2_actions(density, 0.3))
    assert models.build_robot("biped", reach=0.3).actions.shape == (720, 3)
    assert models.build_robot("g1", reach=robots.PAPER_REACH).actions.shape == (496, 3)
    with pytest.raises(ValueError, match="robots.g1 takes no reach"):
        models.build_robot("g1", reach=0.3)
    with pytest.raises(ValueError, match="model must be one of biped, g1, got 'hrp2'"):
        models.robot_defaults("hrp2")
    assert "reach" not in models.robot_keys("g1") and models.robot_keys("biped") == tuple(sweep.ROBOT_DEFAULTS)
    assert sweep.action_counts([0.5, 1.0], model="g1").tolist() == [117.0, 496.0]


def test_a_trace_files_commands_are_read_through_the_g1(tmp_path):
    """A trace's stick is read through the sweep's robot's command range and step time: the G1's (built by
    models.build_robot, as every robot of a sweep), whose range is HRP-2's (the same lattice shifted to its
    wider stance) in its shorter step time."""
    trace = tmp_path / "drive.csv"
    trace.write_text("t,forward,left,turn\n0.0, 1.0, 0.5, -0.3\n2.0, 0.0, 0.0, 0.0\n")
    text = BASE.replace("num_steps = 3\n", "").replace("[command]\nvx = 0.25\n", '[command]\nfile = "drive.csv"\n')
    cfg = sweep.parse_config(text, str(tmp_path / "g1.toml"))
    want = sweep.recorded.read_commands(trace, robots.g1())
    np.testing.assert_array_equal(cfg.command_steps, want.commands)
    assert cfg.model == "g1" and len(want.commands) == cfg.num_steps >= 2
    ratio = float(robots.hrp2().step_time) / float(robots.g1().step_time)  # 0.8 s / 0.5 s
    np.testing.assert_allclose(np.asarray(robots.command_range(robots.g1())),
                               ratio * np.asarray(robots.command_range(robots.hrp2())), rtol=1e-6)


# --------------------------------------------------------------------------------------------- runs


def test_a_g1_sweep_with_the_perfect_robot_walks_the_g1_and_records_it(tmp_path):
    """The G1's 18 cm feet in the results, its 496 actions in the manifest, the model in sweep.toml; its walks are
    those of ``rollout`` with ``robots.g1()`` from the scenarios' starts."""
    import ijoy_jax as ij

    cfg = parse(BASE)
    stats = sweep.run(cfg, tmp_path / "g1", progress=False)
    assert stats.complete
    df = sweep.load(tmp_path / "g1")
    assert len(df) == 2 and (df["robot.foot_length"] == 0.18).all() and (df["robot.foot_width"] == 0.06).all()
    manifest = json.loads((tmp_path / "g1" / "manifest.json").read_text())
    assert manifest["robot"] == {"model": "g1", "name": "the Unitree G1", "actions": {"1": 496}}
    assert sweep.load_config(tmp_path / "g1" / "sweep.toml").model == "g1"
    for sid in range(2):
        s = sweep.scenario(cfg, sid)
        traj = ij.rollout(s.terrain, robots.g1(), s.start, s.command, cfg.num_steps, ij.SelectOptions(method="ordered"))
        summary = traj.summary()
        assert float(summary["distance_along"]) == pytest.approx(df["distance_along"].iloc[sid], abs=1e-5)
        assert int(summary["steps_taken"]) == df["steps_taken"].iloc[sid]


@pytest.mark.slow
def test_a_tiny_mjx_sweep_walks_the_simulated_g1_and_records_it(tmp_path):
    """Two G1s, three steps on flat ground in MJX: the simulated robot is Menagerie's G1 (its pelvis height and
    model name), the results hold the physics columns and the G1's feet, the folder records the model."""
    from ijoy_jax.sim import walker

    text = (BASE.replace('model = "g1"', 'model = "g1"\nwalker = "mjx"')
            .replace('family = "obstacles"', 'family = "flat"\nhas_height = true'))
    cfg = parse(text)
    table = sweep.scenarios(cfg)
    sim = sweep.programs.make_sim(cfg, table)
    assert sim.params.model == "g1" and sim.params.foot_length == 0.18
    before = walker.compiled_programs()
    stats = sweep.run(cfg, tmp_path / "mjx", progress=False)
    assert stats.complete and walker.compiled_programs() == before + 1
    df = sweep.load(tmp_path / "mjx")
    assert len(df) == 2 and set(sweep.PHYSICS_METRICS) <= set(df.columns)
    assert (df["robot.foot_length"] == 0.18).all() and not df["fell"].any() and (df["steps_taken"] == 3).all()
    assert np.all(df["placement_error_mean"] < 0.05)
    manifest = json.loads((tmp_path / "mjx" / "manifest.json").read_text())
    assert manifest["robot"]["model"] == "g1" and manifest["robot"]["actions"] == {"1": 496}
    assert 'model = "g1"' in (tmp_path / "mjx" / "sweep.toml").read_text()
