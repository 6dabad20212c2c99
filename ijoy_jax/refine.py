"""Continuous refinement of a chosen step: (dx, dy, dtheta) off the action set's lattice, on the exact cost.

The paper's selector picks from a fixed set of samples, which "can fail to find a possible step in severely
constrained environments" (its section VI): a stone or a gap between two lattice points is out of reach of
the lattice however good the search. Here the chosen step is refined in continuous ``(dx, dy, dtheta)``, on
the exact cost the selector minimises,

    cost(p) = FootCost(p) + w * dist(p, p_next)

with FootCost the exact one (:func:`ijoy_jax.foot_cost_terms`, every term and limit) and ``p_next`` the
continuous ideal step (the paper quantises it to F only to precompute its ordered lists, which a continuous
search does not use). The search is a pattern search, deterministic and derivative-free (FootCost is +inf
wherever a foothold is invalid, so gradients of the relaxed cost of :mod:`ijoy_jax.tune` would have to be
verified anyway; here every candidate is scored by the exact cost itself):

* starts: the method's lattice step and the ``starts - 1`` lattice actions nearest ``p_next`` (valid or
  not: an invalid lattice point may have valid ground a centimetre away);
* moves: the 27-point stencil ``x + h * {-1, 0, 1}^3`` around each start's current point, the best candidate
  taken when it lowers the cost by more than ``min_gain``; two moves per level, ``h`` halving every level
  from half the trust radius (``levels`` levels: ``span`` lattice spacings / 2^levels at the end, 1.6 mm
  and 0.2 deg for HRP-2 at the defaults);
* every candidate stays within the action set's box (the range of S's dx, dy and dtheta for that foot),
  within ``span`` lattice spacings of its start on every axis, and off the stance foot
  (:func:`ijoy_jax.robots.overlaps_stance`); its per-action limits (cost, clearance, step height) are those
  of the lattice action it started from;
* after a lookahead (``method="lookahead"``), a candidate must also keep the plan valid: the planned next
  steps (:attr:`ijoy_jax.lookahead.Plan.sequence`), put down in turn from it, must all stay valid by the exact
  FootCost. The refined step then never leads into a dead end the lattice step avoided, and its own cost
  still never exceeds the lattice step's.

The result is the lowest-cost point found over all starts, or the method's lattice step itself: refinement
never returns a step costlier than that step (measured against ``p_next``), and every refined step is
scored by the exact FootCost, so it is valid whenever its cost is finite. When no lattice step is valid the
other starts may still find one. ``StepChoice.index`` stays the lattice action the step started from.

:func:`ijoy_jax.select_step` (``SelectOptions(refine=True)`` or a :class:`RefineParams` as its ``refine``) is
the public entry point.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ijoy_jax import geometry
from ijoy_jax.footcost import TerrainIndex, foot_cost_terms
from ijoy_jax.robots import Robot, dist, overlaps_stance, side_actions, side_sign
from ijoy_jax.struct import is_traced, pytree_dataclass, static_field
from ijoy_jax.terrain import Terrain

__all__ = ["MOVES_PER_LEVEL", "RefineParams", "Refined", "check_params", "lattice_spacing", "params",
           "params_supported", "refine_step"]

MOVES_PER_LEVEL = 2
"""Stencil moves per step size (static): a point can travel up to two steps before the step halves."""

_STENCIL = np.array([(0, 0, 0)] + [o for o in itertools.product((-1, 0, 1), repeat=3) if o != (0, 0, 0)],
                    np.float32)  # (27, 3): the centre first, so staying put wins ties


@pytree_dataclass
class RefineParams:
    """Options of the refinement (:func:`params` builds and checks them).

    Leaves (traced: changing them never recompiles)::

      span: () float32 trust-region half-width around each start, in lattice spacings per axis (1.0: up to
        the neighbouring lattice points).
      min_gain: () float32 cost units a move must gain to be taken (float32 noise is ~1e-7 of a cost).

    Static::

      levels: step sizes tried (each half the last); 2 moves each.
      starts: start points: the method's lattice step and the ``starts - 1`` actions nearest ``p_next``.
    """

    span: jax.Array
    min_gain: jax.Array
    levels: int = static_field()
    starts: int = static_field()


def params(span: float = 1.0, min_gain: float = 1e-5, *, levels: int = 5, starts: int = 4) -> RefineParams:
    """Checked :class:`RefineParams` (what ``SelectOptions(refine=True)`` uses: the defaults).

    Raises:
      ValueError: a span not finite and > 0, a min_gain not finite and >= 0, levels or starts not an int >= 1.

    Example:
      >>> from ijoy_jax import refine
      >>> p = refine.params(span=0.5)
      >>> float(p.span), p.levels, p.starts
      (0.5, 5, 4)
    """
    for name, v in (("levels", levels), ("starts", starts)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be an int >= 1 (static), got {v!r}")
    check_params(RefineParams(span, min_gain, int(levels), int(starts)))
    return RefineParams(jnp.asarray(span, jnp.float32), jnp.asarray(min_gain, jnp.float32), int(levels),
                        int(starts))


def check_params(p, num_actions: int | None = None) -> None:
    """Refuse a bad :class:`RefineParams` at the boundary (concrete leaves; traced ones are flagged instead)."""
    if not isinstance(p, RefineParams):
        raise TypeError(f"refine must be a bool or an ijoy_jax.refine.RefineParams (refine.params), "
                        f"got {type(p).__name__}")
    for name, v, positive in (("span", p.span, True), ("min_gain", p.min_gain, False)):
        if is_traced(v):
            continue
        a = np.asarray(v, np.float64)
        if a.shape != ():
            raise ValueError(f"refine {name} must be a scalar, got shape {a.shape}")
        if not np.isfinite(a) or (a <= 0 if positive else a < 0):
            raise ValueError(f"refine {name} must be finite and {'> 0' if positive else '>= 0'}, got {float(a)}")
    if num_actions is not None and p.starts > num_actions:
        raise ValueError(f"refine starts must be at most the action set's size N = {num_actions}, got {p.starts}")


def params_supported(p: RefineParams) -> jax.Array:
    """() bool: refinement options the search supports (traceable): span finite and > 0, min_gain finite, >= 0."""
    return jnp.isfinite(p.span) & (p.span > 0) & jnp.isfinite(p.min_gain) & (p.min_gain >= 0)


def lattice_spacing(robot: Robot) -> tuple[float, float, float]:
    """The action set's lattice spacing per axis (m, m, rad; static): twice the step of the target set F
    (:func:`ijoy_jax.robots.target_lattice` puts two points of F per action spacing)."""
    return tuple(2.0 * s for s in robot.target_grid[1])


class Refined(NamedTuple):
    """The result of :func:`refine_step` (one decision).

    Fields::

      rel: (3,) the refined step in the stance foot's frame (dx, dy, dtheta; m, rad).
      pose: (3,) its world pose.
      cost: () FootCost + w * dist(rel, p_next) (+inf when no valid point was found).
      foot_cost: () its FootCost.
      index: () int32 the lattice action it started from (-1 when no valid point was found).
      start_cost: () the method's lattice step's cost against p_next (+inf if it had none or it was invalid):
        ``cost <= start_cost`` always.
      evaluated: () int32 FootCost evaluations.
    """

    rel: jax.Array
    pose: jax.Array
    cost: jax.Array
    foot_cost: jax.Array
    index: jax.Array
    start_cost: jax.Array
    evaluated: jax.Array


def refine_step(terrain: Terrain, robot: Robot, stance, stance_side, target, chosen, p: RefineParams, *,
                swing_from=None, index: TerrainIndex | None = None, continuation=None) -> Refined:
    """Refine the lattice step ``chosen`` in continuous (dx, dy, dtheta) (see the module docstring).

    Args:
      terrain, robot: as :func:`ijoy_jax.select_step`.
      stance: (3,) world pose of the stance foot (m, rad); stance_side: +1 left, -1 right.
      target: (3,) ``p_next`` in the stance foot's frame (the swing foot's ideal step).
      chosen: () int32 the method's lattice action (-1: none was valid; the other starts are still searched).
      p: :class:`RefineParams`.
      swing_from: (3,) where the swing foot starts (the swing-path check), or None.
      index: the terrain's prebuilt index (:func:`ijoy_jax.select.prepare`), built inside when None.
      continuation: (K,) int32 lattice actions of the steps planned after this one (the lookahead's best
        sequence, :attr:`ijoy_jax.lookahead.Plan.sequence` after its first), or None. A candidate is then
        valid only if those steps, put down in turn from it (feet alternating, each swing foot starting where
        it stood), all stay valid by the exact FootCost: refinement never turns the plan into a dead end.

    Returns:
      :class:`Refined`. Traceable; vmap for batches.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> free = np.ones((100, 100), bool); free[55:, :] = False        # wall at x = 1.1 m
      >>> terrain = ij.terrain.from_arrays(None, free, 0.02)
      >>> robot = ij.robots.hrp2(margin=0.02)
      >>> lattice = ij.select_step(terrain, robot, [0.77, 1.0, 0.0], -1, [0.25, 0.0, 0.0])
      >>> fine = ij.select_step(terrain, robot, [0.77, 1.0, 0.0], -1, [0.25, 0.0, 0.0], ij.SelectOptions(refine=True))
      >>> round(float(lattice.pose[0]), 3), round(float(fine.pose[0]), 3), int(fine.index) == int(lattice.index)
      (0.92, 0.957, True)
    """
    stance = jnp.asarray(stance, jnp.float32)
    target = jnp.asarray(target, jnp.float32)
    side = side_sign(stance_side)
    acts = side_actions(robot, -side)  # (N, 3) in the stance frame
    n = robot.num_actions
    starts = min(p.starts, n)
    d_all = dist(acts, target, robot.rotation_weight)
    near = jnp.lexsort((jnp.arange(n, dtype=jnp.int32), d_all))[:starts].astype(jnp.int32)
    chosen = jnp.asarray(chosen, jnp.int32)
    first = jnp.where(chosen >= 0, chosen, near[0])
    idx = jnp.concatenate([first[None], near[: starts - 1]])  # (S,) start actions: the chosen one first
    x0 = acts[idx]  # (S, 3)
    radius = p.span * jnp.asarray(lattice_spacing(robot), jnp.float32)  # (3,)
    lo = jnp.maximum(jnp.min(acts, axis=0), x0 - radius)  # (S, 3): the box of S and the trust region
    hi = jnp.minimum(jnp.max(acts, axis=0), x0 + radius)

    def costs(rel, a, plan=True):
        """(M,) FootCost and cost of steps ``rel`` (M, 3) taken as actions ``a`` (M,); with ``plan``, +inf
        where the planned continuation would not stay valid."""
        world = geometry.compose(stance, rel)
        fc = foot_cost_terms(terrain, robot, stance, side, world, swing_from=swing_from, action_index=a,
                             index=index).total
        fc = jnp.where(overlaps_stance(robot, rel), jnp.inf, fc).astype(jnp.float32)
        if plan and continuation is not None:
            fc = jnp.where(_continues(world), fc, jnp.inf)
        return fc, (fc + robot.w * dist(rel, target, robot.rotation_weight)).astype(jnp.float32)

    def _continues(world):
        """(M,) bool: the planned steps after ``world`` (M, 3) are all valid, put down from it in turn."""
        here, prev, sd = world, jnp.broadcast_to(stance, world.shape), -side
        ok = jnp.ones(world.shape[:1], bool)
        for b in jnp.asarray(continuation, jnp.int32):
            nxt = geometry.compose(here, side_actions(robot, -sd)[jnp.maximum(b, 0)])

            def one(st, pv, nx, sd=sd, b=b):
                return foot_cost_terms(terrain, robot, st, sd, nx[None], swing_from=None if swing_from is None else pv,
                                       action_index=jnp.maximum(b, 0)[None], index=index).total[0]

            ok = ok & ((b < 0) | jnp.isfinite(jax.vmap(one)(here, prev, nxt)))
            here, prev, sd = nxt, here, -sd
        return ok

    fc0, c0 = costs(x0, idx)
    # The lattice step as the method chose it, scored without the plan's check (which it passes by construction,
    # up to float32 rounding of a metric at its limit: then the step stays as chosen).
    lat_fc, lat_c = (v[0] for v in costs(x0[:1], idx[:1], plan=False))
    start_cost = jnp.where(chosen >= 0, lat_c, jnp.inf)
    stencil = jnp.asarray(_STENCIL)
    k = len(_STENCIL)
    moves = MOVES_PER_LEVEL * p.levels

    def move(m, state):
        x, c, fc = state
        h = radius * jnp.exp2(-(1.0 + (m // MOVES_PER_LEVEL)).astype(jnp.float32))
        cand = jnp.clip(x[:, None, :] + h * stencil[None], lo[:, None, :], hi[:, None, :])  # (S, 27, 3)
        cfc, cc = costs(cand.reshape(-1, 3), jnp.repeat(idx, k))
        cfc, cc = cfc.reshape(starts, k), cc.reshape(starts, k)
        j = jnp.argmin(cc, axis=1)  # first of equal costs: the centre
        best = jnp.take_along_axis(cc, j[:, None], 1)[:, 0]
        gain = best < c - p.min_gain  # +inf - gain is +inf: any finite point beats an invalid start
        x = jnp.where(gain[:, None], cand[jnp.arange(starts), j], x)
        fc = jnp.where(gain, jnp.take_along_axis(cfc, j[:, None], 1)[:, 0], fc)
        return x, jnp.where(gain, best, c), fc

    x, c, fc = lax.fori_loop(0, moves, move, (x0, c0, fc0))
    w = jnp.argmin(c)  # the chosen lattice step's search first among equal costs
    found = jnp.isfinite(c[w])
    # Never worse than the lattice step (its own search started there, at its cost); no valid point: unchanged.
    keep = ~found | (c[w] >= start_cost)
    rel = jnp.where(keep, x0[0], x[w])
    cost = jnp.where(keep, start_cost, c[w])
    out_fc = jnp.where(keep, jnp.where(chosen >= 0, lat_fc, jnp.inf), fc[w])
    out_idx = jnp.where(keep, jnp.where(chosen >= 0, chosen, -1), idx[w])
    per_candidate = 1 + (0 if continuation is None else int(jnp.shape(continuation)[0]))
    evaluated = starts * (1 + moves * k) * per_candidate + 1
    return Refined(rel=rel, pose=geometry.compose(stance, rel), cost=cost.astype(jnp.float32),
                   foot_cost=out_fc.astype(jnp.float32), index=out_idx.astype(jnp.int32),
                   start_cost=start_cost.astype(jnp.float32), evaluated=jnp.int32(evaluated))

