"""Tests of ijoy_jax.tune.relaxed_rollout: gradients vs finite differences, the exact limit, memory with remat."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.robots import get_leaf, set_leaf
from ijoy_jax.tune import relaxed_rollout

RES = 0.02
FD_RTOL64 = 1e-5  # float64 central differences, h = 1e-6 (truncation ~h^2, rounding ~1e-16 / h), as test_tune_relax
EXPECTED_ATOL = 1e-3  # m: expected pose vs exact foothold at tau = 1e-3 (off-mode mass <= exp(-gap / tau))
ST_ATOL = 1e-5  # m: straight-through forward pass = the mode's pose (float32 rounding of compose)
START = np.array([[0.2, 0.595, 0.0], [0.2, 0.405, 0.0]], np.float32)


def _walk_terrain() -> ij.Terrain:
    """2D, 1.6 m x 1.0 m, a block in the left foot's way at x = 0.9-1.0 m: the exact walk must sidestep."""
    free = np.ones((80, 50), bool)
    free[45:50, 27:40] = False
    return ij.terrain.from_arrays(None, free, RES)


def _tiny_terrain() -> ij.Terrain:
    """2.5D, 1.0 m x 0.8 m: a 4 cm step up at x = 0.6 m, a bump and a 12 cm bar (above the 10 cm clearance)."""
    n = (50, 40)
    xs, ys = np.arange(n[0]) * RES, np.arange(n[1]) * RES
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    h = 0.04 * (gx > 0.6) + 0.03 * np.exp(-((gx - 0.45) ** 2 + (gy - 0.3) ** 2) / 0.01)
    h[22:24, 26:34] = 0.12
    return ij.terrain.from_arrays(h, None, RES)


@pytest.fixture(scope="module")
def robot():
    return ij.robots.hrp2(margin=0.02, density=0.25, max_margin=0.03)


def test_relaxed_rollout_tends_to_exact_rollout(robot):
    """As tau -> 0 at a large sharpness, the relaxed footsteps equal ``ij.rollout``'s (perfect walker)."""
    terrain = _walk_terrain()
    cmd = np.array([0.25, 0.0, 0.0], np.float32)
    exact = ij.rollout(terrain, robot, START, cmd, 8, options=ij.SelectOptions(quantize=False))
    assert bool(np.all(exact.valid))
    assert len(set(np.asarray(exact.index).tolist())) > 2  # not a plain straight walk: the block matters
    ref = np.asarray(exact.footsteps)
    st = relaxed_rollout.relaxed_rollout_jit(terrain, robot, START, cmd, 8, sharpness=1000.0, tau=1e-3,
                                     estimator="straight_through")
    np.testing.assert_array_equal(np.asarray(st.mode), np.asarray(exact.index))
    np.testing.assert_allclose(np.asarray(st.footsteps), ref, atol=ST_ATOL)
    errors = []
    for tau in (1.0, 0.1, 1e-3):
        ex = relaxed_rollout.relaxed_rollout_jit(terrain, robot, START, cmd, 8, sharpness=1000.0, tau=tau)
        errors.append(float(np.max(np.abs(np.asarray(ex.footsteps) - ref))))
        if tau == 1.0:
            cache = compiled_count(relaxed_rollout.relaxed_rollout_jit)
    assert compiled_count(relaxed_rollout.relaxed_rollout_jit) == cache  # new tau / sharpness values do not recompile
    # Gumbel-softmax: at tau -> 0 the log-probability gaps (cost gap / tau) swamp the O(1) Gumbel noise.
    gs = relaxed_rollout.relaxed_rollout_jit(terrain, robot, START, cmd, 8, sharpness=1000.0, tau=1e-3,
                                             estimator="gumbel", key=jax.random.key(0))
    assert float(np.max(np.abs(np.asarray(gs.footsteps) - ref))) < EXPECTED_ATOL
    with pytest.raises(ValueError, match="PRNG key"):
        relaxed_rollout.relaxed_rollout(terrain, robot, START, cmd, 2, sharpness=1.0, tau=1.0, estimator="gumbel")
    print(f"max |relaxed - exact| footstep (expected estimator) at tau 1, 0.1, 1e-3: {errors}")
    assert errors[0] > errors[-1]
    assert errors[-1] < EXPECTED_ATOL


