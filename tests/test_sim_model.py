"""Tests of ijoy_jax.sim.model: the MjSpec biped, its height field, standing, and MJX terrain batches."""

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax.sim import hfield, model

P = model.BipedParams()
RES = 0.02
ORIGIN = (-0.3, -0.3)
SHAPE = (40, 30)  # x in [-0.3, 0.5], y in [-0.3, 0.3]
BLOCK = (slice(28, 34), slice(12, 18))  # obstacle cells: x in [0.26, 0.38], y in [-0.06, 0.06], clear of the feet
BALL_R = P.sole_radius  # as small as the sole spheres: the same MJX collision kernel (one compile)
# Site poses after mj_forward follow float64 IK and MuJoCo's float64 kinematics: ~1e-15; 1e-6 is the requirement.
POSE_TOL = 1e-6
# Soft contacts: a resting body sinks a few mm into the surface under MuJoCo's default solref (0.02 s) and solimp.
REST_TOL = 0.005
STAND_DROP = 0.02  # metres of pelvis drop allowed while standing for 2 s (the "no fall" check)


def _block_centre():
    i = (BLOCK[0].start + BLOCK[0].stop) / 2
    j = (BLOCK[1].start + BLOCK[1].stop) / 2
    return np.array(ORIGIN) + np.array([i, j]) * RES


def _obstacle_terrain():
    free = np.ones(SHAPE, bool)
    free[BLOCK] = False
    return ij.terrain.from_arrays(None, free, RES, ORIGIN)


def _with_ball(terrain):
    """Biped + a free ball of the sole spheres' size above the obstacle block (the ball is geom -1, qpos 19:26)."""
    spec = model.build_spec(P, terrain.shape, terrain.resolution, np.asarray(terrain.origin))
    ball = spec.worldbody.add_body(name="ball", pos=[*_block_centre(), P.obstacle_height + 0.1])
    ball.add_freejoint()
    ball.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[BALL_R, 0, 0], mass=0.1, contype=1, conaffinity=0)
    m = spec.compile()
    m.hfield_data[:] = np.asarray(hfield.hfield_data(P, terrain))
    return m


def test_compiles_with_mass_and_order():
    m = model.build_model(model.biped_params(ij.robots.hrp2()), ij.terrain.flat(SHAPE, RES, ORIGIN))
    assert m.nq == 19 and m.nv == 18 and m.nu == 12
    assert abs(float(m.body_mass.sum()) - 58.0) < 0.5
    ix = model.model_index(m)
    names = [f"{s}_{j}" for s in model.SIDES for j in model.JOINTS]
    assert [m.joint(i).name for i in range(1, 13)] == names
    assert [m.actuator(i).name for i in range(12)] == names
    np.testing.assert_array_equal(ix.qpos_adr.ravel(), np.arange(7, 19))
    np.testing.assert_array_equal(ix.qvel_adr.ravel(), np.arange(6, 18))
    np.testing.assert_array_equal(ix.actuator.ravel(), np.arange(12))
    assert ix.sole_geoms.shape == (2, 6)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    np.testing.assert_allclose(m.actuator_ctrlrange[:6], m.jnt_range[1:7])  # radians, not degrees
    # only sole spheres (and the terrain) take part in collisions
    colliding = {int(g) for g in np.flatnonzero((m.geom_contype | m.geom_conaffinity) != 0)}
    assert colliding == set(ix.sole_geoms.ravel().tolist()) | {int(ix.hfield_geom)}


@pytest.mark.parametrize("shape", [(40, 30), (123, 77), (512, 512)])
def test_mjx_collides_each_sole_sphere_with_2x2_cells(shape):
    from mujoco.mjx._src import collision_driver  # private: the grouping MJX compiles, one kernel per key

    m = model.build_model(P, ij.terrain.flat(shape, RES, (-1.37, -2.11)))
    assert [k.subgrid_size for k in collision_driver._geom_groups(m)] == [(2, 2)]


def test_shin_contacts_flag():
    m = model.build_spec(dataclasses.replace(P, shin_contacts=True), (2, 2), 1.0).compile()
    assert np.all(m.geom_contype[model.model_index(m).shin_geom] == 1)


