"""Running a sweep: scenarios batched with jit + vmap in chunks, written as they complete, resumable.

Layout of an output folder::

    DIR/sweep.toml              the sweep file's text, as run
    DIR/manifest.json           sweep text, plan, package versions, device, git commit, timings
    DIR/parts/part-00000.parquet  one file per completed chunk (written atomically), its plan record
                                (sweep name, chunk plan and the plan's hash) in the parquet metadata
    DIR/processes/process-00001.json  sessions of process 1 of several (process 0's are in the manifest)
    DIR/aggregates.parquet      per-cell means and 95% confidence intervals (when complete)
    DIR/.lock                   held (flock) while a run writes here: a second run refuses (see _FolderLock)

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
One chunk is in flight behind the host: chunk k+1 is built and dispatched before chunk k's
summaries are fetched and its part written (the first chunk of a group, which compiles, waits until
the chunk before it is written, so steady rates hold no compile time); a chunk dispatched before an
error or interrupt is still written.

Physics (``walker = "mjx"``). The MJX biped (:func:`ijoy_jax.sim.walker.make_sim`
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

Compiles (measured by :func:`trace_count`, tested): parameter values never
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

Devices. A chunk's rows are split evenly over the local devices (all of them
by default, or the first ``devices``), and each device runs the one-device
program on its slice (:class:`_OnDevices`): the shared inputs (base robot,
targets, key, MJX model) are copied to every device, each device's call is
made from its own thread (a new program compiles side by side; the calls
return once dispatched, so the devices compute at the same time), and the
summaries are gathered to the host. No program spans devices and nothing is
exchanged between them, so a device's rows come out exactly as one device
alone computes them; each device's program is the one-device program, compiled
for the devices side by side (a later run loads it from JAX's persistent
compilation cache, which ``ijoy`` turns on). The chunk size
is rounded up to a multiple of the device count (the plan's ``chunk_size``)
and a padded chunk is padded to a multiple of it too. Each session in the
manifest records ``devices`` and ``sharding`` (how rows were split).

Chunk size. Given, or (``chunk_size=None``) the manifest's when resuming, else
:func:`default_chunk_size`: :data:`DEFAULT_CHUNK` on CPU; on an accelerator
the compiled chunk function's memory for one scenario of the largest action
set (:func:`scenario_bytes`, ahead-of-time ``memory_analysis()``, nothing
runs; split into per-scenario and shared bytes) sets :func:`auto_chunk_size`,
a power of two per device filling :data:`MEMORY_FRACTION` of
``memory_stats()["bytes_limit"]``.

Several processes (hosts). Process ``I`` of ``N`` (``jax.process_index()``
and ``jax.process_count()`` after :func:`jax.distributed.initialize`, or
``process_id``/``num_processes``) runs the chunks with ``chunk_id % N == I``
over its local devices and writes their parts into the shared folder; there
are no cross-process collectives (see :mod:`ijoy_jax.sweep.distributed`).
Process 0 alone writes ``manifest.json`` (with the ``layout``) and
``sweep.toml``; process ``I > 0`` records its sessions in
``processes/process-0000I.json``. At the end a coordination-service barrier
(when ``jax.distributed`` is up; a timeout or a dead peer only skips it) lets
process 0 write ``aggregates.parquet`` once every part exists. Each process
resumes its own chunks; :func:`ijoy_jax.sweep.load` reads the union and names
missing chunks and their processes.

Progress: one line per chunk on stderr (scenarios done, scenarios/s over
compiled chunks, ETA); ``first_chunk_s`` in the manifest holds each density's
first chunk time, which includes its compile.

Slices. ``scenarios_per_cell=N`` runs the first N replicates of every cell (the sweep shrunk evenly),
``max_scenarios=M`` the first M scenario ids (cell after cell: a check of the program, which stays a
prefix of the ids so its rows are a whole run's first rows, as :func:`scenario` numbers them). Either is a
slice (:func:`ijoy_jax.sweep.results.selection`) computed in the whole sweep's chunks: calls of the group's
chunk shape (the whole run's compiled program) hold the slice's rows of one or more chunks, and each row is
written into its own chunk's part, merged with the rows that part already holds. So a later run into the
same folder with a larger slice, or none, computes only the scenarios missing, and the folder ends equal to
a whole run's, bit for bit. ``manifest.json`` records the union of the slices asked (``selection``) and
whether the folder holds the whole sweep (``complete``); each session its own ``selection`` and
``truncated``.

Resume. The chunk plan is a pure function of the sweep file and ``chunk_size``
(after rounding to the device count), the whole sweep's whatever slice a run computes, and is saved in the
manifest; a rerun with another device count resumes when the rounded chunk
size is the same (e.g. the default 32 on 1, 2, 4 or 8 devices). Each finished
chunk is written to a temporary file and renamed (atomic on POSIX), so after a
kill a part file is either complete or absent; a rerun on the same folder reads which scenarios each part
holds and computes the rest. Nothing is lost or duplicated.
Every part records the hash of its plan (:func:`ijoy_jax.sweep.results.plan_hash`:
the sweep text and the chunk plan; also in the manifest as ``plan_hash``): a run
refuses a folder holding parts of another plan (even with ``manifest.json``
deleted) before writing anything, and :func:`ijoy_jax.sweep.load` refuses to mix them.
A part or record damaged outside a run (truncated, overwritten, hand-edited) is never
skipped or read as results: the run and :func:`ijoy_jax.sweep.load` refuse it in one
line naming the file and the way out (delete that part, and the run recomputes its
chunk; delete a record, and the run writes it anew from the parts' plan records).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from importlib import metadata
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import robots
from ijoy_jax.control import rollout
from ijoy_jax.select import make_targets
from ijoy_jax.sweep import distributed
from ijoy_jax.sweep.config import (
    COMMAND_KEYS,
    ROBOT_DEFAULTS,
    SweepConfig,
    SweepConfigError,
    load_config,
    reach_of,
    scenarios,
)
from ijoy_jax.sweep.results import (
    PLAN_KEY,
    check_plans,
    chunk_plan,
    describe_selection,
    differences,
    part_plan,
    plan_hash,
    read_part,
    read_record,
    selected,
    selection,
)
from ijoy_jax.terrain import generators

__all__ = ["DEFAULT_CHUNK", "MAX_AUTO_CHUNK", "MEMORY_FRACTION", "RunStats", "Scenario", "auto_chunk_size",
           "default_chunk_size", "run", "scenario", "scenario_bytes", "trace_count"]

DEFAULT_CHUNK = 32
"""Scenarios per jitted call on CPU (and wherever the device reports no memory figure)."""
MEMORY_FRACTION = 0.5
"""Share of an accelerator's memory a default-sized chunk may fill (the rest: XLA workspace, fragmentation)."""
MAX_AUTO_CHUNK = 4096
"""Largest chunk per device :func:`auto_chunk_size` picks: large enough to amortise dispatch and fill a GPU
(the MJX walker's physics steps/s still grow from 1024 to 4096 robots), small enough to resume often."""

_PART = "part-{:05d}.parquet"
_PROC = "process-{:05d}.json"
class _Static(NamedTuple):
    """Everything about a chunk that is static under jit (hashable)."""

    family: str | None  # None: the recorded terrain of the shared _Scene
    shape: tuple[int, int]
    resolution: float
    has_height: bool
    max_count: int | None
    num_steps: int
    method: str
    kernel: str
    walker: str
    horizon: int = 1
    beam: int | None = None
    refine: bool = False


