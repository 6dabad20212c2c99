"""Walking benchmark per terrain family: ``ijoy bench walk``, the perfect robot next to the MJX biped.

The benchmark is a set of sweep files, ``<family>_<commands>.toml`` (:data:`SWEEPS`: shipped with the package, a
source checkout's ``sweeps/walk``), one per terrain family of
:data:`ijoy_jax.terrain.walk_families.FAMILIES` and command kind (:data:`COMMANDS`), run by the sweep engine
(:func:`ijoy_jax.sweep.run`); this module runs the files asked for with each walker and summarises the sweep
results into the table of BENCHMARKS.md (:func:`markdown_table`) and a bar plot (:func:`plot`).

On one GPU (H100 or H200), the whole default run (12 families x 2 command kinds x 1024 robots x 30 steps, both
walkers)::

    ijoy bench walk --batch 1024 --steps 30 --out results/bench_walk --json out/walk.json --plot out/walk.png

(``python -m ijoy_jax.apps.cli bench walk ...`` where the ``ijoy`` script is not installed; ``--families``
takes a comma-separated subset, e.g. to split the run in two). A smoke test on a CPU (4 robots, 6 steps)::

    ijoy bench walk --quick --json /tmp/walk.json --plot /tmp/walk.png

What a file declares (sweeps/README.md has the table): HRP-2's joystick loop (margin 2 cm,
496 actions, ``method = "ordered"``) on the family's maps (``[terrain] walk``: replicate r walks its own
5 m x 2 m map of 2 cm cells drawn from the family's ranges with the key ``fold_in(key(seed), r)``, standing at
``x = 0.5 m`` on the centre line facing +x), for 30 steps, with a new random command every step inside the
action set's range (``[command] random = true``) or the held forward command (``vx`` = :data:`FORWARD` m/s; the
stairs' 0.375 m/s, their robot ``[robot] reach = 0.30``). Replicate r is the same map in both files of a
family and the same random commands in every ``random`` file. The files say ``walker = "mjx"``; the perfect
robot's run is the same file with ``walker = "perfect"`` (:func:`sweep_text`). The options of :func:`run`
(robots, steps, seed, search) are set in each file's text before it is parsed, so the text saved with each
run's results (its folder's ``sweep.toml``) is what ran.

The robot (``model``, ``ijoy bench walk --model g1``): every file walks HRP-2 (``"biped"``: its selector robot
and the project's HRP-2-like biped in MJX) unless ``model = "g1"`` sets ``[sweep] model`` in its text
(:data:`ijoy_jax.sweep.MODELS`): the Unitree G1 chooses (:func:`ijoy_jax.robots.g1`, with the files' other
``[robot]`` values) and Menagerie's G1 walks in MJX. The stairs are skipped for the G1, with the reason in
their row, the table and the printed JSON line: their robot is ``robots.hrp2(reach=0.30)``, whose 0.30 m steps
put a foot past a riser between the feet, and the G1 takes no reach (:mod:`ijoy_jax.sweep.models`: its lattice
steps at most 0.20 m, the range its legs were checked to realise, and at 0.30 m its widest step would be
0.485 m from the stance foot, beyond its 0.48 m ``max_sole_distance``), so with the paper's steps it would only
mark time before the first riser, which measures nothing. A G1 run's sweeps are named, and their results
folders, ``<file stem>_g1_<walker>``; HRP-2's keep ``<file stem>_<walker>``.

The table's numbers per (family, commands, walker) come from the sweep's per-scenario results
(:func:`summarize`): falls, stops, progress along +x and the steps made (:data:`ijoy_jax.sweep.WALK_METRICS`),
footholds on obstacles, and for the MJX biped obstacle contacts while standing and the touch-down errors of the
steps made (:data:`ijoy_jax.sweep.WALK_PHYSICS_METRICS`). Timings: each run's compile seconds from JAX's own
compile events, the rest of its wall time as run time, and physics steps (or decisions) per second of that.

Compiles. Each walker's rollout (the MJX biped's :func:`ijoy_jax.sim.walker.rollout_batch`, the perfect
robot's vmapped :func:`ijoy_jax.control.rollout`) is one program for every family and command kind of one chunk
shape and action set (the stairs' longer reach compiles once more), as before; the sweep's small programs that
draw a family's maps and summarise its rollouts compile once per family (:mod:`ijoy_jax.sweep.programs`).
"""

