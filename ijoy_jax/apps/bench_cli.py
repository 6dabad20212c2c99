"""``ijoy bench NAME``: one subcommand per benchmark, each with its own options and help (figures: BENCHMARKS.md).

Every benchmark is one :class:`Benchmark` of :data:`BENCHMARKS`, registered the same way: the line of
``ijoy bench --help``, the text of ``ijoy bench NAME --help``, the function that adds its own options beside
every benchmark's ``--quick`` and ``--json``, and the function that runs it from the parsed options (it prints
as it goes and returns the results that ``--json`` writes). Those functions live beside each benchmark's code
(:mod:`~ijoy_jax.apps.bench`, :mod:`~ijoy_jax.apps.bench_cue`, ...); ``walk`` and ``tune``, whose code is a
library of its own, get theirs here.

Each benchmark's parser also takes every other benchmark's options, hidden from its help, so that an option
given to the wrong benchmark is refused by name (``--batch: options of 'ijoy bench walk' only, not of 'sim'``)
instead of with argparse's "unrecognized arguments".
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from typing import NamedTuple

from ijoy_jax.apps import bench, bench_cue, bench_haptics, bench_serve, tune_cli
from ijoy_jax.apps.options import names_of, output_file, output_folder, positive_int


class Benchmark(NamedTuple):
    """One ``ijoy bench`` benchmark: its help, its options and how it runs."""

    summary: str  # its line in ``ijoy bench --help``
    description: str  # the text of ``ijoy bench NAME --help``
    run: Callable[[argparse.Namespace], object]  # runs it from the parsed options; the results --json writes
    add_options: Callable[[argparse.ArgumentParser], None] | None = None  # its own options, beside --quick, --json
    refusal: str = "{flags}: options of {owners} only, not of '{name}'"  # one of its options given to another


def _walk_families(text: str) -> list[str]:
    """``--families`` as a list of :data:`ijoy_jax.apps.bench_walk.FAMILIES` names (ArgumentTypeError otherwise)."""
    from ijoy_jax.apps import bench_walk

    return names_of(text, bench_walk.FAMILIES, "terrain families")


def _walkers(text: str) -> list[str]:
    """``--walkers`` as a list of :data:`ijoy_jax.apps.bench_walk.WALKERS` (ArgumentTypeError otherwise)."""
    walkers = ("perfect", "mjx")  # bench_walk.WALKERS, without importing MuJoCo to parse the line
    names = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in walkers]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"walkers must be some of {', '.join(walkers)}, got {text!r}")
    return names


def _walk_options(parser) -> None:
    """``ijoy bench walk``'s own options; each None unless given (its defaults depend on --quick)."""
    walk = parser.add_argument_group("walk", "options of 'ijoy bench walk' (ijoy_jax/apps/bench_walk.py)")
    walk.add_argument(
        "--families",
        default=None,
        type=_walk_families,
        help="comma-separated terrain families (default: all of flat, clutter2d, uphill, downhill, cross, "
        "rough, stones, platforms, stairs_up, stairs_down, image, natural)",
    )
    walk.add_argument(
        "--batch", type=positive_int, default=None, help="robots (maps) per family (default: 1024; --quick: 4)"
    )
    walk.add_argument("--steps", type=positive_int, default=None, help="steps per rollout (default: 30; --quick: 6)")
    walk.add_argument(
        "--commands",
        choices=["random", "forward", "both"],
        default=None,
        help="a new random command every step, a held forward command, or both (default: both)",
    )
    walk.add_argument(
        "--walkers",
        type=_walkers,
        default=None,
        help="comma-separated walkers: perfect (the paper's robot), mjx (the MJX biped) (default: both)",
    )
    walk.add_argument(
        "--model",
        choices=["biped", "g1"],  # ijoy_jax.sweep.MODELS, without importing the sweep engine to parse the line
        default=None,
        help="the robot: biped (HRP-2 choosing, the project's HRP-2-like biped in MJX) or g1 (the Unitree G1 "
        "choosing and in MJX; the stairs, whose robot is HRP-2 with a 0.30 m reach, are skipped) (default: biped)",
    )
    walk.add_argument("--resolution", type=float, default=None, help="cell size in metres (default: the files' 0.02)")
    walk.add_argument(
        "--chunk",
        type=positive_int,
        default=None,
        help="rollouts per jitted call (default: the batch, up to 1024 on an accelerator, 32 on a CPU)",
    )
    walk.add_argument("--seed", type=int, default=None, help="maps and random commands (default: the files' 0)")
    walk.add_argument(
        "--refine",
        action="store_const",
        const=True,
        default=None,
        help="refine each lattice choice to a continuous foothold (both walkers)",
    )
    walk.add_argument(
        "--kernel",
        choices=["xla", "pallas"],
        default=None,
        help="FootCost in both walkers' selector: xla (default) or pallas, the fused kernel (GPU)",
    )
    walk.add_argument(
        "--set",
        action="append",
        default=None,
        metavar="NAME=VALUE",
        help="a robot leaf of the choice for every family, e.g. metrics.support_limit=0.003 "
        "(repeatable; names: ijoy_jax.robots.SELECTOR_LEAVES)",
    )
    walk.add_argument(
        "--sweeps",
        default=None,
        help="folder of the walk sweep files <family>_<commands>.toml (default: the ones shipped with the package)",
    )
    walk.add_argument(
        "--out",
        default=None,
        type=output_folder,
        help="folder of the sweeps' results, one subfolder per file and walker; a rerun with the same options "
        "resumes there, other options need another folder (default: a new temporary folder, named in the last "
        "JSON line)",
    )
    walk.add_argument("--plot", default=None, type=output_file, help="write the bar plot (PNG) here")


