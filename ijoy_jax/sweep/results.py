"""Sweep results: the tidy per-scenario table, per-cell aggregates with 95% confidence intervals, a plot.

Per-scenario table (:func:`load`): one row per scenario with its parameters
(``robot.*``, ``terrain.*``, ``command.*``), ids (``scenario``, ``cell``,
``replicate``, ``chunk``) and the metrics of :meth:`ijoy_jax.Trajectory.summary`
(:data:`METRICS`, units in :data:`UNITS`), plus the terrain family's extra
metrics (:data:`EXTRA_METRICS`, e.g. ``crossed`` for bars) when it has any, and for
a ``walker = "mjx"`` sweep its physics (``sim.*``) and the physics metrics of
:func:`ijoy_jax.sim.walker.summary` (:data:`PHYSICS_METRICS`).

Aggregates (:func:`aggregate`): per cell and metric, ``mean``, ``std``
(sample, ddof 1), ``n``, ``sem = std / sqrt(n)`` and the half-width
``ci95 = t_{0.975, n-1} * sem`` of a two-sided 95% Student-t interval for the
mean (``mean +- ci95``; NaN for n < 2). Boolean metrics (``stopped``;
``fell`` and ``collided``: the fall and collision rates) are averaged as
fractions. The t quantile comes from a table (n - 1 <= 30) and a
Cornish-Fisher expansion beyond (:func:`ijoy_jax.stats.t_quantile`; no SciPy needed).
Scenarios of a replicate share terrain and command across cells (paired), so
differences between cells are estimated more precisely than these marginal
intervals suggest.

Slices. A run may compute part of a sweep (:func:`selection`: the first N replicates of every cell, or the
first M scenario ids) into a folder that a later run with more scenarios extends: the chunk plan is always the
whole sweep's (:func:`chunk_plan`), a part holds the rows of its chunk computed so far, and ``manifest.json``
records what the folder was asked for (``selection``) and whether it holds the whole sweep (``complete``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from pathlib import Path

import numpy as np

from ijoy_jax.stats import t_quantile
from ijoy_jax.sweep.config import METRICS, PHYSICS_METRICS, ROBOT_DEFAULTS, SweepConfig, parse_config, scenarios
from ijoy_jax.terrain import generators

__all__ = ["EXTRA_METRICS", "PAPER_ACTIONS", "PHYSICS_PLOT_METRICS", "PLAN_KEY",
           "PLOT_METRICS", "SELECTOR_PLOT_METRICS", "UNITS", "IncompleteSweepError", "action_counts",
           "aggregate", "b_max", "check_plans", "chunk_plan", "describe_plan", "describe_selection",
           "differences", "load", "load_aggregates", "paired_differences",
           "part_plan", "plan_hash", "read_part", "read_record", "selected", "selection",
           "plot", "plot_crossing", "plot_tradeoff", "summary_metrics"]

EXTRA_METRICS = generators.METRIC_NAMES
"""Family-specific metrics (every family's ``metric_names``, :data:`ijoy_jax.terrain.generators.METRIC_NAMES`),
aggregated when present; bars: ``bars_crossed`` bars passed by both feet, ``crossed`` every bar passed
(fraction of scenarios)."""

UNITS = {
    "steps_taken": "steps", "steps_in_place": "steps", "steps_stationary": "steps", "stopped": "fraction",
    "footholds_on_obstacles": "footholds", "footholds_near_obstacles": "footholds", "invalid_footholds": "footholds",
    "distance_along": "m",
    "distance_across": "m",
    "mean_deviation": "m", "mean_foot_cost": "cost units", "commands_not_finite": "decisions",
    "unsupported_decisions": "decisions", "robot.w": "cost units per m",
    "robot.rotation_weight": "cost units per rad",
    "robot.margin": "m", "robot.step_time": "s", "robot.foot_length": "m", "robot.foot_width": "m",
    "robot.max_sole_pitch": "rad", "robot.max_sole_roll": "rad", "robot.max_sole_distance": "m",
    "robot.density": "x HRP-2's 496 actions", "robot.reach": "m", "terrain.rise": "m", "terrain.run": "m",
    "command.vx": "m/s", "command.vy": "m/s", "command.wz": "rad/s",
    "bars_crossed": "bars", "crossed": "fraction", "terrain.width": "m",
    "fell": "fraction", "collided": "fraction", "obstacle_contacts": "steps", "placement_error_mean": "m",
    "placement_error_p95": "m", "yaw_error_mean": "rad", "tilt_error_p95": "rad", "dynamics_invalid": "fraction",
    "sim.friction": "coefficient", "sim.mass_scale": "x nominal", "sim.kp_scale": "x nominal", "sim.latency": "s",
    "sim.stance_noise": "m", "sim.push": "N s",
    "selector.horizon": "steps scored", "selector.refine": "0 or 1", "selector.discount": "1",
}
"""Units of metrics and parameters, for tables and axis labels."""

_PARAMS = ("robot.", "terrain.", "sim.", "selector.")  # the prefixes of the parameter columns

class IncompleteSweepError(ValueError):
    """A sweep folder lacks chunks (a process has not finished), holds duplicated scenarios, mixes in parts
    of another plan, or holds a part or record that cannot be read (truncated, overwritten or hand-edited)."""


def _reason(e: BaseException) -> str:
    """An exception's message as one short line (a parquet or JSON reader's may span lines)."""
    text = " ".join(str(e).split()) or type(e).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def _corrupt_part(path, e: BaseException) -> IncompleteSweepError:
    return IncompleteSweepError(
        f"{path}: corrupt or truncated result part ({_reason(e)}); delete it and rerun `ijoy sweep run` with the "
        f"same sweep file and --out: the run recomputes that chunk alone")


def read_record(path, required: tuple[str, ...] = ()) -> dict:
    """A sweep folder's JSON record (``manifest.json``, ``processes/process-*.json``) as a dict.

    Args:
      path: the record's file.
      required: keys it must hold. Whatever it holds of ``plan`` (a dict with integer ``chunks`` and
        ``scenarios``), ``sweep_text`` (a string) and ``sessions`` (a list of dicts) must have that form.

    Raises:
      IncompleteSweepError: one line naming the file, what is wrong with it and the way out: every part
        records its plan (chunk size included), so a run with the same sweep file and ``--out`` writes the
        record anew once it is deleted, and resumes (only the record's session history is lost, and with it
        what slice the folder was asked for: give ``--scenarios-per-cell`` or ``--max-scenarios`` again).
    """
    path = Path(path)
    way_out = ("delete it and rerun `ijoy sweep run` with the same sweep file and --out (and --scenarios-per-cell "
               "or --max-scenarios as before): the parts record their plan, so the run writes it anew and resumes")
    try:
        record = json.loads(path.read_bytes())
    except OSError as e:
        raise IncompleteSweepError(f"{path}: cannot read the sweep's record: {e.strerror or e}") from None
    except ValueError as e:  # JSONDecodeError, UnicodeDecodeError
        raise IncompleteSweepError(f"{path}: corrupt or truncated record, not JSON ({_reason(e)}); "
                                   f"{way_out}") from None
    if not isinstance(record, dict):
        raise IncompleteSweepError(f"{path}: corrupt record: a JSON {type(record).__name__}, not an object; "
                                   f"{way_out}")
    plan = record.get("plan", {})
    problems = [f"no {k!r}" for k in required if k not in record]
    if not isinstance(plan, dict) or any(isinstance(plan.get(k), bool) or not isinstance(plan.get(k), int)
                                         for k in ("chunks", "scenarios") if "plan" in record):
        problems.append("'plan' is not an object with integer 'chunks' and 'scenarios'")
    if not isinstance(record.get("sweep_text", ""), str):
        problems.append("'sweep_text' is not a string")
    sel = record.get("selection", {})
    if not isinstance(sel, dict) or any(isinstance(sel.get(k), bool) or not isinstance(sel.get(k), int)
                                        or sel[k] < (1 if k == "replicates" else 0)
                                        for k in ("scenarios_per_cell", "max_scenarios", "replicates", "cells",
                                                  "scenarios", "of") if "selection" in record):
        problems.append("'selection' is not an object with non-negative integer 'scenarios_per_cell', "
                        "'max_scenarios', 'replicates' (>= 1), 'cells', 'scenarios' and 'of'")
    sessions = record.get("sessions", [])
    if not isinstance(sessions, list) or not all(isinstance(x, dict) for x in sessions):
        problems.append("'sessions' is not a list of objects")
    if problems:
        raise IncompleteSweepError(f"{path}: corrupt record ({'; '.join(problems)}); {way_out}")
    return record


PLAN_KEY = b"ijoy_jax.plan"
"""Key of the plan record in every part's parquet metadata: JSON ``{"hash", "name", "chunk_size",
"max_scenarios", "scenarios", "chunks"}`` (the hash of the sweep text and the chunk plan, :func:`plan_hash`).
The plan is the whole sweep's (``max_scenarios`` null), whatever slice of it a run computes
(:func:`selection`), so a slice and the whole sweep share a folder."""


def plan_hash(sweep_text: str, plan: dict) -> str:
    """The hash (16 hex digits) of a sweep's plan: its file's text and its chunk plan (chunk size,
    ``max_scenarios``, scenario and chunk counts); everything that decides which results a chunk holds. A run
    of a slice of the sweep (:func:`selection`) has the whole sweep's plan, and so its hash.

    Example:
      >>> plan_hash("[sweep]\\n", {"chunk_size": 2}) == plan_hash("[sweep]\\n", {"chunk_size": 3})
      False
    """
    blob = json.dumps({"sweep_text": sweep_text, "plan": plan}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def part_plan(path) -> dict | None:
    """The plan record a part file was written with (:data:`PLAN_KEY`), or None for a part written before
    parts recorded their plan. Reads only the file's footer.

    Raises:
      IncompleteSweepError: the file is not a readable parquet file (truncated, overwritten) or its plan
        record is not a JSON object; the message names the file and says to delete it and rerun.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        meta = pq.read_schema(path).metadata or {}
    except (OSError, ValueError, pa.ArrowException) as e:  # ArrowInvalid: "Parquet magic bytes not found"
        raise _corrupt_part(path, e) from None
    if PLAN_KEY not in meta:
        return None
    try:
        record = json.loads(meta[PLAN_KEY])
    except ValueError as e:
        raise _corrupt_part(path, ValueError(f"its plan record is not JSON: {e}")) from None
    if not isinstance(record, dict):
        raise _corrupt_part(path, ValueError("its plan record is not a JSON object"))
    return record


