"""``ijoy tune forward|inverse`` and ``ijoy bench tune``: the tuners from the command line.

Kept here so that :mod:`ijoy_jax.apps.cli` only registers the subcommand
(:func:`add_parser`) and dispatches to :func:`main`. Options follow one rule:
a few run-level flags (``--out``, ``--steps``, ``--seed``, ``--runs``,
``--quiet``), every other setting through the config object
(:class:`ijoy_jax.tune.forward.ForwardConfig` or :class:`InverseConfig`),
from ``--config FILE.toml`` and/or repeated ``--set KEY=VALUE``.
"""

from __future__ import annotations

import dataclasses
import json
import time

from ijoy_jax.apps.options import assignments

_SET_HELP = ("override one config field, VALUE parsed as JSON if it can be (0.05, [40, 40], true, \"x\"), "
             "else as a string; repeatable, applied after --config")


def add_parser(sub) -> None:
    """Register ``tune`` (with ``forward`` and ``inverse``) on an argparse subparsers object."""
    tune = sub.add_parser(
        "tune", help="tune the selector's parameters by gradient; write params and loss curves to --out",
        description="Tuning by gradient through the relaxed selector (ijoy_jax.tune). Writes params.npz/json "
                    "(the optimiser's unconstrained variables: logs, or logits for the margin), losses.csv "
                    "(step, run, loss, named terms) and manifest.json (versions, config, tuned values, held-out "
                    "evaluation); read them back with ijoy_jax.tune.load(DIR).")
    tsub = tune.add_subparsers(dest="tune_command", required=True)
    fwd = tsub.add_parser(
        "forward", help="minimise command error + obstacle risk over random terrains and commands",
        description="Forward tuner: minimise E[command error] + risk_weight * P[foothold within `distance` of "
                    "an obstacle under placement noise] over random obstacle maps and commands; then compare "
                    "the EXACT selector at the tuned and at the paper's parameters on held-out decisions. "
                    "Config fields: see ijoy_jax.tune.forward.ForwardConfig (e.g. --set distance=0.04 "
                    "--set names='[\"rotation_weight\", \"margin\"]').")
    inv = tsub.add_parser(
        "inverse", help="recover hidden selector parameters from exact demonstrations (a known-answer check)",
        description="Inverse tuner: label random decisions with the EXACT selector at hidden parameters, fit "
                    "them by maximum-entropy likelihood, and report the recovered values and the held-out "
                    "agreement. Config fields: see ijoy_jax.apps.tune_cli.InverseConfig.")
    for p in (fwd, inv):
        p.add_argument("--out", required=True, help="output folder (created; files in it are overwritten)")
        p.add_argument("--config", default=None, help="TOML file of config fields (top-level keys)")
        p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=_SET_HELP)
        p.add_argument("--steps", type=int, default=None, help="optimiser steps (overrides the config's)")
        p.add_argument("--seed", type=int, default=None, help="seed of the training data (overrides the config's)")
        p.add_argument("--quiet", action="store_true", help="no progress lines")
    fwd.add_argument("--runs", type=int, default=None,
                     help="R tuning runs at once (vmapped), margins spread over (0, max_margin); the best is kept")
    fwd.add_argument("--held-out", type=int, default=200, help="held-out decisions for the exact evaluation "
                     "(default: %(default)s; 0 skips it)")
    fwd.add_argument("--held-out-seed", type=int, default=12345, help="seed of the held-out decisions "
                     "(default: %(default)s)")


