"""A biped read from its MJCF (ijoy_jax.sim.description): the project's biped and the Unitree G1.

References: MuJoCo's own forward kinematics (``mj_kinematics``) for the chains, the analytic leg kinematics of
:mod:`ijoy_jax.sim.kinematics` for the project's biped, and the MJCF's own numbers for what is read.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax.sim import description as D
from ijoy_jax.sim import kinematics, menagerie, model

# float32 kinematics against MuJoCo's float64: six rotations of O(1) rad over a 0.8 m leg round to ~1e-6 m
POS_TOL, ROT_TOL = 5e-6, 5e-6


@functools.cache
def g1_model() -> mujoco.MjModel:
    return menagerie.g1_spec(meshes=False).compile()


@functools.cache
def biped_model() -> mujoco.MjModel:
    return model.build_spec(model.BipedParams()).compile()


@functools.cache
def described(which: str) -> D.BipedDescription:
    if which == "g1":
        return D.describe(g1_model(), soles=menagerie.G1_SOLES, keyframe=menagerie.G1_KEYFRAME)
    return D.describe(biped_model())


def _model(which):
    return g1_model() if which == "g1" else biped_model()


def _random_leg_q(desc, side, rng, n):
    """n joint vectors inside the leg's limits (the G1's hip ranges are wide: keep to +-1.2 rad of standing)."""
    lo, hi = desc.legs[side].lower, desc.legs[side].upper
    centre = desc.stand_leg_q[side]
    return rng.uniform(np.maximum(lo, centre - 1.2), np.minimum(hi, centre + 1.2), size=(n, 6))


_fk = jax.jit(D.leg_fk)
_ik = jax.jit(D.leg_ik)


@pytest.mark.parametrize("which", ["g1", "biped"])
@pytest.mark.parametrize("side", [0, 1])
def test_leg_fk_is_mujocos_forward_kinematics(which, side):
    m, desc = _model(which), described(which)
    d = mujoco.MjData(m)
    root = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, desc.root)
    geom = mujoco.mj_name2id(
        m, mujoco.mjtObj.mjOBJ_GEOM, (menagerie.G1_SOLES if which == "g1" else ("left_foot", "right_foot"))[side]
    )
    for q in _random_leg_q(desc, side, np.random.default_rng(side), 12):
        d.qpos[:] = desc.stand_qpos
        d.qpos[3:7] = [np.cos(0.2), 0.0, 0.0, np.sin(0.2)]  # the root turned: the chain is in the root's frame
        d.qpos[desc.qpos_adr[side]] = q
        mujoco.mj_kinematics(m, d)
        r_root = d.xmat[root].reshape(3, 3)
        g_rot = d.geom_xmat[geom].reshape(3, 3)
        want_pos = r_root.T @ (d.geom_xpos[geom] - g_rot[:, 2] * m.geom_size[geom, 2] - d.xpos[root])
        pos, rot = _fk(desc.legs[side], jnp.asarray(q, jnp.float32))
        np.testing.assert_allclose(pos, want_pos, atol=POS_TOL)
        np.testing.assert_allclose(rot, r_root.T @ g_rot, atol=ROT_TOL)


def test_the_projects_biped_reads_as_its_own_analytic_kinematics():
    """The generic chain of the project's biped is the one sim.kinematics hard-codes (hip yaw-roll-pitch on one
    body, two ankle joints on the foot), and damped least squares finds the analytic IK's walking branch."""
    p, desc = model.BipedParams(), described("biped")
    rng = np.random.default_rng(7)
    for side, name in ((0, "left"), (1, "right")):
        lo, hi = p.joint_range(name)
        for q in rng.uniform(np.maximum(lo, -0.5), np.minimum(hi, 0.5), size=(8, 6)) + [0, 0, -0.3, 0.7, -0.4, 0]:
            q = jnp.asarray(np.clip(q, lo, hi), jnp.float32)
            pos, rot = kinematics.leg_fk(p, name, q)
            got_pos, got_rot = _fk(desc.legs[side], q)
            np.testing.assert_allclose(got_pos, pos, atol=POS_TOL)
            np.testing.assert_allclose(got_rot, rot, atol=ROT_TOL)
            want = kinematics.leg_ik(p, name, jnp.zeros(3), jnp.eye(3), pos, rot)
            sol = _ik(
                desc.legs[side], pos, rot, jnp.asarray(desc.stand_leg_q[side] + [0, 0, -0.3, 0.6, -0.3, 0], jnp.float32)
            )
            assert bool(want.reachable)
            np.testing.assert_allclose(sol.q, want.q, atol=2e-4)
            assert float(sol.position_error) < 2e-6 and float(sol.rotation_error) < 2e-5


