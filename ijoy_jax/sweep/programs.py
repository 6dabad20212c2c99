"""The programs that compute a sweep's chunks, their inputs, and one scenario rebuilt on the host.

Execution. Scenarios are grouped by action-set density (the only parameter
that changes an array shape) and each group is cut into chunks of
``chunk_size`` scenarios; a group's last chunk is padded (the padding rows are
computed and dropped) so every chunk of a group has one shape. One chunk is
one call of a jitted ``vmap`` over scenarios of: generate the terrain (its
family's parameters are traced per scenario; or the recorded terrain of
``[terrain] recording``, shared), ``robot.replace`` with the
scenario's traced leaves (w, rotation weight, margin, step time, footprint,
metric weights), the start stance from the terrain's start zone (or the
recorded start feet), and :func:`ijoy_jax.control.rollout` with the
scenario's commands, one per step: its held command repeated, or the
``[command] file``'s sequence (:mod:`ijoy_jax.sweep.recorded`), the same
program either way, returning
:meth:`ijoy_jax.Trajectory.summary` plus the family's extra metrics
(:meth:`ijoy_jax.terrain.family.Family.metrics`; bars: whether the robot got past them).

Physics (``walker = "mjx"``). The MJX robot of the sweep's model (:func:`ijoy_jax.sim.walker.make_sim`
for the sweep's grid and footprint, built once per run) walks instead of the
perfect robot, each scenario with its :class:`ijoy_jax.sim.physics.Dynamics`
(the ``sim.*`` columns) and noise key (``fold_in(terrain key, 1)``: replicate r
is pushed alike in every cell). A chunk is three programs: a vmap that
generates the terrains, robots and starts, the batch of simulated rollouts
through :func:`ijoy_jax.sim.walker.rollout_batch` itself (the Sim's MJX models
are traced arguments, shared and replicated like the targets; its program
is the one any caller of those shapes uses), and a vmap of
:func:`ijoy_jax.sim.walker.summary` and the family metrics. Everything else
(plan, chunk sizes, devices, parts, resume, processes, aggregates) is the
same as for the perfect robot.

Walk sweeps (``[terrain] walk``). The perfect robot's chunk is three programs too, as the physics chunk's: the
family's maps, robots and starts, the rollouts (one vmap of :func:`ijoy_jax.control.rollout`, the same program
for every family of the same shapes, so the benchmark's twelve families compile the selector's rollout once),
then the summaries.

Compiles (counted by :func:`trace_count`): parameter values never
recompile (physics values and the lookahead's discount neither: they are traced leaves); each density
value compiles once (its action-set size is a shape; no padding of action sets), and so does each value of
the selector's static options (``selector.horizon``, ``selector.refine``): chunks are grouped by density,
horizon and refinement. Static too: the terrain family, grid shape,
resolution, 2D/2.5D flag, ``num_steps``, ``method``, ``kernel``, ``walker`` and the chunk shape
``min(chunk_size, scenarios of that density)`` rounded up to a multiple of
the device count. When ``robot.rotation_weight`` is not swept, the targets F
and L_i are built once per density outside the jit and shared by every
scenario; when it is, each scenario sorts its own
(``|F|`` x N entries), a different compiled function.

The inputs of a chunk are built on the host (:func:`chunk_batch`: the scenarios' rows padded to the call's
shape; :func:`shared_inputs`: the density's base robot and targets; :func:`chunk_scene`: what every scenario
shares), and :func:`scenario` rebuilds one scenario exactly as a run does. :func:`scenario_bytes` measures a
chunk program's memory ahead of time for the chunk size (:mod:`ijoy_jax.sweep.sizing`).
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import robots
from ijoy_jax.control import rollout
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.select_options import SelectOptions
from ijoy_jax.sweep import fits, models, seeding
from ijoy_jax.sweep.expansion import scenarios
from ijoy_jax.sweep.schema import COMMAND_KEYS, ROBOT_DEFAULTS, SweepConfig, SweepConfigError, reach_of
from ijoy_jax.targets import make_targets
from ijoy_jax.terrain import generators, walk_families

__all__ = [
    "Scenario",
    "base_robot",
    "chunk_batch",
    "chunk_runner",
    "chunk_scene",
    "chunk_selector",
    "chunk_static",
    "compiled_programs",
    "make_sim",
    "physics_steps_per_scenario",
    "random_commands",
    "scenario",
    "scenario_bytes",
    "shared_inputs",
    "trace_count",
    "value_columns",
    "walk_summary",
]


class _Static(NamedTuple):
    """Everything about a chunk that is static under jit (hashable)."""

    family: str | None  # None: the recorded terrain of the shared _Scene, or the walk family's
    shape: tuple[int, int]
    resolution: float
    has_height: bool
    max_count: int | None
    num_steps: int
    walker: str
    selector: SelectOptions  # the chunk group's search (chunk_selector); its discount is each scenario's
    walk: str | None = None  # a walking-benchmark family (walk_families.FAMILIES): replicate r's map from its key


class _Scene(NamedTuple):
    """What every scenario of a run shares besides the robot (replicated over devices like the targets)."""

    first_swing: jax.Array  # () float32: +1 the left foot swings first
    terrain: Any = None  # the recorded Terrain ([terrain] recording), or None: the family generates one each
    start: jax.Array | None = None  # (2, 3) float32 the recorded start feet (left, right), or None


def chunk_scene(cfg: SweepConfig) -> _Scene:
    """The run's shared :class:`_Scene` (host arrays to the device)."""
    rec = cfg.terrain_recording
    first = jnp.float32(cfg.first_swing)
    if rec is None:
        return _Scene(first)
    return _Scene(first, rec.terrain, jnp.asarray(rec.start, jnp.float32))


