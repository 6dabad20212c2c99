"""The ``ijoy`` command line.

Every command keeps JAX's compiled programs in a persistent cache on disk (JAX's compilation cache), so a
second run of the same sweep, benchmark or tuning run loads its programs instead of compiling them (an MJX
sweep's ~1 minute of compiles becomes seconds). The cache lives in :func:`compile_cache_dir` (``$IJOY_CACHE_DIR``,
else ``$JAX_COMPILATION_CACHE_DIR``, else ``$XDG_CACHE_HOME/ijoy_jax/jax_compilation_cache``, by default
``~/.cache/ijoy_jax/jax_compilation_cache``); ``ijoy --no-compile-cache ...`` or ``IJOY_COMPILE_CACHE=0`` turns it
off. Entries are keyed by the program, the JAX/XLA versions, flags and devices, so a hit runs the same code; the
folder may be deleted at any time.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

CACHE_MIN_COMPILE_S = 0.1
"""Programs that took at least this long to compile (s) are kept in the persistent cache (tiny eager ops are not)."""


def compile_cache_dir(env=None) -> Path | None:
    """The persistent compilation cache's folder for this environment, or None where it is switched off
    (``IJOY_COMPILE_CACHE`` = 0, false, no or off). See the module docstring for the order of the variables."""
    env = os.environ if env is None else env
    if env.get("IJOY_COMPILE_CACHE", "").strip().lower() in ("0", "false", "no", "off"):
        return None
    for var in ("IJOY_CACHE_DIR", "JAX_COMPILATION_CACHE_DIR"):
        if env.get(var):
            return Path(env[var]).expanduser()
    base = Path(env["XDG_CACHE_HOME"]).expanduser() if env.get("XDG_CACHE_HOME") else Path.home() / ".cache"
    return base / "ijoy_jax" / "jax_compilation_cache"


def _use_compile_cache(enabled: bool) -> Path | None:
    """Point JAX's persistent compilation cache at :func:`compile_cache_dir` (before any compile); its folder."""
    path = compile_cache_dir() if enabled else None
    if path is None:
        return None
    import jax

    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:  # a read-only home: run without the cache rather than not at all
        print(f"ijoy: warning: no compilation cache ({path}: {e.strerror})", file=sys.stderr)
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", CACHE_MIN_COMPILE_S)
    return path


def main(argv: list[str] | None = None) -> int:
    import jax

    from ijoy_jax import __version__
    from ijoy_jax.apps.options import CommandParser, image_size, output_file, output_folder, positive_int
    from ijoy_jax.extras import MissingExtraError

    parser = CommandParser(prog="ijoy", description="The intelligent joystick for legged robots, in JAX.",
                           epilog="Outputs: a command that writes one file writes ijoy_<what>.<ext> in the current "
                                  "folder unless --out names another; one that writes a folder of results writes "
                                  "results/<name>/. Every output is checked (its folder exists and is writable) "
                                  "before any work starts.")
    parser.add_argument("--version", action="version", help="print the version (and JAX's, Python's) and exit",
                        version=f"ijoy {__version__} (jax {jax.__version__}, Python {sys.version.split()[0]})")
    parser.add_argument("--no-compile-cache", action="store_true",
                        help="do not keep compiled programs on disk (env IJOY_COMPILE_CACHE=0); by default they are "
                             "kept in $IJOY_CACHE_DIR, $JAX_COMPILATION_CACHE_DIR or "
                             "~/.cache/ijoy_jax/jax_compilation_cache, so a second run compiles nothing")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="walk HRP-2 through clutter with the intelligent and a naive joystick; "
                                       "write a PNG of the footholds",
                          description="The paper's Fig. 3: HRP-2 walks forward at 0.25 m/s through a 4 x 2.4 m "
                                      "cluttered map, once with the intelligent joystick and once with a naive one "
                                      "(the lattice step nearest the command). Prints both walks' summaries as "
                                      "JSON and draws their footholds in one PNG.")
    demo.add_argument("--out", default="ijoy_demo.png", type=output_file, help="PNG to write (default: %(default)s)")
    demo.add_argument("--steps", type=int, default=24, help="number of steps (default: %(default)s)")
    demo.add_argument("--margin", type=float, default=0.02, help="safety margin in metres (default: %(default)s)")
    _add_bench_parser(sub)
    sweep = sub.add_parser("sweep", help="run a sweep declared in TOML, or summarise a finished one",
                           description="Sweeps over robot/selector parameters, terrains and commands "
                                       "(schema: ijoy_jax/sweep/config.py; examples in sweeps/).")
    sweep_sub = sweep.add_subparsers(dest="sweep_command", required=True)
    srun = sweep_sub.add_parser("run", help="run or resume a sweep; results as parquet parts in --out",
                                description="Run a sweep file's scenarios (or a slice of them) in resumable chunks "
                                            "on every local device: parquet parts, a manifest and aggregates in "
                                            "--out. A folder of the same sweep is resumed or extended; another "
                                            "sweep's is refused.")
    srun.add_argument("file", help="sweep file (TOML), e.g. sweeps/w_sweep.toml")
    srun.add_argument("--out", default=None, type=output_folder,
                      help="output folder; an existing one from the same file and options is resumed "
                           "(default: results/<sweep name>)")
    srun.add_argument("--chunk", type=int, default=None,
                      help="scenarios per jitted call; memory grows with it (default: the folder's when resuming, "
                           "else 32 on CPU and sized to device memory on a GPU)")
    srun.add_argument("--scenarios-per-cell", type=int, default=None, metavar="N",
                      help="a quick, even slice of the sweep: only the first N scenarios (replicates) of every "
                           "cell; the folder is marked incomplete, and a later run into the same --out with a "
                           "larger N, or without it, computes only the scenarios missing")
    srun.add_argument("--max-scenarios", type=int, default=None, metavar="N",
                      help="only the first N scenario ids, cell after cell (a check of the program: fewer than a "
                           "cell's scenarios cover the first cell alone; for a small sweep over every cell use "
                           "--scenarios-per-cell); extended like it by a later run")
    srun.add_argument("--devices", type=int, default=None,
                      help="split each chunk over the first N local devices, each running the one-device "
                           "program (default: all of them)")
    srun.add_argument("--num-processes", type=int, default=None,
                      help="several processes/hosts: how many run this sweep into the same shared --out "
                           "(env IJOY_NUM_PROCESSES; default 1); each runs chunks with chunk %% N == its id")
    srun.add_argument("--process-id", type=int, default=None,
                      help="this process's id in [0, N) (env IJOY_PROCESS_ID); process 0 hosts the coordinator")
    srun.add_argument("--coordinator", default=None,
                      help="HOST:PORT of process 0's jax.distributed coordinator, reachable from every process "
                           "(env IJOY_COORDINATOR)")
    srun.add_argument("--barrier-timeout", type=float, default=3600.0, metavar="S",
                      help="several processes: how long a finished process waits for the others before process 0 "
                           "writes the aggregates (seconds; default 3600); a dead process relaunched within it "
                           "rejoins the run")
    srun.add_argument("--local-processes", type=int, default=None, metavar="N",
                      help="run as N processes on this machine, one GPU each (the first N of CUDA_VISIBLE_DEVICES, "
                           "else 0..N-1), coordinated on localhost; for several GPUs of one host, the faster "
                           "layout for short chunks (sweeps/README.md)")
    srun.add_argument("--distributed", action="store_true",
                      help="call jax.distributed.initialize and let JAX detect unset values from the cluster "
                           "(SLURM, Open MPI, ...; env IJOY_DISTRIBUTED=1); see sweeps/README.md")
    ssum = sweep_sub.add_parser("summarize", help="print per-cell means with 95%% CIs and write a plot PNG",
                                description="Print a sweep folder's per-cell means with 95%% confidence intervals "
                                            "and plot them (summary.png; --tradeoff: a safety metric against "
                                            "its price, tradeoff.png).")
    ssum.add_argument("dir", help="a sweep's output folder")
    ssum.add_argument("--png", default=None, type=output_file, help="plot to write (default: DIR/summary.png)")
    ssum.add_argument("--x", default=None, help="parameter on the plot's x axis (default: the most varied)")
    ssum.add_argument("--tradeoff", nargs="?", const="fell,distance_along", default=None, metavar="Y,X",
                      help="also write DIR/tradeoff.png: one point per cell, metric Y (safety) against metric X "
                           "(its price; default fell,distance_along: falls against progress)")
    ssum.add_argument("--metrics", default=None,
                      help="comma-separated metrics, one panel each (default: the table's columns, in its order; "
                           "for a physics sweep falls and collisions beside progress)")
    simp = sub.add_parser("sim", help="the MJX biped: a rendered rollout (physics sweeps: 'ijoy sweep run' with "
                                      "walker = \"mjx\", e.g. sweeps/margin_physics.toml)",
                          description="The simulated biped (MuJoCo XLA): a rendered walk through clutter. Physics "
                                      "sweeps run with 'ijoy sweep run' on a file with walker = \"mjx\", e.g. "
                                      "sweeps/margin_physics.toml.")
    sim_sub = simp.add_subparsers(dest="sim_command", required=True)
    rend = sim_sub.add_parser("render", help="walk the simulated biped through clutter and write a GIF "
                                             "(offscreen; headless Linux uses EGL)",
                              description="Walk the MJX biped forward at 0.2 m/s through a 4 x 2 m clutter map "
                                          "(sweeps/margin_physics.toml's) with the intelligent joystick and write "
                                          "the walk as a GIF (offscreen; headless Linux uses EGL), optionally a "
                                          "filmstrip PNG; prints the walk's summary as JSON. Compiling the walk "
                                          "takes about a minute on a CPU (stderr says what compiles and for how "
                                          "long; seconds once the compilation cache holds it).")
    rend.add_argument("--out", default="ijoy_walk.gif", type=output_file, help="GIF to write (default: %(default)s)")
    rend.add_argument("--strip", default=None, type=output_file, help="also write a filmstrip PNG of 5 frames")
    rend.add_argument("--steps", type=positive_int, default=12, help="steps to walk (default: %(default)s)")
    rend.add_argument("--frames", type=positive_int, default=10, help="frames per 0.8 s step (default: %(default)s)")
    rend.add_argument("--margin", type=float, default=0.02, help="safety margin in metres (default: %(default)s)")
    rend.add_argument("--seed", type=int, default=0, help="clutter map (default: %(default)s)")
    rend.add_argument("--size", default="480x320", type=image_size,
                      help="WIDTHxHEIGHT in pixels (default: %(default)s)")
    from ijoy_jax.apps import cue_cli, drive_cli, serve_cli, tune_cli

    tune_cli.add_parser(sub)
    cue_cli.add_parser(sub)
    serve_cli.add_parser(sub)
    drive_cli.add_parser(sub)
    try:
        args = parser.parse_args(argv)  # a refused command line raises UsageError, a ValueError
        _use_compile_cache(not args.no_compile_cache)
        return _run(args)
    except (ValueError, TypeError, OSError, MissingExtraError) as e:  # bad input, or a file or server it names:
        # one line, argparse's refusals too (OSError: a file that is missing, a folder or read-only; a server that
        # does not answer, TimeoutError); a part of the package whose extra is not installed
        print(f"ijoy: error: {e}", file=sys.stderr)
        return 2


def _run(args) -> int:
    """Dispatch a parsed command line; bad input raises ValueError, TypeError or OSError."""
    from ijoy_jax.apps import tune_cli

    if args.command == "tune":
        return tune_cli.main(args)
    if args.command == "drive":
        from ijoy_jax.apps import drive_cli

        return drive_cli.main(args)
    if args.command == "cue":
        from ijoy_jax.apps import cue_cli

        return cue_cli.main(args)
    if args.command == "serve":
        from ijoy_jax.apps import serve_cli

        return serve_cli.main(args)
    if args.command == "sweep":
        return _sweep(args)
    if args.command == "sim":
        return _sim(args)
    if args.command == "demo":
        from ijoy_jax.apps import demo as demo_mod

        result = demo_mod.run(args.out, args.steps, args.margin)
        print(json.dumps(result, indent=2))
        return 0
    if args.command == "bench":
        from ijoy_jax.apps import bench as bench_mod

        if args.ref is not None and args.name != "check":
            raise ValueError(f"--ref is read or written by 'ijoy bench check' only, not by '{args.name}'")
        walk_only = [f"--{k}" for k in _WALK_OPTIONS if getattr(args, k) is not None]
        if walk_only and args.name != "walk":
            raise ValueError(f"{', '.join(walk_only)}: options of 'ijoy bench walk' only, not of '{args.name}'")
        if args.name == "sim":
            from ijoy_jax.apps import bench_sim as sim_bench

            rows = []
            for row in sim_bench.run(quick=args.quick):
                print(json.dumps(row), flush=True)
                rows.append(row)
        elif args.name == "walk":
            rows = _bench_walk(args)
        elif args.name == "tune":
            rows = tune_cli.bench(quick=args.quick)
        elif args.name == "haptics":
            from ijoy_jax.apps import bench_haptics

            rows = bench_haptics.run(quick=args.quick)
            print(bench_haptics.format_report(rows))
        elif args.name == "cue":
            from ijoy_jax.apps import bench_cue

            rows = bench_cue.run(quick=args.quick)
            print(bench_cue.format_report(rows))
        elif args.name == "serve":
            from ijoy_jax.apps import bench_serve

            rows = bench_serve.run(quick=args.quick)
            print(bench_serve.format_report(rows))
        else:
            rows = bench_mod.run(args.name, quick=args.quick, path=args.ref)
        if args.json:
            with open(args.json, "w") as f:
                json.dump(rows, f, indent=2)
        return 0
    return 2


