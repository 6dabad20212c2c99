"""Tests of ijoy_jax.sim.preview: preview gains against SciPy, tracking, ZMP reference timing."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from jax import lax

from ijoy_jax.sim import preview as pv
from ijoy_jax.testing import enable_x64

# float64 gains against SciPy's DARE: both solve the same equation to machine
# precision; 1e-8 relative leaves room for the Riccati's conditioning (~1e4).
GAIN_RTOL_F64 = 1e-8
# float32: the doubling runs through W = I + G H with cond(W) up to ~1e8
# (r = 1e-6 against a ZMP that depends on cddot through z_c / g), so
# eps32 * cond is the scale; measured errors are 1e-4 .. 7e-4 relative.
GAIN_RTOL_F32 = 3e-3
G = 9.81
# float64 trajectory against the textbook loop: same maths, different association
# (the update is formed about zmp_future[0]); cddot ~ 3 m/s^2 differs by ~1e-8.
TRAJ_RTOL_F64 = 1e-8

# One horizon for all cases: it is static, so they share one compile per dtype.
CASES = [(0.8, 0.005, 161), (0.8, 0.01, 161), (0.6, 0.002, 161)]


def np_gains(zc, dt, n, q=1.0, r=1e-6, g=G):
    """Textbook preview gains (Kajita 2003 / Katayama 1985) with SciPy's DARE, float64."""
    a = np.array([[1, dt, dt * dt / 2], [0, 1, dt], [0, 0, 1]])
    b = np.array([dt**3 / 6, dt * dt / 2, dt])
    c = np.array([1, 0, -zc / g])
    at = np.zeros((4, 4))
    at[0, 0] = 1
    at[0, 1:] = c @ a
    at[1:, 1:] = a
    bt = np.r_[c @ b, b]
    qt = np.zeros((4, 4))
    qt[0, 0] = q
    p = scipy.linalg.solve_discrete_are(at, bt[:, None], qt, np.array([[r]]))
    d = r + bt @ p @ bt
    gi = (bt @ p[:, 0]) / d
    gx = (bt @ p @ at[:, 1:]) / d
    ac = at - np.outer(bt, np.r_[gi, gx])
    gd = [0.0]
    x = p[:, 0].copy()
    for _ in range(1, n):
        gd.append(-(bt @ x) / d)
        x = ac.T @ x
    return dict(A=a, B=b, C=c, P=p, Gi=gi, Gx=gx, Gd=np.array(gd))


def np_servo(ref, zc, dt, n, x0, q=1.0, r=1e-6, e0=None):
    """Textbook preview servo loop, float64, world frame. ref: (T + n, 2)."""
    g = np_gains(zc, dt, n, q, r)
    x = np.array(x0, float)
    e = np.zeros(2) if e0 is None else np.array(e0, float)
    out = []
    for k in range(ref.shape[0] - n + 1):
        e = e + g["C"] @ x - ref[k]
        u = -g["Gi"] * e - g["Gx"] @ x - g["Gd"] @ ref[k : k + n]
        x = g["A"] @ x + g["B"][:, None] * u[None]
        out.append(x.copy())
    return np.array(out)


@functools.partial(jax.jit, static_argnums=4)
def _servo(gains, ref, x0, e0, steps):
    n = gains.Gd.shape[0]

    def body(carry, k):
        x, e = carry
        x, e, z = pv.preview_update(gains, x, e, lax.dynamic_slice_in_dim(ref, k, n))
        return (x, e), (x, z)

    return lax.scan(body, (x0, e0), jnp.arange(steps))[1]


def run_servo(gains, ref, x0, e0=None):
    """jit + scan of preview_update over a fixed reference array (T + N - 1, 2)."""
    e0 = jnp.zeros(2, gains.Gi.dtype) if e0 is None else e0
    return _servo(gains, ref, x0, e0, ref.shape[0] - gains.Gd.shape[0] + 1)


def rel_err(a, b):
    return np.max(np.abs(np.asarray(a, np.float64) - b)) / np.max(np.abs(b))