def _setup(static: _Static, base: robots.Robot, key, scene: _Scene, seed, robot_vals, terrain_vals):
    """One scenario's terrain key, terrain parameters (None for a recorded terrain), terrain, robot and start
    stance."""
    tkey = jax.random.fold_in(key, seed)
    robot = robots.set_leaves(base, {k: robot_vals[k] for k in robots.SCALAR_LEAVES})
    if static.walk is not None:  # the family's map drawn from the replicate's key, the robot at its start
        terrain = walk_families.FAMILIES[static.walk].one(tkey, shape=static.shape, resolution=static.resolution)
        return tkey, None, terrain, robot, robots.start_stance(base, *walk_families.START)
    if static.family is None:  # the recorded terrain and start feet: the same for every scenario
        return tkey, None, scene.terrain, robot, scene.start
    fam = generators.FAMILIES[static.family]
    params = fam.params(**terrain_vals)
    kw = {} if static.max_count is None else {"max_count": static.max_count}
    terrain = fam.generator(
        tkey, params, shape=static.shape, resolution=static.resolution, has_height=static.has_height, **kw
    )
    centre = generators.start_point(params, shape=static.shape, resolution=static.resolution)
    start = robots.start_stance(base, centre[0], centre[1])  # side by side at the step-in-place width, facing +x
    return tkey, params, terrain, robot, start


def _family_metrics(static: _Static, tkey, params, feet, robot) -> dict:
    """The family's extra metrics (bars: whether the robot got past them), from the terrain it generated ({} for a
    recorded terrain)."""
    if static.family is None:
        return {}
    fam = generators.FAMILIES[static.family]
    return fam.metrics(
        tkey,
        params,
        feet,
        robot.foot_length,
        robot.foot_width,
        shape=static.shape,
        resolution=static.resolution,
        max_count=static.max_count,
    )


