"""A described robot on the terrain height field (ijoy_jax.sim.scene), proved on the Unitree G1 with native MuJoCo.

References: the MJCF's own foot boxes (sphere placement), MuJoCo's contact forces (the ankle sensors and the
load on each foot) and its subtree centre of mass (the com sensor).
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax.sim import hfield, menagerie, model, scene

ORIGIN, SHAPE, RES = (-0.6, -0.6), (60, 60), 0.02


@pytest.fixture(scope="module")
def g1_on_flat():
    m = scene.terrain_scene(menagerie.g1_spec(meshes=False), shape=SHAPE, resolution=RES, origin=ORIGIN).compile()
    flat = ij.terrain.flat(SHAPE, RES, origin=ORIGIN, has_height=True)
    m.hfield_data[:] = np.asarray(hfield.hfield_data(model.BipedParams(), flat))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key(menagerie.G1_KEYFRAME).id)
    mujoco.mj_kinematics(m, d)
    soles = [m.site(f"{s}_sole").id for s in scene.SIDES]
    d.qpos[2] -= d.site_xpos[soles, 2].mean()  # the soles on the ground (z = 0)
    mujoco.mj_forward(m, d)
    return m, d


def test_the_floor_and_everything_naming_it_are_gone_and_only_the_sole_spheres_collide(g1_on_flat):
    m, _ = g1_on_flat
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor") < 0
    assert m.geom("terrain").type == mujoco.mjtGeom.mjGEOM_HFIELD
    assert m.npair == 3  # the G1's hand-thigh and foot-foot pairs stay; its two foot-floor pairs are gone
    assert not any("floor" in m.sensor(i).name for i in range(m.nsensor))
    colliding = {m.geom(g).name for g in range(m.ngeom) if m.geom_contype[g] or m.geom_conaffinity[g]}
    p = model.BipedParams()
    n = p.sole_grid[0] * p.sole_grid[1]
    assert colliding == {"terrain"} | {f"{s}_sole{k}" for s in scene.SIDES for k in range(n)}


def test_the_sole_spheres_rest_on_the_foot_boxes_bottom_faces(g1_on_flat):
    m, d = g1_on_flat
    r = model.BipedParams().sole_radius
    for side, box in zip(scene.SIDES, menagerie.G1_SOLES, strict=True):
        g = m.geom(box).id
        rot, half = d.geom_xmat[g].reshape(3, 3), m.geom_size[g]
        bottom = d.geom_xpos[g] - rot[:, 2] * half[2]
        spheres = np.array([d.geom_xpos[m.geom(f"{side}_sole{k}").id] for k in range(6)])
        local = (spheres - bottom) @ rot  # in the box's frame
        np.testing.assert_allclose(local[:, 2], r, atol=1e-9)  # bottoms on the face
        np.testing.assert_allclose(np.abs(local[:, 0]).max(), half[0] - r, atol=1e-9)  # toe and heel edges
        np.testing.assert_allclose(np.abs(local[:, 1]).max(), half[1] - r, atol=1e-9)
        np.testing.assert_allclose(spheres[:, 2], r, atol=6e-4)  # on the ground (the key's soles pitch 0.35 deg)


def test_standing_the_feet_carry_the_robot_and_the_sensors_read_it(g1_on_flat):
    m, d0 = g1_on_flat
    d = mujoco.MjData(m)
    d.qpos[:], d.ctrl[:] = d0.qpos, d0.ctrl
    for _ in range(50):  # 0.1 s with the keyframe's position targets held
        mujoco.mj_step(m, d)
    load = {s: 0.0 for s in scene.SIDES}
    f = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        names = {m.geom(c.geom1).name, m.geom(c.geom2).name}
        assert "terrain" in names and len(names) == 2, names  # only sole spheres against the terrain
        mujoco.mj_contactForce(m, d, i, f)
        sole = (names - {"terrain"}).pop()
        load[sole.split("_")[0]] += f[0] * c.frame[2]  # the normal force's vertical part
    weight = m.body_subtreemass[1] * -m.opt.gravity[2]
    assert load["left"] == pytest.approx(load["right"], rel=0.02)  # the keyframe is symmetric
    assert 0.8 * weight < load["left"] + load["right"] < 1.3 * weight  # the robot sagging on soft servos
    for side in scene.SIDES:
        adr = m.sensor_adr[m.sensor(f"{side}_ankle_force").id]
        world = d.site_xmat[m.site(f"{side}_ankle").id].reshape(3, 3) @ d.sensordata[adr:adr + 3]
        foot = m.body(m.geom(menagerie.G1_SOLES[scene.SIDES.index(side)]).bodyid[0]).id
        # what the ankle passes down is the ground's push less the foot's own weight (and its tiny acceleration)
        assert -world[2] == pytest.approx(load[side] - m.body_mass[foot] * 9.81, rel=0.03)
    adr = m.sensor_adr[m.sensor("com").id]
    np.testing.assert_allclose(d.sensordata[adr:adr + 3], d.subtree_com[m.body("pelvis").id])
