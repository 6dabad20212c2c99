"""The demo: an intelligent and a naive joystick walking HRP-2 through clutter (paper Fig. 3)."""

from __future__ import annotations

import time

import numpy as np

import ijoy_jax as ij
from ijoy_jax.extras import require
from ijoy_jax.progress import compiling


def demo_scene() -> ij.Terrain:
    """A 4 m x 2.4 m, 2 cm occupancy grid: small obstacles in the feet's lanes and a wall at the far end."""
    t = ij.terrain.flat((200, 120), 0.02)
    boxes = np.array([
        # x, y, yaw, length, width, top  (metres, radians)
        [1.02, 1.30, 0.3, 0.06, 0.06, 0.1],
        [1.62, 1.10, 0.0, 0.07, 0.09, 0.1],
        [2.25, 1.28, 0.6, 0.12, 0.05, 0.1],
        [3.75, 1.20, 0.0, 0.10, 2.40, 0.1],  # wall: the robot walks up to it and steps in place
    ])
    cylinders = np.array([[1.32, 1.12, 0.03, 0.1], [2.70, 1.10, 0.035, 0.1], [3.10, 1.32, 0.03, 0.1]])
    return ij.terrain.scene.rasterize(t, boxes=boxes, cylinders=cylinders)


def plain(summary: dict) -> dict:
    """A :meth:`ijoy_jax.Trajectory.summary` of one rollout as Python numbers: ints for counts, bool, floats."""
    out = {}
    for k, v in summary.items():
        v = np.asarray(v)
        out[k] = bool(v) if v.dtype == bool else int(v) if np.issubdtype(v.dtype, np.integer) else float(v)
    return out


def run(out: str = "ijoy_demo.png", num_steps: int = 24, margin: float = 0.02) -> dict:
    """Run both joysticks on :func:`demo_scene`, write a PNG to ``out``, return their summaries.

    Raises ValueError for a negative margin or fewer than one step (before any compute), MissingExtraError
    without matplotlib.
    """
    require("plot", "matplotlib", what="ijoy demo")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if not num_steps >= 1:
        raise ValueError(f"num_steps must be at least 1, got {num_steps}")
    if not margin >= 0:  # also rejects NaN
        raise ValueError(f"margin must be >= 0 metres, got {margin}")
    terrain = demo_scene()
    robot = ij.robots.hrp2(margin=margin)
    start = ij.robots.start_stance(robot, 0.3, 1.2)  # left, right: 0.19 m apart, facing +x
    command = np.array([0.25, 0.0, 0.0])  # forward at full speed (m/s, m/s, rad/s)
    t0 = time.perf_counter()
    what = f"the two rollouts ({num_steps} steps, the intelligent and the naive joystick)"
    with compiling(what, prefix="ijoy demo: "):
        smart = ij.rollout(terrain, robot, start, command, num_steps)  # the compile; each runs in milliseconds
        naive = ij.rollout(terrain, robot, start, command, num_steps, ij.SelectOptions(method="naive"))
    seconds = time.perf_counter() - t0
    fig, axes = plt.subplots(2, 1, figsize=(10, 9), sharex=True)
    length, width = float(robot.foot_length), float(robot.foot_width)
    legend = [Patch(facecolor="none", edgecolor="tab:blue", lw=1.5, label="left foot"),
              Patch(facecolor="none", edgecolor="tab:red", lw=1.5, label="right foot"),
              Patch(facecolor="0.5", alpha=0.3, label="start stance"),
              Line2D([], [], color="k", marker="x", ls="none", ms=8, mew=2, label="foothold on an obstacle"),
              Patch(facecolor="0.3", label="obstacle")]
    for ax, traj, name in ((axes[0], naive, "naive joystick"), (axes[1], smart, "intelligent joystick")):
        ij.plot.draw_terrain(ax, terrain)
        ij.plot.draw_footsteps(ax, start, [1, -1], length, width, style=dict(fill=True, alpha=0.3))
        ij.plot.draw_footsteps(ax, traj.footsteps, traj.sides, length, width, mask=traj.taken,
                               bad=np.asarray(traj.on_obstacle))
        s = plain(traj.summary())
        ax.set_title(f"{name}: {s['steps_taken']} steps, {s['footholds_on_obstacles']} on obstacles, "
                     f"{s['steps_in_place']} in place, {s['distance_along']:.2f} m forward")
        ax.legend(handles=legend, loc="lower left", fontsize=8, ncol=5, framealpha=0.9)
    fig.suptitle(f"HRP-2 walking forward at 0.25 m/s, safety margin {margin * 100:g} cm: "
                 "naive joystick (top) and intelligent joystick (bottom)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return {"intelligent": plain(smart.summary()), "naive": plain(naive.summary()), "seconds": seconds, "png": out}
