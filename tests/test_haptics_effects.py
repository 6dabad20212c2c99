"""Joystick forces as standard effects: spring conditions, constant forces, blending, Linux encoding."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from jax.test_util import check_grads

from ijoy_jax.haptics import effects as E
from ijoy_jax.jit_cache import compiled_count

# Linux effect fields are 16-bit integers: a field's quantisation step relative to full scale.
Q16 = 1.0 / 0x7FFF


def spring_reference(pos, center, kp, kn, sp, sn, db):
    """One axis of a DirectInput/HID-PID spring condition, scalar NumPy."""
    s = pos - center
    if s > db:
        return -float(np.clip(kp * (s - db), -sp, sp))
    if s < -db:
        return -float(np.clip(kn * (s + db), -sn, sn))
    return 0.0


pos_st = hnp.arrays(np.float64, (2,), elements=st.floats(-0.1, 0.1))
pos_coeff = hnp.arrays(np.float64, (2,), elements=st.floats(0.0, 200.0))
pos_small = hnp.arrays(np.float64, (2,), elements=st.floats(0.0, 5.0))
pos_db = hnp.arrays(np.float64, (2,), elements=st.floats(0.0, 0.02))


@settings(max_examples=40, derandomize=True, deadline=None)
@given(pos_st, pos_st, pos_coeff, pos_coeff, pos_small, pos_small, pos_db)
def test_spring_force_matches_reference(pos, center, kp, kn, sp, sn, db):
    e = E.SpringEffect(*(jnp.asarray(v, jnp.float32) for v in (center, kp, kn, sp, sn, db)))
    got = np.asarray(_spring(e, jnp.asarray(pos, jnp.float32)))
    want = [spring_reference(pos[i], center[i], kp[i], kn[i], sp[i], sn[i], db[i]) for i in range(2)]
    np.testing.assert_allclose(got, want, atol=1e-4)  # float32 of products ~200 * 0.2


_spring = jax.jit(E.spring_force)


def test_linear_and_constant_centring():
    lin = E.linear_centring(50.0, 3.0)
    np.testing.assert_allclose(E.spring_force(lin, jnp.array([0.02, -0.04])), [-1.0, 2.0], rtol=1e-6)
    np.testing.assert_allclose(E.spring_force(lin, jnp.array([0.2, 0.0])), [-3.0, 0.0])  # saturates
    const = E.constant_centring(1.5, ramp=0.002)
    for p in ([0.01, 0.0], [0.05, -0.03], [-0.004, 0.0]):
        f = np.asarray(E.spring_force(const, jnp.array(p)))
        np.testing.assert_allclose(np.abs(f[np.abs(p) > 0.002]), 1.5)  # constant beyond the ramp
    ahead = E.straight_ahead(60.0, 2.0)
    f = np.asarray(E.spring_force(ahead, jnp.array([0.05, 0.01])))
    assert f[0] == 0.0 and f[1] == pytest.approx(-0.6)


def test_saturate_and_constant_effect_round_trip():
    f = jnp.array([3.0, 4.0])
    np.testing.assert_allclose(E.saturate(f, 2.5), [1.5, 2.0], rtol=1e-6)
    np.testing.assert_allclose(E.saturate(f, 10.0), f)
    np.testing.assert_allclose(E.constant_force(E.constant(f)), f, rtol=1e-6)
    zero = E.constant(jnp.zeros(2))
    assert float(zero.magnitude) == 0.0 and float(zero.direction) == 0.0
    # Gradients: finite at zero force (safe norm) and correct elsewhere.
    assert np.all(np.isfinite(np.asarray(jax.grad(lambda v: jnp.sum(E.saturate(v, 1.0)))(jnp.zeros(2)))))
    with jax.enable_x64(True):
        check_grads(lambda v: E.saturate(v, 1.0), (np.array([0.3, -2.0]),), order=1, modes=("fwd", "rev"))
        check_grads(lambda v: E.constant_force(E.constant(v)), (np.array([0.3, -2.0]),), order=1)


def test_project_and_fold():
    axes = jnp.eye(3)[:2]
    f3 = jnp.array([0.5, -0.25, -2.0])
    np.testing.assert_allclose(E.project(f3, axes), [0.5, -0.25])
    np.testing.assert_allclose(E.fold(f3, axes, jnp.array([1.0, 0.0])), [-1.5, -0.25])  # down -> backward
    # Tilted axes: the in-plane part is the projection, the normal part goes along fold_direction.
    c, s = np.cos(0.3), np.sin(0.3)
    tilted = jnp.array([[c, 0.0, -s], [0.0, 1.0, 0.0]])
    normal = np.cross(np.asarray(tilted[0]), np.asarray(tilted[1]))
    d = jnp.array([0.6, 0.8])
    np.testing.assert_allclose(
        E.fold(f3, tilted, d), np.asarray(tilted) @ f3 + (normal @ np.asarray(f3)) * d, rtol=1e-6
    )
    # A force in the plane folds to itself; a force normal to it is not lost (projection loses it).
    np.testing.assert_allclose(E.fold(jnp.array([1.0, 2.0, 0.0]), axes, d), [1.0, 2.0])
    assert np.linalg.norm(E.fold(jnp.array([0.0, 0.0, 3.0]), axes, d)) == pytest.approx(3.0)
    assert np.linalg.norm(E.project(jnp.array([0.0, 0.0, 3.0]), axes)) == 0.0


def test_joystick_forces_blend_and_saturate():
    cfg = E.default_config("fold")
    # Near the centre the device force dominates (Fig. 4 b)...
    near = E.joystick_forces(cfg, jnp.array([0.04, 0.0]), jnp.array([0.0, 0.0, -0.05]))
    assert abs(near.centring[0]) > 10 * abs(near.kinematic[0])
    # ...near a workspace limit the kinematic force does (Fig. 4 a), and the sum saturates.
    far = E.joystick_forces(cfg, jnp.array([0.01, 0.0]), jnp.array([0.0, 0.0, -20.0]))
    assert abs(far.kinematic[0]) > 10 * abs(far.centring[0])
    assert bool(far.saturated) and float(jnp.linalg.norm(far.total)) == pytest.approx(5.0)
    raw = far.centring + far.straight_ahead + far.kinematic
    np.testing.assert_allclose(far.total / jnp.linalg.norm(far.total), raw / jnp.linalg.norm(raw), rtol=1e-6)
    # The constant effect plays the kinematic term (limited to the device).
    np.testing.assert_allclose(E.constant_force(far.kinematic_effect), E.saturate(far.kinematic, 5.0), atol=1e-5)
    # Non-finite kinematic input counts as zero.
    bad = E.joystick_forces(cfg, jnp.array([0.01, 0.0]), jnp.array([jnp.nan, 0.0, jnp.inf]))
    assert np.all(np.isfinite(np.asarray(bad.total))) and np.all(np.asarray(bad.kinematic) == 0)
    with pytest.raises(ValueError):
        E.default_config("squash")


def test_no_recompile_when_tuning():
    cfg = E.default_config()
    E.joystick_forces(cfg, jnp.array([0.01, 0.02]), jnp.ones(3))
    before = compiled_count(E.joystick_forces)
    for k in (10.0, 20.0, 30.0):
        tuned = cfg.replace(centring=E.linear_centring(k, 2.0), max_force=jnp.float32(k / 4))
        E.joystick_forces(tuned, jnp.array([0.03, -0.01]), jnp.ones(3))
    assert compiled_count(E.joystick_forces) == before


def _decode_linux_condition(cond, x_evdev, max_force, max_deflection):
    """Force on one evdev axis from Linux condition fields, with the scaling documented in effects."""
    pos = x_evdev / max_deflection * 0x7FFF
    center, db = cond["center"], cond["deadband"]
    if pos > center + db:
        k, sat, s = cond["right_coeff"], cond["right_saturation"], pos - center - db
    elif pos < center - db:
        k, sat, s = cond["left_coeff"], cond["left_saturation"], pos - center + db
    else:
        return 0.0
    level = np.clip(k * s / 0x7FFF, -sat / 0xFFFF * 0x7FFF, sat / 0xFFFF * 0x7FFF)
    return -level / 0x7FFF * max_force


def test_linux_spring_plays_the_same_force():
    max_force, max_dev = 5.0, 0.06
    e = E.SpringEffect(
        center=jnp.array([0.005, -0.004]),
        positive_coefficient=jnp.array([40.0, 60.0]),
        negative_coefficient=jnp.array([30.0, 80.0]),
        positive_saturation=jnp.array([2.0, 1.5]),
        negative_saturation=jnp.array([2.5, 1.0]),
        deadband=jnp.array([0.002, 0.001]),
    )
    fields = E.linux_spring(e, max_force, max_dev)
    assert fields["type"] == E.FF_SPRING
    cond_x, cond_y = fields["u"]["condition"]  # evdev X, Y
    for p in np.random.default_rng(0).uniform(-0.05, 0.05, (100, 2)):
        want = np.asarray(E.spring_force(e, jnp.asarray(p, jnp.float32)))
        # joystick (x fwd, y left) -> evdev (X = -y, Y = -x); forces map the same way back.
        fx_ev = _decode_linux_condition(cond_x, -p[1], max_force, max_dev)
        fy_ev = _decode_linux_condition(cond_y, -p[0], max_force, max_dev)
        np.testing.assert_allclose([-fy_ev, -fx_ev], want, atol=20 * Q16 * max_force)


@pytest.mark.parametrize("angle", np.linspace(-np.pi, np.pi, 13))
def test_linux_constant_direction_follows_ff_memless(angle):
    """The kernel's ff-memless plays level * (sin t, -cos t) on evdev (X, Y) for direction t."""
    f = 3.0 * np.array([np.cos(angle), np.sin(angle)])
    fields = E.linux_constant(E.constant(jnp.asarray(f, jnp.float32)), max_force=5.0)
    theta = fields["direction"] / 0x10000 * 2 * np.pi
    level = fields["u"]["constant"]["level"] / 0x7FFF * 5.0
    ev = level * np.array([np.sin(theta), -np.cos(theta)])
    np.testing.assert_allclose([-ev[1], -ev[0]], f, atol=5.0 * (Q16 + 2 * np.pi / 0x10000))
