"""``ijoy sweep run`` and ``ijoy sweep summarize``: run a sweep declared in TOML, or summarise a finished one
(the sweep engine: :mod:`ijoy_jax.sweep`; its schema: ``ijoy_jax/sweep/schema.py``; examples in ``sweeps/``).

``run`` checks its flags and the layout of processes first (no compute, no network), starts ``jax.distributed``
where several processes share the run, and only then loads and validates the sweep file; ``--local-processes N``
runs N children of this command, one GPU each. ``summarize`` checks its metrics before it prints anything.

Kept here so that :mod:`ijoy_jax.apps.cli` only registers the subcommand (:func:`add_parser`) and dispatches
to :func:`main`.
"""

from __future__ import annotations

import json

from ijoy_jax.apps.options import output_file, output_folder


def add_parser(sub) -> None:
    """Register ``sweep`` (with ``run`` and ``summarize``) on an argparse subparsers object."""
    sweep = sub.add_parser(
        "sweep",
        help="run a sweep declared in TOML, or summarise a finished one",
        description="Sweeps over robot/selector parameters, terrains and commands "
        "(schema: ijoy_jax/sweep/schema.py; examples in sweeps/).",
    )
    sweep_sub = sweep.add_subparsers(dest="sweep_command", required=True)
    srun = sweep_sub.add_parser(
        "run",
        help="run or resume a sweep; results as parquet parts in --out",
        description="Run a sweep file's scenarios (or a slice of them) in resumable chunks "
        "on every local device: parquet parts, a manifest and aggregates in "
        "--out. A folder of the same sweep is resumed or extended; another "
        "sweep's is refused.",
    )
    srun.add_argument("file", help="sweep file (TOML), e.g. sweeps/w_sweep.toml")
    srun.add_argument(
        "--out",
        default=None,
        type=output_folder,
        help="output folder; an existing one from the same file and options is resumed (default: results/<sweep name>)",
    )
    srun.add_argument(
        "--chunk",
        type=int,
        default=None,
        help="scenarios per jitted call; memory grows with it (default: the folder's when resuming, "
        "else 32 on CPU and sized to device memory on a GPU)",
    )
    srun.add_argument(
        "--scenarios-per-cell",
        type=int,
        default=None,
        metavar="N",
        help="a quick, even slice of the sweep: only the first N scenarios (replicates) of every "
        "cell; the folder is marked incomplete, and a later run into the same --out with a "
        "larger N, or without it, computes only the scenarios missing",
    )
    srun.add_argument(
        "--max-scenarios",
        type=int,
        default=None,
        metavar="N",
        help="only the first N scenario ids, cell after cell (a check of the program: fewer than a "
        "cell's scenarios cover the first cell alone; for a small sweep over every cell use "
        "--scenarios-per-cell); extended like it by a later run",
    )
    srun.add_argument(
        "--devices",
        type=int,
        default=None,
        help="split each chunk over the first N local devices, each running the one-device "
        "program (default: all of them)",
    )
    srun.add_argument(
        "--num-processes",
        type=int,
        default=None,
        help="several processes/hosts: how many run this sweep into the same shared --out "
        "(env IJOY_NUM_PROCESSES; default 1); each runs chunks with chunk %% N == its id",
    )
    srun.add_argument(
        "--process-id",
        type=int,
        default=None,
        help="this process's id in [0, N) (env IJOY_PROCESS_ID); process 0 hosts the coordinator",
    )
    srun.add_argument(
        "--coordinator",
        default=None,
        help="HOST:PORT of process 0's jax.distributed coordinator, reachable from every process "
        "(env IJOY_COORDINATOR)",
    )
    srun.add_argument(
        "--barrier-timeout",
        type=float,
        default=3600.0,
        metavar="S",
        help="several processes: how long a finished process waits for the others before process 0 "
        "writes the aggregates (seconds; default 3600); a dead process relaunched within it "
        "rejoins the run",
    )
    srun.add_argument(
        "--local-processes",
        type=int,
        default=None,
        metavar="N",
        help="run as N processes on this machine, one GPU each (the first N of CUDA_VISIBLE_DEVICES, "
        "else 0..N-1), coordinated on localhost; for several GPUs of one host, the faster "
        "layout for short chunks (sweeps/README.md)",
    )
    srun.add_argument(
        "--distributed",
        action="store_true",
        help="call jax.distributed.initialize and let JAX detect unset values from the cluster "
        "(SLURM, Open MPI, ...; env IJOY_DISTRIBUTED=1); see sweeps/README.md",
    )
    ssum = sweep_sub.add_parser(
        "summarize",
        help="print per-cell means with 95%% CIs and write a plot PNG",
        description="Print a sweep folder's per-cell means with 95%% confidence intervals "
        "and plot them (summary.png; --tradeoff: a safety metric against "
        "its price, tradeoff.png).",
    )
    ssum.add_argument("dir", help="a sweep's output folder")
    ssum.add_argument("--png", default=None, type=output_file, help="plot to write (default: DIR/summary.png)")
    ssum.add_argument("--x", default=None, help="parameter on the plot's x axis (default: the most varied)")
    ssum.add_argument(
        "--tradeoff",
        nargs="?",
        const="fell,distance_along",
        default=None,
        metavar="Y,X",
        help="also write DIR/tradeoff.png: one point per cell, metric Y (safety) against metric X "
        "(its price; default fell,distance_along: falls against progress)",
    )
    ssum.add_argument(
        "--metrics",
        default=None,
        help="comma-separated metrics, one panel each (default: the table's columns, in its order; "
        "for a physics sweep falls and collisions beside progress)",
    )


def _sweep_local(args) -> int:
    """``ijoy sweep run FILE --local-processes N``: N child processes, one GPU each (no JAX backend here)."""
    import os

    from ijoy_jax.sweep import local

    sweep_args = [args.file] + (["--distributed"] if args.distributed else [])  # local.run refuses layout flags
    for flag, v in (
        ("--out", args.out),
        ("--chunk", args.chunk),
        ("--max-scenarios", args.max_scenarios),
        ("--scenarios-per-cell", args.scenarios_per_cell),
        ("--barrier-timeout", args.barrier_timeout),
        ("--num-processes", args.num_processes),
        ("--process-id", args.process_id),
        ("--coordinator", args.coordinator),
        ("--devices", args.devices),
    ):
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


def main(args) -> int:
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
        raise ValueError(
            "give --scenarios-per-cell or --max-scenarios, not both (--scenarios-per-cell N: the "
            "first N scenarios of every cell; --max-scenarios N: the first N scenario ids)"
        )
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
        stats = sweep.run(
            cfg,
            args.out,
            chunk_size=args.chunk,
            max_scenarios=args.max_scenarios,
            scenarios_per_cell=args.scenarios_per_cell,
            devices=args.devices,
            barrier_timeout_s=args.barrier_timeout,
        )
        row = {
            "out": str(stats.out),
            "scenarios": stats.scenarios,
            "computed": stats.computed,
            "chunks": stats.chunks,
            "skipped_chunks": stats.skipped,
            "compiles": stats.compiles,
            "chunk_size": stats.chunk_size,
            "first_chunk_s": stats.first_chunk_s,
            "run_s": round(stats.run_s, 3),
            "complete": stats.complete,
            # a slice (--scenarios-per-cell, --max-scenarios) leaves the sweep incomplete: a later run extends it
            "sweep_scenarios": stats.sweep_scenarios,
            "sweep_complete": stats.sweep_complete,
            # null when every chunk was its density's first (its time includes the compile)
            "scenarios_per_s": round(stats.rate, 3) if stats.rate > 0 else None,
        }
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
            raise ValueError(
                f"--tradeoff takes two metrics of this sweep, Y,X (e.g. fell,distance_along), got "
                f"{args.tradeoff!r}; known: {', '.join(known)}"
            )
    show = [c for c in agg.columns if c.startswith(("robot.", "terrain.", "sim.", "selector.")) or c == "n"]
    table = agg[show].copy()
    for m in sweep.results.summary_metrics(agg):  # the plot's default panels, in the same order
        unit = sweep.UNITS[m]
        table[f"{m} ({unit})"] = [
            f"{a:.3g} +- {b:.2g}" for a, b in zip(agg[f"{m}.mean"], agg[f"{m}.ci95"], strict=True)
        ]
    man = json.loads((Path(args.dir) / "manifest.json").read_text())
    name, held, total = man.get("name", ""), int(agg["n"].sum()), man.get("plan", {}).get("scenarios")
    if isinstance(total, int) and held < total:  # a slice, or an unfinished run: said above the table and plot
        sel = man.get("selection")
        asked = f", asked for {sweep.results.describe_selection(sel)}" if sel and sel["scenarios"] < total else ""
        print(
            f"incomplete sweep: {held} of {total} scenarios{asked}; `ijoy sweep run {man.get('sweep_file')} "
            f"--out {args.dir}` computes the rest into this folder (only the scenarios missing)"
        )
        name = f"{name} (incomplete: {held} of {total} scenarios)".strip()
    with pd.option_context("display.width", 200, "display.max_columns", 50):
        print(table.to_string(index=False))
    png = args.png or str(Path(args.dir) / "summary.png")
    figs = [sweep.plot(agg, png, x=args.x, metrics=metrics, title=name)]
    print(f"plot: {png}")
    if tradeoff is not None:
        out = str(Path(png).with_name("tradeoff.png"))
        figs.append(sweep.plot_tradeoff(agg, out, safety=tradeoff[0], price=tradeoff[1], title=name))
        print(f"plot: {out}")
    import matplotlib.pyplot as plt

    for fig in figs:  # written: the figures are done
        plt.close(fig)
    return 0
