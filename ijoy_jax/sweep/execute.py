"""Running a sweep: scenarios batched with jit + vmap in chunks, written as they complete, resumable.

A run reads the folder's records and fixes the chunk plan (:mod:`ijoy_jax.sweep.plan`; the chunk size:
:mod:`ijoy_jax.sweep.sizing`), refuses a folder of another plan, records its session
(:mod:`ijoy_jax.sweep.folder`: the folder's layout, lock, records and parts), then computes the scenarios its
parts lack in calls of the chunk programs (:mod:`ijoy_jax.sweep.programs`) split over the local devices
(:mod:`ijoy_jax.sweep.devices`), and at the end writes the aggregates and closes its session.

One chunk is in flight behind the host: chunk k+1 is built and dispatched before chunk k's
summaries are fetched and its part written (the first chunk of a group, which compiles, waits until
the chunk before it is written, so steady rates hold no compile time); a chunk dispatched before an
error or interrupt is still written.

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
slice (:func:`ijoy_jax.sweep.plan.selection`) computed in the whole sweep's chunks: calls of the group's
chunk shape (the whole run's compiled program) hold the slice's rows of one or more chunks, and each row is
written into its own chunk's part, merged with the rows that part already holds. So a later run into the
same folder with a larger slice, or none, computes only the scenarios missing, and the folder ends equal to
a whole run's, bit for bit. ``manifest.json`` records the union of the slices asked (``selection``) and
whether the folder holds the whole sweep (``complete``); each session its own ``selection`` and
``truncated``.

Resume. The chunk plan is a pure function of the sweep file and ``chunk_size``
(after rounding to the device count), the whole sweep's whatever slice a run computes, and is saved in the
manifest; a rerun with another device count resumes when the rounded chunk
size is the same (e.g. the default 32 on 1, 2, 4 or 8 devices). Nothing is lost or duplicated: see
:mod:`ijoy_jax.sweep.folder` for how parts are written, checked against their plan and read back.
"""

from __future__ import annotations

import dataclasses
import math
import platform
import sys
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ijoy_jax.sweep import distributed
from ijoy_jax.sweep.config import load_config
from ijoy_jax.sweep.devices import OnDevices, local_devices
from ijoy_jax.sweep.expansion import scenarios
from ijoy_jax.sweep.folder import (
    FolderLock,
    check_out_folder,
    check_plans,
    check_same_plan,
    held_ids,
    part_path,
    parts_chunk_size,
    read_records,
    start_session,
    write_record,
    write_rows,
)
from ijoy_jax.sweep.plan import chunk_plan, describe_selection, plan_hash, selected, selection
from ijoy_jax.sweep.programs import (
    Scenario,
    base_robot,
    chunk_batch,
    chunk_runner,
    chunk_scene,
    chunk_static,
    make_sim,
    physics_steps_per_scenario,
    scenario,
    scenario_bytes,
    shared_inputs,
    trace_count,
    value_columns,
)
from ijoy_jax.sweep.schema import SweepConfig
from ijoy_jax.sweep.sizing import (
    DEFAULT_CHUNK,
    MAX_AUTO_CHUNK,
    MEMORY_FRACTION,
    auto_chunk_size,
    balanced_chunk_size,  # noqa: F401 - importable from here, as before
    default_chunk_size,
)

__all__ = ["DEFAULT_CHUNK", "MAX_AUTO_CHUNK", "MEMORY_FRACTION", "RunStats", "Scenario", "auto_chunk_size",
           "default_chunk_size", "run", "scenario", "scenario_bytes", "trace_count"]


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
        ``max_scenarios``. Either makes a slice (:func:`ijoy_jax.sweep.plan.selection`): computed in the
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
    pid, nproc = distributed.process_layout(process_id, num_processes)
    devs = local_devices(devices)
    out = Path(out) if out is not None else Path("results") / cfg.name
    sel = selection(cfg.num_cells, cfg.scenarios_per_cell, scenarios_per_cell=scenarios_per_cell,
                    max_scenarios=max_scenarios)
    table = _selected_rows(cfg, sel, progress)
    # Replicate 0 of every cell: the plan's groups, and the robots and MJX biped built for the whole sweep
    # (the same static windows and program for a slice as for the whole sweep).
    cell_rows = scenarios(dataclasses.replace(cfg, scenarios_per_cell=1))
    # Host-side robots per density (cheap, no compile): footprint problems surface before any output.
    bases = {d: base_robot(cfg, cell_rows, d) for d in dict.fromkeys(cell_rows["robot.density"].tolist())}
    sim = make_sim(cfg, cell_rows)  # the MJX biped of a physics sweep (host-side), before any output
    check_out_folder(out)
    lock = FolderLock(out, pid, nproc)  # one run per folder (members of a multi-process run share it)
    try:
        return _run_locked(cfg, out, table, cell_rows, bases, sim, devs, pid, nproc, sel, chunk_size=chunk_size,
                           progress=progress, barrier_timeout_s=barrier_timeout_s, t_start=t_start)
    finally:
        lock.release()


