"""``ijoy sim render``: the MJX biped (or the Unitree G1, ``--model g1``) walking through clutter, written as a GIF
(physics sweeps run with ``ijoy sweep run`` on a file with ``walker = "mjx"``).

Kept here so that :mod:`ijoy_jax.apps.cli` only registers the subcommand (:func:`add_parser`) and dispatches
to :func:`main`.
"""

from __future__ import annotations

import json

from ijoy_jax.apps.options import image_size, output_file, positive_int
from ijoy_jax.robots import MODELS

# ``ijoy sim render``'s map: sweeps/margin_physics.toml's clutter (4 x 2 m at 2 cm, 14 obstacles of 4-12 cm).
_RENDER_SHAPE, _RENDER_RESOLUTION = (200, 100), 0.02
_RENDER_CLUTTER = dict(count=14, size_min=0.04, size_max=0.12)
_RENDER_COMMAND = (0.2, 0.0, 0.0)  # m/s, m/s, rad/s: forward at 80 % of the top speed


def add_parser(sub) -> None:
    """Register ``sim`` (with ``render``) on an argparse subparsers object."""
    simp = sub.add_parser(
        "sim",
        help="the MJX biped: a rendered rollout (physics sweeps: 'ijoy sweep run' with "
        'walker = "mjx", e.g. sweeps/margin_physics.toml)',
        description="The simulated biped (MuJoCo XLA): a rendered walk through clutter. Physics "
        "sweeps run with 'ijoy sweep run' on a file with walker = \"mjx\", e.g. "
        "sweeps/margin_physics.toml.",
    )
    sim_sub = simp.add_subparsers(dest="sim_command", required=True)
    rend = sim_sub.add_parser(
        "render",
        help="walk the simulated biped through clutter and write a GIF (offscreen; headless Linux uses EGL)",
        description="Walk the MJX biped (--model g1: the Unitree G1, with its visual meshes; the robots "
        "extra) forward at 0.2 m/s through a 4 x 2 m clutter map "
        "(sweeps/margin_physics.toml's) with the intelligent joystick and write "
        "the walk as a GIF (offscreen; headless Linux uses EGL), optionally a "
        "filmstrip PNG; prints the walk's summary as JSON. Compiling the walk "
        "takes about a minute on a CPU (stderr says what compiles and for how "
        "long; seconds once the compilation cache holds it).",
    )
    rend.add_argument("--out", default="ijoy_walk.gif", type=output_file, help="GIF to write (default: %(default)s)")
    rend.add_argument("--strip", default=None, type=output_file, help="also write a filmstrip PNG of 5 frames")
    rend.add_argument("--steps", type=positive_int, default=12, help="steps to walk (default: %(default)s)")
    rend.add_argument("--frames", type=positive_int, default=10, help="frames per 0.8 s step (default: %(default)s)")
    rend.add_argument(
        "--model",
        choices=MODELS,
        default="biped",
        help="the robot: the project's HRP-2-like biped or the Unitree G1 (its selector robot robots.g1) "
        "(default: %(default)s)",
    )
    rend.add_argument("--margin", type=float, default=0.02, help="safety margin in metres (default: %(default)s)")
    rend.add_argument("--seed", type=int, default=0, help="clutter map (default: %(default)s)")
    rend.add_argument(
        "--size", default="480x320", type=image_size, help="WIDTHxHEIGHT in pixels (default: %(default)s)"
    )


def main(args) -> int:
    """``ijoy sim render``: the simulated biped through one clutter map, as a GIF."""
    import jax
    import numpy as np

    from ijoy_jax import robots
    from ijoy_jax.sim import render
    from ijoy_jax.sim import walker as W
    from ijoy_jax.terrain import generators

    width, height = args.size  # (pixels, pixels), checked as parsed
    robot = robots.for_model(args.model, margin=args.margin)
    sim = W.make_sim(_RENDER_SHAPE, _RENDER_RESOLUTION, robot=robot, model=args.model)
    params = generators.ObstacleParams(**_RENDER_CLUTTER)
    terrain = generators.obstacles(
        jax.random.key(args.seed), params, shape=_RENDER_SHAPE, resolution=_RENDER_RESOLUTION, max_count=16
    )
    x, y = np.asarray(generators.start_point(params, shape=_RENDER_SHAPE, resolution=_RENDER_RESOLUTION))
    start = robots.start_stance(robot, x, y)
    traj = W.rollout(
        sim,
        terrain,
        robot,
        start,
        np.asarray(_RENDER_COMMAND, np.float32),
        num_steps=args.steps,
        frames_per_step=args.frames,
        progress=True,
    )
    frames = render.render(
        sim,
        terrain,
        render.states(traj),
        width=width,
        height=height,
        footsteps=traj.commanded,
        sides=traj.sides,
        smooth=args.frames,
    )
    render.write_gif(args.out, frames, fps=args.frames / sim.cfg.step_time)
    if args.strip:
        from PIL import Image

        Image.fromarray(render.filmstrip(frames, 5)).save(args.strip)
    summary = {k: np.asarray(v).tolist() for k, v in W.summary(traj).items()}
    print(json.dumps(dict(gif=args.out, strip=args.strip, frames=len(frames), **summary)))
    return 0
