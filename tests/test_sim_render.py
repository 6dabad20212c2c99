"""The renderer (ijoy_jax.sim.render) with the Unitree G1: its visual meshes, which its physics leaves out, drawn
at the simulated qpos (the project's biped is rendered in tests/test_sim_rollouts.py, from its own rollouts).

MuJoCo renders for real, offscreen (EGL: tests/conftest.py imports ijoy_jax.sim first). The fast test renders
the G1 standing, from :func:`ijoy_jax.sim.bodies.stand_pose`; the slow ones walk it with MJX through the clutter
of ``ijoy sim render`` (one compile) and render the walk, through the library and through the command line.
"""

import json

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from PIL import Image

import ijoy_jax as ij
from ijoy_jax.apps import cli
from ijoy_jax.sim import bodies, render
from ijoy_jax.sim import walker as W
from ijoy_jax.terrain import generators

# ``ijoy sim render``'s walk (apps/sim_cli.py): its 4 x 2 m clutter map at 2 cm, forward at 0.2 m/s
SHAPE, RES = (200, 100), 0.02
CLUTTER = generators.ObstacleParams(count=14, size_min=0.04, size_max=0.12)
COMMAND = (0.2, 0.0, 0.0)
STEPS, FRAMES = 3, 3
W_PX, H_PX = 160, 120
GROUND_TOL = 0.01  # m: a stance sole's height above the flat ground between the obstacles (its spheres' contact)


def _g1():
    robot = ij.robots.g1(margin=0.02)
    return robot, W.make_sim(SHAPE, RES, robot=robot, model="g1")


