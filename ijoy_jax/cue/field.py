"""The haptic cue: the biped's feasible commands, and a force on the stick where the terrain blocks the command.

Both papers joined. The intelligent joystick (Chestnutt et al., HRP-2) silently deviates from, or refuses,
a command the terrain does not allow; the ALDURO joystick (Germann et al.) pushes back near the limits of
what the machine can do. Here the joystick pushes the stick out of the commands the terrain blocks, toward
the nearest command the robot can carry out, so the operator feels where the robot cannot go before it
deviates.

Command space. The selector's ideal step for a command ``j`` is ``p_next = p0 + dt j`` in the stance foot's
frame (:func:`ijoy_jax.select.ideal_step`; ``p0`` the step in place, which carries the lateral offset to the
nominal foot placement). Its inverse maps every action ``a`` of S to the command ``j_a = (a - p0) / dt`` that
asks for exactly that step (a and p0 mirrored for a right swing foot; m/s, m/s, rad/s), and one FootCost
evaluation of the whole action set (:func:`ijoy_jax.select.action_foot_costs`, the one the exhaustive
selector makes) marks each ``j_a`` valid or not: :func:`feasible_commands`, once per step. The action set
is a lattice (every preset, :func:`ijoy_jax.robots.lattice_actions`); the *cell* of ``j_a`` is the box of
half the lattice spacing around it per axis (``half_cell``): on open ground every command in it is realised
by ``a`` (the selector rounds per axis; its dist has the same nearest action in every metric of this form).

Distance. With per-axis units ``u = unit * scales`` (``unit = (s, s, s / rotation_weight)``, ``s`` the
largest forward command of the action set, so one unit is a full forward deflection and a rotation costs
what it costs in the selector's dist ``|dxy| + rotation_weight |dtheta|``), the distance from a command to
a cell is the paper's dist in command space::

    e_k = max(|j_k - j_a,k| - h_k, 0) / u_k,      d_a(j) = |(e_x, e_y)| + e_theta.

The command is first clipped into the hull of the cells (this step's commands: a lateral command towards
the stance foot is realised by the next step, not refused by this one, so it is not a blockage).

Depth. ``depth(j) = min over valid cells d_a - min over all cells d_a``: zero where the command falls in a
valid cell (it is *open*: the selector realises it with the action it would take on open ground), and
otherwise how much further, in command distance, the nearest command the robot can realise lies than the
one asked for: the deviation the terrain forces on the selector.

Force. In the stick's own axes (forward, sideways, turn), as a fraction of the device's maximum force::

    f = m(depth) * n,    m = C1 (1 - exp(-ramp(depth) / decay)) = C1 - C1 * C2 ** ramp(depth),

with ``C2 = exp(-1 / decay)``: the ALDURO term ``C1 C2^d`` is the part of the force still to come, so the
force is 0 at the edge of the blocked region and grows with the depth to C1 (a saturating virtual wall,
stiffness ``C1 / decay`` per unit of depth). ``n`` is the unit vector, in stick coordinates (command over
full deflection), from the clipped command to the nearest feasible command. Zero where the command is
open, in [-1, 1] per axis everywhere (``|f| <= C1 <= 1``).

Smoothness. Every min is a soft min (log-sum-exp) with the temperature T (distance units); the clip, the
excess ``max(., 0)`` and ``|.|`` are softened at scale T, the nearest feasible command is the
softmin-weighted mean of the nearest points of the valid cells, and the force starts with the C1-smooth
ramp ``ramp(u) = 0 (u <= 0), u^2 / 2T (u < T), u - T/2``. The soft min over the valid cells lies below
their min and the softmin-weighted mean over all cells above the min of all, so the depth they give is
<= 0, and the force exactly 0, wherever the command is open; on ground where every action is valid the
force is exactly zero for every command. Where the command lies in a blocked cell the force is zero only
within about ``T log(k)`` of a valid cell (k near-equal valid cells), where the selector's rounding
realises it with that cell's action. No valid action at all: the force is a full ``C1`` towards the
centre of the stick (stop), flagged ``no_valid``; a non-finite command gives zero force, flagged.

Two rates. :func:`feasible_commands` runs once per step (the future stance changes once a step); the
force (:func:`force`, :func:`force_terms`) runs at the haptic rate from that pytree alone: a few
thousand flops per tick, no terrain access. :func:`reach` gives the polar picture of where the robot can
go (largest open speed per direction) for display; :func:`device_effects` maps a force onto the
force-feedback effects of :mod:`ijoy_jax.haptics.effects`.

Tunable numbers (C1, the decay, the per-axis scales, the temperature) are the traced leaves of
:class:`CueParams`: changing them never recompiles, and the force is differentiable in them and in the
command.

Units: metres, seconds, radians; commands in m/s, m/s, rad/s; forces as fractions of the device's maximum.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import select
from ijoy_jax._struct import as_array, as_pose, check_numeric, is_traced, pytree_dataclass
from ijoy_jax.footcost import TerrainIndex, query_supported
from ijoy_jax.footcost.xla import poses_supported
from ijoy_jax.haptics import effects as fx
from ijoy_jax.robots import Robot, side_actions, side_p0, side_sign
from ijoy_jax.terrain import Terrain

DEFAULT_C1 = 0.8
"""Largest cue force, as a fraction of the device's maximum (leaves 20 % for the device's own centring)."""
DEFAULT_DECAY = 0.1
"""Depth (command-distance units: fractions of a full forward deflection) over which the force rises to
``1 - 1/e`` of C1: 63 % at 2 cm of step beyond the last open cell (0.1 * 0.25 m/s * 0.8 s for HRP-2)."""
DEFAULT_TEMPERATURE = 0.001
"""Soft-min temperature and smoothing scale (distance units): well below HRP-2's half cells (0.125 units
forward, 0.05 sideways), so the soft geometry is the cells' to within a few percent of a cell."""
GAP_TOL = 1e-6
"""m, rad: two action coordinates closer than this are one lattice value (float32 rounding of a lattice)."""
MIN_UNIT = 1e-6
"""Command units: floor of a distance unit (an action set with no forward extent, a rotation weight of 0)."""
CLIP_SLACK = 1.0
"""Distance units: commands further than this outside the cells' hull are clipped hard before the soft clip
(where the soft clip is exact to ``exp(-1 / T)``), so a huge finite command cannot overflow it."""
ROUNDING_ULPS = 16
"""The depth is reduced by this many ulps of the two soft mins compared: their float rounding (a few ulps)
must not turn an open command into a blocked one."""
DEFAULT_TRAVEL = 0.03
"""m: stick deflection at full scale for :func:`device_effects` (half of a consumer stick's ~6 cm travel)."""