class _Scene(NamedTuple):
    """What every scenario of a run shares besides the robot (replicated over devices like the targets)."""

    first_swing: jax.Array  # () float32: +1 the left foot swings first
    terrain: Any = None  # the recorded Terrain ([terrain] recording), or None: the family generates one each
    start: jax.Array | None = None  # (2, 3) float32 the recorded start feet (left, right), or None


def _scene(cfg: SweepConfig) -> _Scene:
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
    if static.family is None:  # the recorded terrain and start feet: the same for every scenario
        return tkey, None, scene.terrain, robot, scene.start
    fam = generators.FAMILIES[static.family]
    params = fam.params(**terrain_vals)
    kw = {} if static.max_count is None else {"max_count": static.max_count}
    terrain = fam.generator(tkey, params, shape=static.shape, resolution=static.resolution,
                            has_height=static.has_height, **kw)
    centre = generators.start_point(params, shape=static.shape, resolution=static.resolution)
    start = robots.start_stance(base, centre[0], centre[1])  # side by side at the step-in-place width, facing +x
    return tkey, params, terrain, robot, start


def _family_metrics(static: _Static, tkey, params, feet, robot) -> dict:
    """The family's extra metrics (bars: whether the robot got past them), from the terrain it generated ({} for a
    recorded terrain)."""
    if static.family is None:
        return {}
    fam = generators.FAMILIES[static.family]
    return fam.metrics(tkey, params, feet, robot.foot_length, robot.foot_width, shape=static.shape,
                       resolution=static.resolution, max_count=static.max_count)


def _scenario(static: _Static, base: robots.Robot, targets, key, scene, seed, robot_vals, terrain_vals, commands):
    """One scenario of the perfect robot: terrain, robot, start and rollout of its (num_steps, 3) commands; the
    trajectory's summary (scalars)."""
    tkey, params, terrain, robot, start = _setup(static, base, key, scene, seed, robot_vals, terrain_vals)
    lookahead = dict(horizon=static.horizon, beam=static.beam if static.horizon >= 3 else None,
                     discount=robot_vals["discount"]) if static.method == "lookahead" else {}
    traj = rollout(terrain, robot, start, commands, static.num_steps, method=static.method, targets=targets,
                   kernel=static.kernel, first_swing=scene.first_swing, refine=static.refine, **lookahead)
    return {**traj.summary(), **_family_metrics(static, tkey, params, traj.feet, robot)}


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
    """A physics chunk's per-scenario summary (:func:`ijoy_jax.sim.walker.summary`) and family metrics."""
    from ijoy_jax.sim import walker

    def one(seed, r, t, tr):
        tkey, params, _, robot, _ = _setup(static, base, key, scene, seed, r, t)  # the terrain itself is not used
        return {**walker.summary(tr), **_family_metrics(static, tkey, params, tr.feet, robot)}

    return jax.vmap(one)(seeds, robot_vals, terrain_vals, traj)


_counted_prepare, _prepare_traces = _counting_traces(_prepare)
_run_prepare = jax.jit(_counted_prepare, static_argnames=("static",))
_run_finish = jax.jit(_finish, static_argnames=("static",))


def _physics_chunk(static: _Static, base, targets, key, sim, scene, seeds, robot_vals, terrain_vals, commands,
                   sim_vals):
    """A chunk of the MJX biped: the scenarios' terrains, robots and starts (one small program), their rollouts
    through :func:`ijoy_jax.sim.walker.rollout_batch` (its own program, shared with any other caller of the
    same shapes) with the scenarios' :class:`ijoy_jax.sim.physics.Dynamics`, then the summaries (another small
    program). Traced under one jit (:func:`scenario_bytes`) the three are one program."""
    from ijoy_jax.sim import physics, walker

    terrains, robots_, starts, keys = _run_prepare(static, base, key, scene, seeds, robot_vals, terrain_vals)
    traj = walker.rollout_batch(sim, terrains, robots_, starts, commands, num_steps=static.num_steps,
                                method=static.method, first_swing=scene.first_swing, targets=targets,
                                kernel=static.kernel, dynamics=physics.Dynamics(**sim_vals), key=keys,
                                refine=static.refine)
    return _run_finish(static, base, key, scene, seeds, robot_vals, terrain_vals, traj)


def _chunk_runner(static: _Static):
    """The function that runs a chunk: the perfect robot's jitted chunk or the physics chunk's three programs."""
    return _run_chunk if static.walker == "perfect" else _physics_chunk


class _OnDevices:
    """A chunk's rows split evenly over ``devices``, each slice run by the one-device program on its own device.

    With one device nothing is placed: the arrays go to the default device uncommitted, as other callers pass
    them, so a sweep shares the program they compiled (e.g. :func:`ijoy_jax.sim.walker.rollout_batch`'s).
    With several, the shared inputs are copied to every device once per density, and each device's call is
    made from its own thread: a new program traces and compiles for the devices side by side (one compile's
    wall time on two H200s), and the calls return as soon as their work is dispatched, so the devices
    compute at the same time. Nothing is exchanged between devices, and a device computes exactly what one
    device alone computes on those rows. Handing the whole batch to jit
    with a sharding instead, the partitioner gathered whole batches where it has no per-row rule (the rough
    terrain's FFT, a Pallas kernel's custom call) and reduced vmapped while loops' predicates over all
    devices at every iteration (the selector's search, MJX's solver): on two H200s a perfect-robot sweep ran
    at a sixth of one GPU's rate. A ``shard_map`` over the rows fixed that, but a physics sweep's program
    crashed XLA's GPU compiler (SIGSEGV).
    """

    def __init__(self, devices: list):
        self.devices = list(devices)

    def put_shared(self, shared) -> list:
        """``shared`` committed to each device (one copy per device); as it is with one device."""
        if len(self.devices) == 1:
            return [shared]
        return [jax.device_put(shared, d) for d in self.devices]

    def dispatch(self, run, static: _Static, shared: list, batch) -> list:
        """``run(static, *shared[i], *rows_i)`` on device i for the i-th of equal slices of the host ``batch``
        (its leading axis a multiple of the device count). Returns each device's outputs once its work is
        dispatched (a new program is traced and compiled first); :meth:`collect` waits for them."""
        k = len(self.devices)
        m = len(batch[0]) // k

        def one(i):
            rows = jax.tree.map(lambda x: x[i * m:(i + 1) * m], batch)
            # With one device: uncommitted, on the default device (the program other callers compiled).
            return run(static, *shared[i], *jax.device_put(rows, self.devices[i] if k > 1 else None))

        if k == 1:
            return [one(0)]
        with ThreadPoolExecutor(k) as pool:  # a thread per device; they return once dispatched
            return list(pool.map(one, range(k)))

    @staticmethod
    def collect(outs: list) -> dict:
        """The devices' summaries (from :meth:`dispatch`) on the host, concatenated in device order."""
        outs = jax.device_get(outs)
        return {name: np.concatenate([np.asarray(o[name]) for o in outs]) for name in outs[0]}


def trace_count() -> int:
    """How many chunk programs have been traced (compiled) in this process: the perfect robot's chunk function,
    plus each physics chunk shape's preparation (its rollouts are :func:`ijoy_jax.sim.walker.rollout_batch`'s
    program, counted by :func:`ijoy_jax.sim.walker.compiled_programs`)."""
    return _chunk_traces() + _prepare_traces()