from __future__ import annotations

import math
import tempfile
import time
import tomllib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import ijoy_jax.sim  # noqa: F401  before mujoco: headless EGL, and mjx imported without the warp lines

# isort: split
import jax
import numpy as np

from ijoy_jax import robots, sweep
from ijoy_jax.extras import require
from ijoy_jax.jit_cache import compile_seconds
from ijoy_jax.sim import model

# The terrain families live in ijoy_jax.terrain.walk_families; the benchmark names them where it always did.
from ijoy_jax.terrain.walk_families import (  # noqa: F401
    CLUTTER,
    CLUTTER_HEIGHT,
    FAMILIES,
    IMAGE_EXPONENT,
    IMAGE_PIXELS,
    IMAGE_RMS,
    IMAGE_SCALE,
    IMAGE_WAVELENGTHS,
    PAD_FRONT,
    PLATFORM_HEIGHT_MAX,
    PLATFORM_HEIGHT_MIN,
    RESOLUTION,
    ROUGH_CORRELATION,
    ROUGH_RMS,
    SIZE,
    SLOPE_DEG,
    STAIR_COUNT,
    STAIR_FIRST,
    STAIR_FORWARD,
    STAIR_REACH,
    STAIR_RISE,
    STAIR_RUNS,
    START,
    START_RADIUS,
    STONES,
    WalkFamily,
    clutter2d,
    cross,
    downhill,
    flat_maps,
    grid_shape,
    ground_image,
    image,
    load_ground,
    platforms,
    rough,
    rough_params,
    stairs_down,
    stairs_up,
    start_zone,
    stone_row,
    stones,
    uphill,
    window_offsets,
    write_ground_png,
)

HEIGHT_RANGE = (model.BipedParams.z_lo, model.BipedParams.z_hi)
"""z_lo, z_hi (m) of the Sim's height field (the biped's defaults): every family's heights lie inside (tested)."""
FORWARD = 0.25
"""Held forward command (m/s) of the ``forward`` files: the paper's action set's fastest, 0.2 m steps of 0.8 s;
on open ground the robot reaches the far edge of the 5 m map after about 21 steps and marks time there."""
COMMANDS = ("random", "forward")
"""The command kinds, one sweep file each per family: a new random command every step, the held forward one."""
WALKERS = ("perfect", "mjx")
"""The perfect robot (``walker = "perfect"``) and the MJX biped (``walker = "mjx"``) of :mod:`ijoy_jax.sweep`."""
CHUNK = 1024
"""Rollouts per jitted call on an accelerator when ``chunk`` is not given (at most the batch; 32 on a CPU, the sweep
engine's :data:`ijoy_jax.sweep.DEFAULT_CHUNK`): a rollout holds tens of MB of selector windows, and 1024 ran
more physics steps/s than 512 (docs/benchmarks_history.md). Given, the sweep engine does not size the chunk to
the device's memory, which costs an ahead-of-time compile of each file's program."""
SWEEPS = Path(__file__).resolve().parent / "walk_sweeps"
"""The shipped sweep files: package data (``ijoy_jax/apps/walk_sweeps``, installed with the package; a source
checkout's ``sweeps/walk`` links to it), so ``ijoy bench walk`` runs from an installed package as from a
checkout; ``run(sweeps=...)`` and ``--sweeps`` take another folder."""


def family_robot(family: WalkFamily, model: str = "biped") -> robots.Robot:
    """The family's robot of ``model`` (:func:`ijoy_jax.sweep.models.build_robot`): ``robots.hrp2()``, or
    ``robots.hrp2(reach=...)`` for a family with its own reach; ``robots.g1()`` (ValueError for a family with its
    own reach: the G1 takes none)."""
    return sweep.models.build_robot(model, reach=family.reach)


def robot_label(model: str, robot: Mapping[str, float] | None = None) -> str:
    """The selector's robot of a walk sweep (its ``model`` and ``[robot]`` values) as a row names it: ``"hrp2()"``,
    ``"hrp2(reach=0.3)"`` or ``"g1()"``."""
    if model == "g1":
        return "g1()"
    return "hrp2()" if "reach" not in (robot or {}) else f"hrp2(reach={robot['reach']:g})"