def _segments(sim, terrain):
    """The rendered model's geoms, by kind: the robot's mesh geoms, its other visible geoms, its hidden ones."""
    m = bodies.build_model(sim.params, terrain, meshes=True)
    robot = m.geom_bodyid > 0
    mesh = robot & (m.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
    hidden = robot & (m.geom_group >= 3)  # MuJoCo's viewers hide groups 3-5: the G1's collision shapes
    return np.flatnonzero(mesh), np.flatnonzero(robot & ~mesh & ~hidden), np.flatnonzero(hidden)


def test_the_g1_stands_drawn_with_its_meshes_in_the_projects_looks():
    robot, sim = _g1()
    terrain = ij.terrain.flat(SHAPE, RES, has_height=True)
    feet = jnp.asarray(ij.robots.start_stance(robot, 1.0, 1.0))
    qpos, ok = bodies.stand_pose(sim.params, feet, jnp.zeros(2), jnp.float32(sim.cfg.pelvis_height))
    assert bool(ok) and qpos.shape == (sim.mj_model.nq,)
    rgb = render.render(sim, terrain, np.asarray(qpos), width=W_PX, height=H_PX)
    assert rgb.shape == (1, H_PX, W_PX, 3) and rgb.dtype == np.uint8
    assert len(np.unique(rgb[0].reshape(-1, 3) // 16, axis=0)) > 30  # a picture, not a blank frame
    seg = render.render(sim, terrain, np.asarray(qpos), width=W_PX, height=H_PX, segmentation=True)[0]
    meshes, others, hidden = _segments(sim, terrain)
    rows, cols = np.nonzero(np.isin(seg, meshes))
    assert rows.size > 500  # the G1 is its meshes
    assert abs(cols.mean() - W_PX / 2) < W_PX / 5  # in the middle, where the camera looks
    assert not np.isin(seg, hidden).any()  # its collision capsules and foot boxes are not drawn
    # the sky and light of the project's biped, not the white sky of the G1's own (MuJoCo Playground) scene
    biped = W.make_sim(SHAPE, RES, robot=ij.robots.hrp2())
    other = render.render(
        biped,
        terrain,
        np.asarray(
            bodies.stand_pose(
                biped.params,
                jnp.asarray(ij.robots.start_stance(ij.robots.hrp2(), 1.0, 1.0)),
                jnp.zeros(2),
                jnp.float32(biped.cfg.pelvis_height),
            )[0]
        ),
        width=W_PX,
        height=H_PX,
    )
    np.testing.assert_array_equal(rgb[0, :8], other[0, :8])  # the top rows: sky only, for both
    assert rgb[0, :8].mean() < 200


@pytest.fixture(scope="module")
def walk():
    """The G1 walked by MJX through ``ijoy sim render``'s clutter (seed 0), STEPS steps, FRAMES states each."""
    robot, sim = _g1()
    terrain = generators.obstacles(jax.random.key(0), CLUTTER, shape=SHAPE, resolution=RES, max_count=16)
    x, y = np.asarray(generators.start_point(CLUTTER, shape=SHAPE, resolution=RES))
    traj = W.rollout(
        sim,
        terrain,
        robot,
        ij.robots.start_stance(robot, x, y),
        np.asarray(COMMAND, np.float32),
        num_steps=STEPS,
        frames_per_step=FRAMES,
    )
    return sim, terrain, jax.tree_util.tree_map(np.asarray, traj)


@pytest.mark.slow
def test_a_g1_walk_renders_its_meshes_in_every_frame_with_its_feet_on_the_ground(walk):
    sim, terrain, traj = walk
    assert traj.taken.all() and not traj.log.fallen.any()  # the walk the picture shows
    q = render.states(traj)
    assert q.shape == (STEPS * FRAMES, sim.mj_model.nq)
    frames = render.render(sim, terrain, q, width=W_PX, height=H_PX, footsteps=traj.commanded, sides=traj.sides)
    assert frames.shape == (STEPS * FRAMES, H_PX, W_PX, 3) and frames.dtype == np.uint8
    assert all(len(np.unique(f.reshape(-1, 3) // 16, axis=0)) > 30 for f in frames)
    seg = render.render(sim, terrain, q, width=W_PX, height=H_PX, segmentation=True)
    meshes, _, hidden = _segments(sim, terrain)
    assert all(np.isin(s, meshes).sum() > 300 for s in seg) and not np.isin(seg, hidden).any()
    # the rendered robot stands where the physics had it: its lower sole on the ground (the clutter's walls are
    # never stepped on: the selector keeps the footholds off them)
    m = bodies.build_model(sim.params, terrain, meshes=True)
    d = mujoco.MjData(m)
    soles = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{side}_sole") for side in ("left", "right")]
    for state in q:
        d.qpos[:] = state
        mujoco.mj_kinematics(m, d)
        assert abs(d.site_xpos[soles, 2].min()) < GROUND_TOL, d.site_xpos[soles]


@pytest.mark.slow
def test_ijoy_sim_render_model_g1_writes_the_walk(walk, tmp_path, capsys):
    # the command line's walk is the fixture's (the same program: the persistent compilation cache holds it)
    gif, strip = tmp_path / "g1.gif", tmp_path / "g1.png"
    assert (
        cli.main(
            [
                "sim",
                "render",
                "--model",
                "g1",
                "--steps",
                str(STEPS),
                "--frames",
                str(FRAMES),
                "--size",
                f"{W_PX}x{H_PX}",
                "--out",
                str(gif),
                "--strip",
                str(strip),
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["frames"] == STEPS * FRAMES and summary["steps_taken"] == STEPS and not summary["fell"]
    with Image.open(gif) as g:
        assert g.n_frames == STEPS * FRAMES and g.size == (W_PX, H_PX)
        g.seek(g.n_frames - 1)
        assert len(np.unique(np.asarray(g.convert("RGB")).reshape(-1, 3) // 16, axis=0)) > 30
    with Image.open(strip) as s:
        assert s.size == (5 * W_PX, H_PX)
    _, _, traj = walk
    np.testing.assert_allclose(summary["distance_along"], W.summary(traj)["distance_along"], atol=1e-6)
