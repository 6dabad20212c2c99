"""The demo: an intelligent and a naive joystick walking HRP-2 through clutter (paper Fig. 3)."""

from __future__ import annotations

import time

import numpy as np

import ijoy_jax as ij


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


def run(out: str = "ijoy_demo.png", num_steps: int = 24, margin: float = 0.02) -> dict:
    """Run both joysticks on :func:`demo_scene`, write a PNG to ``out``, return their summaries."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    terrain = demo_scene()
    robot = ij.robots.hrp2(margin=margin)
    start = ij.robots.start_stance(robot, 0.3, 1.2)  # left, right: 0.19 m apart, facing +x
    command = np.array([0.25, 0.0, 0.0])  # forward at full speed (m/s, m/s, rad/s)
    t0 = time.perf_counter()
    smart = ij.rollout(terrain, robot, start, command, num_steps)
    naive = ij.rollout(terrain, robot, start, command, num_steps, method="naive")
    seconds = time.perf_counter() - t0
    fig, axes = plt.subplots(2, 1, figsize=(10, 9), sharex=True)
    length, width = float(robot.foot_length), float(robot.foot_width)
    for ax, traj, name in ((axes[0], naive, "naive joystick"), (axes[1], smart, "intelligent joystick")):
        ij.plot.draw_terrain(ax, terrain)
        ij.plot.draw_footsteps(ax, start, [1, -1], length, width, style=dict(fill=True, alpha=0.3))
        ij.plot.draw_footsteps(ax, traj.footsteps, traj.sides, length, width, mask=traj.taken,
                               bad=np.asarray(traj.on_obstacle))
        s = {k: float(v) for k, v in traj.summary().items()}
        ax.set_title(f"{name}: {int(s['steps_taken'])} steps, {int(s['footholds_on_obstacles'])} on obstacles, "
                     f"{int(s['steps_in_place'])} in place, {s['distance_along']:.2f} m forward")
    axes[1].text(0.01, 0.02, f"HRP-2, margin {margin * 100:.0f} cm, command forward 0.25 m/s; "
                 "blue = left, red = right, x = foot on an obstacle", transform=axes[1].transAxes, fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return {"intelligent": {k: float(v) for k, v in smart.summary().items()},
            "naive": {k: float(v) for k, v in naive.summary().items()},
            "seconds": seconds, "png": out}
