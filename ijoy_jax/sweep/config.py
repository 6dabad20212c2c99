"""Reading a sweep file: :func:`load_config` and :func:`parse_config` check every table of it, key by key,
into a :class:`~ijoy_jax.sweep.SweepConfig` before any compute.

The schema (tables, keys, defaults and bounds) is :mod:`ijoy_jax.sweep.schema`; the checks across keys that
a parsed sweep must pass (reach, selector, simulated biped, host memory) are :mod:`ijoy_jax.sweep.fits`; the
expansion into cells and scenarios is :mod:`ijoy_jax.sweep.expansion`. A problem raises
:class:`~ijoy_jax.sweep.SweepConfigError` naming the file, the key and the reason. This module also
exports the names sweep files are described with (the schema's constants, the metrics, the expansion).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from ijoy_jax import robots
from ijoy_jax.footcost import MAX_COORDINATE
from ijoy_jax.limits import MAX_ACTIONS, MAX_DENSITY, MAX_HORIZON, MAX_MAP_CELLS, MAX_NUM_STEPS
from ijoy_jax.select import KERNELS, METHODS
from ijoy_jax.sweep import models, recorded
from ijoy_jax.sweep.columns import METRICS, PHYSICS_METRICS
from ijoy_jax.sweep.expansion import HOST_MEMORY_FRACTION, MAX_SCENARIOS, cells, scenarios, table_bytes
from ijoy_jax.sweep.fits import (
    check_reach,
    check_recorded_start_fits,
    check_selector,
    check_size,
    check_start_fits,
    check_walker,
    file_values,
)
from ijoy_jax.sweep.schema import (
    ACTION_SET_KEYS,
    COMMAND_KEYS,
    MAX_FLOAT,
    MAX_OBJECT_SLOTS,
    MIN_RESOLUTION,
    MODELS,
    ROBOT_DEFAULTS,
    SELECTOR_DEFAULTS,
    SELECTOR_STATIC,
    SIM_MIN_RESOLUTION,
    WALKERS,
    Checker,
    SweepConfig,
    SweepConfigError,
    reach_of,
    sim_field_names,
)
from ijoy_jax.terrain import generators, walk_families
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
    "MODELS",
    "ROBOT_DEFAULTS",
    "SweepConfig",
    "SweepConfigError",
    "cells",
    "load_config",
    "parse_config",
    "reach_of",
    "scenarios",
    "set_values",
    "table_bytes",
    "toml_value",
]


# Lower bounds: (bound, strict). Every robot parameter is >= 0; sizes and times > 0.
_POSITIVE = {n for n, spec in robots.SCALAR_LEAVES.items() if spec.positive} | set(ACTION_SET_KEYS)
# Largest margin the sweep accepts (m): the static footprint window grows with it.
_MAX_MARGIN = 0.5
# Longest sweep name (UTF-8 bytes): it names the output folder, and file systems hold 255 bytes per name.
_MAX_NAME_BYTES = 100
# MAX_NUM_STEPS, MAX_DENSITY, MAX_ACTIONS and MAX_MAP_CELLS are the library's (ijoy_jax.limits): a sweep file,
# the CLI, the server and the functions they call share one memory budget.

_SECTIONS = ("sweep", "robot", "terrain", "command", "grid", "random", "sim")
_SWEEP_KEYS = ("name", "description", "seed", "scenarios_per_cell", "num_steps", "method", "kernel",
               "random_samples", "walker", "model", "horizon", "beam", "refine", "discount")

_TERRAIN_KEYS = ("family", "shape", "resolution", "has_height", "max_count", "params")
_RECORDING_KEY = "recording"  # [terrain] recording: a drive recording's terrain, instead of the _TERRAIN_KEYS
_WALK_KEY = "walk"  # [terrain] walk: a walking-benchmark family's maps, with [terrain] resolution alone
_RANDOM_KEY = "random"  # [command] random: a new random command every step, instead of vx, vy, wz or file


def _flatten(table: dict, prefix: str = "") -> dict:
    """{"robot": {"w": [..]}} -> {"robot.w": [..]} (dotted TOML keys and nested tables are the same)."""
    out = {}
    for k, v in table.items():
        if isinstance(v, dict) and v:  # an empty table stays a value, refused where a number or list belongs
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _robot_value(chk: Checker, key: str, name: str, value) -> float:
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
    if name == "density" and v < robots.MIN_DENSITY:
        chk.fail(key, f"must be in [{robots.MIN_DENSITY}, {MAX_DENSITY}] (ijoy_jax.robots.MIN_DENSITY: the smallest "
                      f"action set, 10 actions, which every smaller density gives too), got {v}")
    if name == "density" and v > MAX_DENSITY:
        chk.fail(key, f"must be <= {MAX_DENSITY} (ijoy_jax.limits.MAX_DENSITY: the targets table grows as its sixth "
                      f"power), got {v}")
    return v


def _sim_value(chk: Checker, key: str, name: str, value) -> float:
    """Check one physics value (``name`` a :class:`ijoy_jax.sim.physics.Dynamics` field) against its bounds."""
    from ijoy_jax.sim import physics

    v = chk.number(key, value)
    b = physics.BOUNDS[name]
    if v < b.lo or (b.strict and v == b.lo) or v > b.hi:
        lo = f"> {b.lo:g}" if b.strict else f">= {b.lo:g}"
        chk.fail(key, f"must be {lo} and <= {b.hi:g}{' ' + b.unit if b.unit else ''} ({b.why}; "
                      f"ijoy_jax.sim.physics.BOUNDS), got {v}")
    return v


def _terrain_value(chk: Checker, key: str, fam: Family, name: str, value, max_count: int | None):
    """Check one terrain parameter value by its family's rule (:meth:`ijoy_jax.terrain.family.Family.check`)."""
    chk.int64(key, value)  # a longer integer would overflow in the float conversion
    try:
        v = fam.check(name, value, max_count=max_count, max_count_key="[terrain] max_count")
    except ParamError as e:
        chk.fail(key, e.reason)
    if math.isfinite(v) and abs(v) > MAX_FLOAT:  # the generator's parameters are float32 (inf where allowed)
        chk.fail(key, f"must be at most {MAX_FLOAT:.4g} in magnitude (float32's largest), got {value!r}")
    return v