def unsupported(text: str, model: str) -> str | None:
    """Why the walk sweep file of ``text`` does not run with ``model`` (None: it does): the ``[robot]`` keys it
    sets that the model does not take (:func:`ijoy_jax.sweep.models.robot_keys`; the stairs' HRP-2 ``reach``
    for the G1)."""
    robot = tomllib.loads(text).get("robot", {})
    keys = [k for k in robot if k not in sweep.models.robot_keys(model)]
    if not keys:
        return None
    args = ", ".join(f"{k}={robot[k]!r}" for k in keys)
    return (f"its robot is robots.hrp2({args}), an HRP-2 option {sweep.models.MODEL_NAMES[model]} does not take "
            f"(its steps reach {robots.PAPER_REACH:g} m at most, too short to put a foot past a riser)")


def sweep_file(family: str, commands: str, folder=None) -> Path:
    """The sweep file of a family and command kind: ``<folder>/<family>_<commands>.toml`` (default :data:`SWEEPS`)."""
    return Path(SWEEPS if folder is None else folder) / f"{family}_{commands}.toml"


def sweep_text(text: str, *, walker: str, batch: int | None = None, steps: int | None = None,
               seed: int | None = None, resolution: float | None = None, kernel: str | None = None,
               refine: bool | None = None, robot_leaves: Mapping[str, float] | None = None,
               model: str | None = None) -> str:
    """A walk sweep file's text with the benchmark's options set (:func:`ijoy_jax.sweep.set_values`): the
    ``walker``, ``batch`` (``scenarios_per_cell``), ``steps`` (``num_steps``), ``seed``, ``kernel``, ``refine``
    and ``model`` of ``[sweep]``, the map's ``resolution`` and the robot's leaves (``[robot]``, dotted names as
    ``metrics.support_limit``); None leaves the file's value. The sweep name gets ``_<walker>``, and
    ``_<model>`` before it for a model other than ``"biped"``."""
    name = tomllib.loads(text).get("sweep", {}).get("name", "walk")
    tag = "" if model in (None, "biped") else f"_{model}"
    values = {"sweep.name": f"{name}{tag}_{walker}", "sweep.walker": walker}
    for key, value in (("scenarios_per_cell", batch), ("num_steps", steps), ("seed", seed), ("kernel", kernel),
                       ("refine", refine), ("model", model)):
        if value is not None:
            values[f"sweep.{key}"] = value
    if resolution is not None:
        values["terrain.resolution"] = resolution
    values.update({f"robot.{k}": v for k, v in (robot_leaves or {}).items()})
    return sweep.set_values(text, values)


def _pooled_mean(values, weights) -> float | None:
    """Σ values x weights / Σ weights over the rows with a weight (None without any): the mean over every step
    made of a per-robot mean over its steps made."""
    w = np.asarray(weights, np.float64)
    keep = w > 0
    return float(np.sum(np.asarray(values, np.float64)[keep] * w[keep]) / w[keep].sum()) if keep.any() else None


def _mean(values) -> float | None:
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else None