@pytest.mark.parametrize("side", [0, 1])
def test_leg_ik_reaches_every_pose_the_g1s_leg_can_take(side):
    """Targets made by the leg itself (random joint angles inside the limits, up to 0.6 rad from the standing
    knees): reached from the standing seed to a few micrometres (the G1's hip is pitch-roll-yaw with offsets
    between its axes: no closed form)."""
    desc = described("g1")
    chain, q0 = desc.legs[side], jnp.asarray(desc.stand_leg_q[side], jnp.float32)
    rng = np.random.default_rng(10 + side)
    lo, hi = np.maximum(chain.lower + 0.02, q0 - 0.6), np.minimum(chain.upper - 0.02, q0 + 0.6)
    q_true = jnp.asarray(rng.uniform(lo, hi, size=(128, 6)), jnp.float32)
    targets, rots = jax.vmap(_fk, in_axes=(None, 0))(chain, q_true)
    sol = jax.vmap(_ik, in_axes=(None, 0, 0, None))(chain, targets, rots, q0)
    assert float(sol.position_error.max()) < 1e-5 and float(sol.rotation_error.max()) < 1e-4
    pos, rot = jax.vmap(_fk, in_axes=(None, 0))(chain, sol.q)
    np.testing.assert_allclose(pos, targets, atol=2e-5)
    np.testing.assert_allclose(rot, rots, atol=2e-4)


def test_leg_ik_of_walking_steps_reaches_them_or_stops_at_a_joint_limit():
    """Steps of -0.15..0.25 m along, +-5 cm across, up to 0.15 m up, soles pitched +-0.15 rad and turned +-0.4
    rad, from the standing knees: each is reached to a few micrometres, or the leg ends at one of its joint limits
    (the G1's ankle rolls only +-0.26 rad) with the error reported; always inside the limits."""
    desc = described("g1")
    chain, q0 = desc.legs[0], jnp.asarray(desc.stand_leg_q[0], jnp.float32)
    stand_pos, _ = _fk(chain, q0)
    rng = np.random.default_rng(11)
    n = 256
    targets = jnp.asarray(rng.uniform([-0.15, -0.05, 0.0], [0.25, 0.05, 0.15], size=(n, 3)), jnp.float32) + stand_pos
    rpy = rng.uniform([-0.05, -0.15, -0.4], [0.05, 0.15, 0.4], size=(n, 3))
    rots = jax.vmap(kinematics.rpy_to_rot)(jnp.asarray(rpy, jnp.float32))
    sol = jax.vmap(_ik, in_axes=(None, 0, 0, None))(chain, targets, rots, q0)
    assert bool(jnp.all((sol.q >= chain.lower - 1e-6) & (sol.q <= chain.upper + 1e-6)))
    reached = (sol.position_error < 1e-5) & (sol.rotation_error < 1e-4)
    at_limit = jnp.any((sol.q <= chain.lower + 1e-5) | (sol.q >= chain.upper - 1e-5), axis=1)
    assert bool(jnp.all(reached | at_limit))
    assert float(reached.mean()) > 0.8  # most walking steps are within the G1's reach
    pos, _ = jax.vmap(_fk, in_axes=(None, 0))(chain, sol.q)
    np.testing.assert_allclose(sol.position_error, jnp.linalg.norm(pos - targets, axis=1), atol=1e-5)


def test_leg_ik_out_of_reach_ends_finite_inside_the_limits_and_says_how_far():
    desc = described("g1")
    chain, q0 = desc.legs[0], jnp.asarray(desc.stand_leg_q[0], jnp.float32)
    targets = jnp.array([[0.0, 0.1, -2.0], [2.0, 0.1, -0.5], [0.0, 0.1, -0.1]], jnp.float32)  # far down, ahead, up
    sol = jax.vmap(_ik, in_axes=(None, 0, None, None))(chain, targets, jnp.eye(3), q0)
    assert bool(jnp.all(jnp.isfinite(sol.q)))
    assert bool(jnp.all((sol.q >= chain.lower - 1e-6) & (sol.q <= chain.upper + 1e-6)))
    reached, _ = jax.vmap(_fk, in_axes=(None, 0))(chain, sol.q)
    np.testing.assert_allclose(sol.position_error, jnp.linalg.norm(reached - targets, axis=1), rtol=1e-4)
    assert float(sol.position_error.min()) > 0.05