def walk_summary(traj, start, *, physics: bool = False) -> dict:
    """The walk metrics of one rollout (:data:`ijoy_jax.sweep.WALK_METRICS`, and with ``physics``
    :data:`ijoy_jax.sweep.WALK_PHYSICS_METRICS`); jit- and vmap-friendly, 0-d arrays.

    A step *made* is one taken that ended with the robot standing (``taken`` and not ``log.fallen``; every step
    taken when the trajectory has no log, the perfect robot). ``footholds_on_obstacles_made``: steps made onto an
    obstacle cell. ``progress`` (m): the midpoint of the feet along
    +x after the last step made (each step made puts its swing foot, ``traj.sides`` +1 left, at its
    ``traj.footsteps`` pose) minus that of ``start`` ((2, 3) start feet, left then right).
    """
    taken = traj.taken
    log = traj.log
    fallen = jnp.zeros_like(taken) if log is None else log.fallen
    made = taken & ~fallen
    k = jnp.arange(taken.shape[-1])

    def last_x(mask, row):
        i = jnp.max(jnp.where(mask, k, -1))
        return jnp.where(i >= 0, traj.footsteps[jnp.maximum(i, 0), 0], start[row, 0])

    left, right = last_x(made & (traj.sides > 0), 0), last_x(made & (traj.sides <= 0), 1)
    out = {
        "steps_made": jnp.sum(made, dtype=jnp.int32),
        "progress": 0.5 * (left + right - start[0, 0] - start[1, 0]),
        "footholds_on_obstacles_made": jnp.sum(made & traj.on_obstacle, dtype=jnp.int32),
    }
    if not physics:
        return out
    upright = jnp.concatenate([jnp.ones((1,), bool), ~fallen[:-1]])  # standing as the step began
    any_made = jnp.any(made)

    def p95(values):
        return jnp.where(any_made, jnp.nanpercentile(jnp.where(made, values, jnp.nan), 95), jnp.nan)

    out.update(
        standing_contacts=jnp.sum(log.obstacle_contact & upright, dtype=jnp.int32),
        made_placement_error_mean=jnp.where(
            any_made, jnp.sum(jnp.where(made, log.placement_error, 0.0)) / jnp.maximum(jnp.sum(made), 1), jnp.nan),
        made_placement_error_p95=p95(log.placement_error),
        made_tilt_error_p95=p95(log.tilt_error),
    )
    return out


def _scenario(static: _Static, base: robots.Robot, targets, key, scene, seed, robot_vals, terrain_vals, commands):
    """One scenario of the perfect robot: terrain, robot, start and rollout of its (num_steps, 3) commands; the
    trajectory's summary (scalars)."""
    tkey, params, terrain, robot, start = _setup(static, base, key, scene, seed, robot_vals, terrain_vals)
    options = static.selector
    if options.method == "lookahead":  # the scenario's discount, traced (the other methods do not read it)
        options = options.replace(discount=robot_vals["discount"])
    traj = rollout(terrain, robot, start, commands, static.num_steps, options, targets=targets,
                   first_swing=scene.first_swing)
    walk = {} if static.walk is None else walk_summary(traj, start)
    return {**traj.summary(), **_family_metrics(static, tkey, params, traj.feet, robot), **walk}


def _counting_traces(fn):
    """``fn`` wrapped to count its own traces, and the function that reads that count (the count lives in
    this closure, not in module state)."""
    traces = 0

    @functools.wraps(fn)  # jit reads the wrapped signature (static_argnames)
    def counted(*args, **kwargs):
        nonlocal traces
        traces += 1  # the wrapped function runs once per trace: counts compiles
        return fn(*args, **kwargs)

    return counted, lambda: traces


def _chunk(static: _Static, base, targets, key, sim, scene, seeds, robot_vals, terrain_vals, commands, sim_vals):
    """A chunk of the perfect robot: one vmapped program (``sim`` and ``sim_vals`` are None and {})."""
    fn = lambda s, r, t, c: _scenario(static, base, targets, key, scene, s, r, t, c)  # noqa: E731
    return jax.vmap(fn)(seeds, robot_vals, terrain_vals, commands)


_counted_chunk, _chunk_traces = _counting_traces(_chunk)
_run_chunk = jax.jit(_counted_chunk, static_argnames=("static",))


def _prepare(static: _Static, base, key, scene, seeds, robot_vals, terrain_vals):
    """A physics chunk's inputs of :func:`ijoy_jax.sim.walker.rollout_batch`: per scenario the terrain, robot,
    start and the key of its stance noise and pushes (``fold_in(terrain key, 1)``: replicate r's in every cell)."""

    def one(seed, r, t):
        tkey, _, terrain, robot, start = _setup(static, base, key, scene, seed, r, t)
        return terrain, robot, start, jax.random.fold_in(tkey, 1)

    return jax.vmap(one)(seeds, robot_vals, terrain_vals)


def _finish(static: _Static, base, key, scene, seeds, robot_vals, terrain_vals, traj) -> dict:
    """A chunk's per-scenario summary (a physics chunk's :func:`ijoy_jax.sim.walker.summary`), family metrics and
    walk metrics, after its rollouts."""
    physics = static.walker == "mjx"
    if physics:
        from ijoy_jax.sim import walker

    def one(seed, r, t, tr):
        tkey, params, _, robot, start = _setup(static, base, key, scene, seed, r, t)  # the terrain is not used
        walk = {} if static.walk is None else walk_summary(tr, start, physics=physics)
        summary = walker.summary(tr) if physics else tr.summary()
        return {**summary, **_family_metrics(static, tkey, params, tr.feet, robot), **walk}

    return jax.vmap(one)(seeds, robot_vals, terrain_vals, traj)