def _generated_terrain(chk: Checker, terrain: dict, kw: dict):
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


def _walk_terrain(chk: Checker, terrain: dict, kw: dict) -> None:
    """``[terrain] walk``: a walking-benchmark family (:data:`ijoy_jax.terrain.walk_families.FAMILIES`), its
    5 m x 2 m 2.5D map at ``[terrain] resolution``, into ``kw`` (``family`` None)."""
    name = chk.string(f"terrain.{_WALK_KEY}", terrain[_WALK_KEY], tuple(walk_families.FAMILIES))
    for k in (*_TERRAIN_KEYS, _RECORDING_KEY):
        if k in terrain and k != "resolution":
            chk.fail(f"terrain.{k}", f"the terrain comes from terrain.{_WALK_KEY} (the family's own 5 m x 2 m 2.5D "
                                     "maps, one per replicate): only terrain.resolution goes with it")
    res = walk_families.RESOLUTION
    if "resolution" in terrain:
        res = chk.number("terrain.resolution", terrain["resolution"])
        if res < MIN_RESOLUTION:
            chk.fail("terrain.resolution", f"must be >= {MIN_RESOLUTION} m (sweep.config.MIN_RESOLUTION), got {res}")
    try:
        shape = walk_families.grid_shape(res)
    except ValueError as e:
        chk.fail("terrain.resolution", str(e))
    kw.update(family=None, walk=name, shape=shape, resolution=res, has_height=True, terrain_params={})


def _file_path(chk: Checker, key: str, value, folder: Path) -> Path:
    """A file named in the sweep file (a string; relative to the sweep file's folder)."""
    if not isinstance(value, str) or not value:
        chk.fail(key, f"must be a file name (a string), got {value!r}")
    path = Path(value)
    return path if path.is_absolute() else folder / path


