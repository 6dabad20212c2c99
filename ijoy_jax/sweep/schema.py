"""What a sweep file holds: its tables and keys, their defaults and bounds, and the validated :class:`SweepConfig`.

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
    model = "biped"               # the robot: "biped" (HRP-2; in MJX the project's biped) or "g1" (the Unitree G1)
    horizon = 1                   # method = "lookahead": steps scored per decision (1: the one-step selector)
    beam = 16                     # method = "lookahead", horizons >= 3: sequences kept per level (omit: exact)
    refine = false                # refine each step in continuous (dx, dy, dtheta) (ijoy_jax.refine)
    discount = 1.0                # the lookahead's discount gamma

    [robot]                       # fixed robot values (the model's defaults otherwise)
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
    # or a walking-benchmark family (ijoy_jax.terrain.walk_families.FAMILIES), a map per replicate:
    # walk = "stones"             # with resolution (default 0.02); the 5 m x 2 m map, start (0.5, 1.0) m

    [command]                     # joystick command per scenario: a number or [lo, hi] uniform
    vx = 0.25                     # [m/s] forward, in the stance foot's frame
    vy = [-0.05, 0.05]            # [m/s] left
    wz = 0.0                      # [rad/s] counter-clockwise
    # or, instead of vx, vy and wz, a person's commands, one per step (the same for every scenario):
    # file = "drive.mcap"         # a drive recording (ijoy drive --record), or a trace file "drive.csv"
    # first_swing = 1             # +1 the left foot first (default: the recording's; +1 for a trace)
    # deadzone = 0.1              # trace files only: the stick's dead zone
    # decide_at = 0.0             # trace files only: the fraction of a step at which the stick is read
    # or, instead of vx, vy and wz, a new random command every step:
    # random = true               # uniform over the action set's range (ijoy_jax.robots.command_range)

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
one per sweep; ``reach = 0.30`` for stairs; ``model = "biped"`` only),
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

The simulated walker (``walker = "mjx"``) walks the MJX robot of ``[sweep] model``
(:func:`ijoy_jax.sim.walker.rollout_batch`) in place of the perfect robot: the same
scenarios plus the per-scenario physics metrics (:data:`ijoy_jax.sweep.PHYSICS_METRICS`).
It runs the one-step selectors (``exhaustive``, ``ordered``, ``naive``), refined or not
(``refine``), not the lookahead.
Its body is static, so the sweep must fit it, checked before compute: the step time
is the controller's (``robot.step_time``: 0.8 s, the G1's 0.5 s, or a value fixed in ``[robot]``, a whole
number of 10 ms control periods; not swept), the footprint is the
physical foot's (``robot.foot_length``/``foot_width`` fixed in ``[robot]``, not
swept; the G1's own, its MJCF's, not changed), the map's cells are at least
:data:`SIM_MIN_RESOLUTION` wide, and the robot standing at the start zone's centre
stands on the map.

Commands and terrain from files (:mod:`ijoy_jax.sweep.recorded`, paths relative to the sweep
file): ``[command] file`` replays a recorded drive's commands (or a trace file's) step by step,
``sweep.num_steps`` defaulting to their number; ``[terrain] recording`` walks every scenario on a
recording's map from its start feet (no ``terrain.*`` parameters then; with the perfect robot every
replicate is the same walk, so ``scenarios_per_cell = 1``). ``ijoy drive --replay REC --export-sweep
OUT.toml`` writes such a file for a recorded drive.

The walking benchmark's terrains and commands (``ijoy bench walk`` runs its families as the sweep files of
``sweeps/walk/``): ``[terrain] walk = "<name>"`` gives replicate ``r`` the map
``walk_families.FAMILIES[name].one(fold_in(key(seed), r))`` (its parameters drawn from the family's
ranges, on the family's 5 m x 2 m map at ``[terrain] resolution``, 2.5D, the robot standing at
:data:`ijoy_jax.terrain.walk_families.START`; no ``terrain.*`` parameters); ``[command] random = true``
gives replicate ``r`` a new command every step, uniform over the action set's range
(:func:`ijoy_jax.robots.command_range` of the scenario's robot), from
``np.random.default_rng([seed, 2, r]).random(3 * num_steps)`` (step by step, vx, vy, wz), the same in
every cell. A walk sweep's results add :data:`ijoy_jax.sweep.WALK_METRICS` (steps made, progress along +x,
and with ``walker = "mjx"`` the touch-down figures of the steps made).

The robot (``[sweep] model``, one per sweep; :mod:`ijoy_jax.sweep.models`): ``"biped"`` (the default) walks
HRP-2's selector (:func:`ijoy_jax.robots.hrp2`) and, with ``walker = "mjx"``, the project's HRP-2-like biped;
``"g1"`` the Unitree G1's (:func:`ijoy_jax.robots.g1`) and Menagerie's G1 in MJX (the ``robots`` extra). The
``[robot]`` keys and ``robot.<name>`` parameters are the same for both, their defaults the model's
(:func:`ijoy_jax.sweep.models.robot_defaults`: the G1's 18 x 6 cm foot, its sole limits), except ``reach``,
an option of HRP-2's action set the G1 refuses (its lattice spans the paper's 0.20 m steps); with ``walker =
"mjx"`` the G1's footprint is its MJCF's feet, refused if changed. The model is the file's text (saved with the
results as ``sweep.toml``) and the ``model`` of the folder's ``manifest.json``.

A *cell* is one combination of grid values (times one random sample); each cell
runs ``scenarios_per_cell`` scenarios, replicate ``r`` of every cell on the same
terrain (seed ``r``) with the same command draw: paired comparisons across cells.

Everything is checked by :func:`ijoy_jax.sweep.load_config` before any compute; a problem
raises :class:`SweepConfigError` naming the file, the key and the reason.
Numbers must be finite and within float32's range (the robot, the terrain's
parameters and the commands are float32 on the device), integers within TOML's
64 bits; the sizes that set memory or static shapes have documented bounds:
:data:`~ijoy_jax.limits.MAX_NUM_STEPS`, :data:`~ijoy_jax.limits.MAX_DENSITY`,
:data:`~ijoy_jax.limits.MAX_ACTIONS`, :data:`MIN_RESOLUTION`, :data:`~ijoy_jax.limits.MAX_MAP_CELLS`,
:data:`MAX_OBJECT_SLOTS`, a map within
:data:`~ijoy_jax.footcost.MAX_COORDINATE`, foot sizes within
:data:`~ijoy_jax.robots.MAX_SIZE`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

from ijoy_jax import robots
from ijoy_jax.sweep import recorded
from ijoy_jax.terrain import generators

__all__ = [
    "ACTION_SET_KEYS",
    "COMMAND_KEYS",
    "MAX_FLOAT",
    "MAX_OBJECT_SLOTS",
    "MIN_RESOLUTION",
    "MODELS",
    "ROBOT_DEFAULTS",
    "SELECTOR_DEFAULTS",
    "SELECTOR_STATIC",
    "SIM_MIN_RESOLUTION",
    "WALKERS",
    "Checker",
    "SweepConfig",
    "SweepConfigError",
    "reach_of",
    "sim_field_names",
]


def _robot_defaults() -> dict[str, float]:
    d = robots.hrp2_defaults()  # the one source of HRP-2's numbers; order: body and selector, the action set, metrics
    body = {k: v for k, v in d.items() if k not in ACTION_SET_KEYS and not k.startswith("metrics.")}
    return {**body, **{k: d[k] for k in ACTION_SET_KEYS}, **{k: v for k, v in d.items() if k.startswith("metrics.")}}


ACTION_SET_KEYS = ("density", "reach")
"""The robot keys that shape HRP-2's action set (:func:`ijoy_jax.robots.hrp2`'s arguments, not leaves of the
Robot): density is a compile group of its own; reach is one per sweep."""


ROBOT_DEFAULTS: Mapping[str, float] = MappingProxyType(_robot_defaults())
"""Every sweepable robot parameter and its default (m, s, rad, cost units): HRP-2's, the ``"biped"`` model's
(each model's: :func:`ijoy_jax.sweep.models.robot_defaults`)."""

MODELS = robots.MODELS
"""``[sweep] model``: the robot the sweep walks, named as :data:`ijoy_jax.sim.model.MODELS` names the simulated
ones: ``"biped"``, HRP-2 (the project's HRP-2-like biped in MJX), or ``"g1"``, the Unitree G1
(:mod:`ijoy_jax.sweep.models`)."""

MAX_FLOAT = float(np.finfo(np.float32).max)
"""Largest magnitude of any number in a sweep file (a float32 robot leaf or command; beyond it float32 holds
inf)."""
# TOML's integers are 64-bit (tomllib reads longer ones): a seed or count beyond is refused, not overflowed later.
_MAX_INT = 2**63 - 1
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

SELECTOR_DEFAULTS: Mapping[str, float] = MappingProxyType({"horizon": 1, "refine": False, "discount": 1.0})
"""The selector options a sweep may vary (``selector.<name>``; fixed values: the ``[sweep]`` keys of the same
name) and their defaults: the lookahead's horizon (static, int >= 1), refinement (static, bool) and discount."""

SELECTOR_STATIC = ("horizon", "refine")
"""The selector options that change shapes or the program: swept in ``[grid]`` only, one compile per value."""


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
      model: the robot, one of :data:`MODELS` (static): its selector's robot and, with ``walker = "mjx"``, the
        simulated one (:mod:`ijoy_jax.sweep.models`).
      horizon, refine, discount: the selector's options (:data:`SELECTOR_DEFAULTS`), unless swept as
        ``selector.<name>``; beam: the lookahead's beam for horizons >= 3 (None: exact).
      family: terrain family name (None: the terrain of ``terrain_recording`` or of ``walk``); shape (nx, ny) cells;
        resolution (m); has_height; max_count (static object slots, None: the family's default).
      robot: fixed robot values, ``{name: float}`` (names as in :data:`ROBOT_DEFAULTS`; the model's,
        :func:`ijoy_jax.sweep.models.robot_keys`).
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
      walk: the walking-benchmark family of ``[terrain] walk``
        (:data:`ijoy_jax.terrain.walk_families.FAMILIES`), or None.
      random_commands: ``[command] random``: a new command every step, uniform over the action set's range
        (``command`` is {} then).
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
    model: str = "biped"
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
        default_factory=lambda: {"vx": (0.25, 0.25), "vy": (0.0, 0.0), "wz": (0.0, 0.0)}
    )
    grid: Mapping[str, tuple] = dataclasses.field(default_factory=dict)
    random: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    sim: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    command_file: recorded.CommandSequence | None = dataclasses.field(default=None, compare=False)
    terrain_recording: recorded.RecordedTerrain | None = dataclasses.field(default=None, compare=False)
    walk: str | None = None
    random_commands: bool = False
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
        None: each scenario holds its own command (``command.vx``, ``command.vy``, ``command.wz`` columns, or
        with ``[command] random`` its own draw per step, no columns)."""
        if self.command_file is None:
            return None
        return self.command_file.commands[: self.num_steps]

    @property
    def command_columns(self) -> tuple[str, ...]:
        """The components the scenario table holds per scenario (``command.<k>`` columns): :data:`COMMAND_KEYS`,
        or () when the commands come from ``[command] file`` or are drawn every step (``[command] random``)."""
        return () if self.command_file is not None or self.random_commands else COMMAND_KEYS

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


class Checker:
    """Checks the values of one sweep file (``source``); :meth:`fail` raises :class:`SweepConfigError` reading
    ``"<source>: <key>: <reason>"``."""

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
        if abs(value) > MAX_FLOAT:
            self.fail(
                key,
                f"must be at most {MAX_FLOAT:.4g} in magnitude (float32's largest; the robot and the "
                f"commands are float32), got {value!r}",
            )
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


def reach_of(cfg: SweepConfig) -> float:
    """The sweep's ``robot.reach`` (m): HRP-2's largest forward/backward step, one per sweep (default the paper's,
    the G1's always)."""
    return float(cfg.robot.get("reach", ROBOT_DEFAULTS["reach"]))


def sim_field_names() -> tuple[str, ...]:
    """The ``sim.<field>`` names (:data:`ijoy_jax.sim.physics.FIELDS`; imported only for a ``walker = "mjx"``
    sweep, which needs MuJoCo anyway)."""
    from ijoy_jax.sim import physics

    return physics.FIELDS
