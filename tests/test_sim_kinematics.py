"""Tests of ijoy_jax.sim.kinematics: FK against MuJoCo, IK(FK(q)) == q, reach, batching, gradients."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from ijoy_jax.sim import kinematics as kin
from ijoy_jax.sim import model
from ijoy_jax.testing import enable_x64

P = model.BipedParams()
SIDES = ("left", "right")
# float64 round trip and FK-vs-MuJoCo: both are exact up to a few ulps of trig chains (~1e-15);
# 1e-6 is the requirement and leaves room for ill-conditioned poses near the joint limits.
TOL64 = 1e-6
# float32: positions carry ~6e-8 relative error (|p| < 0.8 m -> ~5e-8 m), amplified by 1 / (a b sin(knee))
# in acos near a straight knee; poses here keep the knee above 0.2 rad, where 2e-3 rad bounds it with margin.
TOL32 = 2e-3


def _random_q(side, u):
    lo, hi = P.joint_range(side)
    return lo + (hi - lo) * np.asarray(u)


def _walking_branch(q) -> bool:
    """The IK's branch: hip above the ankle in the ankle-pitch frame (see leg_ik), away from its edge."""
    a, b = P.thigh, P.shank
    alpha = np.arctan2(a * np.sin(q[3]), a * np.cos(q[3]) + b)
    return abs(alpha + q[4]) < np.radians(80) and abs(q[1]) < np.radians(80) and abs(q[5]) < np.radians(80)


unit6 = st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6)


@given(u=unit6, side=st.sampled_from(SIDES), yaw=st.floats(-3.0, 3.0), roll=st.floats(-0.3, 0.3))
def test_ik_inverts_fk_float64(u, side, yaw, roll):
    q = _random_q(side, u)
    assume(_walking_branch(q))
    with enable_x64():
        q = jnp.asarray(q, jnp.float64)
        pelvis_pos = jnp.array([0.3, -0.2, 1.0], jnp.float64)
        pelvis_rot = kin.rpy_to_rot(jnp.array([roll, 0.1, yaw], jnp.float64))
        pos, rot = kin.leg_fk(P, side, q)
        assert pos.dtype == jnp.float64
        q2, ok = kin.leg_ik(P, side, pelvis_pos, pelvis_rot, pelvis_pos + pelvis_rot @ pos, pelvis_rot @ rot)
        assert bool(ok)
        np.testing.assert_allclose(np.asarray(q2), np.asarray(q), atol=TOL64)


def test_fk_matches_mujoco():
    m = model.build_spec(P, (4, 4), 0.5).compile()
    d = mujoco.MjData(m)
    ix = model.model_index(m)
    rng = np.random.default_rng(0)
    with enable_x64():
        for _ in range(20):
            d.qpos[:3] = rng.normal(size=3)
            quat = rng.normal(size=4)
            d.qpos[3:7] = quat / np.linalg.norm(quat)
            for row, side in enumerate(SIDES):
                d.qpos[ix.qpos_adr[row]] = _random_q(side, rng.uniform(size=6))
            mujoco.mj_kinematics(m, d)
            prot = d.xmat[ix.pelvis].reshape(3, 3)
            np.testing.assert_allclose(kin.quat_to_rot(jnp.asarray(quat)), prot, atol=TOL64)  # quat not normalised
            for row, side in enumerate(SIDES):
                pos, rot = kin.leg_fk(P, side, jnp.asarray(d.qpos[ix.qpos_adr[row]]))
                site = ix.sole_site[row]
                np.testing.assert_allclose(d.xpos[ix.pelvis] + prot @ np.asarray(pos), d.site_xpos[site], atol=TOL64)
                np.testing.assert_allclose(prot @ np.asarray(rot), d.site_xmat[site].reshape(3, 3), atol=TOL64)


