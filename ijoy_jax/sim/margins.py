"""Safety margin against collisions under execution error: the paper's finding, with a simulated robot.

The paper's perfect simulated robot walked through clutter with a 2 cm
safety margin; the real HRP-2 did not land its feet exactly where it was told
and needed 10 cm. :func:`run` walks the MJX biped through random clutter
(2D obstacles standing ``BipedParams.obstacle_height`` tall) with the same
terrains and commands at every margin, and counts what the physics reports:
steps during which a sole or shin touched an obstacle cell, footholds that
landed on one, falls, and the progress made. :func:`plot` draws the result.

    from ijoy_jax.sim import margins
    res = margins.run(margins=[0.0, 0.02, 0.05, 0.1], batch=64, num_steps=16)
    margins.plot(res, "margins.png")

``ijoy sim margins`` runs it from the command line (timings and results of the
paper's 11 margins on 256 maps: BENCHMARKS.md).
"""

from __future__ import annotations

import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import robots
from ijoy_jax.robots import command_range
from ijoy_jax.sim import walker as W
from ijoy_jax.terrain import generators

SHAPE = (200, 100)  # 4 m x 2 m at 2 cm
RESOLUTION = 0.02
MARGINS = tuple(round(0.01 * i, 2) for i in range(11))  # 0 to 10 cm
CLUTTER = generators.ObstacleParams(count=14, size_min=0.04, size_max=0.12)  # 2D: the physics raises them 0.1 m


def clutter(seed: int, batch: int, params: generators.ObstacleParams = CLUTTER, shape=SHAPE,
            resolution: float = RESOLUTION, max_count: int = 16, *, robot: robots.Robot | None = None):
    """``batch`` random 2D clutter maps (a Terrain with a leading batch axis) and each map's start (B, 2, 3).

    The robot (default HRP-2) starts in the generator's keep-clear zone, facing +x, its feet its step in place
    apart (:func:`ijoy_jax.robots.start_stance`; 0.19 m for HRP-2).
    """
    keys = jax.random.split(jax.random.key(seed), batch)
    terrains = jax.vmap(lambda k: generators.obstacles(k, params, shape=shape, resolution=resolution,
                                                       max_count=max_count))(keys)
    x0 = float(params.start_x) * shape[0] * resolution
    y0 = float(params.start_y) * shape[1] * resolution
    start = robots.start_stance(robots.hrp2() if robot is None else robot, x0, y0)
    return terrains, jnp.broadcast_to(start, (batch, 2, 3))


def forward_commands(seed: int, batch: int, robot=None) -> jax.Array:
    """(batch, 3) commands held per rollout: forward at 60-100 % of the fastest the action set realises,
    sideways and turning up to a fifth of theirs (m/s, m/s, rad/s; :func:`ijoy_jax.robots.command_range`)."""
    robot = robots.hrp2() if robot is None else robot
    _, top = command_range(robot)
    k_fwd, k_side = jax.random.split(jax.random.key(seed))
    fwd = jax.random.uniform(k_fwd, (batch, 1), jnp.float32, 0.6, 1.0) * top[0]
    side = jax.random.uniform(k_side, (batch, 2), jnp.float32, -0.2, 0.2) * jnp.asarray(top[1:], jnp.float32)
    return jnp.concatenate([fwd, side], axis=1)


def _stack(items):
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *items)