@pytree_dataclass
class CueParams:
    """The cue's tunable numbers, all traced leaves (float32): changing them never recompiles.

    Attributes:
      c1: () C1, the largest force as a fraction of the device's maximum, in [0, 1].
      decay: () > 0, distance units: the force reaches ``1 - 1/e`` of C1 this deep into the blocked region
        (ALDURO's ``C2 = exp(-1 / decay)`` per unit of depth).
      scales: (3,) > 0, dimensionless multipliers of :attr:`FeasibleCommands.unit` per axis (forward,
        sideways, turn): larger makes that axis's distances count less.
      temperature: () > 0, distance units: soft-min temperature and smoothing scale.
    """

    c1: jax.Array
    decay: jax.Array
    scales: jax.Array
    temperature: jax.Array


def make_params(*, c1=DEFAULT_C1, decay=None, c2=None, scales=(1.0, 1.0, 1.0),
                temperature=DEFAULT_TEMPERATURE) -> CueParams:
    """A fresh :class:`CueParams` (float32 leaves), checked where concrete.

    Args:
      c1: C1 in [0, 1] (fraction of the device's maximum force).
      decay: decay depth > 0 (distance units); default :data:`DEFAULT_DECAY`.
      c2: ALDURO's C2 in (0, 1) per unit of depth, instead of ``decay`` (``decay = -1 / ln C2``).
      scales: (3,) per-axis multipliers of the distance unit, > 0.
      temperature: soft-min temperature > 0 (distance units).

    Raises:
      ValueError: both ``decay`` and ``c2``, or a value out of range, naming it.

    Example:
      >>> from ijoy_jax import cue
      >>> p = cue.make_params(c1=0.5, c2=0.1)
      >>> round(float(p.decay), 4)
      0.4343
    """
    if decay is not None and c2 is not None:
        raise ValueError("give decay or c2 (decay = -1 / ln c2), not both")
    if c2 is not None:
        check_numeric("c2", c2)
        if not is_traced(c2):
            v = np.asarray(c2, np.float64)
            if v.shape != () or not (np.isfinite(v) and 0 < v < 1):
                raise ValueError(f"c2 must be a scalar in (0, 1) (the factor per unit of depth), got {c2!r}")
        decay = -1.0 / jnp.log(jnp.asarray(c2, jnp.float32))
    elif decay is None:
        decay = DEFAULT_DECAY
    scales = _f32(scales)
    if scales.shape not in ((), (3,)):
        raise ValueError(f"scales must be a number or have shape (3,) (forward, sideways, turn), got shape "
                         f"{scales.shape}")
    p = CueParams(c1=_f32(c1), decay=_f32(decay), scales=jnp.broadcast_to(scales, (3,)),
                  temperature=_f32(temperature))
    check_params(p)
    return p


def _f32(v):
    check_numeric("a cue parameter", v)
    return jnp.asarray(v, jnp.float32)


_PARAM_RULES = (
    ("c1", (), "finite and in [0, 1] (a fraction of the device's maximum force)",
     lambda xp, v: xp.isfinite(v) & (v >= 0) & (v <= 1)),
    ("decay", (), "finite and > 0 (distance units)", lambda xp, v: xp.isfinite(v) & (v > 0)),
    ("scales", (3,), "finite and > 0 on every axis", lambda xp, v: xp.all(xp.isfinite(v) & (v > 0))),
    ("temperature", (), "finite and > 0 (distance units)", lambda xp, v: xp.isfinite(v) & (v > 0)),
)