def describe_plan(record: dict | None) -> str:
    """``plan <hash> (sweep 'name', 12 scenarios in 6 chunks of 2)``, for error messages."""
    if record is None:
        return "an unrecorded plan (a part written before parts recorded their plan)"
    return (f"plan {record.get('hash')} (sweep {record.get('name')!r}, {record.get('scenarios')} scenarios in "
            f"{record.get('chunks')} chunks of {record.get('chunk_size')})")


def selection(num_cells: int, replicates: int, *, scenarios_per_cell: int | None = None,
              max_scenarios: int | None = None) -> dict:
    """Which scenarios of a sweep a run computes, or a folder was asked for, as its manifest records it.

    Scenario ``s = cell * replicates + replicate`` is selected when ``replicate < scenarios_per_cell`` or
    ``s < max_scenarios``: the first N replicates of every cell (an even slice: every cell, the same terrains
    and commands in each) and the first M scenario ids (cell 0's replicates first). Neither given: the whole
    sweep. The union of two selections is the selection of their larger N and larger M, so a folder's
    results only ever grow towards the whole sweep.

    Args:
      num_cells, replicates: the sweep's cells and scenarios per cell (``SweepConfig.num_cells``,
        ``SweepConfig.scenarios_per_cell``).
      scenarios_per_cell: N (>= 0; beyond ``replicates`` means all of them), or None.
      max_scenarios: M (>= 0; beyond the sweep's scenarios means all of them), or None.

    Returns:
      ``{"scenarios_per_cell": N, "max_scenarios": M, "replicates", "cells", "scenarios": how many are
      selected, "of": the sweep's scenarios}``, with ``N == replicates`` and ``M == 0`` for the whole sweep.

    Example:
      >>> selection(8, 64, scenarios_per_cell=2)["scenarios"], selection(8, 64, max_scenarios=64)["scenarios"]
      (16, 64)
      >>> selection(4, 3, scenarios_per_cell=1, max_scenarios=4)["scenarios"]  # ids 0, 3, 6, 9 and 0, 1, 2, 3
      6
    """
    total = num_cells * replicates
    if scenarios_per_cell is None and max_scenarios is None:
        n, m = replicates, 0
    else:
        n, m = min(int(scenarios_per_cell or 0), replicates), min(int(max_scenarios or 0), total)
    if n >= replicates or m >= total:  # the whole sweep, one way of writing it
        n, m = replicates, 0
    q, rem = divmod(m, replicates)
    count = num_cells * n + q * (replicates - n) + max(0, rem - n)  # ids below m whose replicate is >= n
    return {"scenarios_per_cell": n, "max_scenarios": m, "replicates": replicates, "cells": num_cells,
            "scenarios": count, "of": total}