def _rollouts(targets, scene, terrains, robots_, starts, commands, discounts, *, selector: SelectOptions,
              num_steps: int):
    """The perfect robot's rollouts of a chunk whose maps come in (a walk sweep's): one program for every walk
    family of the same shapes (each scenario's discount traced, as in :func:`_scenario`)."""

    def one(t, r, s, c, d):
        options = selector.replace(discount=d) if selector.method == "lookahead" else selector
        return rollout(t, r, s, c, num_steps, options, targets=targets, first_swing=scene.first_swing)

    return jax.vmap(one)(terrains, robots_, starts, commands, discounts)


_counted_prepare, _prepare_traces = _counting_traces(_prepare)
_run_prepare = jax.jit(_counted_prepare, static_argnames=("static",))
_run_finish = jax.jit(_finish, static_argnames=("static",))
_counted_rollouts, _rollouts_traces = _counting_traces(_rollouts)
_run_rollouts = jax.jit(_counted_rollouts, static_argnames=("selector", "num_steps"))


def _walk_chunk(static: _Static, base, targets, key, sim, scene, seeds, robot_vals, terrain_vals, commands, sim_vals):
    """A chunk of the perfect robot on a walk family's maps (``[terrain] walk``), as a physics chunk is: the maps,
    robots and starts (a small program per family), the rollouts (:func:`_rollouts`, one program for every
    family), the summaries. (:func:`_chunk`, one program with the maps generated inside, would compile the
    selector's rollout once per family: twelve times for the benchmark.)"""
    terrains, robots_, starts, _ = _run_prepare(static, base, key, scene, seeds, robot_vals, terrain_vals)
    traj = _run_rollouts(targets, scene, terrains, robots_, starts, commands, robot_vals["discount"],
                         selector=static.selector, num_steps=static.num_steps)
    return _run_finish(static, base, key, scene, seeds, robot_vals, terrain_vals, traj)


def _physics_chunk(
    static: _Static, base, targets, key, sim, scene, seeds, robot_vals, terrain_vals, commands, sim_vals
):
    """A chunk of the MJX biped: the scenarios' terrains, robots and starts (one small program), their rollouts
    through :func:`ijoy_jax.sim.walker.rollout_batch` (its own program, shared with any other caller of the
    same shapes) with the scenarios' :class:`ijoy_jax.sim.physics.Dynamics`, then the summaries (another small
    program). Traced under one jit (:func:`scenario_bytes`) the three are one program."""
    from ijoy_jax.sim import physics, walker

    terrains, robots_, starts, keys = _run_prepare(static, base, key, scene, seeds, robot_vals, terrain_vals)
    traj = walker.rollout_batch(
        sim,
        terrains,
        robots_,
        starts,
        commands,
        static.selector,
        num_steps=static.num_steps,
        first_swing=scene.first_swing,
        targets=targets,
        dynamics=physics.Dynamics(**sim_vals),
        key=keys,
    )
    return _run_finish(static, base, key, scene, seeds, robot_vals, terrain_vals, traj)


def chunk_runner(static: _Static):
    """The function that runs a chunk: the perfect robot's jitted chunk, or three programs (the maps, the
    rollouts, the summaries) for the MJX biped and for the perfect robot on a walk family's maps."""
    if static.walker == "mjx":
        return _physics_chunk
    return _run_chunk if static.walk is None else _walk_chunk


def trace_count() -> int:
    """How many chunk programs have been traced (compiled) in this process: the perfect robot's chunk function,
    plus each physics or walk chunk shape's preparation and the perfect robot's rollouts of a walk chunk (a
    physics chunk's rollouts are :func:`ijoy_jax.sim.walker.rollout_batch`'s program, counted by
    :func:`ijoy_jax.sim.walker.compiled_programs`)."""
    return _chunk_traces() + _prepare_traces() + _rollouts_traces()


