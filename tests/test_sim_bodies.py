"""The robots the walker drives (ijoy_jax.sim.bodies): the project's biped and the Unitree G1 behind one interface.

References: MuJoCo itself (``mj_kinematics`` puts the sole sites where the inverse kinematics was asked to, the
subtree centre of mass, the contact forces under each foot for the centre of pressure), and the biped's own
analytic functions (the interface must give exactly what they give).
"""

from __future__ import annotations

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax.sim import bodies, controller, kinematics, model, walker

ORIGIN, SHAPE, RES = (-0.6, -0.6), (60, 60), 0.02
MODELS = ("biped", "g1")


@pytest.fixture(scope="module", params=MODELS)
def robot_model(request):
    params = model.biped_params(model=request.param)
    m = bodies.build_model(params, ij.terrain.flat(SHAPE, RES, origin=ORIGIN, has_height=True))
    return params, m, model.model_index(m)


def _walk_height(params):
    return controller.WalkConfig(**bodies.walk_defaults(params)).pelvis_height


def _sites_at(m, idx, qpos):
    d = mujoco.MjData(m)
    d.qpos[:] = np.asarray(qpos, np.float64)
    mujoco.mj_kinematics(m, d)
    return d, d.site_xpos[idx.sole_site], d.site_xmat[idx.sole_site].reshape(2, 3, 3)


def test_the_legs_come_first_in_qpos_and_one_actuator_drives_each_joint_in_that_order(robot_model):
    params, m, idx = robot_model
    np.testing.assert_array_equal(idx.qpos_adr.ravel(), np.arange(7, 19))
    np.testing.assert_array_equal(idx.actuator.ravel(), np.arange(12))
    assert m.nu == m.nq - 7  # ctrl = qpos[7:]: every joint after the free one has its servo, in qpos order
    np.testing.assert_array_equal(m.jnt_qposadr[m.actuator_trnid[:, 0]], np.arange(7, m.nq))
    assert m.nq == 19  # the G1's waist and arms are welded (ijoy_jax.sim.g1)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(dx=st.floats(-0.2, 0.2), dy=st.floats(0.0, 0.12), yaw=st.floats(-0.3, 0.3), dz=st.floats(-0.04, 0.04),
       roll=st.floats(-0.05, 0.05), pitch=st.floats(-0.15, 0.15))
def test_stand_pose_puts_the_sole_sites_where_asked_as_mujoco_computes_them(robot_model, dx, dy, yaw, dz, roll,
                                                                               pitch):
    params, m, idx = robot_model
    half = params.stand_width / 2
    feet = np.array([[dx, half + dy, yaw], [0.0, -half, 0.0]])
    ground = np.array([dz, 0.0])
    tilt = np.array([[roll, pitch], [0.0, 0.0]])
    qpos, ok = bodies.stand_pose(params, jnp.asarray(feet, jnp.float32), jnp.asarray(ground, jnp.float32),
                                 jnp.float32(min(dz, 0.0) + _walk_height(params)),
                                 tilt=jnp.asarray(tilt, jnp.float32))
    assert bool(ok)
    _, pos, rot = _sites_at(m, idx, qpos)
    np.testing.assert_allclose(pos[:, :2], feet[:, :2], atol=2e-5)  # float32 through a 0.7 m chain
    np.testing.assert_allclose(pos[:, 2], ground, atol=2e-5)
    for row in range(2):
        want = np.asarray(kinematics.rpy_to_rot(jnp.asarray([*tilt[row], feet[row, 2]], jnp.float32)))
        np.testing.assert_allclose(rot[row], want, atol=5e-5)


def test_an_unreachable_sole_is_flagged_not_reached(robot_model):
    params, _, _ = robot_model
    half = params.stand_width / 2
    feet = jnp.asarray([[0.9, half, 0.0], [0.0, -half, 0.0]], jnp.float32)  # a metre-long stride
    _, ok = bodies.stand_pose(params, feet, jnp.zeros(2), jnp.float32(_walk_height(params)))
    assert not bool(ok)