@pytest.mark.parametrize("zc,dt,n", CASES)
def test_gains_match_scipy(zc, dt, n):
    ref = np_gains(zc, dt, n)
    with enable_x64():
        g = pv.preview_gains(zc, dt, n)  # jitted inside, static horizon
        assert g.Gi.dtype == jnp.float64
        for k in ("P", "Gi", "Gx", "Gd", "A", "B", "C"):
            assert rel_err(getattr(g, k), ref[k]) < GAIN_RTOL_F64, k
    g = pv.preview_gains(zc, dt, n)  # jitted inside, static horizon
    assert g.Gi.dtype == jnp.float32
    for k in ("P", "Gi", "Gx", "Gd"):
        assert rel_err(getattr(g, k), ref[k]) < GAIN_RTOL_F32, k
    assert g.Gd[0] == 0 and np.isclose(g.Gd[1], -g.Gi)


def test_bad_static_arguments():
    with pytest.raises(ValueError, match="horizon"):
        pv.preview_gains(0.8, 0.005, 0)
    with pytest.raises(ValueError, match="horizon"):
        pv.preview_gains(0.8, 0.005, 2.5)
    with pytest.raises(ValueError, match="dt"):
        pv.preview_gains(0.8, 0.0, 10)
    with pytest.raises(ValueError, match="com_height"):
        pv.preview_gains(-0.8, 0.005, 10)
    with pytest.raises(ValueError, match="horizon"):
        pv.zmp_reference(jnp.zeros((4, 2)), 0.0, 0.005, 0, 0.8, 0.1)
    with pytest.raises(ValueError, match="waypoints"):
        pv.zmp_reference(jnp.zeros((4, 3)), 0.0, 0.005, 10, 0.8, 0.1)
    g = pv.preview_gains(0.8, 0.01, 161)
    with pytest.raises(ValueError, match="horizon"):
        pv.preview_update(g, pv.initial_state(jnp.zeros(2)), jnp.zeros(2), jnp.zeros((160, 2)))


def test_no_recompile_and_vmap_and_grad():
    traces = []

    def f(zc, dt):
        traces.append(1)
        return pv.preview_gains(zc, dt, 161)

    jf = jax.jit(f)
    f32 = jnp.float32
    a = jf(f32(0.8), f32(0.01))
    b = jf(f32(0.75), f32(0.01))
    c = jf(f32(0.7), f32(0.012))
    assert len(traces) == 1
    assert a.Gi != b.Gi != c.Gi
    # vmap over CoM heights (domain randomisation) with finite float32 gradients.
    gains_of = lambda z: pv.preview_gains(z, 0.01, 161)  # noqa: E731
    batch, grads = jax.jit(jax.vmap(jax.value_and_grad(lambda z: gains_of(z).Gi)))(jnp.array([0.7, 0.8, 0.9]))
    np.testing.assert_allclose(batch[1], a.Gi, rtol=1e-5)
    assert np.all(np.isfinite(grads))
    # Gradients against SciPy finite differences: float64 to 1e-5, float32 to 1%.
    fd = (np_gains(0.8 + 1e-6, 0.01, 161)["Gi"] - np_gains(0.8 - 1e-6, 0.01, 161)["Gi"]) / 2e-6
    assert abs(grads[1] - fd) < 1e-2 * abs(fd)
    with enable_x64():
        g64 = jax.jit(jax.grad(lambda z: gains_of(z).Gi))(0.8)
        assert abs(g64 - fd) < 1e-5 * abs(fd)


def test_matches_numpy_loop_exactly():
    """Whole trajectory against the textbook loop (float64: to rounding; float32: bounded)."""
    zc, dt, n, steps = 0.8, 0.01, 161, 300
    rng = np.random.default_rng(0)
    # A walk-like reference far from the origin, with the initial state at rest there.
    knots = np.cumsum(rng.uniform(-0.2, 0.3, (20, 2)), 0) + np.array([5.0, -3.0])
    ref = np.repeat(knots, 40, axis=0)[: steps + n - 1]
    ref[:60] = ref[0]
    x0 = np.zeros((3, 2))
    x0[0] = ref[0]
    e0 = -(np_gains(zc, dt, n)["Gx"][0] + np_gains(zc, dt, n)["Gd"].sum()) * ref[0] / np_gains(zc, dt, n)["Gi"]
    want = np_servo(ref, zc, dt, n, x0, e0=e0)
    with enable_x64():
        g = pv.preview_gains(zc, dt, n)
        np.testing.assert_allclose(pv.rest_err_sum(g, ref[0]), e0, rtol=1e-7)  # Gx[0] + sum(Gd) cancels 1e2x
        got, _ = run_servo(g, jnp.asarray(ref), jnp.asarray(x0), jnp.asarray(e0))
        np.testing.assert_allclose(got, want, rtol=TRAJ_RTOL_F64, atol=TRAJ_RTOL_F64)
    g = pv.preview_gains(zc, dt, n)
    got, _ = run_servo(g, jnp.asarray(ref, jnp.float32), jnp.asarray(x0, jnp.float32), pv.rest_err_sum(g, ref[0]))
    # CoM position within 2 mm of float64 (gains differ ~5e-4 relative; positions are ~10 m).
    assert np.max(np.abs(np.asarray(got)[:, 0] - want[:, 0])) < 2e-3