def check_params(params: CueParams) -> None:
    """Raise naming the field if a concrete :class:`CueParams` value is out of range (tracers are skipped).

    Inside a trace the same rules give a zero force flagged ``bad_params`` (:class:`CueForce`).

    Raises:
      TypeError: not a CueParams. ValueError: a wrong shape or a value out of range.
    """
    if not isinstance(params, CueParams):
        raise TypeError(f"params must be an ijoy_jax.cue.CueParams (make_params), got {type(params).__name__}")
    for name, shape, must, rule in _PARAM_RULES:
        v = getattr(params, name)
        if np.shape(v) != shape:
            raise ValueError(f"params.{name} must have shape {shape}, got {np.shape(v)}")
        if is_traced(v):
            continue
        check_numeric(f"params.{name}", v)
        arr = np.asarray(v, np.float64)
        if not bool(rule(np, arr)):
            raise ValueError(f"params.{name} must be {must}, got {arr.tolist()}")


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
    cost = select.action_foot_costs(terrain, robot, stance, stance_side, swing_from=swing_from, index=index,
                                    kernel=kernel)
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
    frame = jnp.stack([half, jnp.min(commands, axis=0) - half, jnp.max(commands, axis=0) + half,
                       jnp.maximum(unit, MIN_UNIT), full])
    return FeasibleCommands(commands=commands, valid=valid, cost=cost.astype(jnp.float32), frame=frame,
                            any_valid=jnp.any(valid), unsupported=~supported)


_feasible_jit = jax.jit(_feasible, static_argnames=("kernel",))


def feasible_commands(terrain: Terrain, robot: Robot, stance, stance_side, swing_from=None, *,
                      index: TerrainIndex | None = None, kernel: str = "xla") -> FeasibleCommands:
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
      kernel: "xla" or "pallas" (static), as :func:`ijoy_jax.select_step`.

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
    select.validate(terrain, robot, stance, stance_side, np.zeros(3), swing_from=swing_from, index=index,
                    kernel=kernel)
    # One program whatever the caller's array types (lists, NumPy float64, Python ints).
    stance = jnp.asarray(stance, jnp.float32)
    swing_from = None if swing_from is None else jnp.asarray(swing_from, jnp.float32)
    return _feasible_jit(terrain, robot, stance, jnp.asarray(stance_side, jnp.int32), swing_from, index,
                         kernel=kernel)


class CueForce(NamedTuple):
    """The cue at one command (:func:`force_terms`); vmapped calls add leading axes.

    Fields::

      force: (3,) float32 on the stick's axes (forward, sideways, turn) as fractions of the device's
        maximum force, each in [-1, 1] (``|force| <= c1``); what :func:`force` returns.
      magnitude: () float32 ``C1 (1 - exp(-ramp(depth) / decay))``, in [0, c1] (c1 when ``no_valid``).
      depth: () float32 distance units: how much further the nearest feasible command is than the cell
        the command falls in (<= 0 where open; soft); +inf when no action is valid.
      nearest: (3,) float32 command units: the soft-nearest feasible command (where the force points;
        the centre of the spring in :func:`device_effects`); the clipped command when no action is valid.
      blocked: () bool, the force is not zero (the command is not open, or no action is valid).
      no_valid: () bool, no action is valid: the force is a full C1 towards the stick's centre (stop).
      nonfinite_command: () bool, the command had NaN/inf: zero force (the stick's reading is unknown).
      bad_params: () bool, a parameter was out of range (traced): zero force.
    """

    force: jax.Array
    magnitude: jax.Array
    depth: jax.Array
    nearest: jax.Array
    blocked: jax.Array
    no_valid: jax.Array
    nonfinite_command: jax.Array
    bad_params: jax.Array


def _ramp(u, t):
    """C1-smooth onset ``max(u, 0)``: exactly 0 for u <= 0, ``u^2 / 2t`` up to t, then ``u - t/2``."""
    pos = jnp.maximum(u, 0.0)
    return jnp.where(pos < t, pos * pos / (2.0 * t), pos - 0.5 * t)


def _relu(u, t):
    """C1-smooth ``max(u, 0)`` exact beyond ``|u| >= t/2``: ``(u + t/2)^2 / 2t`` in between (no transcendental)."""
    v = jnp.clip(u + 0.5 * t, 0.0, t)
    return jnp.where(u >= 0.5 * t, u, v * v / (2.0 * t))


def _soft_clip(z, lo, hi, t):
    """C1-smooth ``clip(z, lo, hi)``: exact farther than t/2 from both bounds."""
    return lo + _relu(z - lo, t) - _relu(z - hi, t)


def _all3(x):
    """``all`` over a last axis of size 3, unrolled: a reduction would end an XLA fusion."""
    return x[..., 0] & x[..., 1] & x[..., 2]


def _sum3(x):
    return x[..., 0] + x[..., 1] + x[..., 2]


def _unit_vector(v, eps):
    """``v / sqrt(|v|^2 + eps^2)`` over a last axis of 3: a unit vector away from 0, smoothly 0 at 0."""
    return v / jnp.sqrt(_sum3(v * v) + eps * eps)[..., None]


def _params_ok(params: CueParams) -> jax.Array:
    """() bool, every parameter in range (the rules of :func:`check_params`, unrolled for the tick)."""
    c1, decay, s, t = params.c1, params.decay, params.scales, params.temperature
    return ((c1 >= 0) & (c1 <= 1) & (decay > 0) & jnp.isfinite(decay) & _all3(jnp.isfinite(s) & (s > 0))
            & (t > 0) & jnp.isfinite(t))


@pytree_dataclass
class CueTick:
    """What the haptic tick needs, prepared once per step (and whenever the parameters change): two leaves.

    :func:`prepare_tick` builds it from a :class:`FeasibleCommands` and :class:`CueParams`;
    :func:`tick_force` evaluates the force from it alone. Vmapped calls add leading axes.

    Attributes:
      cells: (4, N) float32: rows 0-2 each action's command in distance units (``commands / (unit *
        scales)``), one contiguous row per axis; row 3 is 1.0 for the cells the soft min over feasible
        commands runs over (the valid ones; all of them when none is valid), else 0.0.
      consts: (20,) float32, in distance units where they have one: half cell (3), hull lo (3), hull hi (3),
        the distance unit ``unit * scales`` in command units (3), the full scale (3), then C1, the decay,
        the temperature (safe stand-ins where the parameters were out of range), 1.0 if the parameters
        were in range, 1.0 if any action is valid.
    """

    cells: jax.Array
    consts: jax.Array


def _prepare(feasible: FeasibleCommands, params: CueParams) -> CueTick:
    """The body of :func:`prepare_tick` (traceable, differentiable in the parameters)."""
    dtype = jnp.result_type(feasible.commands.dtype, jnp.float32)  # float64 feasible sets compute in float64
    ok = _params_ok(params)
    # Safe stand-ins: neither the value nor the gradient sees out-of-range parameters.
    c1 = jnp.where(ok, params.c1, 0.0)
    decay = jnp.where(ok, params.decay, 1.0)
    t = jnp.where(ok, params.temperature, DEFAULT_TEMPERATURE)
    u = feasible.unit * jnp.where(ok, params.scales, 1.0)  # (3,) command units per unit of distance
    g = feasible.frame / u  # (5, 3) half cell, hull lo, hull hi, unit, full scale, in distance units
    any_valid = feasible.any_valid
    use = (feasible.valid | ~any_valid).astype(dtype)
    cells = jnp.concatenate([(feasible.commands / u).T, use[None]]).astype(dtype)
    full = jnp.maximum(g[4], MIN_UNIT / u)
    flags = jnp.stack([ok, any_valid]).astype(dtype)
    consts = jnp.concatenate([g[0], g[1], g[2], u, full, jnp.stack([c1, decay, t]), flags]).astype(dtype)
    return CueTick(cells=cells, consts=consts)


def _tick(tick: CueTick, command) -> CueForce:
    """The cue from a prepared tick (one command; jit/vmap/grad).

    One pass over the action set for the distances (one contiguous row per axis), one reduction for the two
    soft mins' maxima and one matrix product for every sum they weigh: one exp (per soft min) and one sqrt
    per action.
    """
    k = tick.consts
    hs, lo, hi, u, full = k[0:3], k[3:6], k[6:9], k[9:12], k[12:15]
    c1, decay, t, ok, any_valid = k[15], k[16], k[17], k[18] > 0, k[19] > 0
    command = jnp.asarray(command, k.dtype)
    finite = _all3(jnp.isfinite(command))
    j = jnp.where(finite, command, 0.0)
    z = jnp.clip(j / u, lo - CLIP_SLACK, hi + CLIP_SLACK)
    zc = _soft_clip(z, lo, hi, t)  # (3,) the command inside the cells' hull, distance units
    rows = [tick.cells[i] for i in range(3)]  # (N,) per axis: the cells' centres
    e = [_relu(jnp.abs(zc[i] - rows[i]) - hs[i], t) for i in range(3)]  # smooth excess beyond each cell
    sq = e[0] * e[0] + e[1] * e[1]
    pos = sq > 0
    d = jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0) + e[2]  # (N,) distance to each cell
    # Soft mins by log-sum-exp over all cells and over the valid ones, each shifted by its maximum (no
    # gradient: the shift cancels); with no valid cell the second runs over all cells (a finite stand-in,
    # not used). Cells left out get logit -inf, weight exactly 0.
    logits = -d / t
    both = jnp.stack([logits, jnp.where(tick.cells[3] > 0, logits, -jnp.inf)])  # (2, N)
    top = jax.lax.stop_gradient(jnp.max(both, axis=1))  # (2,)
    w = jnp.exp(both - top[:, None])
    near = [_soft_clip(zc[i], rows[i] - hs[i], rows[i] + hs[i], t) for i in range(3)]  # nearest point per cell
    sums = w @ jnp.stack([jnp.ones_like(d), d, *near], axis=1)  # (2, 5)
    d_valid = -t * (top[1] + jnp.log(sums[1, 0]))  # <= min over the valid cells
    m_all = sums[0, 1] / sums[0, 0]  # >= min over all cells
    # <= 0 where the command is open, but for rounding: a few ulps of the distances are not a blockage.
    depth = d_valid - m_all - ROUNDING_ULPS * jnp.finfo(k.dtype).eps * (jnp.abs(d_valid) + jnp.abs(m_all))
    mag = c1 * -jnp.expm1(-_ramp(depth, t) / decay)
    nearest_z = sums[1, 2:] / sums[1, 0]
    n = _unit_vector((nearest_z - zc) / full, t)  # towards the nearest feasible command, stick coordinates
    centre = -_unit_vector(j / u / full, t)  # no valid action: back to the centre of the stick (stop)
    live = finite & ok
    force = jnp.where(live, jnp.clip(jnp.where(any_valid, mag * n, c1 * centre), -1.0, 1.0), 0.0)
    magnitude = jnp.where(live, jnp.where(any_valid, mag, c1), 0.0)
    return CueForce(
        force=force,
        magnitude=magnitude,
        depth=jnp.where(any_valid, depth, jnp.inf),
        nearest=jnp.where(any_valid, nearest_z, zc) * u,
        blocked=magnitude > 0,
        no_valid=~any_valid,
        nonfinite_command=~finite,
        bad_params=~ok,
    )


def _force(feasible: FeasibleCommands, command, params: CueParams) -> CueForce:
    """The body of :func:`force_terms`: the tick of the prepared step (one mechanism; jit/vmap/grad)."""
    return _tick(_prepare(feasible, params), command)


_force_jit = jax.jit(_force)


def _check_feasible(feasible) -> None:
    if not isinstance(feasible, FeasibleCommands):
        raise TypeError(f"feasible must be an ijoy_jax.cue.FeasibleCommands (feasible_commands), "
                        f"got {type(feasible).__name__}")
    n = np.shape(feasible.commands)
    if len(n) != 2 or n[1] != 3:
        raise ValueError(f"feasible.commands must have shape (N, 3) for one stance (vmap for batches), got {n}")
    for name, shape in (("valid", n[:1]), ("cost", n[:1]), ("frame", (5, 3)), ("any_valid", ()),
                        ("unsupported", ())):
        if np.shape(getattr(feasible, name)) != shape:
            raise ValueError(f"feasible.{name} must have shape {shape}, got {np.shape(getattr(feasible, name))}")


def _check_command(command) -> None:
    check_numeric("command", command)
    if np.shape(command) != (3,):
        raise ValueError(f"command must have shape (3,) (forward m/s, sideways m/s, turn rad/s), "
                         f"got {np.shape(command)}")
    if not is_traced(command):
        with np.errstate(over="ignore"):
            bad = not np.all(np.isfinite(np.asarray(command, np.float32)))
        if bad:
            raise ValueError(f"command must be finite (as float32), got {np.asarray(command).tolist()}")


def _resolve_params(params, overrides) -> CueParams:
    if params is None:
        base = dict(c1=DEFAULT_C1, decay=DEFAULT_DECAY, scales=(1.0, 1.0, 1.0), temperature=DEFAULT_TEMPERATURE)
    else:
        check_params(params)
        base = dict(c1=params.c1, decay=params.decay, scales=params.scales, temperature=params.temperature)
    given = {k: v for k, v in overrides.items() if v is not None}
    if "c2" in given:
        base.pop("decay")
    base.update(given)
    if params is not None and not given:
        return params
    return make_params(**base)


def force_terms(feasible: FeasibleCommands, command, params: CueParams | None = None, *, c1=None, decay=None,
                c2=None, scales=None, temperature=None) -> CueForce:
    """The cue force at one command, with its depth, nearest feasible command and flags (the haptic tick).

    Args:
      feasible: :func:`feasible_commands` of the current stance (one stance; vmap for batches).
      command: (3,) the stick's command (forward m/s, sideways m/s, turn rad/s; stance frame).
      params: :class:`CueParams`; None: :func:`make_params`'s defaults.
      c1, decay, c2, scales, temperature: replace that parameter (see :func:`make_params`; ``c2`` is
        ALDURO's factor per unit of depth, ``decay = -1 / ln c2``).

    Returns:
      :class:`CueForce`.

    Raises:
      ValueError, TypeError: a malformed feasible set, a command of the wrong shape or (concrete) not
      finite, a parameter out of range. Traced values are not checked: a non-finite command or an
      out-of-range parameter gives a zero force, flagged.

    The public entry point and the one to call inside your jit or vmap; eagerly it runs through one
    module-level jit (parameters are traced leaves: no recompile when they change).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax import cue
      >>> free = np.ones((100, 100), bool); free[55:, :] = False        # a wall at x = 1.1 m
      >>> f = cue.feasible_commands(ij.terrain.from_arrays(None, free, 0.02), ij.robots.hrp2(), [0.8, 1.0, 0.0], -1)
      >>> out = cue.force_terms(f, [0.25, 0.0, 0.0])
      >>> bool(out.blocked), bool(out.force[0] < -0.5), round(float(out.nearest[0]), 3)
      (True, True, 0.219)
    """
    _check_feasible(feasible)
    command = as_array("command", command)
    _check_command(command)
    p = _resolve_params(params, dict(c1=c1, decay=decay, c2=c2, scales=scales, temperature=temperature))
    command = jnp.asarray(command, jnp.result_type(feasible.commands.dtype, jnp.float32))  # one program
    return _force_jit(feasible, command, p)