@dataclasses.dataclass(frozen=True)
class InverseConfig:
    """Settings of ``ijoy tune inverse`` (a known-answer inverse problem).

    hidden: dict name -> value of the parameters that label the demonstrations.
    names: parameters to fit (log space). starts: starting values of rotation_weight
      (one vmapped run each; the likelihood is flat in it once large).
    num_train, num_held_out: demonstrations (random decisions of
      :func:`ijoy_jax.tune.forward.sample_decisions` on ``terrain`` maps).
    terrain: a :class:`~ijoy_jax.tune.forward.ForwardConfig` field dict for the maps and commands.
    density, margin, max_margin: the robot (HRP-2).
    sharpness, tau, noise, learning_rate, steps, seed: of :func:`ijoy_jax.tune.inverse.fit`.
    """

    hidden: dict = dataclasses.field(default_factory=lambda: {"w": 0.5, "rotation_weight": 0.5})
    names: tuple = ("w", "rotation_weight")
    starts: tuple = (0.1, 1.0, 10.0, 100.0)
    num_train: int = 50
    num_held_out: int = 30
    terrain: dict = dataclasses.field(default_factory=lambda: {"shape": (60, 60), "has_height": True,
                                                               "family": "rough"})
    density: float = 0.5
    margin: float = 0.02
    max_margin: float = 0.03
    sharpness: float = 300.0
    tau: float = 0.003
    noise: float = 0.05
    learning_rate: float = 0.3
    steps: int = 300
    seed: int = 0


def _parse_value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _build_config(cls, args, extra: dict):
    fields = {f.name for f in dataclasses.fields(cls)}
    values: dict = {}
    if args.config:
        import tomllib

        with open(args.config, "rb") as f:
            values.update(tomllib.load(f))
    for key, val in assignments(args.set, "distance=0.04").items():
        values[key] = _parse_value(val)
    values.update({k: v for k, v in extra.items() if v is not None})
    unknown = sorted(set(values) - fields)
    if unknown:
        raise ValueError(f"unknown config field(s) {unknown}; known: {sorted(fields)}")
    return cls(**values)


def main(args) -> int:
    """Run ``ijoy tune ...`` from parsed arguments; bad options raise ValueError, TypeError or FileNotFoundError
    (:func:`ijoy_jax.apps.cli.main` prints them as one line and exits with status 2)."""
    if args.tune_command == "forward":
        return _forward(args)
    return _inverse(args)


def _forward(args) -> int:
    import numpy as np

    from ijoy_jax.tune import forward, loop

    cfg = _build_config(forward.ForwardConfig, args, {"steps": args.steps, "seed": args.seed})
    if args.runs is not None and args.runs < 1:
        raise ValueError(f"--runs must be >= 1, got {args.runs}")
    if args.held_out < 0:
        raise ValueError(f"--held-out must be >= 0, got {args.held_out}")
    robot = forward.paper_robot(cfg)
    init = None
    if args.runs:
        hi = forward.max_margin_of(robot)
        init = {"margin": np.linspace(0.15, 0.85, args.runs) * hi} if "margin" in cfg.tuned_names() else None
    fit = forward.tune_forward(robot, cfg, init=init, num_runs=args.runs, progress=not args.quiet)
    extra = {"tuned": fit.params, "best_run": fit.best_run}
    if args.held_out:
        extra["held_out"] = forward.compare(fit.robot, cfg, num=args.held_out, key=args.held_out_seed)
        extra["held_out"]["seed"] = args.held_out_seed
    out = loop.save(args.out, fit.result, config=cfg, extra=extra)
    print(json.dumps({"out": str(out), "compile_s": round(fit.result.compile_s, 3),
                      "s_per_step": fit.result.seconds_per_step, **extra}, indent=2))
    return 0