@pytest.mark.parametrize("bad, match", [
    (dict(thigh=-0.3), r"BipedParams\.thigh "), (dict(kp=(1.0,) * 5), r"BipedParams\.kp must be a tuple of 6"),
    (dict(z_hi=-1.0), "must exceed z_lo"), (dict(timestep=0.0), r"BipedParams\.timestep "),
    (dict(stand_height=0.9), "straight leg"), (dict(nonsense=1.0), "unknown BipedParams fields"),
    (dict(thigh="0.3"), r"BipedParams\.thigh "), (dict(friction=True), r"BipedParams\.friction "),
    (dict(hip_offset_y=-0.01), r"BipedParams\.hip_offset_y "), (dict(iterations=2.5), r"BipedParams\.iterations "),
    (dict(ls_iterations=0), r"BipedParams\.ls_iterations "), (dict(sole_grid=(3, 0)), r"BipedParams\.sole_grid\[1\] "),
    (dict(kp=(1.0,) * 5 + (float("nan"),)), r"BipedParams\.kp\[5\] "), (dict(kv=(1.0,) * 5 + (-1.0,)), r"kv\[5\]"),
    (dict(kp=[1.0] * 6), "must be a tuple"), (dict(shin_contacts=1), "shin_contacts must be True or False"),
    (dict(range_lo=P.range_hi), "range_lo must be below range_hi"), (dict(sole_radius=0.1), "too large for the foot"),
])
def test_bad_params(bad, match):
    with pytest.raises(ValueError, match=match):
        model.biped_params(**bad)


PARAM_FIELDS = [f.name for f in dataclasses.fields(model.BipedParams)]


@settings(max_examples=80, deadline=None)
@given(st.sampled_from(PARAM_FIELDS), st.one_of(st.none(), st.text(max_size=3), st.complex_numbers(),
                                                st.sampled_from([float("nan"), float("inf"), -float("inf")]),
                                                st.lists(st.floats(), max_size=2)))
def test_biped_params_refuse_hostile_values_by_name(name, bad):
    """Every field, through ``dataclasses.replace`` too: a clear ValueError naming it, never MuJoCo's compiler."""
    with pytest.raises(ValueError, match=rf"BipedParams\.{name}[ \[]"):
        dataclasses.replace(P, **{name: bad})


def test_biped_params_accept_numpy_scalars_and_the_documented_zeros():
    p = model.BipedParams(thigh=np.float32(0.3), iterations=np.int64(3), friction=0.0, hip_offset_y=0,
                          sole_grid=(np.int32(2), 2), damping=(0.0,) * 6, shin_contacts=np.bool_(True))
    assert p.iterations == 3 and p.friction == 0.0


def test_standing_qpos_puts_soles_on_the_commanded_poses():
    m = model.build_spec(P, (2, 2), 1.0).compile()
    d = mujoco.MjData(m)
    ix = model.model_index(m)
    rng = np.random.default_rng(0)
    for k in range(10):
        local = np.array([[0.0, 0.095, 0.0], [0.0, -0.095, 0.0]]) + rng.uniform(-0.05, 0.05, (2, 3))
        yaw = rng.uniform(-3, 3)
        c, s = np.cos(yaw), np.sin(yaw)
        feet = np.stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1], local[:, 2] + yaw], 1)
        feet[:, :2] += rng.uniform(-1, 1, 2)
        ground = rng.uniform(-0.05, 0.05, 2) if k else np.zeros(2)  # a 10 cm step at most
        d.qpos[:] = model.standing_qpos(P, feet, ground)
        mujoco.mj_forward(m, d)
        for row in range(2):
            np.testing.assert_allclose(d.site_xpos[ix.sole_site[row]], [*feet[row, :2], ground[row]], atol=POSE_TOL)
            want = np.array(ij.sim.kinematics.rot_z(feet[row, 2]), np.float64)
            np.testing.assert_allclose(d.site_xmat[ix.sole_site[row]].reshape(3, 3), want, atol=1e-5)
            if not k:  # flat: every sole sphere touches z = 0
                np.testing.assert_allclose(d.geom_xpos[ix.sole_geoms[row], 2], P.sole_radius, atol=POSE_TOL)
    q = model.standing_qpos(P, com_height=0.75)
    d.qpos[:] = q
    mujoco.mj_forward(m, d)
    assert abs(d.subtree_com[0, 2] - 0.75) < 1e-3
    with pytest.raises(ValueError):
        model.standing_qpos(P, [[0.0, 0.5, 0.0], [0.0, -0.5, 0.0]])