def _selected_rows(cfg: SweepConfig, sel: dict, progress: bool):
    """The scenario rows of a :func:`~ijoy_jax.sweep.plan.selection` (only those are built): the first N
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



def _group_label(cfg: SweepConfig, group: tuple):
    """How a group is named in :attr:`RunStats.first_chunk_s`: its density when the selector is not swept,
    else ``"<density> horizon=<h> refine=<r>"``."""
    density, horizon, refine = group
    if "selector.horizon" not in cfg.grid and "selector.refine" not in cfg.grid:
        return density
    return f"{density:g} horizon={horizon} refine={str(refine).lower()}"



def _progress(done: int, total: int, rate: float, chunk: int, nchunks: int, who: str = "",
              physics_steps: int = 0) -> None:
    eta = (total - done) / rate if rate > 0 else float("nan")
    physics = f" ({rate * physics_steps / 1e6:.3g} M physics steps/s)" if physics_steps else ""
    line = (f"[ijoy sweep{who}] {done}/{total} scenarios  chunk {chunk}/{nchunks}  "
            f"{rate:.1f} scenarios/s{physics}  ETA {eta:.0f} s")
    end = "\r" if sys.stderr.isatty() and done < total else "\n"
    print(line.ljust(78), end=end, file=sys.stderr, flush=True)


def _run_locked(cfg: SweepConfig, out: Path, table, cell_rows, bases: dict, sim, devs: list, pid: int, nproc: int,
                sel: dict, *, chunk_size, progress: bool, barrier_timeout_s: float, t_start: float) -> RunStats:
    """:func:`run` once it holds the folder's lock: the plan, checked against the folder's; the session
    recorded; the calls of the scenarios the parts lack, computed; then the end of the run."""
    ndev = len(devs)
    parts = out / "parts"
    old, mine = read_records(out, pid)  # IncompleteSweepError (a ValueError) naming a record that is not one
    run_key = f"{cfg.name}/{sel['scenarios_per_cell']}/{sel['max_scenarios']}"  # the same in every process
    chunk_size = _chunk_size(cfg, chunk_size, old or mine, out, run_key, cell_rows, bases, devs, sim, pid)
    plan = chunk_plan(cfg, chunk_size, cell_rows)  # the whole sweep's, whatever slice this run computes
    plan_key = _plan_key(cfg, chunk_size, plan)
    check_same_plan(out, (old, mine), cfg.text, plan_key, ndev)
    # Every part records its plan: parts of another plan (a deleted manifest) are never skipped as done.
    phash = plan_hash(cfg.text, plan_key)
    plan_record = {"hash": phash, "name": cfg.name, **plan_key}
    if parts.exists():  # IncompleteSweepError naming a part of another plan (and this run's), or a corrupt one
        # unrecorded (older) parts are vouched for by a matching manifest only
        check_plans(out, sorted(parts.glob("part-*.parquet")), plan_record, allow_unrecorded=(old or mine) is not None)
    union = _asked(cfg, old, sel)
    # The chunks this run's slice touches, with its scenarios in each; this process's share of them
    touched = _touched(plan, sel)
    mine_plan = [p for p in touched if p[0] % nproc == pid]
    truncated = sel["scenarios"] < sel["of"]
    session = _session(pid, nproc, len(mine_plan), sel, truncated, devs, chunk_size)
    manifest, record = start_session(out, cfg, pid, nproc, old, mine, plan_key, phash, union, session)

    stats = RunStats(out=out, scenarios=sel["scenarios"], chunks=len(touched), devices=ndev, chunk_size=chunk_size,
                     physics_steps=physics_steps_per_scenario(sim, cfg.num_steps), sweep_scenarios=cfg.num_scenarios)
    # Per chunk of this process: the scenarios its part already holds, and those of the slice still to compute
    held = {p[0]: held_ids(part_path(out, p[0]), p[2]) for p in mine_plan}
    need = {p[0]: p[3][~np.isin(p[3], held[p[0]])] for p in mine_plan}
    stats.skipped = sum(not len(v) for v in need.values())
    if pid == 0 and any(len(v) for v in need.values()):
        (out / "aggregates.parquet").unlink(missing_ok=True)  # stale once this run adds scenarios; rewritten after
    calls = _calls(plan, mine_plan, need, chunk_size, ndev)
    total = int(sum(len(p[3]) for p in mine_plan))
    done_before = total - int(sum(len(v) for v in need.values()))
    who = f" {pid}/{nproc}" if nproc > 1 else ""
    _compute(cfg, calls, table, cell_rows, bases, sim, devs, out, held, plan_record, stats, progress=progress,
             who=who, total=total, done_before=done_before)
    stats.run_s = time.perf_counter() - t_start
    _end(cfg, out, plan, touched, union, sel, held, stats, pid, nproc, progress=progress, who=who, run_key=run_key,
         barrier_timeout_s=barrier_timeout_s, manifest=manifest, record=record, session=session)
    if progress and not calls:
        print(f"[ijoy sweep{who}] {out}: all {len(mine_plan)} of this process's chunks already done",
              file=sys.stderr)
    if progress and truncated and pid == 0:
        print(f"[ijoy sweep] {out}: a slice of the sweep, {describe_selection(sel)}; the manifest marks the folder "
              "incomplete: a later run into this --out with a larger slice, or the whole sweep, computes only the "
              "scenarios missing", file=sys.stderr)
    return stats


def _chunk_size(cfg: SweepConfig, chunk_size, prev_record, out: Path, run_key: str, cell_rows, bases: dict,
                devs: list, sim, pid: int) -> int:
    """The plan's chunk size: the one asked, else the folder's (its record's, else its parts': a deleted manifest
    is rewritten), else process 0 sizes it (:func:`default_chunk_size`) and the others take its figure; rounded
    up to a multiple of the device count."""
    if chunk_size is None:
        prev = (prev_record or {}).get("plan", {}).get("chunk_size") or parts_chunk_size(out / "parts")
        chunk_size = distributed.agree(f"ijoy_sweep/chunk_size/{run_key}",
                                       lambda: prev or default_chunk_size(cfg, cell_rows, bases, devs, sim), pid)
    return -(-chunk_size // len(devs)) * len(devs)  # a multiple of the device count


def _plan_key(cfg: SweepConfig, chunk_size: int, plan: list) -> dict:
    """The plan a run records (and hashes): chunk size, scenario and chunk counts, and the input files' hashes."""
    # max_scenarios is null: a slice is recorded apart (selection), so it shares the whole sweep's plan and hash
    plan_key = {"chunk_size": chunk_size, "max_scenarios": None, "scenarios": cfg.num_scenarios,
                "chunks": len(plan)}
    if cfg.inputs:  # the files it reads (their hashes): a changed recording is another plan
        plan_key["inputs"] = cfg.inputs
    return plan_key


