"""Offscreen images of a simulated rollout with MuJoCo's renderer (``mujoco.Renderer``).

Record states with ``walker.rollout(..., frames_per_step=F)`` (they land in
``traj.log.qpos``, (num_steps, F, nq)), then::

    frames = render.render(sim, terrain, render.states(traj), footsteps=traj.commanded)
    render.write_gif("walk.gif", frames, fps=F / sim.cfg.step_time)

On a Linux machine without a display, importing :mod:`ijoy_jax.sim` before
``mujoco`` selects EGL (``MUJOCO_GL=egl``, software rendering when there is
no GPU); set ``MUJOCO_GL`` yourself to choose otherwise.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from ijoy_jax.sim import bodies, hfield

LEFT_RGBA = (0.95, 0.75, 0.1, 0.6)  # commanded footholds of the left foot
RIGHT_RGBA = (0.1, 0.7, 0.95, 0.6)  # and of the right


def states(traj, index: int | None = None) -> np.ndarray:
    """(T, nq) the recorded states of a rollout in time order (``index`` picks one rollout of a batch)."""
    q = np.asarray(traj.log.qpos)
    if index is not None:
        q = q[index]
    if q.ndim != 3 or q.shape[1] == 0:
        raise ValueError(f"the trajectory holds no states (log.qpos has shape {q.shape}); roll out with "
                         "frames_per_step > 0 (and pick one rollout of a batch with index=)")
    return q.reshape(-1, q.shape[-1])


def _check_gl() -> None:
    """GLFW needs a display: headless, MuJoCo must have been imported with MUJOCO_GL=egl or osmesa."""
    from mujoco.rendering.classic import gl_context

    ctx = getattr(gl_context, "GLContext", None)
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and (
            ctx is None or ctx.__module__ == "mujoco.glfw"):
        raise RuntimeError("offscreen rendering without a display needs MUJOCO_GL=egl (or osmesa) set before mujoco "
                           "is imported; mujoco was imported with MUJOCO_GL="
                           f"{os.environ.get('MUJOCO_GL', '(unset)')}. Set it in the environment, or import "
                           "ijoy_jax.sim before mujoco")


def _add_looks(spec: mujoco.MjSpec) -> None:
    """A sky, a 0.5 m checker on the ground and MuJoCo's default headlight (looks only: the physics' model has
    neither sky nor checker). The same for every robot: the G1's own scene's white sky and bright headlight
    (MuJoCo Playground's) give way to them."""
    for sky in [t for t in spec.textures if t.type == mujoco.mjtTexture.mjTEXTURE_SKYBOX]:
        spec.delete(sky)
    light, default = spec.visual.headlight, mujoco.MjSpec().visual.headlight
    light.ambient, light.diffuse, light.specular = default.ambient, default.diffuse, default.specular
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[0.6, 0.75, 0.9], rgb2=[0.15, 0.17, 0.2], width=64, height=384)
    spec.add_texture(name="checker", type=mujoco.mjtTexture.mjTEXTURE_2D,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=[0.58, 0.62, 0.52], rgb2=[0.5, 0.54, 0.45],
                     width=64, height=64)
    mat = spec.add_material(name="ground", texrepeat=[1.0, 1.0], texuniform=True)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "checker"
    spec.geom("terrain").material = "ground"
    spec.geom("terrain").rgba = [1.0, 1.0, 1.0, 1.0]


def _host_model(sim, terrain, width: int, height: int) -> mujoco.MjModel:
    """The robot on ``terrain`` as :func:`ijoy_jax.sim.bodies.build_model` makes it, with its visual meshes (the
    G1's), :func:`_add_looks` and an offscreen buffer of at least ``width`` x ``height`` pixels."""
    m = bodies.build_model(sim.params, terrain, edit=_add_looks, meshes=True)
    m.vis.global_.offwidth = max(int(width), m.vis.global_.offwidth)
    m.vis.global_.offheight = max(int(height), m.vis.global_.offheight)
    return m


def _add_footprints(scene: mujoco.MjvScene, footsteps, sides, heights, length: float, width: float) -> None:
    for (x, y, yaw), side, z in zip(footsteps, sides, heights, strict=True):
        if scene.ngeom >= scene.maxgeom:
            return
        c, s = math.cos(yaw), math.sin(yaw)
        mat = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).ravel()
        rgba = np.array(LEFT_RGBA if side > 0 else RIGHT_RGBA, np.float32)
        mujoco.mjv_initGeom(scene.geoms[scene.ngeom], mujoco.mjtGeom.mjGEOM_BOX,
                            np.array([length / 2, width / 2, 0.002]), np.array([x, y, z + 0.004]), mat, rgba)
        scene.ngeom += 1