def _recorded_terrain(chk: Checker, terrain: dict, kw: dict, folder: Path) -> None:
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


def _command_file(chk: Checker, command: dict, kw: dict, folder: Path, swept: tuple[str, ...]) -> None:
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
        # longest max_sole_distance the file sets lets hrp2 build the reach, which check_reach has checked
        # against the shortest)
        model = kw.get("model", SweepConfig.model)
        defaults = models.robot_defaults(model)
        msd = max(defaults["max_sole_distance"],
                  *file_values(kw["robot"], kw["grid"], kw["random"], "max_sole_distance", model=model))
        try:
            robot = models.build_robot(model, density=kw["robot"].get("density", defaults["density"]),
                                       reach=kw["robot"].get("reach"), max_sole_distance=msd,
                                       step_time=kw["robot"].get("step_time", defaults["step_time"]))
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
    chk = Checker(source)
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
    # The name is the default output folder results/<name>: one path component, never "." or ".." (or hidden),
    # and short enough for every file system's folder names (255 bytes) to hold it.
    where = "sweep.name" if "name" in sweep else "sweep.name (the file's stem, when not given)"
    if not kw["name"].replace("-", "_").replace(".", "_").isidentifier() or kw["name"].startswith("."):
        chk.fail(where, f"must be letters, digits, '_', '-' or '.', not starting with '.', got {kw['name']!r}")
    if len(kw["name"].encode()) > _MAX_NAME_BYTES:
        chk.fail(where, f"must be at most {_MAX_NAME_BYTES} characters (UTF-8 bytes: it names the folder "
                        f"results/<name>), got {len(kw['name'].encode())} starting {kw['name'][:24]!r}")
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
    if "model" in sweep:
        kw["model"] = chk.string("sweep.model", sweep["model"], MODELS)
    model = kw.get("model", SweepConfig.model)
    if "horizon" in sweep:
        kw["horizon"] = chk.integer("sweep.horizon", sweep["horizon"], lo=1, hi=_MAX_HORIZON)
    if "beam" in sweep:
        kw["beam"] = chk.integer("sweep.beam", sweep["beam"], lo=1)
    if "refine" in sweep:
        kw["refine"] = _bool(chk, "sweep.refine", sweep["refine"])
    if "discount" in sweep:
        kw["discount"] = _discount(chk, "sweep.discount", sweep["discount"])
    mjx = kw.get("walker") == "mjx"
    sim_fields = sim_field_names() if mjx else ()

    terrain = chk.table("terrain", raw.get("terrain", {}))
    chk.unknown("terrain.", terrain, (*_TERRAIN_KEYS, _RECORDING_KEY, _WALK_KEY))
    folder = Path(source).parent if source != "<string>" else Path(".")
    if _WALK_KEY in terrain:
        fam, fields, max_count = None, (), None
        _walk_terrain(chk, terrain, kw)
    elif _RECORDING_KEY in terrain:
        fam, fields, max_count = None, (), None
        _recorded_terrain(chk, terrain, kw, folder)
    else:
        fam, fields, max_count = _generated_terrain(chk, terrain, kw)

    robot = _flatten(chk.table("robot", raw.get("robot", {})))
    chk.unknown("robot.", robot, tuple(ROBOT_DEFAULTS))
    for k in robot:
        _model_takes(chk, f"robot.{k}", k, model)
    kw["robot"] = {k: _robot_value(chk, f"robot.{k}", k, v) for k, v in robot.items()}

    command = chk.table("command", raw.get("command", {}))
    chk.unknown("command.", command, (*COMMAND_KEYS, *recorded.COMMAND_FILE_KEYS, _RANDOM_KEY))
    if _RANDOM_KEY in command and _bool(chk, f"command.{_RANDOM_KEY}", command[_RANDOM_KEY]):
        for k in command:
            if k != _RANDOM_KEY:
                chk.fail(f"command.{k}", f"the commands are drawn every step (command.{_RANDOM_KEY} = true): give "
                                         "random, a distribution (vx, vy, wz) or a file, one of them")
        kw.update(random_commands=True, command={})
    elif "file" in command:  # read once the grid is known (a trace's robot must not be swept)
        for k in COMMAND_KEYS:
            if k in command:
                chk.fail(f"command.{k}", "the commands come from command.file: give a file or a distribution, "
                                         "not both")
    else:
        for k in recorded.COMMAND_FILE_KEYS:
            if k in command:
                chk.fail(f"command.{k}", "only with command.file (commands from a recorded drive or a trace file)")
        cmd = {"vx": (0.25, 0.25), "vy": (0.0, 0.0), "wz": (0.0, 0.0)}
        for k, v in ((k, v) for k, v in command.items() if k != _RANDOM_KEY):  # random = false: held commands
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
                                         f"[terrain] {_WALK_KEY if kw.get('walk') else _RECORDING_KEY}")
        known = (tuple(f"robot.{k}" for k in ROBOT_DEFAULTS) + tuple(f"terrain.{k}" for k in fields)
                 + tuple(f"sim.{k}" for k in sim_fields) + tuple(f"selector.{k}" for k in SELECTOR_DEFAULTS))
        if key not in known:
            chk.fail(f"{section}.{key}", f"unknown parameter; known: {', '.join(known)}")
        if head == "robot":
            _model_takes(chk, f"{section}.{key}", name, model)
        if head == "selector":
            if name in sweep:
                chk.fail(f"{section}.{key}", f"also set as a fixed value in [sweep] ({name}); set it in one place")
            if section == "random" and name in SELECTOR_STATIC:
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

    check_reach(chk, kw["robot"], out_grid, out_rand)  # before a trace file's robot is built with it (HRP-2's)
    if "file" in command:
        _command_file(chk, command, kw, folder, (*out_grid, *out_rand))
    cfg = SweepConfig(**kw)
    check_selector(chk, cfg)
    check_size(chk, cfg)  # before cells() or scenarios() allocate anything
    if mjx:
        check_walker(chk, cfg)
    # Cross-field checks (the family's ordered ranges) on every cell's resolved values, still before any compute.
    # The start zone must leave room for the terrain on the sweep's map (family.Family.validate).
    # Only the terrain values matter: each distinct combination is checked once, in cell order (the first
    # failing cell's combination fails first), not every cell (2e5 cells took 35 s).
    if cfg.walk is not None:  # a walk family: its own maps; the simulated robot stands at its start
        if mjx:
            ext = [n * cfg.resolution for n in cfg.shape]
            check_start_fits(chk, cfg, walk_families.START[0] / ext[0], walk_families.START[1] / ext[1])
        return cfg
    if fam is None:  # a recorded terrain: no family rules; the recorded start must fit the simulated robot
        if mjx:
            check_recorded_start_fits(chk, cfg)
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
            check_start_fits(chk, cfg, _terrain_of(cfg, row, "start_x"), _terrain_of(cfg, row, "start_y"))
    return cfg


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


