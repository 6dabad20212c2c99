"""Tests of ijoy_jax.sim.physics (the traced Dynamics pytree) and of the Sim as a pytree: host-side and small
jitted functions only, no MJX rollout (those are in tests/test_sweep_physics.py, which compiles one).

The reference for the model-side leaves is MuJoCo's own compiler: a biped built from BipedParams whose masses,
armatures, gains and friction are those of the varied robot (``mj_setConst`` recomputes the inverse weights),
put on the device with ``mjx.put_model``, must equal :func:`physics.put_dynamics` of the nominal model.
"""

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from jax import lax
from mujoco import mjx

import ijoy_jax as ij
from ijoy_jax.sim import model, physics
from ijoy_jax.sim import walker as W

SHAPE, RES = (12, 10), 0.05
TERRAIN = ij.terrain.flat(SHAPE, RES, has_height=True)
# MuJoCo computes the scaled robot in float64 and MJX stores float32; put_dynamics scales the float32 values:
# the two differ by the rounding of each (2 ulp of float32).
SCALED_RTOL = 2.5e-7
_MASSES = ("pelvis_mass", "torso_mass", "head_mass", "arm_mass", "thigh_mass", "shank_mass", "foot_mass")


def _device_model(**overrides):
    return mjx.put_model(model.build_model(model.biped_params(**overrides), TERRAIN))


@pytest.fixture(scope="module")
def nominal():
    return _device_model()


def _leaves(m):
    return dict(jax.tree_util.tree_flatten_with_path(m)[0])


@pytest.mark.parametrize("friction, mass, kp", [(0.3, 1.0, 1.0), (1.0, 1.7, 1.0), (1.0, 1.0, 0.6), (0.05, 0.5, 2.0)])
def test_put_dynamics_is_the_robot_mujocos_compiler_builds(nominal, friction, mass, kp):
    p = model.BipedParams()
    ref = _device_model(friction=friction, armature=tuple(mass * a for a in p.armature),
                        kp=tuple(kp * k for k in p.kp), **{n: mass * getattr(p, n) for n in _MASSES})
    got = physics.put_dynamics(nominal, physics.Dynamics(friction=friction, mass_scale=mass, kp_scale=kp))
    want, have, base = _leaves(ref), _leaves(got), _leaves(nominal)
    assert want.keys() == have.keys()
    changed = []
    for path, w in want.items():
        w, h, b = np.asarray(w), np.asarray(have[path]), np.asarray(base[path])
        np.testing.assert_allclose(h, w, rtol=SCALED_RTOL, atol=0, err_msg=jax.tree_util.keystr(path))
        if not np.array_equal(h, b):
            changed.append(jax.tree_util.keystr(path))
    expected = {".geom_friction"} if friction != 1.0 else set()
    expected |= ({".body_mass", ".body_inertia", ".body_subtreemass", ".dof_armature", ".dof_M0", ".body_invweight0",
                  ".dof_invweight0", ".actuator_acc0", ".stat.meaninertia", ".stat.meanmass"} if mass != 1.0 else set())
    expected |= {".actuator_gainprm", ".actuator_biasprm"} if kp != 1.0 else set()
    assert set(changed) == expected
    # the ground and the soles both carry the friction (MuJoCo uses the larger of a pair's)
    host = model.build_model(model.biped_params(friction=friction), TERRAIN)
    ids = model.model_index(host)
    np.testing.assert_allclose(np.asarray(got.geom_friction)[[int(ids.hfield_geom), *ids.sole_geoms.ravel()], 0],
                               friction, rtol=1e-7)


def test_nominal_dynamics_change_no_bit_of_the_model(nominal):
    got = physics.put_dynamics(nominal, physics.NOMINAL)
    for path, w in _leaves(nominal).items():
        np.testing.assert_array_equal(np.asarray(_leaves(got)[path]), np.asarray(w), err_msg=str(path))
    assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(nominal)


