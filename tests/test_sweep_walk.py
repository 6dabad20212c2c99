"""The walking benchmark's terrains and commands in a sweep file: ``[terrain] walk``, ``[command] random``, the walk
metrics (:data:`ijoy_jax.sweep.WALK_METRICS`) and :func:`ijoy_jax.sweep.set_values`.

The schema's refusals name the file, the key and the reason (as every sweep key's do, tests/test_sweep.py); the
random commands are NumPy's generator of each replicate mapped onto the action set's range, the same in every cell;
a run's replicate r walks the walk family's map ``maps(key(seed), B)[r]``. The runs compile the perfect robot's
chunk program (slow tier); the table built from them is tests/test_bench_walk.py's.
"""


import jax
import numpy as np
import pytest
from _sweep_util import refused_by  # tests/ is on sys.path (pytest rootdir import)
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import robots, sweep
from ijoy_jax.sweep import programs
from ijoy_jax.terrain import walk_families as WF

BASE = """[sweep]
scenarios_per_cell = 3
num_steps = 4
method = "ordered"

[terrain]
walk = "rough"

[command]
random = true
"""
COMMAND_TOL = 1e-6
"""m/s: the commands are float32 (lo + u (hi - lo) rounded once)."""


def parse(text, source="walk.toml"):
    return sweep.parse_config(text, source)


def refused(text, key, reason):
    return refused_by("walk.toml", text, key, reason)


# --------------------------------------------------------------------------------------------- the schema


def test_walk_and_random_parse_into_the_config():
    cfg = parse(BASE)
    assert cfg.walk == "rough" and cfg.family is None and cfg.terrain_recording is None
    assert cfg.shape == WF.grid_shape() == (250, 100) and cfg.resolution == WF.RESOLUTION and cfg.has_height
    assert cfg.random_commands and cfg.command == {} and cfg.command_columns == ()
    assert cfg.terrain_fields == () and cfg.terrain_params == {}
    table = sweep.scenarios(cfg)
    assert len(table) == 3 and not [c for c in table.columns if c.startswith(("command.", "terrain."))]
    coarse = parse(BASE.replace('walk = "rough"', 'walk = "stones"\nresolution = 0.04'))
    assert coarse.walk == "stones" and coarse.shape == (125, 50) and coarse.resolution == 0.04
    held = parse(BASE.replace("random = true", "random = false\nvx = 0.1"))
    assert not held.random_commands and held.command_columns == sweep.COMMAND_KEYS
    assert held.command["vx"] == (0.1, 0.1) and "command.vx" in sweep.scenarios(held)


@pytest.mark.parametrize("old, new, key, reason", [
    ('walk = "rough"', 'walk = "lava"', "terrain.walk", "must be one of flat, clutter2d"),
    ('walk = "rough"', "walk = 3", "terrain.walk", "must be a string"),
    ('walk = "rough"', 'walk = "rough"\nfamily = "rough"', "terrain.family", "only terrain.resolution goes with it"),
    ('walk = "rough"', 'walk = "rough"\nshape = [250, 100]', "terrain.shape", "only terrain.resolution"),
    ('walk = "rough"', 'walk = "rough"\nhas_height = true', "terrain.has_height", "only terrain.resolution"),
    ('walk = "rough"', 'walk = "rough"\nmax_count = 4', "terrain.max_count", "only terrain.resolution"),
    ('walk = "rough"', 'walk = "rough"\nrecording = "d.mcap"', "terrain.recording", "only terrain.resolution"),
    ('walk = "rough"', 'walk = "rough"\n[terrain.params]\namplitude = 0.02', "terrain.params",
     "only terrain.resolution"),
    ('walk = "rough"', 'walk = "rough"\nresolution = 0.03', "terrain.resolution", "whole cells"),
    ('walk = "rough"', 'walk = "rough"\nresolution = 0.002', "terrain.resolution", r"must be >= 0\.005"),
    ('walk = "rough"', 'walk = "rough"\nresolution = "fine"', "terrain.resolution", "must be a number"),
    ('walk = "rough"', 'walk = "rough"\nresolution = -0.02', "terrain.resolution", r"must be >= 0\.005"),
    ("random = true", 'random = true\n[grid]\n"terrain.amplitude" = [0.01]', "grid.terrain.amplitude",
     r"not \[terrain\] walk"),
    ("random = true", "random = 1", "command.random", "must be true or false"),
    ("random = true", 'random = "yes"', "command.random", "must be true or false"),
    ("random = true", "random = true\nvx = 0.2", "command.vx", "drawn every step"),
    ("random = true", 'random = true\nfile = "d.csv"', "command.file", "drawn every step"),
    ("random = true", "random = true\ndeadzone = 0.1", "command.deadzone", "drawn every step"),
    ("random = true", "randm = true", "command.randm", "unknown key"),
    ('method = "ordered"', 'method = "ordered"\nwalker = "mjx"\n[sim]\nfriction = 0.8\n[terrain.x]\n',
     "terrain.x", "unknown key"),
])
def test_bad_walk_and_random_keys_name_file_key_and_reason(old, new, key, reason):
    assert old in BASE
    refused(BASE.replace(old, new, 1), key, reason)


