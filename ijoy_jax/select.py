"""Step selection: the best valid step of S for a joystick command (paper section IV.B).

cost(p) = FootCost(p, e) + w * dist(p, target), with
dist(p, q) = ``|p_xy - q_xy|`` + rotation_weight * ``|wrap(p_theta - q_theta)|``
measured in the stance foot's frame. The ideal step is p_next = p0 + dt * j for
the joystick command j = (xdot, ydot, thetadot) in the robot's (stance foot's)
frame; the paper quantises it to the nearest f_i of a precomputed target set F
(:class:`~ijoy_jax.targets.Targets`, a lattice; :mod:`ijoy_jax.targets`), and both
selectors score against that f_i by default so their ``.cost`` agree.

Selectors (same step on the same inputs)::

  "exhaustive": FootCost of every action in parallel, then the argmin.
  "ordered":    the paper's algorithm: walk L_i (the actions sorted by dist
                to f_i, precomputed) in chunks, keeping the best so far, and
                stop once best <= w * dist(next action, f_i): FootCost >= 0,
                so nothing later can win. In 2D, with zero action costs, this
                stops at the first valid step.
  "naive":      the conventional joystick of the paper's Fig. 3: the action
                nearest the target, whatever the terrain (``pose`` and
                ``index`` are that action; ``valid`` says whether its
                foothold is actually valid).
  "lookahead":  beyond the paper: the first step of the best sequence of
                ``horizon`` steps under the held command, feet alternating
                (:mod:`ijoy_jax.lookahead`: exact for any horizon, or a beam);
                a horizon of 1 is "exhaustive".

The method and the rest of the search's options are one value, a
:class:`~ijoy_jax.SelectOptions` (``ij.SelectOptions(method="ordered")``).
Any of the terrain-aware methods can be followed by a continuous refinement of
the chosen step (``SelectOptions(refine=True)``, :mod:`ijoy_jax.refine`): (dx, dy, dtheta) off
the lattice, on the exact cost against p_next, never costlier than the lattice
step; ``index`` stays the lattice action it started from.

Ties break the same way in every method: lowest cost, then lowest dist to the
target, then lowest action index (L_i is sorted by (dist, index)). Costs that
differ only by float rounding may be decided differently by the two methods.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ijoy_jax import geometry, lookahead, select_options
from ijoy_jax import refine as refine_mod
from ijoy_jax.footcost import TerrainIndex, foot_cost_fused, foot_cost_terms, index_terrain, query_supported
from ijoy_jax.footcost import validate as validate_foot_cost
from ijoy_jax.footcost.plane import plane_metrics
from ijoy_jax.footcost.query import poses_supported, safe_poses
from ijoy_jax.footcost.xla import footprint_blocked
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.robots import Robot, check_robot, mirror, side_actions, side_p0, side_sign
from ijoy_jax.select_options import SelectOptions as SelectOptions
from ijoy_jax.select_options import checked
from ijoy_jax.struct import as_array, as_pose, check_numeric, is_traced
from ijoy_jax.targets import Targets as Targets
from ijoy_jax.targets import action_dists as action_dists
from ijoy_jax.targets import ideal_step as ideal_step
from ijoy_jax.targets import make_targets as make_targets
from ijoy_jax.terrain import Terrain

METHODS = select_options.METHODS
"""The selectors (:class:`~ijoy_jax.SelectOptions` ``method``; the module docstring describes each)."""
KERNELS = select_options.KERNELS
"""How FootCost is computed (:class:`~ijoy_jax.SelectOptions` ``kernel``): XLA, or the fused Pallas kernel."""
_ORDERED_CHUNK = 32  # actions per chunk of the ordered search when select_step's chunk is None


class StepChoice(NamedTuple):
    """Result of :func:`select_step` (one decision; vmapped calls add leading axes).

    Fields::

      pose: (3,) world pose of the chosen swing foot (the step-in-place pose
        when no step is valid, so it is never NaN).
      foothold: (6,) float32 full world pose of the sole at ``pose``:
        x, y (m), z (m), roll, pitch, yaw (rad). x, y and yaw are ``pose``'s;
        z, roll and pitch are the sole's at rest on the ground under its
        contact points (:func:`foothold`, :mod:`ijoy_jax.footcost.sole`): its
        height at the foot centre and its orientation with that yaw,
        ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (as
        :func:`ijoy_jax.sim.kinematics.rpy_to_rot`; the sole's z axis is its
        plane's upward normal: :func:`ijoy_jax.footcost.plane.sole_tilt`). z,
        roll and pitch are 0 on a 2D terrain. What a robot's footstep message
        carries; the control loop passes it to the walker.
      valid: () bool, False when no valid step exists: the caller stops walking.
      cost: () float32, FootCost + w * dist of the choice (+inf if not valid).
      foot_cost: () float32, the FootCost part of ``cost`` (action cost plus
        terrain terms; +inf if the foothold is invalid).
      index: () int32 index into the action set (-1 when not valid).
      target: (3,) world pose the choice was scored against (f_i, or p_next).
      command_ok: () bool, False if the command had NaN/inf (treated as zero).
      evaluated: () int32 number of actions whose FootCost was computed.
      unsupported: () bool, True when the robot's or terrain's values (set by
        ``replace`` or vmap inside a trace) are outside what FootCost supports:
        a margin or footprint beyond the static windows, a negative margin,
        weight or cost, NaN/inf, a non-finite origin or height, a map beyond
        ``MAX_COORDINATE`` (:func:`~ijoy_jax.footcost.query_supported`);
        or when the query's own traced values are: a stance or swing pose
        that is not finite or turns beyond
        :data:`~ijoy_jax.geometry.MAX_ANGLE`, a stance side other than +1 or
        -1 (:func:`~ijoy_jax.footcost.query.poses_supported`; ``pose``,
        ``foothold`` and ``target`` then come from finite stand-ins).
        Then no step is valid
        (``valid`` False, ``cost`` +inf): the reason a robot stops.
    """

    pose: jax.Array
    foothold: jax.Array
    valid: jax.Array
    cost: jax.Array
    foot_cost: jax.Array
    index: jax.Array
    target: jax.Array
    command_ok: jax.Array
    evaluated: jax.Array
    unsupported: jax.Array


class Prepared(NamedTuple):
    """What a selector needs of one terrain and one robot, built once for many decisions (:func:`prepare`).

    index: the terrain's :class:`~ijoy_jax.footcost.TerrainIndex` for this
      robot's static windows (height tables padded by ``index.pad`` cells,
      obstacle prefix counts, kernel window sums; float32 / int32 arrays
      sized by the terrain grid).
    targets: the robot's :class:`~ijoy_jax.targets.Targets`: F and L_i, ``order`` (``|F|``, N)
      int32 and ``dist`` (``|F|``, N) float32.
    """

    index: TerrainIndex
    targets: Targets


def prepare(terrain: Terrain, robot: Robot, *, targets: Targets | None = None) -> Prepared:
    """Build the per-terrain and per-robot tables once, for many decisions on one terrain.

    Pass ``index=p.index, targets=p.targets`` to :func:`select_step` (the
    rollout, the tuners and the sweeps do). Traceable: call it inside your jit
    (it is what :func:`select_step` builds when not given them).

    Args:
      terrain: one Terrain.
      robot: the robot model (its windows size the index; its actions and
        rotation weight give L_i).
      targets: a prebuilt :func:`make_targets` of this robot, reused as is;
        None: built here (a sort of ``|F|`` x N entries).

    Returns:
      :class:`Prepared`.

    Example:
      >>> import ijoy_jax as ij
      >>> terrain, robot = ij.terrain.flat((100, 100), 0.02), ij.robots.hrp2()
      >>> p = ij.select.prepare(terrain, robot)
      >>> c = ij.select_step(terrain, robot, [1.0, 1.0, 0.0], -1, [0.2, 0.0, 0.0], index=p.index, targets=p.targets)
      >>> bool(c.valid)
      True
    """
    return Prepared(index_terrain(terrain, robot), make_targets(robot) if targets is None else targets)


def on_obstacle(terrain: Terrain, robot: Robot, pose, *, index: TerrainIndex | None = None, margin=0.0) -> jax.Array:
    """() bool: the bare footprint (no safety margin) at world ``pose`` (3,) overlaps an obstacle or leaves the map.

    How the rollout scores a foothold once taken (``Trajectory.on_obstacle``): a
    naive joystick steps onto obstacles, the selector never does. ``margin``
    (m, default 0): the footprint grown by that much instead, e.g. whether an
    obstacle lies within 4 cm of the foot (``Trajectory.near_obstacle``); it must
    fit the robot's static window (``max_margin``); a traced margin that is
    negative or NaN reads True. ``index``: the terrain's prebuilt index
    (:func:`prepare`), built inside when None. Only the footprint's cells are
    looked up (FootCost's obstacle test, :func:`ijoy_jax.footcost.xla.footprint_blocked`).
    """
    pose = as_array("pose", pose)
    if np.shape(pose) != (3,):
        raise ValueError(f"pose must have shape (3,) (x, y, yaw), got {np.shape(pose)}")
    check_numeric("margin", margin)
    if not is_traced(margin) and not (np.shape(margin) == () and float(margin) >= 0.0):
        raise ValueError(f"margin must be a number >= 0 (m), got {margin!r}")
    validate_foot_cost(terrain, robot, pose, 1, pose[None], index=index)  # types, a finite pose, the map's frame
    # the footprint grown by the margin within the robot's static window, the rule FootCost's robot check holds
    check_robot(robot.replace(margin=jnp.zeros_like(robot.margin) + jnp.asarray(margin, robot.margin.dtype)))
    if index is None:
        index = index_terrain(terrain, robot)
    pose = jnp.asarray(pose, jnp.float32)
    pose = jnp.where(jnp.all(jnp.isfinite(pose)), pose, 0.0)  # as FootCost takes a traced non-finite step
    grow = jnp.asarray(margin, jnp.float32)
    hl, hw = 0.5 * robot.foot_length + grow, 0.5 * robot.foot_width + grow
    return footprint_blocked(terrain, index, pose, hl, hw)[1] | ~(grow >= 0.0)


def foothold(terrain: Terrain, robot: Robot, pose, *, index: TerrainIndex | None = None) -> jax.Array:
    """(6,) float32 full world pose ``(x, y, z, roll, pitch, yaw)`` of a sole put down at ``pose`` (3,) (m, rad).

    x, y and yaw are the pose's; z, roll and pitch are the rested sole's
    (:func:`ijoy_jax.footcost.plane.plane_metrics`, :mod:`ijoy_jax.footcost.sole`): the sole on the ground
    under its contact points, its height at the foot centre and its orientation
    (``R = Rz(yaw) Ry(pitch) Rx(roll)``, :func:`ijoy_jax.footcost.plane.sole_tilt`'s convention).
    Zeros on a 2D terrain; finite wherever the pose is (beyond the map's
    edge its heights continue the edge's). Traceable (one FootCost plane):
    :func:`select_step` returns it as :attr:`StepChoice.foothold`.
    ``index``: the terrain's prebuilt index (:func:`prepare`), built inside when None.
    """
    pose = jnp.asarray(pose, jnp.float32)
    zero = jnp.zeros((), jnp.float32)
    if not terrain.has_height:
        return jnp.stack([pose[0], pose[1], zero, zero, zero, pose[2]])
    if index is None:
        index = index_terrain(terrain, robot)
    plane = plane_metrics(terrain, index, robot, pose)
    z, roll, pitch = (jnp.where(jnp.isfinite(v), v, zero).astype(jnp.float32)
                      for v in (plane.rest_height, plane.rest_roll, plane.rest_pitch))
    return jnp.stack([pose[0], pose[1], z, roll, pitch, pose[2]])


def validate(terrain, robot, stance, stance_side, command, options: SelectOptions | None = None, *, swing_from=None,
             targets=None, index=None, foot_costs=None) -> SelectOptions:
    """Check the arguments of :func:`select_step` (raises ValueError / TypeError); returns the options (None:
    the defaults) checked against the robot: the beam and the refinement's starts at most its N, no
    refinement with the naive method.

    Values of tracers are not checked (their shapes are), so it costs nothing
    inside a trace; :func:`ijoy_jax.rollout` runs it on its own arguments.
    """
    options = checked(options, robot)
    validate_foot_cost(terrain, robot, stance, stance_side, np.zeros((1, 3)), swing_from, index)
    check_numeric("command", command)
    if np.shape(command) != (3,):
        raise ValueError(f"command must have shape (3,) (xdot, ydot, thetadot), got {np.shape(command)}")
    if targets is not None and not isinstance(targets, Targets):
        raise TypeError(f"targets must be an ijoy_jax.select.Targets (make_targets), got {type(targets).__name__}")
    if foot_costs is not None:
        if options.method not in ("exhaustive", "lookahead"):
            raise ValueError(f"foot_costs (every action's FootCost) serve method='exhaustive' or 'lookahead' only, "
                             f"got {options.method!r}")
        check_numeric("foot_costs", foot_costs)
        if np.shape(foot_costs) != (robot.num_actions,):
            raise ValueError(f"foot_costs must have shape ({robot.num_actions},) (one FootCost per action), "
                             f"got {np.shape(foot_costs)}")
        if not is_traced(foot_costs) and np.any(np.isnan(np.asarray(foot_costs, np.float64))
                                                | (np.asarray(foot_costs, np.float64) < 0)):
            raise ValueError("foot_costs must be >= 0 or +inf (FootCost of each action; action_foot_costs), "
                             "got NaN or a negative value")
    return options


def _costs_of(terrain, robot, stance, side, steps, idx, swing_from, index, kernel, active=True) -> jax.Array:
    """FootCost totals of the actions ``idx`` put down at world ``steps``: the one mechanism of every selector.

    ``active`` False (traced: a vmapped search's finished query) lets the fused kernel skip the work; its totals
    are then +inf, and the caller discards them. The XLA path evaluates every query of a batch either way."""
    if kernel == "pallas":
        return foot_cost_fused(terrain, robot, stance, side, steps, swing_from=swing_from, action_index=idx,
                               index=index, active=active)
    return foot_cost_terms(terrain, robot, stance, side, steps, swing_from=swing_from, action_index=idx,
                           index=index).total


def action_foot_costs(terrain: Terrain, robot: Robot, stance, stance_side, *, swing_from=None,
                      index: TerrainIndex | None = None, kernel: str = "xla") -> jax.Array:
    """(N,) float32 FootCost of every action of S from one stance: the evaluation the exhaustive selector makes.

    Entry ``i`` is the FootCost of action ``i`` (``robot.actions[i]``, mirrored
    for a right swing foot) put down from ``stance``: action cost plus terrain
    terms, ``+inf`` where the foothold is invalid (and everywhere when the
    robot's or terrain's values are unsupported). Pass it to
    :func:`select_step` (``foot_costs=``) so that a decision and anything else
    that needs the whole action set (e.g. :func:`ijoy_jax.cue.feasible_commands`)
    share one evaluation. Traceable: call it inside your jit (called eagerly,
    FootCost runs through its own module-level jit).

    Args:
      terrain, robot, stance, stance_side, swing_from, index: as
        :func:`select_step` (stance (3,) world pose in m, rad; stance_side +1
        left, -1 right).
      kernel: "xla" or "pallas" (static), as a :class:`~ijoy_jax.SelectOptions`' ``kernel``.

    Returns:
      (N,) float32 FootCost, ``>= 0`` or ``+inf``.

    Example:
      >>> import ijoy_jax as ij
      >>> terrain, robot = ij.terrain.flat((100, 100), 0.02), ij.robots.hrp2()
      >>> fc = ij.select.action_foot_costs(terrain, robot, [1.0, 1.0, 0.0], -1)
      >>> fc.shape, bool((fc == 0).all())
      ((496,), True)
    """
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")
    stance, swing_from = as_pose("stance", stance), as_pose("swing_from", swing_from)
    ok = poses_supported(stance, stance_side, swing_from)  # the raw side: side_sign would make 7 a valid +1
    stance, swing_from = safe_poses(stance, swing_from)
    side = side_sign(stance_side)
    steps = geometry.compose(stance, side_actions(robot, -side))
    idx = jnp.arange(robot.num_actions, dtype=jnp.int32)
    return jnp.where(ok, _costs_of(terrain, robot, stance, side, steps, idx, swing_from, index, kernel), jnp.inf)


def _select(terrain, robot, stance, stance_side, command, swing_from, targets, index, foot_costs,
            options: SelectOptions) -> StepChoice:
    """The body of :func:`select_step` (always run through :data:`_select_jit`)."""
    method, kernel, chunk, discount, refine = (options.method, options.kernel, options.chunk, options.discount,
                                               options.refine)
    if index is None:
        index = index_terrain(terrain, robot)
    # A traced stance or swing pose that is not finite (or turns beyond MAX_ANGLE), or a side other than +-1:
    # flagged unsupported, decided from finite stand-ins so that no NaN reaches the choice.
    poses_ok = poses_supported(stance, stance_side, swing_from)
    stance, swing_from = safe_poses(stance, swing_from)
    side = side_sign(stance_side)
    swing = -side
    n = robot.num_actions
    quantize = options.quantize or method == "ordered"
    dists, target_rel, ok = action_dists(robot, side, command, targets, quantize=quantize)
    steps = geometry.compose(stance, side_actions(robot, swing))  # (N, 3)

    def terms_of(idx, active=True):
        return _costs_of(terrain, robot, stance, side, steps[idx], idx, swing_from, index, kernel, active)

    supported = query_supported(terrain, robot) & poses_ok  # FootCost's own rules
    plan_rest = None  # the lookahead's planned steps after this one (refinement keeps them valid)
    if method == "naive":
        best = jnp.argmin(dists).astype(jnp.int32)  # lowest dist, then lowest index
        fc = terms_of(best[None])[0]
        cost = fc + robot.w * dists[best]
        evaluated = jnp.int32(1)
    elif method in ("exhaustive", "lookahead"):
        fc_all = terms_of(jnp.arange(n, dtype=jnp.int32)) if foot_costs is None else foot_costs.astype(jnp.float32)
        cost_all = fc_all + robot.w * dists
        evaluated = jnp.int32(n)
        if method == "lookahead" and options.horizon > 1:
            plan = _search(terrain, robot, stance, side, command, swing_from, targets, index, options, cost_all,
                           dists, steps)
            best = jnp.maximum(plan.first, 0)
            plan_rest = plan.sequence[1:]
            evaluated = evaluated + plan.evaluated
            supported = supported & lookahead.discount_supported(discount)
        else:
            best = _lexmin(cost_all, dists)
        cost, fc = cost_all[best], fc_all[best]
    else:
        fi = targets.nearest(mirror(swing, ideal_step(robot, side, command)[0]))
        best, cost, fc, evaluated = _ordered(terms_of, targets.order[fi], dists, robot.w, n,
                                             _ORDERED_CHUNK if chunk is None else chunk)
    valid = jnp.isfinite(cost) & supported  # e.g. w < 0: the search's early exit is wrong and its cost negative
    target = geometry.compose(stance, target_rel)
    pose = steps[best]
    if refine is not None:
        p_next = ideal_step(robot, side, command)[0]
        r = refine_mod.refine_step(terrain, robot, stance, side, p_next, jnp.where(valid, best, -1), refine,
                                   swing_from=swing_from, index=index, continuation=plan_rest)
        supported = supported & refine_mod.params_supported(refine)
        valid = jnp.isfinite(r.cost) & supported
        pose, cost, fc, best = r.pose, r.cost, r.foot_cost, jnp.maximum(r.index, 0)
        target = geometry.compose(stance, p_next)
        evaluated = evaluated + r.evaluated
    in_place = geometry.compose(stance, side_p0(robot, swing))
    # The naive joystick steps to its action whatever the terrain; the others
    # report no step (index -1, the step-in-place pose) when none is valid.
    chosen = valid | (method == "naive")
    pose = jnp.where(chosen, pose, in_place)
    return StepChoice(
        pose=pose,
        foothold=foothold(terrain, robot, pose, index=index),
        valid=valid,
        cost=jnp.where(valid, cost, jnp.inf),
        foot_cost=jnp.where(valid, fc, jnp.inf),
        index=jnp.where(chosen, best, -1).astype(jnp.int32),
        target=target,
        command_ok=ok,
        evaluated=evaluated,
        unsupported=~supported,
    )


def _search(terrain, robot, stance, side, command, swing_from, targets, index, options: SelectOptions, cost_all,
            dists, steps) -> lookahead.Plan:
    """The lookahead's search from the first level's costs: its FootCost oracle is this module's (either
    kernel), its second level's dists those of the other foot for the same command."""
    n, kernel, chunk = robot.num_actions, options.kernel, options.chunk

    def costs_from(st, sd, sf):
        at = geometry.compose(st, side_actions(robot, -sd))
        return _costs_of(terrain, robot, st, sd, at, jnp.arange(n, dtype=jnp.int32),
                         None if swing_from is None else sf, index, kernel)

    dists2, _, _ = action_dists(robot, -side, command, targets, quantize=options.quantize)
    return lookahead.search(cost_all, steps, stance, side, swing_from, costs_from, robot, (dists, dists2),
                            options.discount, horizon=options.horizon, beam=options.beam,
                            chunk=lookahead.DEFAULT_CHUNK if chunk is None else chunk)


def _plan(terrain, robot, stance, stance_side, command, swing_from, targets, index,
          options: SelectOptions) -> lookahead.Plan:
    """The body of :func:`lookahead_plan` (run through :data:`_plan_jit`)."""
    if index is None:
        index = index_terrain(terrain, robot)
    poses_ok = poses_supported(stance, stance_side, swing_from)
    stance, swing_from = safe_poses(stance, swing_from)
    side = side_sign(stance_side)
    n = robot.num_actions
    dists, _, _ = action_dists(robot, side, command, targets, quantize=options.quantize)
    steps = geometry.compose(stance, side_actions(robot, -side))
    fc = _costs_of(terrain, robot, stance, side, steps, jnp.arange(n, dtype=jnp.int32), swing_from, index,
                   options.kernel)
    fc = jnp.where(poses_ok, fc, jnp.inf)  # an unsupported query plans nothing (Plan.valid False)
    return _search(terrain, robot, stance, side, command, swing_from, targets, index, options,
                   fc + robot.w * dists, dists, steps)


_plan_jit = jax.jit(_plan)


def lookahead_plan(terrain: Terrain, robot: Robot, stance, stance_side, command, options: SelectOptions | None = None,
                   *, swing_from=None, targets: Targets | None = None,
                   index: TerrainIndex | None = None) -> lookahead.Plan:
    """The lookahead's whole plan for one decision: its best sequence, score and whether it fell back.

    What :func:`select_step` with ``method="lookahead"`` decides from (its ``index`` is ``plan.first``), for
    a caller that wants the planned steps or the sequence's score (:class:`ijoy_jax.lookahead.Plan`). Same
    arguments and checks as :func:`select_step`; ``options`` (None: ``SelectOptions(method="lookahead")``,
    horizon 2) has ``method="lookahead"`` and a horizon of at least 2 (1 has no plan); its ``refine`` is
    not used (the plan is the lattice search's).

    Example:
      >>> import ijoy_jax as ij
      >>> terrain, robot = ij.terrain.flat((100, 100), 0.02), ij.robots.hrp2()
      >>> plan = ij.select.lookahead_plan(terrain, robot, [1.0, 1.0, 0.0], -1, [0.25, 0.0, 0.0])
      >>> [robot.actions[int(a)].tolist() for a in plan.sequence]   # left foot, then right (stored as left)
      [[0.20000000298023224, 0.1899999976158142, 0.0], [0.20000000298023224, 0.1899999976158142, 0.0]]
    """
    stance, swing_from = as_pose("stance", stance), as_pose("swing_from", swing_from)
    command = as_array("command", command)
    options = SelectOptions(method="lookahead") if options is None else options
    options = validate(terrain, robot, stance, stance_side, command, options, swing_from=swing_from,
                       targets=targets, index=index)
    if options.method != "lookahead":
        raise ValueError(f"lookahead_plan needs options with method='lookahead', got {options.method!r}")
    if options.horizon < 2:
        raise ValueError(f"lookahead_plan needs a horizon of at least 2 (1 is the one-step selector), got "
                         f"{options.horizon}")
    targets = make_targets(robot) if targets is None else targets
    swing_from = swing_from if options.swing_path else None
    return _plan_jit(terrain, robot, stance, stance_side, command, swing_from, targets, index,
                     options.replace(refine=None))


def _lexmin(cost, dists):
    """Index of the lowest cost, ties by lowest dist, then lowest index."""
    is_min = cost == jnp.min(cost)
    d = jnp.where(is_min, dists, jnp.inf)
    return jnp.argmin(d).astype(jnp.int32)  # argmin returns the first of equal values


def _ordered(terms_of, order, dists, w, n, chunk):
    """The paper's ordered traversal of L_i, a chunk of actions at a time.

    Vmapped over queries, the loop runs until the batch's slowest query is done and every query goes through
    the body each time: ``terms_of`` is told which queries are still searching (``active``), so that the
    fused kernel does no work for the finished ones (most queries finish in a few chunks, the slowest of a
    large batch near the last)."""
    chunk = min(chunk, n)
    num_chunks = -(-n // chunk)
    pad = num_chunks * chunk - n
    # Carry dtypes are explicit (int32 positions, float32 costs), so the loop also types under jax_enable_x64.
    order = jnp.concatenate([order, jnp.full((pad,), order[-1], jnp.int32)])
    d_sorted = jnp.concatenate([dists[order[:n]], jnp.full((pad,), jnp.inf, dists.dtype)]).astype(jnp.float32)

    def searching(state):
        k, best_cost, _, _ = state
        nxt = jnp.minimum(k * chunk, n - 1)
        # Stop once the best so far cannot be beaten by anything not yet seen.
        done = (k > 0) & (best_cost <= w * d_sorted[nxt])
        return (k < num_chunks) & ~done

    def body(state):
        k, best_cost, best_fc, best_pos = state
        pos = k * chunk + jnp.arange(chunk, dtype=jnp.int32)
        idx = lax.dynamic_slice(order, (k * chunk,), (chunk,))
        fc = terms_of(idx, searching(state))  # False only for a finished query of a vmapped batch
        c = (fc + w * lax.dynamic_slice(d_sorted, (k * chunk,), (chunk,))).astype(jnp.float32)
        c = jnp.where(pos < n, c, jnp.inf)
        j = jnp.argmin(c)  # first in L_i order among equal costs
        better = c[j] < best_cost
        return (k + 1, jnp.where(better, c[j], best_cost), jnp.where(better, fc[j], best_fc),
                jnp.where(better, pos[j], best_pos))

    init = (jnp.int32(0), jnp.float32(jnp.inf), jnp.float32(jnp.inf), jnp.int32(0))
    k, best_cost, best_fc, best_pos = lax.while_loop(searching, body, init)
    return order[best_pos], best_cost, best_fc, jnp.minimum(k * chunk, n).astype(jnp.int32)


def select_step(
    terrain: Terrain,
    robot: Robot,
    stance,
    stance_side,
    command,
    options: SelectOptions | None = None,
    *,
    swing_from=None,
    targets: Targets | None = None,
    index: TerrainIndex | None = None,
    foot_costs=None,
) -> StepChoice:
    """Choose the next swing-foot placement for a joystick command.

    Args:
      terrain: one Terrain (vmap for batches), within
        :data:`~ijoy_jax.footcost.MAX_COORDINATE` m of the world origin, where
        float32 holds millimetres (a UTM-scale origin is refused: shift your
        world frame; traced inside a jit, every step is flagged invalid).
      robot: the robot model; ``robot.w`` and ``robot.rotation_weight`` weigh dist.
      stance: (3,) world pose of the stance foot (m, rad). A concrete heading
        beyond :data:`~ijoy_jax.geometry.MAX_ANGLE` (1024 rad) is reduced by
        whole turns in float64 first; a traced one is flagged
        ``unsupported``, as a traced NaN is.
      stance_side: +1 if the stance foot is the left one (the right foot
        swings), -1 if it is the right one (traced: anything else is flagged).
      command: (3,) joystick command (xdot m/s, ydot m/s, thetadot rad/s) in
        the stance foot's frame. NaN/inf: treated as zero and flagged.
      options: how the step is searched for, a :class:`~ijoy_jax.SelectOptions`
        (None: its defaults, the exhaustive method): the method ("exhaustive",
        "ordered" (the paper's search), "naive" or "lookahead", the first step
        of the best ``horizon``-step sequence, :mod:`ijoy_jax.lookahead`), the
        FootCost kernel, quantisation, the swing-path check, the lookahead's
        horizon, beam and discount, and refinement: with ``refine``,
        ``pose`` is the refined step, ``index`` the lattice action it started
        from, ``cost`` and ``target`` are against p_next (:mod:`ijoy_jax.refine`).
      swing_from: (3,) current world pose of the swing foot, for the swing-path
        check on 2.5D terrains (None, or ``options.swing_path`` False: no check).
      targets: a prebuilt :func:`make_targets` (F and L_i); built if None.
      index: the terrain's prebuilt :class:`~ijoy_jax.footcost.TerrainIndex`;
        built if None. For many decisions on one terrain build both once
        with :func:`prepare`.
      foot_costs: (N,) every action's FootCost from this stance, already
        evaluated (:func:`action_foot_costs`, or the ``cost`` of
        :func:`ijoy_jax.cue.feasible_commands`): the exhaustive method decides
        from them instead of evaluating FootCost again (the same choice).
        None: evaluated here. Only with the methods "exhaustive" and
        "lookahead" (its first level).

    Returns:
      :class:`StepChoice`.

    The public entry point and the function to call inside your own jit or
    vmap: the checks skip traced values (the options' static fields key the
    program; ``discount`` and ``refine``'s leaves are traced: changing them
    never recompiles), and the work runs through one module-level jit (an
    eager loop compiles once; inside your jit it is inlined).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> free = np.ones((100, 100), bool); free[55:, :] = False      # wall at x = 1.1 m
      >>> terrain = ij.terrain.from_arrays(None, free, 0.02)
      >>> robot = ij.robots.hrp2(margin=0.02)
      >>> c = ij.select_step(terrain, robot, [0.8, 1.0, 0.0], -1, [0.25, 0.0, 0.0])
      >>> bool(c.valid), round(float(c.pose[0]), 2)   # as far forward as the wall allows
      (True, 0.95)
    """
    stance, swing_from = as_pose("stance", stance), as_pose("swing_from", swing_from)
    command = as_array("command", command)
    foot_costs = as_array("foot_costs", foot_costs)
    options = validate(terrain, robot, stance, stance_side, command, options, swing_from=swing_from,
                       targets=targets, index=index, foot_costs=foot_costs)
    targets = make_targets(robot) if targets is None else targets  # outside the jit: one program with or without
    swing_from = swing_from if options.swing_path else None
    return _select_jit(terrain, robot, stance, stance_side, command, swing_from, targets, index, foot_costs, options)


_select_jit = jax.jit(_select)


def compiled_programs() -> int:
    """How many programs :func:`select_step` and :func:`lookahead_plan` hold compiled (in this process).

    Read it before and after a loop of calls to learn how many compiles the loop caused: each new input
    shape or static option (:class:`~ijoy_jax.SelectOptions`' static fields, ``refine``'s included) compiles
    once; new terrain values, robot parameters, commands, ``discount`` or ``refine``'s leaves reuse the
    program.
    """
    return compiled_count(_select_jit) + compiled_count(_plan_jit)