def compiled_programs() -> int:
    """How many programs the chunk functions of :func:`chunk_runner` hold compiled (in this process).

    The perfect robot's chunk and a physics chunk's preparation and summaries (its rollouts are counted by
    :func:`ijoy_jax.sim.walker.compiled_programs`). Read it before and after a run to learn how many compiles
    the run caused: each new static setting (:func:`chunk_static`) or chunk shape compiles once; new parameter
    values, seeds and commands reuse the program (:func:`trace_count` counts the traces behind them).
    """
    return (compiled_count(_run_chunk) + compiled_count(_run_prepare) + compiled_count(_run_finish)
            + compiled_count(_run_rollouts))


def base_robot(cfg: SweepConfig, table, density: float) -> robots.Robot:
    """The density's robot of the sweep's model (at the sweep's reach) with static windows covering the sweep's
    largest footprint and margin (:func:`ijoy_jax.sweep.models.build_robot`).

    Raises SweepConfigError when the largest footprint makes an action overlap the stance foot.
    """
    fl = float(table["robot.foot_length"].max())
    fw = float(table["robot.foot_width"].max())
    mm = max(float(table["robot.margin"].max()), 0.10)
    reach = reach_of(cfg)
    # hrp2 refuses a reach beyond max_sole_distance; the scenarios' own values replace this one, and load_config
    # checked a sweep's reach against each (a shorter limit at the paper's reach only refuses the far steps)
    msd = max(float(table["robot.max_sole_distance"].max()), models.robot_defaults(cfg.model)["max_sole_distance"])
    try:
        return models.build_robot(
            cfg.model,
            margin=0.0,
            density=density,
            reach=reach,
            foot_length=fl,
            foot_width=fw,
            max_margin=mm,
            max_sole_distance=msd,
        )
    except ValueError as e:
        raise SweepConfigError(
            f"{cfg.source}: robot.foot_length/robot.foot_width: a {fl} x {fw} m footprint "
            f"does not fit {models.MODEL_NAMES[cfg.model]}'s action set at density {density} and reach {reach} m: {e}"
        ) from None


class Scenario(NamedTuple):
    """One scenario of a sweep, rebuilt on the host (:func:`scenario`).

    terrain: its generated :class:`~ijoy_jax.Terrain` (or the recorded one); robot: its :class:`~ijoy_jax.Robot`
    (the density's action set, the scenario's leaves); start: (2, 3) float32 feet (left, right; m, rad);
    command: (3,) float32 its held command (m/s, m/s, rad/s), or (num_steps, 3) one per step when the commands
    come from ``[command] file`` or are drawn every step (``[command] random``); cell, replicate: its cell and
    replicate (its terrain key is ``fold_in(key(seed), replicate)``); first_swing: +1 if the left foot swings first. So
    ``ijoy_jax.rollout(s.terrain, s.robot, s.start, s.command, num_steps, first_swing=s.first_swing)`` walks it
    as the sweep does (the perfect robot).
    """

    terrain: Any
    robot: robots.Robot
    start: np.ndarray
    command: np.ndarray
    cell: int
    replicate: int
    first_swing: int = 1


def scenario(cfg: SweepConfig, scenario_id: int) -> Scenario:
    """The terrain, robot, start and command of scenario ``scenario_id`` of a sweep, exactly as a run builds them.

    For walking one scenario by hand (``ijoy drive --scenario FILE:ID``) or looking at it. Only the rows up
    to ``scenario_id`` are expanded (:func:`ijoy_jax.sweep.scenarios` with ``max_scenarios``).

    Raises:
      SweepConfigError: the id is not a scenario of the sweep.
    """
    if (
        isinstance(scenario_id, bool)
        or not isinstance(scenario_id, (int, np.integer))
        or not (0 <= scenario_id < cfg.num_scenarios)
    ):
        raise SweepConfigError(
            f"{cfg.source}: scenario {scenario_id!r} does not exist (the sweep has "
            f"{cfg.num_scenarios} scenarios, ids 0 to {cfg.num_scenarios - 1})"
        )
    table = scenarios(cfg, max_scenarios=int(scenario_id) + 1)
    row = table.iloc[[int(scenario_id)]]
    density = float(row["robot.density"].iloc[0])
    base = base_robot(cfg, table, density)
    robot_cols, terrain_cols, _ = value_columns(table)
    replicate, robot_vals, terrain_vals, commands, _ = chunk_batch(row, 1, robot_cols, terrain_cols, cfg=cfg,
                                                                   base=base)
    one = lambda d: {k: v[0] for k, v in d.items()}  # noqa: E731
    _, _, terrain, robot, start = _setup(
        chunk_static(cfg),
        base,
        jax.random.key(cfg.seed),
        chunk_scene(cfg),
        replicate[0],
        one(robot_vals),
        one(terrain_vals),
    )
    command = commands[0] if not cfg.command_columns else commands[0, 0]  # (num_steps, 3) or held (3,)
    return Scenario(
        terrain,
        robot,
        np.asarray(start, np.float32),
        np.asarray(command, np.float32),
        int(row["cell"].iloc[0]),
        int(replicate[0]),
        cfg.first_swing,
    )


