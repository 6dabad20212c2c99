"""The ALDURO-like leg: calibration to the paper's example, law of cosines, Jacobian, Fig. 8."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from ijoy_jax.haptics import leg as L
from ijoy_jax.haptics import workspace as W
from ijoy_jax.jit_cache import compiled_count

# The paper prints x to 4 decimals (0.1 mm); float32 FK of a 1.6 m leg is good to ~1e-6 m.
PAPER_X_TOL = 1e-4


def test_calibration_reproduces_paper_example():
    leg = L.alduro_leg(-1.0)  # the paper's leg has its foot at y < 0: a right leg
    np.testing.assert_allclose(L.forward_kinematics(leg, jnp.array(L.PAPER_Q)), L.PAPER_X, atol=PAPER_X_TOL)
    with jax.enable_x64(True):
        leg64 = L.alduro_leg(-1.0, jnp.float64)
        np.testing.assert_allclose(L.forward_kinematics(leg64, jnp.array(L.PAPER_Q)), L.PAPER_X, atol=1e-9)


def test_calibration_constants_from_an_independent_solve():
    """Solve the paper pose for the joint angles with scipy (hip rotation 0) and recompute the offsets."""
    from scipy.optimize import fsolve

    with jax.enable_x64(True):
        leg = L.alduro_leg(-1.0, jnp.float64)

        def residual(v):
            return np.asarray(L.forward_kinematics_angles(leg, jnp.array([v[0], v[1], 0.0, v[2]]))) - L.PAPER_X

        psi, theta, omega = fsolve(residual, [0.9, 0.0, 1.6], xtol=1e-14)
        a, b, g0 = (np.asarray(v) for v in (leg.arm_a, leg.arm_b, leg.gamma_min))
        length = np.sqrt(a * a + b * b - 2 * a * b * np.cos(g0)) + np.array(L.PAPER_Q)
        gamma = np.arccos((a * a + b * b - length**2) / (2 * a * b))
        want = np.array([psi, theta, 0.0, omega]) - np.asarray(leg.direction) * (gamma - g0)
        np.testing.assert_allclose(np.asarray(leg.angle_at_min), want, atol=1e-10)


def test_law_of_cosines_round_trip_and_strokes():
    leg = L.alduro_leg()
    with jax.enable_x64(True):
        leg = L.alduro_leg(dtype=jnp.float64)
        q = np.random.default_rng(0).uniform(0, 1, (20, 4)) * np.asarray(leg.stroke)
        for qi in q:
            ang = np.asarray(L.joint_angles(leg, qi))
            gamma = np.asarray(leg.gamma_min) + (ang - np.asarray(leg.angle_at_min)) * np.asarray(leg.direction)
            length = np.asarray(L.cylinder_length(leg.arm_a, leg.arm_b, gamma))
            l_min = np.asarray(L.cylinder_length(leg.arm_a, leg.arm_b, leg.gamma_min))
            np.testing.assert_allclose(length - l_min, qi, atol=1e-12)
        # Strokes: the triangle's angle sweeps the documented range.
        top = np.asarray(L.cylinder_length(leg.arm_a, leg.arm_b, np.deg2rad([130, 105, 120, 140])))
        np.testing.assert_allclose(
            top - np.asarray(L.cylinder_length(leg.arm_a, leg.arm_b, leg.gamma_min)), np.asarray(leg.stroke), atol=1e-12
        )
    assert float(leg.thigh + leg.shank) == pytest.approx(1.6)


def test_jacobian_is_the_derivative():
    with jax.enable_x64(True):
        leg = L.alduro_leg(-1.0, jnp.float64)
        q = np.array(L.PAPER_Q)
        ws = L.leg_workspace(leg, q)
        h = 1e-6
        fd = np.stack(
            [
                (np.asarray(L.forward_kinematics(leg, q + h * e)) - np.asarray(L.forward_kinematics(leg, q - h * e)))
                / (2 * h)
                for e in np.eye(4)
            ],
            axis=1,
        )
        np.testing.assert_allclose(np.asarray(ws.jacobian), fd, atol=1e-8)
        check_grads(jax.jit(lambda x: L.forward_kinematics(leg, x)), (q,), order=1, modes=("fwd", "rev"))


def _hip_axes(leg, angles):
    """World lines (point, direction) of the rotation, abduction and flexion axes, by probing the FK:
    a joint's axis is the fixed line of the motion it causes."""
    pts = []
    for j in (2, 1, 0):  # rotation, abduction, flexion

        def foot(t, j=j):
            return L.forward_kinematics_angles(leg, angles.at[j].add(t))

        v = np.asarray(jax.jacfwd(foot)(0.0))  # = axis x (foot - point)
        a = np.asarray(jax.jacfwd(jax.jacfwd(foot))(0.0))  # = axis x v = -(foot - point) projected
        x = np.asarray(foot(0.0))
        axis = np.cross(a, v)
        axis /= np.linalg.norm(axis)
        point = x + a - axis * (axis @ a)  # foot minus its offset perpendicular to the axis
        pts.append((point, axis))
    return pts