def run(margins=MARGINS, batch: int = 64, num_steps: int = 16, seed: int = 0, sim: W.Sim | None = None,
        method: str = "ordered", chunk: int | None = None, frames_per_step: int = 0) -> dict[str, Any]:
    """Walk ``batch`` robots through random clutter at every margin (the same maps and commands at each).

    Args:
      margins: safety margins to compare (m, each in [0, 0.10]: the HRP-2 preset's windows are sized for 10 cm).
      batch: clutter maps (and commands) per margin.
      num_steps: steps per rollout (static).
      seed: maps and commands.
      sim: a :class:`~ijoy_jax.sim.walker.Sim` for the 200 x 100 grid at 2 cm (built when None).
      method: the selector ("ordered" or "exhaustive": the same steps).
      chunk: rollouts per jitted call; equal chunks reuse one compile. Each rollout holds about 40 MB of
        selector windows, so the default is at most 512 on an accelerator and 32 on a CPU.
      frames_per_step: states kept per step for :mod:`ijoy_jax.sim.render` (static; 0: none).

    Returns:
      A dict of NumPy arrays, one entry per margin along axis 0 (and per map along axis 1 where it says so):
      ``margin`` (M,) m; ``contact`` (M, B) steps with a sole or shin touching an obstacle cell;
      ``on_obstacle`` (M, B) footholds measured on an obstacle cell; ``fell`` (M, B) bool;
      ``steps`` (M, B) steps taken; ``progress`` (M, B) m walked along the command;
      ``placement_error`` (M, B) mean touch-down error, m; and the summaries ``collision_rate`` (M,)
      (fraction of rollouts with any contact), ``contacts_per_step`` (M,), ``fall_rate`` (M,),
      ``mean_progress`` (M,) m, plus ``wall_s``, ``compiles`` (new compiles of the batched rollout),
      ``terrains``, ``starts``, ``commands`` (per map) and ``traj`` (the :class:`~ijoy_jax.control.Trajectory`
      with leading axes (M, B), e.g. to render a rollout that touched an obstacle).
    """
    margins = np.asarray(margins, np.float64).ravel().round(6)  # float32 0.1 > 0.1 would resize the windows
    if margins.size == 0 or np.any(~np.isfinite(margins)) or margins.min() < 0 or margins.max() > 0.10 + 1e-6:
        raise ValueError(f"margins must be finite and in [0, 0.10] m, got {margins}")
    if batch < 1 or num_steps < 1:
        raise ValueError(f"batch and num_steps must be positive, got {batch} and {num_steps}")
    robot0 = robots.hrp2()
    sim = W.make_sim(SHAPE, RESOLUTION, robot=robot0) if sim is None else sim
    terrains, starts = clutter(seed, batch)
    # One command per step, as a schedule: the batched rollout then has the shapes of any other schedule.
    commands = jnp.broadcast_to(forward_commands(seed + 1, batch, robot0)[:, None], (batch, num_steps, 3))
    m, b = len(margins), batch
    # Every (margin, map) pair: margin-major order.
    rep = lambda x: jnp.concatenate([x] * m)  # noqa: E731
    all_terrains = jax.tree_util.tree_map(rep, terrains)
    all_robots = _stack([robots.hrp2(margin=float(mg)) for mg in margins for _ in range(b)])
    all_starts, all_commands = rep(starts), rep(commands)
    total = m * b
    if chunk is None:
        chunk = 32 if jax.default_backend() == "cpu" else 512
    chunk = max(1, min(int(chunk), total))
    parts, t0 = [], time.perf_counter()
    before = W.compiled_programs()
    for lo in range(0, total, chunk):
        idx = np.arange(lo, lo + chunk) % total  # the last chunk wraps round to keep one shape (one compile)
        take = lambda x, idx=idx: x[idx]  # noqa: E731
        traj = W.rollout_batch(sim, jax.tree_util.tree_map(take, all_terrains),
                               jax.tree_util.tree_map(take, all_robots), all_starts[idx], all_commands[idx],
                               num_steps=num_steps, method=method, frames_per_step=frames_per_step)
        parts.append(jax.tree_util.tree_map(lambda a, n=min(chunk, total - lo): np.asarray(a)[:n], traj))
    wall = time.perf_counter() - t0
    traj = jax.tree_util.tree_map(lambda *a: np.concatenate(a), *parts)
    shape = lambda x: np.asarray(x).reshape(m, b, *np.shape(x)[1:])  # noqa: E731
    taken = shape(traj.taken)
    contact = shape(traj.log.obstacle_contact).sum(-1)
    steps = taken.sum(-1)
    err = np.where(taken, shape(traj.log.placement_error), 0.0).sum(-1) / np.maximum(steps, 1)
    out = dict(
        margin=margins,
        contact=contact,
        on_obstacle=shape(traj.on_obstacle).sum(-1),
        fell=shape(traj.log.fallen).any(-1),
        steps=steps,
        progress=shape(traj.along).sum(-1),
        placement_error=err,
    )
    out.update(
        collision_rate=(contact > 0).mean(1),
        contacts_per_step=contact.sum(1) / np.maximum(steps.sum(1), 1),
        fall_rate=out["fell"].mean(1),
        mean_progress=out["progress"].mean(1),
        wall_s=wall,
        compiles=W.compiled_programs() - before,
        terrains=terrains,
        starts=np.asarray(starts),
        commands=np.asarray(commands),
        traj=jax.tree_util.tree_map(shape, traj),
    )
    return out


def plot(result: dict[str, Any], path=None, ax=None):
    """Collision rate (rollouts with any contact) and falls against margin, progress on a second axis."""
    import matplotlib

    if path is not None and ax is None:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig = None
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 3.6))
    cm = 100 * np.asarray(result["margin"])
    b = np.asarray(result["contact"]).shape[1]
    rate = np.asarray(result["collision_rate"])
    err = 1.96 * np.sqrt(np.maximum(rate * (1 - rate), 1e-12) / b)
    ax.errorbar(cm, 100 * rate, yerr=100 * err, marker="o", capsize=3, label="rollouts touching an obstacle")
    ax.plot(cm, 100 * np.asarray(result["fall_rate"]), marker="x", ls="--", label="rollouts that fell")
    ax.set_xlabel("safety margin (cm)")
    ax.set_ylabel(f"% of {b} rollouts")
    ax.set_ylim(bottom=0)
    ax2 = ax.twinx()
    ax2.plot(cm, np.asarray(result["mean_progress"]), color="tab:green", marker=".", label="progress (m)")
    ax2.set_ylabel("mean progress along the command (m)", color="tab:green")
    ax2.set_ylim(bottom=0)
    lines = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
    ax.legend(lines, [ln.get_label() for ln in lines], fontsize=8, loc="upper right")
    ax.set_title("MJX biped in clutter: safety margin vs collisions")
    if fig is not None and path is not None:
        fig.tight_layout()
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return ax