_MAX_HORIZON = MAX_HORIZON
"""Longest lookahead a sweep accepts, the library's: a beam search costs (horizon - 1) x beam x N FootCost
evaluations per step."""


def _bool(chk: Checker, key: str, value) -> bool:
    if not isinstance(value, bool):
        chk.fail(key, f"must be true or false, got {type(value).__name__} {value!r}")
    return value


def _discount(chk: Checker, key: str, value) -> float:
    v = chk.number(key, value)
    if v < 0:
        chk.fail(key, f"must be >= 0 (the weight of each later step), got {v}")
    return v


def _selector_value(chk: Checker, key: str, name: str, value):
    """Check one value of a selector option (``name`` in :data:`SELECTOR_DEFAULTS`)."""
    if name == "horizon":
        return chk.integer(key, value, lo=1, hi=_MAX_HORIZON)
    if name == "refine":
        return _bool(chk, key, value)
    return _discount(chk, key, value)


_REACH_FIXED = ("reach shapes the action set and is fixed per sweep: set it in [robot] (one sweep per reach)")


def _model_takes(chk: Checker, key: str, name: str, model: str) -> None:
    """Refuse a robot parameter ``name`` (as in ROBOT_DEFAULTS) that the sweep's ``model`` does not take."""
    if name not in models.robot_keys(model):
        chk.fail(key, f"{name} is an option of HRP-2's action set (robots.hrp2({name}=...)), not the G1's: "
                      f'[sweep] model = "{model}" walks robots.g1, whose lattice spans the paper\'s '
                      f"{robots.PAPER_REACH} m steps; leave it out, or use model = \"biped\"")


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