def _asked(cfg: SweepConfig, old: dict | None, sel: dict) -> dict:
    """What the folder was asked for: the union of its runs' slices (a manifest from before slices: the plan's
    all) and this run's ``sel``."""
    before = (old or {}).get("selection") or (selection(cfg.num_cells, cfg.scenarios_per_cell) if old else sel)
    return selection(cfg.num_cells, cfg.scenarios_per_cell,
                     scenarios_per_cell=max(before["scenarios_per_cell"], sel["scenarios_per_cell"]),
                     max_scenarios=max(before["max_scenarios"], sel["max_scenarios"]))


def _touched(plan: list, sel: dict) -> list:
    """The chunks ``(chunk id, group, ids, wanted ids)`` of the plan holding scenarios of the selection ``sel``."""
    touched = []
    for chunk_id, group, ids in plan:
        want = ids[selected(ids, sel)]
        if len(want):
            touched.append((chunk_id, group, ids, want))
    return touched


def _session(pid: int, nproc: int, chunks_assigned: int, sel: dict, truncated: bool, devs: list,
             chunk_size: int) -> dict[str, Any]:
    """A session's record as it starts: the process layout, the slice, the host and devices, the chunk size."""
    ndev = len(devs)
    return {"started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "process_id": pid, "num_processes": nproc, "chunks_assigned": chunks_assigned,
            "selection": sel, "truncated": truncated,
            "host": platform.node(),
            "device": str(devs[0]), "backend": jax.default_backend(),
            "device_count": jax.device_count(), "devices": ndev, "chunk_size": chunk_size,
            "sharding": None if ndev == 1 else f"rows split evenly over {ndev} devices "
                                               f"({', '.join(str(d) for d in devs)}), the "
                                               "one-device program on each"}