@settings(max_examples=60, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**31 - 1), rank=st.integers(0, 6), damping=st.sampled_from([1e-3, 1e-2, 1.0]))
def test_spd_solve_is_numpys_solve_on_damped_normal_matrices(seed, rank, damping):
    """``J J^T + d^2 I`` as leg_ik builds it, J of any rank (0: all zero, <6: a singular leg such as the straight
    knee): the element-by-element Cholesky solves it as NumPy's LU does (float64), within float32's precision
    times the matrix's condition; finite always."""
    rng = np.random.default_rng(seed)
    jac = rng.normal(size=(6, rank)) @ rng.normal(size=(rank, 6)) if rank else np.zeros((6, 6))
    a = jac @ jac.T + damping**2 * np.eye(6)
    b = rng.normal(size=6)
    want = np.linalg.solve(a, b)
    got = np.asarray(jax.jit(D.spd_solve)(jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32)), np.float64)
    assert np.all(np.isfinite(got))
    # float32 rounding of a and b, amplified by the condition number
    tol = 5e-6 * np.linalg.cond(a) * np.linalg.norm(want) + 1e-6
    assert np.linalg.norm(got - want) <= tol, (np.linalg.norm(got - want), tol)
    with jax.enable_x64(True):
        got64 = np.asarray(D.spd_solve(jnp.asarray(a), jnp.asarray(b)))
    assert got64.dtype == np.float64
    assert np.linalg.norm(got64 - want) <= 1e-13 * np.linalg.cond(a) * np.linalg.norm(want) + 1e-12


def test_leg_kinematics_run_in_float64_to_float64_precision():
    desc = described("g1")
    with jax.enable_x64(True):
        chain, q0 = desc.legs[1], jnp.asarray(desc.stand_leg_q[1])
        pos, rot = D.leg_fk(chain, q0)
        assert pos.dtype == jnp.float64
        sol = D.leg_ik(chain, pos + jnp.array([0.2, -0.03, 0.05]), rot, q0)
        assert sol.q.dtype == jnp.float64 and float(sol.position_error) < 1e-10


def test_the_g1_is_read_as_its_mjcf_declares():
    m, desc = g1_model(), described("g1")
    assert desc.joint_names[0] == tuple(
        f"left_{j}_joint" for j in ("hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch", "ankle_roll")
    )
    np.testing.assert_allclose(desc.sole_size, [0.18, 0.06])  # <geom name="left_foot" size="0.09 0.03 0.008">
    np.testing.assert_allclose(desc.kp, [[75, 75, 75, 75, 20, 2]] * 2)  # the position actuators' kp
    np.testing.assert_allclose(desc.mass, m.body_mass.sum())  # every body hangs from the pelvis
    np.testing.assert_allclose(desc.stand_leg_q, [[-0.312, 0, 0, 0.669, -0.363, 0]] * 2)  # the knees_bent key
    np.testing.assert_allclose(desc.legs[0].lower, m.jnt_range[[m.joint(n).id for n in desc.joint_names[0]], 0])
    assert desc.soles[0, 1] == pytest.approx(-desc.soles[1, 1]) and desc.soles[0, 1] > 0.1  # left is +y
    # knees_bent puts the pelvis at 0.755 m with the soles 3.5 mm into the floor (the key's own numbers)
    assert desc.stand_height == pytest.approx(0.7585, abs=1e-3)
    assert 0.0 < desc.com[0] < 0.06 and abs(desc.com[1]) < 1e-3  # ahead of the pelvis, on the centre line


def test_visual_meshes_drop_without_changing_the_physics():
    full, light = menagerie.g1_spec().compile(), g1_model()
    assert full.nmesh > 0 and light.nmesh == 0
    np.testing.assert_array_equal(light.body_mass, full.body_mass)
    np.testing.assert_array_equal(light.body_inertia, full.body_inertia)
    assert all(p.exists() for p in menagerie.g1_licenses())


def test_describe_refuses_what_is_not_a_six_hinge_leg_with_a_box_sole():
    m = g1_model()
    with pytest.raises(ValueError, match=r"no root body named 'hips'; it has \[.*'pelvis'"):
        D.describe(m, root="hips")
    with pytest.raises(ValueError, match="no left sole geom named 'left_sole'"):
        D.describe(m, soles=("left_sole", "right_foot"))
    with pytest.raises(ValueError, match="has 5 hinge joints"):
        D.describe(m, root="left_hip_pitch_link", soles=("left_foot", "left_foot"))
    with pytest.raises(ValueError, match="'right_foot' does not hang from root body 'left_hip_pitch_link'"):
        D.describe(m, root="left_hip_pitch_link", soles=("right_foot", "left_foot"))
    with pytest.raises(ValueError, match="must be a box"):
        D.describe(m, soles=("floor", "right_foot"))
    with pytest.raises(ValueError, match="no keyframe named 'standing'; it has \\['home', 'knees_bent'\\]"):
        D.describe(m, keyframe="standing")