def test_hfield_data_matches_build_model_and_mujoco_rescales_user_data():
    rng = np.random.default_rng(1)
    height = rng.uniform(-1.3, 1.4, SHAPE).astype(np.float32)  # beyond [z_lo, z_hi]: clipped
    free = rng.uniform(size=SHAPE) > 0.2
    for t in (ij.terrain.from_arrays(height, free, RES, ORIGIN), ij.terrain.from_arrays(None, free, RES, ORIGIN)):
        m = model.build_model(P, t)
        data = jax.jit(hfield.hfield_data, static_argnums=0)(P, t)
        assert data.dtype == jnp.float32 and data.shape == (SHAPE[0] * SHAPE[1],)
        np.testing.assert_array_equal(m.hfield_data, np.asarray(data))
        assert m.hfield_nrow[0] == SHAPE[1] and m.hfield_ncol[0] == SHAPE[0]
        h = np.asarray(hfield.physical_heights(t, P.obstacle_height))
        i, j = 7, 11  # row j (y), column i (x)
        z = P.z_lo + m.hfield_data[j * SHAPE[0] + i] * m.hfield_size[0, 2]
        assert abs(z - np.clip(h[i, j], P.z_lo, P.z_hi)) < 1e-6
    # why build_model writes hfield_data after compiling: MuJoCo min-max normalises user data
    spec = mujoco.MjSpec()
    spec.add_hfield(name="h", nrow=2, ncol=2, size=[1, 1, 1, 0.1], userdata=[0.25, 0.5, 0.25, 0.25])
    np.testing.assert_allclose(spec.compile().hfield_data, [0.0, 1.0, 0.0, 0.0])


def test_hfield_geometry_samples_at_cell_centres():
    t = ij.terrain.flat(SHAPE, RES, ORIGIN)
    m = model.build_model(P, t)
    g = int(model.model_index(m).hfield_geom)
    first = m.geom_pos[g][:2] - m.hfield_size[0, :2]
    last = m.geom_pos[g][:2] + m.hfield_size[0, :2]
    np.testing.assert_allclose(first, np.array(ORIGIN) + 0.5 * RES, atol=1e-9)
    np.testing.assert_allclose(last, np.array(ORIGIN) + (np.array(SHAPE) - 0.5) * RES, atol=1e-9)
    assert abs(m.geom_pos[g][2] - P.z_lo) < 1e-12


def test_ball_rests_on_2d_obstacle_and_robot_stands_cpu():
    m = _with_ball(_obstacle_terrain())
    d = mujoco.MjData(m)
    d.qpos[:19] = model.standing_qpos(P)
    d.qpos[19:22] = [*_block_centre(), P.obstacle_height + 0.1]
    d.qpos[22] = 1.0
    d.ctrl[:] = d.qpos[7:19]
    z0 = d.qpos[2]
    for _ in range(int(2.0 / m.opt.timestep)):
        mujoco.mj_step(m, d)
    assert abs(d.qpos[21] - (P.obstacle_height + BALL_R)) < REST_TOL
    assert z0 - d.qpos[2] < STAND_DROP
    np.testing.assert_allclose(d.qpos[:2], 0.0, atol=0.02)


