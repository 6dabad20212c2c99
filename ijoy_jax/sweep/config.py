"""Sweep declarations: the TOML schema, its validation, and the expansion into cells and scenarios.

A sweep file has these tables (every key optional unless noted; units in brackets):

.. code-block:: toml

    [sweep]
    name = "w_sweep"              # names the default output folder
    description = "..."
    seed = 0                      # terrains, commands and random cells derive from it
    scenarios_per_cell = 16       # replicates of every cell (terrain seed = replicate index)
    num_steps = 16                # decisions per rollout
    method = "exhaustive"         # "exhaustive", "ordered" or "naive"
    kernel = "xla"                # FootCost: "xla" or "pallas" (the fused kernel: GPU; interpreted elsewhere)
    random_samples = 0            # cells drawn from [random] (crossed with the grid)
    walker = "perfect"            # "perfect" (every step lands as sent) or "mjx" (the MuJoCo XLA biped)
    horizon = 1                   # method = "lookahead": steps scored per decision (1: the one-step selector)
    beam = 16                     # method = "lookahead", horizons >= 3: sequences kept per level (omit: exact)
    refine = false                # refine each step in continuous (dx, dy, dtheta) (ijoy_jax.refine)
    discount = 1.0                # the lookahead's discount gamma

    [robot]                       # fixed robot values (HRP-2's defaults otherwise)
    margin = 0.02                 # [m]
    metrics.slope_weight = 0.5    # any TerrainMetrics field

    [terrain]
    family = "obstacles"          # a name in ijoy_jax.terrain.generators.FAMILIES
    shape = [150, 100]            # cells along x and y (static)
    resolution = 0.02             # [m] (static)
    has_height = false            # 2D occupancy grid or 2.5D height map (static)
    max_count = 16                # object slots of the object families (static)

    [terrain.params]              # fixed values of the family's parameter pytree
    count = 12

    # or, instead of family, shape, resolution, has_height, max_count and params:
    # recording = "drive.mcap"    # a drive recording's map and start feet (ijoy_jax.sweep.recorded)

    [command]                     # joystick command per scenario: a number or [lo, hi] uniform
    vx = 0.25                     # [m/s] forward, in the stance foot's frame
    vy = [-0.05, 0.05]            # [m/s] left
    wz = 0.0                      # [rad/s] counter-clockwise
    # or, instead of vx, vy and wz, a person's commands, one per step (the same for every scenario):
    # file = "drive.mcap"         # a drive recording (ijoy drive --record), or a trace file "drive.csv"
    # first_swing = 1             # +1 the left foot first (default: the recording's; +1 for a trace)
    # deadzone = 0.1              # trace files only: the stick's dead zone
    # decide_at = 0.0             # trace files only: the fraction of a step at which the stick is read

    [grid]                        # cartesian product of value lists
    "robot.w" = [0.0, 0.5, 1, 2, 4]
    "robot.density" = [0.5, 1.0]  # a shape-changing axis: one compile per value
    "selector.horizon" = [1, 2, 3]  # static too: one compile per value (method = "lookahead")
    "selector.refine" = [false, true]

    [random]                      # uniform [lo, hi] per random cell (not density)
    "robot.margin" = [0.0, 0.1]

    [sim]                         # walker = "mjx" only: the physics (ijoy_jax.sim.physics.Dynamics),
    friction = 0.8                # a number, or [lo, hi] uniform per replicate as the commands
    stance_noise = [0.0, 0.02]    # [m]; also mass_scale, kp_scale, latency [s], push [N s]

Parameter names are ``robot.<name>`` (``w``, ``rotation_weight``, ``margin``,
``step_time``, ``foot_length``, ``foot_width``, ``max_sole_pitch``,
``max_sole_roll``, ``max_sole_distance``, ``density``, ``reach`` (the largest
forward/backward step of :func:`ijoy_jax.robots.hrp2`, m: fixed in ``[robot]``,
one per sweep; ``reach = 0.30`` for stairs),
``metrics.<TerrainMetrics field>``), ``terrain.<field of the family's
parameter class>``, ``selector.<name>`` (the selector's options:
``selector.horizon`` and ``selector.refine`` in ``[grid]`` only, they are
static; ``selector.discount`` in either; their fixed values are the
``[sweep]`` keys ``horizon``, ``refine`` and ``discount``; the beam applies to
horizons of 3 or more, horizon 2 is searched exactly) and, with
``walker = "mjx"``, ``sim.<field>`` (the fields of
:class:`ijoy_jax.sim.physics.Dynamics`: ``friction``, ``mass_scale``, ``kp_scale``,
``latency`` [s], ``stance_noise`` [m], ``push`` [N s]; bounds in
:data:`ijoy_jax.sim.physics.BOUNDS`). In ``[grid]`` and
``[random]`` they may be written quoted (``"robot.w" = [...]``) or as nested tables
(``[grid.robot] w = [...]``).

The simulated walker (``walker = "mjx"``) walks the MJX biped
(:func:`ijoy_jax.sim.walker.rollout_batch`) in place of the perfect robot: the same
scenarios plus the per-scenario physics metrics (:data:`ijoy_jax.sweep.PHYSICS_METRICS`).
It runs the one-step selectors (``exhaustive``, ``ordered``, ``naive``), refined or not
(``refine``), not the lookahead.
Its body is static, so the sweep must fit it, checked before compute: the step time
is the controller's (``robot.step_time`` 0.8 s, not swept), the footprint is the
physical foot's (``robot.foot_length``/``foot_width`` fixed in ``[robot]``, not
swept), the map's cells are at least :data:`SIM_MIN_RESOLUTION` wide, and the robot
standing at the start zone's centre stands on the map.

Commands and terrain from files (:mod:`ijoy_jax.sweep.recorded`, paths relative to the sweep
file): ``[command] file`` replays a recorded drive's commands (or a trace file's) step by step,
``sweep.num_steps`` defaulting to their number; ``[terrain] recording`` walks every scenario on a
recording's map from its start feet (no ``terrain.*`` parameters then; with the perfect robot every
replicate is the same walk, so ``scenarios_per_cell = 1``). ``ijoy drive --replay REC --export-sweep
OUT.toml`` writes such a file for a recorded drive.

A *cell* is one combination of grid values (times one random sample); each cell
runs ``scenarios_per_cell`` scenarios, replicate ``r`` of every cell on the same
terrain (seed ``r``) with the same command draw: paired comparisons across cells.

Everything is checked by :func:`load_config` before any compute; a problem
raises :class:`SweepConfigError` naming the file, the key and the reason.
Numbers must be finite and within float32's range (the robot, the terrain's
parameters and the commands are float32 on the device), integers within TOML's
64 bits; the sizes that set memory or static shapes have documented bounds:
:data:`MAX_NUM_STEPS`, :data:`MAX_DENSITY`, :data:`MAX_ACTIONS`, :data:`MIN_RESOLUTION`,
:data:`MAX_MAP_CELLS`, :data:`MAX_OBJECT_SLOTS`, a map within
:data:`~ijoy_jax.footcost.MAX_COORDINATE`, foot sizes within
:data:`~ijoy_jax.robots.MAX_SIZE`.

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

import dataclasses
import math
import os
import sys
import time
import tomllib
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from ijoy_jax import robots
from ijoy_jax.footcost import MAX_COORDINATE
from ijoy_jax.limits import MAX_ACTIONS, MAX_DENSITY, MAX_MAP_CELLS, MAX_NUM_STEPS
from ijoy_jax.select import KERNELS, METHODS
from ijoy_jax.sweep import recorded, seeding
from ijoy_jax.terrain import generators
from ijoy_jax.terrain.family import Family, ParamError

__all__ = [
    "COMMAND_KEYS",
    "METRICS",
    "PHYSICS_METRICS",
    "SELECTOR_DEFAULTS",
    "SIM_MIN_RESOLUTION",
    "WALKERS",
    "HOST_MEMORY_FRACTION",
    "MAX_ACTIONS",
    "MAX_DENSITY",
    "MAX_MAP_CELLS",
    "MAX_NUM_STEPS",
    "MAX_OBJECT_SLOTS",
    "MAX_SCENARIOS",
    "MIN_RESOLUTION",
    "ROBOT_DEFAULTS",
    "SweepConfig",
    "SweepConfigError",
    "cells",
    "load_config",
    "parse_config",
    "reach_of",
    "scenarios",
    "table_bytes",
]

def _robot_defaults() -> dict[str, float]:
    d = robots.hrp2_defaults()  # the one source of HRP-2's numbers; order: body and selector, the action set, metrics
    body = {k: v for k, v in d.items() if k not in _ACTION_SET and not k.startswith("metrics.")}
    return {**body, **{k: d[k] for k in _ACTION_SET}, **{k: v for k, v in d.items() if k.startswith("metrics.")}}


_ACTION_SET = ("density", "reach")
# What shapes HRP-2's action set (robots.hrp2's arguments, not leaves of the Robot): density is a compile group
# of its own; reach is one per sweep.


ROBOT_DEFAULTS: Mapping[str, float] = MappingProxyType(_robot_defaults())
"""Every sweepable robot parameter and its default (m, s, rad, cost units)."""

# Lower bounds: (bound, strict). Every robot parameter is >= 0; sizes and times > 0.
_POSITIVE = {n for n, spec in robots.SCALAR_LEAVES.items() if spec.positive} | set(_ACTION_SET)
# Largest margin the sweep accepts (m): the static footprint window grows with it.
_MAX_MARGIN = 0.5
# Largest magnitude of any number (a float32 robot leaf or command; beyond it float32 holds inf).
_MAX_FLOAT = float(np.finfo(np.float32).max)
# TOML's integers are 64-bit (tomllib reads longer ones): a seed or count beyond is refused, not overflowed later.
_MAX_INT = 2**63 - 1
# MAX_NUM_STEPS, MAX_DENSITY, MAX_ACTIONS and MAX_MAP_CELLS are the library's (ijoy_jax.limits): a sweep file,
# the CLI, the server and the functions they call share one memory budget.
MIN_RESOLUTION = 0.005
"""Finest map resolution (m): FootCost's windows hold the footprint in cells, ~(footprint / resolution)**2 per
candidate (~110 x 110 for HRP-2 at 5 mm)."""
MAX_OBJECT_SLOTS = 1024
"""Most object slots (``terrain.max_count``) of an object family's map: each is rasterised over every cell."""

