"""Lookahead step selection: score sequences of H steps under the held command and take the first step of the best.

The paper's selector looks at the next step only (its section VI names it as a drawback): a step that is the
best on its own may leave the robot on a foothold from which no good next step exists, or none at all. Here a
decision scores whole sequences of ``horizon`` steps, feet alternating, under the command held throughout:

* step 1 is the decision's own: the swing foot leaves ``swing_from`` and lands at ``p_a`` (action ``a`` of S
  from the stance ``s0``);
* step 2 is taken by the other foot: the old stance foot swings from ``s0`` (its swing-path check starts
  there), its stance is ``p_a``, and its ideal step ``p_next`` is computed from ``p_a`` with the same command;
* step k alternates likewise.

Each step costs what the one-step selector charges, ``c_k = FootCost_k + w * dist_k`` (the same FootCost, the
same target ``f_i`` or ``p_next``), and a sequence ``a_1 .. a_H`` scores

    J = c_1 + gamma c_2 + gamma^2 c_3 + ... + gamma^(H-1) c_H          (gamma: the discount, >= 0)

with ``J = +inf`` as soon as one step is invalid. The score of a first action is the best score of the
sequences it starts, ``V(a) = c_1(a) + gamma min_b [...]``; the decision takes the first action of lowest
``V``, ties broken as the one-step selector breaks them (lowest ``V``, then lowest dist of the first step to
its target, then lowest action index). Rules at the edges:

* ``horizon = 1`` is the one-step exhaustive selector, exactly.
* A first step from which no valid continuation exists (a dead end: ``V = +inf``) is never taken while some
  first step has one. If every valid first step is a dead end, the decision falls back to the one-step choice
  (``Plan.dead_end``): the robot takes the best step it has rather than stopping a step early.
* No valid first step: no step, as the one-step selector (the robot stops).
* ``gamma = 0`` is the one-step choice among first steps that have a valid continuation. An invalid discount
  (NaN, inf or < 0, traced) makes the decision unsupported, like a robot value FootCost does not support.

Two searches give the first action:

* exact (``beam=None``): branch and bound over the first actions in order of ``c_1``. FootCost is never
  negative, so ``V(a) >= c_1(a) + gamma LB`` with ``LB`` the dists' share of the rest
  (``w min dist_2 + gamma w min dist_3 + ...``); first actions are expanded ``chunk`` at a time and the search
  stops once the best score found is below the bound of the next one (strictly: ties are expanded). Each
  expansion is the exact search of horizon ``H - 1`` from the new stance (recursively), so the result is the
  brute-force minimum over all ``N^H`` sequences. Open ground typically expands one chunk (``chunk x N``
  FootCost evaluations for ``H = 2``); a map where every first step is a dead end expands all of them
  (``N^2``, e.g. 246 k for HRP-2). Fine for ``H = 2``; for ``H >= 3`` its worst case is ``N^H``: use a beam.
* beam (``beam=K``): the ``K`` best first actions by ``c_1``, then at each further level the ``K`` best partial
  sequences by their score so far (ties by rank, then action index) out of ``K x N`` expansions, and the
  best complete sequence: a fixed ``(H - 1) K N`` FootCost evaluations per decision, what a GPU wants. With
  ``K = N`` and ``H = 2`` it is exact; its loss against exact is measured in docs/lookahead.md.

Every function here is for one decision (vmap for batches) and traceable; :func:`ijoy_jax.select_step`
(``method="lookahead"``) is the public entry point, which builds the FootCost oracle and the dists.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ijoy_jax import geometry, limits
from ijoy_jax.robots import Robot, side_actions, side_sign
from ijoy_jax.struct import is_traced

__all__ = ["DEFAULT_CHUNK", "CostsFrom", "Plan", "check_options", "discount_supported", "search"]

DEFAULT_CHUNK = 8
"""First actions expanded per iteration of the exact search (static): 8 x 496 FootCost evaluations per
iteration for HRP-2 on a CPU; a GPU wants more (``SelectOptions(method="lookahead", chunk=64)``)."""


class Plan(NamedTuple):
    """The result of :func:`search` (one decision).

    Fields::

      first: () int32 the first action taken (the one-step choice on a fallback; -1 when no first step is valid).
      score: () float32 ``V`` of the first action taken: the best score of the sequences it starts (+inf on a
        fallback or when none is valid).
      dead_end: () bool, every valid first step was a dead end: ``first`` is the one-step choice.
      sequence: (H,) int32 the actions of the best sequence found, the first one ``first`` (all -1 on a fallback
        or when none): what :mod:`ijoy_jax.refine` keeps valid when it refines the first step.
      expanded: () int32 first actions whose continuations were evaluated.
      evaluated: () int32 FootCost evaluations beyond the first level's N (the exact search's include the
        re-derivation of its best sequence's continuation: N more for H = 2).
    """

    first: jax.Array
    score: jax.Array
    dead_end: jax.Array
    sequence: jax.Array
    expanded: jax.Array
    evaluated: jax.Array


CostsFrom = Callable[[jax.Array, jax.Array, "jax.Array | None"], jax.Array]
"""``costs_from(stance (3,), stance_side (), swing_from (3,) or None) -> (N,)`` FootCost of every action of S
put down from ``stance``: the oracle :func:`search` calls for the levels after the first."""


def discount_supported(discount) -> jax.Array:
    """() bool: a discount the search supports (finite and >= 0; traceable)."""
    g = jnp.asarray(discount, jnp.float32)
    return jnp.isfinite(g) & (g >= 0)


def _add_tail(c, tail, discount):
    """``c + discount * tail``, +inf where either is +inf (never ``0 * inf``)."""
    ok = jnp.isfinite(c) & jnp.isfinite(tail)
    return jnp.where(ok, c + discount * jnp.where(ok, tail, 0.0), jnp.inf).astype(jnp.float32)


def _better(j, d, i, bj, bd, bi):
    """Lexicographic (score, dist, index) comparison: is (j, d, i) strictly before (bj, bd, bi)?"""
    return (j < bj) | ((j == bj) & ((d < bd) | ((d == bd) & (i < bi))))


def _lex_order(c, d):
    """Action indices sorted by (c, d, index)."""
    idx = jnp.arange(c.shape[0], dtype=jnp.int32)
    return jnp.lexsort((idx, d, c)).astype(jnp.int32)


class _Level(NamedTuple):
    """What the searches need to know about the decision (closed over, one per decision)."""

    robot: Robot
    costs_from: CostsFrom
    dists: tuple  # per parity: (N,) dist of each action to its target; level k (1-based) uses dists[(k - 1) % 2]
    discount: jax.Array
    horizon: int
    chunk: int

    def cost(self, level, fc):
        return (fc + self.robot.w * self.dists[(level - 1) % 2]).astype(jnp.float32)

    def bound(self, level):
        """Lower bound of the discounted cost of levels ``level .. horizon`` (FootCost >= 0)."""
        lb = jnp.float32(0.0)
        for k in range(self.horizon, level - 1, -1):
            lb = self.robot.w * jnp.min(self.dists[(k - 1) % 2]) + self.discount * lb
        return lb.astype(jnp.float32)


def _branch_and_bound(lv: _Level, level: int, c, steps, stance, side, swing_from):
    """The exact search at ``level`` (< horizon) given its step costs ``c`` (N,): best (index, score, count of
    first actions expanded, FootCost evaluations below). ``side`` is the stance side at this level."""
    n = c.shape[0]
    d = lv.dists[(level - 1) % 2]
    order = _lex_order(c, d)
    n_valid = jnp.sum(jnp.isfinite(c)).astype(jnp.int32)
    lb = lv.bound(level + 1)
    chunk = min(lv.chunk, n)
    num_chunks = -(-n // chunk)

    def tail(idx):
        """V of the next level from each action's foothold: (chunk,) values and the evaluations they took."""
        def one(step):
            return _value(lv, level + 1, step, -side, stance)
        return jax.vmap(one)(steps[idx])

    def cond(state):
        k, bj, _, _, _ = state
        nxt = order[jnp.minimum(k * chunk, n - 1)]
        hopeless = bj < _add_tail(c[nxt], lb, lv.discount)  # nothing unexpanded can match the best: done
        return (k < num_chunks) & (k * chunk < n_valid) & ~hopeless

    def body(state):
        k, bj, bd, bi, evals = state
        pos = k * chunk + jnp.arange(chunk, dtype=jnp.int32)
        idx = order[jnp.minimum(pos, n - 1)]
        values, ev = tail(idx)
        j = jnp.where(pos < n_valid, _add_tail(c[idx], values, lv.discount), jnp.inf)
        dd = d[idx]
        cand = jnp.lexsort((idx, dd, j))[0]  # the chunk's best by (score, dist, action index)
        take = jnp.isfinite(j[cand]) & _better(j[cand], dd[cand], idx[cand], bj, bd, bi)
        return (k + 1, jnp.where(take, j[cand], bj), jnp.where(take, dd[cand], bd), jnp.where(take, idx[cand], bi),
                evals + jnp.sum(ev).astype(jnp.int32))

    init = (jnp.int32(0), jnp.float32(jnp.inf), jnp.float32(jnp.inf), jnp.int32(-1), jnp.int32(0))
    k, bj, _, bi, evals = lax.while_loop(cond, body, init)
    return bi, bj, jnp.minimum(k * chunk, n_valid).astype(jnp.int32), evals


def _value(lv: _Level, level: int, stance, side, swing_from):
    """``min`` over sequences of levels ``level .. horizon`` from ``stance`` (its side ``side``), and the FootCost
    evaluations it took: the exact search's recursion (one evaluation of N per level, plus the expansions)."""
    n = lv.robot.num_actions
    fc = lv.costs_from(stance, side, swing_from)
    c = lv.cost(level, fc)
    if level == lv.horizon:
        return jnp.min(c), jnp.int32(n)
    steps = geometry.compose(stance, side_actions(lv.robot, -side))
    _, best, _, evals = _branch_and_bound(lv, level, c, steps, stance, side, swing_from)
    return best, jnp.int32(n) + evals


def _continuation(lv: _Level, first, steps1, stance, side):
    """The rest of the exact search's best sequence after its first action: at each level the exact search of
    the remaining horizon from where the sequence stands (what the search found, re-derived: one exact search
    of horizon H - 1 and one of N evaluations per later level). Returns ((H - 1,) actions, evaluations)."""
    robot, n = lv.robot, lv.robot.num_actions
    idx = jnp.arange(n, dtype=jnp.int32)
    here, prev, sd = steps1[first], stance, -side
    out, evals = [], jnp.int32(0)
    for level in range(2, lv.horizon + 1):
        c = lv.cost(level, lv.costs_from(here, sd, prev))
        evals = evals + jnp.int32(n)
        acts = side_actions(robot, -sd)
        if level < lv.horizon:
            best, _, _, ev = _branch_and_bound(lv, level, c, geometry.compose(here, acts), here, sd, prev)
            evals = evals + ev
        else:
            best = jnp.lexsort((idx, lv.dists[(level - 1) % 2], c))[0].astype(jnp.int32)
        best = jnp.maximum(best, 0)
        out.append(best)
        here, prev, sd = geometry.compose(here, acts[best]), here, -sd
    return jnp.stack(out).astype(jnp.int32), evals


def _beam(lv: _Level, c1, steps1, stance, side, beam: int):
    """The beam search: (first action, score, sequence (H,), FootCost evaluations)."""
    robot, n, h = lv.robot, lv.robot.num_actions, lv.horizon
    order = _lex_order(c1, lv.dists[0])[:beam]
    first, score = order, c1[order]  # (K,): each entry's first action and score so far
    seq = order[:, None]
    here, prev = steps1[order], jnp.broadcast_to(stance, (beam, 3))  # each entry's stance and its swing foot's pose
    sd = -side  # the stance side at level 2: the foot put down at level 1
    scale = jnp.float32(1.0)
    evals = jnp.int32(0)
    flat_j = None
    for level in range(2, h + 1):
        scale = scale * lv.discount
        fc = jax.vmap(lambda st, pv, sd=sd: lv.costs_from(st, sd, pv))(here, prev)  # (K, N)
        c = lv.cost(level, fc)
        ok = jnp.isfinite(score)[:, None] & jnp.isfinite(c)
        j = jnp.where(ok, score[:, None] + scale * jnp.where(ok, c, 0.0), jnp.inf).astype(jnp.float32)
        evals = evals + jnp.int32(beam * n)
        flat_j = j.reshape(-1)  # entry-major: ties keep the entry's rank, then the action index
        if level == h:
            break
        keep = jnp.argsort(flat_j, stable=True)[:beam].astype(jnp.int32)
        e, a = keep // n, keep % n
        acts = side_actions(robot, -sd)
        nxt = geometry.compose(here[e], acts[a])
        first, score, seq = first[e], flat_j[keep], jnp.concatenate([seq[e], a[:, None]], axis=1)
        here, prev, sd = nxt, here[e], -sd
    best = jnp.argmin(flat_j).astype(jnp.int32)
    e, a = best // n, best % n
    sequence = jnp.concatenate([seq[e], a[None]])
    return first[e], flat_j[best], sequence, evals