def random_commands(cfg: SweepConfig, base: robots.Robot, replicates, step_time) -> np.ndarray:
    """(n, num_steps, 3) float32 ``[command] random``'s commands: replicate r's ``default_rng([seed, 2, r])
    .random(3 * num_steps)`` (:func:`ijoy_jax.sweep.seeding.first_doubles`, step by step, vx, vy, wz) mapped
    onto :func:`ijoy_jax.robots.command_range` of ``base`` (the density's action set) at each scenario's
    ``step_time`` (s, (n,)): the same commands for replicate r in every cell of a step time."""
    reps = np.asarray(replicates, np.int64)
    dt = np.asarray(step_time, np.float32)
    u = seeding.first_doubles([cfg.seed, 2], reps, 3 * cfg.num_steps).reshape(len(reps), cfg.num_steps, 3)
    out = np.empty(u.shape, np.float32)
    for t in np.unique(dt):
        lo, hi = robots.command_range(base.replace(step_time=jnp.float32(t)))
        rows = dt == t
        out[rows] = lo + u[rows] * (hi - lo)
    return out


def chunk_batch(rows, size: int, robot_cols, terrain_cols, sim_cols=(), *, cfg: SweepConfig, base=None):
    """Per-scenario inputs of a chunk: ``rows`` padded to ``size`` by repeating the last one (NumPy): the
    replicates, robot values, terrain values, commands (size, num_steps, 3) (each scenario's held command at
    every step, the ``[command] file``'s sequence, or with ``[command] random`` its :func:`random_commands` at
    the density's ``base`` robot; the same program each way) and physics values ({} for the perfect robot)."""
    n = len(rows)
    pad = np.concatenate([np.arange(n), np.full(size - n, n - 1)])

    def col(name, dtype):
        return np.asarray(rows[name].to_numpy()[pad], dtype)

    robot_vals = {c.partition(".")[2]: col(c, np.float32) for c in robot_cols}
    terrain_vals = {
        c.partition(".")[2]: col(c, np.int32 if rows[c].dtype.kind == "i" else np.float32) for c in terrain_cols
    }
    steps = cfg.command_steps
    if cfg.random_commands:
        commands = random_commands(cfg, base, col("replicate", np.int64), col("robot.step_time", np.float32))
    elif steps is None:
        held = np.stack([col(f"command.{k}", np.float32) for k in COMMAND_KEYS], axis=-1)
        commands = np.repeat(held[:, None, :], cfg.num_steps, axis=1)
    else:
        commands = np.repeat(np.asarray(steps, np.float32)[None], size, axis=0)
    sim_vals = {c.partition(".")[2]: col(c, np.float32) for c in sim_cols}
    return col("replicate", np.int32), robot_vals, terrain_vals, commands, sim_vals


def shared_inputs(table, base):
    """Per-density inputs shared by every scenario: (base robot, targets or None when each scenario sorts)."""
    if table["robot.rotation_weight"].nunique() > 1:
        return base, None
    return base, make_targets(base.replace(rotation_weight=jnp.float32(table["robot.rotation_weight"].iloc[0])))


def value_columns(table):
    """The scenario table's columns a chunk takes per scenario: (robot values, terrain values, physics values)."""
    # The lookahead's discount travels with the robot values (traced per scenario, like them).
    robot_cols = [f"robot.{k}" for k in ROBOT_DEFAULTS if k not in ("density", "reach")] + ["selector.discount"]
    return (
        robot_cols,
        [c for c in table.columns if c.startswith("terrain.")],
        [c for c in table.columns if c.startswith("sim.")],
    )


def chunk_selector(cfg: SweepConfig, horizon: int, refine: bool) -> SelectOptions:
    """The search of a chunk group: the sweep's method and kernel with that group's ``horizon`` and ``refine``
    (``selector.horizon``, ``selector.refine``), and the sweep's beam for horizons of 3 or more (2 is searched
    exactly). Its discount is the default: each scenario sets its own (``selector.discount``, traced)."""
    lookahead = cfg.method == "lookahead"
    return SelectOptions(
        method=cfg.method,
        kernel=cfg.kernel,
        horizon=int(horizon) if lookahead else 1,
        beam=cfg.beam if lookahead and horizon >= 3 else None,
        refine=bool(refine),
    )


def chunk_static(cfg: SweepConfig, horizon: int | None = None, refine: bool | None = None) -> _Static:
    """The chunk's static configuration (``family`` None for a recorded terrain), for the chunk group of
    ``horizon`` and ``refine`` (None: the sweep's fixed ``horizon`` and ``refine``)."""
    return _Static(
        cfg.family,
        cfg.shape,
        cfg.resolution,
        cfg.has_height,
        cfg.static_max_count,
        cfg.num_steps,
        cfg.walker,
        chunk_selector(cfg, cfg.horizon if horizon is None else horizon, cfg.refine if refine is None else refine),
        cfg.walk,
    )


def make_sim(cfg: SweepConfig, table):
    """The MJX robot of a ``walker = "mjx"`` sweep: its model's (``make_sim(..., model=cfg.model)``: the
    project's biped or the G1), its map's grid, the sweep's fixed footprint and step time
    (:func:`ijoy_jax.sweep.fits.walk_config`; host-side, no compile); or None for the perfect robot."""
    if cfg.walker != "mjx":
        return None
    from ijoy_jax.sim import walker

    fixed = {k: float(table[f"robot.{k}"].iloc[0]) for k in ("foot_length", "foot_width", "step_time")}
    return walker.make_sim(cfg.shape, cfg.resolution, cfg=fits.walk_config(cfg),
                           robot=models.build_robot(cfg.model, **fixed), model=cfg.model)


def physics_steps_per_scenario(sim, num_steps: int) -> int:
    """Physics steps of one simulated rollout of ``num_steps`` steps
    (:attr:`ijoy_jax.sweep.RunStats.physics_steps`): the steps and the standing warm-up step, each of control
    ticks of physics steps; 0 without a Sim."""
    return 0 if sim is None else (num_steps + 1) * sim.cfg.ticks_per_step * sim.substeps


def scenario_bytes(cfg: SweepConfig, table, base: robots.Robot, sim=None) -> tuple[int, int]:
    """Device bytes of a chunk, from the compiled chunk function for one scenario (AOT: nothing runs).

    ``jit(...).lower(...).compile().memory_analysis()`` of a one-scenario chunk with ``base`` (pass
    the largest action set: memory grows with it), split into what every scenario adds (its inputs,
    outputs and XLA temporaries) and what the chunk holds once (the shared base robot, target tables
    and key, e.g. 27 MB for 496 actions, 0.9 GB for 3307; with ``walker = "mjx"`` also the MJX models of
    ``sim``, built when None). The per-scenario part is an upper bound of the temporaries' measured slope
    over batch sizes (BENCHMARKS.md has the figures). A physics chunk is measured as one program (its
    three programs traced under one jit).

    Returns:
      ``(per_scenario, shared)`` in bytes.
    """
    robot_cols, terrain_cols, sim_cols = value_columns(table)
    base, targets = shared_inputs(table, base)
    key = jax.random.key(cfg.seed)
    sim = make_sim(cfg, table) if sim is None else sim
    batch = chunk_batch(table.iloc[:1], 1, robot_cols, terrain_cols, sim_cols, cfg=cfg, base=base)
    heaviest = chunk_static(
        cfg, int(table["selector.horizon"].max()), bool(table["selector.refine"].max())
    )  # the most memory per scenario
    runner = chunk_runner(heaviest)
    runner = runner if runner is _run_chunk else jax.jit(runner, static_argnames=("static",))
    compiled = runner.lower(heaviest, base, targets, key, sim, chunk_scene(cfg), *batch).compile()
    mem = compiled.memory_analysis()
    if mem is None:
        raise RuntimeError("the backend reports no memory analysis")
    # Arguments are the per-scenario inputs plus the shared ones jit keeps (unused leaves are pruned).
    inputs = sum(int(x.nbytes) for x in jax.tree.leaves(batch))
    shared = max(0, int(mem.argument_size_in_bytes) - inputs)
    return inputs + int(mem.output_size_in_bytes + mem.temp_size_in_bytes), shared
