"""Drawings of the cue: its field in command space beside the terrain, the paper's scenarios, the study.

Host-side matplotlib (imported lazily); the field itself is computed by one jitted vmap of
:func:`ijoy_jax.cue.force_terms` over a grid of commands.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import plot as terrain_plot
from ijoy_jax.cue import field
from ijoy_jax.extras import require
from ijoy_jax.robots import Robot, side_sign
from ijoy_jax.terrain import Terrain

require("plot", "matplotlib", what="ijoy_jax.cue.plot")


@jax.jit
def _field_grid(feasible, commands, params):
    return jax.vmap(lambda c: field.force_terms(feasible, c, params))(commands)


def field_grid(feasible: field.FeasibleCommands, params: field.CueParams | None = None, *, turn_rate=0.0,
               num: int = 61, margin: float = 1.1) -> dict:
    """The cue on a grid of forward and sideways commands at one turn rate (NumPy arrays).

    Args:
      feasible: one stance's :func:`~ijoy_jax.cue.feasible_commands`.
      params: :class:`~ijoy_jax.cue.CueParams` (default: defaults).
      turn_rate: rad/s.
      num: grid points per axis.
      margin: the grid spans ``margin`` times the stick's full scale each way.

    Returns:
      ``{"xdot": (num,), "ydot": (num,), "force": (num, num, 3), "magnitude": (num, num)}`` indexed
      ``[i_ydot, i_xdot]`` (image order), m/s and fractions of the device's maximum force.
    """
    params = field.make_params() if params is None else params
    full = np.asarray(feasible.full_scale)
    xs = np.linspace(-margin * full[0], margin * full[0], num)
    ys = np.linspace(-margin * full[1], margin * full[1], num)
    gx, gy = np.meshgrid(xs, ys)
    cmds = np.stack([gx, gy, np.full_like(gx, float(turn_rate))], -1).reshape(-1, 3)
    out = _field_grid(feasible, jnp.asarray(cmds, jnp.float32), params)
    return {"xdot": xs, "ydot": ys, "force": np.asarray(out.force).reshape(num, num, 3),
            "magnitude": np.asarray(out.magnitude).reshape(num, num)}


def draw_field(ax, feasible: field.FeasibleCommands, params: field.CueParams | None = None, *, turn_rate=0.0,
               num: int = 61, arrows: int = 13, reach_directions: int = 72, colorbar: bool = True) -> None:
    """Draw the cue field in command space: force magnitude, force arrows, the actions, and the reach.

    Shading: the force's magnitude (fraction of the device's maximum) over forward (x) and sideways (y)
    commands at ``turn_rate``; arrows: its forward and sideways components; dots: the commands of the
    actions whose turn is nearest ``turn_rate`` (green valid, red blocked); dashed: :func:`~ijoy_jax.cue.reach`,
    the largest open speed per direction; grey box: the stick's full scale.
    """
    params = field.make_params() if params is None else params
    g = field_grid(feasible, params, turn_rate=turn_rate, num=num)
    xs, ys = g["xdot"], g["ydot"]
    im = ax.imshow(g["magnitude"], origin="lower", extent=(xs[0], xs[-1], ys[0], ys[-1]), cmap="Oranges",
                   vmin=0.0, vmax=max(float(params.c1), 1e-6), aspect="auto", interpolation="bilinear")
    if colorbar:
        ax.figure.colorbar(im, ax=ax, label="cue force (fraction of max)", shrink=0.85)
    step = max(1, num // arrows)
    sub = (slice(step // 2, None, step), slice(step // 2, None, step))
    f = g["force"][sub]
    gx, gy = np.meshgrid(xs[sub[1]], ys[sub[0]])
    live = np.hypot(f[..., 0], f[..., 1]) > 1e-3
    scale = 0.6 * (xs[-1] - xs[0]) / arrows
    ax.quiver(gx[live], gy[live], f[..., 0][live] * scale, f[..., 1][live] * scale, angles="xy",
              scale_units="xy", scale=1.0, color="0.15", width=0.004)
    cmds = np.asarray(feasible.commands)
    valid = np.asarray(feasible.valid)
    layer = np.abs(cmds[:, 2] - cmds[np.argmin(np.abs(cmds[:, 2] - float(turn_rate))), 2]) < 1e-6
    ax.plot(cmds[layer & valid, 0], cmds[layer & valid, 1], "o", color="tab:green", ms=3.5, label="open action")
    ax.plot(cmds[layer & ~valid, 0], cmds[layer & ~valid, 1], "x", color="tab:red", ms=4.5, mew=1.5,
            label="blocked action")
    r = np.asarray(field.reach(feasible, reach_directions, turn_rate=turn_rate))
    phi = 2 * np.pi * np.arange(reach_directions + 1) / reach_directions
    rr = np.append(r, r[0])
    ax.plot(rr * np.cos(phi), rr * np.sin(phi), "--", color="tab:blue", lw=1.5, label="reach")
    full = np.asarray(feasible.full_scale)
    ax.plot([-full[0], full[0], full[0], -full[0], -full[0]], [-full[1], -full[1], full[1], full[1], -full[1]],
            color="0.5", lw=1)
    ax.set_xlim(xs[0], xs[-1])
    ax.set_ylim(ys[0], ys[-1])
    ax.set_xlabel("forward command xdot (m/s)")
    ax.set_ylabel("sideways command ydot (m/s)")


def draw_stance(ax, terrain: Terrain, robot: Robot, stance, stance_side, feasible: field.FeasibleCommands, *,
                turn_rate=0.0, zoom: float = 0.7) -> None:
    """The terrain around a stance: the stance foot (filled), and the footholds of the actions whose turn is
    nearest ``turn_rate``, green where valid and red where blocked (the same actions as :func:`draw_field`)."""
    terrain_plot.draw_terrain(ax, terrain)
    stance = np.asarray(stance, np.float64)
    side = float(side_sign(stance_side))
    length, width = float(robot.foot_length), float(robot.foot_width)
    terrain_plot.draw_footsteps(ax, stance[None], [side], length, width, style=dict(fill=True, alpha=0.5))
    cmds = np.asarray(feasible.commands)
    layer = np.abs(cmds[:, 2] - cmds[np.argmin(np.abs(cmds[:, 2] - float(turn_rate))), 2]) < 1e-6
    from ijoy_jax.robots import action_steps

    steps = np.asarray(action_steps(robot, stance, stance_side))
    valid = np.asarray(feasible.valid)
    for ok, colour in ((True, "tab:green"), (False, "tab:red")):
        pick = layer & (valid == ok)
        ax.plot(steps[pick, 0], steps[pick, 1], ".", color=colour, ms=4)
    ax.set_xlim(stance[0] - zoom, stance[0] + zoom)
    ax.set_ylim(stance[1] - zoom, stance[1] + zoom)


def scenario_figure(cases, robot: Robot, params: field.CueParams | None = None, *, out: str | None = None):
    """One row per case: the terrain and stance (left), the cue field in command space (right).

    Args:
      cases: sequence of ``(title, terrain, stance (3,), stance_side, turn_rate)``.
      robot: the robot.
      params: the cue's parameters (default: defaults).
      out: PNG to write (optional).

    Returns:
      The matplotlib figure.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(cases), 2, figsize=(11, 4.6 * len(cases)), squeeze=False,
                             gridspec_kw=dict(width_ratios=[1, 1.25]))
    for row, (title, terrain, stance, side, turn) in zip(axes, cases, strict=True):
        feas = field.feasible_commands(terrain, robot, stance, side)
        draw_stance(row[0], terrain, robot, stance, side, feas, turn_rate=turn)
        row[0].set_title(f"{title}: stance and candidate footholds")
        draw_field(row[1], feas, params, turn_rate=turn)
        row[1].set_title(f"{title}: cue field at turn {turn:g} rad/s")
        row[1].legend(loc="lower left", fontsize=8, framealpha=0.9)
    fig.tight_layout()
    if out is not None:
        fig.savefig(out, dpi=100)
    return fig


def study_figure(result: dict, *, out: str | None = None, metrics=None):
    """:func:`ijoy_jax.cue.study.compare`'s means with 95% intervals (top row) and, when it has them, the paired
    differences from the baseline condition with theirs (bottom row), one column per metric."""
    import matplotlib.pyplot as plt

    from ijoy_jax.cue.study import METRICS, UNITS

    metrics = METRICS if metrics is None else metrics
    names = list(result["summary"])
    diffs = list(result.get("difference", {}))
    rows = 2 if diffs else 1
    fig, axes = plt.subplots(rows, len(metrics), figsize=(2.6 * len(metrics), 3.2 * rows), squeeze=False)
    colours = ["0.6", "tab:orange", "tab:green", "tab:purple", "tab:brown"]
    for k, m in enumerate(metrics):
        ax = axes[0, k]
        means = [result["summary"][c][m][0] for c in names]
        cis = [np.nan_to_num(result["summary"][c][m][1]) for c in names]
        ax.bar(range(len(names)), means, yerr=cis, capsize=4, color=colours[: len(names)])
        ax.set_xticks(range(len(names)), names, rotation=20)
        ax.set_title(f"{m}\n({UNITS[m]})", fontsize=9)
        if diffs:
            ax = axes[1, k]
            means = [result["difference"][c][m][0] for c in diffs]
            cis = [np.nan_to_num(result["difference"][c][m][1]) for c in diffs]
            ax.bar(range(len(diffs)), means, yerr=cis, capsize=4, color=colours[1: len(diffs) + 1])
            ax.axhline(0.0, color="k", lw=0.8)
            ax.set_xticks(range(len(diffs)), [f"{c} - {names[0]}" for c in diffs], rotation=20)
            ax.set_title(f"paired difference: {m}", fontsize=9)
    fig.suptitle(f"n = {result['n']} scenarios, the same for every condition (mean +- 95% CI)", fontsize=10)
    fig.tight_layout()
    if out is not None:
        fig.savefig(out, dpi=100)
    return fig


def paper_cases() -> list:
    """The paper's scenarios as ``scenario_figure`` cases (2 cm maps, HRP-2 sizes; right stance foot).

    * wall ahead: a wall across the way 0.22 m before the stance foot (forward steps beyond 5 cm blocked);
    * sidestep along a wall: a wall slanted 30 deg, 0.2 m ahead: forward blocked, sideways open;
    * clutter: the demo's scene (:func:`ijoy_jax.apps.demo` draws the same map): a box in the left foot's lane.
    """
    from ijoy_jax.terrain import flat, from_arrays, scene

    free = np.ones((100, 100), bool)
    free[56:, :] = False
    wall = from_arrays(None, free, 0.02)
    slanted = scene.rasterize(flat((100, 100), 0.02), boxes=[[1.25, 1.0, np.radians(30.0), 0.1, 3.0, 0.1]])
    clutter = scene.rasterize(flat((200, 120), 0.02), boxes=[[1.02, 1.30, 0.3, 0.06, 0.06, 0.1],
                                                              [1.62, 1.10, 0.0, 0.07, 0.09, 0.1]],
                              cylinders=[[1.32, 1.12, 0.03, 0.1]])
    return [("wall ahead", wall, [0.9, 1.0, 0.0], -1, 0.0),
            ("sidestep along a wall", slanted, [0.95, 1.0, 0.0], -1, 0.0),
            ("clutter", clutter, [0.82, 1.105, 0.0], -1, 0.0)]
