"""A recorded drive exported as a sweep file: a person's commands, step by step, walked by the sweep engine
with the drive's robot, on its recorded map or on more maps of its terrain family (``ijoy drive --replay
FILE --export-sweep OUT.toml``). The file is read back and its scenario 0 checked against the recording, bit
for bit, before it is written. How a sweep reads the recording it names: :mod:`ijoy_jax.sweep.recorded`.
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path

import jax
import numpy as np

from ijoy_jax import recordings, robots
from ijoy_jax.limits import MAX_DENSITY
from ijoy_jax.robots import Robot
from ijoy_jax.sweep import models
from ijoy_jax.sweep.config import load_config, parse_config, toml_value
from ijoy_jax.sweep.expansion import scenarios
from ijoy_jax.sweep.programs import scenario
from ijoy_jax.sweep.schema import ROBOT_DEFAULTS, SweepConfigError

__all__ = ["EXPORT_TERRAINS", "export_drive"]

EXPORT_TERRAINS = ("recording", "family")
"""Where an exported sweep's terrain comes from (:func:`export_drive`): the recording's own map, or the
generator family it was drawn from (replicate 0 is the recorded map)."""


def _shortest(x) -> str:
    """The shortest decimal that reads back as the same float32 (0.02, not 0.019999999552965164)."""
    return np.format_float_positional(np.float32(x), unique=True, trim="0")


def _first_difference(a, b, what: str) -> str | None:
    """None if the pytrees ``a`` and ``b`` are the same (structure, static fields, every leaf bit for bit), else
    the first difference in words."""
    leaves_a, tree_a = jax.tree_util.tree_flatten_with_path(a)
    leaves_b, tree_b = jax.tree_util.tree_flatten_with_path(b)
    if tree_a != tree_b:
        return f"the {what}'s static fields or structure differ"
    for (path, x), (_, y) in zip(leaves_a, leaves_b, strict=True):
        x, y = np.asarray(x), np.asarray(y)
        if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
            return f"the {what}'s {jax.tree_util.keystr(path)} differs"
    return None


def _density(robot: Robot, spec: dict) -> float:
    """The action-set density whose HRP-2 has the recorded robot's actions (the sweep's ``robot.density``): 1, that
    of the sweep scenario the drive walked, or the coarsest decimal density with the same lattice."""
    candidates = [ROBOT_DEFAULTS["density"]]
    if spec.get("kind") == "scenario":  # a sweep scenario's robot: that sweep's density for the scenario
        try:
            cfg = load_config(spec["sweep"])
            row = scenarios(cfg, max_scenarios=int(spec["id"]) + 1).iloc[int(spec["id"])]
            candidates.insert(0, float(row["robot.density"]))
        except (OSError, KeyError, TypeError, ValueError, IndexError):
            pass
    actions = np.asarray(robot.actions)
    counts = tuple(len(np.unique(actions[:, k])) for k in range(3))  # the lattice's dx, dy, dtheta values
    for step in (0.05, 0.01):
        candidates += [round(float(d), 2) for d in np.arange(step, MAX_DENSITY + step / 2, step)]
    for d in candidates:
        if robots.density_counts(d) != counts:
            continue
        try:
            theirs = np.asarray(models.build_robot("biped", density=d, foot_length=float(robot.foot_length),
                                                   foot_width=float(robot.foot_width)).actions)
        except ValueError:
            continue
        if theirs.shape == actions.shape and np.array_equal(theirs, actions):
            return d
    raise ValueError(f"the recorded robot's action set ({actions.shape[0]} actions) is not HRP-2's at any density "
                     f"a sweep can name (at most {MAX_DENSITY}, the paper's reach): a sweep cannot build it")


def export_drive(recording: recordings.Recording, path, recording_path, *, terrain: str = "recording",
                 name: str | None = None) -> dict:
    """Write a sweep file (TOML) whose one scenario is the recorded drive: a person's commands as a sweep.

    The file replays the recorded decisions' commands step by step (``[command] file``, the recording; the
    recording's first swing) with the drive's robot (every value that differs from HRP-2's defaults in
    ``[robot]``, and its density) and walker (``walker = "perfect"`` for the perfect body, ``"mjx"`` for the
    MuJoCo biped, native or MJX: the sweep's is the batched MJX one), ``num_steps`` = the recorded decisions,
    ``method = "exhaustive"`` (the live deciders'), one scenario per cell. ``terrain``:

    * ``"recording"``: ``[terrain] recording``, the recorded map and start feet;
    * ``"family"``: the generator family the drive's map was drawn from, with the drive's seed, so replicate
      0 is the recorded map and ``scenarios_per_cell`` more maps of the family (the drive's terrain spec must
      be a family and its start the family's start zone).

    Before writing, the file is read back (:func:`~ijoy_jax.sweep.parse_config`) and its scenario 0
    (:func:`ijoy_jax.sweep.scenario`) is checked against the recording: the terrain, the robot (every leaf and
    static field), the start feet, the commands and the first swing, bit for bit. Add a ``[grid]`` (margins,
    w, physics, ...) to walk the same commands with other robots.

    The sweep's rollout stops at a decision without a valid step, where the drive stood and decided again
    (:mod:`ijoy_jax.sweep.recorded`): with such decisions in the recording (``invalid_decisions``) the footsteps
    agree up to the first of them; the file says so.

    Args:
      recording: the drive (:func:`ijoy_jax.live.read_recording`).
      path: the sweep file to write (its folder is made).
      recording_path: the recording's file, named in the sweep relative to ``path``'s folder.
      terrain: one of :data:`EXPORT_TERRAINS`.
      name: the sweep's name (default: the file's stem).

    Returns:
      ``{"sweep", "recording", "decisions", "terrain", "walker", "invalid_decisions"}``.

    Raises:
      ValueError: one line: no decisions, a robot or terrain a sweep cannot build, a bad ``terrain``.
    """
    if terrain not in EXPORT_TERRAINS:
        raise ValueError(f"terrain must be one of {EXPORT_TERRAINS}, got {terrain!r}")
    path, recording_path = Path(path), Path(recording_path)
    decisions = recording.decisions
    if not decisions:
        raise ValueError(f"{str(recording_path)!r}: the recording has no decisions (nothing to replay)")
    settings = recording.config.get("settings", {})
    spec = settings.get("terrain", {})
    body = settings.get("body", "perfect")
    if settings.get("model", "biped") != "biped":
        raise ValueError(f"the recording's robot is model {settings['model']!r}: a sweep walks the project's biped "
                         "(HRP-2) only")
    walker = {"perfect": "perfect", "native": "mjx", "mjx": "mjx"}.get(body)
    if walker is None:
        raise ValueError(f"the recording's body {body!r} has no sweep walker (perfect, native or mjx)")
    robot = recording.robot
    density = _density(robot, spec)
    defaults = ROBOT_DEFAULTS
    values = {n: float(np.asarray(robots.get_leaf(robot, n))) for n in robots.SCALAR_LEAVES}
    changed = {n: v for n, v in values.items() if np.float32(v) != np.float32(defaults[n])}
    if density != defaults["density"]:
        changed["density"] = density
    name = name or "".join(c if c.isalnum() or c in "_-." else "_" for c in path.stem) or "drive"
    invalid = [int(d["step"]) for d in decisions if not d.get("valid", False)]
    rel = os.path.relpath(recording_path.resolve(), path.resolve().parent)
    lines = [f"# A recorded drive as a sweep: ijoy drive --replay {recording_path} --export-sweep {path}"
             f" ({datetime.datetime.now(datetime.UTC).date().isoformat()}).",
             f"# The person's {len(decisions)} commands, one per step, replayed by the {walker} walker; add a [grid]",
             "# (robot.margin, robot.w, sim.friction, ...) to walk them with other robots: ijoy sweep run THIS_FILE."]
    if invalid:
        lines += [f"# The drive had decisions without a valid step (steps {invalid[:10]}): it stood and decided again,",
                  "# the sweep's robot stops there for good, so the footsteps agree up to the first of them."]
    lines += ["", "[sweep]", f"name = {toml_value(name)}",
              f"description = {toml_value(f'the drive recorded in {recording_path.name}, its commands step by step')}",
              f"seed = {int(spec.get('seed', 0)) if terrain == 'family' else 0}",
              "scenarios_per_cell = 1", f"num_steps = {len(decisions)}",
              'method = "exhaustive"               # the live deciders\' search (ordered: the same footholds)',
              f"walker = {toml_value(walker)}", "",
              "[robot]                             # the drive's robot: HRP-2's (sweep.ROBOT_DEFAULTS) but these"]
    lines += [f"{n} = {_shortest(v) if n != 'density' else toml_value(v)}" for n, v in changed.items()]
    lines += ["", "[terrain]"]
    if terrain == "recording":
        lines += [f"recording = {toml_value(rel)}   # the drive's own map and start feet"]
    else:
        if spec.get("kind") != "family":
            raise ValueError(f"the drive's terrain was not drawn from a generator family (its spec: "
                             f"{spec.get('kind')!r}): export it with its recorded map (terrain 'recording')")
        if settings.get("start") is not None:
            raise ValueError("the drive started away from the family's start zone (--start): a generated sweep "
                             "starts there; export it with its recorded map (terrain 'recording')")
        lines += [f"family = {toml_value(spec['family'])}                 # replicate 0 is the drive's map",
                  f"shape = [{', '.join(str(int(v)) for v in spec.get('shape', (200, 120)))}]",
                  f"resolution = {toml_value(float(spec.get('resolution', 0.02)))}",
                  f"has_height = {toml_value(bool(spec.get('has_height', False)))}"]
        if spec.get("max_count") is not None:
            lines.append(f"max_count = {int(spec['max_count'])}")
        if spec.get("params"):
            lines += ["", "[terrain.params]"] + [f"{k} = {toml_value(v, f'terrain.params.{k}')}"
                                                   for k, v in spec["params"].items()]
    first_swing = int(settings.get("first_swing", 1))
    lines += ["", "[command]", f"file = {toml_value(rel)}   # the recorded decisions' commands, one per step",
              f"first_swing = {first_swing}                     # the drive's first swing foot (+1 left)", ""]
    text = "\n".join(lines)
    path.parent.mkdir(parents=True, exist_ok=True)  # the recording is named relative to it
    try:
        cfg = parse_config(text, str(path))
        got = scenario(cfg, 0)
    except SweepConfigError as e:
        raise ValueError(f"the drive cannot be this sweep: {e}") from None
    recorded_commands = np.asarray([d["command"] for d in decisions], np.float32)
    start = np.asarray(recording.config.get("start"), np.float32)
    why = (_first_difference(got.terrain, recording.terrain, "terrain")
           or _first_difference(got.robot, robot, "robot")
           or (None if np.array_equal(got.start, start) else "the start feet differ")
           or (None if np.array_equal(got.command, recorded_commands) else "the commands differ")
           or (None if got.first_swing == first_swing else "the first swing differs"))
    if why is not None:
        raise ValueError(f"the exported sweep's scenario 0 is not the recorded drive ({why}); export it with its "
                         f"recorded map (terrain 'recording')" if terrain == "family" else
                         f"the exported sweep's scenario 0 is not the recorded drive ({why})")
    path.write_text(text)
    return {"sweep": str(path), "recording": str(recording_path), "decisions": len(decisions), "terrain": terrain,
            "walker": walker, "invalid_decisions": invalid}