def _terrain_of(cfg: SweepConfig, row, name: str):
    key = f"terrain.{name}"
    if key in row:
        return row[key]
    if name in cfg.terrain_params:
        return cfg.terrain_params[name]
    return getattr(cfg.params_class(), name)



_TABLE_LINE = re.compile(r"^\s*\[\s*([A-Za-z0-9_.-]+)\s*\]\s*(#.*)?$")


def toml_value(value, key: str = "value") -> str:
    """One bool, int, float or string as a TOML value (a string as a basic string that reads back as itself,
    whatever its characters); ``key`` names the value in the ValueError any other type raises."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value) if isinstance(value, int) or math.isfinite(value) else str(value)
    if isinstance(value, str):
        # a TOML basic string: JSON's escapes, non-ASCII as itself (JSON's \\u escapes of surrogates are not TOML's),
        # DEL escaped (a control character TOML refuses literally)
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    raise ValueError(f"{key}: a sweep file value must be a bool, int, float or string, got {value!r}")


def set_values(text: str, values) -> str:
    """A sweep file's text with the given values set: ``{"table.key": value}``, e.g. ``{"sweep.num_steps": 6,
    "robot.metrics.support_limit": 0.003}`` (``key`` may be dotted within ``[table]``).

    Each key's line in its table (``key = ...`` on one line) is replaced, or the key is added under the table's
    header, the table added at the end when the text has none; the rest of the text (comments included) stays
    as it is, so the text saved with a run's results says what ran. The values are checked when the text is
    parsed (:func:`parse_config`), not here.

    Raises:
      ValueError: a key without a table, a value that is not a bool, int, float or string, or a key whose
        line this cannot edit (a value spanning lines, or written as a nested table).

    Example:
      >>> text = set_values("[sweep]\\nnum_steps = 30  # steps\\n", {"sweep.num_steps": 6, "robot.margin": 0.03})
      >>> cfg = parse_config(text)
      >>> cfg.num_steps, cfg.robot["margin"]
      (6, 0.03)
    """
    lines = text.splitlines()
    for dotted, value in values.items():
        table, _, key = str(dotted).partition(".")
        if not table or not key:
            raise ValueError(f"{dotted!r}: name a table and a key, as 'sweep.num_steps'")
        line = f"{key} = {toml_value(value, dotted)}"
        key_re = re.compile(rf"^\s*({re.escape(key)}|\"{re.escape(key)}\")\s*=")
        current, header, found = None, None, None
        for i, text_line in enumerate(lines):
            m = _TABLE_LINE.match(text_line)
            if m:
                current = m.group(1)
                header = i if current == table else header
            elif current == table and key_re.match(text_line):
                found = i
        if found is not None:
            lines[found] = line
        elif header is not None:
            lines.insert(header + 1, line)
        else:
            lines += ["", f"[{table}]", line]
        try:
            got = _flatten(tomllib.loads("\n".join(lines)).get(table, {})).get(key)
        except tomllib.TOMLDecodeError as e:
            raise ValueError(f"{dotted}: cannot set it in this text ({e})") from None
        if got != value:
            raise ValueError(f"{dotted}: cannot set it in this text (a value spanning lines, or a nested table)")
    return "\n".join(lines) + "\n"
