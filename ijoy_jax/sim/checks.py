"""The checks of a simulated rollout's inputs, made once at the boundary of :func:`ijoy_jax.sim.walker.rollout`.

Shapes and static settings are always checked (the selector's options are
checked as they are built, :class:`ijoy_jax.SelectOptions`); values only where they are
concrete, so the checks pass through a caller's ``jax.jit`` or ``jax.vmap``.
:func:`rollout_keys` turns the ``key`` argument into one typed PRNG key per
rollout, and :func:`as_flag` refuses a static boolean option that is not one.

Implementation module of :mod:`ijoy_jax.sim.walker`.
"""

from __future__ import annotations

import jax
import numpy as np

from ijoy_jax.limits import check_num_steps
from ijoy_jax.prng import as_key
from ijoy_jax.robots import LEFT, Robot
from ijoy_jax.sim import physics
from ijoy_jax.sim.simulator import Sim, check_robot_for_sim
from ijoy_jax.sim.walk_step import frame_ticks
from ijoy_jax.struct import is_traced
from ijoy_jax.terrain import Terrain


def check_rollout_inputs(
    sim: Sim,
    terrain: Terrain,
    robot: Robot,
    start,
    commands,
    *,
    num_steps,
    first_swing,
    frames_per_step: int,
    batch: int | None,
    dynamics,
) -> None:
    """The inputs of one rollout (``batch`` None) or of ``batch`` rollouts: shapes and static options always,
    values only where they are concrete (so the checks pass through a caller's jit or vmap)."""
    lead = () if batch is None else (batch,)
    check_terrain_grid(sim, terrain, batch=len(lead))
    check_robot_for_sim(robot, sim.cfg)
    # concrete terrain values as ij.rollout's boundary checks them (check_terrain: finite heights and origin)
    for name in ("height", "origin"):
        leaf = getattr(terrain, name)
        if not is_traced(leaf) and not np.all(np.isfinite(np.asarray(leaf))):  # NumPy: no op staged into a trace
            raise ValueError(f"terrain.{name} must be finite (no NaN or inf)")
    check_num_steps(num_steps)
    frame_ticks(sim, frames_per_step)
    if dynamics is not None:
        physics.check(dynamics, batch)
    if np.shape(first_swing) not in ((), lead) or (
        not is_traced(first_swing) and not np.all(np.isin(np.asarray(first_swing), (LEFT, -LEFT)))
    ):
        raise ValueError(f"first_swing must be +1 (left) or -1 (right) (one, or one per rollout), got {first_swing!r}")
    if batch is None and np.shape(start) != (2, 3):
        raise ValueError(f"start must have shape (2, 3) (left foot, right foot), got {np.shape(start)}")
    if batch is not None and np.shape(start) != (batch, 2, 3):
        raise ValueError(
            f"starts must have shape (B, 2, 3) with B = the terrains' batch {batch}, got {np.shape(start)}"
        )
    if not is_traced(start) and not np.all(np.isfinite(np.asarray(start))):
        raise ValueError("start must be finite")
    shapes = (lead + (3,), lead + (num_steps, 3))
    if np.shape(commands) not in shapes:
        raise ValueError(f"commands must have shape {shapes[0]} or {shapes[1]}, got {np.shape(commands)}")


def check_terrain_grid(sim: Sim, terrain: Terrain, *, batch: int = 0) -> None:
    """The terrain's grid (its cells after ``batch`` leading batch axes) and cell size (m) are the Sim's: its
    height field was built for them (:func:`ijoy_jax.sim.walker.make_sim`). ValueError naming both otherwise."""
    grid = tuple(np.shape(terrain.free)[batch:])
    if grid != sim.shape or float(terrain.resolution) != sim.resolution:
        raise ValueError(
            f"terrain grid {grid} at {float(terrain.resolution)} m does not match "
            f"the Sim's {sim.shape} at {sim.resolution} m; build a Sim with make_sim for this grid"
        )


def rollout_keys(key, batch: int | None) -> jax.Array:
    """One rollout's typed key (``batch`` None) or B of them: an int seed or key (split into B), or B keys."""
    k = as_key(0 if key is None else key)
    if batch is None:
        if k.shape != ():
            raise ValueError(f"key must be one PRNG key or int seed, got keys of shape {k.shape}")
        return k
    if k.shape == ():
        return jax.random.split(k, batch)
    if k.shape != (batch,):
        raise ValueError(f"key must be one PRNG key (split into the batch) or {batch} keys, got shape {k.shape}")
    return k


def as_flag(name: str, value) -> bool:
    """A boolean option, True or False (NumPy's too); ValueError names it otherwise."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)