def summarize(df) -> dict[str, Any]:
    """The benchmark's numbers for one walk sweep's per-scenario results (:func:`ijoy_jax.sweep.load`).

    Keys: ``robots``; ``fell`` / ``fell_pct`` (robots that fell; 0 for the perfect robot); ``stops`` /
    ``stops_pct``, robots that stopped walking before the last step without falling (no valid foothold: the
    loop stops, Algorithm 1's StopWalking); ``progress_mean_m`` / ``progress_min_m`` (``progress``: the feet's
    midpoint along +x after the last step made); ``steps_made_mean``; ``footholds_on_obstacles`` (steps made onto
    an obstacle cell, bare footprint); ``unsupported_decisions``. With the MJX biped's columns
    (:data:`ijoy_jax.sweep.WALK_PHYSICS_METRICS`) also ``obstacle_contacts`` (steps begun standing during which
    a sole or shin touched an obstacle cell) and ``robots_with_contact``; ``placement_error_mean_m``, the mean
    touch-down error over every step made by every robot; ``placement_error_p95_m`` and ``tilt_error_p95_rad``,
    the mean over robots of each robot's 95th percentile over its steps made (robots that made none left out).
    These are None for the perfect robot (not measured).
    """
    fell = df["fell"].to_numpy(bool) if "fell" in df else np.zeros(len(df), bool)
    stops = df["stopped"].to_numpy(bool) & ~fell
    progress = df["progress"].to_numpy(np.float64)
    out: dict[str, Any] = dict(
        robots=int(len(df)),
        fell=int(fell.sum()),
        fell_pct=100.0 * float(fell.mean()),
        stops=int(stops.sum()),
        stops_pct=100.0 * float(stops.mean()),
        progress_mean_m=float(progress.mean()),
        progress_min_m=float(progress.min()),
        steps_made_mean=float(df["steps_made"].mean()),
        footholds_on_obstacles=int(df["footholds_on_obstacles_made"].sum()),
        unsupported_decisions=int(df["unsupported_decisions"].sum()),
    )
    if "standing_contacts" not in df:
        out.update(obstacle_contacts=None, robots_with_contact=None, placement_error_mean_m=None,
                   placement_error_p95_m=None, tilt_error_p95_rad=None)
        return out
    contacts = df["standing_contacts"].to_numpy(np.int64)
    out.update(
        obstacle_contacts=int(contacts.sum()),
        robots_with_contact=int((contacts > 0).sum()),
        placement_error_mean_m=_pooled_mean(df["made_placement_error_mean"], df["steps_made"]),
        placement_error_p95_m=_mean(df["made_placement_error_p95"]),
        tilt_error_p95_rad=_mean(df["made_tilt_error_p95"]),
    )
    return out