def test_a_simulated_walk_sweep_needs_the_simulators_resolution():
    text = BASE.replace('method = "ordered"', 'method = "ordered"\nwalker = "mjx"').replace(
        'walk = "rough"', 'walk = "rough"\nresolution = 0.005')
    refused(text, "terrain.resolution", r"must be >= 0\.01 m with walker")
    assert parse(text.replace("resolution = 0.005", "resolution = 0.01")).walker == "mjx"


@settings(max_examples=40, deadline=None)
@given(name=st.text(st.characters(blacklist_categories=("Cs",)), max_size=12).filter(lambda n: n not in WF.FAMILIES))
def test_any_other_walk_name_is_refused_by_name(name):
    refused(sweep.set_values(BASE, {"terrain.walk": name}), "terrain.walk", "must be one of")


@settings(max_examples=40, deadline=None)
@given(res=st.floats(0.005, 2.0, allow_nan=False))
def test_a_resolution_gives_the_walk_grid_or_a_refusal_naming_it(res):
    text = BASE.replace('walk = "rough"', f'walk = "rough"\nresolution = {res!r}')
    try:
        shape = WF.grid_shape(res)
    except ValueError:
        refused(text, "terrain.resolution", "whole cells")
    else:
        assert parse(text).shape == shape


# --------------------------------------------------------------------------------------------- set_values


@settings(max_examples=40, deadline=None)
@given(steps=st.integers(1, 100), seed=st.integers(0, 2**40), refine=st.booleans(),
       margin=st.floats(0.0, 0.5, allow_nan=False), kernel=st.sampled_from(["xla", "pallas"]))
def test_set_values_sets_what_the_parsed_file_holds(steps, seed, refine, margin, kernel):
    text = sweep.set_values(BASE, {"sweep.num_steps": steps, "sweep.seed": seed, "sweep.refine": refine,
                                   "sweep.kernel": kernel, "robot.margin": margin,
                                   "robot.metrics.support_limit": 0.01})
    cfg = parse(text)
    assert (cfg.num_steps, cfg.seed, cfg.refine, cfg.kernel) == (steps, seed, refine, kernel)
    assert cfg.robot == {"margin": margin, "metrics.support_limit": 0.01}
    assert cfg.walk == "rough" and cfg.random_commands and cfg.scenarios_per_cell == 3  # the rest as it was


