"""Tests of ijoy_jax.tune.forward: objective gradients, a short tuning run, the exact held-out evaluation."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import ijoy_jax as ij
from ijoy_jax.testing import enable_x64, rect_corners, rect_touches_cells
from ijoy_jax.tune import forward, loop

FD_RTOL64 = 1e-5  # float64 central differences, h = 1e-6: truncation ~h^2, rounding ~1e-16 / h
IMPROVEMENT = 0.95  # a short run on a fixed batch must bring the objective below this fraction of its start
# (measured 0.89: 0.711 -> 0.631; the rest is the command-error floor of a 10-action set)

TINY = forward.ForwardConfig(shape=(40, 40), density=0.1, batch_size=3, num_noise_samples=4, steps=4)


def _float_leaves(tree, dtype):
    return jax.tree.map(lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x, tree)


@pytest.mark.slow
def test_objective_gradient_matches_finite_differences_float64():
    cfg = forward.ForwardConfig(shape=(40, 40), density=0.1, has_height=True, batch_size=3, num_noise_samples=4,
                                sharpness=5.0, tau=30.0)
    # warm: every action keeps some probability (on this dense clutter the relaxed costs of one decision spread
    # over ~100-300 cost units, mostly obstacle and support barriers; at tau = 1 each decision is one-hot and
    # every gradient vanishes)
    robot = forward.paper_robot(cfg)
    batch = jax.jit(forward.make_batch_fn(robot, cfg))(jax.random.key(4))
    assert float(jnp.sum(batch.risk)) > 0  # the risk term takes part
    with enable_x64():
        r64 = _float_leaves(robot, jnp.float64)
        b64 = _float_leaves(batch, jnp.float64)
        u = {k: v.astype(jnp.float64) for k, v in forward.to_unconstrained(r64, cfg.tuned_names()).items()}
        vg = jax.jit(jax.value_and_grad(lambda p: forward.objective(p, b64, r64, cfg)[0]))  # one compile
        f = lambda p: vg(p)[0]  # noqa: E731
        grads = vg(u)[1]
        h = 1e-6
        worst = 0.0
        for name in cfg.tuned_names():
            plus, minus = dict(u), dict(u)
            plus[name], minus[name] = u[name] + h, u[name] - h
            fd = (f(plus) - f(minus)) / (2 * h)
            an = grads[name]
            assert np.isfinite(float(an)), name
            err = abs(float(fd - an)) / max(1e-3, abs(float(fd)))
            worst = max(worst, err)
            assert err < FD_RTOL64, (name, float(fd), float(an))
        nonzero = [n for n in cfg.tuned_names() if abs(float(grads[n])) > 1e-8]
        assert {"margin", "rotation_weight"} <= set(nonzero), nonzero
        print(f"float64 worst relative gradient error {worst:.2e}; nonzero gradients: {nonzero}")


def test_short_tuning_run_lowers_the_objective():
    # Warm (tau = 0.3): with 10 actions a cold Boltzmann choice is nearly one-hot and the fixed-batch objective
    # nearly piecewise constant; the check is that the optimiser descends the smooth relaxed objective.
    cfg = forward.ForwardConfig(shape=(40, 40), density=0.1, batch_size=6, num_noise_samples=4, tau=0.3,
                                learning_rate=0.3)
    robot = forward.paper_robot(cfg)
    fixed = jax.jit(forward.make_batch_fn(robot, cfg))(jax.random.key(1))  # a fixed batch: a deterministic check
    u0 = forward.to_unconstrained(robot, cfg.tuned_names())
    loss = lambda p, _: forward.objective(p, fixed, robot, cfg)  # noqa: E731
    res = loop.tune(loss, u0, optax.adam(cfg.learning_rate), 25, key=0, has_aux=True, progress=False)
    value = jax.jit(lambda p: forward.objective(p, fixed, robot, cfg)[0])
    before, after = float(value(u0)), float(value({k: jnp.asarray(v) for k, v in res.params.items()}))
    print(f"objective {before:.4f} -> {after:.4f}")
    assert after < IMPROVEMENT * before
    assert np.all(np.isfinite(res.losses))


@pytest.mark.slow
def test_tune_forward_runs_batched_and_saves(tmp_path):
    robot = forward.paper_robot(TINY)
    fit = forward.tune_forward(robot, TINY, key=0, init={"margin": np.array([0.01, 0.05])}, num_runs=2,
                               progress=False, out_dir=tmp_path)
    assert fit.result.losses.shape == (2, TINY.steps)
    assert set(fit.params) == {"margin", "rotation_weight"}
    assert 0 < fit.params["margin"] < forward.max_margin_of(robot)
    assert float(fit.robot.margin) == pytest.approx(fit.params["margin"], rel=1e-6)
    assert float(fit.robot.w) == float(robot.w)  # not tuned: unchanged
    saved = loop.load(tmp_path)
    assert saved.manifest["config"]["density"] == TINY.density and saved.manifest["tuned"] == fit.params
    assert saved.params["margin"].shape == (2,)


def _numpy_counts(terrain, robot, decisions, cfg, index):
    """Brute force (float64): noisy placements near / on obstacles, and errors, of the given exact choices."""
    free = np.asarray(terrain.free)
    res, shape = terrain.resolution, free.shape
    size = np.array(shape) * res
    near, on, trans = [], [], []
    for b in range(len(index)):
        stance = np.asarray(decisions.stances[b], np.float64)
        side = float(decisions.sides[b])
        acts = np.asarray(robot.actions, np.float64) * np.array([1.0, -side, -side])
        p_next = np.asarray(robot.p0, np.float64) * np.array([1.0, -side, -side]) + 0.8 * np.asarray(
            decisions.commands[b], np.float64)
        a = acts[index[b]] if index[b] >= 0 else np.asarray(robot.p0) * np.array([1.0, -side, -side])
        c, s = np.cos(stance[2]), np.sin(stance[2])
        pose = np.array([stance[0] + c * a[0] - s * a[1], stance[1] + s * a[0] + c * a[1], stance[2] + a[2]])
        trans.append(np.hypot(*(a[:2] - p_next[:2])))
        counts = []
        for grow in (cfg.distance, 0.0):
            n = 0
            for z in np.asarray(decisions.noise[b], np.float64):
                x, y, th = pose + np.array([cfg.noise_xy, cfg.noise_xy, cfg.noise_theta]) * z
                hl, hw = 0.121 + grow, 0.065 + grow
                corners = rect_corners(x, y, th, hl, hw)
                off = np.any(corners < 0) or np.any(corners > size)
                hit = np.any(rect_touches_cells(x, y, th, hl, hw, res, shape) & ~free)
                n += int(off or hit)
            counts.append(n if index[b] >= 0 else 0)
        near.append(counts[0])
        on.append(counts[1])
    return np.array(near), np.array(on), np.array(trans)


@pytest.mark.slow
def test_held_out_evaluation_matches_brute_force_numpy():
    cfg = forward.ForwardConfig(shape=(40, 40), density=0.1, num_noise_samples=6, noise_xy=0.03, distance=0.04)
    robot = ij.robots.hrp2(margin=0.005, density=0.1, max_margin=0.08)
    d = jax.jit(forward.sample_decisions, static_argnums=(1, 2))(jax.random.key(3), 5, cfg)
    ev = forward.evaluate(robot, d, cfg)
    for b in range(5):  # the choice is the public exact selector's
        t = jax.tree.map(lambda x, b=b: x[b], d.terrains)
        c = ij.select_step(t, robot, d.stances[b], d.sides[b], d.commands[b], options=ij.SelectOptions(quantize=False))
        assert int(c.index) == int(ev.index[b])
    near, on, trans = [], [], []
    for b in range(5):
        t = jax.tree.map(lambda x, b=b: x[b], d.terrains)
        one = jax.tree.map(lambda x, b=b: x[b : b + 1], d)
        n, o, e = _numpy_counts(t, robot, one, cfg, np.asarray(ev.index[b : b + 1]))
        near.append(n[0])
        on.append(o[0])
        trans.append(e[0])
    print(f"near {near}, on {on} (of {cfg.num_noise_samples} each)")
    assert sum(near) > 0 and sum(on) > 0  # the case exercises both counts
    np.testing.assert_array_equal(np.asarray(ev.near), near)
    np.testing.assert_array_equal(np.asarray(ev.on_obstacle), on)
    np.testing.assert_allclose(np.asarray(ev.translation_error_m), trans, atol=1e-5)
    s = forward.summarize(ev, cfg)
    assert s["near_obstacle"] == sum(near) and s["placements"] == int(np.sum(ev.valid)) * 6


def test_config_validation():
    with pytest.raises(ValueError, match="margin"):
        forward.ForwardConfig(margin=0.2, max_margin=0.08)
    with pytest.raises(ValueError, match="names"):
        forward.ForwardConfig(names=("foot_length",))
    assert forward.ForwardConfig(has_height=True).tuned_names()[:3] == ("w", "rotation_weight", "margin")
    assert hash(forward.ForwardConfig(shape=[40, 40])) == hash(forward.ForwardConfig(shape=(40, 40)))


def test_terrain_params_are_checked_by_the_family():
    with pytest.raises(ValueError, match=r"ObstacleParams.size_min: impossible range"):
        forward.ForwardConfig(terrain_params={"size_min": 0.3})
    with pytest.raises(ValueError, match=r"ObstacleParams.count: must be an integer"):
        forward.ForwardConfig(terrain_params={"count": 2.5})
    with pytest.raises(ValueError, match=r"RoughParams.count: unknown field"):
        forward.ForwardConfig(family="rough", terrain_params={"count": 3})
    with pytest.raises(ValueError, match="clear_radius"):
        forward.ForwardConfig(terrain_params={"start_radius": 0.1})
    cfg = forward.ForwardConfig(shape=(40, 40), num_noise_samples=2, terrain_params={"count": 3, "size_max": 0.1})
    assert cfg.terrain_params == (("count", 3), ("size_max", 0.1)) and hash(cfg)
    d = forward.sample_decisions(0, 2, cfg)
    assert d.terrains.free.shape == (2, 40, 40) and not bool(d.terrains.free.all())
