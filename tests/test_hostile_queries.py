"""A query's own traced values (stance, swing pose, stance side, start feet) inside a caller's jit: what the
boundary refuses where they are concrete is flagged there, and no NaN leaves the function (issue #52, 2-4).
Headings beyond geometry.MAX_ANGLE are reduced by whole turns at the boundary, in float64."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import cue, geometry, select
from ijoy_jax.server import schema, service

RES = 0.02
SHAPE = (40, 40)
ROBOT = ij.robots.hrp2(margin=0.02)
TARGETS = ij.make_targets(ROBOT)
_rng = np.random.default_rng(0)
ROUGH = ij.terrain.from_arrays((0.004 * _rng.standard_normal(SHAPE)).astype(np.float32), np.ones(SHAPE, bool), RES)
STANCE = np.array([0.4, 0.45, 0.0], np.float32)
SWING = np.array([0.35, 0.26, 0.0], np.float32)
COMMAND = jnp.array([0.2, 0.0, 0.3], jnp.float32)
BAD = [math.nan, math.inf, -math.inf]


def _decide(methods):
    """The methods on one traced query, one program for them all."""
    return jax.jit(lambda stance, side, swing_from: {
        m: ij.select_step(ROUGH, ROBOT, stance, side, COMMAND, options=ij.SelectOptions(method=m),
                          swing_from=swing_from, targets=TARGETS)
        for m in methods})


_decide_all = _decide(("exhaustive",))  # the fast tier's: one selector program
_decide_others = _decide(("ordered", "naive", "lookahead"))  # the other searches: larger programs, slow tier
_plan = jax.jit(lambda s, d, w: select.lookahead_plan(ROUGH, ROBOT, s, d, COMMAND, swing_from=w, targets=TARGETS))


@jax.jit
def _costs_and_cue(stance, side, swing_from):
    costs = select.action_foot_costs(ROUGH, ROBOT, stance, side, swing_from=swing_from)
    feasible = cue.feasible_commands(ROUGH, ROBOT, stance, side, swing_from)
    return costs, feasible, cue.force_terms(feasible, COMMAND)


def _expected_supported(stance, side, swing_from) -> bool:
    """The rule, from NumPy: finite poses within MAX_ANGLE and a side of exactly +1 or -1."""
    poses = np.stack([stance, swing_from]).astype(np.float64)
    return bool(np.all(np.isfinite(poses)) and np.all(np.abs(poses[:, 2]) <= geometry.MAX_ANGLE)
                and side in (1.0, -1.0))


def _pose(draw, base):
    pose = np.array(base, np.float32)
    for i in range(3):
        kind = draw(st.sampled_from(["keep", "keep", "bad", "far"]))
        if kind == "bad":
            pose[i] = draw(st.sampled_from(BAD))
        elif kind == "far" and i == 2:
            pose[i] = draw(st.sampled_from([1100.0, -2.0e4, 6.2831852e7]))
    return pose


@st.composite
def hostile_queries(draw):
    side = draw(st.sampled_from([1.0, -1.0, 0.0, 7.0, -7.0, 0.5, math.nan]))
    return _pose(draw, STANCE), side, _pose(draw, SWING)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(hostile_queries())
def test_a_traced_query_is_flagged_where_the_boundary_would_refuse_it_and_never_nan(query):
    stance, side, swing_from = query
    ok = _expected_supported(stance, side, swing_from)
    _check_choices(_decide_all(jnp.asarray(stance), jnp.float32(side), jnp.asarray(swing_from)), ok)
    costs, feasible, force = _costs_and_cue(jnp.asarray(stance), jnp.float32(side), jnp.asarray(swing_from))
    assert bool(feasible.unsupported) == (not ok)
    assert np.all(np.isfinite(np.asarray(force.force)))
    if not ok:
        assert np.all(np.asarray(costs) == np.inf) and not bool(feasible.any_valid)
        assert bool(force.no_valid)  # the stop cue a robot that cannot step gets, flagged in the feasible set


@pytest.mark.slow
@settings(max_examples=12, deadline=None, derandomize=True)
@given(hostile_queries())
def test_the_other_searches_flag_a_traced_query_alike(query):
    stance, side, swing_from = query
    ok = _expected_supported(stance, side, swing_from)
    _check_choices(_decide_others(jnp.asarray(stance), jnp.float32(side), jnp.asarray(swing_from)), ok)
    plan = _plan(jnp.asarray(stance), jnp.float32(side), jnp.asarray(swing_from))
    assert ok or (int(plan.first) == -1 and np.all(np.asarray(plan.sequence) == -1)
                  and float(plan.score) == np.inf)


def _check_choices(out, ok):
    for method, c in out.items():
        assert bool(c.unsupported) == (not ok), method
        for name in ("pose", "foothold", "target"):
            assert np.all(np.isfinite(np.asarray(getattr(c, name)))), (method, name)
        if not ok:
            assert not bool(c.valid) and float(c.cost) == np.inf and float(c.foot_cost) == np.inf, method
            assert method == "naive" or int(c.index) == -1, method


def test_a_supported_query_decides_as_before():
    """The flags cost nothing where the values are fine: the traced decision equals the eager one."""
    out = _decide_all(jnp.asarray(STANCE), jnp.float32(-1), jnp.asarray(SWING))
    eager = ij.select_step(ROUGH, ROBOT, STANCE, -1, COMMAND, swing_from=SWING, targets=TARGETS)
    assert bool(eager.valid) and not bool(out["exhaustive"].unsupported)
    np.testing.assert_array_equal(np.asarray(out["exhaustive"].pose), np.asarray(eager.pose))


def test_a_traced_start_that_is_not_finite_stops_flagged_with_finite_distances():
    run = jax.jit(lambda start, first: ij.rollout(ROUGH, ROBOT, start, COMMAND, 3, first_swing=first,
                                                  targets=TARGETS))
    good = np.array([[0.4, 0.55, 0.0], [0.4, 0.36, 0.0]], np.float32)
    for start, first in ((np.where([[False] * 3, [False, True, False]], np.nan, good), 1.0),
                         (good + np.array([[0, 0, 2e4], [0, 0, 2e4]], np.float32), 1.0), (good, 0.0), (good, 7.0)):
        traj = run(jnp.asarray(start), jnp.float32(first))
        s = traj.summary()
        assert int(s["unsupported_decisions"]) == 3 and bool(s["stopped"]) and int(s["steps_taken"]) == 0
        for name in ("distance_along", "distance_across"):
            assert float(s[name]) == 0.0, name
        assert np.all(np.isfinite(np.asarray(traj.footsteps))) and np.all(np.isfinite(np.asarray(traj.feet)))
    assert int(run(jnp.asarray(good), jnp.float32(1.0)).summary()["unsupported_decisions"]) == 0


TURNS = [2.0e2, 1.0e7, -3.0e9]


def test_a_heading_of_many_turns_keeps_the_steps_turn():
    """2 pi 1e7 rad in float32 is 4 rad coarse: a step's turn would vanish in the sum. The boundary reduces the
    heading by whole turns in float64, so the decision equals the one from the same direction written small."""
    small, swing = np.array([0.4, 0.45, 0.3]), np.array([0.35, 0.26, 0.3])  # swing_from: the program above's
    a = ij.select_step(ROUGH, ROBOT, small, -1, [0.1, 0.0, 0.4], swing_from=swing, targets=TARGETS)
    for turns in TURNS:
        many, far_swing = (p + np.array([0.0, 0.0, 2 * np.pi * turns]) for p in (small, swing))
        b = ij.select_step(ROUGH, ROBOT, list(many), -1, [0.1, 0.0, 0.4], swing_from=far_swing, targets=TARGETS)
        assert bool(b.valid) and int(b.index) == int(a.index), turns
        np.testing.assert_allclose(np.asarray(b.pose[:2]), np.asarray(a.pose[:2]), atol=2e-6)
        assert abs(float(geometry.wrap_angle(b.pose[2] - a.pose[2]))) < 1e-5, turns


@pytest.mark.slow
@pytest.mark.parametrize("turns", TURNS)
def test_the_rollout_and_the_server_reduce_a_heading_of_many_turns_alike(turns):
    small = np.array([0.4, 0.45, 0.3])
    many = small + np.array([0.0, 0.0, 2 * np.pi * turns])
    a = ij.select_step(ROUGH, ROBOT, small, -1, [0.1, 0.0, 0.4], targets=TARGETS)
    feet = np.array([[0.4, 0.55, 0.0], [0.4, 0.36, 0.0]]) + np.array([0.0, 0.0, 2 * np.pi * turns])
    t_many = ij.rollout(ROUGH, ROBOT, feet, [0.1, 0.0, 0.4], 2, targets=TARGETS)
    t_small = ij.rollout(ROUGH, ROBOT, feet - np.array([0.0, 0.0, 2 * np.pi * turns]), [0.1, 0.0, 0.4], 2,
                         targets=TARGETS)
    np.testing.assert_allclose(np.asarray(t_many.footsteps[:, :2]), np.asarray(t_small.footsteps[:, :2]), atol=2e-6)
    svc = service.Service(ROBOT)
    ok = schema.decode_reply(svc.handle(schema.encode({"version": 1, "type": "set_terrain", "resolution": RES},
                                                      {"height": np.asarray(ROUGH.height),
                                                       "free": np.ones(SHAPE, bool)}))).header
    assert ok["ok"], ok
    reply = schema.decode_reply(svc.handle(schema.encode({"version": 1, "type": "step", "stance": many.tolist(),
                                                          "stance_side": -1, "command": [0.1, 0.0, 0.4]}))).header
    assert reply["index"] == int(a.index), reply


def test_reduce_turns_keeps_small_headings_and_nan_as_given():
    poses = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 2 * np.pi * 1e7 + 0.25], [0.0, 0.0, math.nan], [0, 0, -1e300],
                      [0.0, 0.0, math.inf]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # NaN and inf pass without NumPy's RuntimeWarning: the finite checks name them
        out = geometry.reduce_turns(poses)
    assert out[0].tolist() == [1.0, 2.0, 3.0] and math.isnan(out[2, 2]) and out[4, 2] == math.inf
    assert out[1, 2] == pytest.approx(0.25, abs=1e-6) and abs(out[3, 2]) <= math.pi