@dataclasses.dataclass
class RunStats:
    """What :func:`run` did (seconds are wall time).

    Fields::

      out: the output folder.
      scenarios: scenarios this call was asked for (its slice, or the whole sweep); computed: scenarios
        computed by this call (those already in the folder excluded); chunks: the plan's chunks holding them;
        skipped: this process's share of those with nothing left to compute.
      compiles: traces of the chunk function during this call.
      devices: devices the rows of a chunk are split over; chunk_size: the
        plan's chunk size (the requested one rounded up to a multiple of devices).
      first_chunk_s: per density (and selector horizon and refinement, when the sweep varies them: see
        the group's label), wall time of its first chunk (includes compile).
      run_s: total wall time of this call.
      rate: scenarios/s over the chunks after each density's first (0 when there were none).
      physics_steps: physics steps per scenario (``walker = "mjx"``: the steps and the robot's one standing
        step, times the control ticks per step and the physics steps per tick; 0 for the perfect robot), so
        ``rate * physics_steps`` is the physics steps/s.
      complete: every scenario this call was asked for (all processes' share of its slice, or of the whole
        sweep) has its result in the folder at the end of the call (with several processes: after the final
        barrier, or its timeout).
      sweep_scenarios: scenarios of the whole sweep (``scenarios`` is fewer for a slice: ``max_scenarios``,
        ``scenarios_per_cell``); sweep_complete: every one of them has its result in the folder (False after
        a slice, until a later run computes the rest; the manifest's ``"complete"``).
    """

    out: Path
    scenarios: int = 0
    computed: int = 0
    chunks: int = 0
    skipped: int = 0
    compiles: int = 0
    devices: int = 1
    chunk_size: int = 0
    first_chunk_s: dict = dataclasses.field(default_factory=dict)
    run_s: float = 0.0
    rate: float = 0.0
    physics_steps: int = 0
    complete: bool = False
    sweep_scenarios: int = 0
    sweep_complete: bool = False


def _base_robot(cfg: SweepConfig, table, density: float) -> robots.Robot:
    """The density's robot (at the sweep's reach) with static windows covering the sweep's largest footprint and
    margin.

    Raises SweepConfigError when the largest footprint makes an action overlap the stance foot.
    """
    fl = float(table["robot.foot_length"].max())
    fw = float(table["robot.foot_width"].max())
    mm = max(float(table["robot.margin"].max()), 0.10)
    reach = reach_of(cfg)
    # hrp2 refuses a reach beyond max_sole_distance; the scenarios' own values replace this one, and load_config
    # checked a sweep's reach against each (a shorter limit at the paper's reach only refuses the far steps)
    msd = max(float(table["robot.max_sole_distance"].max()), ROBOT_DEFAULTS["max_sole_distance"])
    try:
        return robots.hrp2(margin=0.0, density=density, reach=reach, foot_length=fl, foot_width=fw, max_margin=mm,
                           max_sole_distance=msd)
    except ValueError as e:
        raise SweepConfigError(f"{cfg.source}: robot.foot_length/robot.foot_width: a {fl} x {fw} m footprint "
                               f"does not fit HRP-2's action set at density {density} and reach {reach} m: {e}"
                               ) from None


