"""Force-feedback tuners: the input filter's (f0, zeta) and the repulsion constants (C1, decay length).

Both are tuned by gradient (optax Adam on log-parameters, so they stay
positive) through the exact models of :mod:`ijoy_jax.haptics`, on synthetic
data with explicit PRNG keys, and evaluated on held-out keys against defaults.

Input filter (ALDURO paper, section 2.1). The filter should remove "small
involuntary movements" while "large deflections of the joystick are
transmitted almost instantly". Synthetic joystick signal (:func:`synthetic_joystick`):
a smooth intended command (three sinusoids of 0.1-1 Hz, RMS 0.3 of full
deflection) + physiological tremor (Gaussian noise band-limited to 8-12 Hz, RMS
0.05) + white sensor noise (RMS 0.005). Objective (:func:`filter_objective`),
after a 0.5 s settling time::

    loss = tremor + lam * tracking + overshoot_weight * overshoot^2,
    tremor    = output power in the tremor band / input power in that band  (FFT, band-limited),
    tracking  = mean (H intended - intended)^2 / mean intended^2             (lag and gain error),
    overshoot = max(unit-step response) - 1                                  (resonance),

where ``H intended`` is the filtered intended signal (the filter is linear, so
it is exactly the intended part of the output). Without the overshoot term the
optimum is a nearly undamped filter (zeta ~ 0.06, f0 ~ 2.6 Hz: second-order
roll-off over the tremor band, no lag below 1 Hz) that rings at f0 after any
jolt, which the synthetic signal happens not to excite. Gradients flow through the
exact ZOH discretisation (:func:`ijoy_jax.haptics.filter.discretize`). Default
filter (:data:`DEFAULT_FILTER`): the paper gives no numbers, so the reference is
the docs' matched-cut-off spring-damper, -3 dB at 2 Hz with zeta = 1/sqrt 2
(f0 = 0.972 Hz).

Repulsion constants (section 3.2). The repulsive force should "inform the
operator of the proximity of [the workspace] limits", and workspace is "only of
interest to the operator when the robot is close to the limit": so it should
keep the leg inside its strokes while costing the operator as little force as
possible away from them. Simulation (:func:`simulate_leg`): an operator drives
the foot of the ALDURO-like leg (:func:`ijoy_jax.haptics.alduro_leg`) with a
smooth intended foot velocity (:func:`operator_intent`); the operator's hand
yields to the joystick force with an admittance (m/s per N), so the commanded
velocity is ``v = v_intent + admittance * f``; cylinder rates follow by damped
least squares ``dq = J^T (J J^T + mu^2 I)^-1 v``; q is integrated unclamped so
that driving past an end of stroke is measured (the real cylinder would hit
its end stop). Objective (:func:`repulsion_objective`)::

    loss = overrun + force_weight * force,
    overrun = mean_t sum_i (stroke overrun_i / 1 cm)^2,   force = mean_t (|f| / 1 N)^2.

Defaults (:data:`DEFAULT_REPULSION`): C1 = 1 N, decay length 5 cm (the
examples of :mod:`ijoy_jax.haptics.leg`; the paper gives no numbers).

Units: seconds, hertz, metres, newtons; signals in fractions of full deflection.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from ijoy_jax import optim
from ijoy_jax.haptics.filter import SpringDamper, discretize, filter_signal, init_state
from ijoy_jax.haptics.leg import LegGeometry, alduro_leg, forward_kinematics
from ijoy_jax.haptics.workspace import linearize, plane_forces
from ijoy_jax.prng import as_key

TREMOR_BAND_HZ = (8.0, 12.0)
SETTLE_S = 0.5  # s of start-up transient excluded from every metric
#: Default filter: -3 dB at 2 Hz, zeta = 1/sqrt(2) (docs/haptics.md's matched-cut-off row): (f0 Hz, zeta).
DEFAULT_FILTER = (
    2.0 / math.sqrt(1.0 + 2 * 0.5 + math.sqrt((1.0 + 2 * 0.5) ** 2 + 1.0)),
    1.0 / math.sqrt(2.0),
)
#: Default repulsion: (C1 N, decay length m).
DEFAULT_REPULSION = (1.0, 0.05)


def _band_noise(key, n: int, dt: float, lo_hz: float, hi_hz: float, rms, dtype):
    """(n,) Gaussian noise band-limited to [lo_hz, hi_hz] by an FFT mask, scaled to the given RMS."""
    freqs = jnp.fft.rfftfreq(n, dt)
    kr, ki = jax.random.split(key)
    spec = jax.random.normal(kr, freqs.shape, dtype) + 1j * jax.random.normal(ki, freqs.shape, dtype)
    spec = jnp.where((freqs >= lo_hz) & (freqs <= hi_hz), spec, 0.0)
    x = jnp.fft.irfft(spec, n).astype(dtype)
    return x * (rms / jnp.sqrt(jnp.mean(x * x)))


class JoystickSignal(NamedTuple):
    """One synthetic joystick channel, all (T,) in fractions of full deflection.

    raw = intended + tremor + noise (what the joystick reports).
    """

    raw: jax.Array
    intended: jax.Array
    tremor: jax.Array
    noise: jax.Array


def synthetic_joystick(key, num_samples: int = 4000, dt: float = 1e-3, *, intended_rms=0.3, tremor_rms=0.05,
                       noise_rms=0.005, dtype=jnp.float32) -> JoystickSignal:
    """A synthetic joystick signal: smooth intended command + 8-12 Hz tremor + white noise.

    Args:
      key: PRNG key or int seed.
      num_samples: T (static).
      dt: sample period (s), static.
      intended_rms, tremor_rms, noise_rms: RMS of each part (fraction of full deflection).
      dtype: float dtype.

    Returns:
      :class:`JoystickSignal` of (T,) arrays.

    Example:
      >>> s = synthetic_joystick(0, 1000)
      >>> s.raw.shape, round(float(jnp.sqrt(jnp.mean(s.tremor ** 2))), 3)
      ((1000,), 0.05)
    """
    k_f, k_p, k_a, k_t, k_n = jax.random.split(as_key(key), 5)
    t = jnp.arange(num_samples, dtype=dtype) * dt
    f = jax.random.uniform(k_f, (3,), dtype, 0.1, 1.0)
    phase = jax.random.uniform(k_p, (3,), dtype, 0.0, 2 * jnp.pi)
    amp = jax.random.uniform(k_a, (3,), dtype, 0.5, 1.0)
    intended = jnp.sum(amp * jnp.sin(2 * jnp.pi * f * t[:, None] + phase), axis=1)
    intended = intended * (intended_rms / jnp.sqrt(jnp.mean(intended**2)))
    tremor = _band_noise(k_t, num_samples, dt, *TREMOR_BAND_HZ, tremor_rms, dtype)
    noise = noise_rms * jax.random.normal(k_n, (num_samples,), dtype)
    return JoystickSignal(intended + tremor + noise, intended, tremor, noise)


def filter_params(log_params) -> SpringDamper:
    """SpringDamper from ``log_params`` (2,) = (log f0 [log Hz], log zeta)."""
    return SpringDamper(2 * jnp.pi * jnp.exp(log_params[0]), jnp.exp(log_params[1]))


def filter_objective(log_params, signal: JoystickSignal, dt: float = 1e-3, lam=1.0,
                     overshoot_weight=1.0) -> dict[str, jax.Array]:
    """Tremor-vs-lag objective of the spring-damper filter on one signal, as named terms.

    Args:
      log_params: (2,) (log f0 [log Hz], log zeta).
      signal: :class:`JoystickSignal` of (T,) arrays.
      dt: sample period (s), static.
      lam: () weight of the tracking term.
      overshoot_weight: () weight of the squared step overshoot.

    Returns:
      dict of () arrays: ``loss`` = ``tremor`` + lam * ``tracking`` + overshoot_weight * ``overshoot``^2
      (see the module docstring); ``tremor`` (output/input power ratio in 8-12 Hz), ``tracking``
      (normalised MSE of the intended signal), ``overshoot`` (unit-step overshoot, fraction).
    """
    coeffs = discretize(filter_params(log_params), dt)
    s = int(round(SETTLE_S / dt))
    step = (jnp.arange(signal.raw.shape[0]) >= s).astype(signal.raw.dtype)  # unit step at the end of settling
    x = jnp.stack([signal.raw, signal.intended, step], axis=1)  # (T, 3): output, its intended part (linearity), step
    y, _, _ = filter_signal(coeffs, x, init_state(x[0]))
    out, out_int = y[s:, 0], y[s:, 1]
    overshoot = jax.nn.relu(jnp.max(y[s:, 2]) - 1.0)
    raw, intended = signal.raw[s:], signal.intended[s:]
    freqs = jnp.fft.rfftfreq(out.shape[0], dt)
    band = (freqs >= TREMOR_BAND_HZ[0]) & (freqs <= TREMOR_BAND_HZ[1])

    def band_power(v):
        return jnp.sum(jnp.where(band, jnp.abs(jnp.fft.rfft(v)) ** 2, 0.0))

    tremor = band_power(out) / band_power(raw)
    tracking = jnp.mean((out_int - intended) ** 2) / jnp.mean(intended**2)
    return {
        "loss": tremor + lam * tracking + overshoot_weight * overshoot**2,
        "tremor": tremor,
        "tracking": tracking,
        "overshoot": overshoot,
    }


class HapticTuneResult(NamedTuple):
    """A haptic tuning run: final log-parameters (2,), and per-step loss (steps,) and log-parameters (steps, 2)."""

    log_params: jax.Array
    losses: jax.Array
    trajectory: jax.Array


def _adam_run(loss_fn, init, steps: int, learning_rate: float) -> HapticTuneResult:
    """Adam on ``loss_fn(log_params)`` by the one tuning loop (:func:`ijoy_jax.optim.run_steps`)."""
    tuner = optim.make_tuner(lambda p, _: loss_fn(p), optax.adam(learning_rate))
    state, metrics, trajectory = optim.run_steps(tuner, tuner.init(init), steps, trace_params=True)
    return HapticTuneResult(state.params, metrics.loss, trajectory)


def filter_batch_loss(log_params, signals: JoystickSignal, dt: float = 1e-3, lam=1.0) -> jax.Array:
    """() mean :func:`filter_objective` loss over a batch of signals (leading axis B)."""
    return jnp.mean(jax.vmap(lambda s: filter_objective(log_params, s, dt, lam)["loss"])(signals))


def tune_filter(key, *, num_signals: int = 4, num_samples: int = 4000, dt: float = 1e-3, lam=1.0,
                steps: int = 150, learning_rate: float = 0.05, init=DEFAULT_FILTER) -> HapticTuneResult:
    """Tune (f0, zeta) by Adam on a batch of synthetic joystick signals.

    Args:
      key: PRNG key or int seed of the training signals.
      num_signals, num_samples, dt: training batch (static).
      lam: tracking weight of :func:`filter_objective`.
      steps, learning_rate: Adam on (log f0, log zeta).
      init: (f0 Hz, zeta) starting point.

    Returns:
      :class:`HapticTuneResult`; ``filter_params(result.log_params)`` is the tuned SpringDamper.

    Example:
      >>> r = tune_filter(0, num_signals=1, num_samples=1500, steps=3)
      >>> r.losses.shape
      (3,)
    """
    keys = jax.random.split(as_key(key), num_signals)
    signals = jax.vmap(lambda k: synthetic_joystick(k, num_samples, dt))(keys)
    init = jnp.log(jnp.asarray(init, jnp.float32))
    return _tune_filter_jit(init, signals, dt, lam, steps, learning_rate)


@jax.jit(static_argnames=("dt", "steps", "learning_rate"))
def _tune_filter_jit(init, signals, dt, lam, steps, learning_rate):
    return _adam_run(lambda p: filter_batch_loss(p, signals, dt, lam), init, steps, learning_rate)


def evaluate_filter(log_params, key, *, num_signals: int = 8, num_samples: int = 4000, dt: float = 1e-3,
                    lam=1.0) -> dict[str, float]:
    """Mean :func:`filter_objective` terms over held-out synthetic signals (host floats)."""
    keys = jax.random.split(as_key(key), num_signals)
    signals = jax.vmap(lambda k: synthetic_joystick(k, num_samples, dt))(keys)
    return {k: float(v) for k, v in _filter_terms(jnp.asarray(log_params), signals, dt, lam).items()}


@jax.jit(static_argnames=("dt",))
def _filter_terms(log_params, signals, dt, lam):
    terms = jax.vmap(lambda s: filter_objective(log_params, s, dt, lam))(signals)
    return {k: jnp.mean(v) for k, v in terms.items()}


# ---------------------------------------------------------------------------
# Repulsion constants.

OVERRUN_SCALE = 0.01  # m of cylinder overrun that costs 1
FORCE_SCALE = 1.0  # N of force that costs 1
DLS_DAMPING = 0.02  # m: damped-least-squares mu; guards J J^T at singular poses


class LegRollout(NamedTuple):
    """Simulated operator-driven leg, per step (T,): q (T, 4) m, force (T, 3) N, foot (T, 3) m (hip frame)."""

    q: jax.Array
    force: jax.Array
    foot: jax.Array


def operator_intent(key, num_steps: int = 200, dt: float = 0.02, *, speed_rms=0.1, drift=1.0,
                    dtype=jnp.float32) -> jax.Array:
    """(T, 3) smooth intended foot velocity (m/s): per axis two sinusoids of 0.05-0.5 Hz plus a constant drift.

    The drift (``drift`` times ``speed_rms``, random direction) makes the operator lean on a workspace
    limit within a few seconds: the force must hold the leg there against the push.
    """
    k_f, k_p, k_a, k_d = jax.random.split(as_key(key), 4)
    t = jnp.arange(num_steps, dtype=dtype) * dt
    f = jax.random.uniform(k_f, (2, 3), dtype, 0.05, 0.5)
    ph = jax.random.uniform(k_p, (2, 3), dtype, 0.0, 2 * jnp.pi)
    a = jax.random.uniform(k_a, (2, 3), dtype, 0.5, 1.0)
    v = jnp.sum(a * jnp.sin(2 * jnp.pi * f * t[:, None, None] + ph), axis=1)
    v = v * (speed_rms / jnp.sqrt(jnp.mean(v * v)))
    d = jax.random.normal(k_d, (3,), dtype)
    return v + (drift * speed_rms) * d / jnp.sqrt(jnp.sum(d * d))


def simulate_leg(leg: LegGeometry, q0, intent, c1, decay_length, *, dt: float = 0.02, admittance=0.05) -> LegRollout:
    """Operator-driven leg with the repulsive force fed back through the hand (module docstring).

    Args:
      leg: LegGeometry.
      q0: (4,) initial cylinder positions (m), inside the strokes.
      intent: (T, 3) intended foot velocity (m/s, hip frame).
      c1: () C1 (N); decay_length: () lambda (m) > 0.
      dt: step (s); admittance: () m/s of commanded foot velocity per N of joystick force.

    Returns:
      :class:`LegRollout`; q is integrated unclamped (overrun is measured, not prevented).
    """
    fk = lambda x: forward_kinematics(leg, x)  # noqa: E731

    def step(q, v_intent):
        ws = linearize(fk, q, leg.q_min, leg.q_max)
        f = plane_forces(ws.planes, c1, 1.0 / decay_length).force
        v = v_intent + admittance * f
        j = ws.jacobian
        jjt = j @ j.T + DLS_DAMPING**2 * jnp.eye(3, dtype=j.dtype)
        q_next = q + dt * (j.T @ jnp.linalg.solve(jjt, v))
        return q_next, (q_next, f, ws.position)

    _, (q, f, foot) = jax.lax.scan(step, jnp.asarray(q0, intent.dtype), intent)
    return LegRollout(q, f, foot)


def repulsion_objective(log_params, leg: LegGeometry, q0, intent, *, dt: float = 0.02, admittance=0.05,
                        force_weight=0.1) -> dict[str, jax.Array]:
    """Named terms of the repulsion objective on one operator trajectory.

    Args:
      log_params: (2,) (log C1 [log N], log decay length [log m]).
      leg, q0, intent, dt, admittance: as :func:`simulate_leg`.
      force_weight: () weight of the force term.

    Returns:
      dict of (): ``loss`` = ``overrun`` + force_weight * ``force``; ``overrun`` (mean sum of squared
      stroke overruns in units of 1 cm), ``force`` (mean squared force in N^2), ``outside`` (fraction of
      steps with a cylinder past an end of stroke; no gradient), ``max_overrun_m``.
    """
    r = simulate_leg(leg, q0, intent, jnp.exp(log_params[0]), jnp.exp(log_params[1]), dt=dt, admittance=admittance)
    over = jax.nn.relu(r.q - leg.q_max) + jax.nn.relu(leg.q_min - r.q)  # (T, 4) m
    overrun = jnp.mean(jnp.sum((over / OVERRUN_SCALE) ** 2, axis=1))
    force = jnp.mean(jnp.sum(r.force**2, axis=1)) / FORCE_SCALE**2
    return {
        "loss": overrun + force_weight * force,
        "overrun": overrun,
        "force": force,
        "outside": jax.lax.stop_gradient(jnp.mean(jnp.any(over > 0, axis=1))),
        "max_overrun_m": jax.lax.stop_gradient(jnp.max(over)),
    }


def operator_batch(key, num: int, num_steps: int = 200, dt: float = 0.02, leg: LegGeometry | None = None):
    """``(q0 (B, 4), intent (B, T, 3))``: random starts in the middle 20-80 % of the strokes and intents."""
    leg = alduro_leg(-1.0) if leg is None else leg
    kq, ki = jax.random.split(as_key(key))
    u = jax.random.uniform(kq, (num, 4), leg.stroke.dtype, 0.2, 0.8)
    q0 = leg.q_min + u * (leg.q_max - leg.q_min)
    intent = jax.vmap(lambda k: operator_intent(k, num_steps, dt))(jax.random.split(ki, num))
    return q0, intent


def repulsion_batch_terms(log_params, leg, q0, intent, *, dt=0.02, admittance=0.05, force_weight=0.1):
    """Mean of :func:`repulsion_objective`'s terms over a batch (q0 (B, 4), intent (B, T, 3))."""
    terms = jax.vmap(lambda q, v: repulsion_objective(log_params, leg, q, v, dt=dt, admittance=admittance,
                                                      force_weight=force_weight))(q0, intent)
    return {k: jnp.mean(v) for k, v in terms.items()}