def selected(ids, sel: dict) -> np.ndarray:
    """Which scenario ids (an int array) the :func:`selection` ``sel`` holds: a bool array of their shape.

    Example:
      >>> selected([0, 1, 3, 4], selection(2, 3, scenarios_per_cell=1)).tolist()
      [True, False, True, False]
    """
    ids = np.asarray(ids, np.int64)
    return (ids % sel["replicates"] < sel["scenarios_per_cell"]) | (ids < sel["max_scenarios"])


def describe_selection(sel: dict) -> str:
    """A :func:`selection` in words, for messages: ``2 of 64 scenarios per cell (16 of 512 scenarios)``.

    Example:
      >>> describe_selection(selection(8, 64, max_scenarios=64))
      'the first 64 scenario ids, 1 of 8 cells (64 of 512 scenarios)'
    """
    n, m, reps, cells = sel["scenarios_per_cell"], sel["max_scenarios"], sel["replicates"], sel["cells"]
    if n >= reps:
        return f"all {sel['of']} scenarios"
    what = []
    if n:
        what.append(f"{n} of {reps} scenarios per cell")
    if m:
        what.append(f"the first {m} scenario ids, {min(cells, -(-m // reps))} of {cells} cells")
    return f"{' and '.join(what)} ({sel['scenarios']} of {sel['of']} scenarios)"


def _groups(rows) -> np.ndarray:
    """Each row's compile group: (density, selector horizon, selector refine) as a structured array."""
    out = np.empty(len(rows), [("density", "f8"), ("horizon", "i8"), ("refine", "i8")])
    out["density"] = rows["robot.density"].to_numpy()
    out["horizon"] = rows["selector.horizon"].to_numpy()
    out["refine"] = rows["selector.refine"].to_numpy()
    return out


def chunk_plan(cfg: SweepConfig, chunk_size: int, rows=None) -> list[tuple[int, tuple, np.ndarray]]:
    """The whole sweep's chunks: ``(chunk id, group, scenario ids)``, by compile group (what changes the
    compiled program: density, the selector's horizon and refinement) in order of first appearance, each
    group's scenario ids in order, cut every ``chunk_size``.

    A run of a slice of the sweep (:func:`selection`) computes its scenarios in this plan's chunks too, so a
    scenario lands in the same chunk (and part file) whatever slice computed it.

    Args:
      cfg: the sweep.
      chunk_size: scenarios per chunk (as the run rounds it: a multiple of its device count).
      rows: one row per cell with its ``robot.density``, ``selector.horizon`` and ``selector.refine`` (e.g.
        replicate 0 of every cell); None: built here (:func:`ijoy_jax.sweep.scenarios` of one replicate).

    Example:
      >>> from ijoy_jax.sweep import parse_config
      >>> cfg = parse_config('[sweep]\\nscenarios_per_cell = 3\\n[grid]\\n"robot.w" = [1, 2]\\n')
      >>> [ids.tolist() for _, _, ids in chunk_plan(cfg, 4)]
      [[0, 1, 2, 3], [4, 5]]
    """
    if rows is None:
        rows = scenarios(dataclasses.replace(cfg, scenarios_per_cell=1))
    reps = cfg.scenarios_per_cell
    groups = _groups(rows)
    cell = rows["cell"].to_numpy()
    plan = []
    for g in dict.fromkeys(groups.tolist()):
        ids = (cell[groups == np.array(g, groups.dtype)][:, None] * reps + np.arange(reps)).ravel()
        for i in range(0, len(ids), chunk_size):
            plan.append((len(plan), (float(g[0]), int(g[1]), bool(g[2])), ids[i : i + chunk_size]))
    return plan


def read_part(path, columns=None):
    """A result part's rows (``columns`` of them, None: all) as a pandas.DataFrame.

    Raises:
      IncompleteSweepError: the file cannot be read (truncated, overwritten); the message names it and says to
        delete it and rerun (the run recomputes its chunk).
    """
    import pandas as pd
    import pyarrow as pa

    try:
        return pd.read_parquet(path, columns=columns)
    except (OSError, ValueError, pa.ArrowException) as e:
        raise _corrupt_part(path, e) from None