class Scenario(NamedTuple):
    """One scenario of a sweep, rebuilt on the host (:func:`scenario`).

    terrain: its generated :class:`~ijoy_jax.Terrain` (or the recorded one); robot: its :class:`~ijoy_jax.Robot`
    (the density's action set, the scenario's leaves); start: (2, 3) float32 feet (left, right; m, rad);
    command: (3,) float32 its held command (m/s, m/s, rad/s), or (num_steps, 3) one per step when the commands
    come from ``[command] file``; cell, replicate: its cell and replicate (its terrain key is
    ``fold_in(key(seed), replicate)``); first_swing: +1 if the left foot swings first. So
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
    if isinstance(scenario_id, bool) or not isinstance(scenario_id, (int, np.integer)) or not (
            0 <= scenario_id < cfg.num_scenarios):
        raise SweepConfigError(f"{cfg.source}: scenario {scenario_id!r} does not exist (the sweep has "
                               f"{cfg.num_scenarios} scenarios, ids 0 to {cfg.num_scenarios - 1})")
    table = scenarios(cfg, max_scenarios=int(scenario_id) + 1)
    row = table.iloc[[int(scenario_id)]]
    density = float(row["robot.density"].iloc[0])
    base = _base_robot(cfg, table, density)
    robot_cols, terrain_cols, _ = _cols(table)
    replicate, robot_vals, terrain_vals, commands, _ = _batch(row, 1, robot_cols, terrain_cols, cfg=cfg)
    one = lambda d: {k: v[0] for k, v in d.items()}  # noqa: E731
    _, _, terrain, robot, start = _setup(_static(cfg), base, jax.random.key(cfg.seed), _scene(cfg), replicate[0],
                                         one(robot_vals), one(terrain_vals))
    command = commands[0] if cfg.command_file is not None else commands[0, 0]  # (num_steps, 3) or held (3,)
    return Scenario(terrain, robot, np.asarray(start, np.float32), np.asarray(command, np.float32),
                    int(row["cell"].iloc[0]), int(replicate[0]), cfg.first_swing)


def _versions() -> dict:
    out = {"python": platform.python_version()}
    for pkg in ("ijoy_jax", "jax", "jaxlib", "numpy", "pandas", "pyarrow"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def _git_commit() -> str | None:
    try:
        here = Path(__file__).resolve().parent
        r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5)
        dirty = subprocess.run(["git", "status", "--porcelain"], cwd=here, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    if r.returncode != 0:
        return None
    return r.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


_WHO = f"{platform.node()}-{os.getpid()}"  # names this process's temporary files (host and pid)
_LOCK = ".lock"
_LOCK_PROC = ".lock-process-{:05d}"


def check_out_folder(out: Path) -> None:
    """Refuse an output folder that holds anything but a sweep's results (ValueError naming it and what it holds).

    A folder is a sweep's once it has ``manifest.json`` or ``parts/``; before that (a fresh or an empty folder,
    or one whose run stopped at once) it may hold only the run's locks and ``processes/``. So ``--out .`` in a
    project, or a folder of other files, is never written into (a sweep writes ``sweep.toml`` there)."""
    if not out.exists():
        return
    if not out.is_dir():
        raise ValueError(f"{out} is not a folder; choose another --out")
    if (out / "manifest.json").exists() or (out / "parts").is_dir():
        return
    foreign = sorted(p.name for p in out.iterdir()
                     if not (p.name == _LOCK or p.name.startswith(".lock-process-") or p.name == "processes"))
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise ValueError(f"{out} holds files that are not a sweep's results ({shown}); a sweep writes only into a "
                         f"new or empty folder or its own results: choose another --out")


class _FolderLock:
    """An advisory lock (``fcntl.flock``) on a sweep's output folder, taken before its manifest is read.

    One process of one (process 0 of 1) holds ``DIR/.lock`` exclusively; the processes of a
    multi-process layout (``num_processes > 1``: members of one ``jax.distributed`` run, which
    split the chunks between them) share it and each holds ``DIR/.lock-process-I`` exclusively.
    So a second run on the folder, or a second process I, is refused (ValueError naming the
    holder's pid and host, written into the lock file). The kernel drops a flock when its process
    dies, so a lock file left by a dead process is stale and simply taken over. (On NFS, Linux maps
    flock onto the server's byte-range locks.)
    """

    def __init__(self, out: Path, pid: int, nproc: int):
        import fcntl

        out.mkdir(parents=True, exist_ok=True)
        self.fds: list[int] = []
        me = {"pid": os.getpid(), "host": platform.node(), "process_id": pid, "num_processes": nproc,
              "since": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        wanted = ([(out / _LOCK, fcntl.LOCK_EX)] if nproc == 1 else
                  [(out / _LOCK, fcntl.LOCK_SH), (out / _LOCK_PROC.format(pid), fcntl.LOCK_EX)])
        try:
            for path, mode in wanted:
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
                self.fds.append(fd)
                try:
                    fcntl.flock(fd, mode | fcntl.LOCK_NB)
                except BlockingIOError:
                    raise ValueError(self._refusal(out, path, nproc)) from None
                if mode == fcntl.LOCK_EX:  # the holder, for the next one's error message
                    os.ftruncate(fd, 0)
                    os.pwrite(fd, json.dumps(me).encode(), 0)
        except BaseException:
            self.release()
            raise
        if nproc == 1:  # alone in the folder: temporary files left by killed runs are garbage
            for tmp in (out / "parts").glob("*.tmp"):
                tmp.unlink(missing_ok=True)

    @staticmethod
    def _refusal(out: Path, path: Path, nproc: int) -> str:
        holders = []
        for f in [out / _LOCK, *sorted(out.glob(".lock-process-*"))]:
            try:
                h = json.loads(f.read_text())
                if not _alive(h):
                    continue  # a stale record (its lock is not held)
                holders.append(f"pid {h['pid']} on {h['host']}"
                               + (f" (process {h['process_id']} of {h['num_processes']})"
                                  if h.get("num_processes", 1) > 1 else ""))
            except (OSError, ValueError, KeyError, TypeError):
                continue
        who = "; ".join(dict.fromkeys(holders)) or "another process"
        what = "another run" if path.name == _LOCK else "another process with this --process-id"
        return (f"{out} is in use by {what} ({who} holds {path.name}); wait for it to finish or choose another "
                f"--out" + ("" if nproc > 1 else "; processes of one multi-process run share a folder "
                            "(--num-processes/--process-id)"))

    def release(self) -> None:
        for fd in self.fds:
            os.close(fd)  # closing drops the flock
        self.fds = []


def _alive(holder: dict) -> bool:
    """Whether a lock file's holder may still run (a pid on another host cannot be checked: True)."""
    if holder.get("host") != platform.node():
        return True
    try:
        os.kill(int(holder["pid"]), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _parts_chunk_size(parts: Path) -> int | None:
    """The chunk size the first part in ``parts`` records in its plan, or None (no part, or none recorded)."""
    for f in sorted(parts.glob("part-*.parquet")) if parts.is_dir() else ():
        rec = part_plan(f)  # IncompleteSweepError for a part that cannot be read
        if rec is not None and isinstance(rec.get("chunk_size"), int) and rec["chunk_size"] >= 1:
            return rec["chunk_size"]
    return None


def _what_differs(prev: dict, text: str, plan_key: dict) -> str:
    """What differs between a folder's record (``prev``: its sweep text and plan) and this run's, compactly: the
    sweep file's keys (``sweep.seed 3 -> 4``, ``grid.robot.w [0.5, 2.0] -> [1.0, 4.0]``), then the plan's
    (``plan.chunk_size 2 -> 4``), each sorted, old -> new; the first differing line where the sweep files differ
    only in comments or layout (the plan's hash covers the text)."""
    import tomllib

    old_text = prev.get("sweep_text", "")
    sweep = ""
    if old_text != text:
        try:
            sweep = differences(tomllib.loads(old_text), tomllib.loads(text))
        except tomllib.TOMLDecodeError:
            sweep = "the sweep file's text (the folder's is not TOML)"
        if not sweep:  # the same keys and values
            old_lines, new_lines = old_text.splitlines(), text.splitlines()
            n = next((i for i, (a, b) in enumerate(zip(old_lines, new_lines, strict=False)) if a != b),
                     min(len(old_lines), len(new_lines)))

            def line(lines: list[str]) -> str:
                return json.dumps(lines[n]) if n < len(lines) else "the end of the file"

            sweep = f"the sweep file's comments or layout, line {n + 1}: {line(old_lines)} -> {line(new_lines)}"
    plan = differences({"plan": prev.get("plan", {})}, {"plan": plan_key})
    return ", ".join(d for d in (sweep, plan) if d)


def _write_json(path: Path, obj) -> None:
    tmp = path.with_name(f"{path.name}.{_WHO}.tmp")
    tmp.write_text(json.dumps(obj, indent=2, default=str))
    os.replace(tmp, path)


def _write_part(df, path: Path, plan_record: dict) -> None:
    """Write one chunk's results as parquet, its plan record in the file's metadata (:data:`PLAN_KEY`)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(df, preserve_index=False)
    meta = {**(table.schema.metadata or {}), PLAN_KEY: json.dumps(plan_record).encode()}
    pq.write_table(table.replace_schema_metadata(meta), path)


def _group_label(cfg: SweepConfig, group: tuple):
    """How a group is named in :attr:`RunStats.first_chunk_s`: its density when the selector is not swept,
    else ``"<density> horizon=<h> refine=<r>"``."""
    density, horizon, refine = group
    if "selector.horizon" not in cfg.grid and "selector.refine" not in cfg.grid:
        return density
    return f"{density:g} horizon={horizon} refine={str(refine).lower()}"


def _local_devices(devices) -> list:
    """The first ``devices`` local devices (all when None); ValueError when there are not that many."""
    local = jax.local_devices()
    if devices is None:
        return local
    if isinstance(devices, bool) or not isinstance(devices, int) or not 1 <= devices <= len(local):
        raise ValueError(f"devices must be an int in [1, {len(local)}] (local devices) or None, got {devices!r}")
    return local[:devices]


def _progress(done: int, total: int, rate: float, chunk: int, nchunks: int, who: str = "",
              physics_steps: int = 0) -> None:
    eta = (total - done) / rate if rate > 0 else float("nan")
    physics = f" ({rate * physics_steps / 1e6:.3g} M physics steps/s)" if physics_steps else ""
    line = (f"[ijoy sweep{who}] {done}/{total} scenarios  chunk {chunk}/{nchunks}  "
            f"{rate:.1f} scenarios/s{physics}  ETA {eta:.0f} s")
    end = "\r" if sys.stderr.isatty() and done < total else "\n"
    print(line.ljust(78), end=end, file=sys.stderr, flush=True)


def _process_layout(process_id, num_processes) -> tuple[int, int]:
    """(I, N) from the arguments, defaulting to ``jax.process_index()`` / ``jax.process_count()``."""
    if process_id is None and num_processes is None:
        return jax.process_index(), jax.process_count()
    for name, v in (("process_id", process_id), ("num_processes", num_processes)):
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"process_id and num_processes must both be ints (or both None), got {name}={v!r}")
    if num_processes < 1 or not 0 <= process_id < num_processes:
        raise ValueError(f"process id {process_id} out of range for {num_processes} processes "
                         f"(0 to {num_processes - 1})")
    if jax.process_count() > 1 and (process_id, num_processes) != (jax.process_index(), jax.process_count()):
        raise ValueError(f"process_id={process_id}, num_processes={num_processes} disagree with jax.distributed "
                         f"(process {jax.process_index()} of {jax.process_count()})")
    return process_id, num_processes


def _batch(rows, size: int, robot_cols, terrain_cols, sim_cols=(), *, cfg: SweepConfig):
    """Per-scenario inputs of a chunk: ``rows`` padded to ``size`` by repeating the last one (NumPy): the
    replicates, robot values, terrain values, commands (size, num_steps, 3) (each scenario's held command at
    every step, or the ``[command] file``'s sequence, the same program either way) and physics values ({} for
    the perfect robot)."""
    n = len(rows)
    pad = np.concatenate([np.arange(n), np.full(size - n, n - 1)])

    def col(name, dtype):
        return np.asarray(rows[name].to_numpy()[pad], dtype)

    robot_vals = {c.partition(".")[2]: col(c, np.float32) for c in robot_cols}
    terrain_vals = {c.partition(".")[2]: col(c, np.int32 if rows[c].dtype.kind == "i" else np.float32)
                    for c in terrain_cols}
    steps = cfg.command_steps
    if steps is None:
        held = np.stack([col(f"command.{k}", np.float32) for k in COMMAND_KEYS], axis=-1)
        commands = np.repeat(held[:, None, :], cfg.num_steps, axis=1)
    else:
        commands = np.repeat(np.asarray(steps, np.float32)[None], size, axis=0)
    sim_vals = {c.partition(".")[2]: col(c, np.float32) for c in sim_cols}
    return col("replicate", np.int32), robot_vals, terrain_vals, commands, sim_vals


def _shared(table, base):
    """Per-density inputs shared by every scenario: (base robot, targets or None when each scenario sorts)."""
    if table["robot.rotation_weight"].nunique() > 1:
        return base, None
    return base, make_targets(base.replace(rotation_weight=jnp.float32(table["robot.rotation_weight"].iloc[0])))


def _cols(table):
    # The lookahead's discount travels with the robot values (traced per scenario, like them).
    robot_cols = [f"robot.{k}" for k in ROBOT_DEFAULTS if k not in ("density", "reach")] + ["selector.discount"]
    return (robot_cols, [c for c in table.columns if c.startswith("terrain.")],
            [c for c in table.columns if c.startswith("sim.")])


def _device_bytes(device) -> int | None:
    """Memory an accelerator lets XLA allocate (``memory_stats()["bytes_limit"]``); None on CPU or unknown."""
    if device.platform == "cpu":
        return None
    try:
        stats = device.memory_stats()
    except Exception:  # noqa: BLE001 - some backends raise instead of returning None
        return None
    limit = (stats or {}).get("bytes_limit")
    return int(limit) if limit else None


def _static(cfg: SweepConfig) -> _Static:
    """The chunk's static configuration (``family`` None for a recorded terrain)."""
    return _Static(cfg.family, cfg.shape, cfg.resolution, cfg.has_height, cfg.static_max_count,
                   cfg.num_steps, cfg.method, cfg.kernel, cfg.walker, cfg.horizon, cfg.beam, cfg.refine)


def _make_sim(cfg: SweepConfig, table):
    """The MJX biped of a ``walker = "mjx"`` sweep (its map's grid, the sweep's fixed footprint; host-side, no
    compile), or None for the perfect robot."""
    if cfg.walker != "mjx":
        return None
    from ijoy_jax.sim import walker

    size = {k: float(table[f"robot.{k}"].iloc[0]) for k in ("foot_length", "foot_width")}
    return walker.make_sim(cfg.shape, cfg.resolution, robot=robots.hrp2(**size))


def _physics_steps(sim, num_steps: int) -> int:
    """Physics steps of one simulated rollout of ``num_steps`` steps (:attr:`RunStats.physics_steps`): the steps
    and the standing warm-up step, each of control ticks of physics steps; 0 without a Sim."""
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
    robot_cols, terrain_cols, sim_cols = _cols(table)
    base, targets = _shared(table, base)
    key = jax.random.key(cfg.seed)
    sim = _make_sim(cfg, table) if sim is None else sim
    batch = _batch(table.iloc[:1], 1, robot_cols, terrain_cols, sim_cols, cfg=cfg)
    runner = _run_chunk if cfg.walker == "perfect" else jax.jit(_physics_chunk, static_argnames=("static",))
    heaviest = _static(cfg)._replace(horizon=int(table["selector.horizon"].max()),
                                     refine=bool(table["selector.refine"].max()))  # the most memory per scenario
    compiled = runner.lower(heaviest, base, targets, key, sim, _scene(cfg), *batch).compile()
    mem = compiled.memory_analysis()
    if mem is None:
        raise RuntimeError("the backend reports no memory analysis")
    # Arguments are the per-scenario inputs plus the shared ones jit keeps (unused leaves are pruned).
    inputs = sum(int(x.nbytes) for x in jax.tree.leaves(batch))
    shared = max(0, int(mem.argument_size_in_bytes) - inputs)
    return inputs + int(mem.output_size_in_bytes + mem.temp_size_in_bytes), shared


def auto_chunk_size(bytes_per_scenario: int, device_bytes: int, num_devices: int = 1, *, shared_bytes: int = 0,
                    fraction: float = MEMORY_FRACTION, max_chunk: int = MAX_AUTO_CHUNK) -> int:
    """The chunk size that fills ``fraction`` of each device's memory, as a power of two per device.

    ``per_device = 2 ** floor(log2((fraction * device_bytes - shared_bytes) / bytes_per_scenario))``
    (at least 1; ``shared_bytes`` is held once per device), at most ``max_chunk``, times ``num_devices``:
    each device runs the batch it would run alone. Powers of two keep the plan (and so
    resume) stable when the estimate moves a little.

    Example:
      >>> auto_chunk_size(2**20, 80 * 2**30, 1)   # 1 MiB per scenario on an 80 GiB GPU: capped
      4096
      >>> auto_chunk_size(100 * 2**20, 16 * 2**30, 2)   # 100 MiB per scenario, 2 x 16 GiB
      128
    """
    if bytes_per_scenario <= 0 or device_bytes <= 0 or num_devices < 1 or shared_bytes < 0:
        raise ValueError(f"need positive sizes, got bytes_per_scenario={bytes_per_scenario}, "
                         f"device_bytes={device_bytes}, num_devices={num_devices}, shared_bytes={shared_bytes}")
    fit = int((fraction * device_bytes - shared_bytes) // bytes_per_scenario)
    per_device = 1 << (fit.bit_length() - 1) if fit >= 1 else 1
    return min(per_device, max_chunk) * num_devices


def balanced_chunk_size(cap: int, total: int, num_devices: int = 1) -> int:
    """The smallest chunk (a multiple of ``num_devices``) that runs ``total`` scenarios in as many chunks as
    ``cap`` does, so the last chunk is not mostly padding.

    A physics rollout costs thousands of decisions, so a 4608-scenario sweep in chunks of 4096 would simulate
    8192 robots; in two chunks of 2304 it simulates 4608.

    Example:
      >>> balanced_chunk_size(4096, 4608), balanced_chunk_size(4096, 2816), balanced_chunk_size(4096, 2816, 3)
      (2304, 2816, 2817)
    """
    if cap < 1 or total < 1 or num_devices < 1:
        raise ValueError(f"need cap, total and num_devices >= 1, got {cap}, {total}, {num_devices}")
    chunks = -(-total // cap)
    per_chunk = -(-total // chunks)
    return -(-per_chunk // num_devices) * num_devices


def default_chunk_size(cfg: SweepConfig, table, bases: dict, devices: list, sim=None) -> int:
    """The chunk size used when none is given: :data:`DEFAULT_CHUNK` on CPU, else sized to device memory.

    On an accelerator with a known memory limit: :func:`auto_chunk_size` of
    :func:`scenario_bytes` for the largest action set (one extra ahead-of-time
    compile; ``sim``: a physics sweep's MJX biped); :data:`DEFAULT_CHUNK` when
    the backend reports no memory figure. ``table``: rows covering every cell (a run passes replicate 0 of
    each); a physics sweep's chunks are balanced over the whole sweep's scenarios, so a slice of it plans the
    chunks the whole sweep does.
    """
    mem = _device_bytes(devices[0])
    if mem is None:
        return DEFAULT_CHUNK
    base = max(bases.values(), key=lambda b: b.num_actions)
    try:
        per, shared = scenario_bytes(cfg, table, base, sim)
    except RuntimeError:
        return DEFAULT_CHUNK
    cap = auto_chunk_size(per, mem, len(devices), shared_bytes=shared)
    # a physics sweep's padded rollouts cost as much as real ones: balance the chunks (a perfect-robot sweep
    # keeps the power of two, whose compiled program other sweeps' sizes reuse)
    return cap if sim is None else balanced_chunk_size(cap, cfg.num_scenarios, len(devices))


def run(
    sweep,
    out=None,
    *,
    chunk_size: int | None = None,
    max_scenarios: int | None = None,
    scenarios_per_cell: int | None = None,
    progress: bool = True,
    devices: int | None = None,
    process_id: int | None = None,
    num_processes: int | None = None,
    barrier_timeout_s: float = 3600.0,
) -> RunStats:
    """Run (or resume, or extend) a sweep, or a slice of it, or this process's share of it, and write its results
    (see the module docstring).

    Args:
      sweep: a sweep file path or a :class:`SweepConfig`.
      out: output folder (default ``results/<name>``); an existing folder
        from the same sweep file and chunk size is resumed, or extended by a larger slice.
      chunk_size: scenarios per jitted call (>= 1); memory grows linearly with it.
        Rounded up to a multiple of the device count. None (default): the
        chunk size of the folder's manifest when resuming (or of its parts'
        plan records, when the manifest was deleted), else
        :func:`default_chunk_size` (:data:`DEFAULT_CHUNK` on CPU, sized to
        device memory on an accelerator; process 0 decides for all).
      max_scenarios: run only the first this many scenario ids (a check of the program: ids are cell-major, so
        fewer than ``scenarios_per_cell`` of the sweep cover its first cell alone).
      scenarios_per_cell: run only the first this many replicates of every cell: the sweep shrunk evenly, each
        cell on the same terrains with the same commands. Beyond the sweep's own: all of them. Not with
        ``max_scenarios``. Either makes a slice (:func:`ijoy_jax.sweep.results.selection`): computed in the
        whole sweep's chunks (the same compiled program), so a later run into ``out`` with a larger slice, or
        none, computes only the scenarios missing and the folder ends as a whole run's, bit for bit.
      progress: print a progress line (scenarios/s, ETA) to stderr.
      devices: split each chunk over the first this many local devices
        (default None: all of them); 1 runs on the default device.
      process_id, num_processes: run only the chunks with ``chunk_id % num_processes == process_id``
        (default: ``jax.process_index()`` and ``jax.process_count()``, i.e. the whole sweep
        unless ``jax.distributed`` is initialized). Give both or neither.
      barrier_timeout_s: with several processes under ``jax.distributed``, how long a finished
        process waits for the others before process 0 writes ``aggregates.parquet`` (a process
        that times out just skips that file; results are complete once every part exists).

    Returns:
      :class:`RunStats`.

    Raises:
      SweepConfigError: a bad sweep file (before any compute).
      ValueError: ``out`` holds results of a different sweep or chunk plan (the message lists what
        differs), a part or record that cannot be read (IncompleteSweepError naming it), or is in
        use by another run (its lock; members of one multi-process run share it), or a
        bad ``chunk_size``, ``max_scenarios``, ``scenarios_per_cell``, ``devices`` or process layout.

    Example:
      >>> from ijoy_jax import sweep
      >>> stats = sweep.run("sweeps/w_sweep.toml", "/tmp/w", scenarios_per_cell=2, progress=False)  # doctest: +SKIP
      >>> sweep.load("/tmp/w").shape[0], stats.sweep_complete  # 2 of 64 per cell, 8 cells  # doctest: +SKIP
      (16, False)
    """
    t_start = time.perf_counter()
    cfg = sweep if isinstance(sweep, SweepConfig) else load_config(sweep)
    if chunk_size is not None and (isinstance(chunk_size, bool) or not isinstance(chunk_size, int)
                                   or chunk_size < 1):
        raise ValueError(f"chunk_size must be a positive int or None, got {chunk_size!r}")
    for name, v in (("max_scenarios", max_scenarios), ("scenarios_per_cell", scenarios_per_cell)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise ValueError(f"{name} must be a positive int, got {v!r}")
    if max_scenarios is not None and scenarios_per_cell is not None:
        raise ValueError("give max_scenarios or scenarios_per_cell, not both (scenarios_per_cell: an even slice of "
                         "every cell; max_scenarios: the first scenario ids)")
    if isinstance(barrier_timeout_s, bool) or not isinstance(barrier_timeout_s, (int, float)) or not (
            0 < barrier_timeout_s < math.inf):
        raise ValueError(f"barrier_timeout_s must be a positive number of seconds, got {barrier_timeout_s!r}")
    pid, nproc = _process_layout(process_id, num_processes)
    devs = _local_devices(devices)
    out = Path(out) if out is not None else Path("results") / cfg.name
    sel = selection(cfg.num_cells, cfg.scenarios_per_cell, scenarios_per_cell=scenarios_per_cell,
                    max_scenarios=max_scenarios)
    table = _selected_rows(cfg, sel, progress)
    # Replicate 0 of every cell: the plan's groups, and the robots and MJX biped built for the whole sweep
    # (the same static windows and program for a slice as for the whole sweep).
    cell_rows = scenarios(dataclasses.replace(cfg, scenarios_per_cell=1))
    # Host-side robots per density (cheap, no compile): footprint problems surface before any output.
    bases = {d: _base_robot(cfg, cell_rows, d) for d in dict.fromkeys(cell_rows["robot.density"].tolist())}
    sim = _make_sim(cfg, cell_rows)  # the MJX biped of a physics sweep (host-side), before any output
    check_out_folder(out)
    lock = _FolderLock(out, pid, nproc)  # one run per folder (members of a multi-process run share it)
    try:
        return _run_locked(cfg, out, table, cell_rows, bases, sim, devs, pid, nproc, sel, chunk_size=chunk_size,
                           progress=progress, barrier_timeout_s=barrier_timeout_s, t_start=t_start)
    finally:
        lock.release()


def _selected_rows(cfg: SweepConfig, sel: dict, progress: bool):
    """The scenario rows of a :func:`~ijoy_jax.sweep.results.selection` (only those are built): the first N
    replicates of every cell are the rows of the sweep with N per cell, renumbered into the sweep's ids
    (replicate r's terrain, command and physics draws do not depend on the replicate count)."""
    import pandas as pd

    n, m, reps = sel["scenarios_per_cell"], sel["max_scenarios"], sel["replicates"]
    if n >= reps:
        return scenarios(cfg, progress=progress)
    tables = []
    if n:
        t = scenarios(dataclasses.replace(cfg, scenarios_per_cell=n), progress=progress)
        t["scenario"] = t["cell"] * reps + t["replicate"]
        tables.append(t)
    if m:
        tables.append(scenarios(cfg, m, progress=progress))
    t = tables[0] if len(tables) == 1 else pd.concat(tables).drop_duplicates("scenario")
    return t.sort_values("scenario", kind="stable").reset_index(drop=True)


def _held(path: Path, ids: np.ndarray) -> np.ndarray:
    """The scenario ids whose results the part of a chunk (its scenario ids ``ids``) holds: none without a part,
    all of them when its footer counts them all, else its ``scenario`` column."""
    import pyarrow.parquet as pq

    if not path.exists():
        return ids[:0]
    try:
        if pq.read_metadata(path).num_rows == len(ids):
            return ids
    except Exception:  # noqa: BLE001 - read_part names the damaged file in one line
        pass
    return read_part(path, ["scenario"])["scenario"].to_numpy(np.int64)


def _run_locked(cfg: SweepConfig, out: Path, table, cell_rows, bases: dict, sim, devs: list, pid: int, nproc: int,
                sel: dict, *, chunk_size, progress: bool, barrier_timeout_s: float, t_start: float) -> RunStats:
    """:func:`run` once it holds the folder's lock."""
    import pandas as pd

    ndev = len(devs)
    parts = out / "parts"
    manifest_path = out / "manifest.json"
    proc_path = out / "processes" / _PROC.format(pid)
    # IncompleteSweepError (a ValueError) naming a record that is not one, and the way out
    needed = ("sweep_text", "plan", "sessions")
    old = read_record(manifest_path, needed) if manifest_path.exists() else None
    mine = read_record(proc_path, needed) if pid > 0 and proc_path.exists() else None
    run_key = f"{cfg.name}/{sel['scenarios_per_cell']}/{sel['max_scenarios']}"  # the same in every process
    if chunk_size is None:
        # Resume with the folder's chunk size (its record's, else its parts': a deleted manifest is rewritten);
        # otherwise process 0 sizes it and the others take its figure.
        prev = (old or mine or {}).get("plan", {}).get("chunk_size") or _parts_chunk_size(parts)
        chunk_size = distributed.agree(f"ijoy_sweep/chunk_size/{run_key}",
                                       lambda: prev or default_chunk_size(cfg, cell_rows, bases, devs, sim), pid)
    chunk_size = -(-chunk_size // ndev) * ndev  # a multiple of the device count
    plan = chunk_plan(cfg, chunk_size, cell_rows)  # the whole sweep's, whatever slice this run computes
    # max_scenarios is null: a slice is recorded apart (selection), so it shares the whole sweep's plan and hash
    plan_key = {"chunk_size": chunk_size, "max_scenarios": None, "scenarios": cfg.num_scenarios,
                "chunks": len(plan)}
    if cfg.inputs:  # the files it reads (their hashes): a changed recording is another plan
        plan_key["inputs"] = cfg.inputs
    for prev in (old, mine):
        if prev is not None and (prev.get("sweep_text") != cfg.text or prev.get("plan") != plan_key):
            what = _what_differs(prev, cfg.text, plan_key)
            if prev.get("plan", {}).get("chunk_size") != plan_key["chunk_size"]:
                what += f"; chunk_size is rounded up to a multiple of the {ndev} device(s)"
            raise ValueError(f"{out} holds results of a different sweep or chunk plan ({what}); choose another "
                             f"--out or delete it")
    # Every part records its plan: parts of another plan (a deleted manifest) are never skipped as done.
    phash = plan_hash(cfg.text, plan_key)
    plan_record = {"hash": phash, "name": cfg.name, **plan_key}
    if parts.exists():  # IncompleteSweepError naming a part of another plan (and this run's), or a corrupt one
        # unrecorded (older) parts are vouched for by a matching manifest only
        check_plans(out, sorted(parts.glob("part-*.parquet")), plan_record, allow_unrecorded=(old or mine) is not None)
    # What the folder was asked for: the union of its runs' slices (a manifest from before slices: the plan's all)
    before = (old or {}).get("selection") or (selection(cfg.num_cells, cfg.scenarios_per_cell) if old else sel)
    union = selection(cfg.num_cells, cfg.scenarios_per_cell,
                      scenarios_per_cell=max(before["scenarios_per_cell"], sel["scenarios_per_cell"]),
                      max_scenarios=max(before["max_scenarios"], sel["max_scenarios"]))
    layout = {"num_processes": nproc, "rule": "chunk % num_processes == process_id",
              "process_files": "processes/process-NNNNN.json (sessions of processes 1..N-1)"}
    if pid == 0:  # the manifest and sweep.toml are written by process 0 only
        manifest = old or {"sweep_file": cfg.source, "sweep_text": cfg.text, "name": cfg.name, "plan": plan_key,
                           "versions": _versions(), "git_commit": _git_commit(), "sessions": []}
        manifest.setdefault("plan_hash", phash)  # a manifest from before plans were hashed: same text and plan
        manifest["layout"] = layout
        manifest["selection"] = union
        manifest.setdefault("complete", False)  # the whole sweep is in the folder (set when a session ends)
        record = manifest_path
    else:  # each other process writes only its own file
        manifest = mine or {"sweep_text": cfg.text, "plan": plan_key, "process_id": pid, "sessions": []}
        manifest.setdefault("plan_hash", phash)
        record = proc_path
    # The chunks this run's slice touches, with its scenarios in each; this process's share of them
    touched = []
    for chunk_id, group, ids in plan:
        want = ids[selected(ids, sel)]
        if len(want):
            touched.append((chunk_id, group, ids, want))
    mine_plan = [p for p in touched if p[0] % nproc == pid]
    parts.mkdir(parents=True, exist_ok=True)
    record.parent.mkdir(parents=True, exist_ok=True)
    if pid == 0:
        (out / "sweep.toml").write_text(cfg.text)
    truncated = sel["scenarios"] < sel["of"]
    session: dict[str, Any] = {"started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                               "process_id": pid, "num_processes": nproc, "chunks_assigned": len(mine_plan),
                               "selection": sel, "truncated": truncated,
                               "host": platform.node(),
                               "device": str(devs[0]), "backend": jax.default_backend(),
                               "device_count": jax.device_count(), "devices": ndev, "chunk_size": chunk_size,
                               "sharding": None if ndev == 1 else f"rows split evenly over {ndev} devices "
                                                                  f"({', '.join(str(d) for d in devs)}), the "
                                                                  "one-device program on each"}
    manifest["sessions"].append(session)
    _write_json(record, manifest)

    stats = RunStats(out=out, scenarios=sel["scenarios"], chunks=len(touched), devices=ndev, chunk_size=chunk_size,
                     physics_steps=_physics_steps(sim, cfg.num_steps), sweep_scenarios=cfg.num_scenarios)
    static = _static(cfg)
    run_chunk = _chunk_runner(static)
    on_devices = _OnDevices(devs)
    key = jax.random.key(cfg.seed)
    robot_cols, terrain_cols, sim_cols = _cols(table)
    # Scenarios per group of the whole plan, counted once: a group's call shape (the same for a slice)
    per_group: dict[tuple, int] = {}
    for _, group, ids in plan:
        per_group[group] = per_group.get(group, 0) + len(ids)
    # Per chunk of this process: the scenarios its part already holds, and those of the slice still to compute
    held = {p[0]: _held(parts / _PART.format(p[0]), p[2]) for p in mine_plan}
    need = {p[0]: p[3][~np.isin(p[3], held[p[0]])] for p in mine_plan}
    stats.skipped = sum(not len(v) for v in need.values())
    if pid == 0 and any(len(v) for v in need.values()):
        (out / "aggregates.parquet").unlink(missing_ok=True)  # stale once this run adds scenarios; rewritten after
    # Calls: per group, the scenarios to compute in plan order cut into the group's call shape; a call may hold
    # rows of several chunks (a slice's few rows of many chunks), each row written into its own chunk's part.
    calls = []
    for group in per_group:
        size = -(-min(chunk_size, per_group[group]) // ndev) * ndev  # every device gets the same rows
        rows_g = [(need[c], np.full(len(need[c]), c)) for c, g, _, _ in mine_plan if g == group and len(need[c])]
        if rows_g:
            ids_g, chunks_g = (np.concatenate(x) for x in zip(*rows_g, strict=True))
            calls += [(group, size, ids_g[i:i + size], chunks_g[i:i + size]) for i in range(0, len(ids_g), size)]
    total = int(sum(len(p[3]) for p in mine_plan))
    done_before = total - int(sum(len(v) for v in need.values()))
    who = f" {pid}/{nproc}" if nproc > 1 else ""
    by_id = table.set_index("scenario", drop=False)
    traces0 = trace_count()
    shared_of: dict[float, Any] = {}  # per density: (base robot, targets, key, sim, scene), placed
    computed = steady_n = 0
    steady_s = 0.0
    t_last = None  # when the last call's results were written

    def write(result) -> None:
        """Write a call's rows into their chunks' parts, each merged with the rows its part already holds."""
        for c in dict.fromkeys(result["chunk"].tolist()):
            rows = result[result["chunk"] == c]
            path = parts / _PART.format(c)
            if len(held[c]):  # an earlier slice's rows of this chunk: kept, the new ones added
                rows = pd.concat([read_part(path), rows], ignore_index=True).sort_values("scenario", kind="stable")
            tmp = path.with_name(f"{path.name}.{_WHO}.tmp")  # per process: members never share a temp file
            _write_part(rows.reset_index(drop=True), tmp, plan_record)
            os.replace(tmp, path)
            held[c] = rows["scenario"].to_numpy(np.int64)

    def finish(p) -> None:
        """Wait for a dispatched call's summaries, write its rows and count them."""
        nonlocal computed, steady_n, steady_s, t_last
        index, label, rows, chunk_of, outs, t0 = p
        summary = _OnDevices.collect(outs)
        n = len(rows)
        result = rows.reset_index(drop=True).copy()
        for k, v in summary.items():
            result[k] = np.asarray(v)[:n]
        result.insert(1, "chunk", chunk_of.astype(np.int64))
        write(result)
        now = time.perf_counter()
        # A call's time: from its start, or from the last write when it ran behind the call before it.
        dt = now - (t0 if t_last is None else max(t0, t_last))
        t_last = now
        if label not in stats.first_chunk_s:
            stats.first_chunk_s[label] = dt  # includes the compile
        else:
            steady_n, steady_s = steady_n + n, steady_s + dt
        computed += n
        if progress:
            # Rate over compiled calls only (the first call of a density includes its compile).
            rate = steady_n / steady_s if steady_n else n / dt
            _progress(done_before + computed, total, rate, index + 1, len(calls), who, stats.physics_steps)

    # One call in flight behind the host: call k+1 is built and dispatched before call k's summaries are
    # fetched and written, so the devices compute while the host writes. A call that compiles (the first of
    # its group) waits until the one before is written, so no compile time is counted in a steady call.
    pending = None

    def finish_pending(new=None) -> None:
        """Finish the call in flight, if any; ``new`` (a dispatched call, or None) is in flight after."""
        nonlocal pending
        done, pending = pending, new
        if done is not None:
            finish(done)

    try:
        for index, (group, size, ids, chunk_of) in enumerate(calls):
            density = group[0]
            static_g = static._replace(horizon=group[1], refine=group[2])
            label = _group_label(cfg, group)
            if pending is not None and label not in stats.first_chunk_s and label != pending[1]:
                finish_pending()
            t0 = time.perf_counter()
            if density not in shared_of:  # shared by every scenario: a copy on every device
                shared_of[density] = on_devices.put_shared((*_shared(cell_rows, bases[density]), key, sim,
                                                            _scene(cfg)))
            rows = by_id.loc[ids]
            batch = _batch(rows, size, robot_cols, terrain_cols, sim_cols, cfg=cfg)
            outs = on_devices.dispatch(run_chunk, static_g, shared_of[density], batch)
            finish_pending((index, label, rows, chunk_of, outs, t0))
        finish_pending()
    finally:
        if pending is not None:  # an error or interrupt after a call was dispatched: keep its results
            try:
                finish(pending)
            except Exception:  # noqa: BLE001 - the error that got here is the one to report
                pass
    stats.computed = computed
    stats.rate = steady_n / steady_s if steady_n else 0.0
    stats.compiles = trace_count() - traces0
    stats.run_s = time.perf_counter() - t_start

    def lacking(chunks, of_sel) -> list[int]:
        """The chunks (id, group, ids, ...) whose parts lack scenarios of the selection ``of_sel``."""
        out_ = []
        for chunk_id, _, ids, *_ in chunks:
            want = ids[selected(ids, of_sel)]
            have = held[chunk_id] if chunk_id in held else _held(parts / _PART.format(chunk_id), ids)
            if len(want) and not np.isin(want, have).all():
                out_.append(chunk_id)
        return out_

    if nproc > 1:  # no device collective: the coordination service's barrier (skipped without jax.distributed)
        missing = sorted({c % nproc for c in lacking(touched, sel)})
        if progress and missing and distributed.client() is not None:
            print(f"[ijoy sweep{who}] this process is done; waiting up to {barrier_timeout_s:g} s for process(es) "
                  f"{', '.join(map(str, missing))} (relaunch one that died with its same command)", file=sys.stderr)
        distributed.barrier(f"ijoy_sweep/done/{run_key}", barrier_timeout_s)
    complete = stats.complete = not lacking(touched, sel)
    stats.sweep_complete = complete and not lacking(plan, selection(cfg.num_cells, cfg.scenarios_per_cell))
    if pid == 0:
        if complete and not lacking(plan, union):  # everything the folder was asked for
            from ijoy_jax.sweep.results import aggregate, load

            aggregate(load(out), cfg.swept).to_parquet(out / "aggregates.parquet", index=False)
        manifest["complete"] = stats.sweep_complete
    session.update(finished=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), run_s=stats.run_s,
                   computed=computed, skipped_chunks=stats.skipped, compiles=stats.compiles, rate=stats.rate,
                   physics_steps_per_scenario=stats.physics_steps,
                   first_chunk_s={str(k): v for k, v in stats.first_chunk_s.items()}, complete=complete)
    _write_json(record, manifest)
    if progress and not calls:
        print(f"[ijoy sweep{who}] {out}: all {len(mine_plan)} of this process's chunks already done",
              file=sys.stderr)
    if progress and truncated and pid == 0:
        print(f"[ijoy sweep] {out}: a slice of the sweep, {describe_selection(sel)}; the manifest marks the folder "
              "incomplete: a later run into this --out with a larger slice, or the whole sweep, computes only the "
              "scenarios missing", file=sys.stderr)
    return stats
