"""Tests of ijoy_jax.haptics.tuning: gradients vs finite differences and held-out gains over the defaults."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ijoy_jax.haptics import alduro_leg
from ijoy_jax.haptics import tuning as haptic

FD_RTOL64 = 1e-5  # float64 central differences, h = 1e-6 in log-parameters (truncation ~h^2, rounding ~1e-16/h)
NUM_SAMPLES = 3000  # 3 s at 1 kHz: 2.5 s after settling, 0.4 Hz FFT bins (10 of them in 8-12 Hz)
TRAIN_KEY, HELD_OUT_KEY = 0, 12345


def _fd(f, x, d, h=1e-6):
    return (f(x + h * d) - f(x - h * d)) / (2 * h)


@pytest.mark.parametrize("f0_zeta", [haptic.DEFAULT_FILTER, (0.5, 1.0)])
def test_filter_objective_gradient_float64(f0_zeta):
    """Through the exact ZOH discretisation, including critical damping (zeta = 1: the series branch)."""
    with jax.enable_x64(True):
        sig = haptic.synthetic_joystick(3, NUM_SAMPLES, dtype=jnp.float64)
        p = jnp.log(jnp.asarray(f0_zeta, jnp.float64))
        f = jax.jit(lambda q: haptic.filter_objective(q, sig)["loss"])
        g = jax.jit(jax.grad(lambda q: haptic.filter_objective(q, sig)["loss"]))(p)
        assert np.all(np.isfinite(np.asarray(g)))
        for d in (jnp.array([1.0, 0.0]), jnp.array([0.0, 1.0]), jnp.array([0.6, -0.8])):
            fd = float(_fd(f, p, d))
            assert abs(fd - float(g @ d)) <= FD_RTOL64 * max(1.0, abs(fd)), (d, fd, float(g @ d))


@pytest.mark.slow
def test_tuned_filter_beats_default_on_held_out_signals():
    result = haptic.tune_filter(TRAIN_KEY, num_signals=2, num_samples=NUM_SAMPLES, steps=80)
    losses = np.asarray(result.losses)
    assert np.all(np.isfinite(losses)) and losses[-1] < losses[0]
    default = haptic.evaluate_filter(jnp.log(jnp.asarray(haptic.DEFAULT_FILTER)), HELD_OUT_KEY,
                                     num_samples=NUM_SAMPLES)
    tuned = haptic.evaluate_filter(result.log_params, HELD_OUT_KEY, num_samples=NUM_SAMPLES)
    f0, zeta = np.exp(np.asarray(result.log_params))
    print(f"filter: default (f0 {haptic.DEFAULT_FILTER[0]:.3f} Hz, zeta {haptic.DEFAULT_FILTER[1]:.3f}) {default}; "
          f"tuned (f0 {f0:.3f} Hz, zeta {zeta:.3f}) {tuned}")
    assert tuned["loss"] < 0.9 * default["loss"]


@pytest.mark.slow
def test_repulsion_objective_gradient_float64():
    with jax.enable_x64(True):
        leg = alduro_leg(-1.0, dtype=jnp.float64)
        q0, intent = haptic.operator_batch(4, 1, num_steps=60, leg=leg)
        intent = intent.astype(jnp.float64)

        def loss(p):
            return haptic.repulsion_objective(p, leg, q0[0], intent[0])["loss"]

        p = jnp.log(jnp.asarray(haptic.DEFAULT_REPULSION, jnp.float64))
        f = jax.jit(loss)
        g = jax.jit(jax.grad(loss))(p)
        assert np.all(np.isfinite(np.asarray(g))) and float(jnp.abs(g).sum()) > 0
        for d in (jnp.array([1.0, 0.0]), jnp.array([0.0, 1.0])):
            fd = float(_fd(f, p, d))
            assert abs(fd - float(g @ d)) <= FD_RTOL64 * max(1.0, abs(fd)), (d, fd, float(g @ d))


@pytest.mark.slow
def test_tuned_repulsion_beats_default_on_held_out_operators():
    kw = dict(num_steps=100)
    result = haptic.tune_repulsion(TRAIN_KEY, num_trajectories=16, steps=40, **kw)
    assert np.all(np.isfinite(np.asarray(result.losses)))
    default = haptic.evaluate_repulsion(jnp.log(jnp.asarray(haptic.DEFAULT_REPULSION)), HELD_OUT_KEY,
                                        num_trajectories=16, **kw)
    tuned = haptic.evaluate_repulsion(result.log_params, HELD_OUT_KEY, num_trajectories=16, **kw)
    c1, lam = np.exp(np.asarray(result.log_params))
    print(f"repulsion: default (C1 {haptic.DEFAULT_REPULSION[0]} N, decay {haptic.DEFAULT_REPULSION[1]} m) {default}; "
          f"tuned (C1 {c1:.3f} N, decay {lam:.4f} m) {tuned}")
    assert tuned["loss"] < default["loss"]