def test_put_dynamics_batch_is_put_dynamics_per_robot_with_playgrounds_in_axes(nominal):
    dyn = physics.Dynamics(friction=jnp.array([0.2, 1.0, 0.7]), mass_scale=jnp.array([1.0, 1.3, 0.8]),
                           kp_scale=0.5)  # a shared leaf broadcasts
    batched, in_axes = physics.put_dynamics_batch(nominal, dyn)
    axes = jax.tree_util.tree_flatten_with_path(in_axes, is_leaf=lambda x: x is None)[0]
    on = {jax.tree_util.keystr(p) for p, a in axes if a == 0}
    assert on == {".geom_friction", ".body_mass", ".body_inertia", ".body_subtreemass", ".dof_armature", ".dof_M0",
                  ".body_invweight0", ".dof_invweight0", ".actuator_acc0", ".actuator_gainprm", ".actuator_biasprm",
                  ".stat"}
    for i in range(3):
        one = physics.put_dynamics(nominal, jax.tree_util.tree_map(lambda x, i=i: jnp.broadcast_to(x, (3,))[i], dyn))
        for path, leaf in _leaves(one).items():
            b = _leaves(batched)[path]
            per_robot = any(jax.tree_util.keystr(path).startswith(k) for k in on)
            np.testing.assert_array_equal(np.asarray(b[i] if per_robot else b), np.asarray(leaf))
    # what vmap with those in_axes sees per robot is that robot's model
    masses = jax.vmap(lambda m: jnp.sum(m.body_mass), in_axes=(in_axes,))(batched)
    np.testing.assert_allclose(masses, 58.0 * np.array([1.0, 1.3, 0.8]), rtol=1e-6)
    with pytest.raises(ValueError, match="leading batch axis"):
        physics.put_dynamics_batch(nominal, physics.NOMINAL)


# --------------------------------------------------------------------------- bounds, hostile values


values = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32),
                   st.sampled_from([0.0, -0.0, 1e-30, -1e-30, 1e30, 0.1, 0.1000001, 200.0, 200.5, 10.0, 10.000001]))


@given(name=st.sampled_from(physics.FIELDS), value=values)
def test_a_value_is_refused_at_the_boundary_iff_it_is_flagged_inside_jit(name, value):
    """check() raises (naming the field and its bounds) exactly where sanitize() replaces the value by its nominal
    one and flags it; never a NaN through."""
    b = physics.BOUNDS[name]
    within = np.isfinite(value) and (value > b.lo if b.strict else value >= b.lo) and value <= b.hi
    dyn = physics.NOMINAL.replace(**{name: np.float32(value)})
    if within:
        physics.check(dyn)
    else:
        with pytest.raises(ValueError, match=rf"^dynamics\.{name} must be finite, .*{b.hi:g}"):
            physics.check(dyn)
    clean, invalid = jax.jit(physics.sanitize)(dyn)
    assert bool(invalid) == (not within)
    got = float(getattr(clean, name))
    assert got == (np.float32(value) if within else getattr(physics.NOMINAL, name))
    for other in physics.FIELDS:
        assert np.isfinite(float(getattr(clean, other)))


@pytest.mark.parametrize("bad, error, match", [
    ({"friction": "high"}, TypeError, "dynamics.friction must be numbers"),
    ({"push": True}, TypeError, "dynamics.push must be numbers"),
    ({"latency": np.zeros(3)}, ValueError, r"dynamics.latency must be a scalar, got shape \(3,\)"),
])
def test_check_refuses_wrong_types_and_shapes(bad, error, match):
    with pytest.raises(error, match=match):
        physics.check(physics.NOMINAL.replace(**bad))
    with pytest.raises(TypeError, match="must be an ijoy_jax.sim.physics.Dynamics"):
        physics.check({"friction": 1.0})


def test_a_batch_takes_scalars_or_one_value_per_robot():
    physics.check(physics.Dynamics(friction=np.array([0.3, 1.0]), push=2.0), batch=2)
    with pytest.raises(ValueError, match=r"dynamics.friction must be a scalar or shape \(3,\)"):
        physics.check(physics.Dynamics(friction=np.array([0.3, 1.0])), batch=3)
    with pytest.raises(ValueError, match="dynamics.mass_scale must be finite, > 0"):
        physics.check(physics.Dynamics(mass_scale=np.array([1.0, 0.0])), batch=2)


@pytest.mark.parametrize("latency, ticks", [(0.0, 0), (0.004, 0), (0.006, 1), (0.01, 1), (0.049, 5), (0.1, 10),
                                            (0.5, 10), (-0.02, 0)])
def test_latency_is_whole_control_ticks(latency, ticks):
    assert int(physics.latency_ticks(latency, 0.01)) == ticks
    assert physics.max_latency_ticks(0.01) == 10 and physics.max_latency_ticks(0.02) == 5


# --------------------------------------------------------------------------- the Sim as a pytree


@pytest.fixture(scope="module")
def sims():
    robot = ij.robots.hrp2()
    return W.make_sim(SHAPE, RES, robot=robot), W.make_sim(SHAPE, RES, robot=robot)