def _flat(d: dict, prefix: str = "") -> dict:
    """``{"grid": {"robot.w": v}}`` as ``{"grid.robot.w": v}`` (an empty table stays a value)."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict) and v:
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


_UNSET = object()


def differences(old: dict, new: dict, *, limit: int = 8) -> str:
    """The keys whose values differ between two (nested) dicts, compactly: ``key old -> new`` for each, sorted
    by dotted key (nested tables flattened: ``grid.robot.w``), values as JSON, ``unset`` where a key is absent;
    at most ``limit`` of them, then how many more. ``""`` when none differ.

    Example:
      >>> differences({"plan": {"chunk_size": 2, "chunks": 3}}, {"plan": {"chunk_size": 3, "chunks": 2}})
      'plan.chunk_size 2 -> 3, plan.chunks 3 -> 2'
    """
    a, b = _flat(old), _flat(new)

    def show(v) -> str:
        return "unset" if v is _UNSET else json.dumps(v, sort_keys=True, default=str)

    diffs = [f"{k} {show(a.get(k, _UNSET))} -> {show(b.get(k, _UNSET))}" for k in sorted(set(a) | set(b))
             if a.get(k, _UNSET) != b.get(k, _UNSET)]
    more = f" and {len(diffs) - limit} more" if len(diffs) > limit else ""
    return ", ".join(diffs[:limit]) + more


def check_plans(path: Path, files, expected: dict | None, *, allow_unrecorded: bool) -> None:
    """Raise :class:`IncompleteSweepError` (naming the folder, the part, both plans and what differs between
    them) unless every part in ``files`` was written by the plan ``expected`` (a record as in :data:`PLAN_KEY`;
    None: the first recorded part's plan). Unrecorded (older) parts pass when ``allow_unrecorded``; a part that
    cannot be read raises too (:func:`part_plan`)."""

    def without_hash(record: dict | None) -> dict:
        return {k: v for k, v in (record or {}).items() if k != "hash"}

    for f in files:
        rec = part_plan(f)
        if rec is None and allow_unrecorded:
            continue
        if expected is None:
            expected = rec
            continue
        if rec is None or rec.get("hash") != expected.get("hash"):
            differing = ""
            if rec is not None:  # the hash also covers the sweep file's text, which the records do not hold
                what = differences(without_hash(rec), without_hash(expected)) or "the sweep file's text"
                differing = f" (differing: {what})"
            raise IncompleteSweepError(
                f"{path}: {Path(f).relative_to(path)} belongs to another plan: {describe_plan(rec)}, not "
                f"{describe_plan(expected)}{differing}; results of "
                f"different sweeps would be mixed: run into another folder, or delete the parts of the other plan")


def _process_sessions(path: Path) -> list[dict]:
    """Every process's sessions: the manifest's (process 0) and ``processes/process-*.json``'s."""
    out = []
    man = path / "manifest.json"
    if man.exists():
        out += read_record(man).get("sessions", [])
    for f in sorted((path / "processes").glob("process-*.json")):
        out += read_record(f).get("sessions", [])
    return out


def _chunk_of(part: Path) -> int:
    """The chunk id in a part's name (``part-00012.parquet``: 12)."""
    digits = part.name[len("part-"):-len(".parquet")]
    if not digits.isdigit():
        raise IncompleteSweepError(f"{part}: not a part a sweep writes (part-NNNNN.parquet, NNNNN its chunk): "
                                   f"move it out of {part.parent}")
    return int(digits)


def _check_complete(path: Path, files: list[Path], df) -> None:
    """Raise :class:`IncompleteSweepError` unless the parts hold every scenario the folder was asked for (the
    manifest's ``selection``; the whole plan for a manifest written before runs recorded one), each once, and
    nothing outside the manifest's plan."""
    man_path = path / "manifest.json"
    if not man_path.exists():
        raise IncompleteSweepError(f"{path}: no manifest.json (process 0 writes it when it starts; has it run?)")
    man = read_record(man_path, ("plan",))
    plan = man["plan"]
    have = [_chunk_of(f) for f in files]
    foreign = sorted(set(have) - set(range(plan["chunks"])))
    if foreign:
        raise IncompleteSweepError(f"{path}: parts of chunks {foreign} are not in the plan ({plan['chunks']} "
                                   f"chunks): results of another plan are mixed in")
    dup = df["scenario"][df["scenario"].duplicated()].unique()
    if len(dup):
        raise IncompleteSweepError(f"{path}: scenarios {sorted(dup.tolist())[:20]} appear more than once "
                                   f"(in chunks {sorted(df.loc[df['scenario'].isin(dup), 'chunk'].unique())})")
    ids = df["scenario"].to_numpy(np.int64)
    outside = ids[(ids < 0) | (ids >= plan["scenarios"])]
    if len(outside):
        raise IncompleteSweepError(f"{path}: scenarios {sorted(outside.tolist())[:20]} are not in the plan "
                                   f"({plan['scenarios']} scenarios): results of another plan are mixed in")
    sel = man.get("selection") or selection(plan["scenarios"], 1)  # before slices: the whole plan
    if np.count_nonzero(selected(ids, sel)) >= sel["scenarios"]:
        return
    sliced = sel["scenarios"] < sel["of"]
    flags = "".join(f" and --{k.replace('_', '-')} {sel[k]}" for k in ("scenarios_per_cell", "max_scenarios")
                    if sliced and sel[k])  # what the folder was asked for
    asked = f" (it was asked for {describe_selection(sel)})" if sliced else ""
    missing, touched = _missing_chunks(man, sel, ids, have)
    if missing is None:  # the plan cannot be rebuilt (its sweep file reads a file that moved): count scenarios
        what = f"{sel['scenarios'] - np.count_nonzero(selected(ids, sel))} of {sel['scenarios']} scenarios missing"
    else:
        shown = ", ".join(map(str, missing[:20])) + (", ..." if len(missing) > 20 else "")
        what = f"{len(missing)} of {touched} chunks missing (chunks {shown})"
    sessions = _process_sessions(path)
    latest = max(sessions, key=lambda s: s.get("started", "")) if sessions else {}
    nproc = int(latest.get("num_processes", 1))
    if nproc > 1 and missing is not None:
        owners = sorted({c % nproc for c in missing})
        who = (f"; with {nproc} processes (chunk % {nproc} == process id) they belong to process(es) "
               f"{', '.join(map(str, owners))}: has each finished? Rerun `ijoy sweep run` with the same --out"
               f"{flags} and --process-id to resume it")
    else:
        who = f"; the sweep has not finished: rerun `ijoy sweep run` with the same --out{flags} to resume it"
    raise IncompleteSweepError(f"{path}: incomplete sweep{asked}: {what}{who}; or load(..., partial=True) for the "
                               f"finished chunks")


def _missing_chunks(man: dict, sel: dict, ids: np.ndarray, have: list[int]) -> tuple[list[int] | None, int]:
    """The chunks lacking selected scenarios and how many chunks the selection touches; (None, 0) when the plan
    cannot be rebuilt from the manifest's sweep text."""
    plan = man["plan"]
    if "selection" not in man:  # written before slices: every part holds its whole chunk
        return sorted(set(range(plan["chunks"])) - set(have)), plan["chunks"]
    try:
        cfg = parse_config(man["sweep_text"], man.get("sweep_file", "<manifest>"))
        chunks = chunk_plan(cfg, plan["chunk_size"])
    except (ValueError, KeyError, TypeError, OSError):
        return None, 0
    if cfg.num_scenarios != plan["scenarios"] or len(chunks) != plan["chunks"]:
        return None, 0
    missing, touched = [], 0
    for cid, _, cids in chunks:
        want = cids[selected(cids, sel)]
        touched += bool(len(want))
        if not np.isin(want, ids).all():
            missing.append(cid)
    return missing, touched


def load(path, *, partial: bool = False):
    """The per-scenario table of a sweep folder, in one call: the union of every process's parts.

    Args:
      path: the sweep's output folder (``ijoy sweep run --out``).
      partial: return the finished chunks of an unfinished sweep instead of raising. A folder of a slice of
        its sweep (``ijoy sweep run --scenarios-per-cell`` or ``--max-scenarios``) loads without it once that
        slice is done: its manifest says ``"complete": false`` and the table holds the slice's scenarios.

    Returns:
      pandas.DataFrame, one row per scenario, sorted by ``scenario``.

    Raises:
      FileNotFoundError: no parts at all (NotADirectoryError: ``path`` is a file).
      IncompleteSweepError: parts of another plan are mixed in (every part records its plan's
        hash; also with ``partial``); a part or the manifest cannot be read (truncated, overwritten,
        hand-edited: the message names the file and the way out); or (unless ``partial``) scenarios the
        folder was asked for (the manifest's ``selection``) are missing (the message names their chunks and,
        for a multi-process run, the processes they belong to), or scenarios are duplicated.

    Example:
      >>> from ijoy_jax import sweep
      >>> df = sweep.load("results/w_sweep")  # doctest: +SKIP
      >>> df.groupby("robot.w")["distance_along"].mean()  # doctest: +SKIP
    """
    import pandas as pd

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{path} is a file, not a sweep's output folder (ijoy sweep run --out)")
    files = sorted((path / "parts").glob("part-*.parquet"))
    if not files:
        raise FileNotFoundError(f"no result parts under {path / 'parts'}"
                                + ("" if path.exists() else f" ({path} does not exist)"))
    man_path = path / "manifest.json"
    man = read_record(man_path) if man_path.exists() else {}
    expected = ({"hash": man["plan_hash"], "name": man.get("name"), **man.get("plan", {})}
                if "plan_hash" in man else None)
    check_plans(path, files, expected, allow_unrecorded=True)  # even with partial: never mix two sweeps
    tables = []
    for p in files:
        t = read_part(p)  # the footer was read above; a part cut or overwritten inside its data fails here
        if not {"scenario", "chunk"} <= set(t.columns):
            raise _corrupt_part(p, ValueError("no 'scenario' and 'chunk' columns"))
        tables.append(t)
    df = pd.concat(tables, ignore_index=True)
    if not partial:
        _check_complete(path, files, df)
    return df.sort_values("scenario", kind="stable").reset_index(drop=True)


def _swept(path) -> tuple[str, ...]:
    man = read_record(Path(path) / "manifest.json", ("sweep_text",))
    return parse_config(man["sweep_text"], man.get("sweep_file", "<manifest>")).swept


def aggregate(df, by=None):
    """Per-cell aggregates with 95% confidence intervals (see the module docstring).

    Args:
      df: a per-scenario table (:func:`load`).
      by: parameter columns to keep alongside ``cell`` (default: every
        ``robot.*``/``terrain.*``/``sim.*``/``selector.*`` column that varies, and
        ``robot.reach`` when it is not the paper's).

    Returns:
      pandas.DataFrame, one row per cell: ``cell``, the ``by`` columns, and
      for each metric m ``m.mean``, ``m.std``, ``m.sem``, ``m.ci95``; ``n``.
    """
    import pandas as pd

    if by is None:
        by = [c for c in df.columns if c.startswith(_PARAMS) and df[c].nunique() > 1]
        if "robot.reach" in df.columns and (df["robot.reach"] != ROBOT_DEFAULTS["reach"]).any():
            by.append("robot.reach")  # fixed per sweep, but what its action set means (action_counts)
    rows = []
    for cell, g in df.groupby("cell", sort=True):
        row = {"cell": cell, **{c: g[c].iloc[0] for c in by}, "n": len(g)}
        t = t_quantile(len(g) - 1)
        for m in tuple(e for e in METRICS + EXTRA_METRICS + PHYSICS_METRICS if e in df.columns):
            x = g[m].to_numpy(np.float64)
            std = float(np.std(x, ddof=1)) if len(x) > 1 else math.nan
            sem = std / math.sqrt(len(x))
            row.update({f"{m}.mean": float(np.mean(x)), f"{m}.std": std, f"{m}.sem": sem, f"{m}.ci95": t * sem})
        rows.append(row)
    return pd.DataFrame(rows)


def paired_differences(df, baseline: dict, metrics=None, by=None):
    """Per cell, the mean difference of each metric from a baseline cell, replicate by replicate, with 95% CIs.

    Replicate r of every cell runs on the same terrain with the same command (:func:`ijoy_jax.sweep.scenarios`),
    so the difference ``metric(cell, r) - metric(baseline, r)`` removes the variation between terrains: its
    t interval is the one to read when comparing cells (the marginal intervals of :func:`aggregate` overlap
    where the paired one does not).

    Args:
      df: a per-scenario table (:func:`load`).
      baseline: ``{column: value}`` naming the baseline cell's parameters (e.g. ``{"selector.horizon": 1,
        "selector.refine": 0}``); every other varying parameter column must match too (compared within it).
      metrics: the metrics (default: :data:`METRICS` present in ``df``).
      by: the parameter columns that define the cells (default: every varying ``robot.*``, ``terrain.*``,
        ``sim.*`` and ``selector.*`` column).

    Returns:
      pandas.DataFrame, one row per cell: its ``by`` columns, ``n`` (paired replicates) and per metric
      ``m.diff`` (mean difference) and ``m.ci95`` (half-width of its 95% t interval; NaN for n < 2).

    Example:
      >>> import pandas as pd
      >>> df = pd.DataFrame({"cell": [0, 0, 1, 1], "replicate": [0, 1, 0, 1], "selector.horizon": [1, 1, 2, 2],
      ...                    "distance_along": [1.0, 2.0, 1.5, 2.75]})
      >>> paired_differences(df, {"selector.horizon": 1}, ["distance_along"])["distance_along.diff"].tolist()
      [0.0, 0.625]
    """
    import pandas as pd

    if by is None:
        by = [c for c in df.columns if c.startswith(_PARAMS) and df[c].nunique() > 1]
    if metrics is None:
        metrics = [m for m in METRICS if m in df.columns]
    missing = [k for k in baseline if k not in df.columns]
    if missing:
        raise ValueError(f"baseline names columns the table does not have: {missing}")
    others = [c for c in by if c not in baseline]
    base = df
    for k, v in baseline.items():
        base = base[base[k] == v]
    if base.empty:
        raise ValueError(f"no scenario matches the baseline {baseline}")
    keyed = base.set_index([*others, "replicate"])[list(metrics)]
    rows = []
    for cell, g in df.groupby("cell", sort=True):
        key_cols = [*others, "replicate"]
        mine = g.set_index(key_cols)[list(metrics)]
        common = mine.index.intersection(keyed.index)
        d = mine.loc[common].astype(float) - keyed.loc[common].astype(float)
        n = len(d)
        row = {"cell": cell, **{c: g[c].iloc[0] for c in by}, "n": n}
        t = t_quantile(n - 1) if n > 1 else math.nan
        for m in metrics:
            x = d[m].to_numpy(np.float64)
            row[f"{m}.diff"] = float(np.mean(x)) if n else math.nan
            row[f"{m}.ci95"] = float(t * np.std(x, ddof=1) / math.sqrt(n)) if n > 1 else math.nan
        rows.append(row)
    return pd.DataFrame(rows)


def load_aggregates(path, *, partial: bool = False):
    """The per-cell aggregates of a sweep folder, computed from its parts (see :func:`load` for ``partial``)."""
    return aggregate(load(path, partial=partial), list(_swept(path)))


PAPER_ACTIONS = 496
"""Actions per foot in the paper's HRP-2 action set (``ijoy_jax.robots.hrp2(density=1.0)``)."""


def action_counts(densities, reach=None) -> np.ndarray:
    """Actions per foot of HRP-2's action set at each density (:func:`ijoy_jax.robots.hrp2`), as float64.

    ``reach`` (m): a number, or one per density (a sweep's ``robot.reach`` column); None: the paper's 0.20.

    Example:
      >>> action_counts([0.4, 1.0, 2.0]).tolist(), action_counts([1.0], reach=0.30).tolist()
      ([52.0, 496.0, 3307.0], [720.0])
    """
    from ijoy_jax import robots

    d = np.asarray(densities, np.float64)
    r = np.broadcast_to(np.asarray(robots.PAPER_REACH if reach is None else reach, np.float64), d.shape)
    pairs = list(zip(d.ravel().tolist(), r.ravel().tolist(), strict=True))
    sizes = {p: len(robots.hrp2_actions(*p)) for p in dict.fromkeys(pairs)}
    return np.array([sizes[p] for p in pairs], np.float64).reshape(d.shape)


PLOT_METRICS = ("distance_along", "mean_deviation", "steps_in_place", "stopped", "footholds_on_obstacles",
                "footholds_near_obstacles")
"""A perfect-robot sweep's summary (:func:`summary_metrics`), in order: progress along the command (m), deviation
from it (m), steps marking time, the fraction of walks stopped (no valid step), footholds on and near obstacles."""

SELECTOR_PLOT_METRICS = PLOT_METRICS
"""A sweep over the selector's options (``selector.*``) is a perfect-robot sweep: the same summary, whose
progress, marking time, stops and footholds near obstacles are what a better selector changes."""

PHYSICS_PLOT_METRICS = ("fell", "distance_along", "collided", "placement_error_mean",
                        *(m for m in PLOT_METRICS if m != "distance_along"))
"""A ``walker = "mjx"`` sweep's summary: the fall rate and the collision rate on either side of progress (the
safety beside its price), the mean touch-down error (m), then the rest of :data:`PLOT_METRICS`."""


def summary_metrics(agg) -> tuple[str, ...]:
    """The metrics a sweep's summary shows by default, in order: the columns of the table ``ijoy sweep summarize``
    prints and the panels of :func:`plot`, one definition for both so they cannot disagree.

    :data:`PHYSICS_PLOT_METRICS` for a ``walker = "mjx"`` sweep (aggregates with ``fell``), else
    :data:`PLOT_METRICS`, keeping those the aggregates hold (results written before
    ``footholds_near_obstacles`` existed lack it).

    Args:
      agg: :func:`aggregate` output (columns ``m.mean`` per metric ``m``).

    Returns:
      the metric names, a tuple of str.

    Example:
      >>> import pandas as pd
      >>> summary_metrics(pd.DataFrame(columns=["distance_along.mean", "stopped.mean", "fell.mean"]))
      ('fell', 'distance_along', 'stopped')
    """
    return tuple(m for m in (PHYSICS_PLOT_METRICS if "fell.mean" in agg else PLOT_METRICS) if f"{m}.mean" in agg)


_TITLES = {"collided": "collision rate (rollouts touching an obstacle)", "fell": "fall rate (rollouts that fell)"}


def plot(agg, out, x=None, metrics=None, title: str = ""):
    """Plot aggregates against one swept parameter, one panel per metric (up to 3 columns, titled with the
    metric and its unit), points at the mean over scenarios with 95% CI error bars.

    Args:
      agg: :func:`aggregate` output.
      out: PNG path.
      x: the parameter on the x axis (default: the swept column with most values).
      metrics: the metrics to plot (one panel each; default :func:`summary_metrics`, the columns of the
        summary table: :data:`PHYSICS_PLOT_METRICS` for a physics sweep, else :data:`PLOT_METRICS`).
      title: figure title.

    Other swept columns become one line each (legend). A robot parameter's
    library default (:data:`ijoy_jax.sweep.ROBOT_DEFAULTS`) is marked by a
    dashed line; values spanning 20x or more get a symlog axis. Action-set
    density is drawn as the number of actions per foot (:func:`action_counts`)
    on a log axis with the paper's 496 (:data:`PAPER_ACTIONS`) marked. Returns ``out``.

    A physics parameter (``sim.*``) on the x axis has its nominal value
    marked; a rate's interval (a ``fraction`` metric) is clipped to [0, 1].
    So a margin sweep crossed with an execution-error level draws the
    collision and fall rates against the margin, one line per level.

    Aggregates of a bar-crossing sweep (a ``crossed`` metric and a swept
    ``terrain.width``) with the default ``metrics`` and ``x`` go to
    :func:`plot_crossing` instead.
    """
    if "crossed.mean" in agg and "terrain.width" in agg and x in (None, "terrain.width") and metrics is None:
        return plot_crossing(agg, out, title=title)
    if metrics is None:
        metrics = summary_metrics(agg)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = [c for c in agg.columns if c.startswith(_PARAMS)]
    if x is None:
        x = max(params, key=lambda c: agg[c].nunique()) if params else "cell"
    others = [c for c in params if c != x]
    ncols = min(3, len(metrics))  # a readable grid, not one long row
    nrows = -(-len(metrics) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.7 * nrows), squeeze=False)
    for ax in axes.ravel()[len(metrics):]:
        ax.remove()
    groups = agg.groupby(others, sort=True) if others else [((), agg)]
    # Density is drawn as what it means: the number of actions in the set (HRP-2's lattice), 496 the paper's.
    reach = (lambda g: g["robot.reach"]) if "robot.reach" in agg.columns else (lambda g: None)
    xv = ((lambda g: action_counts(g[x], reach(g))) if x == "robot.density"
          else (lambda g: np.asarray(g[x], np.float64)))
    for ax, m in zip(axes.ravel(), metrics, strict=False):
        for key, g in groups:
            g = g.sort_values(x)
            key = key if isinstance(key, tuple) else (key,)
            label = ", ".join(f"{c.partition('.')[2]} = {v:g}" for c, v in zip(others, key, strict=True))
            mean, ci = g[f"{m}.mean"].to_numpy(np.float64), np.nan_to_num(g[f"{m}.ci95"].to_numpy(np.float64))
            # a rate's interval stays within [0, 1] (a mean outside it, which only made-up aggregates have,
            # gets no bar on that side rather than matplotlib's refusal of a negative one)
            lo, hi = (np.clip(mean - ci, 0, 1), np.clip(mean + ci, 0, 1)) if UNITS.get(m) == "fraction" else (
                mean - ci, mean + ci)
            yerr = [np.maximum(mean - lo, 0.0), np.maximum(hi - mean, 0.0)]
            ax.errorbar(xv(g), mean, yerr=yerr, marker="o", capsize=3, label=label or None)
        if x == "robot.density":
            ax.axvline(PAPER_ACTIONS, color="0.4", ls="--", lw=1, label=f"paper's {PAPER_ACTIONS} actions (HRP-2)")
            ax.set_xscale("log")
            ticks = sorted(set(xv(agg).astype(int).tolist()) | {PAPER_ACTIONS})
            ax.set_xticks(ticks, [str(t) for t in ticks], rotation=45, fontsize=7)
            ax.minorticks_off()
            ax.set_xlabel("actions in the set S, per foot (count)")
        else:
            default = ROBOT_DEFAULTS.get(x.partition(".")[2]) if x.startswith("robot.") else None
            what = "library default"
            if x.startswith("sim."):
                from ijoy_jax.sim import physics

                default, what = getattr(physics.NOMINAL, x.partition(".")[2]), "nominal robot"
            if default is not None:
                ax.axvline(default, color="0.4", ls="--", lw=1, label=f"{what} ({default:g})")
            pos = agg[x][agg[x] > 0] if x in agg else []
            if len(pos) and agg[x].max() >= 20 * pos.min():
                ax.set_xscale("symlog", linthresh=float(pos.min()), linscale=0.5)
                ax.set_xlim(min(0.0, float(agg[x].min())) - 0.3 * float(pos.min()), 1.5 * float(agg[x].max()))
            ax.set_xlabel(f"{x.partition('.')[2] or x} ({UNITS.get(x, '-')})")
            ticks = np.unique(xv(agg)) if x in agg else np.array([])
            if 0 < len(ticks) <= 12 and np.allclose(ticks, np.round(ticks)):
                ax.set_xticks(ticks)  # a count (the lookahead's horizon): no ticks between its values
        ax.set_ylabel(f"mean ({UNITS[m]})")
        ax.set_title(_TITLES.get(m, f"{m.replace('_', ' ')} ({UNITS[m]})"), fontsize=10)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    return _finish(fig, agg, title, out)