COMMAND_KEYS = ("vx", "vy", "wz")
"""Joystick command components: forward (m/s), left (m/s), turn (rad/s), in the stance foot's frame."""

WALKERS = ("perfect", "mjx")
"""``[sweep] walker``: the paper's perfect robot, or the MuJoCo XLA biped (:mod:`ijoy_jax.sim`)."""

SIM_MIN_RESOLUTION = 0.01
"""Finest map resolution (m) of a ``walker = "mjx"`` sweep: MJX collides each 9 mm sole sphere with
``(ceil(2 r / res) + 1)^2`` height-field prisms per physics step, 4 at 2 cm, 9 at 1 cm, 25 at 5 mm."""

MAX_SCENARIOS = 10**8
"""Most scenarios one sweep may declare (cells x scenarios_per_cell): their host tables alone take tens of GB."""
HOST_MEMORY_FRACTION = 0.5
"""Share of the host's physical memory a sweep's tables (:func:`table_bytes`) may need."""
_TABLE_COPIES = 3  # the scenario table, its index by scenario while running, the loaded results at the end
_PROGRESS_EVERY = 1 << 22  # replicates between progress lines while drawing commands (~1 s)

_SECTIONS = ("sweep", "robot", "terrain", "command", "grid", "random", "sim")
_SWEEP_KEYS = ("name", "description", "seed", "scenarios_per_cell", "num_steps", "method", "kernel",
               "random_samples", "walker", "horizon", "beam", "refine", "discount")

SELECTOR_DEFAULTS: Mapping[str, float] = MappingProxyType({"horizon": 1, "refine": False, "discount": 1.0})
"""The selector options a sweep may vary (``selector.<name>``; fixed values: the ``[sweep]`` keys of the same
name) and their defaults: the lookahead's horizon (static, int >= 1), refinement (static, bool) and discount."""

# The metric columns of every results table (ijoy_jax.sweep.results reads and aggregates them; here they
# count towards the table's size before a sweep runs).
METRICS = ("steps_taken", "steps_in_place", "steps_stationary", "stopped", "footholds_on_obstacles",
           "footholds_near_obstacles", "invalid_footholds", "distance_along", "distance_across", "mean_deviation",
           "mean_foot_cost", "commands_not_finite", "unsupported_decisions")
"""Rollout metrics (:meth:`ijoy_jax.Trajectory.summary`) in every results table (``footholds_near_obstacles``:
footholds taken with an obstacle within :data:`ijoy_jax.control.NEAR_OBSTACLE` of the foot; absent from
results written before it existed, which aggregate without it)."""

PHYSICS_METRICS = ("fell", "collided", "obstacle_contacts", "placement_error_mean", "placement_error_p95",
                   "yaw_error_mean", "tilt_error_p95", "dynamics_invalid")
"""Per-scenario metrics of a ``walker = "mjx"`` sweep (:func:`ijoy_jax.sim.walker.summary`): the robot fell,
touched an obstacle (``collided``) and in how many steps, its touch-down errors (m, rad), and whether a
physics value was out of bounds (``dynamics_invalid``; refused before compute, so False)."""

_SELECTOR_STATIC = ("horizon", "refine")  # shape or program changing: [grid] only, one compile per value
_TERRAIN_KEYS = ("family", "shape", "resolution", "has_height", "max_count", "params")
_RECORDING_KEY = "recording"  # [terrain] recording: a drive recording's terrain, instead of the _TERRAIN_KEYS


class SweepConfigError(ValueError):
    """A sweep file is malformed: the message names the file, the key and the reason."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class SweepConfig:
    """A validated sweep (see the module docstring for the TOML schema).

    Fields::

      name: sweep name (default: the file's stem).
      description: free text.
      seed: base seed (int).
      scenarios_per_cell: replicates per cell (>= 1).
      num_steps: decisions per rollout (>= 1; static).
      method: selector, one of :data:`ijoy_jax.select.METHODS` (static).
      kernel: FootCost path, one of :data:`ijoy_jax.select.KERNELS` (static): "pallas" runs the fused
        kernel (the same decisions; several times faster on a GPU, slow interpreted on a CPU).
      random_samples: random cells drawn from ``random`` (0: none).
      walker: who executes the steps, one of :data:`WALKERS` (static).
      horizon, refine, discount: the selector's options (:data:`SELECTOR_DEFAULTS`), unless swept as
        ``selector.<name>``; beam: the lookahead's beam for horizons >= 3 (None: exact).
      family: terrain family name (None: the terrain of ``terrain_recording``); shape (nx, ny) cells;
        resolution (m); has_height; max_count (static object slots, None: the family's default).
      robot: fixed robot values, ``{name: float}`` (names as in :data:`ROBOT_DEFAULTS`).
      terrain_params: fixed terrain parameters, ``{field: number}``.
      command: ``{component: (lo, hi)}``, lo == hi for a fixed value (m/s, rad/s); {} when the commands
        come from ``command_file``.
      command_file: the :class:`~ijoy_jax.sweep.recorded.CommandSequence` of ``[command] file`` (step ``k``
        of every rollout gets its ``k``-th command), or None: the ``[command]`` distribution.
      terrain_recording: the :class:`~ijoy_jax.sweep.recorded.RecordedTerrain` of ``[terrain] recording``
        (every scenario walks that terrain from its start feet), or None: the family generates them.
      grid: ``{"robot.x" | "terrain.x" | "sim.x" | "selector.x": (values...)}``.
      random: ``{"robot.x" | "terrain.x" | "sim.x" | "selector.discount": (lo, hi)}``.
      sim: ``{key: (lo, hi)}`` of the ``[sim]`` table, lo == hi for a fixed value (``walker = "mjx"``).
      source: the file it came from; text: the file's text (saved with the results).
    """

    name: str
    description: str = ""
    seed: int = 0
    scenarios_per_cell: int = 8
    num_steps: int = 16
    method: str = "exhaustive"
    kernel: str = "xla"
    random_samples: int = 0
    walker: str = "perfect"
    horizon: int = 1
    beam: int | None = None
    refine: bool = False
    discount: float = 1.0
    family: str = "obstacles"
    shape: tuple[int, int] = (150, 100)
    resolution: float = 0.02
    has_height: bool = False
    max_count: int | None = None
    robot: Mapping[str, float] = dataclasses.field(default_factory=dict)
    terrain_params: Mapping[str, float] = dataclasses.field(default_factory=dict)
    command: Mapping[str, tuple[float, float]] = dataclasses.field(
        default_factory=lambda: {"vx": (0.25, 0.25), "vy": (0.0, 0.0), "wz": (0.0, 0.0)})
    grid: Mapping[str, tuple] = dataclasses.field(default_factory=dict)
    random: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    sim: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    command_file: recorded.CommandSequence | None = dataclasses.field(default=None, compare=False)
    terrain_recording: recorded.RecordedTerrain | None = dataclasses.field(default=None, compare=False)
    source: str = "<string>"
    text: str = ""

    @property
    def params_class(self) -> type | None:
        """The terrain family's parameter pytree class (None for a recorded terrain)."""
        return None if self.family is None else generators.FAMILIES[self.family].params

    @property
    def terrain_fields(self) -> tuple[str, ...]:
        """The terrain parameters of the family (``terrain.<field>`` columns); () for a recorded terrain."""
        cls = self.params_class
        return () if cls is None else tuple(f.name for f in dataclasses.fields(cls))

    @property
    def static_max_count(self) -> int | None:
        """Object slots passed to the generator (None for families without them, and for a recorded terrain)."""
        if self.family is None:
            return None
        fam = generators.FAMILIES[self.family]
        if fam.max_count is None:
            return None
        return fam.max_count if self.max_count is None else self.max_count

    @property
    def first_swing(self) -> int:
        """+1 if every rollout's left foot swings first (the command file's choice; +1 without one)."""
        return 1 if self.command_file is None else self.command_file.first_swing

    @property
    def command_steps(self) -> np.ndarray | None:
        """(num_steps, 3) float32 the command of every step, the same for every scenario (``[command] file``), or
        None: each scenario holds its own command (``command.vx``, ``command.vy``, ``command.wz`` columns)."""
        if self.command_file is None:
            return None
        return self.command_file.commands[: self.num_steps]

    @property
    def inputs(self) -> dict:
        """The SHA-256 of each file the sweep reads besides its own text, ``{key: hex digest}`` ({} for none):
        part of its plan, so the results of a changed file are never mixed with the old ones on resume."""
        files = (("command.file", self.command_file), ("terrain.recording", self.terrain_recording))
        return {key: f.sha256 for key, f in files if f is not None}

    @property
    def swept(self) -> tuple[str, ...]:
        """Parameter names that vary across cells (grid keys, then random keys)."""
        return tuple(self.grid) + tuple(self.random)

    @property
    def num_cells(self) -> int:
        """Number of cells: product of the grid sizes times max(1, random_samples)."""
        n = math.prod(len(v) for v in self.grid.values())
        return n * (max(1, self.random_samples) if self.random else 1)

    @property
    def num_scenarios(self) -> int:
        """Number of scenarios: cells times scenarios_per_cell."""
        return self.num_cells * self.scenarios_per_cell


# --------------------------------------------------------------------------- validation helpers


class _Checker:
    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, reason: str):
        raise SweepConfigError(f"{self.source}: {key}: {reason}")

    def table(self, key: str, value) -> dict:
        if not isinstance(value, dict):
            self.fail(key, f"must be a table, got {type(value).__name__} {value!r}")
        return value

    def unknown(self, key_prefix: str, table: dict, known) -> None:
        for k in table:
            if k not in known:
                self.fail(f"{key_prefix}{k}", f"unknown key; known keys: {', '.join(known)}")

    def number(self, key: str, value) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, f"must be a number, got {type(value).__name__} {value!r}")
        self.int64(key, value)
        if not math.isfinite(value):
            self.fail(key, f"must be finite, got {value!r}")
        if abs(value) > _MAX_FLOAT:
            self.fail(key, f"must be at most {_MAX_FLOAT:.4g} in magnitude (float32's largest; the robot and the "
                           f"commands are float32), got {value!r}")
        return float(value)

    def int64(self, key: str, value) -> None:
        """An integer must fit TOML's 64 bits (tomllib reads longer ones, which overflow later)."""
        if isinstance(value, int) and abs(value) > _MAX_INT:
            self.fail(key, f"must fit in 64 bits (|x| <= 2**63 - 1, as TOML integers do), got {value}")

    def integer(self, key: str, value, lo: int | None = None, hi: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(key, f"must be an integer, got {type(value).__name__} {value!r}")
        self.int64(key, value)
        if lo is not None and value < lo:
            self.fail(key, f"must be >= {lo}, got {value}")
        if hi is not None and value > hi:
            self.fail(key, f"must be <= {hi}, got {value}")
        return int(value)

    def string(self, key: str, value, choices=None) -> str:
        if not isinstance(value, str):
            self.fail(key, f"must be a string, got {type(value).__name__} {value!r}")
        if choices is not None and value not in choices:
            self.fail(key, f"must be one of {', '.join(choices)}, got {value!r}")
        return value

    def range(self, key: str, value) -> tuple[float, float]:
        if not isinstance(value, list) or len(value) != 2:
            self.fail(key, f"must be a range [lo, hi] of two numbers, got {value!r}")
        lo, hi = self.number(f"{key}[0]", value[0]), self.number(f"{key}[1]", value[1])
        if lo > hi:
            self.fail(key, f"impossible range: lo ({lo}) > hi ({hi})")
        return lo, hi


def _flatten(table: dict, prefix: str = "") -> dict:
    """{"robot": {"w": [..]}} -> {"robot.w": [..]} (dotted TOML keys and nested tables are the same)."""
    out = {}
    for k, v in table.items():
        if isinstance(v, dict) and v:  # an empty table stays a value, refused where a number or list belongs
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _robot_value(chk: _Checker, key: str, name: str, value) -> float:
    """Check one robot parameter value (``name`` as in ROBOT_DEFAULTS)."""
    v = chk.number(key, value)
    if name in _POSITIVE and v <= 0:
        chk.fail(key, f"must be > 0, got {v}")
    if v < 0:
        chk.fail(key, f"must be >= 0, got {v}")
    if name == "margin" and v > _MAX_MARGIN:
        chk.fail(key, f"must be <= {_MAX_MARGIN} m, got {v}")
    if name in ("foot_length", "foot_width") and v > robots.MAX_SIZE:
        chk.fail(key, f"must be <= {robots.MAX_SIZE} m (ijoy_jax.robots.MAX_SIZE), got {v}")
    if name == "density" and v > MAX_DENSITY:
        chk.fail(key, f"must be <= {MAX_DENSITY} (ijoy_jax.limits.MAX_DENSITY: the targets table grows as its sixth "
                      f"power), got {v}")
    return v


def _sim_value(chk: _Checker, key: str, name: str, value) -> float:
    """Check one physics value (``name`` a :class:`ijoy_jax.sim.physics.Dynamics` field) against its bounds."""
    from ijoy_jax.sim import physics

    v = chk.number(key, value)
    b = physics.BOUNDS[name]
    if v < b.lo or (b.strict and v == b.lo) or v > b.hi:
        lo = f"> {b.lo:g}" if b.strict else f">= {b.lo:g}"
        chk.fail(key, f"must be {lo} and <= {b.hi:g}{' ' + b.unit if b.unit else ''} ({b.why}; "
                      f"ijoy_jax.sim.physics.BOUNDS), got {v}")
    return v


def _terrain_value(chk: _Checker, key: str, fam: Family, name: str, value, max_count: int | None):
    """Check one terrain parameter value by its family's rule (:meth:`ijoy_jax.terrain.family.Family.check`)."""
    chk.int64(key, value)  # a longer integer would overflow in the float conversion
    try:
        v = fam.check(name, value, max_count=max_count, max_count_key="[terrain] max_count")
    except ParamError as e:
        chk.fail(key, e.reason)
    if math.isfinite(v) and abs(v) > _MAX_FLOAT:  # the generator's parameters are float32 (inf where allowed)
        chk.fail(key, f"must be at most {_MAX_FLOAT:.4g} in magnitude (float32's largest), got {value!r}")
    return v


def _generated_terrain(chk: _Checker, terrain: dict, kw: dict):
    """A generated terrain's ``[terrain]`` table into ``kw``; returns (the family, its parameter fields, its
    object slots)."""
    family = chk.string("terrain.family", terrain.get("family", "obstacles"), tuple(generators.FAMILIES))
    kw["family"] = family
    if "shape" in terrain:
        s = terrain["shape"]
        if not isinstance(s, list) or len(s) != 2:
            chk.fail("terrain.shape", f"must be [nx, ny], got {s!r}")
        kw["shape"] = (chk.integer("terrain.shape[0]", s[0], lo=8), chk.integer("terrain.shape[1]", s[1], lo=8))
        if math.prod(kw["shape"]) > MAX_MAP_CELLS:
            chk.fail("terrain.shape", f"{kw['shape'][0]} x {kw['shape'][1]} cells exceed the limit of "
                                      f"{MAX_MAP_CELLS} (ijoy_jax.limits.MAX_MAP_CELLS)")
    if "resolution" in terrain:
        r = chk.number("terrain.resolution", terrain["resolution"])
        if r <= 0:
            chk.fail("terrain.resolution", f"must be > 0 m, got {r}")
        if r < MIN_RESOLUTION:
            chk.fail("terrain.resolution", f"must be >= {MIN_RESOLUTION} m (sweep.config.MIN_RESOLUTION), got {r}")
        kw["resolution"] = r
    extent = max(kw.get("shape", SweepConfig.shape)) * kw.get("resolution", SweepConfig.resolution)
    if extent > MAX_COORDINATE:
        chk.fail("terrain.resolution" if "resolution" in terrain else "terrain.shape",
                 f"the map reaches {extent:.6g} m, beyond the {MAX_COORDINATE:g} m where float32 holds millimetres "
                 "(ijoy_jax.footcost.MAX_COORDINATE)")
    if "has_height" in terrain:
        if not isinstance(terrain["has_height"], bool):
            chk.fail("terrain.has_height", f"must be true or false, got {terrain['has_height']!r}")
        kw["has_height"] = terrain["has_height"]
    fam = generators.FAMILIES[family]
    if "max_count" in terrain:
        if fam.max_count is None:
            chk.fail("terrain.max_count", f"family {family!r} has no object slots")
        kw["max_count"] = chk.integer("terrain.max_count", terrain["max_count"], lo=0, hi=MAX_OBJECT_SLOTS)
    max_count = kw.get("max_count", fam.max_count)
    fields = tuple(f.name for f in dataclasses.fields(fam.params))
    tparams = chk.table("terrain.params", terrain.get("params", {}))
    chk.unknown("terrain.params.", tparams, fields)
    kw["terrain_params"] = {k: _terrain_value(chk, f"terrain.params.{k}", fam, k, v, max_count)
                            for k, v in tparams.items()}
    return fam, fields, max_count


def _file_path(chk: _Checker, key: str, value, folder: Path) -> Path:
    """A file named in the sweep file (a string; relative to the sweep file's folder)."""
    if not isinstance(value, str) or not value:
        chk.fail(key, f"must be a file name (a string), got {value!r}")
    path = Path(value)
    return path if path.is_absolute() else folder / path


def _recorded_terrain(chk: _Checker, terrain: dict, kw: dict, folder: Path) -> None:
    """``[terrain] recording``: a drive recording's terrain (and start), its sizes within the sweep's bounds, into
    ``kw`` (``family`` None)."""
    key = f"terrain.{_RECORDING_KEY}"
    for k in _TERRAIN_KEYS:
        if k in terrain:
            chk.fail(f"terrain.{k}", f"the terrain comes from {key} (the recorded map): give a recording or a "
                                     "generated terrain, not both")
    try:
        rec = recorded.read_terrain(_file_path(chk, key, terrain[_RECORDING_KEY], folder))
    except ValueError as e:
        chk.fail(key, str(e))
    t = rec.terrain
    shape, res = tuple(int(v) for v in t.shape), float(t.resolution)
    if min(shape) < 8 or math.prod(shape) > MAX_MAP_CELLS:
        chk.fail(key, f"the recorded map of {shape[0]} x {shape[1]} cells is outside the sweep's sizes (at least "
                      f"8 cells a side, at most {MAX_MAP_CELLS} cells: ijoy_jax.limits.MAX_MAP_CELLS)")
    if not res >= MIN_RESOLUTION:
        chk.fail(key, f"the recorded map's resolution {res} m is finer than {MIN_RESOLUTION} m "
                      "(sweep.config.MIN_RESOLUTION)")
    reach = float(np.max(np.abs(np.asarray(t.origin, np.float64)))) + max(shape) * res
    if reach > MAX_COORDINATE:
        chk.fail(key, f"the recorded map reaches {reach:.6g} m, beyond the {MAX_COORDINATE:g} m where float32 holds "
                      "millimetres (ijoy_jax.footcost.MAX_COORDINATE)")
    kw.update(family=None, shape=shape, resolution=res, has_height=bool(t.has_height), terrain_recording=rec,
              terrain_params={})


def _command_file(chk: _Checker, command: dict, kw: dict, folder: Path, swept: tuple[str, ...]) -> None:
    """``[command] file``: the command sequence (:func:`ijoy_jax.sweep.recorded.read_commands`) into ``kw``,
    and ``sweep.num_steps`` checked against it (its default: every command)."""
    path = _file_path(chk, "command.file", command["file"], folder)
    options = {}
    for k in ("deadzone", "decide_at"):
        if k in command:
            if recorded.is_recording(path):
                chk.fail(f"command.{k}", "is for trace files: a recording's commands are recorded (the stick "
                                         "already went through its dead zone, read when the drive read it)")
            options[k] = chk.number(f"command.{k}", command[k])
            if not 0.0 <= options[k] < 1.0:
                chk.fail(f"command.{k}", f"must be in [0, 1), got {options[k]}")
    if "first_swing" in command:
        v = command["first_swing"]
        if isinstance(v, bool) or v not in (1, -1):
            chk.fail("command.first_swing", f"must be 1 (left foot first) or -1 (right), got {v!r}")
        options["first_swing"] = int(v)
    robot = None
    if not recorded.is_recording(path):
        # A trace's commands are the stick through the robot's command range, read once per step time.
        for k in ("robot.step_time", "robot.density"):  # (robot.reach is never swept)
            if k in swept:
                where = "grid" if k in kw["grid"] else "random"
                chk.fail(f"{where}.{k}", "a trace file's commands depend on the robot's step time and action set "
                                         "(its command range and decision times): fix it in [robot]")
        # (the command range needs the action set alone: as for the sweep's base robot, the default or the
        # longest max_sole_distance the file sets lets hrp2 build the reach, which _check_reach has checked
        # against the shortest)
        msd = max(ROBOT_DEFAULTS["max_sole_distance"],
                  *_file_values(kw["robot"], kw["grid"], kw["random"], "max_sole_distance"))
        try:
            robot = robots.hrp2(density=kw["robot"].get("density", ROBOT_DEFAULTS["density"]),
                                reach=kw["robot"].get("reach", ROBOT_DEFAULTS["reach"]), max_sole_distance=msd,
                                step_time=kw["robot"].get("step_time", ROBOT_DEFAULTS["step_time"]))
        except ValueError as e:
            chk.fail("robot", f"the trace's robot cannot be built: {e}")
    try:
        seq = recorded.read_commands(path, robot, max_steps=MAX_NUM_STEPS + 1, **options)
    except ValueError as e:
        chk.fail("command.file", str(e))
    n = len(seq.commands)
    if n > MAX_NUM_STEPS:
        chk.fail("command.file", f"more than {MAX_NUM_STEPS} commands (ijoy_jax.limits.MAX_NUM_STEPS)")
    if "num_steps" not in kw:
        kw["num_steps"] = n
    elif kw["num_steps"] > n:
        chk.fail("sweep.num_steps", f"{kw['num_steps']} steps, but command.file holds {n} commands (one per step; "
                                    f"at most {n}, the default)")
    kw["command_file"] = seq
    kw["command"] = {}


def parse_config(text: str, source: str = "<string>") -> SweepConfig:
    """Parse and validate a sweep from TOML text (see the module docstring).

    Args:
      text: the TOML text.
      source: file name used in error messages.

    Returns:
      :class:`SweepConfig`.

    Raises:
      SweepConfigError: malformed TOML, unknown keys, wrong types, impossible
        ranges or unknown names; the message reads ``"<source>: <key>: <reason>"``.

    Example:
      >>> cfg = parse_config('[grid]\\n"robot.w" = [0.5, 1.0]\\n[sweep]\\nscenarios_per_cell = 2\\n')
      >>> cfg.num_cells, cfg.num_scenarios
      (2, 4)
    """
    chk = _Checker(source)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SweepConfigError(f"{source}: <toml>: {e}") from None
    chk.unknown("", raw, _SECTIONS)
    kw: dict[str, Any] = {"name": Path(source).stem if source != "<string>" else "sweep", "source": source,
                          "text": text}

    sweep = chk.table("sweep", raw.get("sweep", {}))
    chk.unknown("sweep.", sweep, _SWEEP_KEYS)
    for k in ("name", "description"):
        if k in sweep:
            kw[k] = chk.string(f"sweep.{k}", sweep[k])
    # The name is the default output folder results/<name>: one path component, never "." or ".." (or hidden).
    if not kw["name"].replace("-", "_").replace(".", "_").isidentifier() or kw["name"].startswith("."):
        where = "sweep.name" if "name" in sweep else "sweep.name (the file's stem, when not given)"
        chk.fail(where, f"must be letters, digits, '_', '-' or '.', not starting with '.', got {kw['name']!r}")
    if "seed" in sweep:
        kw["seed"] = chk.integer("sweep.seed", sweep["seed"], lo=0)  # < 2**63: jax.random.key's range
    if "scenarios_per_cell" in sweep:
        kw["scenarios_per_cell"] = chk.integer("sweep.scenarios_per_cell", sweep["scenarios_per_cell"], lo=1)
    if "num_steps" in sweep:
        kw["num_steps"] = chk.integer("sweep.num_steps", sweep["num_steps"], lo=1, hi=MAX_NUM_STEPS)
    if "random_samples" in sweep:
        kw["random_samples"] = chk.integer("sweep.random_samples", sweep["random_samples"], lo=0)
    if "method" in sweep:
        kw["method"] = chk.string("sweep.method", sweep["method"], METHODS)
    if "kernel" in sweep:
        kw["kernel"] = chk.string("sweep.kernel", sweep["kernel"], KERNELS)
    if "walker" in sweep:
        kw["walker"] = chk.string("sweep.walker", sweep["walker"], WALKERS)
    if "horizon" in sweep:
        kw["horizon"] = chk.integer("sweep.horizon", sweep["horizon"], lo=1, hi=_MAX_HORIZON)
    if "beam" in sweep:
        kw["beam"] = chk.integer("sweep.beam", sweep["beam"], lo=1)
    if "refine" in sweep:
        kw["refine"] = _bool(chk, "sweep.refine", sweep["refine"])
    if "discount" in sweep:
        kw["discount"] = _discount(chk, "sweep.discount", sweep["discount"])
    mjx = kw.get("walker") == "mjx"
    sim_fields = _sim_fields() if mjx else ()

    terrain = chk.table("terrain", raw.get("terrain", {}))
    chk.unknown("terrain.", terrain, (*_TERRAIN_KEYS, _RECORDING_KEY))
    folder = Path(source).parent if source != "<string>" else Path(".")
    if _RECORDING_KEY in terrain:
        fam, fields, max_count = None, (), None
        _recorded_terrain(chk, terrain, kw, folder)
    else:
        fam, fields, max_count = _generated_terrain(chk, terrain, kw)

    robot = _flatten(chk.table("robot", raw.get("robot", {})))
    chk.unknown("robot.", robot, tuple(ROBOT_DEFAULTS))
    kw["robot"] = {k: _robot_value(chk, f"robot.{k}", k, v) for k, v in robot.items()}

    command = chk.table("command", raw.get("command", {}))
    chk.unknown("command.", command, (*COMMAND_KEYS, *recorded.COMMAND_FILE_KEYS))
    if "file" in command:  # read once the grid is known (a trace's robot must not be swept)
        for k in COMMAND_KEYS:
            if k in command:
                chk.fail(f"command.{k}", "the commands come from command.file: give a file or a distribution, "
                                         "not both")
    else:
        for k in recorded.COMMAND_FILE_KEYS:
            if k in command:
                chk.fail(f"command.{k}", "only with command.file (commands from a recorded drive or a trace file)")
        cmd = {"vx": (0.25, 0.25), "vy": (0.0, 0.0), "wz": (0.0, 0.0)}
        for k, v in command.items():
            cmd[k] = chk.range(f"command.{k}", v) if isinstance(v, list) else (chk.number(f"command.{k}", v),) * 2
        kw["command"] = cmd

    sim = chk.table("sim", raw.get("sim", {}))
    if sim and not mjx:
        chk.fail(f"sim.{next(iter(sim))}", 'physics needs [sweep] walker = "mjx" (the perfect robot has none)')
    chk.unknown("sim.", sim, sim_fields)
    kw["sim"] = {k: (tuple(_sim_value(chk, f"sim.{k}[{i}]", k, x) for i, x in enumerate(chk.range(f"sim.{k}", v)))
                     if isinstance(v, list) else (_sim_value(chk, f"sim.{k}", k, v),) * 2) for k, v in sim.items()}

    def param(dotted: str, key: str, value):
        """Validate one swept value of the parameter ``dotted`` ("robot.x", "terrain.x", "sim.x" or
        "selector.x"), reported as ``key``."""
        head, _, name = dotted.partition(".")
        if head == "robot":
            return _robot_value(chk, key, name, value)
        if head == "selector":
            return _selector_value(chk, key, name, value)
        if head == "sim":
            return _sim_value(chk, key, name, value)
        return _terrain_value(chk, key, fam, name, value, max_count)

    def check_name(section: str, key: str) -> None:
        head, _, name = key.partition(".")
        if head == "sim" and not mjx:
            chk.fail(f"{section}.{key}", 'physics needs [sweep] walker = "mjx" (the perfect robot has none)')
        if head == "terrain" and fam is None:
            chk.fail(f"{section}.{key}", "terrain parameters need a generated terrain ([terrain] family), not "
                                         "[terrain] recording")
        known = (tuple(f"robot.{k}" for k in ROBOT_DEFAULTS) + tuple(f"terrain.{k}" for k in fields)
                 + tuple(f"sim.{k}" for k in sim_fields) + tuple(f"selector.{k}" for k in SELECTOR_DEFAULTS))
        if key not in known:
            chk.fail(f"{section}.{key}", f"unknown parameter; known: {', '.join(known)}")
        if head == "selector":
            if name in sweep:
                chk.fail(f"{section}.{key}", f"also set as a fixed value in [sweep] ({name}); set it in one place")
            if section == "random" and name in _SELECTOR_STATIC:
                chk.fail(f"random.{key}", f"{name} is static (one compile per value): sweep it in [grid]")
            return
        fixed = {"robot": kw["robot"], "terrain": kw["terrain_params"], "sim": kw["sim"]}[head]
        if name in fixed:
            chk.fail(f"{section}.{key}", f"also set as a fixed value in [{head}]; set it in one place")
        if mjx and key in ("robot.step_time", "robot.foot_length", "robot.foot_width"):
            what = ("the simulated controller's step time (WalkConfig.step_time)" if name == "step_time" else
                    "the simulated foot's size (the MuJoCo model's, one per sweep)")
            chk.fail(f"{section}.{key}", f'is {what} with walker = "mjx": fix it in [robot], do not sweep it')

    grid = _flatten(chk.table("grid", raw.get("grid", {})))
    out_grid = {}
    for k, values in grid.items():
        check_name("grid", k)
        if k == "robot.reach":
            chk.fail(f"grid.{k}", _REACH_FIXED)
        if not isinstance(values, list) or not values:
            chk.fail(f"grid.{k}", f"must be a non-empty list of values, got {values!r}")
        vals = tuple(param(k, f"grid.{k}[{i}]", v) for i, v in enumerate(values))
        if len(set(vals)) != len(vals):
            chk.fail(f"grid.{k}", f"repeated values in {list(vals)}")
        out_grid[k] = vals
    kw["grid"] = out_grid

    rand = _flatten(chk.table("random", raw.get("random", {})))
    out_rand = {}
    for k, rng in rand.items():
        check_name("random", k)
        if k in out_grid:
            chk.fail(f"random.{k}", "also in [grid]; sweep it in one place")
        if k == "robot.density":
            chk.fail(f"random.{k}", "density changes array shapes (one compile per value): sweep it in [grid]")
        if k == "robot.reach":
            chk.fail(f"random.{k}", _REACH_FIXED)
        if k.startswith("terrain.") and fam.rules[k.partition(".")[2]].integer:
            chk.fail(f"random.{k}", "counts are integers: sweep them in [grid]")
        lo, hi = chk.range(f"random.{k}", rng)
        out_rand[k] = (param(k, f"random.{k}[0]", lo), param(k, f"random.{k}[1]", hi))
    kw["random"] = out_rand
    if out_rand and kw.get("random_samples", 0) < 1:
        chk.fail("sweep.random_samples", "must be >= 1 when [random] is given")
    if not out_rand and kw.get("random_samples", 0) > 0:
        chk.fail("sweep.random_samples", "is set but [random] is empty")

    _check_reach(chk, kw["robot"], out_grid, out_rand)  # before a trace file's robot is built with it
    if "file" in command:
        _command_file(chk, command, kw, folder, (*out_grid, *out_rand))
    cfg = SweepConfig(**kw)
    _check_selector(chk, cfg)
    _check_size(chk, cfg)  # before cells() or scenarios() allocate anything
    if mjx:
        _check_walker(chk, cfg)
    # Cross-field checks (the family's ordered ranges) on every cell's resolved values, still before any compute.
    # The start zone must leave room for the terrain on the sweep's map (family.Family.validate).
    # Only the terrain values matter: each distinct combination is checked once, in cell order (the first
    # failing cell's combination fails first), not every cell (2e5 cells took 35 s).
    if fam is None:  # a recorded terrain: no family rules; the recorded start must fit the simulated robot
        if mjx:
            _check_recorded_start_fits(chk, cfg)
        return cfg
    swept_terrain = [k for k in (*kw["grid"], *kw["random"]) if k.startswith("terrain.")]
    combos = cells(cfg)[swept_terrain].drop_duplicates() if swept_terrain else None
    for row in ([{}] if combos is None else combos.to_dict("records")):  # records keep each column's type
        try:
            fam.validate({name: _terrain_of(cfg, row, name) for name in fields}, shape=cfg.shape,
                         resolution=cfg.resolution)
        except ParamError as e:
            chk.fail(_blame(fam, e.field, kw), e.reason)
        if mjx:
            _check_start_fits(chk, cfg, _terrain_of(cfg, row, "start_x"), _terrain_of(cfg, row, "start_y"))
    return cfg


def _sim_fields() -> tuple[str, ...]:
    """The ``sim.<field>`` names (:data:`ijoy_jax.sim.physics.FIELDS`; imported only for a ``walker = "mjx"``
    sweep, which needs MuJoCo anyway)."""
    from ijoy_jax.sim import physics

    return physics.FIELDS


def _check_walker(chk: _Checker, cfg: SweepConfig) -> None:
    """A ``walker = "mjx"`` sweep fits the simulated biped: its step time and resolution (before compute)."""
    from ijoy_jax.sim.controller import WalkConfig

    step = WalkConfig().step_time
    if abs(cfg.robot.get("step_time", ROBOT_DEFAULTS["step_time"]) - step) > 1e-6:
        chk.fail("robot.step_time", f'must be the simulated controller\'s {step} s with walker = "mjx" '
                                    f"(WalkConfig.step_time), got {cfg.robot['step_time']}")
    if cfg.resolution < SIM_MIN_RESOLUTION:
        chk.fail("terrain.resolution", f'must be >= {SIM_MIN_RESOLUTION} m with walker = "mjx" '
                                       f"(sweep.config.SIM_MIN_RESOLUTION: each sole sphere meets "
                                       f"(ceil(2 r / res) + 1)^2 height-field prisms per physics step), "
                                       f"got {cfg.resolution}")


def _check_start_fits(chk: _Checker, cfg: SweepConfig, start_x: float, start_y: float) -> None:
    """The simulated robot standing at the start point (feet side by side, the step-in-place width apart, facing
    +x) must stand on the map: MuJoCo's height field ends at its edges."""
    length = cfg.robot.get("foot_length", ROBOT_DEFAULTS["foot_length"])
    width = cfg.robot.get("foot_width", ROBOT_DEFAULTS["foot_width"])
    apart = robots.HRP2_P0[1]  # the step in place, HRP-2's at every footprint and density
    ext_x, ext_y = cfg.shape[0] * cfg.resolution, cfg.shape[1] * cfg.resolution
    x, y = start_x * ext_x, start_y * ext_y
    half_x, half_y = length / 2, apart / 2 + width / 2
    if x - half_x < 0 or x + half_x > ext_x or y - half_y < 0 or y + half_y > ext_y:
        chk.fail("terrain.shape", f"the simulated robot standing at the start point ({x:.3g}, {y:.3g}) m needs "
                                  f"[{x - half_x:.3g}, {x + half_x:.3g}] x [{y - half_y:.3g}, {y + half_y:.3g}] m "
                                  f"of ground, beyond the {ext_x:.3g} x {ext_y:.3g} m map (its height field ends "
                                  f"there): a larger map or another start_x/start_y")


def _check_recorded_start_fits(chk: _Checker, cfg: SweepConfig) -> None:
    """The simulated robot standing on a recording's start feet must stand on its map (every sole corner)."""
    rec = cfg.terrain_recording
    length = cfg.robot.get("foot_length", ROBOT_DEFAULTS["foot_length"])
    width = cfg.robot.get("foot_width", ROBOT_DEFAULTS["foot_width"])
    lo = np.asarray(rec.terrain.origin, np.float64)
    hi = lo + np.asarray(cfg.shape) * cfg.resolution
    for x, y, yaw in np.asarray(rec.start, np.float64):
        c, s = math.cos(yaw), math.sin(yaw)
        for dx, dy in ((length / 2, width / 2), (length / 2, -width / 2), (-length / 2, width / 2),
                       (-length / 2, -width / 2)):
            px, py = x + c * dx - s * dy, y + s * dx + c * dy
            if not (lo[0] <= px <= hi[0] and lo[1] <= py <= hi[1]):
                chk.fail("terrain.recording", f"the simulated robot standing on the recorded start feet needs "
                                              f"ground at ({px:.3g}, {py:.3g}) m, beyond the map "
                                              f"[{lo[0]:.3g}, {hi[0]:.3g}] x [{lo[1]:.3g}, {hi[1]:.3g}] m (its "
                                              "height field ends there)")


def _blame(fam: Family, field: str, kw: dict) -> str:
    """The key of the file to name for a cross-field error of ``field``: the field itself or the other end of
    its range (``Rule.at_most``), where the file sets it (grid, random, then params); else its params key."""
    rules = fam.rules
    ends = [field, *([rules[field].at_most] if rules[field].at_most else []),
            *(n for n, r in rules.items() if r.at_most == field)]
    for f in ends:
        for s in ("grid", "random"):
            if f"terrain.{f}" in kw[s]:
                return f"{s}.terrain.{f}"
        if f in kw["terrain_params"]:
            return f"terrain.params.{f}"
    return f"terrain.params.{field}"


_MAX_HORIZON = 8
"""Longest lookahead a sweep accepts: a beam search costs (horizon - 1) x beam x N FootCost evaluations per step."""


def _bool(chk: _Checker, key: str, value) -> bool:
    if not isinstance(value, bool):
        chk.fail(key, f"must be true or false, got {type(value).__name__} {value!r}")
    return value


def _discount(chk: _Checker, key: str, value) -> float:
    v = chk.number(key, value)
    if v < 0:
        chk.fail(key, f"must be >= 0 (the weight of each later step), got {v}")
    return v


def _selector_value(chk: _Checker, key: str, name: str, value):
    """Check one value of a selector option (``name`` in :data:`SELECTOR_DEFAULTS`)."""
    if name == "horizon":
        return chk.integer(key, value, lo=1, hi=_MAX_HORIZON)
    if name == "refine":
        return _bool(chk, key, value)
    return _discount(chk, key, value)


def _selector_values(cfg: SweepConfig, name: str) -> tuple:
    """Every value the selector option ``name`` takes in the sweep (its grid values, or its fixed value)."""
    key = f"selector.{name}"
    if key in cfg.grid:
        return cfg.grid[key]
    if key in cfg.random:
        return cfg.random[key]
    return (getattr(cfg, name),)


def _check_selector(chk: _Checker, cfg: SweepConfig) -> None:
    """The selector options fit the method and the walker (before compute)."""
    horizons = _selector_values(cfg, "horizon")
    where = "grid.selector.horizon" if "selector.horizon" in cfg.grid else "sweep.horizon"
    if cfg.method != "lookahead" and max(horizons) > 1:
        chk.fail(where, f'a horizon above 1 needs [sweep] method = "lookahead", got method = {cfg.method!r}')
    if cfg.beam is not None and cfg.method != "lookahead":
        chk.fail("sweep.beam", f'the beam is an option of method = "lookahead", got method = {cfg.method!r}')
    largest = max(_file_values(cfg.robot, cfg.grid, cfg.random, "density"))
    if cfg.beam is not None and cfg.beam > len(robots.hrp2_actions(largest, reach_of(cfg))):
        chk.fail("sweep.beam", f"must be at most the action set's size, got {cfg.beam}")
    refines = _selector_values(cfg, "refine")
    if any(refines) and cfg.method == "naive":
        chk.fail("grid.selector.refine" if "selector.refine" in cfg.grid else "sweep.refine",
                 "refinement applies to the terrain-aware methods; method = \"naive\" ignores the terrain")
    if cfg.walker == "mjx" and cfg.method == "lookahead":
        chk.fail("sweep.method", 'walker = "mjx" runs the one-step selectors (exhaustive, ordered, naive), '
                 'with or without refinement')


def _file_values(robot: dict, grid: dict, rand: dict, name: str) -> tuple:
    """Every value a sweep file gives robot parameter ``name``: its ``[grid]`` values and ``[random]`` bounds, or
    else its fixed ``[robot]`` value (or default)."""
    swept = (*grid.get(f"robot.{name}", ()), *rand.get(f"robot.{name}", ()))
    return swept or (robot.get(name, ROBOT_DEFAULTS[name]),)


def reach_of(cfg: SweepConfig) -> float:
    """The sweep's ``robot.reach`` (m): HRP-2's largest forward/backward step, one per sweep (default the paper's)."""
    return float(cfg.robot.get("reach", ROBOT_DEFAULTS["reach"]))


_REACH_FIXED = ("reach shapes the action set and is fixed per sweep: set it in [robot] (one sweep per reach)")


def _check_reach(chk: _Checker, robot: dict, grid: dict, rand: dict) -> None:
    """``[robot] reach`` (with the file's fixed ``robot`` values, ``grid`` axes and ``random`` ranges): at most
    :data:`MAX_ACTIONS` per density, every action within ``max_sole_distance``."""
    if "reach" not in robot:
        return
    reach = robot["reach"]
    limit = min(_file_values(robot, grid, rand, "max_sole_distance"))
    for density in _file_values(robot, grid, rand, "density"):
        counts = robots.density_counts(density, reach)
        if math.prod(counts) > 2 * MAX_ACTIONS:  # (refused before the lattice is built: reach may be huge)
            size = f"about {math.prod(counts):.3g}"
        else:
            actions = robots.hrp2_actions(density, reach)
            size = len(actions)
            farthest = float(np.max(np.hypot(actions[:, 0], actions[:, 1])))
            if farthest > limit:
                chk.fail("robot.reach", f"{reach:g} m puts an action {farthest:.3f} m from the stance foot, beyond "
                                        f"robot.max_sole_distance = {limit:g} m: its steps would always be refused")
        if isinstance(size, str) or size > MAX_ACTIONS:
            chk.fail("robot.reach", f"{reach:g} m makes {size} actions at density {density:g}, more than "
                                    f"{MAX_ACTIONS} (ijoy_jax.limits.MAX_ACTIONS: the targets table's bound)")


def _host_memory() -> int | None:
    """This host's physical memory in bytes (None where the OS does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def table_bytes(cfg: SweepConfig, num_scenarios: int | None = None) -> int:
    """Estimated host bytes of a sweep's tables: ``num_scenarios`` (default all) rows of 8-byte columns (ids,
    every robot, terrain and command value, the metrics), times the copies a run holds at once.

    Example:
      >>> cfg = parse_config("[sweep]\\nscenarios_per_cell = 1000\\n")
      >>> 100_000 < table_bytes(cfg) < 10_000_000
      True
    """
    fam = None if cfg.family is None else generators.FAMILIES[cfg.family]
    terrain_columns = 0 if fam is None else len(fam.rules) + len(fam.metric_names)
    command_columns = 0 if cfg.command_file is not None else len(COMMAND_KEYS)
    columns = 4 + len(ROBOT_DEFAULTS) + terrain_columns + command_columns + len(SELECTOR_DEFAULTS) + len(METRICS)
    if cfg.walker == "mjx":
        columns += len(_sim_fields()) + len(PHYSICS_METRICS)
    n = cfg.num_scenarios if num_scenarios is None else num_scenarios
    return n * columns * 8 * _TABLE_COPIES


def _check_size(chk: _Checker, cfg: SweepConfig) -> None:
    """Refuse a sweep whose scenarios exceed :data:`MAX_SCENARIOS` or whose tables would not fit in memory."""
    n, cells_, per = cfg.num_scenarios, cfg.num_cells, cfg.scenarios_per_cell
    key = "grid" if cells_ > MAX_SCENARIOS else "sweep.scenarios_per_cell"
    what = f"{n:.3g} scenarios ({cells_} cells x {per} per cell)"
    if n > MAX_SCENARIOS:
        chk.fail(key, f"{what} exceed the limit of {MAX_SCENARIOS:.0e} (sweep.config.MAX_SCENARIOS; their tables "
                      f"would need ~{table_bytes(cfg) / 2**30:.3g} GiB of host memory): split the sweep")
    mem = _host_memory()
    if mem is not None and table_bytes(cfg) > HOST_MEMORY_FRACTION * mem:
        chk.fail(key, f"{what} need ~{table_bytes(cfg) / 2**30:.3g} GiB of host memory for their tables, more "
                      f"than {HOST_MEMORY_FRACTION:g} of this host's {mem / 2**30:.3g} GiB: split the sweep")


def load_config(path) -> SweepConfig:
    """Read and validate a sweep file (see :func:`parse_config`).

    Raises:
      SweepConfigError: the file cannot be read, or is malformed (file, key, reason).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise SweepConfigError(f"{p}: <file>: cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:  # a binary file named by mistake (a recording, a parquet part)
        raise SweepConfigError(f"{p}: <file>: not a TOML text file (byte {e.start} is not UTF-8)") from None
    return parse_config(text, str(p))


# --------------------------------------------------------------------------- expansion


def _terrain_of(cfg: SweepConfig, row, name: str):
    key = f"terrain.{name}"
    if key in row:
        return row[key]
    if name in cfg.terrain_params:
        return cfg.terrain_params[name]
    return getattr(cfg.params_class(), name)


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


def _draw_commands(cfg: SweepConfig, reps: int, progress: bool, stream: int = 2,
                   ranges: list | None = None) -> np.ndarray:
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
        print(f"[ijoy sweep] drawing {what}: {done}/{reps} replicates  {rate:.0f}/s  "
              f"ETA {(reps - done) / rate:.0f} s", file=sys.stderr, flush=True)

    ranges = [cfg.command[k] for k in COMMAND_KEYS] if ranges is None else ranges
    return seeding.uniform_draws([cfg.seed, stream], ranges, reps, on_block=report,
                                 on_replicate=lambda i: report(i + 1))


def scenarios(cfg: SweepConfig, max_scenarios: int | None = None, *, progress: bool = False):
    """Every scenario of the sweep with all its parameters resolved (host only, no JAX).

    Scenario ``cell * scenarios_per_cell + replicate``; its terrain key is
    ``fold_in(key(seed), replicate)`` and its command is drawn per replicate
    from ``np.random.default_rng([seed, 2, replicate])``, so replicate r is the
    same terrain and command in every cell. The ``[sim]`` ranges of a
    ``walker = "mjx"`` sweep are drawn per replicate as well, from
    ``np.random.default_rng([seed, 3, replicate])`` (paired across cells too).

    Columns: ``scenario``, ``cell``, ``replicate``, ``robot.<name>`` (all of
    :data:`ROBOT_DEFAULTS`), ``terrain.<field>`` (all of the family's
    parameters; none for a recorded terrain), ``command.vx`` (m/s), ``command.vy`` (m/s),
    ``command.wz`` (rad/s) (none when the commands come from ``[command] file``: every scenario
    takes :attr:`SweepConfig.command_steps`), ``selector.horizon``, ``selector.refine`` (int64, 0 or 1),
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
    if cfg.command_file is not None:
        cmd = np.zeros((reps, 0))  # no command columns: the file's sequence, the same for every scenario
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
    sim_fields = _sim_fields() if cfg.walker == "mjx" else ()
    command_keys = () if cfg.command_file is not None else COMMAND_KEYS
    names = ["scenario", "cell", "replicate", *(f"robot.{n}" for n in ROBOT_DEFAULTS),
             *(f"terrain.{n}" for n in fields), *(f"command.{k}" for k in command_keys),
             *(f"selector.{k}" for k in SELECTOR_DEFAULTS), *(f"sim.{k}" for k in sim_fields)]
    ints = {"scenario", "cell", "replicate", *(f"terrain.{n}" for n in fields if rules[n].integer),
            *(f"selector.{k}" for k in _SELECTOR_STATIC)}
    floats = [n for n in names if n not in ints]
    block = np.empty((len(floats), total))
    cols: dict[str, np.ndarray] = {n: block[i] for i, n in enumerate(floats)}
    cols.update({n: np.empty(total, np.int64) for n in names if n in ints})
    full, rem = divmod(total, n_rep)  # scenario s is replicate s % n_rep of cell s // n_rep

    def per_cell(out, values):
        """out[s] = values[s // n_rep]: a broadcast write per cell row (no index arrays)."""
        out[:full * n_rep].reshape(full, n_rep)[:] = values[:full, None]
        if rem:
            out[full * n_rep:] = values[full]

    def per_replicate(out, values):
        """out[s] = values[s % n_rep] (``values`` has min(n_rep, total) rows)."""
        if full:
            out[:full * n_rep].reshape(full, n_rep)[:] = values[None, :]
        out[full * n_rep:] = values[:rem]

    cols["scenario"][:] = np.arange(total, dtype=np.int64)
    per_cell(cols["cell"], c["cell"].to_numpy())  # cells() numbers its rows 0, 1, ...
    per_replicate(cols["replicate"], np.arange(reps, dtype=np.int64))
    defaults = None if cfg.params_class is None else cfg.params_class()
    fixed = {**{f"robot.{n}": cfg.robot.get(n, d) for n, d in ROBOT_DEFAULTS.items()},
             **{f"terrain.{n}": cfg.terrain_params.get(n, getattr(defaults, n)) for n in fields},
             **{f"selector.{n}": getattr(cfg, n) for n in SELECTOR_DEFAULTS}}
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
        draws = (_draw_commands(cfg, reps, progress, stream=3, ranges=[cfg.sim[k] for k in drawn])
                 if drawn else np.zeros((reps, 0)))
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
