"""Turning without overshoot: a heading-hold mode for the joystick's turn axis, and the overshoot it removes.

The paper (section VI): "due to the fact that the robot is deciding where to step based on a future stance
location, there is a latency between issuing a joystick command, and when the robot takes a step in reaction
to that command ... when turning the robot to face a particular direction, it is easy to overshoot the desired
orientation." Two things carry the robot past the heading the operator saw when letting go of the turn axis:

* the feet turn one at a time. With a turn rate held, the swing foot lands ``step_time * thetadot`` beyond the
  stance foot, so the body's heading (the feet's mean yaw, what the operator sees) trails the foot that turned
  last by half a step's turn. Let go, and the rate mode (the paper's, ``thetadot = 0``: the swing foot lands
  parallel to the stance foot) brings the other foot up to it: the robot settles half a step's turn beyond
  the heading shown (10 deg at HRP-2's largest turn, 20 deg per step);
* the command is read ``latency`` decisions before the step it moves (the paper's future stance: one), and
  each of those steps keeps turning: a whole step's turn more per decision of latency.

The heading-hold mode (:func:`heading_hold`) reads the turn axis as the paper does while it is held. When it is
let go (``|thetadot|`` at most ``deadband``) it holds the heading the robot showed at that moment, the mean
yaw of the feet ``latency`` decisions before the decision that reads the release (when the operator let go),
and replaces the turn by the rate that puts each swing foot at that heading: the foot that had turned
furthest is brought back, and the robot settles on the heading the operator saw (within the action set's
rotation spacing, 6.7 deg for HRP-2 at the lattice; exactly with refinement, ``SelectOptions(refine=True)``).
A command's forward and sideways parts are untouched. It is a :class:`ijoy_jax.control.CommandFilter`, so it
works with any method and walker: ``ij.rollout(..., command_filter=ij.turning.heading_hold())``.

:func:`overshoot_study` measures both modes with a simulated operator (turn at a held rate until the heading
shown reaches a goal, then let go) on flat ground, with and without the paper's one-step latency.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import control, geometry, select
from ijoy_jax.refine import lattice_spacing
from ijoy_jax.robots import Robot, side_p0, side_sign, start_stance
from ijoy_jax.select_options import SelectOptions
from ijoy_jax.struct import is_traced, pytree_dataclass, static_field
from ijoy_jax.terrain import Terrain, flat

__all__ = ["HeadingHold", "OvershootResult", "body_heading", "heading_hold", "overshoot_study"]

_ANGLE_SLACK = 1e-4  # rad: float32 rounding of a heading difference (~1e-7) with room; 0.006 deg


def body_heading(left_yaw, right_yaw) -> jax.Array:
    """The robot's heading as an operator sees it: the mean yaw of its two feet (rad; the circular mean of two
    angles, ``a + wrap(b - a) / 2``)."""
    a = jnp.asarray(left_yaw, jnp.float32)
    return a + 0.5 * geometry.wrap_angle(jnp.asarray(right_yaw, jnp.float32) - a)


class _HoldState(NamedTuple):
    holding: jax.Array  # () bool: the turn axis is let go
    heading: jax.Array  # () float32 the heading held (rad, world)
    shown: jax.Array  # (latency + 1,) float32 the headings shown at the last decisions, oldest first


@pytree_dataclass
class HeadingHold:
    """The heading-hold turning mode (see the module docstring); :func:`heading_hold` builds it.

    Leaves (traced)::

      deadband: () float32 rad/s: a turn command this small counts as let go.
      tolerance: () float32, in rotation spacings of the action set (:func:`ijoy_jax.refine.lattice_spacing`):
        a stance foot within this of the held heading counts as on it, and the swing foot lands parallel to
        it. 0.5 (default): the lattice's nearest, so the feet settle parallel instead of alternating between
        the two rotations either side of the heading; 0 with ``refine``, which reaches it exactly.

    Static::

      latency: decisions between the operator's input and the decision that reads it (0 for this package's
        loop, which decides on the stance the robot stands on; 1 for the paper's future stance).
    """

    deadband: jax.Array
    tolerance: jax.Array
    latency: int = static_field()

    def build(self, robot: Robot) -> control.CommandFilter:
        """The :class:`ijoy_jax.control.CommandFilter` of this mode for ``robot`` (called inside the trace)."""
        n = self.latency + 1
        deadband = jnp.asarray(self.deadband, jnp.float32)
        close = jnp.asarray(self.tolerance, jnp.float32) * lattice_spacing(robot)[2]  # rad

        def init(start, first_swing):
            h = body_heading(start[0, 2], start[1, 2])
            return _HoldState(jnp.bool_(False), h, jnp.full((n,), h, jnp.float32))

        def apply(state, info: control.StanceInfo, command):
            command = jnp.asarray(command, jnp.float32)
            left_stands = info.stance_side > 0
            shown_now = body_heading(jnp.where(left_stands, info.stance[2], info.swing_from[2]),
                                     jnp.where(left_stands, info.swing_from[2], info.stance[2]))
            shown = jnp.concatenate([state.shown[1:], shown_now[None]])
            # A NaN or inf command is left as it is: the selector treats it as zero and flags it.
            released = jnp.all(jnp.isfinite(command)) & (jnp.abs(command[2]) <= deadband)
            heading = jnp.where(released & ~state.holding, shown[0], state.heading)
            p0_turn = side_p0(robot, -side_sign(info.stance_side))[2]
            off = geometry.wrap_angle(heading - info.stance[2])
            # On the heading (within float32 rounding of the tolerance: a foot exactly half a spacing off is as
            # close as the lattice gets): the swing foot lands parallel.
            off = jnp.where(jnp.abs(off) <= close + _ANGLE_SLACK, 0.0, off)
            hold = (off - p0_turn) / robot.step_time
            out = jnp.where(released, command.at[2].set(hold), command)
            return _HoldState(released, heading, shown), out

        return control.CommandFilter(init, apply)


def heading_hold(deadband: float = 1e-3, tolerance: float = 0.5, *, latency: int = 0) -> HeadingHold:
    """The heading-hold turning mode: the turn axis let go holds the heading shown when it was let go.

    Args:
      deadband: rad/s; a turn command of at most this magnitude counts as let go (a stick's rest noise).
      tolerance: rotation spacings of the action set within which a stance foot counts as on the heading
        (:class:`HeadingHold`; 0.5 on the lattice, 0 with ``refine``).
      latency: decisions between the operator's input and the decision that reads it (static; 0 for this
        package's loop; 1 for a robot that decides on its future stance, as the paper's).

    Returns:
      :class:`HeadingHold`, for ``ij.rollout(..., command_filter=...)``.

    Raises:
      ValueError: a deadband or tolerance not finite and >= 0, a latency not an int >= 0.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> terrain, robot = ij.terrain.flat((100, 100), 0.02), ij.robots.hrp2()
      >>> start = ij.robots.start_stance(robot, 1.0, 1.0)
      >>> turn = np.array([[0.0, 0.0, 0.436]] * 2 + [[0.0, 0.0, 0.0]] * 3)   # turn 2 steps, then let go
      >>> rate = ij.rollout(terrain, robot, start, turn, num_steps=5)
      >>> hold = ij.rollout(terrain, robot, start, turn, num_steps=5, command_filter=ij.turning.heading_hold())
      >>> # Shown when let go: 30 deg (feet at 20 and 40). Rate mode settles at 40; heading hold at the
      >>> # lattice's rotation nearest 30 (6.7 deg apart), 26.7.
      >>> [round(float(np.degrees(ij.turning.body_heading(*t.feet[:, 2]))), 1) for t in (rate, hold)]
      [40.0, 26.7]
    """
    if isinstance(latency, bool) or not isinstance(latency, (int, np.integer)) or latency < 0:
        raise ValueError(f"latency must be an int >= 0 (decisions), got {latency!r}")
    for name, v in (("deadband", deadband), ("tolerance", tolerance)):
        if not is_traced(v):
            d = np.asarray(v, np.float64)
            if d.shape != () or not (np.isfinite(d) and d >= 0):
                raise ValueError(f"{name} must be a finite scalar >= 0, got {v!r}")
    return HeadingHold(jnp.asarray(deadband, jnp.float32), jnp.asarray(tolerance, jnp.float32), int(latency))


class OvershootResult(NamedTuple):
    """Per scenario of :func:`overshoot_study` (degrees; positive: past the heading, in the turn's direction).

    goal: the heading the operator turned to. shown: the heading shown when they let go (>= goal: they let go
    once it is reached). settled: the robot's heading at the end. overshoot: settled - shown, what the robot
    added after the release. error: settled - goal. turning_steps: decisions the operator held the turn.
    """

    goal: np.ndarray
    shown: np.ndarray
    settled: np.ndarray
    overshoot: np.ndarray
    error: np.ndarray
    turning_steps: np.ndarray


def _operator(goal, rate, forward, latency: int) -> control.CommandFilter:
    """A simulated operator: turns left at ``rate`` (rad/s) while the heading shown is below ``goal`` (rad), then
    lets go for good; ``forward`` m/s throughout. The robot reads each command ``latency`` decisions late."""
    n = latency + 1

    def init(start, first_swing):
        return jnp.bool_(False), jnp.zeros((n, 3), jnp.float32)

    def apply(state, info, command):
        released, queue = state
        left_stands = info.stance_side > 0
        shown = body_heading(jnp.where(left_stands, info.stance[2], info.swing_from[2]),
                             jnp.where(left_stands, info.swing_from[2], info.stance[2]))
        released = released | (shown >= goal)
        mine = jnp.stack([forward, 0.0, jnp.where(released, 0.0, rate)]).astype(jnp.float32)
        queue = jnp.concatenate([queue[1:], mine[None]])
        return (released, queue), queue[0]

    return control.CommandFilter(init, apply)


def _chain(first: control.CommandFilter, then: control.CommandFilter | None) -> control.CommandFilter:
    if then is None:
        return first

    def init(start, first_swing):
        return first.init(start, first_swing), then.init(start, first_swing)

    def apply(state, info, command):
        a, command = first.apply(state[0], info, command)
        b, command = then.apply(state[1], info, command)
        return (a, b), command

    return control.CommandFilter(init, apply)


def _study(terrain: Terrain, robot: Robot, start, goals, rates, forward, mode: HeadingHold | None, num_steps: int,
           latency: int, refine):
    def one(goal, rate):
        index, targets = select.prepare(terrain, robot)
        selector = control.exact_selector(terrain, robot, SelectOptions(refine=refine), targets=targets,
                                          index=index)
        cf = _chain(_operator(goal, rate, forward, latency), None if mode is None else mode.build(robot))
        _, rec = control.loop(control.perfect_walker(), selector, start, jnp.float32(1.0),
                              jnp.zeros((num_steps, 3), jnp.float32), command_filter=cf)
        return rec["footsteps"], rec["sides"]

    return jax.vmap(one)(goals, rates)


_study_jit = jax.jit(_study, static_argnames=("num_steps", "latency", "refine"))


def overshoot_study(robot: Robot, *, num: int = 64, seed: int = 0, latency: int = 0, mode: str = "rate",
                    forward: float = 0.0, goal_range=(30.0, 150.0), rate_range=(0.5, 1.0), settle: int = 6,
                    refine: bool = False) -> OvershootResult:
    """Turn to a goal heading with a simulated operator, and measure how far the robot goes past it.

    Each scenario: HRP-2 stands on flat ground facing 0; the operator turns left at a rate drawn from
    ``rate_range`` (fractions of the action set's largest turn rate) until the heading shown (the feet's mean
    yaw after each step) reaches a goal drawn from ``goal_range`` (deg), then lets go; the robot reads each
    command ``latency`` decisions late and walks ``settle`` more decisions after the last possible release.
    The perfect walker; one compiled vmapped program per (latency, mode, refine).

    Args:
      robot: the robot (e.g. ``ij.robots.hrp2()``).
      num: scenarios; seed: of the goals and rates.
      latency: decisions of latency (0: this package's loop; 1: the paper's future stance).
      mode: "rate" (the paper's) or "heading" (:func:`heading_hold` with this latency).
      forward: m/s held throughout (0: turning on the spot).
      goal_range: deg; rate_range: fractions of the largest turn rate.
      settle: decisions after the slowest turn could end.
      refine: refine each step (:mod:`ijoy_jax.refine`): the heading held exactly instead of to the lattice.

    Returns:
      :class:`OvershootResult` (NumPy, degrees).
    """
    if mode not in ("rate", "heading"):
        raise ValueError(f"mode must be 'rate' or 'heading', got {mode!r}")
    rng = np.random.default_rng(seed)
    goals = np.radians(rng.uniform(*goal_range, num)).astype(np.float32)
    max_rate = float(np.max(np.abs(np.asarray(robot.actions)[:, 2])) / float(robot.step_time))
    rates = (rng.uniform(*rate_range, num) * max_rate).astype(np.float32)
    per_step = float(np.min(rates)) * float(robot.step_time)
    num_steps = int(np.ceil(np.radians(goal_range[1]) / per_step)) + 2 + latency + settle
    half = 1.0 + num_steps * float(robot.step_time) * abs(forward)  # m: room for the walk in every direction
    cells = int(np.ceil(2 * half / 0.02))
    terrain = flat((cells, cells), 0.02)
    start = start_stance(robot, half, half)
    spec = heading_hold(tolerance=0.0 if refine else 0.5, latency=latency) if mode == "heading" else None
    steps, sides = _study_jit(terrain, robot, start, jnp.asarray(goals), jnp.asarray(rates), jnp.float32(forward),
                              spec, num_steps=num_steps, latency=latency, refine=bool(refine))
    steps, sides = np.asarray(steps, np.float64), np.asarray(sides)
    feet = np.broadcast_to(np.asarray(start, np.float64), (num, 2, 3)).copy()
    shown_at = np.full(num, np.nan)
    turning = np.zeros(num, np.int32)
    released = np.zeros(num, bool)
    for k in range(num_steps):
        shown = feet[:, 0, 2] + 0.5 * np.angle(np.exp(1j * (feet[:, 1, 2] - feet[:, 0, 2])))
        newly = ~released & (shown >= goals)
        shown_at[newly] = shown[newly]
        released |= newly
        turning += ~released
        row = np.where(sides[:, k] > 0, 0, 1)
        feet[np.arange(num), row] = steps[:, k]
    settled = feet[:, 0, 2] + 0.5 * np.angle(np.exp(1j * (feet[:, 1, 2] - feet[:, 0, 2])))
    deg = np.degrees
    return OvershootResult(goal=deg(goals.astype(np.float64)), shown=deg(shown_at), settled=deg(settled),
                           overshoot=deg(settled - shown_at), error=deg(settled - goals), turning_steps=turning)
