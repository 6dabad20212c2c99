"""The joystick control loop (the paper's Algorithm 1) as one scanned, jit-able rollout.

Each iteration: GetJoystickCommand (from a schedule), ComputeStanceLocation
(the walker's future stance: where the robot will stand when it can next
change its trajectory), ComputeTargetLocation (p_next), GetNextStep (the
selector), then SendRobotCmd or StopWalking. The terrain is fixed over a
rollout (GetEnvironment), and its index is built once, outside the scan.

The robot that executes the steps is a :class:`Walker`: three pure functions
over a state pytree. :func:`perfect_walker` is the paper's simulated robot
(every step executed exactly); a physically simulated robot implements the
same three functions, and the selector is untouched.

The step chooser is the other seam, a :class:`Selector`: :func:`exact_selector`
is the paper's (``select.select_step`` and the Trajectory's metrics); the
relaxed, differentiable one of :mod:`ijoy_jax.tune.relaxed_rollout` is another.
:func:`loop` is Algorithm 1's bookkeeping (stance, stop, execute, the scan)
for any walker and selector, so every rollout in the package is this loop.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ijoy_jax import geometry, select
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.limits import check_num_steps
from ijoy_jax.robots import LEFT, Robot, footprints_overlap, side_actions
from ijoy_jax.select_options import SelectOptions, checked
from ijoy_jax.struct import as_array, as_pose, check_numeric, is_traced
from ijoy_jax.targets import Targets
from ijoy_jax.terrain import Terrain

NEAR_OBSTACLE = 0.04
"""m: a foothold taken with an obstacle cell within this distance of its bare footprint counts as near one
(``Trajectory.near_obstacle``): how close a selector puts the feet to obstacles, beyond its own margin."""


class StanceInfo(NamedTuple):
    """What the selector needs from the robot for the next decision."""

    stance: jax.Array  # (3,) world pose of the (future) stance foot
    stance_side: jax.Array  # () +1 left, -1 right
    swing_from: jax.Array  # (3,) world pose the swing foot starts from
    # (2,) m, world frame, or None (none): how far the robot's balance asks the next step to move (e.g. a pushed
    # robot's capture-point lead; ijoy_jax.sim.controller.WalkConfig.capture_gain). The exact selector measures
    # the candidates from the stance moved by it, so the step's foothold is still chosen on the terrain (rollouts
    # and sweeps; the live drive's decider and the other selectors measure from the stance itself).
    balance: jax.Array | None = None

class Walker(NamedTuple):
    """A robot that executes footsteps (optax-style: a tuple of pure functions).

    Fields::

      init(start (2, 3), first_swing ()) -> state
      stance(state) -> StanceInfo              (ComputeStanceLocation)
      execute(state, foothold (6,), go ()) -> state
                                               (SendRobotCmd if go else StopWalking,
                                                then WaitForNextStep)
      feet(state) -> (2, 3) world poses, row 0 left, row 1 right.
      log(state) -> pytree recorded after every step (optional; e.g. a physically
          simulated robot's placement error and falls), kept in Trajectory.log.
      warmup: loop iterations before the first decision (static int, default 0)
          in which the robot settles: ``execute`` is called with ``go=False``,
          the loop does not stop, and nothing of them is kept in the Trajectory.
          A robot that must stand a step before walking uses it instead of
          stepping in ``init``, so the step's code is traced (and compiled) once.

    ``foothold`` is the chosen step's full sole pose :attr:`ijoy_jax.select.StepChoice.foothold`:
    x, y, z (m), roll, pitch, yaw (rad), ``R = Rz(yaw) Ry(pitch) Rx(roll)``; z, roll and pitch
    those of the sole at rest on the ground (:mod:`ijoy_jax.footcost.sole`; 0 on a 2D terrain). A planar robot reads
    ``foothold[jnp.array([0, 1, 5])]``, the (x, y, yaw) pose.
    """

    init: Callable[[jax.Array, jax.Array], Any]
    stance: Callable[[Any], StanceInfo]
    execute: Callable[[Any, jax.Array, jax.Array], Any]
    feet: Callable[[Any], jax.Array]
    log: Callable[[Any], Any] | None = None
    warmup: int = 0

class _PerfectState(NamedTuple):
    feet: jax.Array  # (2, 3) row 0 left, row 1 right
    swing: jax.Array  # () +1 if the left foot swings next

def perfect_walker(dtype=jnp.float32) -> Walker:
    """The paper's simulated robot: each commanded step lands exactly where it was sent.

    ``dtype``: of its feet (float32; the relaxed rollout keeps float64 under x64).
    """

    def init(start, first_swing):
        return _PerfectState(jnp.asarray(start, dtype), jnp.asarray(first_swing, dtype))

    def stance(s):
        left_swings = s.swing > 0
        st = jnp.where(left_swings, s.feet[1], s.feet[0])
        sw = jnp.where(left_swings, s.feet[0], s.feet[1])
        return StanceInfo(st, -s.swing, sw)

    def execute(s, foothold, go):
        pose = foothold[jnp.array([0, 1, 5])]  # x, y, yaw: the planar pose of the sole
        row = jnp.where(s.swing > 0, 0, 1)
        feet = jnp.where(go, s.feet.at[row].set(pose), s.feet)
        return _PerfectState(feet, jnp.where(go, -s.swing, s.swing))

    return Walker(init, stance, execute, lambda s: s.feet)


class Selector(NamedTuple):
    """How the loop chooses each step (a tuple of pure functions, like :class:`Walker`): the seam of Algorithm 1's
    GetNextStep, so the exact selector and a relaxed one share :func:`loop`.

    Fields::

      choose(info: StanceInfo, command (3,), key) -> (foothold (6,), sendable () bool, choice)
          foothold: the sole pose the walker is sent (x, y, z, roll, pitch, yaw; ``Walker.execute``);
          sendable: whether it may be sent (Algorithm 1 stops walking when not); choice: any pytree
          handed on to ``record``. ``key``: this step's PRNG key (None unless :func:`loop` got keys).
      record(info, command, choice, go (), stopped (), before (2, 3), after (2, 3)) -> dict
          the step's records (scanned into arrays with a leading step axis): ``go`` whether the step
          was sent, ``stopped`` whether the robot has stopped, the feet before and after it.
    """

    choose: Callable[[StanceInfo, jax.Array, Any], tuple[jax.Array, jax.Array, Any]]
    record: Callable[..., dict]


class CommandFilter(NamedTuple):
    """How the joystick's commands are read before each decision, with a state carried from step to step: the
    part of the paper's Joystick Control between GetJoystickCommand and ComputeTargetLocation (a tuple of pure
    functions, like :class:`Walker`; traced inside :func:`loop`).

    Fields::

      init(start (2, 3), first_swing ()) -> state
      apply(state, info: StanceInfo, command (3,)) -> (state, command (3,))
          the command the selector is given (and the records measure against).

    :func:`rollout` takes a *spec* instead (``command_filter=``): a pytree whose leaves are traced and whose
    ``build(robot) -> CommandFilter`` makes the filter inside the trace (e.g.
    :func:`ijoy_jax.turning.heading_hold`), so its numbers never recompile.
    """

    init: Callable[[jax.Array, jax.Array], Any]
    apply: Callable[[Any, StanceInfo, jax.Array], tuple[Any, jax.Array]]


def loop(walker: Walker, selector: Selector, start, first_swing, commands, *, keys=None,
         remat: bool = False, command_filter: CommandFilter | None = None) -> tuple[Any, dict]:
    """Algorithm 1's bookkeeping for any walker and selector, as one ``lax.scan`` (trace it inside jit).

    Each iteration: the walker's stance (ComputeStanceLocation), the selector's choice, SendRobotCmd if it is
    sendable and the robot has not stopped, else StopWalking (the robot stays stopped), then the records. The
    walker's ``warmup`` iterations run first with nothing sent and nothing kept.

    Args:
      walker: the robot (:class:`Walker`).
      selector: the step chooser (:class:`Selector`).
      start: (2, 3) the feet, row 0 left (as the walker's ``init`` takes them).
      first_swing: () +1 if the left foot swings first.
      commands: (T, 3) one command per decision.
      keys: (T,) PRNG keys handed to ``selector.choose`` step by step (None: None each step).
      remat: recompute each step on the backward pass (:func:`jax.checkpoint`) instead of storing it.
      command_filter: reads each command before the selector does (:class:`CommandFilter`); None: as given.

    Returns:
      ``(final walker state, records)``: the records of :attr:`Selector.record` with a leading T axis, plus
      ``"log"`` (the walker's :attr:`Walker.log` after every step) when the walker has one.
    """
    state0 = walker.init(start, first_swing)
    filter0 = None if command_filter is None else command_filter.init(start, first_swing)

    def step(carry, xs):
        command, settling, key = xs
        state, stopped, fstate = carry
        info = walker.stance(state)
        if command_filter is not None:
            fstate, command = command_filter.apply(fstate, info, command)
        foothold, sendable, choice = selector.choose(info, command, key)
        go = ~stopped & sendable & ~settling
        now_stopped = stopped | (~go & ~settling)
        before = walker.feet(state)
        new_state = walker.execute(state, foothold, go)
        record = selector.record(info, command, choice, go, now_stopped, before, walker.feet(new_state))
        if walker.log is not None:
            record["log"] = walker.log(new_state)
        return (new_state, now_stopped, fstate), record

    warm = int(walker.warmup)
    num_steps = commands.shape[0]
    commands = jnp.concatenate([jnp.zeros((warm, 3), commands.dtype), commands])
    settling = jnp.arange(warm + num_steps) < warm
    if keys is not None and warm:
        keys = jnp.concatenate([keys[:1]] * warm + [keys])
    body = jax.checkpoint(step, prevent_cse=False) if remat else step
    (state, _, _), rec = lax.scan(body, (state0, jnp.bool_(False), filter0), (commands, settling, keys))
    if warm:
        rec = jax.tree_util.tree_map(lambda a: a[warm:], rec)
    return state, rec


class Trajectory(NamedTuple):
    """One rollout of the control loop (T = num_steps; vmapped rollouts add axes).

    Per step (T,) unless noted::

      footsteps: (T, 3) world pose of the swing foot after the step (the
        foothold put down; its old pose on steps not taken).
      sides: +1 if the left foot was the swing foot, -1 the right.
      valid: the chosen foothold is valid (FootCost < inf).
      taken: a step was executed (False once stopped).
      stopped: the robot has stopped walking (no valid step; it stays stopped).
      cost: the selector's cost of the choice (+inf if none).
      foot_cost: its FootCost part (action cost + terrain terms; +inf if the
        chosen foothold is invalid): how good the ground under the foot is.
      index: action index (-1 if none).
      target: (T, 3) world pose the choice was scored against.
      commanded: (T, 3) world pose sent to the robot (the chosen step; the
        swing foot's pose when none was sent). With a perfect walker it equals
        ``footsteps`` wherever a step was taken.
      footholds: (T, 6) the full sole pose passed to the walker with each
        decision (:attr:`ijoy_jax.select.StepChoice.foothold`: x, y, z, roll,
        pitch, yaw; m, rad), whether or not it was sent (``taken``): the
        chosen step's, or the step in place's when none was valid.
      command_ok: False where the command had NaN/inf (treated as zero).
      in_place: the step taken was the step-in-place action p0.
      stationary: the step taken put the swing foot back where it was (the
        robot marks time without p0, e.g. feet staggered before a blockage).
      on_obstacle: the foothold taken overlaps an obstacle cell or leaves the
        map (footprint without margin); 0 for the intelligent joystick.
      near_obstacle: the foothold taken has an obstacle cell (or the map's
        edge) within :data:`NEAR_OBSTACLE` (4 cm) of its bare footprint.
      along, across: displacement of the feet's midpoint (m) along and across
        the commanded direction (world frame at the decision; 0 for a zero
        command).
      deviation: |achieved - p_next| of the swing foot in the stance frame (m).
      rotation_deviation: |wrap(achieved - p_next)| rotation (rad).
      evaluated: actions whose FootCost was computed.
      unsupported: the robot's or terrain's values were outside what FootCost
        supports (:attr:`ijoy_jax.select.StepChoice.unsupported`): the reason
        no step was valid, so the robot stopped.

    feet: (2, 3) final foot poses (row 0 left).
    log: the walker's per-step log (leaves with a leading T axis), or None.
    """

    footsteps: jax.Array
    sides: jax.Array
    valid: jax.Array
    taken: jax.Array
    stopped: jax.Array
    cost: jax.Array
    foot_cost: jax.Array
    index: jax.Array
    target: jax.Array
    command_ok: jax.Array
    in_place: jax.Array
    stationary: jax.Array
    on_obstacle: jax.Array
    along: jax.Array
    across: jax.Array
    deviation: jax.Array
    rotation_deviation: jax.Array
    evaluated: jax.Array
    unsupported: jax.Array
    feet: jax.Array
    commanded: jax.Array | None = None
    footholds: jax.Array | None = None
    log: Any = None
    near_obstacle: jax.Array | None = None

    def summary(self) -> dict[str, jax.Array]:
        """Per-rollout totals over the last axis (jit- and vmap-friendly; 0-d arrays for one rollout).

        Counts are int32: ``steps_taken``, ``steps_in_place``, ``steps_stationary``,
        ``footholds_on_obstacles``, ``footholds_near_obstacles`` (:attr:`near_obstacle`; only when the
        trajectory records it) and ``invalid_footholds`` (steps taken onto a foothold with
        FootCost = +inf, e.g. the naive joystick stepping on an obstacle). ``stopped`` is bool.
        Floats: ``distance_along``, ``distance_across`` (m), ``mean_deviation`` from p_next (m)
        and ``mean_foot_cost``, the mean FootCost over every foothold taken: +inf as soon as one
        of them was invalid (infinite cost means impossible; it is never averaged away), 0 if no
        step was taken.
        Flagged inputs (int32 counts of decisions): ``commands_not_finite``, commands with NaN/inf,
        treated as zero (step in place), and ``unsupported_decisions``, decisions whose robot or
        terrain values were unsupported (:attr:`Trajectory.unsupported`), so a silent NaN in a command
        stream or a robot changed out of range shows up.
        """
        taken = self.taken
        count = lambda b: jnp.sum(b, axis=-1, dtype=jnp.int32)  # noqa: E731
        n_taken = count(taken)
        near = {} if self.near_obstacle is None else {"footholds_near_obstacles": count(self.near_obstacle & taken)}
        return {
            "steps_taken": n_taken,
            "steps_in_place": count(self.in_place & taken),
            "steps_stationary": count(self.stationary & taken),
            "stopped": jnp.any(self.stopped, axis=-1),
            "footholds_on_obstacles": count(self.on_obstacle & taken),
            "invalid_footholds": count(taken & ~self.valid),
            "distance_along": jnp.sum(self.along, axis=-1),
            "distance_across": jnp.sum(self.across, axis=-1),
            "mean_deviation": jnp.sum(self.deviation * taken, axis=-1) / jnp.maximum(n_taken, 1),
            "mean_foot_cost": jnp.sum(jnp.where(taken, self.foot_cost, 0.0), axis=-1) / jnp.maximum(n_taken, 1),
            "commands_not_finite": count(~self.command_ok),
            "unsupported_decisions": count(self.unsupported),
            **near,
        }

def exact_selector(terrain: Terrain, robot: Robot, options: SelectOptions | None = None, *,
                   targets: Targets | None = None, index=None, supported=True) -> Selector:
    """The paper's GetNextStep as a :class:`Selector`: :func:`ijoy_jax.select.select_step` (its full foothold
    sent; sendable when valid, always for ``"naive"``), recording the :class:`Trajectory` fields per step.

    ``options``: the search, as in :func:`rollout` (None: the defaults); ``index`` and ``targets``: the
    terrain's index and the targets, built by :func:`ijoy_jax.select.prepare` once per rollout (call it
    inside jit). ``supported`` (() bool, traced) False flags every decision ``unsupported`` (no step
    valid), as a non-finite stance is: what :func:`rollout` does with a traced start it cannot use.
    """
    options = checked(options, robot)
    if index is None or targets is None:
        prepared = select.prepare(terrain, robot, targets=targets)
        index = prepared.index if index is None else index
        targets = prepared.targets

    def choose(info, command, key):
        stance = info.stance if info.balance is None else info.stance.at[:2].add(info.balance)
        stance = jnp.where(supported, stance, jnp.nan)  # refused as any non-finite stance is
        choice = select.select_step(terrain, robot, stance, info.stance_side, command, options,
                                    swing_from=info.swing_from, targets=targets, index=index)
        return choice.foothold, choice.valid | (options.method == "naive"), choice

    def record(info, command, choice, go, stopped, before, after):
        swing_row = jnp.where(info.stance_side > 0, 1, 0)
        landed = after[swing_row]
        # the bare footprint and the one grown by NEAR_OBSTACLE as one batched lookup (one copy in the program)
        on_obs, near = jax.vmap(lambda m: select.on_obstacle(terrain, robot, landed, index=index, margin=m))(
            jnp.array([0.0, NEAR_OBSTACLE], jnp.float32))
        # Command-following metrics in the stance foot's frame at decision time.
        p_next, _ = select.ideal_step(robot, info.stance_side, command)
        achieved = geometry.relative(info.stance, landed)
        err = achieved - p_next
        cmd = jnp.where(jnp.all(jnp.isfinite(command)), command, 0.0)
        c, s = jnp.cos(info.stance[2]), jnp.sin(info.stance[2])
        dir_world = jnp.array([c * cmd[0] - s * cmd[1], s * cmd[0] + c * cmd[1]])
        norm = jnp.sqrt(jnp.sum(dir_world**2))
        unit = jnp.where(norm > 0, dir_world / jnp.where(norm > 0, norm, 1.0), 0.0)
        move = jnp.mean(after[:, :2], axis=0) - jnp.mean(before[:, :2], axis=0)
        # A refined step that left its lattice action is not the step in place, whatever its index.
        lattice = geometry.compose(info.stance, side_actions(robot, -info.stance_side)[
            jnp.maximum(choice.index, 0)])
        off_lattice_ok = jnp.max(jnp.abs(choice.pose - lattice)) < 1e-5
        return dict(
            footsteps=landed,
            sides=-info.stance_side.astype(jnp.int32),
            valid=choice.valid,
            taken=go,
            stopped=stopped,
            cost=choice.cost,
            foot_cost=choice.foot_cost,
            index=choice.index,
            target=choice.target,
            commanded=jnp.where(go, choice.pose, info.swing_from),
            footholds=choice.foothold,
            command_ok=choice.command_ok,
            in_place=go & (choice.index >= 0) & jnp.all(
                jnp.abs(robot.actions[jnp.maximum(choice.index, 0)] - robot.p0) < 1e-6) & off_lattice_ok,
            stationary=go & (jnp.max(jnp.abs(landed - info.swing_from)) < 1e-5),
            on_obstacle=go & on_obs,
            near_obstacle=go & near,
            along=jnp.dot(move, unit),
            across=unit[0] * move[1] - unit[1] * move[0],
            deviation=jnp.where(go, jnp.hypot(err[0], err[1]), 0.0),
            rotation_deviation=jnp.where(go, jnp.abs(geometry.wrap_angle(err[2])), 0.0),
            evaluated=choice.evaluated,
            unsupported=choice.unsupported,
        )

    return Selector(choose, record)


def _rollout(terrain, robot, start, commands, first_swing, targets, options, command_filter, num_steps,
             walker) -> Trajectory:
    """The body of :func:`rollout`, run through :data:`_rollout_jit` or inlined into a caller's trace."""
    walker = perfect_walker() if walker is None else walker
    index, targets = select.prepare(terrain, robot, targets=targets)
    commands = jnp.asarray(commands, jnp.float32)
    if commands.ndim == 1:
        commands = jnp.broadcast_to(commands, (num_steps, 3))
    # A traced start that is not finite (or turns beyond geometry.MAX_ANGLE): every decision flagged
    # unsupported, the feet kept at finite stand-ins, so no NaN reaches the trajectory.
    start = jnp.asarray(start, jnp.float32)
    start_ok = geometry.pose_supported(start)
    start = jnp.where(start_ok, start, 0.0)
    selector = exact_selector(terrain, robot, options, targets=targets, index=index, supported=start_ok)
    state, rec = loop(walker, selector, start, jnp.asarray(first_swing, jnp.float32),
                      commands[:num_steps],
                      command_filter=None if command_filter is None else command_filter.build(robot))
    return Trajectory(feet=walker.feet(state), **rec)

_rollout_jit = jax.jit(_rollout, static_argnames=("num_steps", "walker"))


def compiled_programs() -> int:
    """How many programs :func:`rollout` holds compiled (in this process).

    Read it before and after a loop of rollouts to learn how many compiles the loop caused: each new input
    shape, ``num_steps``, walker or static option (:class:`~ijoy_jax.SelectOptions`' static fields) compiles
    once; new terrain values, robot parameters, starts, commands, ``discount`` or ``refine``'s leaves reuse the
    program.
    """
    return compiled_count(_rollout_jit)

def _check_start(robot: Robot, start) -> None:
    """Refuse concrete start feet whose footprints overlap or that stand crossed (left foot on the right)."""
    size = (robot.foot_length, robot.foot_width)
    if is_traced(start, size):
        return
    feet = np.asarray(start, np.float64)
    length, width = (float(v) for v in size)

    def seen_from(a, b):  # pose of foot b in foot a's frame
        d = feet[b, :2] - feet[a, :2]
        c, s = np.cos(feet[a, 2]), np.sin(feet[a, 2])
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], feet[b, 2] - feet[a, 2]])

    left_seen = seen_from(1, 0)
    if footprints_overlap(left_seen, length, width)[0]:
        raise ValueError(f"start: the feet's footprints ({length} x {width} m) overlap, left {feet[0].tolist()}, "
                         f"right {feet[1].tolist()}; start with them apart (robots.start_stance)")
    if left_seen[1] < 0 or seen_from(0, 1)[1] > 0:
        raise ValueError(f"start: the feet are crossed, the left foot (row 0, {feet[0].tolist()}) is to the right of "
                         f"the right foot (row 1, {feet[1].tolist()}) in their own frames; row 0 is the left foot")