def test_the_biped_goes_through_its_own_analytic_functions_unchanged():
    params = model.BipedParams()
    feet = jnp.asarray([[0.05, 0.1, 0.1], [-0.02, -0.095, 0.0]], jnp.float32)
    ground, z = jnp.asarray([0.02, 0.0], jnp.float32), jnp.float32(0.65)
    for a, b in zip(bodies.stand_pose(params, feet, ground, z), model.stand_pose(params, feet, ground, z),
                    strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert bodies.foot(params) == (params.foot_mass, (0.0, 0.0, params.ankle_height))


def test_the_ground_centre_of_pressure_from_the_ankle_sensors_is_the_contacts_own(robot_model):
    # The G1's ankle sits 4 cm behind its sole centre: the sensor's offset must be carried to the sole.
    params, m, idx = robot_model
    half = params.stand_width / 2
    # the pelvis moved about where the CoM stands above the soles' midpoint: the G1's CoM lies 3.9 cm ahead of
    # its pelvis (controller.standing_shift), the biped's 1 cm
    centre = -0.045 if params.model == "g1" else -0.01
    for shift in (centre - 0.025, centre, centre + 0.025):
        qpos, _ = bodies.stand_pose(params, jnp.asarray([[0.0, half, 0.0], [0.0, -half, 0.0]], jnp.float32),
                                    jnp.zeros(2), jnp.float32(_walk_height(params)),
                                    jnp.asarray([shift, 0.01], jnp.float32))
        d = mujoco.MjData(m)
        d.qpos[:] = np.asarray(qpos)
        d.ctrl[:] = d.qpos[7:]
        for _ in range(300):
            mujoco.mj_step(m, d)
        mujoco.mj_forward(m, d)
        wrench = np.concatenate([d.sensordata[idx.ankle_sensor[:, k, None] + np.arange(3)] for k in range(2)], 1)
        f, cop = controller.ground_cop(params, jnp.asarray(wrench, jnp.float32))
        for side in range(2):
            geoms = set(idx.sole_geoms[side].tolist())
            force, moment = 0.0, np.zeros(3)
            for i in range(d.ncon):
                c = d.contact[i]
                if {c.geom1, c.geom2} & geoms:
                    f6 = np.zeros(6)
                    mujoco.mj_contactForce(m, d, i, f6)
                    force += f6[0]
                    moment += f6[0] * c.pos
            site = idx.sole_site[side]
            want = d.site_xmat[site].reshape(3, 3).T @ (moment / force - d.site_xpos[site])
            assert force > 50.0
            np.testing.assert_allclose(float(f[side, 2]), force, rtol=0.01)
            # 1.5 mm: the sensors neglect the foot's inertia and read the step before the contacts settle
            np.testing.assert_allclose(np.asarray(cop[side]), want[:2], atol=1.5e-3)


@pytest.mark.slow  # a World and the start state of each robot: 45 s of compiles
@pytest.mark.parametrize("name", MODELS)
def test_the_walker_starts_with_the_centre_of_mass_above_the_soles(name):
    robot = ij.robots.g1() if name == "g1" else ij.robots.hrp2()
    terrain = ij.terrain.flat(SHAPE, RES, origin=ORIGIN, has_height=True)
    sim = walker.make_sim(SHAPE, RES, robot=robot, model=name)
    fitted = {k: getattr(sim.cfg, k) for k in ("com_height", "com_offset", "leg_share")}  # make_sim fits these
    assert sim.params.model == name and sim.cfg == controller.WalkConfig(**bodies.walk_defaults(sim.params), **fitted)
    assert sim.cfg.step_time == pytest.approx(float(robot.step_time))  # the G1: its own 0.5 s steps
    start = ij.robots.start_stance(robot, 0.0, 0.0, 0.4)
    state = walker.init_state(sim, walker.make_world(sim, terrain), robot, start, 1)
    d = mujoco.MjData(sim.mj_model)
    d.qpos[:] = np.asarray(state.data.qpos)
    mujoco.mj_kinematics(sim.mj_model, d)
    mujoco.mj_comPos(sim.mj_model, d)
    mid = d.site_xpos[sim.index.sole_site].mean(0)
    # the CoM model is fitted (controller.WalkConfig.com_offset, leg_share): within 3 mm of the midpoint
    np.testing.assert_allclose(d.subtree_com[sim.index.pelvis][:2], mid[:2], atol=3e-3)


def test_make_sim_refuses_an_unknown_robot_and_a_model_that_contradicts_its_params():
    with pytest.raises(ValueError, match="model must be one of"):
        walker.make_sim(SHAPE, RES, model="atlas")
    with pytest.raises(ValueError, match="differs from params.model"):
        walker.make_sim(SHAPE, RES, model.BipedParams(), model="g1")
    with pytest.raises(ValueError, match="BipedParams.model must be one of"):
        model.BipedParams(model="G1")


def test_the_g1s_welded_upper_body_stands_exactly_as_menageries_full_model_on_its_keyframe():
    """The walker's G1 welds the waist and arms at the ``knees_bent`` angles (ijoy_jax.sim.g1): on that keyframe
    every body sits where Menagerie's full model puts it, with the same masses, and only the legs move."""
    from ijoy_jax.sim import menagerie

    full = menagerie.g1_spec(meshes=False).compile()
    welded = bodies.build_model(model.biped_params(model="g1"), ij.terrain.flat(SHAPE, RES, origin=ORIGIN,
                                                                                has_height=True))
    assert (full.nv, welded.nv, welded.nu) == (35, 18, 12)
    poses = []
    for m in (full, welded):
        d = mujoco.MjData(m)
        mujoco.mj_resetDataKeyframe(m, d, m.key(menagerie.G1_KEYFRAME).id)
        mujoco.mj_kinematics(m, d)
        ids = [m.body(full.body(b).name).id for b in range(1, full.nbody)]
        poses.append((d.xpos[ids], d.xmat[ids], m.body_mass[ids], m.body_inertia[ids]))
    for a, b in zip(*poses, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-9)


@pytest.mark.parametrize("name", MODELS)
def test_the_rendered_robot_replays_the_physics_qpos(name):
    """The robot as rendered (``meshes=True``: the G1's visual meshes, which its physics leaves out) has the
    physics' joints in the same order, the same bodies and masses and the same contacts, so a simulated qpos
    puts every body where the physics had it."""
    params = model.biped_params(model=name)
    terrain = ij.terrain.flat(SHAPE, RES, origin=ORIGIN, has_height=True)
    phys, looks = bodies.build_model(params, terrain), bodies.build_model(params, terrain, meshes=True)
    assert (looks.nmesh > 0) == (name == "g1") and phys.nmesh == 0
    for size in ("nq", "nv", "nu", "njnt", "nbody", "nsite", "nsensor"):
        assert getattr(looks, size) == getattr(phys, size), size
    names = lambda m, obj, n: [mujoco.mj_id2name(m, obj, i) for i in range(n)]  # noqa: E731
    for obj, n in ((mujoco.mjtObj.mjOBJ_JOINT, "njnt"), (mujoco.mjtObj.mjOBJ_BODY, "nbody"),
                   (mujoco.mjtObj.mjOBJ_ACTUATOR, "nu")):
        assert names(looks, obj, getattr(looks, n)) == names(phys, obj, getattr(phys, n))
    for field in ("jnt_qposadr", "jnt_type", "jnt_range", "body_parentid", "body_mass", "body_inertia", "body_ipos",
                  "actuator_gainprm", "actuator_trnid"):
        np.testing.assert_array_equal(getattr(looks, field), getattr(phys, field), err_msg=field)
    # what touches: the same geoms, sizes and frictions (every added geom is visual: contype and conaffinity 0)
    touching = lambda m: [(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g), m.geom_type[g], *m.geom_size[g],  # noqa: E731
                           *m.geom_friction[g]) for g in range(m.ngeom) if m.geom_contype[g] or m.geom_conaffinity[g]]
    assert touching(looks) == touching(phys)
    meshes = looks.geom_type == mujoco.mjtGeom.mjGEOM_MESH
    assert not (looks.geom_contype[meshes] | looks.geom_conaffinity[meshes]).any()
    robot = ij.robots.for_model(name)
    feet = jnp.asarray(ij.robots.start_stance(robot, 0.0, 0.0, 0.3))
    qpos = np.asarray(bodies.stand_pose(params, feet, jnp.zeros(2), jnp.float32(_walk_height(params)))[0])
    d_phys, d_looks = mujoco.MjData(phys), mujoco.MjData(looks)
    for m, d in ((phys, d_phys), (looks, d_looks)):
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
    np.testing.assert_array_equal(d_looks.xpos, d_phys.xpos)
    np.testing.assert_array_equal(d_looks.site_xpos, d_phys.site_xpos)
