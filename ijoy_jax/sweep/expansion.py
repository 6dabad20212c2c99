"""The expansion of a sweep into its cells and scenario rows (host only, no JAX), and the host memory those
tables take.

A *cell* is one combination of grid values (times one random sample); each cell runs ``scenarios_per_cell``
scenarios, replicate ``r`` of every cell on the same terrain (seed ``r``) with the same command draw: paired
comparisons across cells.

Sizes. A sweep is held on the host as one table row per scenario (:func:`scenarios`,
then the results), so its size is checked when it is parsed, before anything is
allocated: at most :data:`MAX_SCENARIOS` scenarios, and the tables' estimated host
memory (:func:`table_bytes`) at most :data:`HOST_MEMORY_FRACTION` of this host's
physical memory. Replicate r's command comes from its own generator, drawn for all
replicates at once (:mod:`ijoy_jax.sweep.seeding`: ~3 s for 2e7 replicates, where one
NumPy generator per replicate took ~7 minutes); :func:`scenarios` reports its progress
(``progress=True``, as :func:`ijoy_jax.sweep.run` does) and builds only the rows it is
asked for.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from ijoy_jax.sweep import models, seeding
from ijoy_jax.sweep.columns import METRICS, PHYSICS_METRICS, walk_metrics
from ijoy_jax.sweep.schema import (
    COMMAND_KEYS,
    ROBOT_DEFAULTS,
    SELECTOR_DEFAULTS,
    SELECTOR_STATIC,
    SweepConfig,
    sim_field_names,
)
from ijoy_jax.terrain import generators

__all__ = ["HOST_MEMORY_FRACTION", "MAX_SCENARIOS", "cells", "scenarios", "table_bytes"]

MAX_SCENARIOS = 10**8
"""Most scenarios one sweep may declare (cells x scenarios_per_cell): their host tables alone take tens of GB."""
HOST_MEMORY_FRACTION = 0.5
"""Share of the host's physical memory a sweep's tables (:func:`table_bytes`) may need."""
_TABLE_COPIES = 3  # the scenario table, its index by scenario while running, the loaded results at the end
_PROGRESS_EVERY = 1 << 22  # replicates between progress lines while drawing commands (~1 s)


def table_bytes(cfg: SweepConfig, num_scenarios: int | None = None) -> int:
    """Estimated host bytes of a sweep's tables: ``num_scenarios`` (default all) rows of 8-byte columns (ids,
    every robot, terrain and command value, the metrics), times the copies a run holds at once.

    Example:
      >>> from ijoy_jax.sweep import parse_config
      >>> cfg = parse_config("[sweep]\\nscenarios_per_cell = 1000\\n")
      >>> 100_000 < table_bytes(cfg) < 10_000_000
      True
    """
    fam = None if cfg.family is None else generators.FAMILIES[cfg.family]
    terrain_columns = 0 if fam is None else len(fam.rules) + len(fam.metric_names)
    command_columns = len(cfg.command_columns)
    columns = 4 + len(ROBOT_DEFAULTS) + terrain_columns + command_columns + len(SELECTOR_DEFAULTS) + len(METRICS)
    columns += len(walk_metrics(cfg.walk is not None, cfg.walker))
    if cfg.walker == "mjx":
        columns += len(sim_field_names()) + len(PHYSICS_METRICS)
    n = cfg.num_scenarios if num_scenarios is None else num_scenarios
    return n * columns * 8 * _TABLE_COPIES


def cells(cfg: SweepConfig):
    """The sweep's cells: one row per cell, columns ``cell`` and each swept parameter.

    Grid values are crossed (first grid key slowest); random cells draw each
    ``[random]`` key uniformly from ``np.random.default_rng([seed, 1])``, and
    every grid cell is crossed with every random draw.

    Returns:
      pandas.DataFrame with ``cfg.num_cells`` rows.
    """
    import pandas as pd

    keys = list(cfg.grid)
    n_grid = math.prod(len(cfg.grid[k]) for k in keys)
    samples = cfg.random_samples if cfg.random else 1
    n = n_grid * samples
    cols: dict[str, np.ndarray] = {}
    combo = np.arange(n, dtype=np.int64) // samples  # each cell's grid combination, every draw crossed with it
    stride = n_grid
    for k in keys:  # the first key slowest, as itertools.product
        values = np.asarray(cfg.grid[k])  # int64 for counts, float64 for the rest (as pandas reads the lists)
        stride //= len(values)
        cols[k] = values[(combo // stride) % len(values)]
    if cfg.random:
        # One generator, the keys of a sample in turn, sample after sample: C order of Generator.uniform's
        # broadcast, which draws each element as the scalar calls do (lo + (hi - lo) * u).
        rng = np.random.default_rng([cfg.seed, 1])
        bounds = np.array(list(cfg.random.values()), np.float64).reshape(-1, 2)
        draws = rng.uniform(bounds[:, 0], bounds[:, 1], size=(cfg.random_samples, len(bounds)))
        sample = np.arange(n, dtype=np.int64) % samples
        for j, k in enumerate(cfg.random):
            cols[k] = draws[sample, j]
    df = pd.DataFrame(cols, index=pd.RangeIndex(n))
    df.insert(0, "cell", np.arange(n, dtype=np.int64))
    return df


def _draw_commands(
    cfg: SweepConfig, reps: int, progress: bool, stream: int = 2, ranges: list | None = None
) -> np.ndarray:
    """(reps, 3): replicate r's command, ``np.random.default_rng([seed, 2, r]).uniform(lo, hi)`` per component
    (vectorised, bit-identical: :func:`ijoy_jax.sweep.seeding.uniform_draws`); a progress line on stderr each
    time another :data:`_PROGRESS_EVERY` replicates are done. With ``stream`` and ``ranges``: the same for
    other per-replicate draws (the ``[sim]`` ranges: ``default_rng([seed, 3, r])``), (reps, len(ranges))."""
    t0 = time.perf_counter()
    shown = 0

    def report(done: int) -> None:
        nonlocal shown
        if done < shown:  # NumPy's own generators draw them again (seeding.uniform_draws' fallback)
            shown = 0
        if not progress or done // _PROGRESS_EVERY == shown // _PROGRESS_EVERY:
            return
        shown = done
        rate = done / max(time.perf_counter() - t0, 1e-9)
        what = "commands" if stream == 2 else "physics"
        print(
            f"[ijoy sweep] drawing {what}: {done}/{reps} replicates  {rate:.0f}/s  ETA {(reps - done) / rate:.0f} s",
            file=sys.stderr,
            flush=True,
        )

    ranges = [cfg.command[k] for k in COMMAND_KEYS] if ranges is None else ranges
    return seeding.uniform_draws(
        [cfg.seed, stream], ranges, reps, on_block=report, on_replicate=lambda i: report(i + 1)
    )


def scenarios(cfg: SweepConfig, max_scenarios: int | None = None, *, progress: bool = False):
    """Every scenario of the sweep with all its parameters resolved (host only, no JAX).

    Scenario ``cell * scenarios_per_cell + replicate``; its terrain key is
    ``fold_in(key(seed), replicate)`` and its command is drawn per replicate
    from ``np.random.default_rng([seed, 2, replicate])``, so replicate r is the
    same terrain and command in every cell. The ``[sim]`` ranges of a
    ``walker = "mjx"`` sweep are drawn per replicate as well, from
    ``np.random.default_rng([seed, 3, replicate])`` (paired across cells too).

    Columns: ``scenario``, ``cell``, ``replicate``, ``robot.<name>`` (all of
    :data:`ROBOT_DEFAULTS`; unless set, the model's defaults, :func:`ijoy_jax.sweep.models.robot_defaults`),
    ``terrain.<field>`` (all of the family's
    parameters; none for a recorded terrain), ``command.vx`` (m/s), ``command.vy`` (m/s),
    ``command.wz`` (rad/s) (none when the commands come from ``[command] file``: every scenario
    takes :attr:`SweepConfig.command_steps`; nor with ``[command] random``: each scenario draws its own per step,
    :func:`ijoy_jax.sweep.programs.chunk_batch`), ``selector.horizon``, ``selector.refine`` (int64, 0 or 1),
    ``selector.discount``, and for ``walker = "mjx"`` ``sim.<field>`` (every
    :class:`ijoy_jax.sim.physics.Dynamics` field: the grid's, random cell's, ``[sim]``'s or the nominal value).

    Args:
      cfg: the sweep.
      max_scenarios: build only the first this many scenarios (None: all).
      progress: print a progress line on stderr every ~4e6 replicates while drawing commands
        (~1 s each).

    Returns:
      pandas.DataFrame, one row per scenario, ordered by ``scenario``.
    """
    import pandas as pd

    c = cells(cfg)
    n_rep = cfg.scenarios_per_cell
    total = len(c) * n_rep if max_scenarios is None else min(len(c) * n_rep, int(max_scenarios))
    reps = min(n_rep, total)  # only the replicates of the rows asked for
    if not cfg.command_columns:
        cmd = np.zeros((reps, 0))  # no command columns: the file's sequence, or drawn per step (chunk_batch)
    elif all(lo == hi for lo, hi in cfg.command.values()):
        # Fixed commands: what every replicate's draw gives (lo + (hi - lo) * u), without drawing.
        cmd = np.zeros((reps, 3))
        cmd[:] = [lo + (hi - lo) * 0.0 for lo, hi in (cfg.command[k] for k in COMMAND_KEYS)]
    else:
        cmd = _draw_commands(cfg, reps, progress)
    # Columns (in this order): ids, robot values, terrain values, commands. Each is written once into its
    # final place, by broadcasting a value per cell or per replicate: the float64 ones into one 2D block that
    # becomes the DataFrame's without a copy, the int64 ones inserted beside it (at 2e7 rows, np.full and
    # fancy indexing per column, then pandas stacking the columns into a block, took ~22 s of 28).
    rules = {} if cfg.family is None else generators.FAMILIES[cfg.family].rules
    fields = list(cfg.terrain_fields)
    sim_fields = sim_field_names() if cfg.walker == "mjx" else ()
    command_keys = cfg.command_columns
    names = [
        "scenario",
        "cell",
        "replicate",
        *(f"robot.{n}" for n in ROBOT_DEFAULTS),
        *(f"terrain.{n}" for n in fields),
        *(f"command.{k}" for k in command_keys),
        *(f"selector.{k}" for k in SELECTOR_DEFAULTS),
        *(f"sim.{k}" for k in sim_fields),
    ]
    ints = {
        "scenario",
        "cell",
        "replicate",
        *(f"terrain.{n}" for n in fields if rules[n].integer),
        *(f"selector.{k}" for k in SELECTOR_STATIC),
    }
    floats = [n for n in names if n not in ints]
    block = np.empty((len(floats), total))
    cols: dict[str, np.ndarray] = {n: block[i] for i, n in enumerate(floats)}
    cols.update({n: np.empty(total, np.int64) for n in names if n in ints})
    full, rem = divmod(total, n_rep)  # scenario s is replicate s % n_rep of cell s // n_rep

    def per_cell(out, values):
        """out[s] = values[s // n_rep]: a broadcast write per cell row (no index arrays)."""
        out[: full * n_rep].reshape(full, n_rep)[:] = values[:full, None]
        if rem:
            out[full * n_rep :] = values[full]

    def per_replicate(out, values):
        """out[s] = values[s % n_rep] (``values`` has min(n_rep, total) rows)."""
        if full:
            out[: full * n_rep].reshape(full, n_rep)[:] = values[None, :]
        out[full * n_rep :] = values[:rem]

    cols["scenario"][:] = np.arange(total, dtype=np.int64)
    per_cell(cols["cell"], c["cell"].to_numpy())  # cells() numbers its rows 0, 1, ...
    per_replicate(cols["replicate"], np.arange(reps, dtype=np.int64))
    defaults = None if cfg.params_class is None else cfg.params_class()
    fixed = {
        **{f"robot.{n}": cfg.robot.get(n, d) for n, d in models.robot_defaults(cfg.model).items()},
        **{f"terrain.{n}": cfg.terrain_params.get(n, getattr(defaults, n)) for n in fields},
        **{f"selector.{n}": getattr(cfg, n) for n in SELECTOR_DEFAULTS},
    }
    for key, value in fixed.items():
        out = cols[key]
        if key in c:
            per_cell(out, c[key].to_numpy().astype(out.dtype))
        else:
            out[:] = np.asarray(value).astype(out.dtype)
    for j, k in enumerate(command_keys):
        per_replicate(cols[f"command.{k}"], cmd[:, j])
    if sim_fields:
        from ijoy_jax.sim import physics

        drawn = [k for k, (lo, hi) in cfg.sim.items() if lo != hi]
        draws = (
            _draw_commands(cfg, reps, progress, stream=3, ranges=[cfg.sim[k] for k in drawn])
            if drawn
            else np.zeros((reps, 0))
        )
        for k in sim_fields:
            out = cols[f"sim.{k}"]
            if f"sim.{k}" in c:
                per_cell(out, c[f"sim.{k}"].to_numpy().astype(out.dtype))
            elif k in drawn:
                per_replicate(out, draws[:, drawn.index(k)])
            else:
                out[:] = cfg.sim.get(k, (getattr(physics.NOMINAL, k),) * 2)[0]
    df = pd.DataFrame(block.T, columns=floats, copy=False)
    for i, n in enumerate(names):
        if n in ints:
            df.insert(i, n, pd.Series(cols[n], index=df.index, copy=False))  # a bare array would be copied
    return df