def _inverse(args) -> int:
    import jax
    import jax.numpy as jnp
    import numpy as np

    from ijoy_jax import robots
    from ijoy_jax.tune import forward, inverse, loop

    cfg = _build_config(InverseConfig, args, {"steps": args.steps, "seed": args.seed})
    names = tuple(cfg.names)
    bad = [n for n in (*names, *cfg.hidden) if n not in forward.TUNABLE or n == "margin"]
    if bad:
        raise ValueError(f"inverse: cannot fit/hide {bad}; use positive leaves of {forward.TUNABLE[:2]} + metrics")
    tcfg = forward.ForwardConfig(**cfg.terrain, density=cfg.density, margin=cfg.margin, max_margin=cfg.max_margin)
    robot = robots.hrp2(margin=cfg.margin, density=cfg.density, max_margin=cfg.max_margin)
    hidden = robot
    for k, v in cfg.hidden.items():
        hidden = robots.set_leaf(hidden, k, jnp.float32(v))
    d = cfg.num_train + cfg.num_held_out
    dec = jax.jit(forward.sample_decisions, static_argnums=(1, 2))(jax.random.key(cfg.seed), d, tcfg)
    demos = inverse.make_demonstrations(dec.terrains, hidden, dec.stances, dec.sides, dec.commands)
    train, held = demos.take(np.arange(cfg.num_train)), demos.take(np.arange(cfg.num_train, d))
    init = {"rotation_weight": np.asarray(cfg.starts, np.float32)} if "rotation_weight" in names else None
    if init is not None:
        init.update({n: np.full(len(cfg.starts), float(robots.get_leaf(robot, n)), np.float32)
                     for n in names if n != "rotation_weight"})
    t0 = time.perf_counter()
    fit = inverse.fit(train, robot, names, init=init, sharpness=cfg.sharpness, tau=cfg.tau, noise=cfg.noise,
                      learning_rate=cfg.learning_rate, num_steps=cfg.steps)
    seconds = time.perf_counter() - t0
    result = loop.TuneResult(params={n: np.log(np.float32(v)) for n, v in fit.params.items() if n in names},
                             losses=np.asarray(fit.losses), terms={}, grad_norms=np.full(cfg.steps, np.nan),
                             compile_s=float("nan"), run_s=seconds, out_dir=None)
    extra = {
        "fitted": {n: fit.params[n] for n in names},
        "hidden": dict(cfg.hidden),
        "held_out_agreement": {"fitted": inverse.exact_agreement(held, fit.robot),
                               "start": inverse.exact_agreement(held, robot)},
        "final_losses_per_start": np.asarray(fit.final_losses).tolist(),
    }
    out = loop.save(args.out, result, config=cfg, extra=extra)
    print(json.dumps({"out": str(out), "seconds": round(seconds, 2), **extra}, indent=2))
    return 0


def bench(quick: bool = False) -> list:
    """``ijoy bench tune``: time per forward-tuning step (default config; JSON lines to stdout).

    ``compile_s`` is the first call (trace, compile and one step); ``step_s``
    the mean of the next calls after ``block_until_ready``.
    """
    import functools

    import jax
    import optax

    from ijoy_jax.tune import forward, loop

    rows = []
    sizes = [(8, 0.5)] if quick else [(8, 0.5), (32, 0.5), (8, 1.0)]
    for batch, density in sizes:
        cfg = forward.ForwardConfig(batch_size=batch, density=density)
        robot = forward.paper_robot(cfg)
        tuner = loop.make_tuner(functools.partial(forward.objective, robot=robot, cfg=cfg),
                                optax.adam(cfg.learning_rate), batch_fn=forward.make_batch_fn(robot, cfg),
                                has_aux=True)
        state = tuner.init(forward.to_unconstrained(robot, cfg.tuned_names()))
        key = jax.random.key(0)
        t0 = time.perf_counter()
        state, m = tuner.step(state, key)
        jax.block_until_ready((state, m))
        compile_s = time.perf_counter() - t0
        n = 3 if quick else 10
        t0 = time.perf_counter()
        for _ in range(n):
            state, m = tuner.step(state, key)
        jax.block_until_ready((state, m))
        step_s = (time.perf_counter() - t0) / n
        row = {"bench": "tune_forward_step", "backend": jax.default_backend(), "batch_size": batch,
               "actions": robot.num_actions, "map": list(cfg.shape), "noise_samples": cfg.num_noise_samples,
               "tuned": list(cfg.tuned_names()), "compile_s": round(compile_s, 3), "step_s": round(step_s, 5),
               "decisions_per_s": round(batch / step_s, 1)}
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows
