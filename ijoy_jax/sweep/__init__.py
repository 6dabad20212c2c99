"""Sweeps: declare a grid or random samples of scenarios in TOML, run them batched and resumable, load the results.

Public names::

  load_config / parse_config / SweepConfig / SweepConfigError   the TOML schema, validated before compute
  set_values                                                     a sweep file's text with some values set
  cells / scenarios                                              the expansion into cells and scenarios
  MAX_SCENARIOS / HOST_MEMORY_FRACTION / table_bytes             sizes checked before any allocation
  MAX_NUM_STEPS / MAX_DENSITY / MIN_RESOLUTION / MAX_MAP_CELLS /  bounds of the sizes that set memory and
  MAX_OBJECT_SLOTS / MAX_ACTIONS                                 static shapes
  run / RunStats / DEFAULT_CHUNK / trace_count                   jit + vmap in chunks split over local
                                                                 devices, parquet parts, resume
  scenario / Scenario                                            one scenario's terrain, robot, start and
                                                                 command by id (``ijoy drive --scenario``)
  recorded                                                       commands from a recorded drive or a trace
                                                                 file, a recorded terrain ([command] file,
                                                                 [terrain] recording)
  default_chunk_size / auto_chunk_size / scenario_bytes /        chunks sized to device memory (physics:
  balanced_chunk_size                                            balanced, no padded chunk)
  distributed                                                    several processes/hosts (jax.distributed)
  local                                                          N local processes, one GPU each, in one call
  load / aggregate / load_aggregates / plot / METRICS / UNITS    tidy table (union of processes), 95% CIs, plot
  paired_differences                                             cell minus baseline, replicate by replicate
  plot_tradeoff                                                  a safety metric against its price per cell
                                                                 (falls against progress)
  PLOT_METRICS / PHYSICS_PLOT_METRICS / SELECTOR_PLOT_METRICS    the plot's default panels
  SELECTOR_DEFAULTS                                              the selector's options a sweep varies
                                                                 (lookahead horizon, refinement, discount)
  WALKERS / PHYSICS_METRICS / SIM_MIN_RESOLUTION                 walker = "mjx": the MJX biped, its metrics
                                                                 (falls, collisions, placement errors)
  MODELS / models                                                [sweep] model: the robot, HRP-2 ("biped")
                                                                 or the Unitree G1 ("g1"), for the selector
                                                                 and in MJX; its defaults, actions, builder
  IncompleteSweepError / action_counts / PAPER_ACTIONS           missing chunks, parts of another plan;
                                                                 density as action counts
  plan_hash / part_plan                                          the plan every part records (its hash)
  WALK_METRICS / WALK_PHYSICS_METRICS                            [terrain] walk: steps made, progress along +x
                                                                 (ijoy bench walk's table)
  EXTRA_METRICS / plot_crossing / b_max                          family metrics (bars: crossing rate vs the
                                                                 paper's bound; see terrain.family.Family.metrics)

Example:
  >>> from ijoy_jax import sweep
  >>> cfg = sweep.load_config("sweeps/w_sweep.toml")  # doctest: +SKIP
  >>> sweep.run(cfg, "results/w_sweep")  # doctest: +SKIP
  >>> sweep.load_aggregates("results/w_sweep")  # doctest: +SKIP

Command line: ``ijoy sweep run FILE`` and ``ijoy sweep summarize DIR``.
"""

# ruff: noqa: E402  (the package's imports follow the check of its extra)
from ijoy_jax.extras import require as _require

_require("sweep", "pandas", "pyarrow", "matplotlib")

from ijoy_jax.limits import MAX_ACTIONS, MAX_DENSITY, MAX_MAP_CELLS, MAX_NUM_STEPS
from ijoy_jax.sweep import distributed, export, local, models, recorded
from ijoy_jax.sweep.columns import EXTRA_METRICS, METRICS, PHYSICS_METRICS, UNITS, WALK_METRICS, WALK_PHYSICS_METRICS
from ijoy_jax.sweep.config import load_config, parse_config, set_values
from ijoy_jax.sweep.execute import RunStats, run
from ijoy_jax.sweep.expansion import HOST_MEMORY_FRACTION, MAX_SCENARIOS, cells, scenarios, table_bytes
from ijoy_jax.sweep.export import EXPORT_TERRAINS, export_drive
from ijoy_jax.sweep.folder import IncompleteSweepError, part_plan
from ijoy_jax.sweep.plan import plan_hash
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
)
from ijoy_jax.sweep.programs import Scenario, scenario, scenario_bytes, trace_count
from ijoy_jax.sweep.results import aggregate, load, load_aggregates, paired_differences
from ijoy_jax.sweep.schema import (
    COMMAND_KEYS,
    MAX_OBJECT_SLOTS,
    MIN_RESOLUTION,
    MODELS,
    ROBOT_DEFAULTS,
    SELECTOR_DEFAULTS,
    SIM_MIN_RESOLUTION,
    WALKERS,
    SweepConfig,
    SweepConfigError,
)
from ijoy_jax.sweep.sizing import (
    DEFAULT_CHUNK,
    MAX_AUTO_CHUNK,
    MEMORY_FRACTION,
    auto_chunk_size,
    balanced_chunk_size,
    default_chunk_size,
)

__all__ = [
    "COMMAND_KEYS",
    "DEFAULT_CHUNK",
    "EXPORT_TERRAINS",
    "EXTRA_METRICS",
    "HOST_MEMORY_FRACTION",
    "MAX_AUTO_CHUNK",
    "MAX_ACTIONS",
    "MAX_DENSITY",
    "MAX_MAP_CELLS",
    "MAX_NUM_STEPS",
    "MAX_OBJECT_SLOTS",
    "MEMORY_FRACTION",
    "MAX_SCENARIOS",
    "MIN_RESOLUTION",
    "METRICS",
    "MODELS",
    "PAPER_ACTIONS",
    "PHYSICS_METRICS",
    "PHYSICS_PLOT_METRICS",
    "PLOT_METRICS",
    "ROBOT_DEFAULTS",
    "SELECTOR_DEFAULTS",
    "SELECTOR_PLOT_METRICS",
    "SIM_MIN_RESOLUTION",
    "UNITS",
    "WALKERS",
    "WALK_METRICS",
    "WALK_PHYSICS_METRICS",
    "IncompleteSweepError",
    "RunStats",
    "Scenario",
    "SweepConfig",
    "SweepConfigError",
    "action_counts",
    "aggregate",
    "auto_chunk_size",
    "balanced_chunk_size",
    "b_max",
    "cells",
    "default_chunk_size",
    "distributed",
    "export",
    "export_drive",
    "local",
    "models",
    "recorded",
    "load",
    "load_aggregates",
    "load_config",
    "paired_differences",
    "parse_config",
    "part_plan",
    "plan_hash",
    "plot",
    "plot_crossing",
    "plot_tradeoff",
    "run",
    "scenario",
    "scenario_bytes",
    "scenarios",
    "set_values",
    "table_bytes",
    "trace_count",
]