def _line_distance(p1, d1, p2, d2):
    n = np.cross(d1, d2)
    if np.linalg.norm(n) < 1e-9:
        return np.linalg.norm(np.cross(p2 - p1, d1))
    return abs((p2 - p1) @ n) / np.linalg.norm(n)


def test_hip_is_not_spherical_and_a_spherical_one_degenerates():
    with jax.enable_x64(True):
        leg = L.alduro_leg(-1.0, jnp.float64)
        angles = L.joint_angles(leg, jnp.array(L.PAPER_Q))
        (p_r, d_r), (p_a, d_a), (p_f, d_f) = _hip_axes(leg, angles)
        assert _line_distance(p_r, d_r, p_a, d_a) == pytest.approx(0.15, abs=1e-6)  # documented offsets
        assert _line_distance(p_a, d_a, p_f, d_f) > 0.1
        ws = L.leg_workspace(leg, jnp.array(L.PAPER_Q))
        hip = np.asarray(ws.jacobian)[:, :3]
        assert abs(np.linalg.det(hip / np.linalg.norm(hip, axis=0))) > 1e-3  # hip columns not coplanar
        assert int(ws.planes.valid.sum()) == 12
        # With all hip axes through one point the hip columns are coplanar: a prism with 8 facets.
        sph = leg.replace(hip_lateral=jnp.zeros(()), hip_forward=jnp.zeros(()), hip_down=jnp.zeros(()))
        ws_s = L.leg_workspace(sph, jnp.array(L.PAPER_Q))
        hip_s = np.asarray(ws_s.jacobian)[:, :3]
        assert abs(np.linalg.det(hip_s / np.linalg.norm(hip_s, axis=0))) < 1e-12
        assert int(ws_s.planes.valid.sum()) == 8


@pytest.mark.parametrize("decay_length", [0.02, 0.05, 0.1, 0.2, 0.5])
def test_fig8_force_points_down_when_knee_is_near_its_end(decay_length):
    """The paper's Fig. 8: at its example pose the knee cylinder (the only one moving the foot up)
    is 4.4 cm from its end of travel, and the repulsive force points downward."""
    leg = L.alduro_leg(-1.0)
    ws = L.leg_workspace(leg, jnp.array(L.PAPER_Q))
    jac = np.asarray(ws.jacobian)
    vertical_share = np.abs(jac[2]) / np.linalg.norm(jac, axis=0)
    assert vertical_share[3] > 0.6 and np.all(vertical_share[:3] < 0.05)
    f = np.asarray(W.plane_forces(ws.planes, 1.0, 1.0 / decay_length).force)
    angle_from_down = np.degrees(np.arccos(-f[2] / np.linalg.norm(f)))
    assert angle_from_down < 15.0
    # Knee cylinder mid-stroke: the limits are far, the force much weaker. At its other end (knee
    # straight, the foot cannot go further down) the force has an upward component.
    q = jnp.array(L.PAPER_Q)
    g = np.asarray(W.plane_forces(L.leg_workspace(leg, q.at[3].set(0.17)).planes, 1.0, 1.0 / decay_length).force)
    assert np.linalg.norm(g) < 0.2 * np.linalg.norm(f)
    q_end = q.at[3].set(float(leg.stroke[3]) - L.PAPER_Q[3])
    h = np.asarray(W.plane_forces(L.leg_workspace(leg, q_end).planes, 1.0, 1.0 / decay_length).force)
    assert h[2] > 0.5 * np.linalg.norm(h)


def test_generator_pairs_one_and_four_are_longest():
    """The paper: "Pairs 1 and 4 are the longest as they originate from the main hip and knee movement"."""
    ws = L.leg_workspace(L.alduro_leg(-1.0), jnp.array(L.PAPER_Q))
    e_minus, e_plus = W.zonotope_generators(ws.jacobian, ws.travel_minus, ws.travel_plus)
    pair_length = np.linalg.norm(np.asarray(e_plus - e_minus), axis=1)
    assert set(np.argsort(pair_length)[-2:]) == {0, 3}


def test_left_leg_mirrors_right_leg():
    q = jnp.array(L.PAPER_Q)
    left, right = L.forward_kinematics(L.alduro_leg(1.0), q), L.forward_kinematics(L.alduro_leg(-1.0), q)
    np.testing.assert_allclose(left, right * jnp.array([1.0, -1.0, 1.0]), atol=1e-7)


def test_stroke_validation_and_clamping():
    leg = L.alduro_leg(-1.0)
    q = np.array(L.PAPER_Q)
    q[3] = -0.01
    with pytest.raises(ValueError, match="outside their stroke"):
        L.leg_workspace(leg, q)
    ws = jax.jit(L.leg_workspace)(leg, jnp.asarray(q))
    assert np.asarray(ws.out_of_range).tolist() == [False, False, False, True]
    assert float(ws.travel_minus[3]) == 0.0
    q_nan = jnp.array(L.PAPER_Q).at[0].set(jnp.nan)
    ws_nan = jax.jit(L.leg_workspace)(leg, q_nan)
    assert bool(ws_nan.out_of_range[0])
    f = W.plane_forces(ws_nan.planes, 1.0, 20.0).force
    assert np.all(np.isfinite(np.asarray(f)))


def test_no_recompile_over_geometry_and_pose():
    f = jax.jit(L.leg_repulsive_force)
    leg = L.alduro_leg(-1.0)
    f(leg, jnp.array(L.PAPER_Q), 1.0, 0.05)
    before = compiled_count(f)
    rng = np.random.default_rng(1)
    for _ in range(3):
        q = jnp.asarray(rng.uniform(0.1, 0.9, 4) * np.asarray(leg.stroke), jnp.float32)
        f(leg.replace(thigh=leg.thigh * rng.uniform(0.9, 1.1)), q, rng.uniform(0.5, 2.0), rng.uniform(0.01, 0.2))
    assert compiled_count(f) == before


@pytest.mark.parametrize("c1,decay_length", [(float("nan"), 0.05), (-1.0, 0.05), (1.0, -0.05), (1.0, float("nan"))])
def test_bad_repulsion_constants(c1, decay_length):
    """Refused where concrete; inside jit a zero force (never NaN, never attraction): issue 22."""
    leg = L.alduro_leg(-1.0)
    q = jnp.array(L.PAPER_Q)
    with pytest.raises(ValueError, match="c1" if c1 != 1.0 else "decay_length"):
        L.leg_repulsive_force(leg, q, c1, decay_length)
    f = jax.jit(L.leg_repulsive_force)(leg, q, c1, decay_length)
    np.testing.assert_array_equal(np.asarray(f), 0.0)
