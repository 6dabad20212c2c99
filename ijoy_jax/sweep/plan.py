"""The chunk plan of a sweep and the slices of it a run computes: which scenario lands in which chunk, and the
plan's hash every part and manifest records.

Slices. A run may compute part of a sweep (:func:`selection`: the first N replicates of every cell, or the
first M scenario ids) into a folder that a later run with more scenarios extends: the chunk plan is always the
whole sweep's (:func:`chunk_plan`), a part holds the rows of its chunk computed so far, and ``manifest.json``
records what the folder was asked for (``selection``) and whether it holds the whole sweep (``complete``).
The plan's hash (:func:`plan_hash`) covers the sweep file's text and the chunk plan, so the parts of two
plans are never mixed; :func:`differences` says what differs between two of them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np

from ijoy_jax.sweep.expansion import scenarios
from ijoy_jax.sweep.schema import SweepConfig

__all__ = [
    "PLAN_KEY",
    "chunk_plan",
    "describe_plan",
    "describe_selection",
    "differences",
    "plan_hash",
    "selected",
    "selection",
]

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


def describe_plan(record: dict | None) -> str:
    """``plan <hash> (sweep 'name', 12 scenarios in 6 chunks of 2)``, for error messages."""
    if record is None:
        return "an unrecorded plan (a part written before parts recorded their plan)"
    return (
        f"plan {record.get('hash')} (sweep {record.get('name')!r}, {record.get('scenarios')} scenarios in "
        f"{record.get('chunks')} chunks of {record.get('chunk_size')})"
    )


def selection(
    num_cells: int, replicates: int, *, scenarios_per_cell: int | None = None, max_scenarios: int | None = None
) -> dict:
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
    return {
        "scenarios_per_cell": n,
        "max_scenarios": m,
        "replicates": replicates,
        "cells": num_cells,
        "scenarios": count,
        "of": total,
    }


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

    diffs = [
        f"{k} {show(a.get(k, _UNSET))} -> {show(b.get(k, _UNSET))}"
        for k in sorted(set(a) | set(b))
        if a.get(k, _UNSET) != b.get(k, _UNSET)
    ]
    more = f" and {len(diffs) - limit} more" if len(diffs) > limit else ""
    return ", ".join(diffs[:limit]) + more
