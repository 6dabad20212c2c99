"""Benchmark the biped's physics: ``ijoy bench sim [--quick]`` (JSON lines, one per measurement).

``mjx_physics``: MuJoCo XLA steps of the biped standing under position
control on its own random height field (one per robot, 2 cm cells, 5 mm
bumps, so every sole sphere is in contact), ``jax.vmap`` over B robots and a
jitted ``lax.scan`` over K physics steps: compile time, then physics steps
per second (B * K / wall time) for each batch size B, on JAX's default
device. ``cpu_rollout``: the same model (one height field), stepped by
multi-threaded C MuJoCo (``mujoco.rollout``, one thread per core), as the
reference. ``closed_loop``: the whole joystick loop (selector, walking
controller with its dynamics filter, physics) for B robots on flat ground,
each with its own random command per step inside the action set's range:
compile time, physics steps/s of the loop (B * steps * physics steps per
walking step / wall time), falls and placement error. Run it on one GPU
through the device tool for the MJX figures.
"""

from __future__ import annotations

import json
import os
import platform
import time

import ijoy_jax.sim  # noqa: F401  before mujoco: headless EGL, and mjx imported without the warp lines

# isort: split
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax import lax
from mujoco import mjx

from ijoy_jax import robots, terrain
from ijoy_jax.sim import hfield, model
from ijoy_jax.terrain import Terrain

SHAPE = (100, 100)
RESOLUTION = 0.02
BUMPS = 0.005


def _terrains(key, batch: int) -> Terrain:
    heights = BUMPS * jax.random.uniform(key, (batch, *SHAPE), jnp.float32)
    return Terrain(height=heights, free=jnp.ones((batch, *SHAPE), bool),
                   origin=jnp.broadcast_to(jnp.float32(-1.0), (batch, 2)), resolution=RESOLUTION, has_height=True)


def _setup(params: model.BipedParams):
    mj_model = model.build_model(params, terrain.flat(SHAPE, RESOLUTION, origin=(-1.0, -1.0), has_height=True))
    qpos = model.standing_qpos(params, ground=(BUMPS, BUMPS))
    return mj_model, qpos


def mjx_physics(batch: int, steps: int, params: model.BipedParams | None = None, seed: int = 0) -> dict:
    """Compile time and physics steps/s of ``batch`` robots for ``steps`` MJX steps."""
    params = model.biped_params() if params is None else params
    mj_model, qpos = _setup(params)
    m = model.put_model(mj_model)
    batched, axes = hfield.put_terrains(m, params, _terrains(jax.random.key(seed), batch))
    d0 = mjx.make_data(m).replace(qpos=jnp.asarray(qpos, jnp.float32), ctrl=jnp.asarray(qpos[7:], jnp.float32))
    data = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (batch, *x.shape)), d0)

    def run(m, d):
        def body(d, _):
            return mjx.step(m, d), None

        return lax.scan(body, d, None, length=steps)[0]

    fn = jax.jit(jax.vmap(run, in_axes=(axes, 0)))
    t0 = time.perf_counter()
    compiled = fn.lower(batched, data).compile()
    compile_s = time.perf_counter() - t0
    out = compiled(batched, data)
    jax.block_until_ready(out)  # warm
    t0 = time.perf_counter()
    out = compiled(batched, out)
    jax.block_until_ready(out)
    wall = time.perf_counter() - t0
    height = np.asarray(out.qpos[:, 2])
    return dict(name="mjx_physics", batch=batch, steps=steps, compile_s=round(compile_s, 2), wall_s=round(wall, 4),
                steps_per_s=batch * steps / wall, standing=float(np.mean(height > 0.6)),
                device=str(jax.devices()[0].device_kind), jax=jax.__version__, mujoco=mujoco.__version__)