def force(feasible: FeasibleCommands, command, params: CueParams | None = None, *, c1=None, decay=None, c2=None,
          scales=None, temperature=None) -> jax.Array:
    """(3,) float32 the cue force on the stick: forward, sideways, turn, each in [-1, 1] of the device's maximum.

    ``force_terms(...).force`` (see :func:`force_terms` for the arguments, the flags and the errors):
    zero where the commanded step is open, else ``C1 (1 - exp(-depth / decay))`` towards the nearest
    feasible command (module docstring).

    Args:
      feasible: :func:`feasible_commands` of the current stance.
      command: (3,) m/s, m/s, rad/s in the stance foot's frame.
      params: :class:`CueParams` (None: defaults).
      c1: C1 in [0, 1]; decay: decay depth > 0 (distance units); c2: ALDURO's C2 in (0, 1) instead of
        decay; scales: (3,) > 0 per-axis distance multipliers; temperature: > 0 soft-min temperature.

    Example:
      >>> import ijoy_jax as ij
      >>> from ijoy_jax import cue
      >>> f = cue.feasible_commands(ij.terrain.flat((100, 100), 0.02), ij.robots.hrp2(), [1.0, 1.0, 0.0], -1)
      >>> cue.force(f, [0.25, 0.1, 0.3], c1=1.0, decay=0.05).tolist()    # open ground: no force
      [0.0, 0.0, 0.0]
    """
    return force_terms(feasible, command, params, c1=c1, decay=decay, c2=c2, scales=scales,
                       temperature=temperature).force


_prepare_jit = jax.jit(_prepare)
_tick_jit = jax.jit(lambda tick, command: _tick(tick, command).force)


def prepare_tick(feasible: FeasibleCommands, params: CueParams | None = None, *, c1=None, decay=None, c2=None,
                 scales=None, temperature=None) -> CueTick:
    """The step's half of the force: everything the haptic tick needs, in two arrays (:class:`CueTick`).

    ``tick_force(prepare_tick(feasible, params), command) == force(feasible, command, params)``: the same
    computation split at the rate boundary, so the tick passes two arrays instead of the feasible set's and
    the parameters' eleven (each costs dispatch time) and divides nothing by the units. Call it once per
    step, and again when the parameters change. Arguments, checks and flags as :func:`force_terms`.

    Example:
      >>> import ijoy_jax as ij
      >>> from ijoy_jax import cue
      >>> f = cue.feasible_commands(ij.terrain.flat((100, 100), 0.02), ij.robots.hrp2(), [1.0, 1.0, 0.0], -1)
      >>> tick = cue.prepare_tick(f, c1=0.5)
      >>> tick.cells.shape, cue.tick_force(tick, [0.2, 0.1, 0.0]).tolist()
      ((4, 496), [0.0, 0.0, 0.0])
    """
    _check_feasible(feasible)
    p = _resolve_params(params, dict(c1=c1, decay=decay, c2=c2, scales=scales, temperature=temperature))
    return _prepare_jit(feasible, p)


def tick_force(tick: CueTick, command) -> jax.Array:
    """(3,) the cue force at one command from a prepared step (:func:`prepare_tick`): the haptic tick.

    The same force as :func:`force` (forward, sideways, turn, each in [-1, 1] of the device's maximum). In a
    1 kHz loop call ``jax.jit(cue.tick_force)`` (the checks below skip traced values; docs/cue.md gives the
    CPU settings the tick's latency was measured with).

    Args:
      tick: :class:`CueTick` of the current step.
      command: (3,) m/s, m/s, rad/s in the stance foot's frame.

    Raises:
      TypeError, ValueError: a tick that is not a :class:`CueTick`, a command of the wrong shape or
      (concrete) not finite. Traced non-finite commands give zero force.
    """
    if not isinstance(tick, CueTick):
        raise TypeError(f"tick must be an ijoy_jax.cue.CueTick (prepare_tick), got {type(tick).__name__}")
    if np.ndim(tick.cells) != 2 or np.shape(tick.cells)[0] != 4 or np.shape(tick.consts) != (20,):
        raise ValueError(f"tick must be one step's CueTick (cells (4, N), consts (20,); vmap for batches), got "
                         f"{np.shape(tick.cells)}, {np.shape(tick.consts)}")
    command = as_array("command", command)
    _check_command(command)
    return _tick_jit(tick, jnp.asarray(command, tick.consts.dtype))


def _hard_open(feasible: FeasibleCommands, commands) -> jax.Array:
    """(...,) bool: the command's nearest cell (hard geometry, after a hard clip into the hull) is valid."""
    u = feasible.unit
    z = jnp.clip(commands, feasible.lo, feasible.hi) / u  # (..., 3)
    x = jnp.abs(z[..., None, :] - feasible.commands / u)  # (..., N, 3)
    e = jnp.maximum(x - feasible.half_cell / u, 0.0)
    d = jnp.hypot(e[..., 0], e[..., 1]) + e[..., 2]
    d_valid = jnp.min(jnp.where(feasible.valid, d, jnp.inf), axis=-1)
    return (d_valid <= jnp.min(d, axis=-1)) & feasible.any_valid


REACH_BISECTIONS = 12
"""Bisection steps refining each direction's reach between its last open and first blocked sample."""


def _reach(feasible: FeasibleCommands, turn_rate, num_directions: int, samples: int) -> jax.Array:
    phi = 2.0 * math.pi * jnp.arange(num_directions, dtype=jnp.float32) / num_directions
    c, s = jnp.cos(phi), jnp.sin(phi)
    full = jnp.maximum(feasible.full_scale, MIN_UNIT)
    r_max = 1.0 / jnp.maximum(jnp.abs(c) / full[0], jnp.abs(s) / full[1])  # (K,) the ray leaves the stick's box
    turn = jnp.asarray(turn_rate, jnp.float32)

    def cmd(r):  # (K, ...) speeds -> (K, ..., 3) commands
        return jnp.stack([r * c.reshape((-1,) + (1,) * (r.ndim - 1)), r * s.reshape((-1,) + (1,) * (r.ndim - 1)),
                          jnp.broadcast_to(turn, r.shape)], axis=-1)

    frac = jnp.linspace(0.0, 1.0, samples, dtype=jnp.float32)
    r = r_max[:, None] * frac[None, :]  # (K, S)
    open_ = _hard_open(feasible, cmd(r))  # (K, S)
    last = jnp.max(jnp.where(open_, jnp.arange(samples), -1), axis=1)  # (K,) -1: none open
    lo = jnp.take_along_axis(r, jnp.maximum(last, 0)[:, None], axis=1)[:, 0]
    hi = jnp.take_along_axis(r, jnp.minimum(last + 1, samples - 1)[:, None], axis=1)[:, 0]

    def bisect(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        ok = _hard_open(feasible, cmd(mid))
        return jnp.where(ok, mid, lo), jnp.where(ok, hi, mid)

    lo, _ = jax.lax.fori_loop(0, REACH_BISECTIONS, bisect, (lo, hi))
    return jnp.where((last >= 0) & feasible.any_valid, lo, 0.0)


_reach_jit = jax.jit(_reach, static_argnames=("num_directions", "samples"))


def reach(feasible: FeasibleCommands, num_directions: int, *, turn_rate=0.0, samples: int = 64) -> jax.Array:
    """(K,) float32 the largest feasible speed (m/s) in each of K directions of the (xdot, ydot) plane.

    Direction k is ``phi_k = 2 pi k / K`` from forward towards the left, at the given turn rate. Along
    each ray, out to the stick's box (``|xdot| <= full_scale[0]``, ``|ydot| <= full_scale[1]``), the
    largest speed whose command is open (its nearest cell is a valid action's: the hard geometry of the
    force, without smoothing), found on ``samples`` evenly spaced speeds and refined by
    :data:`REACH_BISECTIONS` bisections. 0 where no speed is open (or no action is valid). Open ground:
    the box's edge in every direction. A blocked band nearer the centre with open speeds beyond it
    (stepping over) is not shown: draw the force field for that.

    Args:
      feasible: :func:`feasible_commands` of the current stance.
      num_directions: K (static, >= 1).
      turn_rate: the current turn command (rad/s).
      samples: speeds tried per direction (static, >= 2).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax import cue
      >>> free = np.ones((100, 100), bool); free[55:, :] = False        # a wall at x = 1.1 m
      >>> f = cue.feasible_commands(ij.terrain.from_arrays(None, free, 0.02), ij.robots.hrp2(), [0.8, 1.0, 0.0], -1)
      >>> [round(float(v), 3) for v in cue.reach(f, 4)]   # forward, left, backward, right (m/s)
      [0.219, 0.175, 0.25, 0.175]
    """
    _check_feasible(feasible)
    for name, v, least in (("num_directions", num_directions, 1), ("samples", samples, 2)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < least:
            raise ValueError(f"{name} must be an int >= {least}, got {v!r}")
    check_numeric("turn_rate", turn_rate)
    if np.shape(turn_rate) != ():
        raise ValueError(f"turn_rate must be a scalar (rad/s), got shape {np.shape(turn_rate)}")
    if not is_traced(turn_rate) and not np.isfinite(float(turn_rate)):
        raise ValueError(f"turn_rate must be finite, got {turn_rate!r}")
    return _reach_jit(feasible, turn_rate, num_directions=int(num_directions), samples=int(samples))


class CueEffects(NamedTuple):
    """A cue force as the standard force-feedback effects of :mod:`ijoy_jax.haptics.effects`.

    Fields::

      constant: :class:`~ijoy_jax.haptics.ConstantEffect` playing ``planar`` (refresh it every tick).
      spring: :class:`~ijoy_jax.haptics.SpringEffect` centred on the nearest feasible command (forward
        and sideways axes), with the stiffness that plays the cue's planar force magnitude at the current
        stick position and that magnitude as its saturation: between two updates it keeps pulling the
        stick back towards the feasible command; zero stiffness and saturation where the command is open.
      planar: (2,) N, the cue force on the device's two force axes: ``force * max_force`` reduced by the
        configuration's projection or folding (the turn component is dropped or folded), saturated.
    """

    constant: fx.ConstantEffect
    spring: fx.SpringEffect
    planar: jax.Array


def device_effects(cue: CueForce, feasible: FeasibleCommands, command, config: fx.JoystickForceConfig, *,
                   travel=DEFAULT_TRAVEL) -> CueEffects:
    """Map a cue force onto the effects a force-feedback driver plays (constant force, or spring).

    The stick's deflection along the device's axes is ``config.axes @ (command / full_scale) * travel``
    (m); the force ``cue.force * config.max_force`` (N) reaches the device's two axes by the
    configuration's ``reduction`` (:func:`ijoy_jax.haptics.project` or :func:`ijoy_jax.haptics.fold`)
    and is saturated at ``config.max_force``, as :func:`ijoy_jax.haptics.joystick_forces` does with a
    kinematic force. Traceable.

    Args:
      cue: :func:`force_terms` at ``command``.
      feasible: the feasible set it came from (for the stick's full scale).
      command: (3,) the command the cue was evaluated at (m/s, m/s, rad/s).
      config: the joystick's :class:`~ijoy_jax.haptics.JoystickForceConfig` (max force, axes, reduction).
      travel: stick deflection at full scale (m, > 0).

    Returns:
      :class:`CueEffects`.

    Raises:
      TypeError, ValueError: arguments of the wrong type or shape, a concrete non-finite command, a travel
      that is not a finite scalar > 0 (traced values are not checked).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax import cue, haptics
      >>> free = np.ones((100, 100), bool); free[55:, :] = False
      >>> f = cue.feasible_commands(ij.terrain.from_arrays(None, free, 0.02), ij.robots.hrp2(), [0.8, 1.0, 0.0], -1)
      >>> out = cue.force_terms(f, [0.25, 0.0, 0.0])
      >>> e = cue.device_effects(out, f, [0.25, 0.0, 0.0], haptics.default_joystick_config())
      >>> round(float(e.constant.magnitude), 2), round(float(e.constant.direction), 2)  # N, rad: backwards
      (2.85, 3.14)
    """
    if not isinstance(cue, CueForce) or np.shape(cue.force) != (3,):
        raise TypeError(f"cue must be one command's ijoy_jax.cue.CueForce (force_terms), got {type(cue).__name__}")
    _check_feasible(feasible)
    command = as_array("command", command)
    _check_command(command)
    if not isinstance(config, fx.JoystickForceConfig):
        raise TypeError(f"config must be an ijoy_jax.haptics.JoystickForceConfig, got {type(config).__name__}")
    check_numeric("travel", travel)
    if np.shape(travel) != () or (not is_traced(travel) and not (np.isfinite(float(travel)) and float(travel) > 0)):
        raise ValueError(f"travel must be a finite scalar > 0 (m of stick deflection at full scale), got {travel!r}")
    config_max = jnp.asarray(config.max_force, jnp.float32)
    max_force = jnp.where(config_max >= 0, config_max, 0.0)
    f3 = cue.force * max_force
    if config.reduction == "project":
        planar = fx.project(f3, config.axes)
    else:
        planar = fx.fold(f3, config.axes, config.fold_direction)
    planar = fx.saturate(planar, max_force)
    command = jnp.asarray(command, jnp.float32)
    command = jnp.where(jnp.isfinite(command), command, 0.0)
    per_unit = jnp.asarray(travel, jnp.float32) / jnp.maximum(feasible.full_scale, MIN_UNIT)
    stick = config.axes @ (jnp.clip(command, feasible.lo, feasible.hi) * per_unit)
    centre = config.axes @ (cue.nearest * per_unit)
    gap_sq = jnp.sum((stick - centre) ** 2)
    mag_sq = jnp.sum(planar * planar)
    pos = (gap_sq > 0) & (mag_sq > 0)
    stiffness = jnp.where(pos, jnp.sqrt(jnp.where(pos, mag_sq, 1.0) / jnp.where(pos, gap_sq, 1.0)), 0.0)
    spring = fx.spring(stiffness, jnp.minimum(cue.magnitude, 1.0) * max_force, 0.0, centre)
    return CueEffects(constant=fx.constant(planar), spring=spring, planar=planar)
