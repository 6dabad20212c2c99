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
import math
import re
import time
import types
import typing

from ijoy_jax.apps.options import assignments, output_folder

_SET_HELP = ("override one config field, VALUE parsed as JSON if it can be (0.05, [40, 40], true, \"x\"), "
             "else as a string, and checked against the field's type; repeatable, applied after --config")

_INT64 = 2**63  # an integer field holds a value of int64's range (a seed, a count)
_FLOAT_MAX = 1.7976931348623157e308  # float64's largest: beyond it a number is not finite


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
    for p, name in ((fwd, "forward"), (inv, "inverse")):
        p.add_argument("--out", default=f"results/tune_{name}", type=output_folder,
                       help="output folder (created; files in it are overwritten; default: %(default)s)")
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

    Checked when built: each field's type as annotated (numbers finite, lists as tuples; ``terrain``'s
    entries as the ForwardConfig fields they name) and its range; ValueError naming the field.
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

    def __post_init__(self):
        from ijoy_jax.tune import forward

        for name, value in _checked_fields(InverseConfig, vars(self), "InverseConfig").items():
            object.__setattr__(self, name, value)

        def need(ok, msg):
            if not ok:
                raise ValueError(f"InverseConfig: {msg}")

        robot_only = sorted({"density", "margin", "max_margin"} & set(self.terrain))
        need(not robot_only, f"terrain.{robot_only[0] if robot_only else ''}: set it at the top level (the "
                             "robot's, not the maps')")
        object.__setattr__(self, "terrain", _checked_fields(forward.ForwardConfig, self.terrain, "InverseConfig",
                                                            prefix="terrain."))
        bad = {k: v for k, v in self.hidden.items() if isinstance(v, bool) or not isinstance(v, (int, float))
               or not 0 < v < math.inf}
        need(not bad, f"hidden must map parameter names to finite numbers > 0, got {bad}")
        need(len(self.names) > 0, "names must name at least one parameter to fit")
        need(len(self.starts) > 0 and all(v > 0 for v in self.starts),
             f"starts must be one or more numbers > 0, got {list(self.starts)}")
        for name in ("num_train", "num_held_out"):
            need(getattr(self, name) >= 1, f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("density", "margin", "max_margin", "sharpness", "tau", "learning_rate"):
            need(getattr(self, name) > 0, f"{name} must be > 0, got {getattr(self, name)}")
        need(self.noise >= 0, f"noise must be >= 0, got {self.noise}")
        need(self.margin < self.max_margin, f"margin must be < max_margin={self.max_margin}, got {self.margin}")
        need(self.steps >= 1, f"steps must be >= 1, got {self.steps}")


def _parse_value(text: str):
    """A ``--set`` value: JSON where it parses (a number, a list, true, null, "x"), else the text itself."""
    try:
        return json.loads(text)
    except ValueError:  # not JSON; or an integer of more digits than Python converts
        return text


_KINDS = {float: "a finite number", int: "an integer", bool: "true or false", str: "a string",
          dict: "a table (JSON object)"}


def _field_value(cls, name: str, value, where: str, label: str | None = None):
    """``value`` for the field ``name`` of the config dataclass ``cls`` once it has the field's type (the
    annotation; a tuple's items the type of its default's items), as that type.

    Raises:
      ValueError: ``"<where>: <label> takes <type>, got <value>"`` (``label`` defaults to ``name``), one line;
        a range is the config's to check.
    """
    hint = typing.get_type_hints(cls)[name]
    options = typing.get_args(hint) if isinstance(hint, types.UnionType) else (hint,)
    if value is None and type(None) in options:
        return None
    kind = next(o for o in options if o is not type(None))
    default = next(f for f in dataclasses.fields(cls) if f.name == name).default
    items = {type(v) for v in default} if isinstance(default, tuple) else set()
    item = items.pop() if len(items) == 1 else None  # (60, 60): ints; (0.1, 1.0): numbers; ("w",): strings

    def fail(what: str):
        shown = repr(value) if len(repr(value)) <= 80 else repr(value)[:77] + "..."
        raise ValueError(f"{where}: {label or name} takes {what}, got {shown}")

    if kind is tuple:
        what = (f"a list of {_KINDS[item].removeprefix('a ').removeprefix('an ')}s" if item in _KINDS
                else "a list")
        if isinstance(value, dict) and not default:  # an empty default: a table of pairs too (terrain_params)
            return value
        if not isinstance(value, (list, tuple)):
            fail(what)
        return tuple(_scalar(item, v, lambda _: fail(what)) if item in _KINDS else v for v in value)
    return _scalar(kind, value, fail)


def _scalar(kind, value, fail):
    """``value`` as ``kind`` (float, int, bool, str, dict): bools are not numbers, numbers are finite, integers
    within int64; else ``fail(description)``."""
    ok = {float: lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v) <= _FLOAT_MAX,
          int: lambda v: isinstance(v, int) and not isinstance(v, bool) and -_INT64 <= v < _INT64,
          bool: lambda v: isinstance(v, bool), str: lambda v: isinstance(v, str),
          dict: lambda v: isinstance(v, dict)}[kind]
    if not ok(value):  # NaN fails abs(v) <= max, and an int beyond a float's range is compared exactly
        fail(_KINDS[kind] + (" within int64" if kind is int else ""))
    return float(value) if kind is float else value


