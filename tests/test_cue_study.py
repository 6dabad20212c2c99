"""The cue study (ijoy_jax.cue.study) and its drawings (ijoy_jax.cue.plot).

References: the control loop itself (the drive's footsteps replayed through ij.rollout), hand-built logs
for the metrics, SciPy's Student-t interval, and the scenarios' own geometry.
"""

import math

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
import pytest
from scipy import stats

import ijoy_jax as ij
from ijoy_jax import cue
from ijoy_jax import stats as ij_stats
from ijoy_jax.cue import study

matplotlib.use("Agg")

ROBOT = ij.robots.hrp2(margin=0.02)
TARGETS = ij.make_targets(ROBOT)
CFG = study.StudyConfig(num_steps=14, ticks=4)
_CACHE = {}


def _scenarios():
    if "sc" not in _CACHE:
        _CACHE["sc"] = study.make_scenarios(3, 2)
    return _CACHE["sc"]


def _logs():
    if "logs" not in _CACHE:
        sc = _scenarios()
        _CACHE["logs"] = {on: study.drive(sc, ROBOT, cue.make_params(), cue_on=on, cfg=CFG, targets=TARGETS)
                          for on in (False, True)}
    return _CACHE["logs"]


def test_scenarios_keep_start_and_goal_clear_and_families_apart():
    sc = _scenarios()
    assert sc.terrain.free.shape == (6, *study.SHAPE) and sc.goal.shape == (6, 2) and sc.start.shape == (6, 2, 3)
    np.testing.assert_array_equal(np.asarray(sc.family), [0, 0, 1, 1, 2, 2])
    res = study.RESOLUTION
    for i in range(6):
        free = np.asarray(sc.terrain.free[i])
        for point in (np.asarray(sc.goal[i]), np.asarray(sc.start[i, :, :2]).mean(0)):
            ix, iy = (point / res).astype(int)
            assert free[ix - 5:ix + 6, iy - 5:iy + 6].all(), (i, point)  # 10 cm around: free
        blocked = (~free).sum()
        assert blocked > 0
    with pytest.raises(ValueError, match="families"):
        study.make_scenarios(0, 1, families=("maze",))
    with pytest.raises(ValueError, match="num"):
        study.make_scenarios(0, 0)


@pytest.mark.slow
def test_the_drive_is_the_control_loop_fed_the_operators_commands():
    """Replaying the drive's commands through ij.rollout (the project's Algorithm 1) gives its footsteps."""
    sc = _scenarios()
    log = _logs()[True]
    for i in (0, 4):
        terrain = jax.tree_util.tree_map(lambda x, i=i: x[i], sc.terrain)
        traj = ij.rollout(terrain, ROBOT, np.asarray(sc.start[i]), np.asarray(log.command[i]), CFG.num_steps,
                          targets=TARGETS, options=ij.SelectOptions(swing_path=False))
        np.testing.assert_allclose(np.asarray(traj.feet), np.asarray(log.feet[i, -1]), atol=1e-5)
        moved = np.asarray(traj.taken) & ~np.asarray(traj.in_place)
        np.testing.assert_array_equal(moved, np.asarray(log.moved[i]))


def test_cue_off_pushes_nothing_and_the_cue_lowers_the_command_error_on_blocked_drives():
    logs = _logs()
    assert np.all(np.asarray(logs[False].effort) == 0) and not np.any(np.asarray(logs[False].blocked))
    assert np.any(np.asarray(logs[True].blocked))
    off = study.summarize(logs[False], ROBOT, CFG)
    on = study.summarize(logs[True], ROBOT, CFG)
    assert on["effort"].sum() > 0 and on["command_error"].mean() < off["command_error"].mean()


def test_summary_metrics_against_a_hand_built_log():
    t = 5
    dist = np.array([[2.0, 1.0, 0.2, 0.1, 0.0], [3.0, 3.0, 3.0, 3.0, 3.0]])
    cmd = np.zeros((2, t, 3))
    cmd[0, :, 0] = 0.25
    real = np.zeros((2, t, 3))
    real[0, :, 0] = [0.25, 0.125, 0.0, 0.0, 0.0]
    log = study.DriveLog(
        feet=np.zeros((2, t, 2, 3)), command=cmd, reachable=cmd, realized=real,
        moved=np.array([[True, True, False, False, False], [False] * 5]),
        near=np.array([[False, True, True, True, True], [True, False, False, False, False]]), distance=dist,
        effort=np.array([[0.0, 0.5, 1.0, 1.0, 1.0], [0.2] * 5]), blocked=np.zeros((2, t), bool))
    cfg = study.StudyConfig(num_steps=t, goal_radius=0.25)
    m = study.summarize(log, ROBOT, cfg)
    np.testing.assert_allclose(m["time_to_goal"], [3 * 0.8, 5 * 0.8])  # reached after the 3rd decision
    np.testing.assert_array_equal(m["reached"], [1.0, 0.0])
    np.testing.assert_array_equal(m["steps_in_place"], [1.0, 5.0])
    np.testing.assert_allclose(m["command_error"], [(0 + 0.5 + 1.0) / 3, 0.0])  # stick units (full 0.25 m/s)
    np.testing.assert_array_equal(m["near_obstacles"], [2.0, 1.0])
    np.testing.assert_allclose(m["effort"], [0.5, 0.2])


@pytest.mark.parametrize("n", [2, 7, 45])
def test_mean_ci_is_the_student_t_interval(n):
    x = np.random.default_rng(n).normal(1.0, 2.0, n)
    mean, half = ij_stats.mean_ci(x)
    lo, hi = stats.t.interval(0.95, n - 1, loc=np.mean(x), scale=stats.sem(x))
    assert mean == pytest.approx(np.mean(x)) and half == pytest.approx((hi - lo) / 2, rel=1e-6)
    assert math.isnan(ij_stats.mean_ci([1.0])[1])


def test_compare_pairs_the_conditions_on_the_same_scenarios():
    sc = _scenarios()
    res = study.compare(sc, ROBOT, {"off": None, "cue": cue.make_params(), "soft": cue.make_params(c1=0.2)},
                        cfg=CFG, targets=TARGETS)
    assert res["n"] == 6 and res["family"] == ["clutter", "clutter", "wall", "wall", "slide", "slide"]
    for m in study.METRICS:
        d = res["per_scenario"]["cue"][m] - res["per_scenario"]["off"][m]
        assert res["difference"]["cue"][m] == pytest.approx(ij_stats.mean_ci(d), nan_ok=True)
    table = study.markdown(res, "test")
    assert "| command_error (stick units) |" in table and "cue - off" in table and "soft - off" in table
    with pytest.raises(ValueError, match="condition"):
        study.compare(sc, ROBOT, {})


def _facing_a_wall():
    """Two scenarios whose goal lies behind a wall 0.4 m ahead of the start: the cue pushes from the 2nd step."""
    free = np.ones(study.SHAPE, bool)
    free[45:50, :] = False
    terrain = ij.terrain.from_arrays(None, free, study.RESOLUTION)
    start = np.asarray(ij.robots.start_stance(ROBOT, 0.5, 1.2))
    one = study.Scenario(terrain=terrain, start=jnp.asarray(start), goal=jnp.array([1.5, 1.2]), family=jnp.int32(1))
    return jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), one).replace(goal=jnp.array([[1.5, 1.2], [1.5, 1.5]]))


@pytest.mark.slow
def test_tuning_runs_the_projects_loop_and_keeps_the_best_parameters():
    sc = _facing_a_wall()
    cfg = study.StudyConfig(num_steps=5, ticks=2)
    r = study.tune_cue(sc, ROBOT, cfg=cfg, steps=3, learning_rate=0.1)
    assert r.losses.shape == (3,) and np.all(np.isfinite(np.asarray(r.losses)))
    assert set(r.terms) == {"distance", "error", "effort"}
    assert float(r.losses[r.best]) == float(np.min(np.asarray(r.losses)))
    cue.check_params(r.params)
    moved = [float(jnp.abs(r.trajectory[k][1] - r.trajectory[k][0]).max()) for k in ("c1", "decay", "scales")]
    assert max(moved) > 0.01  # Adam moved the parameters: the gradient reached them
    n = study.compiled_programs()
    study.tune_cue(sc, ROBOT, init=cue.make_params(c1=0.5, decay=0.2), cfg=cfg, steps=3, learning_rate=0.1)
    assert study.compiled_programs() == n  # new starting values: no recompile
    # The unconstrained variables round-trip.
    p = cue.make_params(c1=0.3, decay=0.07, scales=[0.5, 2.0, 1.0])
    q = study.to_params(study.from_params(p))
    for a, b in zip(jax.tree_util.tree_leaves(p), jax.tree_util.tree_leaves(q), strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5)


def test_bad_operator_and_steps_are_refused():
    with pytest.raises(ValueError, match="hand_time"):
        study.default_operator(hand_time=0.0)
    with pytest.raises(ValueError, match="unknown"):
        study.default_operator(grip=1.0)
    with pytest.raises(ValueError, match="steps"):
        study.tune_cue(_scenarios(), ROBOT, steps=0)


@pytest.mark.slow
def test_drawings(tmp_path):
    from ijoy_jax.cue import plot

    cases = plot.paper_cases()
    assert [c[0] for c in cases] == ["wall ahead", "sidestep along a wall", "clutter"]
    sc = _facing_a_wall()
    terrain = jax.tree_util.tree_map(lambda x: x[0], sc.terrain)
    stance = np.array([0.72, 1.105, 0.0])  # a right foot 0.18 m before the wall: forward steps blocked
    out = tmp_path / "field.png"
    fig = plot.scenario_figure([("wall", terrain, stance, -1, 0.0)], ROBOT, out=str(out))
    assert out.stat().st_size > 10_000 and len(fig.axes) == 3  # terrain, field and its colour bar
    feas = cue.feasible_commands(terrain, ROBOT, stance, -1)
    g = plot.field_grid(feas, num=9)
    assert g["force"].shape == (9, 9, 3) and g["magnitude"][4, 0] == 0 and g["magnitude"][4, -1] > 0
    res = {"summary": {"off": {m: (1.0, 0.1) for m in study.METRICS}, "cue": {m: (0.8, 0.1) for m in study.METRICS}},
           "n": 4}
    plot.study_figure(res, out=str(tmp_path / "study.png"))
    assert (tmp_path / "study.png").exists()
    import matplotlib.pyplot as plt

    plt.close("all")