def _finish(fig, agg, title, out):
    """Title a sweep figure with its scenarios per point, save it to ``out`` and close it."""
    import matplotlib.pyplot as plt

    n = int(agg["n"].min()) if len(agg) else 0
    fig.suptitle(f"{title}  (mean and 95% CI over {n} scenarios per point)".strip())
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def _short(column: str) -> str:
    """A swept column's name without its prefix, for a point's label (``robot.metrics.support_limit`` ->
    ``support_limit``)."""
    return column.rsplit(".", 1)[-1]


def plot_tradeoff(agg, out, safety: str = "fell", price: str = "distance_along", title: str = ""):
    """The price of safety: one point per cell, a safety metric (up) against what it costs (across), each with
    its 95% CI.

    Args:
      agg: :func:`aggregate` output with ``{safety}.mean`` and ``{price}.mean`` (e.g. a physics sweep's fall
        rate and progress).
      out: PNG path.
      safety, price: the metrics on the y and x axes (:data:`UNITS` gives their units).
      title: figure title.

    The first swept column (e.g. the terrain's amplitude, or the family's parameter) picks each point's
    colour; the other swept columns label the point, so a reader sees which settings buy safety with
    progress. A fraction metric's interval is clipped to [0, 1]. Returns ``out``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for m in (safety, price):
        if f"{m}.mean" not in agg:
            known = [c[: -len(".mean")] for c in agg.columns if c.endswith(".mean")]
            raise ValueError(f"{m!r} is not a metric of this sweep; known: {', '.join(known)}")
    swept = [c for c in agg.columns if c.startswith(_PARAMS)]  # the swept parameters (aggregate groups by them)
    colour_by, labels = (swept[0], swept[1:]) if swept else (None, [])
    fig, ax = plt.subplots(figsize=(8.0, 5.4))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    groups = [(None, agg)] if colour_by is None else list(agg.groupby(colour_by, sort=True))
    for i, (value, g) in enumerate(groups):
        x, y = (g[f"{m}.mean"].to_numpy(np.float64) for m in (price, safety))
        xe, ye = (np.nan_to_num(g[f"{m}.ci95"].to_numpy(np.float64)) for m in (price, safety))
        y_lo, y_hi = y - ye, y + ye
        if UNITS.get(safety) == "fraction":
            y_lo, y_hi = np.clip(y_lo, 0, 1), np.clip(y_hi, 0, 1)
        name = "all cells" if colour_by is None else f"{_short(colour_by)} = {value:g}"
        ax.errorbar(x, y, xerr=xe, yerr=[y - y_lo, y_hi - y], fmt="o", capsize=2, color=colours[i % len(colours)],
                    label=name)
        for (_, row), xi, yi in zip(g.iterrows(), x, y, strict=True):
            text = ", ".join(f"{_short(c)} {row[c]:g}" for c in labels)
            if text:
                ax.annotate(text, (xi, yi), textcoords="offset points", xytext=(4, 3), fontsize=6,
                            color=colours[i % len(colours)])
    ax.set_xlabel(f"{price.replace('_', ' ')} ({UNITS.get(price, '')})")
    ax.set_ylabel(_TITLES.get(safety, f"{safety.replace('_', ' ')} ({UNITS.get(safety, '')})"))
    ax.grid(alpha=0.3)
    if colour_by is not None:
        ax.legend(fontsize=8)
    return _finish(fig, agg, title, out)


def b_max(margin, step_length: float = 0.20, foot_length: float = 0.242):
    """The paper's bound on the bar length a foot can step over: ``2 L - foot length - 2 m`` (metres).

    From a stance beside the bar, the blocked foot lands at most ``L`` ahead of
    the stance foot after starting up to ``L`` behind it (a ``2 L`` swing); its
    grown footprint (length + 2 m) must fit before the bar and then beyond it.
    HRP-2: L = 0.20 m (largest dx of an action), foot length 0.242 m.

    Example:
      >>> round(b_max(0.02), 3)
      0.118
    """
    out = 2.0 * step_length - foot_length - 2.0 * np.asarray(margin, np.float64)
    return float(out) if out.ndim == 0 else out


def plot_crossing(agg, out, title: str = "", step_length: float = 0.20, foot_length: float = 0.242):
    """Crossing rate against bar length, one line per safety margin, the paper's bound marked.

    Args:
      agg: :func:`aggregate` output of a sweep over ``terrain.width`` (bar
        length along the walk) and optionally ``robot.margin``, with the
        ``crossed`` metric (bars family).
      out: PNG path.
      title: figure title.
      step_length, foot_length: L and the foot length in :func:`b_max` (HRP-2's by default).

    Each margin m is drawn in its own colour with the fraction of scenarios
    that crossed (95% CI error bars, clipped to [0, 1]) and a dashed vertical
    line at ``b_max(m)`` (in the legend; a margin with ``b_max <= 0`` admits
    no bar and is noted there). Returns ``out``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9.0, 4.8))
    margins = sorted(agg["robot.margin"].unique()) if "robot.margin" in agg else [None]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    handles = []
    for i, m in enumerate(margins):
        g = (agg if m is None else agg[agg["robot.margin"] == m]).sort_values("terrain.width")
        color = colors[i % len(colors)]
        mean = g["crossed.mean"].to_numpy(np.float64)
        ci = np.nan_to_num(g["crossed.ci95"].to_numpy(np.float64))
        lo, hi = np.clip(mean - ci, 0, 1), np.clip(mean + ci, 0, 1)
        name = "measured" if m is None else f"m = {100 * m:g} cm: measured"
        handles.append(ax.errorbar(g["terrain.width"] * 100, mean, yerr=[mean - lo, hi - mean], marker="o",
                                   capsize=3, color=color, label=name))
        if m is not None:
            bound = float(b_max(m, step_length, foot_length))
            if bound > 0:
                handles.append(ax.axvline(100 * bound, color=color, ls="--", lw=1.2,
                                          label=f"m = {100 * m:g} cm: paper's b_max = {100 * bound:.1f} cm"))
            else:
                handles.append(ax.plot([], [], color=color, ls="--", lw=1.2,
                                       label=f"m = {100 * m:g} cm: b_max = {100 * bound:.1f} cm, none crossable")[0])
    ax.set_xlabel("bar length along the walking direction, b (cm)")
    ax.set_ylabel("scenarios that got past the bar (fraction)")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.set_title(f"dashed: the paper's bound b_max(m) = 2 L - foot length - 2 m (L = {100 * step_length:g} cm, "
                 f"foot {100 * foot_length:g} cm)\npoints: mean and 95% CI; below b_max, crossing also depends "
                 "on where the foothold lattice meets the bar", fontsize=8)
    return _finish(fig, agg, title, out)
