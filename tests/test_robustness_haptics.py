"""Hostile input to the public haptics functions (issue 22): a clear error at the boundary, or a finite, safe,
flagged result inside jit. NaN, inf, huge, tiny, negative, wrong dtype, wrong shape and empty values."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from ijoy_jax import haptics as H
from ijoy_jax.haptics import filter as F
from ijoy_jax.haptics import workspace as W

F32_MAX = float(np.finfo(np.float32).max)
HOSTILE = [np.nan, np.inf, -np.inf, F32_MAX, -F32_MAX, 1e30, -1e30, 1e-45, -1e-45, 0.0, -0.0, -1.0, 1.0, 0.05]
hostile = st.one_of(st.sampled_from(HOSTILE), st.floats(width=32))
# Samples of a signal: beyond ~1e30 any float32 linear filter overflows on differences of samples (a joystick
# reads at most a few units), so "huge" for a signal means 1e30; NaN and inf are held and flagged.
SAMPLE = [np.nan, np.inf, -np.inf, 1e30, -1e30, 1e-45, -1e-45, 0.0, -1.0, 0.4]
samples = st.one_of(st.sampled_from(SAMPLE), st.floats(-float(np.float32(1e30)), float(np.float32(1e30)), width=32))
FAST = settings(max_examples=40, derandomize=True, deadline=None)

filter_jit = jax.jit(F.spring_damper_filter)
discretise_jit = jax.jit(F.discretize)
force_c2_jit = jax.jit(W.repulsive_force)
force_decay_jit = jax.jit(W.repulsive_force_decay)
leg_force_jit = jax.jit(H.leg_repulsive_force)
platform_force_jit = jax.jit(H.platform_force)
CUBE = (jnp.eye(3), -jnp.ones(3), 0.5 * jnp.ones(3))


def _f32(x):
    return jnp.float32(x)


def _finite(tree):
    return all(
        bool(jnp.all(jnp.isfinite(x)))
        for x in jax.tree_util.tree_leaves(tree)
        if jnp.issubdtype(jnp.asarray(x).dtype, jnp.inexact)
    )


# --- the spring-damper filter ------------------------------------------------------------------------------------


@FAST
@given(hostile, hostile, hostile)
def test_filter_parameters(dt, w0, zeta):
    u = jnp.linspace(0.0, 1.0, 16, dtype=jnp.float32)
    valid = all(np.isfinite([dt, w0, zeta])) and dt > 0 and w0 > 0 and zeta >= 0
    if valid:
        assert _finite(F.spring_damper_filter(u, dt, w0, zeta))
    else:
        with pytest.raises(ValueError, match="dt|natural_frequency|damping_ratio"):
            F.spring_damper_filter(u, dt, w0, zeta)
    co = discretise_jit(F.SpringDamper.create(w0, zeta), _f32(dt))
    assert _finite(co)
    y = filter_jit(u, _f32(dt), _f32(w0), _f32(zeta))
    assert _finite(y)
    if not valid:  # the documented rule: flagged, the input passes straight through
        assert bool(co.invalid)
        np.testing.assert_array_equal(np.asarray(y), np.asarray(u))


@FAST
@given(hnp.arrays(np.float32, (24, 2), elements=samples))
def test_filter_samples(x):
    co = F.discretize(F.SpringDamper.create(20.0, 0.7), 1e-3)
    y, final, held = F.filter_signal(co, x)
    assert _finite((y, final))
    np.testing.assert_array_equal(np.asarray(held), ~np.isfinite(x))


@pytest.mark.parametrize(
    "signal,params,error",
    [
        (np.array(["a", "b"]), {}, TypeError),
        (np.ones(4, np.complex64), {}, TypeError),
        (np.float32(0.3), {}, ValueError),  # no time axis
        (np.zeros(5), dict(natural_frequency=np.full(3, 20.0)), ValueError),  # parameters wider than the channels
        (np.zeros((5, 2)), dict(damping_ratio=np.full(3, 0.7)), ValueError),
        (np.zeros(5), dict(dt="fast"), ValueError),
        (np.zeros(5), dict(natural_frequency=None), ValueError),
    ],
)
def test_filter_wrong_types_and_shapes(signal, params, error):
    args = dict(dt=1e-3, natural_frequency=20.0, damping_ratio=0.7) | params
    with pytest.raises(error, match="signal|dt|natural_frequency|damping_ratio"):
        F.spring_damper_filter(signal, **args)


def test_filter_other_dtypes_and_empty():
    for x in (np.arange(5, dtype=np.int32), np.array([True, False, True]), jnp.zeros((4, 2), jnp.bfloat16)):
        y = F.spring_damper_filter(x, 1e-3, 20.0, 0.7)
        assert y.shape == np.shape(x) and _finite(y)
    assert F.spring_damper_filter(np.zeros((0, 3)), 1e-3, 20.0, 0.7).shape == (0, 3)
    assert filter_jit(jnp.zeros((0,)), _f32(1e-3), _f32(20.0), _f32(0.7)).shape == (0,)


# --- repulsive forces ----------------------------------------------------------------------------------------------


@FAST
@given(hostile, hostile, hostile)
def test_repulsion_constants(c1, c2, decay_length):
    c1_ok = np.isfinite(c1) and 0 <= c1 <= W.c1_max()
    for name, fn, jit_fn, k, k_ok in (
        ("c2", W.repulsive_force, force_c2_jit, c2, np.isfinite(c2) and 0 < c2 <= 1),
        (
            "decay_length",
            W.repulsive_force_decay,
            force_decay_jit,
            decay_length,
            np.isfinite(decay_length) and decay_length > 0,
        ),
    ):
        if c1_ok and k_ok:
            assert _finite(fn(*CUBE, c1, k))
        else:
            with pytest.raises(ValueError, match="c1" if not c1_ok else name):
                fn(*CUBE, c1, k)
        f = jit_fn(*CUBE, _f32(c1), _f32(k))
        assert _finite(f)
        if not (c1_ok and k_ok):
            np.testing.assert_array_equal(np.asarray(f), 0.0)
        else:  # never an attraction: the force pushes away from the nearer (upper, at +0.5) planes
            assert np.all(np.asarray(f) <= 0)


@FAST
@given(hnp.arrays(np.float32, (3, 4), elements=hostile), hnp.arrays(np.float32, (2, 4), elements=hostile))
def test_repulsion_geometry(jac, travels):
    tm, tp = travels
    valid = np.all(np.isfinite(jac)) and np.all(np.isfinite(travels)) and np.all(tm <= 0) and np.all(tp >= 0)
    if valid:
        assert _finite(W.repulsive_force_decay(jac, tm, tp, 1.0, 0.05))
        assert _finite(W.workspace_halfspaces(jac, tm, tp))
    else:
        with pytest.raises(ValueError, match="jacobian|stroke"):
            W.repulsive_force_decay(jac, tm, tp, 1.0, 0.05)
    assert _finite(force_decay_jit(jac, tm, tp, _f32(1.0), _f32(0.05)))
    assert _finite(force_c2_jit(jac, tm, tp, _f32(1.0), _f32(1.0)))  # no decay: far planes still count
    assert _finite(W.limiting_planes(jac, tm, tp))


def test_a_subnormal_travel_is_outside_its_stroke_in_every_process():
    """The boundary compares in NumPy: +1e-45 (the smallest float32 subnormal) is > 0, though XLA's CPU
    backend flushes subnormals to zero (a check through jnp let it pass: test_repulsion_geometry failed in
    the runs whose hypothesis examples held an all-F32_MAX Jacobian and 1e-45 travels, 2026-11-26)."""
    jac = jnp.full((3, 4), F32_MAX, jnp.float32)
    tiny = np.full(4, 1e-45, np.float32)
    assert tiny[0] > 0  # a subnormal, not zero
    force_decay_jit(CUBE[0], -jnp.ones(3), jnp.ones(3), _f32(1.0), _f32(0.05)).block_until_ready()  # XLA ran
    assert W.check_travel(tiny, tiny).all()  # travel_minus > 0
    for tm, tp in ((tiny, tiny), (jnp.asarray(tiny), jnp.asarray(tiny))):
        with pytest.raises(ValueError, match="outside their stroke"):
            W.repulsive_force_decay(jac, tm, tp, 1.0, 0.05)


@pytest.mark.parametrize(
    "args",
    [
        (jnp.ones((2, 4)), -jnp.ones(4), jnp.ones(4), 1.0, 0.05),
        (jnp.ones((3, 4)), -jnp.ones(3), jnp.ones(4), 1.0, 0.05),
        (jnp.ones(3), -jnp.ones(1), jnp.ones(1), 1.0, 0.05),
        (*CUBE, jnp.ones(3), 0.05),
        (*CUBE, 1.0, jnp.ones(2)),
        (*CUBE, "strong", 0.05),
    ],
)
def test_repulsion_wrong_shapes_and_types(args):
    with pytest.raises(ValueError, match="jacobian|travel|c1|decay_length"):
        W.repulsive_force_decay(*args)


@FAST
@given(hnp.arrays(np.float32, (4,), elements=hostile), hostile, hostile)
def test_leg_and_platform(q, c1, decay_length):
    leg = H.alduro_leg(-1.0)
    ok = np.isfinite(c1) and 0 <= c1 <= W.c1_max() and np.isfinite(decay_length) and decay_length > 0
    f = leg_force_jit(leg, jnp.asarray(q), _f32(c1), _f32(decay_length))
    assert _finite(f)
    if not ok:
        np.testing.assert_array_equal(np.asarray(f), 0.0)
        with pytest.raises(ValueError, match="c1|decay_length"):
            H.leg_repulsive_force(leg, q, c1, decay_length)
    in_stroke = np.all(np.isfinite(q)) and np.all((q >= 0) & (q <= np.asarray(leg.stroke)))
    if not in_stroke:
        with pytest.raises(ValueError, match="stroke"):
            H.leg_workspace(leg, q)
    plat = H.alduro_platform()
    qs = jnp.tile(jnp.asarray(q), (4, 1))
    pw = jax.jit(H.platform_workspace)(plat, qs)
    out = platform_force_jit(pw, _f32(c1), _f32(decay_length))
    assert _finite((pw.feet, pw.planes, out)) and bool(out.bad_constants) == (not ok)


# --- joystick forces -------------------------------------------------------------------------------------------------


@FAST
@given(hnp.arrays(np.float32, (2,), elements=hostile), hnp.arrays(np.float32, (3,), elements=hostile), hostile)
def test_joystick_forces(position, force3, max_force):
    cfg = H.default_joystick_config("fold").replace(max_force=_f32(max_force))
    out = H.joystick_forces(cfg, jnp.asarray(position), jnp.asarray(force3))
    # Every field finite except a saturation level of +inf (no limit) carried into nothing: total is finite.
    assert _finite((out.centring, out.straight_ahead, out.kinematic, out.total, out.kinematic_effect))
    assert bool(out.nonfinite_input) == (not (np.all(np.isfinite(position)) and np.all(np.isfinite(force3))))
    mf = float(np.float32(max_force))
    mf = 0.0 if abs(mf) < np.finfo(np.float32).tiny else mf  # XLA flushes subnormals to zero
    assert bool(out.bad_max_force) == (not mf >= 0)
    limit = 0.0 if not mf >= 0 else mf
    assert float(jnp.linalg.norm(out.total)) <= limit * (1 + 1e-5) + 1e-30