def test_step_reference_is_tracked():
    zc, dt, n = 0.8, 0.01, 161
    g = pv.preview_gains(zc, dt, n)
    ref = np.zeros((600 + n - 1, 2), np.float32)
    ref[200:, 0] = 0.1
    ref[300:, 1] = -0.05
    xs, zs = run_servo(g, jnp.asarray(ref), pv.initial_state(jnp.zeros(2)))
    xs, zs = np.asarray(xs), np.asarray(zs)
    # Preview: the CoM starts moving before the step (anticipation), ZMP settles on the reference.
    assert xs[150, 0, 0] > 0.005
    settled = slice(450, 600)
    np.testing.assert_allclose(zs[settled], np.broadcast_to([0.1, -0.05], zs[settled].shape), atol=1e-3)
    np.testing.assert_allclose(xs[settled, 0], np.broadcast_to([0.1, -0.05], zs[settled].shape), atol=1e-3)
    assert np.all(np.isfinite(xs))


def test_rest_is_equilibrium_far_from_origin():
    g = pv.preview_gains(0.8, 0.01, 161)
    c = jnp.array([7.0, -4.0])
    ref = jnp.broadcast_to(c, (600 + 160, 2))
    xs, zs = run_servo(g, ref, pv.initial_state(c), pv.rest_err_sum(g, c))
    assert np.max(np.abs(np.asarray(xs)[:, 0] - np.asarray(c))) < 1e-4
    # Without it the integrator starts off equilibrium: a visible transient.
    xs0, _ = run_servo(g, ref, pv.initial_state(c))
    assert np.max(np.abs(np.asarray(xs0)[:, 0] - np.asarray(c))) > 1e-2


def np_zmp_reference(w, t, dt, n, step_time, ds_time):
    w = np.asarray(w, np.float64)
    out = np.zeros((n, 2))
    for k in range(n):
        tau = max(t + k * dt, 0.0)
        m = int(np.floor(tau / step_time))
        if m >= len(w) - 1:
            out[k] = w[-1]
            continue
        phase = tau - m * step_time
        a = 1.0 if ds_time <= 0 else min(phase / ds_time, 1.0)
        out[k] = (1 - a) * w[m] + a * w[m + 1]
    return out


@pytest.mark.parametrize("k", [1, 2, 4, 6])
def test_zmp_reference_matches_numpy(k):
    rng = np.random.default_rng(k)
    w = rng.uniform(-1, 1, (k, 2))
    dt, n, st = 0.005, 321, 0.8
    ts = np.array([0.0, 0.033, 0.5, 0.79, 1.234, 2.0, 5.0])
    dss = np.array([0.1, 0.0, 0.3, 0.8])
    tt, dd = (a.ravel() for a in np.meshgrid(ts, dss, indexing="ij"))
    want = np.stack([np_zmp_reference(w, t, dt, n, st, ds) for t, ds in zip(tt, dd, strict=True)])
    batched = jax.jit(jax.vmap(lambda w, t, ds: pv.zmp_reference(w, t, dt, n, st, ds), (None, 0, 0)))
    # Samples within rounding of a step or ramp boundary may fall either side.
    tau = tt[:, None] + np.arange(n) * dt
    phase = np.mod(tau + 1e-4, st) - 1e-4
    edge = (np.abs(phase) < 1e-4) | (np.abs(phase - dd[:, None]) < 1e-4)
    with enable_x64():
        got = np.asarray(batched(jnp.asarray(w), tt, dd))
        np.testing.assert_allclose(got[~edge], want[~edge], atol=1e-12)
    got32 = np.asarray(batched(jnp.asarray(w, jnp.float32), tt.astype(np.float32), dd.astype(np.float32)))
    np.testing.assert_allclose(got32[~edge], want[~edge], atol=1e-5)