def check_options(families: Sequence[str] | None, *, batch: int, steps: int, commands: Sequence[str],
                  walkers: Sequence[str], chunk: int | None, folder=None, model: str = "biped") -> list[Path]:
    """Validate :func:`run`'s own options before any compute; returns the sweep files in table order (family
    by family in the registry's order, then :data:`COMMANDS`' order). The rest is checked with each file."""
    names = list(FAMILIES) if families is None else list(families)
    unknown = [n for n in names if n not in FAMILIES]
    if unknown or not names:
        raise ValueError(f"unknown terrain families {unknown}; known: {', '.join(FAMILIES)}")
    for label, value in (("batch", batch), ("steps", steps), ("chunk", 1 if chunk is None else chunk)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{label} must be a positive int, got {value!r}")
    bad = [c for c in commands if c not in COMMANDS]
    if bad or not commands:
        raise ValueError(f"commands must be some of {COMMANDS}, got {list(commands)}")
    bad = [w for w in walkers if w not in WALKERS]
    if bad or not walkers:
        raise ValueError(f"walkers must be some of {WALKERS}, got {list(walkers)}")
    if model not in sweep.MODELS:
        raise ValueError(f"model must be one of {', '.join(sweep.MODELS)}, got {model!r}")
    files = [sweep_file(n, c, folder) for n in FAMILIES if n in names for c in COMMANDS if c in commands]
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise ValueError(f"no sweep file {missing[0]} (the walk sweeps ship with the package, in {SWEEPS}; "
                         "--sweeps names another folder of <family>_<commands>.toml files)")
    return files


def run(families: Sequence[str] | None = None, *, batch: int = 1024, steps: int = 30,
        commands: Sequence[str] = COMMANDS, walkers: Sequence[str] = WALKERS, seed: int | None = None,
        resolution: float | None = None, chunk: int | None = None, refine: bool | None = None,
        kernel: str | None = None, robot_leaves: Mapping[str, float] | None = None, model: str = "biped",
        sweeps=None, out=None, emit: Callable[[dict], None] | None = None) -> list[dict[str, Any]]:
    """Run the walk sweep files of ``families`` x ``commands`` with each walker; one record per row.

    Every file and walker is checked (:func:`ijoy_jax.sweep.parse_config` of :func:`sweep_text`) before the
    first runs.

    Args:
      families: names in :data:`FAMILIES` (None: all), in the registry's order.
      batch: robots (maps) per family and command kind (the files' ``scenarios_per_cell``); steps: steps per
        rollout (``num_steps``).
      commands: some of :data:`COMMANDS`; walkers: some of :data:`WALKERS`.
      seed, resolution, refine, kernel: the files' ``[sweep] seed`` (maps and random commands),
        ``[terrain] resolution`` (m), ``[sweep] refine`` (each lattice choice refined to a continuous
        foothold, :mod:`ijoy_jax.refine`) and ``[sweep] kernel`` ("xla", or "pallas": the fused FootCost
        kernel, for a GPU); None keeps the files' (0, 0.02, false, "xla").
      chunk: scenarios per jitted call (:func:`ijoy_jax.sweep.run`'s ``chunk_size``; None: the batch, up to
        :data:`CHUNK` on an accelerator and :data:`ijoy_jax.sweep.DEFAULT_CHUNK` on a CPU).
      robot_leaves: robot values set on every file (``[robot]``, dotted names as ``metrics.support_limit``;
        traced leaves of the choice, so they reuse the compiled programs). Recorded in each row.
      model: the robot, ``"biped"`` (HRP-2) or ``"g1"`` (the Unitree G1), :data:`ijoy_jax.sweep.MODELS`: set as
        each file's ``[sweep] model``. A file whose robot the model cannot be (the stairs' HRP-2 reach, for the
        G1) is skipped: one row per family with ``skipped``, the reason (:func:`unsupported`).
      sweeps: the folder of the sweep files (None: :data:`SWEEPS`).
      out: the folder of the sweeps' results, one subfolder ``<file stem>_<walker>`` each (a folder of the same
        run is resumed, one of another refused by the sweep engine); None: a new temporary folder.
      emit: called with each record as soon as it exists (e.g. to print JSON lines).

    Returns:
      Records (dicts) with ``name`` "walk": ``family``, ``commands``, ``walker``, ``model``, ``robot`` (as
      :func:`robot_label` names it), the numbers of
      :func:`summarize`, ``compile_s`` and ``run_s`` (compile time from JAX's compile events, run time the rest
      of the run's wall time), ``physics_steps_per_s`` (MJX: robots x (steps + the standing step) x physics
      steps per step / run time) and ``new_compiles`` (MJX rollout programs the run compiled,
      :func:`ijoy_jax.sim.walker.compiled_programs`), or ``decisions_per_s`` (perfect), ``compiles`` (the
      sweep's chunk programs traced by the run), the ``sweep`` file, its results folder ``results`` and the
      setup; and a last record ``name`` "walk_compiles" with the totals (``mjx_programs``: MJX rollout programs
      compiled); a skipped family's record has ``name`` "walk", ``family``, ``model`` and ``skipped``.
    """
    from ijoy_jax.sim import walker as W

    files = check_options(families, batch=batch, steps=steps, commands=commands, walkers=walkers, chunk=chunk,
                          folder=sweeps, model=model)
    options = dict(batch=batch, steps=steps, seed=seed, resolution=resolution, kernel=kernel, refine=refine,
                   robot_leaves=robot_leaves, model=model)
    # every (file, walker, its config) parsed before the first runs: a bad option fails before any compute; a
    # family the model cannot walk gets one (file, None, why) where its rows would be
    planned: list[tuple[Path, str | None, Any]] = []
    for path in files:
        text = path.read_text(encoding="utf-8")
        why = unsupported(text, model)
        if why is not None:
            if all(p[1] is not None or _family_of(p[0]) != _family_of(path) for p in planned):
                planned.append((path, None, why))
            continue
        for w in WALKERS:
            if w in walkers:
                planned.append((path, w, sweep.parse_config(sweep_text(text, walker=w, **options), str(path))))
    if chunk is None:
        chunk = min(batch, sweep.DEFAULT_CHUNK if jax.default_backend() == "cpu" else CHUNK)
    out = Path(tempfile.mkdtemp(prefix="ijoy-bench-walk-") if out is None else out)
    emit = (lambda row: None) if emit is None else emit
    rows: list[dict[str, Any]] = []
    programs0, t_all = W.compiled_programs(), time.perf_counter()
    info = _device_info()
    tag = "" if model == "biped" else f"_{model}"
    for path, w, cfg in planned:
        if w is None:  # cfg: why the family is skipped
            rows.append(dict(name="walk", family=_family_of(path), model=model, robot=robot_label(model), skipped=cfg))
            emit(rows[-1])
            continue
        family, kind = cfg.walk, path.stem.rpartition("_")[2]
        folder = out / f"{path.stem}{tag}_{w}"
        before = W.compiled_programs()
        with compile_seconds() as compiled:
            t0 = time.perf_counter()
            stats = sweep.run(cfg, folder, chunk_size=chunk, progress=False)
            wall = time.perf_counter() - t0
        run_s = max(wall - compiled[0], 1e-9)
        fam = FAMILIES[family]
        row = dict(name="walk", family=family, commands=kind, walker=w, model=cfg.model,
                   robot=robot_label(cfg.model, cfg.robot), ranges=fam.ranges, **summarize(sweep.load(folder)),
                   compile_s=round(compiled[0], 3), run_s=round(run_s, 4), compiles=stats.compiles,
                   chunk=min(stats.chunk_size, cfg.num_scenarios), batch=cfg.scenarios_per_cell, steps=cfg.num_steps,
                   seed=cfg.seed, resolution=cfg.resolution, shape=list(cfg.shape),
                   refine=cfg.refine, kernel=cfg.kernel, forward_m_s=cfg.command.get("vx", (None,))[0],
                   robot_leaves={k: float(v) for k, v in (robot_leaves or {}).items()}, sweep=str(path),
                   results=str(folder), **info)
        if w == "mjx":
            row["physics_steps_per_s"] = stats.computed * stats.physics_steps / run_s
            row["new_compiles"] = W.compiled_programs() - before
        else:
            row["decisions_per_s"] = stats.computed * cfg.num_steps / run_s
        rows.append(row)
        emit(row)
    total = dict(name="walk_compiles", model=model, mjx_programs=W.compiled_programs() - programs0,
                 mjx_compile_s=round(sum(r["compile_s"] for r in rows if r.get("walker") == "mjx"), 3),
                 perfect_compile_s=round(sum(r["compile_s"] for r in rows if r.get("walker") == "perfect"), 3),
                 wall_s=round(time.perf_counter() - t_all, 2), results=str(out), **info)
    rows.append(total)
    emit(total)
    return rows


def _family_of(path: Path) -> str:
    """The family of a walk sweep file ``<family>_<commands>.toml``."""
    return path.stem.rpartition("_")[0]


def _device_info() -> dict[str, str]:
    import mujoco

    return dict(device=str(jax.devices()[0].device_kind), jax=jax.__version__, mujoco=mujoco.__version__)


# --------------------------------------------------------------------------------------------- table and plot


def _pairs(rows: Sequence[dict]) -> list[tuple[str, str, dict | None, dict | None, str | None, str]]:
    """(family, commands, perfect row, simulated row, skip reason, robot) per family and command kind, in run
    order ("-" for a row without a robot)."""
    out: dict[tuple[str, str], list] = {}
    for r in rows:
        if r.get("name") != "walk":
            continue
        if "skipped" in r:
            out[(r["family"], "")] = [None, None, r["skipped"], r.get("robot", "-")]
            continue
        slot = out.setdefault((r["family"], r["commands"]), [None, None, None, r.get("robot", "-")])
        slot[WALKERS.index(r["walker"])] = r
    return [(f, c, *slot) for (f, c), slot in out.items()]


def _cell(row: dict | None, key: str, fmt: str, scale: float = 1.0) -> str:
    """A table cell: ``row[key]`` times ``scale`` in ``fmt``, or "-" without a row or a value."""
    value = None if row is None else row[key]
    return "-" if value is None else format(value if scale == 1.0 else scale * value, fmt)


def markdown_table(rows: Sequence[dict]) -> str:
    """The records of :func:`run` as the Markdown table of BENCHMARKS.md: one line per family and command kind,
    the perfect robot and the simulated one side by side ("perfect / simulated"; "-" where a walker did not
    run or a number does not apply).

    Columns: the selector's robot (:func:`robot_label`); then (:func:`summarize`) robots; fell % (simulated);
    stops % and mean progress along +x (m); mean steps made; obstacle contacts (perfect: footholds on obstacle
    cells; simulated: steps with a sole or shin on one); the simulated placement error, its mean over every step
    made and the mean over robots of each robot's p95 (cm); the sole tilt error's mean robot p95 (deg).
    Per-robot percentiles, since the sweep keeps a row per robot: they run a few per cent below the p95 over
    every step pooled, which the tables before the sweep files gave. A skipped family gets one line with the reason.
    """
    head = ("| family | commands | robot | robots | fell % (sim) | stops % (perfect / sim) "
            "| progress m (perfect / sim) | steps made (perfect / sim) | contacts (perfect / sim) "
            "| placement mean / robot p95 cm (sim) | tilt robot p95 deg (sim) |")
    lines = [head, "|" + " --- |" * head.count(" | ") + " --- |"]
    for family, kind, p, s, why, robot in _pairs(rows):
        if why is not None:
            lines.append(f"| {family} | - | {robot} | skipped: {why} |" + " |" * 7)
            continue
        def both(key, fmt, pkey=None, p=p, s=s):
            return f"{_cell(p, pkey or key, fmt)} / {_cell(s, key, fmt)}"

        cells = [family, kind, robot, str((p or s)["robots"]), _cell(s, "fell_pct", ".2f"), both("stops_pct", ".1f"),
                 both("progress_mean_m", ".2f"), both("steps_made_mean", ".1f"),
                 both("obstacle_contacts", "d", pkey="footholds_on_obstacles"),
                 f"{_cell(s, 'placement_error_mean_m', '.2f', 100)} / {_cell(s, 'placement_error_p95_m', '.2f', 100)}",
                 _cell(s, "tilt_error_p95_rad", ".2f", 180 / math.pi)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


_PLOT_ROBOTS = {"biped": ("HRP-2", "MJX biped"), "g1": ("Unitree G1", "MJX G1")}
"""Per model: the selector's robot and the simulated one, as the plot's title names them."""

PLOT_SIZE = (12.0, 8.0)
"""Figure size of :func:`plot` (inches); saved at :data:`PLOT_DPI`."""
PLOT_DPI = 100


def plot(rows: Sequence[dict], path=None):
    """Bars per family: falls %, stops % and mean progress (m), perfect and simulated side by side.

    One panel per measure; in each, four bars per family: perfect and simulated robot (colour) under
    random and forward commands (hatched: forward). Skipped families are left out; the title names the robot
    (the rows' ``model``). Saved as a PNG of
    :data:`PLOT_SIZE` inches at :data:`PLOT_DPI` when ``path`` is given; returns the figure.
    """
    require("plot", "matplotlib", what="ijoy bench walk --plot")
    import matplotlib

    if path is not None:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    pairs = [x for x in _pairs(rows) if x[4] is None]
    families = list(dict.fromkeys(f for f, *_ in pairs))
    kinds = [k for k in COMMANDS if any(c == k for _, c, *_ in pairs)]
    table = {(f, c): (p, s) for f, c, p, s, *_ in pairs}
    fig, axes = plt.subplots(3, 1, figsize=PLOT_SIZE, sharex=True)
    measures = (("fell_pct", "fell (% of robots)"), ("stops_pct", "stopped (% of robots)"),
                ("progress_mean_m", "mean progress along +x (m)"))
    bars = [(w, k) for k in kinds for w in WALKERS]
    width = 0.8 / max(len(bars), 1)
    colours = {"perfect": "tab:blue", "mjx": "tab:orange"}
    x = np.arange(len(families))
    for ax, (key, label) in zip(axes, measures, strict=True):
        for j, (walker, kind) in enumerate(bars):
            values = []
            for f in families:
                row = table.get((f, kind), (None, None))[WALKERS.index(walker)]
                values.append(np.nan if row is None or row[key] is None else row[key])
            ax.bar(x + (j - 0.5 * (len(bars) - 1)) * width, values, width, color=colours[walker],
                   hatch="//" if kind == "forward" else None, edgecolor="white",
                   label=f"{'perfect' if walker == 'perfect' else 'simulated (MJX)'}, {kind} commands")
        ax.set_ylabel(label)
        if key.endswith("_pct"):
            ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
        ax.grid(axis="y", alpha=0.3)
        ax.axhline(0.0, color="black", lw=0.6)
    axes[0].legend(fontsize=8, ncol=2, loc="upper left")
    axes[-1].set_xticks(x, families, rotation=20)
    first = next((r for r in rows if r.get("name") == "walk" and "skipped" not in r), {})
    robot, body = _PLOT_ROBOTS[first.get("model", "biped")]
    axes[0].set_title(f"{robot} joystick per terrain family: {first.get('batch', '?')} robots x "
                      f"{first.get('steps', '?')} steps, perfect robot vs {body}")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=PLOT_DPI)
        plt.close(fig)
    return fig