def _calls(plan: list, mine_plan: list, need: dict, chunk_size: int, ndev: int) -> list:
    """The calls ``(group, call size, scenario ids, their chunks)``: per group, the scenarios to compute in plan
    order cut into the group's call shape; a call may hold rows of several chunks (a slice's few rows of many
    chunks), each row written into its own chunk's part."""
    # Scenarios per group of the whole plan, counted once: a group's call shape (the same for a slice)
    per_group: dict[tuple, int] = {}
    for _, group, ids in plan:
        per_group[group] = per_group.get(group, 0) + len(ids)
    calls = []
    for group in per_group:
        size = -(-min(chunk_size, per_group[group]) // ndev) * ndev  # every device gets the same rows
        rows_g = [(need[c], np.full(len(need[c]), c)) for c, g, _, _ in mine_plan if g == group and len(need[c])]
        if rows_g:
            ids_g, chunks_g = (np.concatenate(x) for x in zip(*rows_g, strict=True))
            calls += [(group, size, ids_g[i:i + size], chunks_g[i:i + size]) for i in range(0, len(ids_g), size)]
    return calls


def _compute(cfg: SweepConfig, calls: list, table, cell_rows, bases: dict, sim, devs: list, out: Path, held: dict,
             plan_record: dict, stats: RunStats, *, progress: bool, who: str, total: int, done_before: int) -> None:
    """Run the ``calls`` on the devices and write their rows into their parts as they complete; fills ``stats``'s
    computed scenarios, first-chunk times, steady rate and compiles."""
    static = chunk_static(cfg)
    run_chunk = chunk_runner(static)
    on_devices = OnDevices(devs)
    key = jax.random.key(cfg.seed)
    robot_cols, terrain_cols, sim_cols = value_columns(table)
    by_id = table.set_index("scenario", drop=False)
    traces0 = trace_count()
    shared_of: dict[float, Any] = {}  # per density: (base robot, targets, key, sim, scene), placed
    computed = steady_n = 0
    steady_s = 0.0
    t_last = None  # when the last call's results were written

    def finish(p) -> None:
        """Wait for a dispatched call's summaries, write its rows and count them."""
        nonlocal computed, steady_n, steady_s, t_last
        index, label, rows, chunk_of, outs, t0 = p
        summary = OnDevices.collect(outs)
        n = len(rows)
        result = rows.reset_index(drop=True).copy()
        for k, v in summary.items():
            result[k] = np.asarray(v)[:n]
        result.insert(1, "chunk", chunk_of.astype(np.int64))
        write_rows(out, result, held, plan_record)
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
            static_g = chunk_static(cfg, group[1], group[2])
            label = _group_label(cfg, group)
            if pending is not None and label not in stats.first_chunk_s and label != pending[1]:
                finish_pending()
            t0 = time.perf_counter()
            if density not in shared_of:  # shared by every scenario: a copy on every device
                shared_of[density] = on_devices.put_shared((*shared_inputs(cell_rows, bases[density]), key, sim,
                                                            chunk_scene(cfg)))
            rows = by_id.loc[ids]
            batch = chunk_batch(rows, size, robot_cols, terrain_cols, sim_cols, cfg=cfg, base=bases[density])
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


def _end(cfg: SweepConfig, out: Path, plan: list, touched: list, union: dict, sel: dict, held: dict,
         stats: RunStats, pid: int, nproc: int, *, progress: bool, who: str, run_key: str, barrier_timeout_s: float,
         manifest: dict, record: Path, session: dict) -> None:
    """The end of a run: with several processes, wait for the others (the coordination service's barrier);
    whether the slice and the whole sweep are complete; process 0 writes the aggregates once the folder holds
    everything it was asked for; the session is closed in the record."""

    def lacking(chunks, of_sel) -> list[int]:
        """The chunks (id, group, ids, ...) whose parts lack scenarios of the selection ``of_sel``."""
        out_ = []
        for chunk_id, _, ids, *_ in chunks:
            want = ids[selected(ids, of_sel)]
            have = held[chunk_id] if chunk_id in held else held_ids(part_path(out, chunk_id), ids)
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
                   computed=stats.computed, skipped_chunks=stats.skipped, compiles=stats.compiles, rate=stats.rate,
                   physics_steps_per_scenario=stats.physics_steps,
                   first_chunk_s={str(k): v for k, v in stats.first_chunk_s.items()}, complete=complete)
    write_record(record, manifest)