def tune_repulsion(key, *, num_trajectories: int = 8, num_steps: int = 200, dt: float = 0.02, admittance=0.05,
                   force_weight=0.1, steps: int = 60, learning_rate: float = 0.1, init=DEFAULT_REPULSION,
                   leg: LegGeometry | None = None) -> HapticTuneResult:
    """Tune (C1, decay length) by Adam on simulated operator trajectories of the ALDURO-like leg.

    Args:
      key: PRNG key or int seed of the training trajectories.
      num_trajectories, num_steps, dt: training batch (static).
      admittance, force_weight: as :func:`repulsion_objective`.
      steps, learning_rate: Adam on (log C1, log decay length).
      init: (C1 N, decay length m).
      leg: default ``alduro_leg(-1.0)`` (the paper's right leg).

    Returns:
      :class:`HapticTuneResult`; ``jnp.exp(result.log_params)`` = (C1, decay length).
    """
    leg = alduro_leg(-1.0) if leg is None else leg
    q0, intent = operator_batch(key, num_trajectories, num_steps, dt, leg)
    init = jnp.log(jnp.asarray(init, jnp.float32))
    return _tune_repulsion_jit(init, leg, q0, intent, dt, admittance, force_weight, steps, learning_rate)


@jax.jit(static_argnames=("dt", "steps", "learning_rate"))
def _tune_repulsion_jit(init, leg, q0, intent, dt, admittance, force_weight, steps, learning_rate):
    def loss(p):
        return repulsion_batch_terms(p, leg, q0, intent, dt=dt, admittance=admittance,
                                     force_weight=force_weight)["loss"]

    return _adam_run(loss, init, steps, learning_rate)


def evaluate_repulsion(log_params, key, *, num_trajectories: int = 16, num_steps: int = 200, dt: float = 0.02,
                       admittance=0.05, force_weight=0.1, leg: LegGeometry | None = None) -> dict[str, float]:
    """Mean repulsion terms over held-out operator trajectories (host floats)."""
    leg = alduro_leg(-1.0) if leg is None else leg
    q0, intent = operator_batch(key, num_trajectories, num_steps, dt, leg)
    terms = _repulsion_terms_jit(jnp.asarray(log_params), leg, q0, intent, dt=dt, admittance=admittance,
                                 force_weight=force_weight)
    return {k: float(v) for k, v in terms.items()}


_repulsion_terms_jit = jax.jit(repulsion_batch_terms, static_argnames=("dt",))
