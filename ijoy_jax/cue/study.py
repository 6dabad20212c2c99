"""Does the cue help? A simulated operator drives the perfect robot with the cue on and off.

The operator (:class:`Operator`, every number a traced leaf) wants to reach a goal and holds the stick:

* **intent**: the goal's displacement from the feet's midpoint, in the stance foot's frame, covered in
  ``horizon`` seconds: ``v = g / horizon``, scaled down (direction kept) so that no axis exceeds
  ``speed`` of a full deflection; a turn towards the goal's bearing (``turn_gain`` per radian, capped
  alike). Nothing is planned around obstacles: the intelligent joystick steps around small ones and
  slides along a slanted wall; goals are placed where a greedy operator can get (:func:`make_scenarios`).
* **hand**: a first-order admittance (the repulsion tuner's operator model,
  :func:`ijoy_jax.haptics.tuning.simulate_leg`, on the stick): over the ``ticks`` haptic ticks of a step
  the stick ``s`` (fractions of a full deflection) moves towards the aim plus the cue's push,
  ``s <- s + (dt / hand_time) (aim + compliance * f(s) - s)``; at rest ``s = aim + compliance f(s)``.
* **watching the robot** (the only feedback without the cue, the HRP-2 paper's section VI): after each
  step the operator sees the command the robot realized and shifts their aim by ``correction`` times the
  difference, a shift that fades by ``memory`` per step; and they judge how blocked the robot is from its
  progress towards the goal, ``seen = clip(1 - 2 progress / intended progress, 0, 1)``, a belief kept
  as ``belief = max(seen, persistence * belief)``.
* **detour**: believing the robot blocked, the operator pushes the stick ``detour * belief`` sideways
  towards the goal's side as seen from the start (the left when it is straight ahead). With the cue on,
  the belief is also the force felt in the hand at each tick (``|f| / C1``): the same reaction, a step
  earlier. The aim is
  ``intent + shift + detour``; within :attr:`StudyConfig.goal_radius` of the goal the operator lets go.

The robot reads the stick at the end of the step (``command = s * full_scale``) and the exhaustive
selector decides from the feasible set's one FootCost evaluation (``select_step(..., foot_costs=)``); the
perfect walker (:func:`ijoy_jax.perfect_walker`) puts the foot down. A step with no valid action moves
nothing (the operator may steer elsewhere). The cue's on/off switch is a traced gate, so one compiled
program runs both conditions on the same scenarios (paired).

Metrics per scenario (:func:`summarize`): ``time_to_goal`` (s; the feet's midpoint within
``goal_radius`` of the goal; ``num_steps * step_time`` if never: censored, with ``reached`` telling
which), ``steps_in_place`` (decisions before the goal that moved nothing: no valid step or the step in
place), ``command_error`` (mean ``|command - realized| / full_scale`` over those decisions, stick units;
the command clipped to what the step could realise, :attr:`DriveLog.reachable`),
``near_obstacles`` (footholds whose footprint grown by ``near_margin`` touches an obstacle) and
``effort`` (mean squared cue force over the ticks). :func:`compare` runs conditions on a batch and
reports means and paired differences with 95% confidence intervals.

Tuning (:func:`tune_cue`): the same drive with a *relaxed* robot that realises the cue's soft-nearest
feasible command (:attr:`ijoy_jax.cue.CueForce.nearest`, at a fixed temperature: the robot model is not
tuned) instead of the selector's choice, so the loss is differentiable in the cue's constants through
the hand and the robot's step; feasibility itself (exact FootCost at each stance) carries no gradient,
and neither does the state carried from one decision to the next (the gradient is truncated at each
decision: through 30 decisions of greedy steering the full gradient is as erratic as the drive's
outcome is sensitive to each step). Loss (:class:`Weights`): the mean distance to the goal after each
step (m) + the mean squared command error + the mean squared force; Adam by the project's one loop
(:func:`ijoy_jax.optim.run_steps`) on (logit C1, log decay, log scales). Evaluate the result with the
exact selector on held-out scenarios (:func:`compare`).

Units: metres, seconds, radians; stick positions and forces as fractions of full scale.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ijoy_jax import geometry, optim, select
from ijoy_jax.control import perfect_walker
from ijoy_jax.cue import field
from ijoy_jax.footcost import foot_cost_terms, index_terrain
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.prng import as_key
from ijoy_jax.robots import Robot, side_p0, side_sign, start_stance
from ijoy_jax.stats import mean_ci
from ijoy_jax.struct import pytree_dataclass, static_field
from ijoy_jax.targets import Targets, make_targets
from ijoy_jax.terrain import Terrain, flat, scene

FAMILIES = ("clutter", "wall", "slide")
"""Scenario families (:func:`make_scenarios`): small obstacles to step around on the way to a goal
ahead; a wall across the way with the goal just before it (walk up against it, the paper's Fig. 5a); a wall
across the way, open on one side, with the goal beyond it on that side (sidestep along it, the paper's
"commanded forward and to the side, the robot sidesteps along the blockage")."""
SHAPE = (200, 120)
"""Cells of every scenario's map (4 m x 2.4 m at :data:`RESOLUTION`)."""
RESOLUTION = 0.02
"""m per cell."""
START = (0.5, 1.2)
"""m: the feet's midpoint at the start (facing +x)."""
METRICS = ("time_to_goal", "reached", "steps_in_place", "command_error", "near_obstacles", "effort")
"""Per-scenario metrics of :func:`summarize`, in report order."""
UNITS = {"time_to_goal": "s", "reached": "fraction", "steps_in_place": "steps", "command_error": "stick units",
         "near_obstacles": "footholds", "effort": "force^2"}
"""Units of :data:`METRICS`."""
CLUTTER_COUNT = 10
"""Boxes of the clutter family (kept only away from the start and the goal)."""
ROBOT_TEMPERATURE = 0.01
"""Distance units: the relaxed robot's soft projection onto the feasible commands (fixed, not tuned)."""


@pytree_dataclass
class Operator:
    """The simulated operator's numbers (traced leaves, scalars; see the module docstring).

    Attributes:
      speed: largest stick deflection the operator asks for, fraction of full scale (0.9).
      horizon: s, the intended velocity is the goal's displacement over it (2.0).
      turn_gain: stick turn per radian of the goal's bearing, fraction of full scale per rad (1.0).
      hand_time: s, the hand's time constant moving the stick (0.15).
      compliance: full deflections the stick yields per unit of cue force (a fraction of the device's
        maximum): the hand's admittance times the maximum force over the stick's travel (0.5).
      correction: fraction of the command error seen after a step that shifts the aim (0.3).
      memory: fraction of that shift kept from one step to the next (0.5).
      detour: sideways stick deflection the operator adds, towards the goal's side (the left when the goal
        is straight ahead), when they believe the robot is blocked (0.8).
      persistence: fraction of that belief kept from one step to the next without new evidence (0.8).
    """

    speed: jax.Array
    horizon: jax.Array
    turn_gain: jax.Array
    hand_time: jax.Array
    compliance: jax.Array
    correction: jax.Array
    memory: jax.Array
    detour: jax.Array
    persistence: jax.Array


def default_operator(**overrides) -> Operator:
    """A fresh :class:`Operator` with the defaults above (float32 leaves); any field may be overridden.

    Example:
      >>> from ijoy_jax.cue import study
      >>> op = study.default_operator(compliance=0.8)
      >>> round(float(op.compliance), 3), round(float(op.hand_time), 3)
      (0.8, 0.15)
    """
    values = dict(speed=0.9, horizon=2.0, turn_gain=1.0, hand_time=0.15, compliance=0.5, correction=0.3,
                  memory=0.5, detour=0.8, persistence=0.8)
    unknown = set(overrides) - set(values)
    if unknown:
        raise ValueError(f"unknown operator fields {sorted(unknown)}; known: {sorted(values)}")
    values.update(overrides)
    for k, v in values.items():
        if not np.isfinite(v) or v < 0 or (k in ("horizon", "hand_time") and v <= 0):
            raise ValueError(f"operator.{k} must be finite and {'> 0' if k in ('horizon', 'hand_time') else '>= 0'}"
                             f", got {v!r}")
    return Operator(**{k: jnp.float32(v) for k, v in values.items()})


@pytree_dataclass
class StudyConfig:
    """Static settings of a drive (hashable: they size the programs).

    Attributes:
      num_steps: decisions per drive (30: 24 s).
      ticks: haptic ticks simulated per step (8: 0.1 s each at HRP-2's 0.8 s step).
      goal_radius: m, the goal is reached when the feet's midpoint is this close (0.25).
      near_margin: m, a foothold whose footprint grown by this touches an obstacle is *near* one (0.05,
        the paper's vision margin).
    """

    num_steps: int = static_field(default=30)
    ticks: int = static_field(default=8)
    goal_radius: float = static_field(default=0.25)
    near_margin: float = static_field(default=0.05)


@pytree_dataclass
class Scenario:
    """One map, start and goal (batched ones carry a leading axis on every leaf).

    Attributes:
      terrain: the 2D map (:data:`SHAPE` cells at :data:`RESOLUTION`).
      start: (2, 3) the feet's world poses, row 0 left (m, rad).
      goal: (2,) m, the point the operator wants the robot's feet around.
      family: () int32 index into :data:`FAMILIES`.
    """

    terrain: Terrain
    start: jax.Array
    goal: jax.Array
    family: jax.Array


def _uniform(key, lo, hi, shape=()):
    return jax.random.uniform(key, shape, jnp.float32, lo, hi)


def _scenario(key, family: int, robot: Robot) -> Scenario:
    """One scenario of a family (traceable in the key; ``family`` static)."""
    kg, k1, k2, k3, k4, k5 = jax.random.split(key, 6)
    base = flat(SHAPE, RESOLUTION)
    width = SHAPE[1] * RESOLUTION
    sx, sy = START
    if family == 0:  # clutter: small boxes between start and goal, none within 0.45 m of either
        goal = jnp.stack([_uniform(kg, 3.2, 3.5), sy + _uniform(k1, -0.5, 0.5)])
        n = CLUTTER_COUNT
        centre = jnp.stack([_uniform(k2, 0.9, 3.4, (n,)), _uniform(k3, 0.3, width - 0.3, (n,))], 1)
        size = _uniform(k4, 0.04, 0.10, (n, 2))
        clear = (jnp.hypot(centre[:, 0] - sx, centre[:, 1] - sy) > 0.45) & (
            jnp.hypot(centre[:, 0] - goal[0], centre[:, 1] - goal[1]) > 0.45)
        yaw = _uniform(k5, 0.0, math.pi, (n,))
        boxes = jnp.column_stack([centre, yaw, size * clear[:, None], jnp.full((n,), 0.1)])
        terrain = scene.rasterize(base, boxes=boxes)
    elif family == 1:  # a wall across the way, the goal 0.15 m before it (the feet stop 0.21 m before it)
        xw = _uniform(kg, 2.0, 3.0)
        goal = jnp.stack([xw - 0.15, sy + _uniform(k1, -0.3, 0.3)])
        terrain = scene.rasterize(base, boxes=jnp.stack([xw + 0.05, width / 2, 0.0, 0.1, 2 * width, 0.1])[None])
    else:  # a wall across the way, open on one side; the goal beyond it on that side: slide along it
        side = jnp.where(jax.random.bernoulli(kg), 1.0, -1.0)
        xw = _uniform(k1, 1.5, 2.0)
        end = sy + side * _uniform(k2, 0.2, 0.4)  # the wall covers the start's lane and ends here
        far = jnp.where(side > 0, 0.0, width)  # its other end: the map's edge
        goal = jnp.stack([_uniform(k3, 3.0, 3.4), end + side * _uniform(k4, 0.4, 0.6)])
        wall = jnp.stack([xw + 0.05, 0.5 * (end + far), 0.0, 0.1, jnp.abs(end - far), 0.1])
        terrain = scene.rasterize(base, boxes=wall[None])
    start = start_stance(robot, sx, sy)
    return Scenario(terrain=terrain, start=start, goal=goal, family=jnp.int32(family))


def make_scenarios(key, num: int, families=FAMILIES, *, robot: Robot | None = None) -> Scenario:
    """``num`` scenarios per family, stacked (``num * len(families)``), from one key (jit inside).

    Maps are :data:`SHAPE` cells at :data:`RESOLUTION` m, the feet start side by side at :data:`START`
    facing +x. ``clutter``: :data:`CLUTTER_COUNT` boxes of 4-10 cm sides (each kept only if its centre
    is more than 0.45 m from the start and the goal) between x = 0.9 and 3.4 m; goal at x 3.2-3.5 m, y
    within 0.5 m of the start's. ``wall``: a 10 cm wall across the map at x 2-3 m; goal 0.15 m before it
    (the feet's centres stop 0.21 m before it: the goal is reached with the robot's front against the wall).
    ``slide``: a 10 cm wall across the map at x 1.5-2 m from one edge to 0.2-0.4 m past the start's lane;
    goal at x 3-3.4 m, 0.4-0.6 m beyond the wall's end.

    Args:
      key: int seed or PRNG key.
      num: scenarios per family (>= 1).
      families: names from :data:`FAMILIES`.
      robot: for the start stance's width (default HRP-2).

    Returns:
      :class:`Scenario` with a leading axis of ``num * len(families)`` (family-major).
    """
    if isinstance(num, bool) or not isinstance(num, (int, np.integer)) or num < 1:
        raise ValueError(f"num must be a positive int, got {num!r}")
    families = tuple(families)
    bad = [f for f in families if f not in FAMILIES]
    if bad or not families:
        raise ValueError(f"families must be a non-empty subset of {FAMILIES}, got {families!r}")
    from ijoy_jax.robots import hrp2

    robot = hrp2() if robot is None else robot
    keys = jax.random.split(as_key(key), len(families))
    parts = [jax.jit(jax.vmap(lambda k, i=FAMILIES.index(f): _scenario(k, i, robot)))(jax.random.split(kf, num))
             for f, kf in zip(families, keys, strict=True)]
    return jax.tree_util.tree_map(lambda *x: jnp.concatenate(x), *parts)


class DriveLog(NamedTuple):
    """One drive, per decision (T = ``num_steps``; batched drives add leading axes).

    Fields::

      feet: (T, 2, 3) world poses of the feet after the step (row 0 left).
      command: (T, 3) the stick's command read at the decision (m/s, m/s, rad/s).
      reachable: (T, 3) that command clipped to the step's feasible hull (what this foot's step could
        realise: a sideways command towards the stance foot waits for the other foot).
      realized: (T, 3) the command of the step taken (0 when nothing moved).
      moved: (T,) bool, a step other than the step in place was taken.
      near: (T,) bool, the foothold taken is near an obstacle (:attr:`StudyConfig.near_margin`).
      distance: (T,) m, the feet's midpoint to the goal after the step.
      effort: (T,) mean squared cue force over the step's ticks.
      blocked: (T,) bool, the cue pushed at the end of the step.
    """

    feet: jax.Array
    command: jax.Array
    reachable: jax.Array
    realized: jax.Array
    moved: jax.Array
    near: jax.Array
    distance: jax.Array
    effort: jax.Array
    blocked: jax.Array


def _intent(op: Operator, feet, stance, goal, full):
    """(3,) the operator's intended stick position (fractions of full scale) and the distance to the goal."""
    mid = jnp.mean(feet[:, :2], axis=0)
    c, s = jnp.cos(stance[2]), jnp.sin(stance[2])
    d = goal - mid
    gx, gy = c * d[0] + s * d[1], -s * d[0] + c * d[1]
    v = jnp.stack([gx, gy]) / op.horizon / full[:2]  # stick units
    big = jnp.maximum(jnp.max(jnp.abs(v)), 1e-6)
    v = v * jnp.minimum(1.0, op.speed / big)
    bearing = jnp.arctan2(gy, gx + 1e-6)
    turn = jnp.clip(op.turn_gain * bearing * jnp.minimum(1.0, geometry.safe_norm(gx, gy) / 0.5), -op.speed,
                    op.speed)
    return jnp.concatenate([v, turn[None]]), geometry.safe_norm(d[0], d[1])


def _drive(scenario: Scenario, robot: Robot, params: field.CueParams, op: Operator, gate, targets, cfg: StudyConfig,
           exact: bool) -> DriveLog:
    """The drive's body: a ``lax.scan`` over decisions, each a ``lax.scan`` over haptic ticks."""
    terrain = scenario.terrain
    index = index_terrain(terrain, robot)
    walker = perfect_walker()
    state0 = walker.init(scenario.start, jnp.float32(1.0))
    near_robot = robot.replace(margin=jnp.float32(cfg.near_margin))
    alpha = jnp.minimum(robot.step_time / cfg.ticks / op.hand_time, 1.0)
    robot_params = field.make_params(temperature=ROBOT_TEMPERATURE)

    c1 = jnp.maximum(params.c1, 1e-6)
    # The side of the detour: the goal's, seen from the start (the operator knows which way round to go).
    goal_side = jnp.where(scenario.goal[1] - jnp.mean(scenario.start[:, 1]) < -0.05, -1.0, 1.0)

    def step(carry, _):
        if not exact:  # the relaxed robot's gradient is truncated at each decision (module docstring)
            carry = jax.lax.stop_gradient(carry)
        state, stick, shift, seen, done = carry
        info = walker.stance(state)
        stance = jax.lax.stop_gradient(info.stance)
        feas = field.feasible_commands(terrain, robot, stance, info.stance_side, index=index)
        full = jnp.maximum(feas.full_scale, field.MIN_UNIT)
        intent, before = _intent(op, walker.feet(state), info.stance, scenario.goal, full)
        keep = jnp.where(done, 0.0, 1.0)  # at the goal the operator lets go of the stick
        intent, seen, shift = intent * keep, seen * keep, shift * keep

        def tick(s, _):
            f = gate * field.force(feas, s * full, params)
            belief = jnp.maximum(seen, gate * jnp.sqrt(jnp.sum(f * f) + 1e-12) / c1)
            aim = jnp.clip(intent + shift + jnp.array([0.0, 1.0, 0.0]) * op.detour * jnp.minimum(belief, 1.0)
                           * goal_side, -1.0, 1.0)
            return jnp.clip(s + alpha * (aim + op.compliance * f - s), -1.0, 1.0), f

        stick, forces = jax.lax.scan(tick, stick, None, length=cfg.ticks)
        command = stick * full
        if exact:
            choice = select.select_step(terrain, robot, info.stance, info.stance_side, command, targets=targets,
                                        index=index, foot_costs=feas.cost)
            go = choice.valid
            realized = jnp.where(go, feas.commands[jnp.maximum(choice.index, 0)], 0.0)
            foothold = choice.foothold
        else:
            realized = field.force_terms(feas, command, robot_params).nearest
            go = feas.any_valid
            rel = side_p0(robot, -side_sign(info.stance_side)) + robot.step_time * realized
            pose = geometry.compose(info.stance, rel)
            zero = jnp.zeros((), pose.dtype)
            foothold = jnp.stack([pose[0], pose[1], zero, zero, zero, pose[2]])
        state = walker.execute(state, foothold, go)
        pose = foothold[jnp.array([0, 1, 5])]
        near = go & (foot_cost_terms(terrain, near_robot, jax.lax.stop_gradient(pose), 1,
                                     jax.lax.stop_gradient(pose)[None], action_index=jnp.zeros(1, jnp.int32),
                                     index=index).obstacle[0] > 0)
        # What this step could realise: a sideways command towards the stance foot waits for the other foot.
        reachable = jnp.clip(command, feas.lo, feas.hi)
        shift = op.memory * shift + op.correction * (realized - reachable) / full
        feet = walker.feet(state)
        mid = jnp.mean(feet[:, :2], axis=0)
        after = geometry.safe_norm(mid[0] - scenario.goal[0], mid[1] - scenario.goal[1])
        intended = jnp.maximum(geometry.safe_norm(*(intent[:2] * full[:2])) * robot.step_time, 1e-3)
        seen = jnp.maximum(jnp.clip(1.0 - 2.0 * (before - after) / intended, 0.0, 1.0), op.persistence * seen)
        record = DriveLog(
            feet=feet, command=command, reachable=reachable, realized=realized,
            moved=go & (jnp.max(jnp.abs(realized)) > 1e-6), near=near, distance=after,
            effort=jnp.mean(jnp.sum(forces**2, axis=1)), blocked=jnp.any(forces[-1] != 0),
        )
        return (state, stick, shift, seen, done | (after < cfg.goal_radius)), record

    init = (state0, jnp.zeros(3), jnp.zeros(3), jnp.float32(0.0), jnp.bool_(False))
    _, log = jax.lax.scan(step, init, None, length=cfg.num_steps)
    return log


def _drives(scenarios, robot, params, op, gate, targets, cfg: StudyConfig, exact: bool) -> DriveLog:
    """:func:`_drive` vmapped over a batch of scenarios (everything else shared)."""
    return jax.vmap(lambda sc: _drive(sc, robot, params, op, gate, targets, cfg, exact))(scenarios)


_drives_jit = jax.jit(_drives, static_argnames=("cfg", "exact"))


def drive(scenarios: Scenario, robot: Robot, params: field.CueParams | None = None,
          operator: Operator | None = None, *, cue_on: bool | jax.Array = True, cfg: StudyConfig | None = None,
          targets: Targets | None = None) -> DriveLog:
    """The operator drives the perfect robot through a batch of scenarios (exact selector; one jit).

    Args:
      scenarios: :func:`make_scenarios` (leading batch axis).
      robot: the robot (its actions and limits); leaves are traced.
      params: the cue's :class:`~ijoy_jax.cue.CueParams` (default :func:`~ijoy_jax.cue.make_params`).
      operator: :class:`Operator` (default :func:`default_operator`).
      cue_on: the cue's gate (traced: on and off share one program).
      cfg: :class:`StudyConfig` (static).
      targets: the robot's :func:`ijoy_jax.make_targets` (built when None).

    Returns:
      :class:`DriveLog` with leading axes (batch, T).
    """
    params = field.make_params() if params is None else params
    field.check_params(params)
    operator = default_operator() if operator is None else operator
    cfg = StudyConfig() if cfg is None else cfg
    targets = make_targets(robot) if targets is None else targets
    return _drives_jit(scenarios, robot, params, operator, jnp.float32(cue_on), targets, cfg=cfg, exact=True)


def summarize(log: DriveLog, robot: Robot, cfg: StudyConfig | None = None) -> dict[str, np.ndarray]:
    """Per-scenario metrics (:data:`METRICS`) of a batch of drives, as NumPy arrays of shape (batch,).

    Decisions after the goal was reached are not counted (the operator is done).
    """
    cfg = StudyConfig() if cfg is None else cfg
    dist = np.asarray(log.distance)
    reached_at = dist < cfg.goal_radius
    reached = reached_at.any(axis=1)
    t = cfg.num_steps
    first = np.where(reached, reached_at.argmax(axis=1) + 1, t)  # decisions until reached (or all)
    active = np.arange(t)[None, :] < first[:, None]
    full = np.maximum(np.abs(np.asarray(field.action_commands(robot, 1))).max(0), field.MIN_UNIT)
    err = np.linalg.norm((np.asarray(log.reachable) - np.asarray(log.realized)) / full, axis=2)
    n_active = np.maximum(active.sum(1), 1)
    return {
        "time_to_goal": first * float(robot.step_time),
        "reached": reached.astype(np.float64),
        "steps_in_place": (active & ~np.asarray(log.moved)).sum(1).astype(np.float64),
        "command_error": (err * active).sum(1) / n_active,
        "near_obstacles": (active & np.asarray(log.near)).sum(1).astype(np.float64),
        "effort": (np.asarray(log.effort) * active).sum(1) / n_active,
    }


def compare(scenarios: Scenario, robot: Robot, conditions: dict, operator: Operator | None = None, *,
            cfg: StudyConfig | None = None, targets: Targets | None = None) -> dict:
    """Drive every condition on the same scenarios; per-scenario metrics and their intervals.

    Args:
      scenarios: a batch (:func:`make_scenarios`).
      robot: the robot.
      conditions: name -> :class:`~ijoy_jax.cue.CueParams`, or None for the cue off (e.g.
        ``{"off": None, "cue": cue.make_params()}``); the first is the baseline of the differences.
      operator, cfg, targets: as :func:`drive`.

    Returns:
      ``{"per_scenario": {condition: {metric: (batch,)}}, "summary": {condition: {metric: (mean,
      ci95)}}, "difference": {condition: {metric: (mean, ci95)}}`` (paired differences from the
      baseline, all conditions but the first), ``"family"``: (batch,) family names, ``"n"``: batch size.
    """
    if not conditions:
        raise ValueError("conditions must name at least one condition")
    cfg = StudyConfig() if cfg is None else cfg
    targets = make_targets(robot) if targets is None else targets
    per = {}
    for name, params in conditions.items():
        log = drive(scenarios, robot, params, operator, cue_on=params is not None, cfg=cfg, targets=targets)
        per[name] = summarize(log, robot, cfg)
    names = list(conditions)
    base = per[names[0]]
    return {
        "per_scenario": per,
        "summary": {c: {m: mean_ci(v[m]) for m in METRICS} for c, v in per.items()},
        "difference": {c: {m: mean_ci(per[c][m] - base[m]) for m in METRICS} for c in names[1:]},
        "family": [FAMILIES[int(i)] for i in np.asarray(scenarios.family)],
        "n": int(np.asarray(scenarios.family).shape[0]),
    }


def markdown(result: dict, title: str = "") -> str:
    """A Markdown table of :func:`compare`'s summary (mean +- 95% CI) and paired differences."""
    names = list(result["summary"])
    head = ["metric (unit)"] + names + [f"{c} - {names[0]}" for c in result["difference"]]
    lines = ([f"{title} (n = {result['n']} scenarios)", ""] if title else []) + [
        "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for m in METRICS:
        row = [f"{m} ({UNITS[m]})"]
        row += [f"{a:.3g} +- {b:.2g}" for a, b in (result["summary"][c][m] for c in names)]
        row += [f"{a:+.3g} +- {b:.2g}" for a, b in (result["difference"][c][m] for c in result["difference"])]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


# --------------------------------------------------------------------------- tuning by gradient


class Weights(NamedTuple):
    """Weights of the tuning loss (module docstring): per metre of distance to the goal, per squared stick
    unit of command error, per squared unit of force. The distance's weight is small: how far a greedy
    drive gets changes by jumps (a detour taken one step earlier or later), which would drown the
    command error and effort the cue's constants set smoothly."""

    distance: float = 0.1
    error: float = 1.0
    effort: float = 0.2


def to_params(u: dict) -> field.CueParams:
    """The cue's parameters from the tuner's unconstrained variables ``{"c1": logit, "decay": log, "scales":
    log (3,)}`` (temperature at its default)."""
    return field.CueParams(c1=jax.nn.sigmoid(u["c1"]), decay=jnp.exp(u["decay"]), scales=jnp.exp(u["scales"]),
                           temperature=jnp.float32(field.DEFAULT_TEMPERATURE))


def from_params(p: field.CueParams) -> dict:
    """The tuner's unconstrained variables of ``p`` (inverse of :func:`to_params`; C1 kept inside (0, 1))."""
    c1 = jnp.clip(jnp.asarray(p.c1, jnp.float32), 1e-4, 1 - 1e-4)
    return {"c1": jnp.log(c1) - jnp.log1p(-c1), "decay": jnp.log(jnp.asarray(p.decay, jnp.float32)),
            "scales": jnp.log(jnp.asarray(p.scales, jnp.float32))}


def relaxed_loss(u: dict, scenarios: Scenario, robot: Robot, op: Operator, targets, cfg: StudyConfig,
                 weights: Weights = Weights()) -> tuple[jax.Array, dict]:
    """() the tuning loss over a batch with the relaxed robot, and its named terms (mean over the batch)."""
    params = to_params(u)
    log = _drives(scenarios, robot, params, op, jnp.float32(1.0), targets, cfg, False)
    full = jnp.maximum(jnp.max(jnp.abs(field.action_commands(robot, 1)), axis=0), field.MIN_UNIT)
    err = jnp.mean(jnp.sum(((log.reachable - log.realized) / full) ** 2, axis=-1))
    terms = {"distance": jnp.mean(log.distance), "error": err, "effort": jnp.mean(log.effort)}
    loss = weights.distance * terms["distance"] + weights.error * terms["error"] + weights.effort * terms["effort"]
    return loss, terms


class CueTuneResult(NamedTuple):
    """A tuning run: ``params`` (the :class:`~ijoy_jax.cue.CueParams` of the lowest loss seen: a greedy
    drive's loss can jump when a detour changes, so the last iterate need not be the best), ``losses``
    (steps,) before each update, the named ``terms`` (dict of (steps,)), ``trajectory`` (the unconstrained
    variables before each update) and ``best`` (the step whose parameters ``params`` are)."""

    params: field.CueParams
    losses: jax.Array
    terms: dict
    trajectory: dict
    best: int


def tune_cue(scenarios: Scenario, robot: Robot, *, init: field.CueParams | None = None,
             operator: Operator | None = None, cfg: StudyConfig | None = None, weights: Weights = Weights(),
             steps: int = 40, learning_rate: float = 0.05) -> CueTuneResult:
    """Tune C1, the decay and the per-axis scales by Adam on the relaxed drives of ``scenarios``.

    The project's tuning loop (:func:`ijoy_jax.optim.make_tuner`, :func:`~ijoy_jax.optim.run_steps`)
    inside one jit; the whole batch every step.

    Args:
      scenarios: training scenarios (:func:`make_scenarios`).
      robot: the robot.
      init: starting parameters (default :func:`ijoy_jax.cue.make_params`).
      operator, cfg: as :func:`drive`.
      weights: :class:`Weights` of the loss.
      steps: Adam steps (>= 1); learning_rate: Adam's.

    Returns:
      :class:`CueTuneResult` (the parameters of the lowest loss seen).
    """
    init = field.make_params() if init is None else init
    field.check_params(init)
    operator = default_operator() if operator is None else operator
    cfg = StudyConfig() if cfg is None else cfg
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps must be a positive int, got {steps!r}")
    targets = make_targets(robot)
    _, metrics, trajectory = _tune_jit(from_params(init), scenarios, robot, operator, targets, cfg, weights,
                                       int(steps), float(learning_rate))
    best = int(np.argmin(np.asarray(metrics.loss)))
    params = to_params(jax.tree_util.tree_map(lambda x: x[best], trajectory))
    return CueTuneResult(params, metrics.loss, dict(metrics.terms), trajectory, best)


@jax.jit(static_argnames=("cfg", "weights", "steps", "learning_rate"))
def _tune_jit(u0, scenarios, robot, operator, targets, cfg, weights, steps, learning_rate):
    tuner = optim.make_tuner(lambda u, _: relaxed_loss(u, scenarios, robot, operator, targets, cfg, weights),
                            optax.adam(learning_rate), has_aux=True)
    return optim.run_steps(tuner, tuner.init(u0), steps, trace_params=True)


def compiled_programs() -> int:
    """How many programs :func:`drive` (and :func:`compare`) and :func:`tune_cue` hold compiled (in this process).

    Read it before and after a loop of calls to learn how many compiles the loop caused: each new batch or
    terrain shape, :class:`StudyConfig`, :class:`Weights`, ``steps`` or ``learning_rate`` compiles once; new
    scenarios, robot parameters, operators, cue parameters (and starting values) and the cue's gate reuse the
    program.
    """
    return compiled_count(_drives_jit) + compiled_count(_tune_jit)