def rollout(
    terrain: Terrain,
    robot: Robot,
    start,
    commands,
    num_steps: int,
    options: SelectOptions | None = None,
    *,
    first_swing=LEFT,
    walker: Walker | None = None,
    targets: Targets | None = None,
    command_filter=None,
) -> Trajectory:
    """Walk the robot with the joystick for ``num_steps`` steps (Algorithm 1), jitted as one scan.

    Args:
      terrain: one Terrain (vmap over a batch of terrains).
      robot: the robot model (its leaves may be batched with vmap).
      start: (2, 3) world poses of the feet, row 0 left, row 1 right (m, rad).
      commands: (3,) one command (xdot m/s, ydot m/s, thetadot rad/s, in the
        stance foot's frame) held throughout, or (num_steps, 3) one per step.
      num_steps: number of decisions (static).
      options: each decision's search, a :class:`~ijoy_jax.SelectOptions`
        (None: its defaults) as :func:`ijoy_jax.select_step` takes it: the
        method ("exhaustive", "ordered" (same steps), "naive" (the
        conventional joystick: always steps to the action nearest p_next) or
        "lookahead" (the first step of the best ``horizon``-step sequence
        under the held command, :mod:`ijoy_jax.lookahead`)), the FootCost
        kernel ("pallas": the fused kernel; the same steps), quantisation
        against F's nearest target (the paper) or p_next, the swing corridor
        check on 2.5D terrains, and refinement (then ``index`` is the lattice
        action each step started from and ``footsteps`` the refined poses).
        Its static fields key the program; ``discount`` and ``refine``'s
        leaves are traced.
      first_swing: +1 if the left foot swings first (default), -1 the right
        (traced: a vmapped batch may mix both).
      walker: the robot executing the steps; default :func:`perfect_walker`.
      targets: prebuilt :func:`ijoy_jax.make_targets` of this robot (F and
        L_i); built inside the jitted rollout when None, which sorts ``|F|`` x N
        entries on every call (about 0.4 s on a 2-core CPU for HRP-2): pass
        it when calling repeatedly with the same actions and rotation weight.
      command_filter: how the joystick's commands are read before each
        decision: a spec whose ``build(robot)`` makes the
        :class:`CommandFilter` (a pytree: its leaves traced), e.g.
        :func:`ijoy_jax.turning.heading_hold` (the turning mode that does not
        overshoot when the turn axis is let go); None: as given.

    Returns:
      :class:`Trajectory`. Once no valid step exists the robot stops and
      stays stopped (``stopped``), as Algorithm 1 stops walking.

    The public entry point and the function to call inside your own jit or
    vmap (a batch of terrains, robots, starts or commands): the checks skip
    traced values (``num_steps``, ``walker`` and the options' static fields
    are static), and the work runs through one module-level jit (an eager loop compiles once; inside your jit it is
    inlined), except that a ``walker`` given with traced arguments is traced
    inline (it may close over the caller's traced values).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> terrain = ij.terrain.flat((150, 100), 0.02)
      >>> robot = ij.robots.hrp2()
      >>> start = np.array([[0.3, 1.095, 0.0], [0.3, 0.905, 0.0]])
      >>> traj = ij.rollout(terrain, robot, start, [0.25, 0.0, 0.0], num_steps=6)
      >>> round(float(traj.summary()["distance_along"]), 2)   # 0.1 + 5 * 0.2 m
      1.1
    """
    start, commands = as_pose("start", start), as_array("commands", commands)
    options = select.validate(terrain, robot, np.zeros(3), 1, np.zeros(3), options, targets=targets)
    if command_filter is not None and not callable(getattr(command_filter, "build", None)):
        raise TypeError(f"command_filter must be a filter spec with build(robot) -> CommandFilter (e.g. "
                        f"ijoy_jax.turning.heading_hold()), got {type(command_filter).__name__}")
    check_numeric("start", start)
    check_numeric("commands", commands)
    if np.shape(start) != (2, 3):
        raise ValueError(f"start must have shape (2, 3) (left foot, right foot), got {np.shape(start)}")
    with np.errstate(over="ignore"):  # finite as the float32 it is computed in (1e39 is not)
        bad_start = not isinstance(start, jax.core.Tracer) and not np.all(np.isfinite(np.asarray(start, np.float32)))
    if bad_start:
        raise ValueError("start must be finite")
    _check_start(robot, start)
    num_steps = check_num_steps(num_steps)
    cs = np.shape(commands)
    if cs not in ((3,), (num_steps, 3)):
        raise ValueError(f"commands must have shape (3,) or ({num_steps}, 3), got {cs}")
    if not isinstance(first_swing, jax.core.Tracer) and (np.shape(first_swing) != ()
                                                         or np.asarray(first_swing).dtype.kind not in "iuf"
                                                         or float(first_swing) not in (LEFT, -LEFT)):
        raise ValueError(f"first_swing must be +1 (left) or -1 (right), got {first_swing!r}")
    args = (terrain, robot, start, commands, first_swing, targets, options, command_filter)
    static = dict(num_steps=int(num_steps), walker=walker)
    # A walker built inside the caller's trace may close over its values (the MJX walker holds the traced
    # terrain): it is traced inline, not made a static key of the module jit's cache.
    inline = walker is not None and is_traced(args)
    return (_rollout if inline else _rollout_jit)(*args, **static)
