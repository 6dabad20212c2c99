"""The cue force: a push on the stick out of the commands the terrain blocks, toward the nearest feasible one.

Both papers joined. The intelligent joystick (Chestnutt et al., HRP-2) silently deviates from, or refuses,
a command the terrain does not allow; the ALDURO joystick (Germann et al.) pushes back near the limits of
what the machine can do. Here the joystick pushes the stick out of the commands the terrain blocks, toward
the nearest command the robot can carry out, so the operator feels where the robot cannot go before it
deviates. The commands and their cells are those of :mod:`ijoy_jax.cue.feasible`.

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

Two rates. :func:`~ijoy_jax.cue.feasible_commands` runs once per step (the future stance changes once a
step); the force (:func:`force`, :func:`force_terms`) runs at the haptic rate from that pytree alone: a few
thousand flops per tick, no terrain access. :func:`prepare_tick` and :func:`tick_force` are the same
computation split at that rate boundary. The tunable numbers are the traced leaves of
:class:`~ijoy_jax.cue.CueParams` (:mod:`ijoy_jax.cue.params`): changing them never recompiles, and the
force is differentiable in them and in the command.

Units: metres, seconds, radians; commands in m/s, m/s, rad/s; forces as fractions of the device's maximum.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.cue.feasible import MIN_UNIT, FeasibleCommands, check_command, check_feasible
from ijoy_jax.cue.params import DEFAULT_C1, DEFAULT_DECAY, DEFAULT_TEMPERATURE, CueParams, check_params, make_params
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.struct import as_array, pytree_dataclass

CLIP_SLACK = 1.0
"""Distance units: commands further than this outside the cells' hull are clipped hard before the soft clip
(where the soft clip is exact to ``exp(-1 / T)``), so a huge finite command cannot overflow it."""
ROUNDING_ULPS = 16
"""The depth is reduced by this many ulps of the two soft mins compared: their float rounding (a few ulps)
must not turn an open command into a blocked one."""


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
    return (
        (c1 >= 0)
        & (c1 <= 1)
        & (decay > 0)
        & jnp.isfinite(decay)
        & _all3(jnp.isfinite(s) & (s > 0))
        & (t > 0)
        & jnp.isfinite(t)
    )


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


def force_terms(
    feasible: FeasibleCommands,
    command,
    params: CueParams | None = None,
    *,
    c1=None,
    decay=None,
    c2=None,
    scales=None,
    temperature=None,
) -> CueForce:
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
    check_feasible(feasible)
    command = as_array("command", command)
    check_command(command)
    p = _resolve_params(params, dict(c1=c1, decay=decay, c2=c2, scales=scales, temperature=temperature))
    command = jnp.asarray(command, jnp.result_type(feasible.commands.dtype, jnp.float32))  # one program
    return _force_jit(feasible, command, p)


def force(
    feasible: FeasibleCommands,
    command,
    params: CueParams | None = None,
    *,
    c1=None,
    decay=None,
    c2=None,
    scales=None,
    temperature=None,
) -> jax.Array:
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
    return force_terms(
        feasible, command, params, c1=c1, decay=decay, c2=c2, scales=scales, temperature=temperature
    ).force


_prepare_jit = jax.jit(_prepare)
_tick_jit = jax.jit(lambda tick, command: _tick(tick, command).force)


def compiled_programs() -> int:
    """How many programs :func:`force_terms`, :func:`prepare_tick` and :func:`tick_force` hold compiled in this process.

    :func:`force` runs through :func:`force_terms`' program. Read it before and after a loop of calls to learn
    how many compiles the loop caused: each new number of actions or dtype compiles once; new commands,
    feasible sets and parameters (traced leaves of :class:`~ijoy_jax.cue.CueParams` and :class:`CueTick`)
    reuse the program.
    """
    return compiled_count(_force_jit) + compiled_count(_prepare_jit) + compiled_count(_tick_jit)


def prepare_tick(
    feasible: FeasibleCommands,
    params: CueParams | None = None,
    *,
    c1=None,
    decay=None,
    c2=None,
    scales=None,
    temperature=None,
) -> CueTick:
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
    check_feasible(feasible)
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
        raise ValueError(
            f"tick must be one step's CueTick (cells (4, N), consts (20,); vmap for batches), got "
            f"{np.shape(tick.cells)}, {np.shape(tick.consts)}"
        )
    command = as_array("command", command)
    check_command(command)
    return _tick_jit(tick, jnp.asarray(command, tick.consts.dtype))