def test_set_values_keeps_comments_and_refuses_what_it_cannot_edit():
    text = "# a comment\n[sweep]\nnum_steps = 30  # steps\n\n[terrain]\nwalk = \"flat\"\n"
    out = sweep.set_values(text, {"sweep.num_steps": 6, "terrain.resolution": 0.04})
    assert out.startswith("# a comment\n[sweep]\nnum_steps = 6\n") and "resolution = 0.04" in out
    assert parse(out).shape == (125, 50)
    with pytest.raises(ValueError, match="name a table and a key"):
        sweep.set_values(text, {"num_steps": 6})
    with pytest.raises(ValueError, match="must be a bool, int, float or string"):
        sweep.set_values(text, {"sweep.num_steps": [6]})
    with pytest.raises(ValueError, match="cannot set it in this text"):
        sweep.set_values("[grid]\nx = [\n 1,\n 2]\n", {"grid.x": 3})
    # a value the schema refuses is set, then refused by the parse with its key
    with pytest.raises(sweep.SweepConfigError, match="sweep.num_steps: must be >= 1"):
        parse(sweep.set_values(text, {"sweep.num_steps": 0}))


# --------------------------------------------------------------------------------------------- commands and metrics


def test_random_commands_are_each_replicates_numpy_draws_on_the_action_range_in_every_cell():
    """Replicate r's command at step k is lo + u (hi - lo) with u the doubles 3k..3k+2 of
    default_rng([seed, 2, r]).random(3 num_steps): the same in every cell (here two values of w), inside the
    action set's range, at the sweep's step time."""
    text = sweep.set_values(BASE, {"sweep.seed": 5, "robot.step_time": 0.6}) + '[grid]\n"robot.w" = [1.0, 2.0]\n'
    cfg = parse(text)
    table = sweep.scenarios(cfg)
    base = programs.base_robot(cfg, table, 1.0)
    robot_cols, terrain_cols, _ = programs.value_columns(table)
    _, _, _, commands, _ = programs.chunk_batch(table, 8, robot_cols, terrain_cols, cfg=cfg, base=base)
    assert commands.shape == (8, 4, 3) and commands.dtype == np.float32
    lo, hi = robots.command_range(robots.hrp2(step_time=0.6))
    for s in range(6):
        r = s % 3
        u = np.random.default_rng([5, 2, r]).random(12).reshape(4, 3)
        np.testing.assert_allclose(commands[s], lo + u * (hi - lo), atol=COMMAND_TOL, err_msg=str(s))
    np.testing.assert_array_equal(commands[:3], commands[3:6])  # paired across cells
    np.testing.assert_array_equal(commands[6:], commands[[5, 5]])  # padding repeats the last row
    assert np.all(commands >= lo - COMMAND_TOL) and np.all(commands <= hi + COMMAND_TOL)
    assert not np.array_equal(commands[0, 0], commands[0, 1])  # a new command every step


def test_walk_summary_of_a_hand_made_walk():
    """Steps made and progress: robot 0 steps left to 0.7 m then right to 0.9 m; robot 1 steps left to 0.7 m, then
    falls during its right step (which lands far ahead): only the first counts; robot 2 never steps."""
    start = np.asarray([[0.5, 1.095, 0.0], [0.5, 0.905, 0.0]], np.float32)
    x = np.array([[0.7, 0.9], [0.7, 2.0], [0.5, 0.5]], np.float32)
    traj = sweep_traj(x, taken=[[1, 1], [1, 1], [0, 0]], fallen=[[0, 0], [0, 1], [0, 0]])
    got = jax.vmap(lambda t: programs.walk_summary(t, start, physics=True))(traj)
    np.testing.assert_array_equal(np.asarray(got["steps_made"]), [2, 1, 0])
    np.testing.assert_allclose(np.asarray(got["progress"]), [0.3, 0.1, 0.0], atol=1e-6)
    # contacts of steps begun standing: robot 1's in the step it fell in counts (it began it standing)
    np.testing.assert_array_equal(np.asarray(got["standing_contacts"]), [1, 1, 0])
    np.testing.assert_allclose(np.asarray(got["made_placement_error_mean"])[:2], [1.5e-3, 1e-3], rtol=1e-6)
    assert np.isnan(np.asarray(got["made_placement_error_p95"])[2])  # no step made: no percentile
    perfect = jax.vmap(lambda t: programs.walk_summary(t._replace(log=None), start))(traj)
    assert set(perfect) == set(sweep.WALK_METRICS)
    np.testing.assert_array_equal(np.asarray(got["footholds_on_obstacles_made"]), [0, 0, 0])
    np.testing.assert_array_equal(np.asarray(perfect["steps_made"]), [2, 2, 0])  # every step taken