def search(c1, steps1, stance, stance_side, swing_from, costs_from: CostsFrom, robot: Robot, dists, discount, *,
           horizon: int, beam: int | None = None, chunk: int = DEFAULT_CHUNK) -> Plan:
    """The first step of the best sequence of ``horizon`` steps (see the module docstring for the score).

    Args:
      c1: (N,) float32 the first step's costs ``FootCost + w * dist`` of every action (+inf where invalid).
      steps1: (N, 3) world poses of the first step's footholds (action ``a`` put down from ``stance``).
      stance: (3,) world pose of the stance foot ``s0`` (m, rad); stance_side: () +1 left, -1 right.
      swing_from: (3,) where the first step's swing foot starts, or None (no swing-path checks at any level;
        otherwise level k's swing foot starts where it stood, level 2's at ``stance``).
      costs_from: the FootCost oracle of the levels after the first (:data:`CostsFrom`).
      robot: the robot (``w``, its actions; N = ``robot.num_actions``).
      dists: ``(d_odd, d_even)``, each (N,): dist of every action to its target at the odd levels (the first
        step's side) and at the even levels (the other foot's).
      discount: () gamma >= 0 (traced).
      horizon: H >= 1 (static); beam: None (exact) or K in [1, N] (static); chunk: first actions expanded per
        iteration of the exact search (static).

    Returns:
      :class:`Plan`. The caller checks ``discount`` (:func:`discount_supported`).

    Example:
      >>> import ijoy_jax as ij
      >>> terrain, robot = ij.terrain.flat((100, 100), 0.02), ij.robots.hrp2()
      >>> options = ij.SelectOptions(method="lookahead", horizon=2)
      >>> c = ij.select_step(terrain, robot, [1.0, 1.0, 0.0], -1, [0.25, 0.0, 0.0], options)
      >>> bool(c.valid), round(float(c.pose[0]), 2)
      (True, 1.2)
    """
    side = side_sign(stance_side)
    discount = jnp.asarray(discount, jnp.float32)
    c1 = jnp.asarray(c1, jnp.float32)
    lv = _Level(robot, costs_from, tuple(jnp.asarray(d, jnp.float32) for d in dists), discount, horizon, chunk)
    fallback = _lex_order(c1, lv.dists[0])[0]
    any_valid = jnp.isfinite(c1[fallback])
    none = jnp.full((horizon,), -1, jnp.int32)
    if horizon == 1:
        first = jnp.where(any_valid, fallback, -1).astype(jnp.int32)
        return Plan(first, jnp.where(any_valid, c1[fallback], jnp.inf), jnp.bool_(False),
                    first[None], jnp.int32(0), jnp.int32(0))
    if beam is None:
        best, score, expanded, evals = _branch_and_bound(lv, 1, c1, steps1, stance, side, swing_from)
        rest, more = _continuation(lv, jnp.maximum(best, 0), steps1, stance, side)
        sequence = jnp.concatenate([best[None], rest])
        evals = evals + more
    else:
        best, score, sequence, evals = _beam(lv, c1, steps1, stance, side, beam)
        expanded = jnp.int32(beam)
    found = jnp.isfinite(score)
    dead_end = any_valid & ~found
    first = jnp.where(found, best, jnp.where(any_valid, fallback, -1)).astype(jnp.int32)
    sequence = jnp.where(found, sequence, none).astype(jnp.int32)
    return Plan(first, jnp.where(found, score, jnp.inf).astype(jnp.float32), dead_end, sequence,
                expanded, evals)


def check_options(method: str, horizon, beam, num_actions: int | None, discount) -> None:
    """Refuse bad lookahead options at the boundary (ValueError/TypeError naming the option).

    ``horizon``: an int >= 1; ``beam``: None or an int in [1, N] (``num_actions`` None: at least 1, N
    unchecked); the lookahead options are accepted only with ``method="lookahead"``; a concrete ``discount``
    must be finite and >= 0 (a traced one is flagged instead; None: not checked here).
    :class:`ijoy_jax.SelectOptions` runs it when built and again with the robot's N at the API boundary.
    """
    for name, v in (("horizon", horizon), ("beam", beam)):
        if v is None and name == "beam":
            continue
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise TypeError(f"{name} must be an int (static), got {type(v).__name__} {v!r}")
    if horizon < 1:
        raise ValueError(f"horizon must be >= 1 (steps scored per decision; 1 is the one-step selector), got "
                         f"{horizon}")
    if horizon > limits.MAX_HORIZON:  # one search level per step in the program: refused before it is traced
        raise ValueError(f"horizon must be <= ijoy_jax.limits.MAX_HORIZON = {limits.MAX_HORIZON} (one search level "
                         f"per step in the compiled program), got {horizon}")
    if beam is not None and not 1 <= beam <= (beam if num_actions is None else num_actions):
        n = "N" if num_actions is None else num_actions
        raise ValueError(f"beam must be in [1, {n}] (sequences kept per level, at most the action set's "
                         f"size N = {n}), got {beam}")
    if method != "lookahead" and (horizon != 1 or beam is not None):
        raise ValueError(f"horizon and beam are options of method='lookahead', got method={method!r} with "
                         f"horizon={horizon}, beam={beam}")
    if discount is not None and not is_traced(discount):
        g = np.asarray(discount, np.float64)
        if g.shape != ():
            raise ValueError(f"discount must be a scalar, got shape {g.shape}")
        if not (np.isfinite(g) and g >= 0):
            raise ValueError(f"discount must be finite and >= 0 (the weight of the later steps), got {float(g)}")