_WALK_OPTIONS = ("families", "batch", "steps", "commands", "resolution", "forward", "chunk", "seed", "refine",
                 "kernel", "set", "plot")

_BENCHMARKS = {
    "footcost": ("FootCost evaluations per second",
                 "FootCost of HRP-2's action set on a 2D and a 2.5D map: evaluations per second, batched, with the "
                 "XLA and (on a GPU) the fused Pallas kernel; compile time apart."),
    "select": ("decisions/s, rollout steps/s and the NumPy baseline",
               "select_step's decisions per second (exhaustive and ordered, batched), rollout steps per second, and "
               "the paper's algorithm in plain NumPy on the same terrain and queries."),
    "lookahead": ("the lookahead and refining selectors' decision time and the beam's loss",
                  "Decision time of the one-step, lookahead (H = 2 exact, all pairs, H = 3 beam) and refining "
                  "selectors, then the beam's loss against the exact search on the constrained families, and the "
                  "turn axis's overshoot (rate mode against heading hold)."),
    "check": ("fixed decisions saved to / compared with --ref (device agreement)",
              "Decisions on a fixed set of queries (2D and 2.5D, every method): written to --ref where it does not "
              "exist, else compared with it (differing decisions, validity and cost), to compare devices."),
    "tune": ("seconds per forward-tuning step",
             "Seconds per step of the forward tuner (default config, several batch sizes), compile separate."),
    "sim": ("MJX physics steps/s beside C MuJoCo, then the closed loop",
            "MJX biped physics steps per second by batch size next to multi-threaded C MuJoCo, then the closed "
            "loop (selector + controller + physics) with falls and placement error. Run on a GPU for the MJX "
            "figures."),
    "walk": ("the perfect robot and the MJX biped per terrain family",
             "The perfect robot and the MJX biped per terrain family: falls, stops, progress, contacts, placement "
             "and tilt errors; JSON lines as they come, then a Markdown table, and a bar plot with --plot."),
    "haptics": ("the ALDURO leg force and filter per call and batched",
                "The ALDURO leg's repulsive force and the joystick filter: compile time, median time per call "
                "(target under 50 us) and evaluations per second batched."),
    "cue": ("the haptic cue's tick, per-step feasible set and batched force",
            "The haptic cue's tick (jitted force per call, both CPU dispatch modes; target under 20 us), the "
            "per-step feasible set and reach, and the force batched over commands."),
    "serve": ("the footstep server's round trip beside the in-process call",
              "The footstep server's round trip over localhost (p50/p99) beside the in-process select_step, one "
              "2.5D decision on a 200 x 200 map; every reply checked against the in-process decision."),
}
"""Each ``ijoy bench`` benchmark: (one-line summary, description of its --help)."""


def _walk_families(text: str) -> list[str]:
    """``--families`` as a list of :data:`ijoy_jax.apps.bench_walk.FAMILIES` names (ArgumentTypeError otherwise)."""
    from ijoy_jax.apps import bench_walk

    names = [f.strip() for f in text.split(",") if f.strip()]
    unknown = [n for n in names if n not in bench_walk.FAMILIES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown terrain families {unknown}; known: {', '.join(bench_walk.FAMILIES)}")
    return names


def _add_bench_parser(sub) -> None:
    """Register ``bench`` on the ``ijoy`` subparsers object: one subcommand per benchmark, each with its own help.

    Every benchmark's parser also takes the options of ``walk`` and ``--ref`` (hidden from its help), so that
    :func:`_run` can say which benchmark they belong to instead of argparse's "unrecognized arguments"."""
    from ijoy_jax.apps.options import output_file, positive_int

    bench = sub.add_parser("bench", help="run a benchmark and print JSON lines (see BENCHMARKS.md)",
                           description="Benchmarks of the library on this machine's default JAX device: compile "
                                       "time and run time reported apart, results as JSON lines (BENCHMARKS.md "
                                       "lists the figures). Each benchmark has its own options: ijoy bench BENCHMARK "
                                       "--help.")
    names = bench.add_subparsers(dest="name", required=True, metavar="BENCHMARK")
    for name, (summary, text) in _BENCHMARKS.items():
        own = name == "walk"

        def shown(help_text, own=own):
            return help_text if own else argparse.SUPPRESS

        b = names.add_parser(name, help=summary, description=text)
        b.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
        b.add_argument("--json", default=None, type=output_file, help="also write the results to this file")
        b.add_argument("--ref", default=None, type=output_file,
                       help="npz of reference decisions: compared with where it exists, else written"
                       if name == "check" else argparse.SUPPRESS)
        walk = b.add_argument_group("walk", "options of 'ijoy bench walk' (ijoy_jax/apps/bench_walk.py)") if own else b
        walk.add_argument("--families", default=None, type=_walk_families,
                          help=shown("comma-separated terrain families (default: all of flat, clutter2d, uphill, "
                                     "downhill, cross, rough, stones, platforms, stairs_up, stairs_down, image)"))
        walk.add_argument("--batch", type=positive_int, default=None,
                          help=shown("robots (maps) per family (default: 1024; --quick: 4)"))
        walk.add_argument("--steps", type=positive_int, default=None,
                          help=shown("steps per rollout (default: 30; --quick: 6)"))
        walk.add_argument("--commands", choices=["random", "forward", "both"], default=None,
                          help=shown("a new random command every step, a held forward command, or both (default: "
                                     "both)"))
        walk.add_argument("--resolution", type=float, default=None, help=shown("cell size in metres (default: 0.02)"))
        walk.add_argument("--forward", type=float, default=None,
                          help=shown("held forward command in m/s (default: 0.25; the stairs keep their own 0.375, "
                                     "the 30 cm step that crosses a riser)"))
        walk.add_argument("--chunk", type=positive_int, default=None,
                          help=shown("simulated rollouts per jitted call (default: up to 1024 on an accelerator, 32 "
                                     "on a CPU)"))
        walk.add_argument("--seed", type=int, default=None, help=shown("maps and random commands (default: 0)"))
        walk.add_argument("--refine", action="store_const", const=True, default=None,
                          help=shown("refine each lattice choice to a continuous foothold (both walkers)"))
        walk.add_argument("--kernel", choices=["xla", "pallas"], default=None,
                          help=shown("FootCost in both walkers' selector: xla (default) or pallas, the fused kernel "
                                     "(GPU)"))
        walk.add_argument("--set", action="append", default=None, metavar="NAME=VALUE",
                          help=shown("a robot leaf of the choice for every family, e.g. metrics.support_limit=0.003 "
                                     "(repeatable; names: ijoy_jax.robots.SELECTOR_LEAVES)"))
        walk.add_argument("--plot", default=None, type=output_file, help=shown("write the bar plot (PNG) here"))


def _bench_walk(args) -> list[dict]:
    """``ijoy bench walk``: JSON lines as the rows come, then the Markdown table; the plot with --plot."""
    from ijoy_jax import robots
    from ijoy_jax.apps import bench_walk
    from ijoy_jax.apps.options import number_assignments

    def given(value, default):
        return default if value is None else value

    families = args.families  # a list of names, checked as parsed
    kinds = bench_walk.COMMANDS if args.commands in (None, "both") else (args.commands,)
    rows = bench_walk.run(families, batch=given(args.batch, 4 if args.quick else 1024),
                          steps=given(args.steps, 6 if args.quick else 30), commands=kinds,
                          resolution=given(args.resolution, bench_walk.RESOLUTION), seed=given(args.seed, 0),
                          chunk=args.chunk, forward=given(args.forward, bench_walk.FORWARD),
                          refine=given(args.refine, False), kernel=given(args.kernel, "xla"),
                          robot_leaves=number_assignments(args.set, robots.SELECTOR_LEAVES,
                                                          "metrics.support_limit=0.003"),
                          emit=lambda row: print(json.dumps(row), flush=True))
    print(bench_walk.markdown_table(rows))
    if args.plot:
        bench_walk.plot(rows, args.plot)
    return rows


# ``ijoy sim render``'s map: sweeps/margin_physics.toml's clutter (4 x 2 m at 2 cm, 14 obstacles of 4-12 cm).
_RENDER_SHAPE, _RENDER_RESOLUTION = (200, 100), 0.02
_RENDER_CLUTTER = dict(count=14, size_min=0.04, size_max=0.12)
_RENDER_COMMAND = (0.2, 0.0, 0.0)  # m/s, m/s, rad/s: forward at 80 % of the top speed


def _sim(args) -> int:
    """``ijoy sim render``: the simulated biped through one clutter map, as a GIF."""
    import jax
    import numpy as np

    from ijoy_jax import robots
    from ijoy_jax.sim import render
    from ijoy_jax.sim import walker as W
    from ijoy_jax.terrain import generators

    width, height = args.size  # (pixels, pixels), checked as parsed
    robot = robots.hrp2(margin=args.margin)
    sim = W.make_sim(_RENDER_SHAPE, _RENDER_RESOLUTION, robot=robot)
    params = generators.ObstacleParams(**_RENDER_CLUTTER)
    terrain = generators.obstacles(jax.random.key(args.seed), params, shape=_RENDER_SHAPE,
                                   resolution=_RENDER_RESOLUTION, max_count=16)
    x, y = np.asarray(generators.start_point(params, shape=_RENDER_SHAPE, resolution=_RENDER_RESOLUTION))
    start = robots.start_stance(robot, x, y)
    traj = W.rollout(sim, terrain, robot, start, np.asarray(_RENDER_COMMAND, np.float32), num_steps=args.steps,
                     frames_per_step=args.frames, progress=True)
    frames = render.render(sim, terrain, render.states(traj), width=width, height=height,
                           footsteps=traj.commanded, sides=traj.sides, smooth=args.frames)
    render.write_gif(args.out, frames, fps=args.frames / sim.cfg.step_time)
    if args.strip:
        from PIL import Image

        Image.fromarray(render.filmstrip(frames, 5)).save(args.strip)
    summary = {k: np.asarray(v).tolist() for k, v in W.summary(traj).items()}
    print(json.dumps(dict(gif=args.out, strip=args.strip, frames=len(frames), **summary)))
    return 0


def _sweep_local(args) -> int:
    """``ijoy sweep run FILE --local-processes N``: N child processes, one GPU each (no JAX backend here)."""
    import os

    from ijoy_jax.sweep import local

    sweep_args = [args.file] + (["--distributed"] if args.distributed else [])  # local.run refuses layout flags
    for flag, v in (("--out", args.out), ("--chunk", args.chunk), ("--max-scenarios", args.max_scenarios),
                    ("--scenarios-per-cell", args.scenarios_per_cell), ("--barrier-timeout", args.barrier_timeout),
                    ("--num-processes", args.num_processes),
                    ("--process-id", args.process_id), ("--coordinator", args.coordinator),
                    ("--devices", args.devices)):
        if v is not None:
            sweep_args += [flag, str(v)]
    env = dict(os.environ, **({"IJOY_COMPILE_CACHE": "0"} if args.no_compile_cache else {}))
    rc, rows = local.run(sweep_args, args.local_processes, env=env)
    done = [r for r in rows if r is not None]
    summary = {"processes": rows, "complete": len(done) == len(rows) and all(r.get("complete") for r in done)}
    for key in ("scenarios_per_s", "physics_steps_per_s"):
        if done and all(r.get(key) for r in done):
            summary[key] = round(sum(r[key] for r in done), 3)
    print(json.dumps(summary, indent=2))
    return rc


def _stop_on_sigterm() -> None:
    """SIGTERM ends the process (exit code 143, ``finally`` blocks run) as it did before ``jax.distributed``
    started: its preemption notifier takes SIGTERM for itself and only notes it, so ``kill`` (or a batch
    scheduler's stop) left a sweep process running. The sweep does not use that notice: a stopped process's
    written parts stay, and the same command resumes."""
    import signal

    def stop(signum, _frame):
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, stop)


def _sweep(args) -> int:
    """``ijoy sweep run`` / ``ijoy sweep summarize`` (bad sweep files raise SweepConfigError, a ValueError)."""
    from pathlib import Path

    from ijoy_jax import sweep

    if args.sweep_command == "run":  # a slice's flags, named, before anything starts
        for flag, v in (("--scenarios-per-cell", args.scenarios_per_cell), ("--max-scenarios", args.max_scenarios)):
            if v is not None and v < 1:
                raise ValueError(f"{flag} must be a positive int, got {v}")
    if args.sweep_command == "run" and args.local_processes is not None:
        return _sweep_local(args)  # each process refuses the flags below as a run does
    if args.sweep_command == "run" and args.scenarios_per_cell is not None and args.max_scenarios is not None:
        raise ValueError("give --scenarios-per-cell or --max-scenarios, not both (--scenarios-per-cell N: the "
                         "first N scenarios of every cell; --max-scenarios N: the first N scenario ids)")
    if args.sweep_command == "run":
        # The layout is checked first (no compute, no network), then jax.distributed starts, before anything
        # can start a JAX backend; then the sweep file is validated, before any compute.
        if not 0 < args.barrier_timeout < float("inf"):
            raise ValueError(f"--barrier-timeout must be a positive number of seconds, got {args.barrier_timeout:g}")
        lay = sweep.distributed.layout(args.num_processes, args.process_id, args.coordinator, args.distributed)
        sweep.distributed.initialize(lay)
        if sweep.distributed.client() is not None:
            _stop_on_sigterm()
        cfg = sweep.load_config(args.file)
        stats = sweep.run(cfg, args.out, chunk_size=args.chunk, max_scenarios=args.max_scenarios,
                          scenarios_per_cell=args.scenarios_per_cell, devices=args.devices,
                          barrier_timeout_s=args.barrier_timeout)
        row = {"out": str(stats.out), "scenarios": stats.scenarios, "computed": stats.computed,
               "chunks": stats.chunks, "skipped_chunks": stats.skipped, "compiles": stats.compiles,
               "chunk_size": stats.chunk_size, "first_chunk_s": stats.first_chunk_s, "run_s": round(stats.run_s, 3),
               "complete": stats.complete,
               # a slice (--scenarios-per-cell, --max-scenarios) leaves the sweep incomplete: a later run extends it
               "sweep_scenarios": stats.sweep_scenarios, "sweep_complete": stats.sweep_complete,
               # null when every chunk was its density's first (its time includes the compile)
               "scenarios_per_s": round(stats.rate, 3) if stats.rate > 0 else None}
        if stats.physics_steps:
            row["physics_steps_per_s"] = round(stats.rate * stats.physics_steps) if stats.rate > 0 else None
        print(json.dumps(row, indent=2), flush=True)
        # The others leave first, then process 0's service; a process missing at the end (dead, or stuck
        # past the barrier) counts as live until its heartbeats time out, so then process 0 does not wait.
        sweep.distributed.shutdown(timeout_s=120.0 if stats.complete else 5.0)
        return 0
    import pandas as pd

    agg = sweep.load_aggregates(args.dir)  # FileNotFoundError, or IncompleteSweepError (a ValueError)
    metrics = None
    if args.metrics is not None:  # checked before anything is printed
        metrics = tuple(m.strip() for m in args.metrics.split(","))
        known = [c[: -len(".mean")] for c in agg.columns if c.endswith(".mean")]
        for m in metrics:
            if m not in known:
                raise ValueError(f"--metrics: {m!r} is not a metric of this sweep; known: {', '.join(known)}")
    tradeoff = None
    if args.tradeoff is not None:  # checked before anything is printed, like --metrics
        tradeoff = tuple(m.strip() for m in args.tradeoff.split(","))
        known = [c[: -len(".mean")] for c in agg.columns if c.endswith(".mean")]
        if len(tradeoff) != 2 or any(m not in known for m in tradeoff):
            raise ValueError(f"--tradeoff takes two metrics of this sweep, Y,X (e.g. fell,distance_along), got "
                             f"{args.tradeoff!r}; known: {', '.join(known)}")
    show = [c for c in agg.columns if c.startswith(("robot.", "terrain.", "sim.", "selector.")) or c == "n"]
    table = agg[show].copy()
    for m in sweep.results.summary_metrics(agg):  # the plot's default panels, in the same order
        unit = sweep.UNITS[m]
        table[f"{m} ({unit})"] = [f"{a:.3g} +- {b:.2g}" for a, b in zip(agg[f"{m}.mean"], agg[f"{m}.ci95"],
                                                                        strict=True)]
    man = json.loads((Path(args.dir) / "manifest.json").read_text())
    name, held, total = man.get("name", ""), int(agg["n"].sum()), man.get("plan", {}).get("scenarios")
    if isinstance(total, int) and held < total:  # a slice, or an unfinished run: said above the table and plot
        sel = man.get("selection")
        asked = f", asked for {sweep.results.describe_selection(sel)}" if sel and sel["scenarios"] < total else ""
        print(f"incomplete sweep: {held} of {total} scenarios{asked}; `ijoy sweep run {man.get('sweep_file')} "
              f"--out {args.dir}` computes the rest into this folder (only the scenarios missing)")
        name = f"{name} (incomplete: {held} of {total} scenarios)".strip()
    with pd.option_context("display.width", 200, "display.max_columns", 50):
        print(table.to_string(index=False))
    png = args.png or str(Path(args.dir) / "summary.png")
    sweep.plot(agg, png, x=args.x, metrics=metrics, title=name)
    print(f"plot: {png}")
    if tradeoff is not None:
        out = str(Path(png).with_name("tradeoff.png"))
        sweep.plot_tradeoff(agg, out, safety=tradeoff[0], price=tradeoff[1], title=name)
        print(f"plot: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