def _checked_fields(cls, values: dict, where: str, prefix: str = "") -> dict:
    """Every ``values[name]`` checked against the type of ``cls``'s field (see :func:`_field_value`), named
    ``prefix + name`` in an error; a name that is not a field is refused, listing the fields."""
    known = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {[prefix + k for k in unknown]}; known: {sorted(known)}")
    return {k: _field_value(cls, k, v, where, prefix + k) for k, v in values.items()}


def _build_config(cls, args, extra: dict):
    """The config ``cls`` from ``--config``, then ``--set``, then the run-level flags in ``extra`` (None: not
    given); each value checked against its field's type, the error naming where it came from."""
    fields = {f.name for f in dataclasses.fields(cls)}
    given: dict = {}  # name -> (value, where it came from)
    if args.config:
        import tomllib

        with open(args.config, "rb") as f:  # OSError: the CLI prints it, naming the file
            try:
                table = tomllib.load(f)
            except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
                raise ValueError(f"--config {args.config}: not a valid TOML file ({e})") from None
        given.update({k: (v, f"--config {args.config}") for k, v in table.items()})
    for key, val in assignments(args.set, "distance=0.04").items():
        shown = val if len(val) <= 40 else val[:37] + "..."
        given[key] = (_parse_value(val), f"--set '{key}={shown}'")
    given.update({k: (v, f"--{k}") for k, v in extra.items() if v is not None})
    unknown = sorted(set(given) - fields)
    if unknown:
        raise ValueError(f"unknown config field(s) {unknown}; known: {sorted(fields)}")
    values = {k: _field_value(cls, k, v, where) for k, (v, where) in given.items()}
    try:
        return cls(**values)
    except ValueError as e:  # the config's own checks name the field: say where its value came from
        msg = str(e)
        found = [(m.start(), where) for k, (_, where) in given.items()
                 if (m := re.search(rf"\b{re.escape(k)}\b", msg))]
        raise ValueError(f"{min(found)[1]}: {msg}" if found else msg) from None


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

    from ijoy_jax import optim
    from ijoy_jax.tune import forward

    rows = []
    sizes = [(8, 0.5)] if quick else [(8, 0.5), (32, 0.5), (8, 1.0)]
    for batch, density in sizes:
        cfg = forward.ForwardConfig(batch_size=batch, density=density)
        robot = forward.paper_robot(cfg)
        tuner = optim.make_tuner(functools.partial(forward.objective, robot=robot, cfg=cfg),
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