def _walk(args) -> list[dict]:
    """``ijoy bench walk``: the walk sweep files through the sweep engine, a JSON line per row as the rows come,
    then the Markdown table; the plot with --plot."""
    from ijoy_jax import robots
    from ijoy_jax.apps import bench_walk
    from ijoy_jax.apps.options import number_assignments

    kinds = bench_walk.COMMANDS if args.commands in (None, "both") else (args.commands,)
    rows = bench_walk.run(
        args.families,  # a list of names, checked as parsed
        batch=(4 if args.quick else 1024) if args.batch is None else args.batch,
        steps=(6 if args.quick else 30) if args.steps is None else args.steps,
        commands=kinds,
        walkers=bench_walk.WALKERS if args.walkers is None else args.walkers,
        resolution=args.resolution,
        seed=args.seed,
        chunk=args.chunk,
        refine=args.refine,
        kernel=args.kernel,
        robot_leaves=number_assignments(args.set, robots.SELECTOR_LEAVES, "metrics.support_limit=0.003"),
        model="biped" if args.model is None else args.model,
        sweeps=args.sweeps,
        out=args.out,
        emit=lambda row: print(json.dumps(row), flush=True),
    )
    print(bench_walk.markdown_table(rows))
    if args.plot:
        bench_walk.plot(rows, args.plot)
    return rows


def _sim(args) -> list[dict]:
    """``ijoy bench sim`` (its module imports MuJoCo, of the sim extra: imported when it runs)."""
    from ijoy_jax.apps import bench_sim

    return bench_sim.report(args)


def _tune(args) -> list:
    """``ijoy bench tune``: :func:`ijoy_jax.apps.tune_cli.bench`."""
    return tune_cli.bench(quick=args.quick)


BENCHMARKS = {
    "footcost": Benchmark(
        "FootCost evaluations per second",
        "FootCost of HRP-2's action set on a 2D and a 2.5D map: evaluations per second, batched, with the "
        "XLA and (on a GPU) the fused Pallas kernel; compile time apart.",
        run=bench.report,
    ),
    "select": Benchmark(
        "decisions/s, rollout steps/s and the NumPy baseline",
        "select_step's decisions per second (exhaustive and ordered, batched) with the FootCosts a decision "
        "evaluated, rollout steps per second, and "
        "the paper's algorithm in plain NumPy on the same terrain and queries; --kernel and --parts run some of "
        "it.",
        run=bench.report,
        add_options=bench.add_select_options,
    ),
    "lookahead": Benchmark(
        "the lookahead and refining selectors' decision time and the beam's loss",
        "Decision time of the one-step, lookahead (H = 2 exact, all pairs, H = 3 beam) and refining "
        "selectors, then the beam's loss against the exact search on the constrained families, and the "
        "turn axis's overshoot (rate mode against heading hold).",
        run=bench.report,
    ),
    "check": Benchmark(
        "fixed decisions saved to / compared with --ref (device agreement)",
        "Decisions on a fixed set of queries (2D and 2.5D, every method): written to --ref where it does not "
        "exist, else compared with it (differing decisions, validity and cost), to compare devices.",
        run=bench.report,
        add_options=bench.add_check_options,
        refusal="{flags} is read or written by {owners} only, not by '{name}'",
    ),
    "tune": Benchmark(
        "seconds per forward-tuning step",
        "Seconds per step of the forward tuner (default config, several batch sizes), compile separate.",
        run=_tune,
    ),
    "sim": Benchmark(
        "MJX physics steps/s beside C MuJoCo, then the closed loop",
        "MJX biped physics steps per second by batch size next to multi-threaded C MuJoCo, then the closed "
        "loop (selector + controller + physics) with falls and placement error. Run on a GPU for the MJX "
        "figures.",
        run=_sim,
    ),
    "walk": Benchmark(
        "the perfect robot and the MJX biped per terrain family",
        "The perfect robot and the MJX biped per terrain family, the walk sweep files (sweeps/walk) run through "
        "the sweep engine: falls, stops, progress, contacts, placement and tilt errors; JSON lines as they come, "
        "then a Markdown table, and a bar plot with --plot.",
        run=_walk,
        add_options=_walk_options,
    ),
    "haptics": Benchmark(
        "the ALDURO leg force and filter per call and batched",
        "The ALDURO leg's repulsive force and the joystick filter: compile time, median time per call "
        "(target under 50 us) and evaluations per second batched.",
        run=bench_haptics.report,
        add_options=bench_haptics.add_options,
    ),
    "cue": Benchmark(
        "the haptic cue's tick, per-step feasible set and batched force",
        "The haptic cue's tick (jitted force per call, both CPU dispatch modes; target under 20 us), the "
        "per-step feasible set and reach, and the force batched over commands.",
        run=bench_cue.report,
        add_options=bench_cue.add_options,
    ),
    "serve": Benchmark(
        "the footstep server's round trip beside the in-process call",
        "The footstep server's round trip over localhost (p50/p99) beside the in-process select_step, one "
        "2.5D decision on a 200 x 200 map; every reply checked against the in-process decision.",
        run=bench_serve.report,
    ),
}
"""Every ``ijoy bench`` benchmark by name, in the order of ``ijoy bench --help``."""


class _Hidden:
    """A benchmark's parser as another benchmark's ``add_options`` sees it: each option is added without a help
    line and with None for its default (so that :func:`main` sees it given), and skipped where the parser has
    that flag already (its own, or an earlier benchmark's). ``added`` holds the options it added."""

    def __init__(self, parser: argparse.ArgumentParser):
        self.parser, self.added = parser, []

    def add_argument(self, *flags, **kwargs) -> None:
        try:
            action = self.parser.add_argument(*flags, **dict(kwargs, default=None, help=argparse.SUPPRESS))
        except argparse.ArgumentError:  # a flag the parser has already
            return
        self.added.append(action)

    def add_argument_group(self, *args, **kwargs) -> _Hidden:
        return self


def _options(benchmark: Benchmark) -> list[argparse.Action]:
    """The options a benchmark adds of its own (none for most)."""
    if benchmark.add_options is None:
        return []
    seen = _Hidden(argparse.ArgumentParser(add_help=False))
    benchmark.add_options(seen)
    return seen.added


def add_parser(sub) -> None:
    """Register ``bench`` on an argparse subparsers object: one subcommand per benchmark of :data:`BENCHMARKS`,
    each with ``--quick``, ``--json`` and its own options, and the others' options hidden (see the module)."""
    parser = sub.add_parser(
        "bench",
        help="run a benchmark and print JSON lines (see BENCHMARKS.md)",
        description="Benchmarks of the library on this machine's default JAX device: compile "
        "time and run time reported apart, results as JSON lines (BENCHMARKS.md "
        "lists the figures). Each benchmark has its own options: ijoy bench "
        "BENCHMARK --help.",
    )
    names = parser.add_subparsers(dest="name", required=True, metavar="BENCHMARK")
    for name, benchmark in BENCHMARKS.items():
        b = names.add_parser(name, help=benchmark.summary, description=benchmark.description)
        b.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
        b.add_argument("--json", default=None, type=output_file, help="also write the results to this file")
        if benchmark.add_options is not None:
            benchmark.add_options(b)
        for other in BENCHMARKS.values():
            if other is not benchmark and other.add_options is not None:
                other.add_options(_Hidden(b))


def main(args) -> int:
    """Run ``ijoy bench NAME`` from parsed arguments: another benchmark's option given raises ValueError, naming
    it, before anything runs; then the benchmark, and its results written to --json."""
    name = args.name
    own = {action.dest for action in _options(BENCHMARKS[name])}
    others = {other: _options(benchmark) for other, benchmark in BENCHMARKS.items() if other != name}
    for other, options in others.items():
        given = [a.option_strings[-1] for a in options if a.dest not in own and getattr(args, a.dest, None) is not None]
        if given:  # named with every benchmark that takes them all
            owners = [o for o, opts in others.items() if set(given) <= {a.option_strings[-1] for a in opts}]
            raise ValueError(
                BENCHMARKS[other].refusal.format(
                    flags=", ".join(given), owners=" and ".join(f"'ijoy bench {o}'" for o in owners), name=name
                )
            )
    rows = BENCHMARKS[name].run(args)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=2)
    return 0