def _loss(terrain, robot, start, command):
    tr = relaxed_rollout.relaxed_rollout(terrain, robot, start, command, 3, sharpness=10.0, tau=1.0, remat=True)
    return relaxed_rollout.command_error(tr) + 0.01 * jnp.mean(tr.expected_cost) + jnp.sum(tr.feet)


@pytest.mark.slow
def test_rollout_gradients_match_finite_differences_float64(robot):
    with jax.enable_x64(True):
        terrain = _tiny_terrain()
        terrain = terrain.replace(height=terrain.height.astype(jnp.float64), origin=terrain.origin.astype(jnp.float64))
        rb = jax.tree.map(lambda x: x.astype(jnp.float64) if jnp.issubdtype(x.dtype, jnp.floating) else x, robot)
        # Feet not exactly one action apart: stepping in place from START is a zero-length swing, where the
        # corridor length |d| has a kink (the gradient is the subgradient 0; central differences average).
        # Off the cell boundaries too: a window origin (floor(x / res)) that flips inside +-h drops or adds
        # membership tails of ~exp(-2 sharpness), a ~1e-10 jump that central differences divide by 2h.
        start = jnp.asarray(START, jnp.float64) + jnp.array([[0.0031, 0.0047, 0.01], [-0.0023, 0.0011, 0.0]])
        command = jnp.array([0.22, 0.03, 0.1])
        f = jax.jit(_loss)
        grads = jax.jit(jax.grad(_loss, argnums=(1, 2, 3)))(terrain, rb, start, command)
        h = 1e-6
        worst = 0.0
        for name in ("w", "rotation_weight", "margin", "step_time", "clearance", "foot_width", "metrics.step_weight"):
            leaf = get_leaf(rb, name)
            d = jnp.asarray(np.random.default_rng(len(name)).normal(size=leaf.shape))
            fd = (f(terrain, set_leaf(rb, name, leaf + h * d), start, command)
                  - f(terrain, set_leaf(rb, name, leaf - h * d), start, command)) / (2 * h)
            an = float(jnp.sum(get_leaf(grads[0], name) * d))
            assert np.isfinite(an), name
            err = abs(float(fd) - an) / max(1.0, abs(float(fd)))
            worst = max(worst, err)
            assert err < FD_RTOL64, (name, float(fd), an)
        for k, (x, g) in enumerate(((start, grads[1]), (command, grads[2]))):
            d = jnp.asarray(np.random.default_rng(20 + k).normal(size=x.shape))
            args = [start, command]
            plus, minus = list(args), list(args)
            plus[k], minus[k] = x + h * d, x - h * d
            fd = (f(terrain, rb, *plus) - f(terrain, rb, *minus)) / (2 * h)
            err = abs(float(fd) - float(jnp.sum(g * d))) / max(1.0, abs(float(fd)))
            worst = max(worst, err)
            assert err < FD_RTOL64, ("start" if k == 0 else "command", float(fd), float(jnp.sum(g * d)))
        print(f"relaxed rollout float64 worst relative gradient error: {worst:.2e}")


@pytest.mark.slow
def test_remat_memory_grows_more_slowly():
    """XLA's compiled temp memory of the rollout gradient: remat stores the carry only, not each step's residuals."""
    terrain = ij.terrain.from_arrays(None, np.ones((40, 30), bool), RES)
    rb = ij.robots.hrp2(density=0.1)
    start = np.array([[0.2, 0.395, 0.0], [0.2, 0.205, 0.0]], np.float32)
    report = relaxed_rollout.memory_report(terrain, rb, start, [0.2, 0.0, 0.0], lengths=(2, 8))
    print(f"temp bytes of jit(grad): {report}")
    grow_plain = report[False][8] - report[False][2]
    grow_remat = report[True][8] - report[True][2]
    assert grow_plain > 0
    assert grow_remat < 0.25 * grow_plain