def sweep_traj(x, taken, fallen):
    """A Trajectory of len(x) rollouts of two steps (left then right), the fields walk_summary reads."""
    import ijoy_jax as ij
    from ijoy_jax.sim import walker as W

    b, t = x.shape
    flags = ("valid", "taken", "stopped", "in_place", "stationary", "on_obstacle", "unsupported")
    fields = {f: np.zeros((b, t), bool if f in flags else np.float32) for f in ij.Trajectory._fields}
    sides = np.array([[1, -1]] * b)
    fields.update(footsteps=np.stack([x, np.where(sides > 0, 1.095, 0.905), np.zeros_like(x)], axis=-1),
                  sides=sides, taken=np.asarray(taken, bool), target=np.zeros((b, t, 3)),
                  commanded=np.zeros((b, t, 3)), feet=np.zeros((b, 2, 3)))
    log = {f: np.zeros((b, t), np.float32) for f in W.StepLog._fields}
    log.update(landed=np.zeros((b, t, 6)), qpos=np.zeros((b, t, 0, 19)), fallen=np.asarray(fallen, bool),
               obstacle_contact=np.array([[0, 1], [0, 1], [0, 0]], bool),
               placement_error=np.array([[1, 2], [1, 90], [90, 90]], np.float32) * 1e-3)
    fields["log"] = W.StepLog(**log)
    return ij.Trajectory(**fields)


@pytest.mark.slow
def test_a_walk_sweep_walks_the_familys_maps_and_both_command_kinds_share_its_program(tmp_path):
    """Replicate r walks maps(key(seed), B)[r] (sweep.scenario rebuilds it), with the random commands above; the
    held-command file of the same family runs in the programs the random one compiled, and another family's
    rollouts in the same rollout program."""
    cfg = parse(sweep.set_values(BASE, {"sweep.seed": 2}))
    stats = sweep.run(cfg, tmp_path / "random", progress=False)
    assert stats.complete and stats.compiles == 2  # the maps (and robots, starts), the rollouts
    df = sweep.load(tmp_path / "random")
    assert set(sweep.WALK_METRICS) <= set(df.columns) and not set(sweep.WALK_PHYSICS_METRICS) & set(df.columns)
    maps = WF.FAMILIES["rough"].maps(jax.random.key(2), 3, shape=cfg.shape, resolution=cfg.resolution)
    for r in range(3):
        s = sweep.scenario(cfg, r)
        np.testing.assert_allclose(np.asarray(s.terrain.height), np.asarray(maps.height[r]), atol=1e-6)
        u = np.random.default_rng([2, 2, r]).random(12).reshape(4, 3)
        lo, hi = robots.command_range(robots.hrp2())
        np.testing.assert_allclose(s.command, lo + u * (hi - lo), atol=COMMAND_TOL)
    held = parse(sweep.set_values(BASE.replace("random = true", "vx = 0.25"), {"sweep.seed": 2}))
    again = sweep.run(held, tmp_path / "forward", progress=False)
    assert again.compiles == 0
    stones = sweep.run(parse(BASE.replace('"rough"', '"stones"')), tmp_path / "stones", progress=False)
    assert stones.compiles == 1  # its maps; the rollouts' program is the one above
    progress = sweep.load(tmp_path / "forward")["progress"].to_numpy()
    assert np.all(progress > 0) and np.all(progress <= 0.1 + 3 * 0.2 + 1e-6)  # forward, at most as on flat ground