@pytest.mark.slow
def test_mjx_put_terrains_ball_contact_and_standing():
    """One jit: a batch of two terrains (flat, obstacle block) in one mjx model; 2 s of standing."""
    from mujoco import mjx

    flat = ij.terrain.flat(SHAPE, RES, ORIGIN)
    m = _with_ball(flat)  # compiled with the flat terrain; the batch swaps in both
    mx = mjx.put_model(m)
    terrains = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), flat, _obstacle_terrain())
    mb, axes = hfield.put_terrains(mx, P, terrains)
    assert mb.hfield_data.shape == (2, SHAPE[0] * SHAPE[1])
    vmapped = jax.eval_shape(jax.vmap(lambda t: hfield.put_terrain(mx, P, t)), terrains)  # a batch of models
    assert vmapped.hfield_data.shape == (2, SHAPE[0] * SHAPE[1]) and vmapped.body_mass.shape[0] == 2
    single = jax.jit(hfield.put_terrain, static_argnums=1)(mx, P, _obstacle_terrain())
    np.testing.assert_array_equal(np.asarray(single.hfield_data), np.asarray(mb.hfield_data[1]))

    qpos = np.array(m.qpos0)
    qpos[:19] = model.standing_qpos(P)
    qpos[19:22] = [*_block_centre(), P.obstacle_height + BALL_R - 0.004]  # 4 mm into the raised block
    d0 = mjx.make_data(mx).replace(qpos=jnp.asarray(qpos), ctrl=jnp.asarray(qpos[7:19]))
    ball = m.ngeom - 1
    steps = int(2.0 / m.opt.timestep)

    def run(mm, d):
        def body(d, _):  # step() collides at the state it starts from: dist[0] is the initial state's
            d = mjx.step(mm, d)
            c = model.contacts(d)
            return d, jnp.min(jnp.where((c.geom1 == ball) | (c.geom2 == ball), c.dist, 1.0))

        d, dist = jax.lax.scan(body, d, None, length=steps)
        return dist[0], d.qpos

    dist0, qpos_end = jax.jit(jax.vmap(run, in_axes=(axes, None)))(mb, d0)
    dist0, qpos_end = np.asarray(dist0), np.asarray(qpos_end)
    assert dist0[0] > 0.1  # flat: no contact under the ball
    assert abs(dist0[1] + 0.004) < 1e-4  # obstacle: the replaced hfield data is what MJX collides with
    assert abs(qpos_end[1, 21] - (P.obstacle_height + BALL_R)) < REST_TOL
    assert qpos_end[0, 21] < 0.05  # the ball fell to the floor of the flat terrain
    for k in range(2):
        assert qpos[2] - qpos_end[k, 2] < STAND_DROP
        np.testing.assert_allclose(qpos_end[k, :2], 0.0, atol=0.02)


def test_put_terrain_places_the_height_field_on_the_terrains_grid():
    """A model built at one origin, given terrains at others: the height field geom sits where build_model puts it."""
    from mujoco import mjx

    params = model.biped_params()
    shape, res = (30, 20), 0.02
    m = mjx.put_model(model.build_model(params, ij.terrain.flat(shape, res, origin=(0.0, 0.0), has_height=True)))
    gid = model.model_index(model.build_model(params, ij.terrain.flat(shape, res, has_height=True))).hfield_geom
    origins = [(-1.0, -0.8), (2.5, 0.3)]
    terrains = [ij.terrain.flat(shape, res, origin=o, has_height=True) for o in origins]
    for t in terrains:
        want = model.build_model(params, t).geom_pos[gid]
        np.testing.assert_allclose(hfield.put_terrain(m, params, t).geom_pos[gid], want, atol=1e-6)
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *terrains)
    mb, axes = hfield.put_terrains(m, params, batch)
    assert axes.geom_pos == 0
    for k, t in enumerate(terrains):
        np.testing.assert_allclose(mb.geom_pos[k, gid], model.build_model(params, t).geom_pos[gid], atol=1e-6)


def test_contacts_accessor_reads_mjx_3_17_contacts():
    """model.contacts reaches into mjx.Data's private _impl: pinned to the mujoco-mjx version we depend on."""
    from importlib import metadata

    from mujoco import mjx

    assert metadata.version("mujoco-mjx") == "3.17.0", "re-check model.contacts against this mujoco-mjx"
    m = model.build_model(P, ij.terrain.flat(SHAPE, RES, ORIGIN))
    ix = model.model_index(m)
    ncon = 4 * ix.sole_geoms.size  # each sole sphere meets a 2 x 2 sub-grid of the height field's prisms
    mx = mjx.put_model(m)
    for c in (model.contacts(mjx.make_data(m)), jax.eval_shape(lambda d: model.contacts(mjx.step(mx, d)),
                                                               mjx.make_data(m))):
        shapes = {k: getattr(c, k).shape for k in ("dist", "pos", "frame", "geom", "geom1", "geom2")}
        assert shapes == dict(dist=(ncon,), pos=(ncon, 3), frame=(ncon, 3, 3), geom=(ncon, 2), geom1=(ncon,),
                              geom2=(ncon,))
