"""The feasible command set: every action of S as a joystick command from one stance, and whether the terrain allows it.

The selector's ideal step for a command ``j`` is ``p_next = p0 + dt j`` in the stance foot's frame
(:func:`ijoy_jax.select.ideal_step`; ``p0`` the step in place, which carries the lateral offset to the
nominal foot placement). Its inverse maps every action ``a`` of S to the command ``j_a = (a - p0) / dt`` that
asks for exactly that step (a and p0 mirrored for a right swing foot; m/s, m/s, rad/s), and one FootCost
evaluation of the whole action set (:func:`ijoy_jax.select.action_foot_costs`, the one the exhaustive
selector makes) marks each ``j_a`` valid or not: :func:`feasible_commands`, once per step (the future
stance changes once a step). The action set is a lattice (every preset,
:func:`ijoy_jax.robots.lattice_actions`); the *cell* of ``j_a`` is the box of half the lattice spacing
around it per axis (``half_cell``): on open ground every command in it is realised by ``a`` (the selector
rounds per axis; its dist has the same nearest action in every metric of this form).

The resulting :class:`FeasibleCommands` pytree is all the haptic rate needs (:mod:`ijoy_jax.cue.forces`,
:mod:`ijoy_jax.cue.reachable`, :mod:`ijoy_jax.cue.effects`): no terrain access after it. The checks of a
feasible set and of a stick command that every consumer runs first live here too.

Units: metres, seconds, radians; commands in m/s, m/s, rad/s.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import select
from ijoy_jax.footcost import TerrainIndex, query_supported
from ijoy_jax.footcost.query import poses_supported
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.robots import Robot, side_actions, side_p0, side_sign
from ijoy_jax.struct import as_pose, check_numeric, is_traced, pytree_dataclass
from ijoy_jax.terrain import Terrain

GAP_TOL = 1e-6
"""m, rad: two action coordinates closer than this are one lattice value (float32 rounding of a lattice)."""
MIN_UNIT = 1e-6
"""Command units: floor of a distance unit (an action set with no forward extent, a rotation weight of 0)."""


@pytree_dataclass
class FeasibleCommands:
    """Every action of S as a joystick command from one stance, and whether the terrain allows it.

    One step's worth (:func:`feasible_commands`); vmapped calls add leading axes. Commands are in the
    stance foot's frame: forward (m/s), sideways to the left (m/s), turn to the left (rad/s).

    Attributes:
      commands: (N, 3) float32, ``j_a = (a - p0) / dt`` of every action (the command that asks for
        exactly that step).
      valid: (N,) bool, FootCost finite (the foothold is allowed) and the values supported.
      cost: (N,) float32 FootCost of each action (action cost plus terrain terms; +inf where invalid):
        the one evaluation, to pass on to :func:`ijoy_jax.select_step` (``foot_costs=``).
      frame: (5, 3) float32, per axis (command units): the rows :attr:`half_cell`, :attr:`lo`,
        :attr:`hi`, :attr:`unit` and :attr:`full_scale` (one leaf: one argument less per haptic tick).
      any_valid: () bool, at least one action is valid.
      unsupported: () bool, the robot's, terrain's or query's values are outside what FootCost supports
        (a traced non-finite stance or swing pose, a stance side other than +1 or -1, as for
        :func:`ijoy_jax.select_step`; then no action is valid and the cue is the stop force).
    """

    commands: jax.Array
    valid: jax.Array
    cost: jax.Array
    frame: jax.Array
    any_valid: jax.Array
    unsupported: jax.Array

    @property
    def num_actions(self) -> int:
        """Size N of the action set (static)."""
        return self.commands.shape[-2]

    @property
    def half_cell(self) -> jax.Array:
        """(3,) half the action lattice's spacing per axis in command units, a cell's half-width."""
        return self.frame[..., 0, :]

    @property
    def lo(self) -> jax.Array:
        """(3,) the low corner of the cells' hull, the min of ``commands`` minus ``half_cell``."""
        return self.frame[..., 1, :]

    @property
    def hi(self) -> jax.Array:
        """(3,) the high corner of the cells' hull, the max of ``commands`` plus ``half_cell``."""
        return self.frame[..., 2, :]

    @property
    def unit(self) -> jax.Array:
        """(3,) command units of one unit of distance, ``(s, s, s / rotation_weight)`` with ``s`` the largest
        forward command of the action set (so the distance is the selector's dist, in full forward deflections)."""
        return self.frame[..., 3, :]

    @property
    def full_scale(self) -> jax.Array:
        """(3,) the largest ``|command|`` per axis over both feet, a full stick deflection."""
        return self.frame[..., 4, :]


def action_commands(robot: Robot, stance_side) -> jax.Array:
    """(N, 3) float32 the command ``(a - p0) / dt`` of every action for a stance side (the inverse of p_next).

    ``select_step`` with command ``j_a`` on open ground takes action ``a`` (its ideal step is exactly ``a``).

    Args:
      robot: the robot (its actions, p0 and step time).
      stance_side: +1 left stance foot (the right foot swings: mirrored actions), -1 right.

    Example:
      >>> import ijoy_jax as ij
      >>> from ijoy_jax import cue
      >>> j = cue.action_commands(ij.robots.hrp2(), -1)
      >>> [round(float(v), 4) for v in j.max(axis=0)]   # m/s forward and left, rad/s left
      [0.25, 0.175, 0.4363]
    """
    swing = -side_sign(stance_side)
    return ((side_actions(robot, swing) - side_p0(robot, swing)) / robot.step_time).astype(jnp.float32)


def _half_spacing(values) -> jax.Array:
    """Half the smallest gap between distinct values (> GAP_TOL) of a 1D array; 0 if all are equal."""
    v = jnp.sort(values)
    gaps = jnp.diff(v)
    gaps = jnp.where(gaps > GAP_TOL, gaps, jnp.inf)
    g = jnp.min(gaps) if gaps.shape[0] else jnp.inf
    return jnp.where(jnp.isfinite(g), 0.5 * g, 0.0)


def _feasible(terrain, robot, stance, stance_side, swing_from, index, kernel) -> FeasibleCommands:
    cost = select.action_foot_costs(
        terrain, robot, stance, stance_side, swing_from=swing_from, index=index, kernel=kernel
    )
    # the query's own values too (a traced NaN stance, a side other than +-1): flagged, no action valid, so the
    # cue is the full force towards the stick's centre that a robot which cannot step gets
    supported = query_supported(terrain, robot) & poses_supported(stance, stance_side, swing_from)
    valid = jnp.isfinite(cost) & supported
    commands = action_commands(robot, stance_side)
    dt = robot.step_time.astype(jnp.float32)
    half = jnp.stack([_half_spacing(robot.actions[:, k].astype(jnp.float32)) for k in range(3)]) / dt
    full = jnp.max(jnp.abs(commands), axis=0)
    s = jnp.maximum(full[0], MIN_UNIT)
    unit = jnp.stack([s, s, s / jnp.maximum(robot.rotation_weight.astype(jnp.float32), MIN_UNIT)])
    frame = jnp.stack(
        [half, jnp.min(commands, axis=0) - half, jnp.max(commands, axis=0) + half, jnp.maximum(unit, MIN_UNIT), full]
    )
    return FeasibleCommands(
        commands=commands,
        valid=valid,
        cost=cost.astype(jnp.float32),
        frame=frame,
        any_valid=jnp.any(valid),
        unsupported=~supported,
    )


_feasible_jit = jax.jit(_feasible, static_argnames=("kernel",))


def compiled_programs() -> int:
    """How many programs :func:`feasible_commands` holds compiled (in this process).

    Read it before and after a loop of calls to learn how many compiles the loop caused: each new input
    shape (terrain grid, action set, a ``swing_from`` or ``index`` given or not), static field or
    ``kernel`` compiles once; new terrain values, robot parameters, stances and sides reuse the program.
    """
    return compiled_count(_feasible_jit)