def render(sim, terrain, qpos, *, width: int = 480, height: int = 320, footsteps=None, sides=None,
           distance: float = 3.2, azimuth: float = 60.0, elevation: float = -20.0, track: bool = True,
           lookat=None, smooth: int = 9, segmentation: bool = False) -> np.ndarray:
    """Render states of the simulated robot on ``terrain`` (the G1 with its visual meshes, which its physics
    leaves out: :func:`ijoy_jax.sim.bodies.build_model`).

    Args:
      sim: the :class:`ijoy_jax.sim.walker.Sim` the states come from.
      terrain: the rollout's terrain (one, not a batch); 2D obstacles stand
        ``sim.params.obstacle_height`` tall, as in the physics.
      qpos: (T, nq) or (nq,) states (see :func:`states`).
      width, height: image size in pixels.
      footsteps: optional (N, 3) world poses (x, y, yaw) drawn as translucent
        soles on the ground (e.g. ``traj.commanded``); ``sides`` (N,) +1 left
        (yellow), -1 right (blue), alternating from the left by default.
      distance, azimuth, elevation: the camera (m, degrees), looking at the
        pelvis when ``track`` (its moving average over ``smooth`` frames, so
        the walking sway does not shake the view), else at ``lookat`` (3,) or
        the first frame's pelvis.
      segmentation: return (T, H, W) int32 geom ids per pixel (-1: none or a
        drawn footprint) instead of colours: the rendered model's
        (``bodies.build_model(sim.params, terrain, meshes=True)``), which are
        ``sim.mj_model``'s for the project's biped, not for the G1 (its
        meshes are geoms too).

    Returns:
      (T, H, W, 3) uint8 RGB frames, or (T, H, W) int32 geom ids.
    """
    _check_gl()
    qpos = np.asarray(qpos, np.float64)
    if qpos.ndim == 1:
        qpos = qpos[None]
    m = _host_model(sim, terrain, width, height)
    if qpos.ndim != 2 or qpos.shape[1] != m.nq:
        raise ValueError(f"qpos must have shape (T, {m.nq}) or ({m.nq},), got {qpos.shape}")
    if not np.all(np.isfinite(qpos)):
        raise ValueError("qpos holds NaN or inf")
    foot = None
    if footsteps is not None:
        foot = np.asarray(footsteps, np.float64).reshape(-1, 3)
        sides = np.where(np.arange(len(foot)) % 2 == 0, 1, -1) if sides is None else np.asarray(sides).ravel()
        if sides.shape != (len(foot),):
            raise ValueError(f"sides must have shape ({len(foot)},), got {sides.shape}")
        from ijoy_jax.sim import swing  # the sole's ground height, as the walker places it

        phys = terrain.replace(height=hfield.physical_heights(terrain, sim.params.obstacle_height), has_height=True)
        ground = np.asarray(jax.vmap(lambda p: swing.footprint_height(
            phys, p, sim.params.foot_length, sim.params.foot_width))(jnp.asarray(foot, jnp.float32)))
    pelvis = qpos[:, :3]
    if track:
        k = 2 * (max(int(smooth), 1) // 2) + 1
        pad = np.concatenate([np.repeat(pelvis[:1], k // 2, 0), pelvis, np.repeat(pelvis[-1:], k // 2, 0)])
        centre = np.stack([np.convolve(pad[:, i], np.ones(k) / k, mode="valid") for i in range(3)], axis=1)
    else:
        centre = np.broadcast_to(pelvis[0] if lookat is None else np.asarray(lookat, np.float64), pelvis.shape)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.distance, cam.azimuth, cam.elevation = distance, azimuth, elevation
    data = mujoco.MjData(m)
    out = []
    renderer = mujoco.Renderer(m, int(height), int(width))
    try:
        if segmentation:
            renderer.enable_segmentation_rendering()
        for q, c in zip(qpos, centre, strict=True):
            data.qpos[:] = q
            mujoco.mj_forward(m, data)
            cam.lookat[:] = [c[0], c[1], c[2] - 0.15]
            renderer.update_scene(data, camera=cam)
            if foot is not None:
                _add_footprints(renderer.scene, foot, sides, ground, sim.params.foot_length, sim.params.foot_width)
            img = renderer.render()
            if segmentation:  # (H, W, 2): object id, object type
                img = np.where(img[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), img[..., 0], -1).astype(np.int32)
            out.append(img.copy())
    finally:
        renderer.close()
    return np.stack(out)


def write_gif(path, frames: Sequence[np.ndarray] | np.ndarray, fps: float = 25.0) -> None:
    """Write (T, H, W, 3) uint8 frames as a looping GIF (Pillow)."""
    from PIL import Image

    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"frames must be (T, H, W, 3) uint8, got {frames.shape} {frames.dtype}")
    images = [Image.fromarray(f) for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=max(int(round(1000 / fps)), 20), loop=0)


def filmstrip(frames: np.ndarray, count: int = 5, columns: int | None = None) -> np.ndarray:
    """``count`` evenly spaced frames tiled into one image (``columns`` per row, all in one row by default)."""
    frames = np.asarray(frames)
    if frames.ndim != 4 or len(frames) == 0:
        raise ValueError(f"frames must be (T, H, W, C) with T >= 1, got {frames.shape}")
    count = max(1, min(int(count), len(frames)))
    pick = frames[np.round(np.linspace(0, len(frames) - 1, count)).astype(int)]
    columns = count if columns is None else max(1, int(columns))
    rows = -(-count // columns)
    pad = np.zeros((rows * columns - count, *frames.shape[1:]), frames.dtype)
    tiles = np.concatenate([pick, pad]).reshape(rows, columns, *frames.shape[1:])
    return np.concatenate([np.concatenate(list(row), axis=1) for row in tiles], axis=0)