def test_zmp_reference_standing_and_no_recompile():
    traces = []

    @jax.jit
    def f(w, t):
        traces.append(1)
        return pv.zmp_reference(w, t, 0.005, 200, 0.8, 0.1)

    mid = jnp.array([0.3, 0.0])
    w = jnp.stack([jnp.array([0.3, 0.1]), mid, mid, mid])
    z = f(w, 0.0)
    np.testing.assert_allclose(z[20:], np.broadcast_to(mid, (180, 2)), atol=1e-6)
    f(w + 1.0, 3.0)
    assert len(traces) == 1


def simulate_walk(waypoints, step_time, ds_time, zc=0.8, dt=0.005, preview=1.6):
    """The lead's loop: each tick, the 4 waypoints of the current step feed zmp_reference."""
    n = int(round(preview / dt)) + 1
    g = pv.preview_gains(zc, dt, n)
    wp = jnp.asarray(waypoints, jnp.float32)
    num_steps = wp.shape[0] - 3
    ticks_per_step = int(round(step_time / dt))

    @jax.jit
    def go(g, wp):
        def body(carry, tick):
            x, e = carry
            m = jnp.minimum(tick // ticks_per_step, num_steps - 1)
            t = (tick - m * ticks_per_step).astype(jnp.float32) * dt
            w = lax.dynamic_slice_in_dim(wp, m, 4)
            ref = pv.zmp_reference(w, t, dt, n, step_time, ds_time)
            lipm_zmp = x[0] - zc / 9.81 * x[2]
            x, e, _ = pv.preview_update(g, x, e, ref)
            return (x, e), (x, ref[0], lipm_zmp)

        x0 = pv.initial_state(wp[0])
        return lax.scan(body, (x0, pv.rest_err_sum(g, wp[0])), jnp.arange(num_steps * ticks_per_step))[1]

    return [np.asarray(a) for a in go(g, wp)]


def test_walk_zmp_follows_reference():
    # Forward walk: 12 steps of 0.25 m, feet 0.2 m apart, ending standing. It starts
    # with two standing 'steps' so the preview sees the first shift coming (from rest,
    # a ZMP ramp that starts at once cannot be tracked: the ZMP must first move away).
    feet = [[0.0, 0.0]] * 3 + [[0.25 * i, 0.1 * (-1) ** i] for i in range(13)]
    feet += [[0.25 * 12, 0.0]] * 3
    xs, ref, zmp = simulate_walk(np.array(feet), 0.8, 0.1)
    err = np.abs(zmp - ref)
    assert np.all(np.isfinite(xs))
    # The LIPM's own ZMP (c - z_c/g cddot) tracks the ramp-and-hold reference to within
    # 1.5 cm (measured 8 mm, at the corners of the 0.1 s double-support ramps), 0.5 mm on average.
    assert err.max() < 0.015, err.max()
    assert np.mean(err) < 0.002
    # Ends standing at rest over the final midpoint.
    np.testing.assert_allclose(xs[-1, 0], [3.0, 0.0], atol=0.01)


def test_periodic_stepping_matches_lipm():
    """In-place stepping with a square-wave ZMP (no double support) between feet at y = +-a.

    Check: the CoM stays strictly between the feet, and its lateral peak over
    the last steps is within 5% of the periodic LIPM solution
    a (1 - 1/cosh(w T/2)) (preview control cannot jump the ZMP, so it is close,
    not exact).
    """
    a, step_time, zc = 0.1, 0.8, 0.8
    feet = [[0.0, 0.0]] * 3 + [[0.0, a * (-1) ** i] for i in range(22)] + [[0.0, a], [0.0, a]]
    xs, ref, _ = simulate_walk(np.array(feet), step_time, 0.0, zc=zc)
    y = xs[:, 0, 1]
    assert np.all(np.abs(y) < a)
    spt = int(step_time / 0.005)
    last = y[8 * spt : 16 * spt]  # steady state, away from the start and the plan's end
    peak = 0.5 * (last.max() - last.min())
    want = float(pv.lipm_sway_amplitude(a, step_time, zc))
    assert abs(peak - want) < 0.05 * want, (peak, want)