def test_sim_models_are_its_leaves_and_its_settings_its_structure(sims):
    a, b = sims
    leaves, tree = jax.tree_util.tree_flatten(a)
    n_model = len(jax.tree_util.tree_leaves(a.mjx_model)) + len(jax.tree_util.tree_leaves(a.mjx_free))
    assert len(leaves) == n_model and all(isinstance(x, jax.Array) for x in leaves)
    assert tree == jax.tree_util.tree_structure(b)  # built twice with the same settings: one structure
    other = dataclasses.replace(a, fall_tilt=0.5)
    assert jax.tree_util.tree_structure(other) != tree
    back = jax.tree_util.tree_unflatten(tree, leaves)
    assert back.mj_model is a.mj_model and back.index is a.index and back.cfg == a.cfg


def test_a_jitted_function_of_a_sim_traces_its_models_and_retraces_for_no_equal_sim(sims):
    a, b = sims
    traces = []

    @jax.jit
    def total_mass(sim):
        traces.append(1)
        assert isinstance(sim.mjx_model.body_mass, jax.core.Tracer)  # an argument, not a constant
        return jnp.sum(sim.mjx_model.body_mass)

    assert float(total_mass(a)) == pytest.approx(58.0, rel=1e-6)
    assert float(total_mass(b)) == pytest.approx(58.0, rel=1e-6)
    heavier = dataclasses.replace(b, mjx_model=physics.put_dynamics(b.mjx_model, physics.Dynamics(mass_scale=2.0)))
    assert float(total_mass(heavier)) == pytest.approx(116.0, rel=1e-6)
    assert len(traces) == 1


def test_nominal_dynamics_are_the_sims_own(sims):
    a, _ = sims
    assert W.nominal_dynamics(a) == physics.NOMINAL
    slippery = dataclasses.replace(a, params=model.biped_params(friction=0.4))
    assert W.nominal_dynamics(slippery) == physics.NOMINAL.replace(friction=0.4)
    # every actuator is a position servo, whose kp put_dynamics scales
    assert set(np.asarray(a.mjx_model.actuator_biastype)) == {int(mujoco.mjtBias.mjBIAS_AFFINE)}


@pytest.mark.slow
def test_sensors_read_after_quiet_steps_are_the_sensors_every_step_computes(sims):
    """The walker's physics steps run without MuJoCo's sensor stage and read the sensors once per control tick
    (:func:`W.read_sensors`): the robot moves exactly as with sensors on, and the sensors read afterwards equal
    those ``mjx.step`` computes in its last step (the ankles' force/torque and the CoM and its velocity).

    Reference: five plain ``mjx.step`` calls of the model with its sensors, from a standing robot given a push and
    joint targets off its pose (so the soles' contact forces and the accelerations are not zero)."""
    sim = sims[0]
    robot = ij.robots.hrp2()

    @jax.jit
    def both():
        world = W.make_world(sim, TERRAIN)
        d = W.init_state(sim, world, robot, ij.robots.start_stance(robot, 0.3, 0.25), 1).data
        d = d.replace(qvel=d.qvel.at[0].set(0.3).at[4].set(-0.5), ctrl=d.ctrl + 0.05)
        plain = lax.fori_loop(0, 5, lambda _, d: mjx.step(world.m, d), d)
        # as the walker's tick: each quiet step carries the state it started from, for the sensors after the last
        quiet, start = lax.fori_loop(0, 5, lambda _, c: (mjx.step(W.without_sensors(world.m), c[0]),
                                                          W.step_start(c[0])), (d, W.step_start(d)))
        return plain, quiet, W.read_sensors(world.m, quiet, start)

    plain, quiet, read = both()
    np.testing.assert_allclose(quiet.qpos, plain.qpos, rtol=0, atol=1e-6)
    np.testing.assert_allclose(quiet.qvel, plain.qvel, rtol=0, atol=1e-5)
    # the quiet steps computed no sensor: sensordata is the start state's (zeros; init_state computes none)
    assert not np.any(np.asarray(quiet.sensordata))
    want = np.asarray(plain.sensordata)
    assert np.abs(want).max() > 100.0  # the soles are loaded: the force sensors read hundreds of N
    # float32, two traces of the same arithmetic: rounding of a few ulp of the largest value (hundreds of N)
    np.testing.assert_allclose(read.sensordata, want, rtol=0, atol=1e-5 * np.abs(want).max())
    for name in ("qpos", "qvel", "act", "time"):  # the integrated state stays
        np.testing.assert_array_equal(getattr(read, name), getattr(quiet, name), err_msg=name)