def feasible_commands(
    terrain: Terrain,
    robot: Robot,
    stance,
    stance_side,
    swing_from=None,
    *,
    index: TerrainIndex | None = None,
    kernel: str = "xla",
) -> FeasibleCommands:
    """The feasible command set of one stance: every action's command and validity (once per step).

    One FootCost evaluation of the whole action set (:func:`ijoy_jax.select.action_foot_costs`, what the
    exhaustive selector evaluates), mapped into joystick space (:func:`action_commands`). Pass
    ``feasible.cost`` to :func:`ijoy_jax.select_step` (``foot_costs=``) to decide the step from the same
    evaluation. Fixed shapes: jit and vmap it (over stances, terrains, robots).

    Args:
      terrain: one Terrain.
      robot: the robot model.
      stance: (3,) world pose of the (future) stance foot (m, rad).
      stance_side: +1 if the stance foot is the left one, -1 the right.
      swing_from: (3,) world pose the swing foot starts from, for the swing-path check on 2.5D terrains
        (None: no check), as :func:`ijoy_jax.select_step`.
      index: the terrain's prebuilt :class:`~ijoy_jax.footcost.TerrainIndex` (:func:`ijoy_jax.select.prepare`),
        built inside when None.
      kernel: "xla" or "pallas" (static), as a :class:`~ijoy_jax.SelectOptions`' ``kernel``.

    Returns:
      :class:`FeasibleCommands`.

    Raises:
      ValueError, TypeError: as :func:`ijoy_jax.select_step` for the terrain, robot, stance and side.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax import cue
      >>> free = np.ones((100, 100), bool); free[55:, :] = False        # a wall at x = 1.1 m
      >>> t = ij.terrain.from_arrays(None, free, 0.02)
      >>> f = cue.feasible_commands(t, ij.robots.hrp2(), [0.8, 1.0, 0.0], -1)
      >>> f.commands.shape, int(f.valid.sum())
      ((496, 3), 412)
    """
    stance, swing_from = as_pose("stance", stance), as_pose("swing_from", swing_from)
    select.validate(terrain, robot, stance, stance_side, np.zeros(3), select.SelectOptions(kernel=kernel),
                    swing_from=swing_from, index=index)
    # One program whatever the caller's array types (lists, NumPy float64, Python ints).
    stance = jnp.asarray(stance, jnp.float32)
    swing_from = None if swing_from is None else jnp.asarray(swing_from, jnp.float32)
    return _feasible_jit(terrain, robot, stance, jnp.asarray(stance_side, jnp.int32), swing_from, index, kernel=kernel)


def check_feasible(feasible) -> None:
    """Raise unless ``feasible`` is one stance's :class:`FeasibleCommands` (commands (N, 3), frame (5, 3)).

    What every function taking a feasible set checks first; shapes only, so traced leaves pass.

    Raises:
      TypeError: not a FeasibleCommands. ValueError: a leaf of the wrong shape (a batch: vmap instead).
    """
    if not isinstance(feasible, FeasibleCommands):
        raise TypeError(
            f"feasible must be an ijoy_jax.cue.FeasibleCommands (feasible_commands), got {type(feasible).__name__}"
        )
    n = np.shape(feasible.commands)
    if len(n) != 2 or n[1] != 3:
        raise ValueError(f"feasible.commands must have shape (N, 3) for one stance (vmap for batches), got {n}")
    for name, shape in (("valid", n[:1]), ("cost", n[:1]), ("frame", (5, 3)), ("any_valid", ()), ("unsupported", ())):
        if np.shape(getattr(feasible, name)) != shape:
            raise ValueError(f"feasible.{name} must have shape {shape}, got {np.shape(getattr(feasible, name))}")


def check_command(command) -> None:
    """Raise unless ``command`` is a (3,) stick command of numbers (forward m/s, sideways m/s, turn rad/s),
    finite as float32 where concrete (tracers are skipped: a traced non-finite command gives a flagged zero
    force instead).

    Raises:
      TypeError: not numbers. ValueError: a shape other than (3,), or a concrete NaN or infinity.
    """
    check_numeric("command", command)
    if np.shape(command) != (3,):
        raise ValueError(
            f"command must have shape (3,) (forward m/s, sideways m/s, turn rad/s), got {np.shape(command)}"
        )
    if not is_traced(command):
        with np.errstate(over="ignore"):
            bad = not np.all(np.isfinite(np.asarray(command, np.float32)))
        if bad:
            raise ValueError(f"command must be finite (as float32), got {np.asarray(command).tolist()}")
