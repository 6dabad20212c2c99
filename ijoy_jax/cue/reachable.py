"""Where the robot can go from one stance: the largest open speed in each direction of the stick.

The polar picture of the feasible command set (:mod:`ijoy_jax.cue.feasible`) for display: along each ray of
the (xdot, ydot) plane, the largest speed whose command is open (its nearest cell is a valid action's), in
the hard geometry of the force (:mod:`ijoy_jax.cue.forces`) without its smoothing, so the reach is where the
force starts.

Units: m/s along each direction; the turn rate in rad/s.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.cue.feasible import MIN_UNIT, FeasibleCommands, check_feasible
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.struct import check_numeric, is_traced


def is_open(feasible: FeasibleCommands, commands) -> jax.Array:
    """(...,) bool: each command is open, its nearest cell a valid action's (the hard geometry of the force).

    The force's distances (:mod:`ijoy_jax.cue.forces`) without their smoothing: the command is clipped hard
    into the cells' hull and its nearest cell found by the exact min, so this is the line :func:`reach`
    draws and the one the force starts from. False for every command when no action is valid. Traceable;
    no checks (pass a :func:`feasible_commands` result).

    Args:
      feasible: :func:`feasible_commands` of one stance.
      commands: (..., 3) commands (forward m/s, sideways m/s, turn rad/s; stance frame).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax import cue
      >>> free = np.ones((100, 100), bool); free[55:, :] = False        # a wall at x = 1.1 m
      >>> f = cue.feasible_commands(ij.terrain.from_arrays(None, free, 0.02), ij.robots.hrp2(), [0.8, 1.0, 0.0], -1)
      >>> cue.is_open(f, np.array([[0.1, 0.0, 0.0], [0.25, 0.0, 0.0]])).tolist()
      [True, False]
    """
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
        return jnp.stack(
            [
                r * c.reshape((-1,) + (1,) * (r.ndim - 1)),
                r * s.reshape((-1,) + (1,) * (r.ndim - 1)),
                jnp.broadcast_to(turn, r.shape),
            ],
            axis=-1,
        )

    frac = jnp.linspace(0.0, 1.0, samples, dtype=jnp.float32)
    r = r_max[:, None] * frac[None, :]  # (K, S)
    open_ = is_open(feasible, cmd(r))  # (K, S)
    last = jnp.max(jnp.where(open_, jnp.arange(samples), -1), axis=1)  # (K,) -1: none open
    lo = jnp.take_along_axis(r, jnp.maximum(last, 0)[:, None], axis=1)[:, 0]
    hi = jnp.take_along_axis(r, jnp.minimum(last + 1, samples - 1)[:, None], axis=1)[:, 0]

    def bisect(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        ok = is_open(feasible, cmd(mid))
        return jnp.where(ok, mid, lo), jnp.where(ok, hi, mid)

    lo, _ = jax.lax.fori_loop(0, REACH_BISECTIONS, bisect, (lo, hi))
    return jnp.where((last >= 0) & feasible.any_valid, lo, 0.0)


_reach_jit = jax.jit(_reach, static_argnames=("num_directions", "samples"))


def compiled_programs() -> int:
    """How many programs :func:`reach` holds compiled (in this process).

    Read it before and after a loop of calls to learn how many compiles the loop caused: each new number of
    actions, ``num_directions`` or ``samples`` compiles once; new feasible sets and turn rates reuse the
    program.
    """
    return compiled_count(_reach_jit)


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
    check_feasible(feasible)
    for name, v, least in (("num_directions", num_directions, 1), ("samples", samples, 2)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < least:
            raise ValueError(f"{name} must be an int >= {least}, got {v!r}")
    check_numeric("turn_rate", turn_rate)
    if np.shape(turn_rate) != ():
        raise ValueError(f"turn_rate must be a scalar (rad/s), got shape {np.shape(turn_rate)}")
    if not is_traced(turn_rate) and not np.isfinite(float(turn_rate)):
        raise ValueError(f"turn_rate must be finite, got {turn_rate!r}")
    return _reach_jit(feasible, turn_rate, num_directions=int(num_directions), samples=int(samples))
