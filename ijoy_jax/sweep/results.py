"""Sweep results: the tidy per-scenario table of a folder, and per-cell aggregates with 95% confidence intervals.

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

Loading checks the folder's parts and records (:mod:`ijoy_jax.sweep.folder`) against its chunk plan
(:mod:`ijoy_jax.sweep.plan`); the plots of the aggregates are :mod:`ijoy_jax.sweep.plots`. The names of
those modules and of the table's columns that code imports from here are exported here too.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ijoy_jax.stats import t_quantile
from ijoy_jax.sweep.columns import (
    EXTRA_METRICS,
    METRICS,
    PARAMETER_PREFIXES,
    PHYSICS_METRICS,
    UNITS,
    WALK_METRICS,
    WALK_PHYSICS_METRICS,
)
from ijoy_jax.sweep.config import parse_config
from ijoy_jax.sweep.folder import IncompleteSweepError, check_plans, corrupt_part, part_plan, read_part, read_record
from ijoy_jax.sweep.plan import (
    PLAN_KEY,
    chunk_plan,
    describe_plan,
    describe_selection,
    differences,
    plan_hash,
    selected,
    selection,
)
from ijoy_jax.sweep.plots import (
    PAPER_ACTIONS,
    PHYSICS_PLOT_METRICS,
    PLOT_METRICS,
    SELECTOR_PLOT_METRICS,
    action_counts,
    b_max,
    plot,
    plot_crossing,
    plot_tradeoff,
    summary_metrics,
)
from ijoy_jax.sweep.schema import ROBOT_DEFAULTS

__all__ = ["EXTRA_METRICS", "PAPER_ACTIONS", "PHYSICS_PLOT_METRICS", "PLAN_KEY",
           "PLOT_METRICS", "SELECTOR_PLOT_METRICS", "UNITS", "IncompleteSweepError", "action_counts",
           "aggregate", "b_max", "check_plans", "chunk_plan", "describe_plan", "describe_selection",
           "differences", "load", "load_aggregates", "paired_differences",
           "part_plan", "plan_hash", "read_part", "read_record", "selected", "selection",
           "plot", "plot_crossing", "plot_tradeoff", "summary_metrics"]



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
            raise corrupt_part(p, ValueError("no 'scenario' and 'chunk' columns"))
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
        by = [c for c in df.columns if c.startswith(PARAMETER_PREFIXES) and df[c].nunique() > 1]
        if "robot.reach" in df.columns and (df["robot.reach"] != ROBOT_DEFAULTS["reach"]).any():
            by.append("robot.reach")  # fixed per sweep, but what its action set means (action_counts)
    rows = []
    for cell, g in df.groupby("cell", sort=True):
        row = {"cell": cell, **{c: g[c].iloc[0] for c in by}, "n": len(g)}
        t = t_quantile(len(g) - 1)
        for m in tuple(e for e in METRICS + EXTRA_METRICS + PHYSICS_METRICS + WALK_METRICS + WALK_PHYSICS_METRICS
                       if e in df.columns):
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
        by = [c for c in df.columns if c.startswith(PARAMETER_PREFIXES) and df[c].nunique() > 1]
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
