"""Tests of ijoy_jax.tune.inverse: recovery of hidden selector parameters from exact demonstrations."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from test_tune_relax import _terrain

import ijoy_jax as ij
from ijoy_jax.tune import inverse

RES = 0.02
NUM_DEMOS = 6


def _demos(robot):
    terrains = []
    for q in range(NUM_DEMOS):
        free = np.ones((50, 50), bool)
        free[30 + q : 40 + q, 10 + 2 * q : 30] = False
        terrains.append(ij.terrain.from_arrays(None, free, RES))
    rng = np.random.default_rng(0)
    stances = np.stack([[0.45, 0.35, 0.0]] * NUM_DEMOS) + rng.uniform(-0.05, 0.05, (NUM_DEMOS, 3))
    commands = rng.uniform([-0.3, -0.1, -0.4], [0.3, 0.1, 0.4], (NUM_DEMOS, 3))
    return inverse.make_demonstrations(inverse.stack_terrains(terrains), robot, stances, -np.ones(NUM_DEMOS), commands)


@pytest.fixture(scope="module")
def robot():
    return ij.robots.hrp2(margin=0.02, density=0.25, max_margin=0.03)


def test_demonstrations_are_exact_choices(robot):
    demos = _demos(robot)
    assert demos.actions.shape == (NUM_DEMOS,)
    assert inverse.exact_agreement(demos, robot) == 1.0


def test_fit_lowers_the_negative_log_likelihood(robot):
    hidden = robot.replace(w=jnp.float32(2.0), rotation_weight=jnp.float32(0.5))
    demos = _demos(hidden)
    result = inverse.fit(demos, robot, ("w", "rotation_weight"), sharpness=50.0, tau=0.1, num_steps=40)
    losses = np.asarray(result.losses)
    assert losses.shape == (40,) and np.all(np.isfinite(losses))
    assert losses[-1] < losses[0]
    assert set(result.params) == {"w", "rotation_weight"}
    assert all(np.isfinite(v) and v > 0 for v in result.params.values())
    # Parameters not tuned are carried over unchanged.
    assert float(result.robot.margin) == float(robot.margin)


def test_fit_of_a_metric_parameter_runs_the_general_path(robot):
    demos = _demos(robot)
    result = inverse.fit(demos, robot, ("margin",), sharpness=20.0, tau=0.3, num_steps=3)
    assert np.all(np.isfinite(np.asarray(result.losses)))
    assert float(result.robot.margin) > 0


HIDDEN = {"w": 0.5, "rotation_weight": 0.5}  # terrain-cautious, trades rotation for translation
NUM_TRAIN, NUM_HELD_OUT = 50, 30
# Exact selector at the recovered parameters must reproduce this fraction of held-out choices.
# Measured on seeds 0..3: 0.89, 1.00, 1.00, 0.93 (the paper's w = 1, rotation_weight = 100 gets 0.77-0.81).
HELD_OUT_RATE = 0.85
PARAM_FACTOR = 1.5  # recovered values within this factor of the hidden ones (measured: <= 1.37)


@pytest.mark.slow
def test_inverse_problem_recovers_hidden_parameters():
    robot = ij.robots.hrp2(margin=0.02, density=0.5, max_margin=0.03)  # paper's w = 1, rotation_weight = 100
    hidden = robot.replace(**{k: jnp.float32(v) for k, v in HIDDEN.items()})
    d = NUM_TRAIN + NUM_HELD_OUT
    rng = np.random.default_rng(0)
    stances = np.stack(
        [[0.6 + rng.uniform(-0.1, 0.1), 0.45 + rng.uniform(-0.1, 0.1), rng.uniform(-0.5, 0.5)] for _ in range(d)]
    )
    commands = rng.uniform([-0.3, -0.1, -0.4], [0.3, 0.1, 0.4], (d, 3))
    terrains = inverse.stack_terrains([_terrain(q, True) for q in range(d)])
    demos = inverse.make_demonstrations(terrains, hidden, stances, -np.ones(d), commands)
    train, held_out = demos.take(np.arange(NUM_TRAIN)), demos.take(np.arange(NUM_TRAIN, d))
    starts = {"w": np.ones(4), "rotation_weight": np.array([0.1, 1.0, 10.0, 100.0])}
    result = inverse.fit(
        train,
        robot,
        ("w", "rotation_weight"),
        init=starts,
        sharpness=300.0,
        tau=0.003,
        noise=0.05,
        learning_rate=0.3,
        num_steps=500,
    )
    before = inverse.exact_agreement(held_out, robot)
    after = inverse.exact_agreement(held_out, result.robot)
    print(f"recovered {result.params} (hidden {HIDDEN}); held-out agreement {before:.2f} -> {after:.2f}")
    assert after >= HELD_OUT_RATE and after > before
    for k, v in HIDDEN.items():
        assert v / PARAM_FACTOR <= result.params[k] <= v * PARAM_FACTOR, (k, result.params[k])
