"""The spring-damper input filter against scipy (expm, lsim with a zero-order hold) and closed forms."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jax.test_util import check_grads

from ijoy_jax.haptics import filter as F
from ijoy_jax.jit_cache import compiled_count

DT = 1e-3  # 1 kHz haptic loop
# float64 references: the exact discretisation and the scan agree with scipy
# to rounding; 1e-10 leaves room for 20k steps of accumulated float64 error.
TOL_F64 = 1e-10
# Closed-form 2x2 exponential vs scipy.linalg.expm, float64: a few ulps.
TOL_EXPM = 1e-13
PARAMS = [  # (natural frequency rad/s, damping ratio): under-, critically, over-damped, undamped
    (2 * np.pi * 0.1, 0.7),
    (2 * np.pi * 2.0, 0.3),
    (40.0, 1.0),
    (40.0, 1.0 + 1e-7),
    (15.0, 3.0),
    (2 * np.pi * 5.0, 0.0),
]


def _ss(w0, zeta):
    """Observable canonical form of (2 zeta w0 s + w0^2) / (s^2 + 2 zeta w0 s + w0^2), as in the module."""
    a = np.array([[-2 * zeta * w0, 1.0], [-(w0**2), 0.0]])
    b = np.array([[2 * zeta * w0], [w0**2]])
    return a, b, np.array([[1.0, 0.0]]), np.zeros((1, 1))


def _lsim_reference(u, dt, w0, zeta):
    """scipy.signal.lsim with a zero-order hold (interp=False), at rest at u[0]; our output[k] = y((k+1) dt)."""
    from scipy import signal

    a, b, c, d = _ss(w0, zeta)
    x0 = np.array([u[0], 0.0])  # rest point (u, 0) of the observable form
    t = np.arange(len(u) + 1) * dt
    _, y, _ = signal.lsim((a, b, c, d), np.append(u, u[-1]), t, X0=x0, interp=False)
    return y[1:]


@pytest.mark.parametrize("w0,zeta", PARAMS)
def test_discretisation_is_expm(w0, zeta):
    from scipy.linalg import expm

    a, *_ = _ss(w0, zeta)
    with jax.enable_x64(True):
        co = F.discretize(F.SpringDamper.create(w0, zeta), DT)
        got = np.array([[co.a11, co.a12], [co.a21, co.a22]], float)
    np.testing.assert_allclose(got, expm(a * DT), rtol=0, atol=TOL_EXPM)


@settings(max_examples=30, derandomize=True, deadline=None)
@given(st.floats(0.5, 300.0), st.floats(0.0, 5.0), st.floats(1e-4, 1e-2))
def test_discretisation_is_expm_property(w0, zeta, dt):
    from scipy.linalg import expm

    a, *_ = _ss(w0, zeta)
    with jax.enable_x64(True):
        co = F.discretize(F.SpringDamper.create(w0, zeta), dt)
        got = np.array([[co.a11, co.a12], [co.a21, co.a22]], float)
    ref = expm(a * dt)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    # Never unstable (zeta >= 0): spectral radius <= 1 (= 1 only without damping), to rounding.
    assert np.max(np.abs(np.linalg.eigvals(got))) <= 1.0 + 1e-12


@pytest.mark.parametrize("w0,zeta", PARAMS[:5])
def test_filter_matches_lsim_zero_order_hold(w0, zeta):
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.normal(size=3000)) * 0.01 + np.where(np.arange(3000) > 1500, 0.5, 0.0)
    with jax.enable_x64(True):
        y = np.asarray(F.spring_damper_filter(u, DT, w0, zeta))
    np.testing.assert_allclose(y, _lsim_reference(u, DT, w0, zeta), rtol=0, atol=TOL_F64)


def test_channels_broadcast_parameters():
    """(T, 2) signal with a different filter per axis equals filtering each axis alone."""
    rng = np.random.default_rng(1)
    u = rng.normal(size=(500, 2))
    w0, zeta = np.array([10.0, 30.0]), np.array([0.5, 1.2])
    with jax.enable_x64(True):
        y = np.asarray(F.spring_damper_filter(u, DT, w0, zeta))
    for i in range(2):
        np.testing.assert_allclose(y[:, i], _lsim_reference(u[:, i], DT, w0[i], zeta[i]), atol=TOL_F64)


def test_float32_accuracy():
    """float32 vs float64: per-step rounding (~eps |x|) accumulates at most over the filter's
    memory ~ 1 / (zeta w0 dt) steps, so the error bound is eps / (zeta w0 dt) of the signal scale."""
    rng = np.random.default_rng(2)
    u = np.cumsum(rng.normal(size=20000)) * 0.01 + np.sin(np.arange(20000) * DT * 2 * np.pi * 0.5)
    scale = np.abs(u).max()
    for w0, zeta in [(2 * np.pi * 0.1, 0.7), (2 * np.pi * 2.0, 0.7), (2 * np.pi * 20.0, 0.3)]:
        y32 = np.asarray(F.spring_damper_filter(u.astype(np.float32), DT, w0, zeta))
        assert y32.dtype == np.float32
        bound = float(np.finfo(np.float32).eps) / (zeta * w0 * DT)
        np.testing.assert_allclose(y32, _lsim_reference(u, DT, w0, zeta), atol=bound * scale)


@pytest.mark.parametrize("cutoff_hz", [0.1, 0.5, 2.0])
def test_unit_dc_gain_exact_in_float32(cutoff_hz):
    """A held input is reproduced bit for bit; a direct-form biquad with float32 coefficients is not."""
    from scipy import signal

    p = F.SpringDamper.from_cutoff(2 * np.pi * cutoff_hz, 0.7)
    w0, zeta = float(p.natural_frequency), float(p.damping_ratio)
    x = np.full(100_000, 0.7, np.float32)
    x[:10] = 0.0
    y = np.asarray(F.spring_damper_filter(x, DT, w0, zeta))
    assert y[-1] == np.float32(0.7)
    # The same exact ZOH system as a transfer function with float32 coefficients:
    b, a = signal.ss2tf(*signal.cont2discrete(_ss(w0, zeta), DT, method="zoh")[:4])
    dc = np.sum(b[0].astype(np.float32), dtype=np.float64) / np.sum(a.astype(np.float32), dtype=np.float64)
    if cutoff_hz <= 0.5:
        assert abs(dc - 1.0) > 1e-3  # the problem the state-space form avoids


def test_step_and_scan_agree_and_output_convention():
    """filter_signal is the scan of filter_step; output[0] is the first sample (at rest)."""
    co = F.discretize(F.SpringDamper.create(20.0, 0.7), DT)
    u = jnp.asarray(np.random.default_rng(3).normal(size=(50, 2)), jnp.float32)
    y, final, held = F.filter_signal(co, u)
    st_ = F.init_state(u[0])
    step = jax.jit(F.filter_step)
    outs = []
    for x in u:
        st_, _ = step(co, st_, x)
        outs.append(st_.position)
    np.testing.assert_allclose(np.stack(outs), y, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(y[0], u[0])
    assert not bool(held.any())
    np.testing.assert_allclose(final.position, y[-1])


def test_nonfinite_samples_hold_last_good_and_are_flagged():
    rng = np.random.default_rng(4)
    u = rng.normal(size=(400, 3))
    bad = rng.uniform(size=u.shape) < 0.1
    bad[:5, 1] = True  # leading bad samples: start at the first finite one
    bad[:, 2] = True  # a channel with no finite sample at all
    x = u.copy()
    x[bad] = rng.choice([np.nan, np.inf, -np.inf], size=bad.sum())
    ref_in = x.copy()  # forward fill, then back fill the leading gap
    for j in range(3):
        col = ref_in[:, j]
        good = np.isfinite(col)
        if not good.any():
            col[:] = 0.0
            continue
        idx = np.where(good, np.arange(len(col)), 0)
        np.maximum.accumulate(idx, out=idx)
        first = np.argmax(good)
        idx[:first] = first
        ref_in[:, j] = col[idx]
    with jax.enable_x64(True):
        co = F.discretize(F.SpringDamper.create(30.0, 0.8), DT)
        y, _, held = F.filter_signal(co, x)
        y_ref, _, _ = F.filter_signal(co, ref_in)
    assert np.all(np.isfinite(np.asarray(y)))
    np.testing.assert_array_equal(np.asarray(held), bad)
    np.testing.assert_allclose(np.asarray(y), np.asarray(y_ref), atol=TOL_F64)
    np.testing.assert_array_equal(np.asarray(y)[:, 2], 0.0)


def test_parameterisations():
    from scipy import signal

    c, d, m = 400.0, 28.0, 2.5
    p = F.SpringDamper.from_physical(c, d, m)
    np.testing.assert_allclose(float(p.natural_frequency), np.sqrt(c / m), rtol=1e-6)
    np.testing.assert_allclose(float(p.damping_ratio), d / (2 * np.sqrt(c * m)), rtol=1e-6)
    np.testing.assert_allclose(float(p.decay_rate), d / (2 * m), rtol=1e-6)  # the paper's "zeta"
    np.testing.assert_allclose([float(v) for v in p.to_physical(m)], [c, d, m], rtol=1e-5)
    # -3 dB frequency from the closed form against scipy.signal.freqs of the transfer function.
    for zeta in (0.3, 0.7071, 1.0, 2.0):
        q = F.SpringDamper.create(10.0, zeta)
        wc = float(q.cutoff_frequency())
        _, h = signal.freqs([2 * zeta * 10.0, 100.0], [1.0, 2 * zeta * 10.0, 100.0], worN=[wc])
        np.testing.assert_allclose(abs(h[0]), 1 / np.sqrt(2), rtol=1e-6)
        np.testing.assert_allclose(float(F.SpringDamper.from_cutoff(wc, zeta).natural_frequency), 10.0, rtol=1e-6)


def test_same_filter_from_either_parameterisation():
    u = jnp.asarray(np.random.default_rng(5).normal(size=300), jnp.float32)
    p = F.SpringDamper.from_physical(900.0, 42.0, 1.0)
    y1 = F.spring_damper_filter(u, DT, p.natural_frequency, p.damping_ratio)
    y2 = F.filter_signal(F.discretize(p, DT), u)[0]
    np.testing.assert_allclose(y1, y2, rtol=0, atol=0)


def test_no_recompile_for_new_parameters():
    """New parameter values reuse the compiled update and filter (jit caches are shared per
    function, so count the entries added after the first call)."""
    step = jax.jit(F.filter_step)
    st_ = F.init_state(jnp.zeros(2))
    sizes = []
    for w0, zeta in [(10.0, 0.5), (20.0, 0.7), (35.0, 1.0), (50.0, 2.0)]:
        co = F.discretize(F.SpringDamper.create(w0, zeta), DT)
        st_, _ = step(co, st_, jnp.array([0.1, 0.2]))
        sizes.append(compiled_count(step))
    assert len(set(sizes)) == 1
    filt = jax.jit(F.spring_damper_filter)
    u = jnp.zeros((20, 2))
    sizes = []
    for w0 in (5.0, 8.0, 13.0):
        filt(u, DT, w0, 0.7)
        sizes.append(compiled_count(filt))
    assert len(set(sizes)) == 1


def test_vmap_over_parameter_sets():
    u = jnp.asarray(np.random.default_rng(6).normal(size=(200, 2)), jnp.float32)
    w0 = jnp.array([5.0, 10.0, 40.0])
    zeta = jnp.array([0.5, 0.7, 1.5])
    ys = jax.vmap(lambda w, z: F.spring_damper_filter(u, DT, w, z))(w0, zeta)
    for i in range(3):
        np.testing.assert_allclose(ys[i], F.spring_damper_filter(u, DT, float(w0[i]), float(zeta[i])), atol=1e-6)


@pytest.mark.parametrize("zeta", [0.4, 1.0, 2.5])  # 1.0: the series branch at critical damping
def test_gradients(zeta):
    u = np.sin(np.arange(200) * 0.05)
    with jax.enable_x64(True):

        def loss(w0, z):
            return jnp.sum(F.spring_damper_filter(jnp.asarray(u), DT, w0, z) ** 2)

        check_grads(loss, (25.0, zeta), order=1, modes=("fwd", "rev"), atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize(
    "kwargs", [dict(dt=0.0), dict(natural_frequency=-1.0), dict(damping_ratio=-0.1), dict(dt=float("nan"))]
)
def test_invalid_parameters_raise(kwargs):
    args = dict(signal=np.zeros(5), dt=DT, natural_frequency=10.0, damping_ratio=0.7) | kwargs
    with pytest.raises(ValueError):
        F.spring_damper_filter(**args)


# --- issue 22: the discretisation stays finite for every stable (w0, zeta, dt) in float32 -------------------------

# float32 coefficients against the float64 matrix exponential of the float32-rounded parameters, in the scaled
# form [[a11, w0 a12], [a21 / w0, a22]] (all dimensionless, |.| <= ~1): each coefficient is a few products of
# exponentials of arguments rounded to float32, so its error is a few eps times max(x e^-x) (measured: at most
# 3.3e-7 over 1500 random points of the grid below); 1e-5 leaves 30x headroom and is still ~100 float32 eps.
TOL_F32_COEFFS = 1e-5
# The new form against the pre-issue-22 float32 closed form where that one was finite: the old form loses up to
# ~5.4e-6 (measured over the same grid) to the cancellation cosh r - sigma sinh(r)/r when overdamped; 2e-5.
TOL_OLD_COEFFS = 2e-5


def _discretise_before_22(w0, zeta, dt):
    """The closed form used before issue 22 (float32): e^-sigma [cosh r I + sinh(r)/r (M + sigma I)]."""
    w0, zeta, dt = (jnp.float32(v) for v in (w0, zeta, dt))
    wh = w0 * dt
    sigma = zeta * wh
    z = (zeta * zeta - 1.0) * wh * wh
    small = jnp.abs(z) < 1e-3
    zs = jnp.where(small, 0.0, z)
    r = jnp.sqrt(jnp.where(small, 1.0, jnp.abs(zs)))
    c_big = jnp.where(zs > 0, jnp.cosh(r), jnp.cos(r))
    s_big = jnp.where(zs > 0, jnp.sinh(r), jnp.sin(r)) / r
    zz = jnp.where(small, z, 0.0)
    c = jnp.where(small, 1.0 + zz * (1.0 / 2.0 + zz * (1.0 / 24.0 + zz / 720.0)), c_big)
    s = jnp.where(small, 1.0 + zz * (1.0 / 6.0 + zz * (1.0 / 120.0 + zz / 5040.0)), s_big)
    e = jnp.exp(-sigma)
    return np.array([e * (c - s * sigma), e * s * dt, -e * s * w0 * wh, e * (c + s * sigma)], np.float64)


def _scaled(coeffs, w0):
    a11, a12, a21, a22 = (float(v) for v in coeffs)
    return np.array([a11, w0 * a12, a21 / w0, a22])


def _expm_scaled(w0, zeta, dt):
    from scipy.linalg import expm

    w0, zeta, dt = (float(np.float32(v)) for v in (w0, zeta, dt))
    a, *_ = _ss(w0, zeta)
    e = expm(a * dt)
    return np.array([e[0, 0], w0 * e[0, 1], e[1, 0] / w0, e[1, 1]])


@pytest.mark.parametrize(
    "w0,zeta,dt",
    [(10.0, 3.0, 10.0), (2e4, 1.5, 5e-3), (1e4, 50.0, 10.0), (3.0, 1.0 + 1e-6, 10.0), (1e-3, 50.0, 1e-6)],
)
def test_overdamped_discretisation_finite_in_float32(w0, zeta, dt):
    """cosh(r) overflowed float32 for r = w0 dt sqrt(zeta^2 - 1) > ~89 and the whole signal came out NaN."""
    co = F.discretize(F.SpringDamper.create(w0, zeta), dt)
    got = _scaled(co[:4], float(np.float32(w0)))
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, _expm_scaled(w0, zeta, dt), rtol=0, atol=TOL_F32_COEFFS)
    y = np.asarray(F.spring_damper_filter(np.linspace(0.0, 1.0, 50, dtype=np.float32), dt, w0, zeta))
    assert np.all(np.isfinite(y))


_LOG_GRID = dict(allow_nan=False, allow_infinity=False)


@settings(max_examples=300, derandomize=True, deadline=None)
@given(
    st.floats(-3.0, 4.0, **_LOG_GRID),
    st.floats(np.log10(0.05), np.log10(50.0), **_LOG_GRID),
    st.floats(-6.0, 1.0, **_LOG_GRID),
)
def test_discretisation_float32_over_wide_grid(log_w0, log_zeta, log_dt):
    """w0 over 1e-3..1e4 rad/s, zeta 0.05..50, dt 1e-6..10 s: float32 coefficients are finite, match the float64
    matrix exponential, keep the filter stable, and match the old closed form wherever that one was finite."""
    w0, zeta, dt = 10.0**log_w0, 10.0**log_zeta, 10.0**log_dt
    co = F.discretize(F.SpringDamper.create(w0, zeta), dt)
    w0_32 = float(np.float32(w0))
    got = _scaled(co[:4], w0_32)
    assert np.all(np.isfinite(got)) and not bool(co.invalid)
    np.testing.assert_allclose(got, _expm_scaled(w0, zeta, dt), rtol=0, atol=TOL_F32_COEFFS)
    assert np.max(np.abs(np.linalg.eigvals(got.reshape(2, 2)))) <= 1.0 + TOL_F32_COEFFS
    old = _discretise_before_22(w0, zeta, dt)
    # Where the old form was finite *and* e^-sigma still a normal float32 (beyond, it flushed to 0 times a finite
    # cosh: finite but wrong, e.g. 0 instead of a11 = -9e-4 at w0 = 5.6, zeta = 3.9, dt = 4.1).
    sigma = float(np.float32(zeta) * np.float32(w0) * np.float32(dt))
    if np.all(np.isfinite(old)) and sigma < 87.0:
        np.testing.assert_allclose(got, _scaled(old, w0_32), rtol=0, atol=TOL_OLD_COEFFS)


def test_negative_dt_inside_jit_passes_the_input_through_and_flags():
    """dt < 0 inside jit gave ~1e6 for a 0.4 input; now the coefficients are flagged and the input passes through."""
    u = jnp.full(200, 0.4, jnp.float32).at[:20].set(0.0)
    y = jax.jit(F.spring_damper_filter)(u, -1e-3, 20.0, 0.7)
    np.testing.assert_array_equal(np.asarray(y), np.asarray(u))
    co = jax.jit(F.discretize)(F.SpringDamper.create(20.0, 0.7), jnp.array([-1e-3, 0.0, jnp.nan, 1e-3]))
    np.testing.assert_array_equal(np.asarray(co.invalid), [True, True, True, False])
    assert np.all(np.asarray(co[:4])[:, :3] == 0.0)


@pytest.mark.parametrize(
    "w0,zeta", [(jnp.nan, 0.7), (jnp.inf, 0.7), (-5.0, 0.7), (0.0, 0.7), (20.0, -0.5), (20.0, jnp.nan)]
)
def test_bad_parameters_inside_jit_are_flagged(w0, zeta):
    co = jax.jit(F.discretize)(F.SpringDamper.create(w0, zeta), 1e-3)
    assert bool(co.invalid)
    u = jnp.linspace(0.0, 1.0, 30)
    y = jax.jit(F.spring_damper_filter)(u, 1e-3, w0, zeta)
    np.testing.assert_array_equal(np.asarray(y), np.asarray(u))


@pytest.mark.parametrize("dt", [-1e-3, 0.0, float("inf"), float("nan")])
def test_discretise_refuses_concrete_bad_dt(dt):
    with pytest.raises(ValueError, match="dt"):
        F.discretize(F.SpringDamper.create(20.0, 0.7), dt)
    with pytest.raises(ValueError, match="dt"):
        F.spring_damper_filter(np.zeros(5), dt, 20.0, 0.7)


@pytest.mark.parametrize("shape", [(0,), (0, 2)])
def test_empty_signal_gives_an_empty_output(shape):
    """An empty signal failed inside JAX with "argmax of an empty sequence"."""
    y = F.spring_damper_filter(np.zeros(shape, np.float32), DT, 20.0, 0.7)
    assert y.shape == shape
    y, final, held = F.filter_signal(F.discretize(F.SpringDamper.create(20.0, 0.7), DT), jnp.zeros(shape))
    assert y.shape == shape and held.shape == shape and final.position.shape == shape[1:]
    np.testing.assert_array_equal(np.asarray(final.position), 0.0)
