"""Inverse problem: recover selector parameters from demonstrated steps (maximum-entropy likelihood).

A demonstration is one decision: a terrain, a stance pose and side, a joystick
command, and the index of the action that was taken. Under the relaxed
selector (:func:`ijoy_jax.tune.relax.relaxed_select`) the demonstrated action
has probability ``p(a | params) = softmax(-cost / tau)[a]``; the tuner
minimises the mean negative log-likelihood over the demonstrations with optax
(Adam), over the logarithms of positive Robot scalars (``w``,
``rotation_weight``, ``margin``, ``metrics.slope_weight``, ...).

When only ``w`` and ``rotation_weight`` are tuned, the soft FootCost does not
depend on the parameters and is computed once (the objective is the same).

Example:
  >>> import numpy as np, ijoy_jax as ij
  >>> from ijoy_jax.tune import inverse
  >>> free = np.ones((60, 60), bool); free[40:, :] = False
  >>> t = ij.terrain.from_arrays(None, free, resolution=0.02)
  >>> robot = ij.robots.hrp2(margin=0.02, density=0.25)
  >>> demos = inverse.make_demonstrations(inverse.stack_terrains([t, t]), robot,
  ...     np.array([[0.5, 0.4, 0.0], [0.5, 0.4, 0.1]]), np.array([-1.0, -1.0]),
  ...     np.array([[0.2, 0.0, 0.1], [0.0, 0.0, -0.2]]))
  >>> fit = inverse.fit(demos, robot, ("w", "rotation_weight"), num_steps=5)
  >>> fit.losses.shape
  (5,)
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ijoy_jax import geometry, optim
from ijoy_jax.robots import Robot, dist, get_leaf, set_leaf, side_actions, side_p0, side_sign
from ijoy_jax.select import prepare, select_step
from ijoy_jax.select_options import SelectOptions, checked
from ijoy_jax.targets import make_targets
from ijoy_jax.terrain import Terrain
from ijoy_jax.tune import relax

_SELECTOR_ONLY = frozenset({"w", "rotation_weight"})  # soft FootCost does not depend on these


class Demonstrations(NamedTuple):
    """D demonstrated decisions (a batch; terrains stacked along a leading axis).

    terrains: Terrain with (D, nx, ny) leaves (same shape and resolution).
    stances: (D, 3) world stance poses (m, rad).
    sides: (D,) stance side, +1 left / -1 right.
    commands: (D, 3) joystick commands (m/s, m/s, rad/s).
    actions: (D,) int32 demonstrated action index (-1: no valid step).
    """

    terrains: Terrain
    stances: jax.Array
    sides: jax.Array
    commands: jax.Array
    actions: jax.Array

    def take(self, idx) -> Demonstrations:
        """The demonstrations at integer indices ``idx`` (NumPy/host)."""
        return jax.tree.map(lambda x: x[np.asarray(idx)], self)


class FitResult(NamedTuple):
    """Result of :func:`fit`.

    Fields::

      robot: the Robot with the fitted parameters.
      params: dict name -> fitted value (natural units).
      losses: (num_steps,) mean negative log-likelihood per Adam step (nats)
        of the best start.
      final_losses: (R,) final loss of every start (R = 1 without restarts).
    """

    robot: Robot
    params: dict
    losses: jax.Array
    final_losses: jax.Array


def stack_terrains(terrains) -> Terrain:
    """Stack a list of same-shape Terrains into one Terrain with a leading batch axis."""
    return jax.tree.map(lambda *x: jnp.stack(x), *terrains)


@jax.jit
def _exact_actions(terrains, robot, stances, sides, commands, options):
    targets = make_targets(robot)

    def one(t, s, side, c):
        p = prepare(t, robot, targets=targets)
        return select_step(t, robot, s, side, c, options, targets=p.targets, index=p.index).index

    return jax.vmap(one)(terrains, stances, sides, commands)


def _exact_options(options: SelectOptions | None, robot: Robot) -> SelectOptions:
    """The exact selector's options here: None is the exhaustive search scored against p_next
    (``quantize=False``, as :func:`fit` scores), checked against ``robot``."""
    return checked(SelectOptions(quantize=False) if options is None else options, robot)


def make_demonstrations(
    terrains: Terrain, robot: Robot, stances, sides, commands, options: SelectOptions | None = None
) -> Demonstrations:
    """Label decisions with the exact selector at ``robot``'s parameters.

    Args:
      terrains: batched Terrain (D, nx, ny); stances (D, 3); sides (D,); commands (D, 3).
      robot: the (hidden) parameters that generate the choices.
      options: the exact selector's :class:`~ijoy_jax.SelectOptions`; None: the exhaustive search scored
        against p_next (``SelectOptions(quantize=False)``, as :func:`fit` scores; the selector's own
        default quantises to F's nearest target).

    Returns:
      :class:`Demonstrations` (actions -1 where no step is valid).
    """
    stances = jnp.asarray(stances, jnp.float32)
    sides = jnp.asarray(sides, jnp.float32)
    commands = jnp.asarray(commands, jnp.float32)
    actions = _exact_actions(terrains, robot, stances, sides, commands, _exact_options(options, robot))
    return Demonstrations(terrains, stances, sides, commands, actions)


def exact_agreement(demos: Demonstrations, robot: Robot, options: SelectOptions | None = None) -> float:
    """Fraction of demonstrations (with a valid step) whose exact choice at ``robot`` is the demonstrated one
    (``options``: as :func:`make_demonstrations`)."""
    pred = np.asarray(_exact_actions(demos.terrains, robot, demos.stances, demos.sides, demos.commands,
                                     _exact_options(options, robot)))
    act = np.asarray(demos.actions)
    ok = act >= 0
    return float(np.mean(pred[ok] == act[ok]))


def with_params(robot: Robot, log_params: dict) -> Robot:
    """Robot with each named scalar leaf set to ``exp(log_params[name])``."""
    for name, v in log_params.items():
        robot = set_leaf(robot, name, jnp.exp(v).astype(get_leaf(robot, name).dtype))
    return robot


def _dists(robot, side, command):
    swing = -side_sign(side)
    acts = side_actions(robot, swing)
    p_next = side_p0(robot, swing) + robot.step_time * command
    return acts, p_next


def negative_log_likelihood(
    log_params: dict,
    demos: Demonstrations,
    robot: Robot,
    *,
    sharpness,
    tau,
    barrier_weight=1.0,
    footcost=None,
    noise=0.0,
) -> jax.Array:
    """() mean -log p(demonstrated action) under the relaxed selector, demonstrations with action -1 excluded.

    Args:
      log_params: dict name -> () log of a positive Robot scalar (the variables);
        the key ``"tau"``, if present, is the log temperature and overrides ``tau``.
      noise: probability in [0, 1) that a demonstration is a uniformly random
        action: ``p' = (1 - noise) p + noise / N``. Bounds each demonstration's
        loss by ``log(N / noise)``, so a demonstrated foothold a fraction of a
        cell from an obstacle (scored a large finite barrier at finite
        sharpness) cannot dominate the fit.
      demos: :class:`Demonstrations`.
      robot: supplies every other parameter.
      sharpness, tau, barrier_weight: of the relaxation (see :mod:`.relax`).
      footcost: optional (D, N) precomputed soft FootCost (valid only when the
        variables are ``w``/``rotation_weight``).
    """
    log_params = dict(log_params)
    if "tau" in log_params:
        tau = jnp.exp(log_params.pop("tau"))
    rb = with_params(robot, log_params)
    lp_size = robot.num_actions

    def one(t, stance, side, command, action, fc):
        if fc is None:
            r = relax.relaxed_select(
                t, rb, stance, side, command, sharpness=sharpness, tau=tau, barrier_weight=barrier_weight, exact=False
            )
            lp = r.log_probs
        else:
            acts, p_next = _dists(rb, side, command)
            cost = fc + rb.w * dist(acts, p_next, rb.rotation_weight, grad_safe=True)
            lp = jax.nn.log_softmax(-cost / tau)
        lp = lp[jnp.maximum(action, 0)]
        if noise > 0:
            lp = jnp.logaddexp(jnp.log1p(-noise) + lp, jnp.log(noise / lp_size))
        return -lp

    nll = jax.vmap(one)(demos.terrains, demos.stances, demos.sides, demos.commands, demos.actions, footcost)
    ok = demos.actions >= 0
    return jnp.sum(jnp.where(ok, nll, 0.0)) / jnp.maximum(jnp.sum(ok), 1)


@jax.jit
def soft_footcosts(demos: Demonstrations, robot: Robot, sharpness, barrier_weight=1.0) -> jax.Array:
    """(D, N) soft FootCost of every action of every demonstration (independent of w and rotation_weight)."""

    def one(t, stance, side, command):
        acts, _ = _dists(robot, side, command)
        steps = geometry.compose(stance, acts)
        return relax.soft_foot_cost_terms(
            t, robot, stance, steps, jnp.arange(acts.shape[0]), sharpness=sharpness, barrier_weight=barrier_weight
        ).total

    return jax.vmap(one)(demos.terrains, demos.stances, demos.sides, demos.commands)


def fit(
    demos: Demonstrations,
    robot: Robot,
    names=("w", "rotation_weight"),
    *,
    init: dict | None = None,
    sharpness=50.0,
    tau=0.1,
    barrier_weight=1.0,
    noise=0.0,
    learning_rate=0.05,
    num_steps=200,
) -> FitResult:
    """Fit positive Robot scalars to demonstrations by Adam on the max-entropy NLL.

    Args:
      demos: :class:`Demonstrations` (e.g. from :func:`make_demonstrations`).
      robot: the starting Robot (its other leaves are held fixed).
      names: static tuple of scalar leaf names (``"metrics.slope_weight"`` for metrics);
        ``"tau"`` fits the temperature too (the max-entropy model's scale), starting at ``tau``.
      init: optional dict name -> starting value (natural units), a scalar or
        an (R,) array: R starts run at once (vmapped) and the one with the
        lowest final loss is returned. Default: the robot's values. Several
        starts matter: the likelihood is flat in rotation_weight once it is
        large enough that no demonstration trades rotation for translation.
      sharpness, tau, barrier_weight: of the relaxation.
      noise: demonstration noise of :func:`negative_log_likelihood` (robust fit).
      learning_rate: Adam step on the log-parameters.
      num_steps: number of Adam steps, run in one ``lax.scan`` under jit (:func:`ijoy_jax.optim.run_steps`).

    Returns:
      :class:`FitResult` with the fitted Robot, the values and the loss curve.
    """
    names = tuple(names)
    init = {} if init is None else dict(init)
    init.setdefault("tau", tau)
    log0 = {n: jnp.log(jnp.asarray(init[n] if n in init else get_leaf(robot, n), jnp.float32)) for n in names}
    num_starts = max([int(np.size(v)) for v in log0.values()] + [1])
    log0 = {n: jnp.broadcast_to(v, (num_starts,)) for n, v in log0.items()}
    selector_only = set(names) <= _SELECTOR_ONLY | {"tau"}
    fc = soft_footcosts(demos, robot, sharpness, barrier_weight) if selector_only else None
    opt = optax.adam(learning_rate)

    @jax.jit
    def run(log0, fc):
        def loss(p, _):
            return negative_log_likelihood(
                p, demos, robot, sharpness=sharpness, tau=tau, barrier_weight=barrier_weight, footcost=fc, noise=noise
            )

        tuner = optim.make_tuner(loss, opt, num_runs=num_starts)  # the R starts vmapped
        state, metrics, _ = optim.run_steps(tuner, tuner.init(log0), num_steps)
        return state.params, metrics.loss.T

    logp, losses = run(log0, fc)  # (R,) params, (R, num_steps) losses
    best = int(jnp.argmin(losses[:, -1]))
    logp = {n: v[best] for n, v in logp.items()}
    values = {n: float(jnp.exp(v)) for n, v in logp.items()}
    logp.pop("tau", None)
    return FitResult(with_params(robot, logp), values, losses[best], losses[:, -1])