def cpu_rollout(batch: int, steps: int, params: model.BipedParams | None = None, threads: int | None = None) -> dict:
    """Physics steps/s of C MuJoCo (``mujoco.rollout``) over ``batch`` robots on ``threads`` threads."""
    from mujoco import rollout

    params = model.biped_params() if params is None else params
    mj_model, qpos = _setup(params)
    threads = threads or os.cpu_count() or 1
    data = mujoco.MjData(mj_model)
    data.qpos[:] = qpos
    data.ctrl[:] = qpos[7:]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.zeros(mujoco.mj_stateSize(mj_model, spec))
    mujoco.mj_getState(mj_model, data, state, spec)
    init = np.tile(state, (batch, 1))
    control = np.tile(qpos[7:], (batch, steps, 1))
    datas = [mujoco.MjData(mj_model) for _ in range(threads)]
    rollout.rollout(mj_model, datas, init[:threads], control[:threads, :2])  # warm the pool
    t0 = time.perf_counter()
    out, _ = rollout.rollout(mj_model, datas, init, control)
    wall = time.perf_counter() - t0
    return dict(name="cpu_rollout", batch=batch, steps=steps, threads=threads, wall_s=round(wall, 4),
                steps_per_s=batch * steps / wall, cpu=platform.processor() or platform.machine(),
                mujoco=mujoco.__version__, final_ok=bool(np.all(np.isfinite(out[:, -1]))))


def closed_loop(batch: int, num_steps: int, seed: int = 0, shape=(300, 300), resolution: float = 0.04,
                params: model.BipedParams | None = None, cfg=None, hold: int = 1) -> dict:
    """The joystick loop with the MJX biped for ``batch`` robots with random commands on flat ground.

    The ground is ``shape`` cells of ``resolution`` m (12 m square by
    default, room for 30 steps any way), centred on the start. Returns compile
    time, wall time of the run, physics steps/s of the loop, the number of
    robots that fell, and the placement error (mean and 95th percentile over
    all steps taken, m). Each random command is held for ``hold`` steps
    (:func:`ijoy_jax.robots.random_commands`).
    """
    from ijoy_jax.sim import walker

    robot = robots.hrp2()
    sim = walker.make_sim(shape, resolution, params, cfg, robot=robot)
    origin = (-0.5 * shape[0] * resolution, -0.5 * shape[1] * resolution)
    ground = terrain.flat(shape, resolution, origin=origin, has_height=True)
    start = robots.start_stance(robot, 0.0, 0.0)
    commands = robots.random_commands(jax.random.key(seed), robot, batch, num_steps, hold)

    def one(cmd):
        return walker.rollout(sim, ground, robot, start, cmd, num_steps=num_steps)

    fn = jax.jit(jax.vmap(one))
    t0 = time.perf_counter()
    compiled = fn.lower(commands).compile()
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    traj = compiled(commands)
    jax.block_until_ready(traj)
    wall = time.perf_counter() - t0
    sub = sim.substeps * sim.cfg.ticks_per_step  # physics steps per walking step
    physics = batch * (num_steps + 1) * sub  # + the standing step that starts every rollout
    taken = np.asarray(traj.taken)
    err = np.asarray(traj.log.placement_error)[taken]
    fell = np.asarray(traj.log.fallen).any(axis=1)
    return dict(name="closed_loop", batch=batch, num_steps=num_steps, hold=hold, compile_s=round(compile_s, 2),
                wall_s=round(wall, 3), physics_steps_per_s=physics / wall, walking_steps_per_s=batch * num_steps / wall,
                fell=int(fell.sum()), steps_taken=int(taken.sum()),
                placement_error_mean=float(err.mean()) if err.size else 0.0,
                placement_error_p95=float(np.percentile(err, 95)) if err.size else 0.0,
                obstacle_contacts=int(np.asarray(traj.log.obstacle_contact).sum()),
                device=str(jax.devices()[0].device_kind), jax=jax.__version__, mujoco=mujoco.__version__)


def run(quick: bool = False) -> list[dict]:
    """The benchmark rows: MJX physics at several batch sizes, the CPU reference, then the closed loop (30 steps)."""
    if quick:
        return [mjx_physics(4, 10), cpu_rollout(8, 50, threads=2)]
    on_gpu = jax.default_backend() != "cpu"
    batches = (1024, 4096, 16384, 32768) if on_gpu else (16, 64)
    rows = [mjx_physics(b, 200 if on_gpu else 50) for b in batches]
    rows.append(cpu_rollout(1024 if on_gpu else 64, 1000 if on_gpu else 200))
    rows += [closed_loop(b, 30) for b in ((1024, 4096) if on_gpu else (4,))]
    return rows


def report(args) -> list[dict]:
    """``ijoy bench sim`` from parsed options: :func:`run`'s rows, each printed as a JSON line."""
    rows = []
    for row in run(quick=args.quick):
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows
