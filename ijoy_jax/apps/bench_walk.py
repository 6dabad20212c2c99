"""Walking benchmark per terrain family: ``ijoy bench walk``, the perfect robot next to the MJX biped.

On one GPU (H100 or H200), the whole default run (11 families x 2 command kinds x 1024 robots x 30 steps,
one MJX compile; 0.28 G physics steps, several minutes)::

    ijoy bench walk --batch 1024 --steps 30 --json out/walk.json --plot out/walk.png

(``python -m ijoy_jax.apps.cli bench walk ...`` where the ``ijoy`` script is not installed; ``--families``
takes a comma-separated subset, e.g. to split the run in two). A smoke test on a CPU (4 robots, 6 steps,
two to three minutes on two cores, a minute of it the one MJX compile)::

    ijoy bench walk --quick --json /tmp/walk.json --plot /tmp/walk.png

Every robot walks HRP-2's joystick loop (margin 2 cm, 496 actions, ``method="ordered"``) on its own
5 m x 2 m map of 2 cm cells (250 x 100), drawn from its family's parameter range (:data:`FAMILIES`),
standing at ``x = 0.5 m`` on the centre line (``y = 1 m``) facing +x, for ``steps`` steps, once with
a new random command every step inside the action set's range (:func:`ijoy_jax.robots.random_commands`)
and once with a held forward command (:data:`FORWARD` m/s). Each (family, commands) pair runs the
paper's perfect robot (:func:`ijoy_jax.control.rollout`, vmapped) and the simulated biped
(:func:`ijoy_jax.sim.walker.rollout_batch`) on the same maps with the same commands, and gives one row
per walker (:func:`aggregate`): falls, stops, progress along +x, obstacle contacts, placement and
sole-tilt errors, and the timings (compile time from JAX's own compile events, run time, physics steps/s).

One compile for everything. Every family is a 2.5D map (``has_height=True``; 2D clutter is stored as the
2.5D map the physics makes of it) of one grid shape and resolution, every command schedule is
(B, steps, 3), the robots share one action set, and one :class:`ijoy_jax.sim.walker.Sim` serves every
family, so :func:`ijoy_jax.sim.walker.rollout_batch` compiles once and every later family only changes
traced heights and free masks; each row says how many new programs its call compiled
(:func:`ijoy_jax.sim.walker.compiled_programs`) and the last record gives the total. A family whose robot
has another action set (the stairs, with ``robots.hrp2(reach=0.30)``) compiles once more.
The Sim's height field spans :data:`HEIGHT_RANGE` (the stairs and 10 deg slopes rise or fall up to
0.9 m over the map).

The families and their map geometry (:data:`FAMILIES`, :data:`START`, :func:`grid_shape`, ...) live in
:mod:`ijoy_jax.terrain.walk_families` and are named here too; this module is the benchmark: the runner, the
aggregation, the table and the plot.

Outputs: JSON records (:func:`run`), the Markdown table of BENCHMARKS.md (:func:`markdown_table`) and a
bar plot of falls, stops and progress per family, perfect and simulated side by side (:func:`plot`).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import ijoy_jax.sim  # noqa: F401  before mujoco: headless EGL, and mjx imported without the warp lines

# isort: split
import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import control, robots, select
from ijoy_jax.extras import require
from ijoy_jax.jit_cache import compile_seconds, compiled_count
from ijoy_jax.select_options import SelectOptions
from ijoy_jax.sim import model
from ijoy_jax.sim import walker as W
from ijoy_jax.terrain import Terrain

# The terrain families live in ijoy_jax.terrain.walk_families; the benchmark names them where it always did.
from ijoy_jax.terrain.walk_families import (  # noqa: F401
    CLUTTER,
    CLUTTER_HEIGHT,
    FAMILIES,
    IMAGE_EXPONENT,
    IMAGE_PIXELS,
    IMAGE_RMS,
    IMAGE_SCALE,
    IMAGE_WAVELENGTHS,
    PAD_FRONT,
    PLATFORM_HEIGHT_MAX,
    PLATFORM_HEIGHT_MIN,
    RESOLUTION,
    ROUGH_CORRELATION,
    ROUGH_RMS,
    SIZE,
    SLOPE_DEG,
    STAIR_COUNT,
    STAIR_FIRST,
    STAIR_FORWARD,
    STAIR_REACH,
    STAIR_RISE,
    STAIR_RUNS,
    START,
    START_RADIUS,
    STONES,
    WalkFamily,
    clutter2d,
    cross,
    downhill,
    flat_maps,
    grid_shape,
    ground_image,
    image,
    load_ground,
    platforms,
    rough,
    rough_params,
    stairs_down,
    stairs_up,
    start_zone,
    stone_row,
    stones,
    uphill,
    window_offsets,
    write_ground_png,
)

HEIGHT_RANGE = (model.BipedParams.z_lo, model.BipedParams.z_hi)
"""z_lo, z_hi (m) of the Sim's height field (the biped's defaults): every family's heights lie inside (tested)."""
FORWARD = 0.25
"""Held forward command (m/s): the paper's action set's fastest, 0.2 m steps of 0.8 s; on open ground the robot
reaches the far edge of the 5 m map after about 21 steps and marks time there."""
COMMANDS = ("random", "forward")


def start_stances(robot: robots.Robot, batch: int) -> jax.Array:
    """(batch, 2, 3) start feet (left, right): side by side at :data:`START`, facing +x, ``p0`` apart."""
    return jnp.broadcast_to(robots.start_stance(robot, *START), (batch, 2, 3))


def family_robot(family: WalkFamily) -> robots.Robot:
    """The family's robot: ``robots.hrp2()``, or ``robots.hrp2(reach=...)`` for a family with its own reach."""
    return robots.hrp2() if family.reach is None else robots.hrp2(reach=family.reach)


# --------------------------------------------------------------------------------------------- the benchmark

WALKERS = ("perfect", "mjx")
"""The perfect robot (:func:`ijoy_jax.control.perfect_walker`) and the MJX biped (:mod:`ijoy_jax.sim.walker`)."""
def forward_commands(batch: int, steps: int, speed: float = FORWARD) -> jax.Array:
    """(batch, steps, 3) the held forward command ``(speed, 0, 0)`` (m/s, m/s, rad/s) for every robot and step."""
    return jnp.broadcast_to(jnp.asarray([speed, 0.0, 0.0], jnp.float32), (batch, steps, 3))


def commands_for(kind: str, key, robot: robots.Robot, batch: int, steps: int, speed: float = FORWARD) -> jax.Array:
    """(batch, steps, 3) commands of a kind: "random" (:func:`ijoy_jax.robots.random_commands`, a new one every
    step inside the action set's range) or "forward" (:func:`forward_commands`)."""
    if kind == "random":
        return robots.random_commands(key, robot, batch, steps)
    if kind == "forward":
        return forward_commands(batch, steps, speed)
    raise ValueError(f"commands must be one of {COMMANDS}, got {kind!r}")


def _percentile(values, q) -> float | None:
    values = np.asarray(values, np.float64).ravel()
    return float(np.percentile(values, q)) if values.size else None


def touchdown_feet(traj: control.Trajectory, start, mask) -> np.ndarray:
    """(B, 2, 3) the feet after the last step of ``mask`` (B, T): the start feet with each masked step's
    foothold (``traj.footsteps``, the measured touch-down of a simulated robot) put down by its swing foot
    (``traj.sides``: +1 left, row 0). With ``mask = traj.taken`` and the perfect robot it is ``traj.feet``."""
    steps, sides, mask = np.asarray(traj.footsteps), np.asarray(traj.sides), np.asarray(mask, bool)
    feet = np.array(np.broadcast_to(np.asarray(start, np.float64), (mask.shape[0], 2, 3)))
    rows = np.arange(mask.shape[0])
    for k in range(mask.shape[1]):
        row = np.where(sides[:, k] > 0, 0, 1)
        feet[rows, row] = np.where(mask[:, k, None], steps[:, k], feet[rows, row])
    return feet


def aggregate(traj: control.Trajectory, start) -> dict[str, Any]:
    """The benchmark's numbers for a batch of rollouts (leading axis B on every leaf of ``traj``).

    A simulated robot's steps count while it stands: a step "made" is one taken that ended with the
    robot standing (``taken`` and not ``log.fallen``); after a fall the loop may go on choosing steps
    that the robot no longer makes. The perfect robot never falls: its steps made are those taken.

    Keys: ``robots``; ``fell`` / ``fell_pct`` (robots that fell; 0 for the perfect robot); ``stops`` /
    ``stops_pct``, robots that stopped walking before the last step without falling (no valid foothold:
    the loop stops, Algorithm 1's StopWalking); ``progress_mean_m`` / ``progress_min_m``, how far the
    midpoint of the feet moved along +x from ``start`` ((B, 2, 3) or (2, 3) start feet) to their
    touch-downs after the last step made (:func:`touchdown_feet`); ``steps_made_mean``;
    ``footholds_on_obstacles`` (steps made onto an obstacle cell, bare footprint); ``unsupported_decisions``.
    With a simulated robot's log (:class:`ijoy_jax.sim.walker.StepLog`), also ``obstacle_contacts``
    (steps begun standing during which a sole or shin touched an obstacle cell) and
    ``robots_with_contact``; over every step made by every robot, ``placement_error_mean_m`` /
    ``_p95_m``, ``yaw_error_p95_rad`` and ``tilt_error_p95_rad`` (the angle between a landed sole's normal
    and its foothold's, ``StepLog.tilt_error``). These are None for the perfect robot (not measured).
    """
    taken = np.asarray(traj.taken, bool)
    b = taken.shape[0]
    log = traj.log
    fallen = np.zeros_like(taken) if log is None else np.asarray(log.fallen, bool)
    made = taken & ~fallen
    upright = np.concatenate([np.ones((b, 1), bool), ~fallen[:, :-1]], axis=1)  # standing as the step began
    fell = fallen.any(axis=1)
    stops = np.asarray(traj.stopped, bool).any(axis=1) & ~fell
    start = np.broadcast_to(np.asarray(start, np.float64), (b, 2, 3))
    progress = touchdown_feet(traj, start, made)[:, :, 0].mean(axis=1) - start[:, :, 0].mean(axis=1)
    out: dict[str, Any] = dict(
        robots=int(b),
        fell=int(fell.sum()),
        fell_pct=100.0 * float(fell.mean()),
        stops=int(stops.sum()),
        stops_pct=100.0 * float(stops.mean()),
        progress_mean_m=float(progress.mean()),
        progress_min_m=float(progress.min()),
        steps_made_mean=float(made.sum(axis=1).mean()),
        footholds_on_obstacles=int((np.asarray(traj.on_obstacle, bool) & made).sum()),
        unsupported_decisions=int(np.asarray(traj.unsupported, bool).sum()),
    )
    if log is None:
        out.update(obstacle_contacts=None, robots_with_contact=None, placement_error_mean_m=None,
                   placement_error_p95_m=None, yaw_error_p95_rad=None, tilt_error_p95_rad=None)
        return out
    contact = np.asarray(log.obstacle_contact, bool) & upright
    err = np.asarray(log.placement_error, np.float64)[made]
    out.update(
        obstacle_contacts=int(contact.sum()),
        robots_with_contact=int(contact.any(axis=1).sum()),
        placement_error_mean_m=float(err.mean()) if err.size else None,
        placement_error_p95_m=_percentile(err, 95),
        yaw_error_p95_rad=_percentile(np.asarray(log.yaw_error, np.float64)[made], 95),
        tilt_error_p95_rad=_percentile(np.asarray(log.tilt_error, np.float64)[made], 95),
    )
    return out


def _to_host(tree):
    return jax.tree_util.tree_map(np.asarray, tree)


def _stack_robot(robot: robots.Robot, batch: int) -> robots.Robot:
    return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (batch, *np.shape(x))), robot)


def walk_options(*, refine: bool = False, kernel: str = "xla") -> SelectOptions:
    """Both walkers' search: the paper's ordered selector with FootCost's ``kernel`` ("xla" or "pallas"), each
    lattice choice refined to a continuous foothold when ``refine`` (:mod:`ijoy_jax.refine`)."""
    return SelectOptions(method="ordered", kernel=kernel, refine=refine)


def perfect_rollouts(terrains: Terrain, robot: robots.Robot, starts, commands, options: SelectOptions | None = None,
                     *, num_steps: int, targets=None) -> control.Trajectory:
    """The perfect robot on B maps: one jitted ``vmap`` of :func:`ijoy_jax.control.rollout`.

    ``terrains``, ``starts`` (B, 2, 3) and ``commands`` (B, num_steps, 3) are batched; the robot and its
    targets (:func:`ijoy_jax.make_targets`, built when None) are shared, and traced: new maps, commands or
    robot values reuse the compiled program. ``options``: the search (None: :func:`walk_options`' default,
    the ordered selector; refinement is one more program).
    """
    targets = select.make_targets(robot) if targets is None else targets
    options = walk_options() if options is None else options
    return _perfect_jit(terrains, robot, starts, commands, targets, options, num_steps=int(num_steps))


@functools.partial(jax.jit, static_argnames=("num_steps",))
def _perfect_jit(terrains, robot, starts, commands, targets, options, *, num_steps: int):
    def one(t, s, c):
        return control.rollout(t, robot, s, c, num_steps, options, targets=targets)

    return jax.vmap(one)(terrains, starts, commands)


def _timed(fn, *args, **kwargs):
    """Run ``fn(*args, **kwargs)`` to completion; return (result on the host, compile seconds, run seconds)."""
    with compile_seconds() as compiled:
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args, **kwargs))
        wall = time.perf_counter() - t0
    return _to_host(out), compiled[0], max(wall - compiled[0], 0.0)


def simulated_rollouts(sim: W.Sim, terrains: Terrain, robot: robots.Robot, starts, commands,
                       options: SelectOptions | None = None, *, num_steps: int, chunk: int, targets=None):
    """The MJX biped on B maps, ``chunk`` rollouts per :func:`ijoy_jax.sim.walker.rollout_batch` call
    (``options``: its selector's search, as :func:`perfect_rollouts`).

    Every call has ``chunk`` rollouts (the last chunk wraps round to the first maps, its extra rollouts
    dropped), so all calls share one compiled program. Returns (trajectory on the host with leading axis B,
    compile seconds, run seconds).
    """
    total = int(np.shape(starts)[0])
    targets = select.make_targets(robot) if targets is None else targets
    options = walk_options() if options is None else options
    stacked = _stack_robot(robot, chunk)
    parts, comp, run_s = [], 0.0, 0.0
    for lo in range(0, total, chunk):
        idx = np.arange(lo, lo + chunk) % total
        part, c, r = _timed(W.rollout_batch, sim, jax.tree_util.tree_map(lambda x, idx=idx: x[idx], terrains),
                            stacked, starts[idx], commands[idx], options, num_steps=num_steps, targets=targets)
        parts.append(jax.tree_util.tree_map(lambda a, n=min(chunk, total - lo): a[:n], part))
        comp, run_s = comp + c, run_s + r
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *parts), comp, run_s


def _device_info() -> dict[str, str]:
    import mujoco

    return dict(device=str(jax.devices()[0].device_kind), jax=jax.__version__, mujoco=mujoco.__version__)


def check_options(families: Sequence[str] | None, *, batch: int, steps: int, commands: Sequence[str],
                  resolution: float, chunk: int | None, walkers: Sequence[str], forward: float) -> list[str]:
    """Validate :func:`run`'s options before any compute; returns the family names in table order."""
    names = list(FAMILIES) if families is None else list(families)
    unknown = [n for n in names if n not in FAMILIES]
    if unknown or not names:
        raise ValueError(f"unknown terrain families {unknown}; known: {', '.join(FAMILIES)}")
    for label, value in (("batch", batch), ("steps", steps), ("chunk", 1 if chunk is None else chunk)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{label} must be a positive int, got {value!r}")
    bad = [c for c in commands if c not in COMMANDS]
    if bad or not commands:
        raise ValueError(f"commands must be some of {COMMANDS}, got {list(commands)}")
    bad = [w for w in walkers if w not in WALKERS]
    if bad or not walkers:
        raise ValueError(f"walkers must be some of {WALKERS}, got {list(walkers)}")
    if not (math.isfinite(forward) and 0 <= forward):
        raise ValueError(f"forward speed must be a finite number of m/s >= 0, got {forward!r}")
    grid_shape(resolution)
    return [n for n in FAMILIES if n in names]


def check_robot_leaves(values: Mapping[str, float] | None) -> dict[str, float]:
    """Validate :func:`run`'s ``robot_leaves`` (names in :data:`ijoy_jax.robots.SELECTOR_LEAVES`, values that
    :func:`ijoy_jax.robots.check_robot` accepts on the preset); returns them as a dict of floats."""
    values = {} if values is None else dict(values)
    unknown = [n for n in values if n not in robots.SELECTOR_LEAVES]
    if unknown:
        raise ValueError(f"unknown robot leaves {unknown}; the choice's leaves: {', '.join(robots.SELECTOR_LEAVES)}")
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ValueError(f"robot.{name} must be a number, got {value!r}")
    out = {n: float(v) for n, v in values.items()}
    robots.check_robot(robots.set_leaves(robots.hrp2(), out))  # names the first bad value
    return out


def run(families: Sequence[str] | None = None, *, batch: int = 1024, steps: int = 30,
        commands: Sequence[str] = COMMANDS, resolution: float = RESOLUTION, seed: int = 0, chunk: int | None = None,
        walkers: Sequence[str] = WALKERS, forward: float = FORWARD, refine: bool = False, kernel: str = "xla",
        robot_leaves: Mapping[str, float] | None = None,
        emit: Callable[[dict], None] | None = None) -> list[dict[str, Any]]:
    """Walk ``batch`` robots per family and command kind with each walker; one record per row (and skips).

    Args:
      families: names in :data:`FAMILIES` (None: all), run in the registry's order.
      batch: robots (maps) per family; steps: steps per rollout.
      commands: some of :data:`COMMANDS`; the same maps serve both kinds.
      resolution: cell size (m) of the 5 m x 2 m maps.
      seed: maps and random commands: a family's come from ``fold_in(seed, i)``, i its index in
        :data:`FAMILIES`, so it walks the same maps and commands whichever families run beside it.
      chunk: simulated rollouts per jitted call (equal chunks, one compile): default ``batch`` up to 1024 on an
        accelerator (a rollout holds tens of MB of selector windows; 1024 ran more physics steps/s than 512,
        docs/benchmarks_history.md), 32 on a CPU.
      walkers: some of :data:`WALKERS`.
      forward: the held forward command (m/s) of families without their own (:attr:`WalkFamily.forward`).
      refine: both walkers refine each lattice choice to a continuous foothold (:mod:`ijoy_jax.refine`,
        ``SelectOptions(refine=True)`` of :func:`ijoy_jax.control.rollout` and
        :func:`ijoy_jax.sim.walker.rollout_batch`).
      kernel: FootCost's implementation in both walkers' selector (:data:`ijoy_jax.select.KERNELS`): "xla", or
        "pallas", the fused kernel (on a GPU it compiles the MJX program several seconds faster, BENCHMARKS.md;
        on a CPU it is interpreted, slowly). Recorded in each row.
      robot_leaves: values of the selector's robot leaves (:data:`ijoy_jax.robots.SELECTOR_LEAVES` by dotted
        name, e.g. ``{"metrics.support_limit": 0.003}``) set on every family's robot: both walkers choose with
        them; traced, so they reuse the compiled programs. Recorded in each row as ``robot_leaves``.
      emit: called with each record as soon as it exists (e.g. to print JSON lines).

    Returns:
      Records (dicts) with ``name`` "walk": ``family``, ``commands``, ``walker``, the numbers of
      :func:`aggregate`, ``compile_s`` and ``run_s`` (compile time from JAX's compile events, run time the
      rest of the wall time), ``physics_steps_per_s`` (simulated: robots x (steps + the standing step) x
      physics steps per step / run time) or ``decisions_per_s`` (perfect), ``new_compiles`` (programs the
      simulated rows' calls added to :func:`ijoy_jax.sim.walker.compiled_programs`), and the setup;
      ``skipped`` (the reason) for a family whose robot cannot be built; and a last record ``name``
      "walk_compiles" with the totals.
    """
    names = check_options(families, batch=batch, steps=steps, commands=commands, resolution=resolution,
                          chunk=chunk, walkers=walkers, forward=forward)
    leaves = check_robot_leaves(robot_leaves)
    if not isinstance(refine, (bool, np.bool_)):
        raise ValueError(f"refine must be True or False, got {refine!r}")
    refine = bool(refine)
    options = walk_options(refine=refine, kernel=kernel)  # the strings of the command line, as one object
    shape = grid_shape(resolution)
    if chunk is None:
        chunk = min(batch, 32 if jax.default_backend() == "cpu" else 1024)
    chunk = min(int(chunk), batch)
    emit = (lambda row: None) if emit is None else emit
    rows: list[dict[str, Any]] = []

    def record(row):
        rows.append(row)
        emit(row)

    base = robots.hrp2()
    sim = None
    if "mjx" in walkers:
        sim = W.make_sim(shape, resolution, robot=base)
    info = _device_info()
    programs0, t_all = W.compiled_programs(), time.perf_counter()
    perfect_compile = 0.0
    setup = dict(batch=batch, steps=steps, resolution=resolution, shape=list(shape), chunk=chunk, seed=seed,
                 forward_m_s=forward, refine=refine, kernel=kernel, robot_leaves=leaves, **info)
    key = jax.random.key(seed)
    for name in names:
        fam = FAMILIES[name]
        try:
            robot = robots.set_leaves(family_robot(fam), leaves)
        except TypeError as e:
            record(dict(name="walk", family=name, skipped=f"robots.hrp2(reach={fam.reach}) failed: {e}", **setup))
            continue
        robot_name = "hrp2()" if fam.reach is None else f"hrp2(reach={fam.reach})"
        k_map, k_cmd = jax.random.split(jax.random.fold_in(key, list(FAMILIES).index(name)))
        t0 = time.perf_counter()
        maps = jax.block_until_ready(fam.maps(k_map, batch, shape=shape, resolution=resolution))
        maps_s = time.perf_counter() - t0
        lo, hi = float(jnp.min(maps.height)), float(jnp.max(maps.height))
        if sim is not None and (lo < HEIGHT_RANGE[0] or hi > HEIGHT_RANGE[1]):
            raise ValueError(f"family {name}: heights {lo:.3f}..{hi:.3f} m leave the Sim's range {HEIGHT_RANGE}")
        starts = start_stances(robot, batch)
        targets = select.make_targets(robot)
        speed = forward if fam.forward is None else fam.forward
        for kind in commands:
            cmd = jax.block_until_ready(
                commands_for(kind, jax.random.fold_in(k_cmd, COMMANDS.index(kind)), robot, batch, steps, speed))
            common = dict(name="walk", family=name, commands=kind, robot=robot_name, ranges=fam.ranges,
                          maps_s=round(maps_s, 3), **dict(setup, forward_m_s=speed))
            if "perfect" in walkers:
                traj, comp, run_s = _timed(perfect_rollouts, maps, robot, starts, cmd, options, num_steps=steps,
                                           targets=targets)
                perfect_compile += comp
                record(dict(common, walker="perfect", **aggregate(traj, starts), compile_s=round(comp, 3),
                            run_s=round(run_s, 4), decisions_per_s=batch * steps / max(run_s, 1e-9)))
            if sim is not None:
                before = W.compiled_programs()
                traj, comp, run_s = simulated_rollouts(sim, maps, robot, starts, cmd, options, num_steps=steps,
                                                       chunk=chunk, targets=targets)
                physics = batch * (steps + 1) * sim.substeps * sim.cfg.ticks_per_step
                record(dict(common, walker="mjx", **aggregate(traj, starts), compile_s=round(comp, 3),
                            run_s=round(run_s, 4), physics_steps_per_s=physics / max(run_s, 1e-9),
                            new_compiles=W.compiled_programs() - before))
    record(dict(name="walk_compiles", mjx_programs=W.compiled_programs() - programs0,
                mjx_calls=sum(1 for r in rows if r.get("walker") == "mjx") * -(-batch // chunk),
                mjx_compile_s=round(sum(r["compile_s"] for r in rows if r.get("walker") == "mjx"), 3),
                perfect_compile_s=round(perfect_compile, 3), wall_s=round(time.perf_counter() - t_all, 2), **setup))
    return rows


def compiled_perfect_programs() -> int:
    """How many programs :func:`perfect_rollouts` holds compiled in this process (one per robot action-set size,
    batch and ``num_steps``; new maps, commands and robot values reuse them)."""
    return compiled_count(_perfect_jit)


# --------------------------------------------------------------------------------------------- table and plot


def _pairs(rows: Sequence[dict]) -> list[tuple[str, str, dict | None, dict | None, str | None]]:
    """(family, commands, perfect row, simulated row, skip reason) per family and command kind, in run order."""
    out: dict[tuple[str, str], list] = {}
    for r in rows:
        if r.get("name") != "walk":
            continue
        if "skipped" in r:
            out[(r["family"], "")] = [None, None, r["skipped"]]
            continue
        slot = out.setdefault((r["family"], r["commands"]), [None, None, None])
        slot[WALKERS.index(r["walker"])] = r
    return [(f, c, p, s, why) for (f, c), (p, s, why) in out.items()]


def _cell(row: dict | None, key: str, fmt: str, scale: float = 1.0) -> str:
    """A table cell: ``row[key]`` times ``scale`` in ``fmt``, or "-" without a row or a value."""
    value = None if row is None else row[key]
    return "-" if value is None else format(value if scale == 1.0 else scale * value, fmt)


def markdown_table(rows: Sequence[dict]) -> str:
    """The records of :func:`run` as the Markdown table of BENCHMARKS.md: one line per family and command kind,
    the perfect robot and the simulated one side by side ("perfect / simulated"; "-" where a walker did not
    run or a number does not apply).

    Columns (:func:`aggregate`): robots; fell % (simulated); stops % and mean progress along +x (m); mean
    steps made; obstacle contacts (perfect: footholds on obstacle cells; simulated: steps with a sole or shin
    on one); the simulated placement error, mean and p95 (cm); its sole tilt error p95 (deg). A skipped
    family gets one line with the reason.
    """
    head = ("| family | commands | robots | fell % (sim) | stops % (perfect / sim) | progress m (perfect / sim) "
            "| steps made (perfect / sim) | contacts (perfect / sim) | placement mean / p95 cm (sim) "
            "| tilt p95 deg (sim) |")
    lines = [head, "|" + " --- |" * head.count(" | ") + " --- |"]
    for family, kind, p, s, why in _pairs(rows):
        if why is not None:
            lines.append(f"| {family} | - | skipped: {why} |" + " |" * 7)
            continue
        def both(key, fmt, pkey=None, p=p, s=s):
            return f"{_cell(p, pkey or key, fmt)} / {_cell(s, key, fmt)}"

        cells = [family, kind, str((p or s)["robots"]), _cell(s, "fell_pct", ".2f"), both("stops_pct", ".1f"),
                 both("progress_mean_m", ".2f"), both("steps_made_mean", ".1f"),
                 both("obstacle_contacts", "d", pkey="footholds_on_obstacles"),
                 f"{_cell(s, 'placement_error_mean_m', '.2f', 100)} / {_cell(s, 'placement_error_p95_m', '.2f', 100)}",
                 _cell(s, "tilt_error_p95_rad", ".2f", 180 / math.pi)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


PLOT_SIZE = (12.0, 8.0)
"""Figure size of :func:`plot` (inches); saved at :data:`PLOT_DPI`."""
PLOT_DPI = 100


def plot(rows: Sequence[dict], path=None):
    """Bars per family: falls %, stops % and mean progress (m), perfect and simulated side by side.

    One panel per measure; in each, four bars per family: perfect and simulated robot (colour) under
    random and forward commands (hatched: forward). Skipped families are left out. Saved as a PNG of
    :data:`PLOT_SIZE` inches at :data:`PLOT_DPI` when ``path`` is given; returns the figure.
    """
    require("plot", "matplotlib", what="ijoy bench walk --plot")
    import matplotlib

    if path is not None:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    pairs = [x for x in _pairs(rows) if x[4] is None]
    families = list(dict.fromkeys(f for f, *_ in pairs))
    kinds = [k for k in COMMANDS if any(c == k for _, c, *_ in pairs)]
    table = {(f, c): (p, s) for f, c, p, s, _ in pairs}
    fig, axes = plt.subplots(3, 1, figsize=PLOT_SIZE, sharex=True)
    measures = (("fell_pct", "fell (% of robots)"), ("stops_pct", "stopped (% of robots)"),
                ("progress_mean_m", "mean progress along +x (m)"))
    bars = [(w, k) for k in kinds for w in WALKERS]
    width = 0.8 / max(len(bars), 1)
    colours = {"perfect": "tab:blue", "mjx": "tab:orange"}
    x = np.arange(len(families))
    for ax, (key, label) in zip(axes, measures, strict=True):
        for j, (walker, kind) in enumerate(bars):
            values = []
            for f in families:
                row = table.get((f, kind), (None, None))[WALKERS.index(walker)]
                values.append(np.nan if row is None or row[key] is None else row[key])
            ax.bar(x + (j - 0.5 * (len(bars) - 1)) * width, values, width, color=colours[walker],
                   hatch="//" if kind == "forward" else None, edgecolor="white",
                   label=f"{'perfect' if walker == 'perfect' else 'simulated (MJX)'}, {kind} commands")
        ax.set_ylabel(label)
        if key.endswith("_pct"):
            ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
        ax.grid(axis="y", alpha=0.3)
        ax.axhline(0.0, color="black", lw=0.6)
    axes[0].legend(fontsize=8, ncol=2, loc="upper left")
    axes[-1].set_xticks(x, families, rotation=20)
    first = next((r for r in rows if r.get("name") == "walk" and "skipped" not in r), {})
    axes[0].set_title(f"HRP-2 joystick per terrain family: {first.get('batch', '?')} robots x "
                      f"{first.get('steps', '?')} steps, perfect robot vs MJX biped")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=PLOT_DPI)
        plt.close(fig)
    return fig
