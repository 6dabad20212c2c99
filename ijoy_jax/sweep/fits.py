"""Whether a sweep fits what runs it: checks across a file's keys, made once its values are read.

The action set (``robot.reach`` against the action count and ``max_sole_distance``), the selector (horizon,
beam and refinement against the method), the simulated biped of a ``walker = "mjx"`` sweep (its step time,
the map's resolution, a start that stands on the map) and this host's memory (the scenario tables'
:func:`~ijoy_jax.sweep.table_bytes`). Each refuses through the file's :class:`~ijoy_jax.sweep.schema.Checker`
(a :class:`~ijoy_jax.sweep.SweepConfigError` naming the file, the key and the reason), before any compute;
:func:`ijoy_jax.sweep.parse_config` runs them.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import TYPE_CHECKING

import numpy as np

from ijoy_jax import robots
from ijoy_jax.limits import MAX_ACTIONS
from ijoy_jax.sweep import models
from ijoy_jax.sweep.expansion import HOST_MEMORY_FRACTION, MAX_SCENARIOS, table_bytes
from ijoy_jax.sweep.schema import SIM_MIN_RESOLUTION, Checker, SweepConfig, reach_of

if TYPE_CHECKING:  # the simulator (MuJoCo) loads only for a walker = "mjx" sweep
    from ijoy_jax.sim.controller import WalkConfig

__all__ = [
    "MIN_STEP_TICKS",
    "check_reach",
    "check_recorded_start_fits",
    "check_selector",
    "check_size",
    "check_start_fits",
    "check_walker",
    "file_values",
    "walk_config",
]

MIN_STEP_TICKS = 20
"""The fewest control periods (of 10 ms) a simulated step may last with ``walker = "mjx"``: double support,
lift-off, swing and landing each take a few (``WalkConfig``'s fractions of the step)."""


def walk_config(cfg: SweepConfig) -> WalkConfig:
    """The :class:`~ijoy_jax.sim.controller.WalkConfig` of a ``walker = "mjx"`` sweep: the model's own
    (:func:`ijoy_jax.sim.bodies.walk_defaults`) with the step time of ``[robot] step_time`` where the file fixes
    it (one value per sweep: the step's length in control ticks is a static shape)."""
    from ijoy_jax.sim import bodies, controller
    from ijoy_jax.sim.model import biped_params

    walk = controller.WalkConfig(**bodies.walk_defaults(biped_params(model=cfg.model)))
    if "step_time" in cfg.robot:
        walk = dataclasses.replace(walk, step_time=float(cfg.robot["step_time"]))
    return walk


def file_values(robot: dict, grid: dict, rand: dict, name: str, *, model: str = "biped") -> tuple:
    """Every value a sweep file gives robot parameter ``name``: its ``[grid]`` values and ``[random]`` bounds, or
    else its fixed ``[robot]`` value (or the ``model``'s default, :func:`ijoy_jax.sweep.models.robot_defaults`)."""
    swept = (*grid.get(f"robot.{name}", ()), *rand.get(f"robot.{name}", ()))
    return swept or (robot.get(name, models.robot_defaults(model)[name]),)


def check_reach(chk: Checker, robot: dict, grid: dict, rand: dict) -> None:
    """``[robot] reach`` (with the file's fixed ``robot`` values, ``grid`` axes and ``random`` ranges): at most
    :data:`MAX_ACTIONS` per density, every action within ``max_sole_distance``. Only HRP-2 takes a reach (the
    G1 refuses the key as it is read)."""
    if "reach" not in robot:
        return
    reach = robot["reach"]
    limit = min(file_values(robot, grid, rand, "max_sole_distance"))
    for density in file_values(robot, grid, rand, "density"):
        counts = robots.density_counts(density, reach)
        if math.prod(counts) > 2 * MAX_ACTIONS:  # (refused before the lattice is built: reach may be huge)
            size = f"about {math.prod(counts):.3g}"
        else:
            actions = models.actions("biped", density, reach)
            size = len(actions)
            farthest = float(np.max(np.hypot(actions[:, 0], actions[:, 1])))
            if farthest > limit:
                chk.fail(
                    "robot.reach",
                    f"{reach:g} m puts an action {farthest:.3f} m from the stance foot, beyond "
                    f"robot.max_sole_distance = {limit:g} m: its steps would always be refused",
                )
        if isinstance(size, str) or size > MAX_ACTIONS:
            chk.fail(
                "robot.reach",
                f"{reach:g} m makes {size} actions at density {density:g}, more than "
                f"{MAX_ACTIONS} (ijoy_jax.limits.MAX_ACTIONS: the targets table's bound)",
            )


def _selector_values(cfg: SweepConfig, name: str) -> tuple:
    """Every value the selector option ``name`` takes in the sweep (its grid values, or its fixed value)."""
    key = f"selector.{name}"
    if key in cfg.grid:
        return cfg.grid[key]
    if key in cfg.random:
        return cfg.random[key]
    return (getattr(cfg, name),)


def check_selector(chk: Checker, cfg: SweepConfig) -> None:
    """The selector options fit the method and the walker (before compute)."""
    horizons = _selector_values(cfg, "horizon")
    where = "grid.selector.horizon" if "selector.horizon" in cfg.grid else "sweep.horizon"
    if cfg.method != "lookahead" and max(horizons) > 1:
        chk.fail(where, f'a horizon above 1 needs [sweep] method = "lookahead", got method = {cfg.method!r}')
    if cfg.beam is not None and cfg.method != "lookahead":
        chk.fail("sweep.beam", f'the beam is an option of method = "lookahead", got method = {cfg.method!r}')
    largest = max(file_values(cfg.robot, cfg.grid, cfg.random, "density", model=cfg.model))
    if cfg.beam is not None and cfg.beam > len(models.actions(cfg.model, largest, reach_of(cfg))):
        chk.fail("sweep.beam", f"must be at most the action set's size, got {cfg.beam}")
    refines = _selector_values(cfg, "refine")
    if any(refines) and cfg.method == "naive":
        chk.fail(
            "grid.selector.refine" if "selector.refine" in cfg.grid else "sweep.refine",
            'refinement applies to the terrain-aware methods; method = "naive" ignores the terrain',
        )
    if cfg.walker == "mjx" and cfg.method == "lookahead":
        chk.fail(
            "sweep.method",
            'walker = "mjx" runs the one-step selectors (exhaustive, ordered, naive), with or without refinement',
        )


def check_walker(chk: Checker, cfg: SweepConfig) -> None:
    """A ``walker = "mjx"`` sweep fits the simulated robot: its step time (a fixed ``[robot] step_time`` is the
    controller's too: :func:`walk_config`), its feet (the G1's are its MJCF's) and the resolution (before
    compute)."""
    if "step_time" in cfg.robot:
        control_dt = walk_config(cfg).control_dt
        ticks = cfg.robot["step_time"] / control_dt
        if abs(ticks - round(ticks)) > 1e-6 or round(ticks) < MIN_STEP_TICKS:
            chk.fail(
                "robot.step_time",
                f'with walker = "mjx" must be a whole number of the controller\'s {control_dt} s periods, at '
                f"least {MIN_STEP_TICKS} (WalkConfig.step_time), got {cfg.robot['step_time']}",
            )
    defaults = models.robot_defaults(cfg.model)
    if cfg.model == "g1":
        for k in ("foot_length", "foot_width"):
            if k in cfg.robot and abs(cfg.robot[k] - defaults[k]) > 1e-6:
                chk.fail(f"robot.{k}", f'must be the G1\'s {defaults[k]} m with model = "g1" and walker = "mjx" '
                                       f"(the simulated G1 stands on its MJCF's foot boxes), got {cfg.robot[k]}")
    if cfg.resolution < SIM_MIN_RESOLUTION:
        chk.fail(
            "terrain.resolution",
            f'must be >= {SIM_MIN_RESOLUTION} m with walker = "mjx" '
            f"(sweep.config.SIM_MIN_RESOLUTION: each sole sphere meets "
            f"(ceil(2 r / res) + 1)^2 height-field prisms per physics step), "
            f"got {cfg.resolution}",
        )


def check_start_fits(chk: Checker, cfg: SweepConfig, start_x: float, start_y: float) -> None:
    """The simulated robot standing at the start point (feet side by side, the step-in-place width apart, facing
    +x) must stand on the map: MuJoCo's height field ends at its edges."""
    defaults = models.robot_defaults(cfg.model)
    length = cfg.robot.get("foot_length", defaults["foot_length"])
    width = cfg.robot.get("foot_width", defaults["foot_width"])
    apart = models.step_in_place(cfg.model)  # the model's step in place, at every footprint and density
    ext_x, ext_y = cfg.shape[0] * cfg.resolution, cfg.shape[1] * cfg.resolution
    x, y = start_x * ext_x, start_y * ext_y
    half_x, half_y = length / 2, apart / 2 + width / 2
    if x - half_x < 0 or x + half_x > ext_x or y - half_y < 0 or y + half_y > ext_y:
        chk.fail(
            "terrain.shape",
            f"the simulated robot standing at the start point ({x:.3g}, {y:.3g}) m needs "
            f"[{x - half_x:.3g}, {x + half_x:.3g}] x [{y - half_y:.3g}, {y + half_y:.3g}] m "
            f"of ground, beyond the {ext_x:.3g} x {ext_y:.3g} m map (its height field ends "
            f"there): a larger map or another start_x/start_y",
        )


def check_recorded_start_fits(chk: Checker, cfg: SweepConfig) -> None:
    """The simulated robot standing on a recording's start feet must stand on its map (every sole corner)."""
    rec = cfg.terrain_recording
    defaults = models.robot_defaults(cfg.model)
    length = cfg.robot.get("foot_length", defaults["foot_length"])
    width = cfg.robot.get("foot_width", defaults["foot_width"])
    lo = np.asarray(rec.terrain.origin, np.float64)
    hi = lo + np.asarray(cfg.shape) * cfg.resolution
    for x, y, yaw in np.asarray(rec.start, np.float64):
        c, s = math.cos(yaw), math.sin(yaw)
        for dx, dy in (
            (length / 2, width / 2),
            (length / 2, -width / 2),
            (-length / 2, width / 2),
            (-length / 2, -width / 2),
        ):
            px, py = x + c * dx - s * dy, y + s * dx + c * dy
            if not (lo[0] <= px <= hi[0] and lo[1] <= py <= hi[1]):
                chk.fail(
                    "terrain.recording",
                    f"the simulated robot standing on the recorded start feet needs "
                    f"ground at ({px:.3g}, {py:.3g}) m, beyond the map "
                    f"[{lo[0]:.3g}, {hi[0]:.3g}] x [{lo[1]:.3g}, {hi[1]:.3g}] m (its "
                    "height field ends there)",
                )


def _host_memory() -> int | None:
    """This host's physical memory in bytes (None where the OS does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def check_size(chk: Checker, cfg: SweepConfig) -> None:
    """Refuse a sweep whose scenarios exceed :data:`MAX_SCENARIOS` or whose tables would not fit in memory."""
    n, cells_, per = cfg.num_scenarios, cfg.num_cells, cfg.scenarios_per_cell
    key = "grid" if cells_ > MAX_SCENARIOS else "sweep.scenarios_per_cell"
    what = f"{n:.3g} scenarios ({cells_} cells x {per} per cell)"
    if n > MAX_SCENARIOS:
        chk.fail(
            key,
            f"{what} exceed the limit of {MAX_SCENARIOS:.0e} (sweep.config.MAX_SCENARIOS; their tables "
            f"would need ~{table_bytes(cfg) / 2**30:.3g} GiB of host memory): split the sweep",
        )
    mem = _host_memory()
    if mem is not None and table_bytes(cfg) > HOST_MEMORY_FRACTION * mem:
        chk.fail(
            key,
            f"{what} need ~{table_bytes(cfg) / 2**30:.3g} GiB of host memory for their tables, more "
            f"than {HOST_MEMORY_FRACTION:g} of this host's {mem / 2**30:.3g} GiB: split the sweep",
        )