@pytest.mark.parametrize("side", SIDES)
def test_ik_float32_round_trip(side):
    rng = np.random.default_rng(1)
    qs = np.array([q for q in (_random_q(side, rng.uniform(size=6)) for _ in range(400))
                   if _walking_branch(q) and q[3] > 0.2], np.float32)
    pos, rot = jax.vmap(lambda q: kin.leg_fk(P, side, q))(jnp.asarray(qs))
    q2, ok = jax.vmap(lambda p, r: kin.leg_ik(P, side, jnp.zeros(3), jnp.eye(3), p, r))(pos, rot)
    assert q2.dtype == jnp.float32
    assert bool(ok.all())
    np.testing.assert_allclose(np.asarray(q2), qs, atol=TOL32)


@pytest.mark.parametrize("side", SIDES)
@pytest.mark.parametrize("target", [(0.0, 0.0, -2.0), (0.6, 0.3, -0.1), (0.0, 0.0, 0.0), (0.0, 0.06, -0.105)])
def test_unreachable_is_finite_and_flagged(side, target):
    sole = jnp.asarray(target, jnp.float32)
    q, ok = kin.leg_ik(P, side, jnp.zeros(3), jnp.eye(3), sole, jnp.eye(3))
    assert np.all(np.isfinite(np.asarray(q)))
    assert not bool(ok)
    if target == (0.0, 0.0, -2.0):  # straight leg pointing its ankle at the target's ankle, foot level
        pos, rot = kin.leg_fk(P, side, q)
        assert float(q[3]) == 0.0
        np.testing.assert_allclose(np.asarray(rot), np.eye(3), atol=1e-6)
        hip = np.array([0.0, kin.leg_sign(side) * P.hip_offset_y, 0.0])
        lift = np.array([0.0, 0.0, P.ankle_height])
        want, got = np.asarray(sole) + lift - hip, np.asarray(pos) + lift - hip
        np.testing.assert_allclose(got / np.linalg.norm(got), want / np.linalg.norm(want), atol=1e-6)
        assert abs(np.linalg.norm(got) - (P.thigh + P.shank)) < 1e-6


def test_jit_vmap_no_recompile():
    traces = []

    def ik(pp, pr, sp, sr):
        traces.append(1)
        return kin.leg_ik(P, "left", pp, pr, sp, sr)

    f = jax.jit(jax.vmap(ik))
    n = 8
    pelvis = jnp.tile(jnp.array([0.0, 0.0, 0.68]), (n, 1))
    rots = jnp.tile(jnp.eye(3), (n, 1, 1))
    soles = jnp.stack([jnp.linspace(-0.1, 0.1, n), jnp.full(n, 0.095), jnp.zeros(n)], axis=1)
    q, ok = f(pelvis, rots, soles, rots)
    assert q.shape == (n, 6) and ok.shape == (n,) and bool(ok.all())
    f(pelvis + 0.01, rots, soles, rots)
    assert len(traces) == 1


def test_finite_grads_at_straight_knee():
    straight = kin.leg_fk(P, "left", jnp.zeros(6))[0]

    def loss(sole):
        q, _ = kin.leg_ik(P, "left", jnp.zeros(3), jnp.eye(3), sole, jnp.eye(3))
        return jnp.sum(q**2)

    for sole in (straight, straight + jnp.array([0.0, 0.0, -0.1])):
        g = jax.grad(loss)(sole)
        assert np.all(np.isfinite(np.asarray(g))), g
    g = jax.grad(lambda q: jnp.sum(kin.leg_fk(P, "right", q)[0]))(jnp.zeros(6))
    assert np.all(np.isfinite(np.asarray(g)))


def test_grads_match_finite_differences():
    from jax.test_util import check_grads

    with enable_x64():
        sole = jnp.array([0.05, 0.1, -0.6], jnp.float64)
        check_grads(lambda s: kin.leg_ik(P, "left", jnp.zeros(3), jnp.eye(3), s, jnp.eye(3))[0], (sole,),
                    order=1, modes=("rev",))


def test_bad_side():
    with pytest.raises(ValueError):
        kin.leg_fk(P, "middle", jnp.zeros(6))
    with pytest.raises(ValueError):
        kin.leg_fk(P, 0, jnp.zeros(6))
