"""The optimiser loop every tuner of the package shares: optax steps, jitted, over one run or many at once.

The pieces, optax-style:

* :func:`make_tuner` builds a :class:`Tuner`, a NamedTuple of two pure
  functions: ``init(params0) -> TuneState`` and the jitted
  ``step(state, key) -> (state, StepMetrics)``. One compile serves every step
  (the step number, the key and the parameters are traced).
* :func:`run_steps` runs ``step`` in one ``lax.scan`` (pure, jit-able): the
  driver for fits that live inside a jitted function (the inverse problem,
  the haptic tuners, the cue's study). :func:`ijoy_jax.tune.loop.tune` is the
  host-side loop around ``step`` (progress, timing, saving).

Many runs at once: with ``num_runs=R`` every leaf of ``params0`` (and of
``hparams``, if given) carries a leading run axis and the update is
``jax.vmap``-ed over it: R initialisations, or R objectives when the
objective's own weights are passed as ``hparams``. Minibatches are drawn per
step by ``batch_fn(key)`` from ``fold_in(key, step)`` *once per step and
shared by every run* (common random numbers: runs differ only by their
parameters, so their curves are comparable).

Positive parameters: optimise an unconstrained variable and map it through a
:class:`Bijector`: :func:`positive` (``exp``; log space) or :func:`interval`
(a scaled sigmoid, for a parameter with an upper bound such as a safety
margin that must stay within a robot's static window).

It sits below the footstep tuners (:mod:`ijoy_jax.tune`), the haptic tuners
(:mod:`ijoy_jax.haptics.tuning`) and the cue's study, which all use it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ijoy_jax.prng import as_key

__all__ = ["Bijector", "StepMetrics", "TuneState", "Tuner", "interval", "make_tuner", "positive", "run_steps"]


# --------------------------------------------------------------------------- transforms


class Bijector(NamedTuple):
    """A smooth invertible map from an unconstrained variable to a constrained parameter.

    forward: u -> value (elementwise, differentiable).
    inverse: value -> u.
    """

    forward: Callable[[Any], Any]
    inverse: Callable[[Any], Any]


def positive() -> Bijector:
    """``value = exp(u)`` (log space): any u gives a value > 0, and steps are relative changes."""
    return Bijector(jnp.exp, jnp.log)


def interval(lo: float, hi: float) -> Bijector:
    """``value = lo + (hi - lo) * sigmoid(u)``: always inside the open interval (lo, hi).

    Example:
      >>> from ijoy_jax import optim
      >>> b = optim.interval(0.0, 0.06)
      >>> round(float(b.forward(b.inverse(0.02))), 6)
      0.02
    """
    if not hi > lo:
        raise ValueError(f"interval needs hi > lo, got ({lo}, {hi})")
    span = hi - lo

    def inverse(v):
        q = (jnp.asarray(v) - lo) / span
        return jnp.log(q) - jnp.log1p(-q)

    return Bijector(lambda u: lo + span * jax.nn.sigmoid(u), inverse)


# --------------------------------------------------------------------------- tuner


class TuneState(NamedTuple):
    """State of a tuning run (a leading run axis on every leaf when runs are vmapped).

    params: the unconstrained parameters (pytree, float32 leaves).
    opt_state: the optax state.
    step: () int32 number of updates done (shared by every run).
    """

    params: Any
    opt_state: Any
    step: jax.Array


class StepMetrics(NamedTuple):
    """What one update reports (with a leading run axis when runs are vmapped).

    loss: () the objective at the parameters *before* the update.
    terms: dict name -> () named terms of the objective (``has_aux`` loss functions; else empty).
    grad_norm: () global L2 norm of the gradient.
    """

    loss: jax.Array
    terms: dict
    grad_norm: jax.Array


class Tuner(NamedTuple):
    """``init(params0) -> TuneState`` and the jitted ``step(state, key) -> (TuneState, StepMetrics)``."""

    init: Callable[[Any], TuneState]
    step: Callable[[TuneState, jax.Array], tuple[TuneState, StepMetrics]]


def make_tuner(
    loss_fn: Callable,
    optimizer: optax.GradientTransformation,
    *,
    batch_fn: Callable[[jax.Array], Any] | None = None,
    hparams: Any = None,
    num_runs: int | None = None,
    has_aux: bool = False,
) -> Tuner:
    """Build the init and jitted update functions of a tuning run (or of R runs at once).

    Args:
      loss_fn: ``loss_fn(params, batch) -> loss`` (or ``-> (loss, terms)`` with
        ``has_aux``; terms a dict of named () arrays), or with ``hparams``
        ``loss_fn(params, batch, hparams)``. ``batch`` is None without ``batch_fn``.
        Must be a pure, jit-able function of one run (no run axis).
      optimizer: an optax GradientTransformation.
      batch_fn: ``batch_fn(key) -> batch``, a jit-able minibatch sampler; called
        once per step with ``fold_in(key, step)`` and shared by every run.
      hparams: optional pytree of per-objective constants (not optimised),
        with a leading run axis when ``num_runs`` is given.
      num_runs: None for one run; R when params (and hparams) carry a leading
        run axis of size R (the update is vmapped over it).
      has_aux: ``loss_fn`` also returns a dict of named terms.

    Returns:
      :class:`Tuner`. ``step`` is one ``jax.jit`` function: it compiles once
      (``jit_cache.compiled_count(tuner.step) == 1`` after any number of steps).

    Example:
      >>> import jax.numpy as jnp, optax
      >>> from ijoy_jax import optim
      >>> t = optim.make_tuner(lambda p, b: jnp.sum(p ** 2), optax.sgd(0.1))
      >>> s = t.init(jnp.ones(2))
      >>> s, m = t.step(s, jax.random.key(0))
      >>> round(float(m.loss), 3), s.params.tolist()
      (2.0, [0.800000011920929, 0.800000011920929])
    """

    def value_and_grad(params, batch, hp):
        args = (params, batch) if hparams is None else (params, batch, hp)
        if has_aux:
            (loss, terms), g = jax.value_and_grad(loss_fn, has_aux=True)(*args)
        else:
            loss, g = jax.value_and_grad(loss_fn)(*args)
            terms = {}
        return loss, dict(terms), g

    def update_one(params, opt_state, batch, hp):
        loss, terms, g = value_and_grad(params, batch, hp)
        updates, opt_state = optimizer.update(g, opt_state, params)
        params = optax.apply_updates(params, updates)
        return params, opt_state, StepMetrics(loss, terms, optax.tree.norm(g))

    def init(params0) -> TuneState:
        params0 = jax.tree.map(lambda x: jnp.asarray(x, jnp.result_type(x, jnp.float32)), params0)
        if num_runs is not None:
            _check_run_axis("params0", params0, num_runs)
            if hparams is not None:
                _check_run_axis("hparams", hparams, num_runs)
            opt_state = jax.vmap(optimizer.init)(params0)
        else:
            opt_state = optimizer.init(params0)
        return TuneState(params0, opt_state, jnp.zeros((), jnp.int32))

    @jax.jit
    def step(state: TuneState, key) -> tuple[TuneState, StepMetrics]:
        batch = None if batch_fn is None else batch_fn(jax.random.fold_in(key, state.step))
        if num_runs is None:
            params, opt_state, metrics = update_one(state.params, state.opt_state, batch, hparams)
        else:
            hp_axis = None if hparams is None else 0
            params, opt_state, metrics = jax.vmap(update_one, (0, 0, None, hp_axis))(
                state.params, state.opt_state, batch, hparams
            )
        return TuneState(params, opt_state, state.step + 1), metrics

    return Tuner(init, step)


def run_steps(
    tuner: Tuner, state: TuneState, steps: int, *, key=None, trace_params: bool = False
) -> tuple[TuneState, StepMetrics, Any]:
    """``steps`` updates of ``tuner.step`` in one ``lax.scan``: pure and jit-able (the in-graph twin of
    :func:`ijoy_jax.tune.loop.tune`).

    Use it where the whole run belongs inside one jitted function (a fit
    vmapped or differentiated as a whole, or one that takes traced data);
    :func:`ijoy_jax.tune.loop.tune` is the host loop with progress, timing and saving.

    Args:
      tuner: from :func:`make_tuner`.
      state: the starting :class:`TuneState` (``tuner.init(params0)``).
      steps: number of updates (static, >= 1).
      key: PRNG key (or int seed) of the minibatches; None only without ``batch_fn``.
      trace_params: static; also return the parameters before each update.

    Returns:
      ``(state, metrics, trajectory)``: the final state; :class:`StepMetrics`
      with a leading (steps,) axis (then the run axis, if any); the (steps, ...)
      parameters before each update, or None without ``trace_params``.

    Example:
      >>> import jax.numpy as jnp, optax
      >>> from ijoy_jax import optim
      >>> t = optim.make_tuner(lambda p, b: jnp.sum(p ** 2), optax.sgd(0.1))
      >>> s, m, traj = optim.run_steps(t, t.init(jnp.ones(2)), 3, trace_params=True)
      >>> m.loss.shape, traj.shape, round(float(s.params[0]), 3)
      ((3,), (3, 2), 0.512)
    """
    if not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps must be a positive int, got {steps!r}")
    key = None if key is None else as_key(key)

    def body(state, _):
        new, metrics = tuner.step(state, key)
        return new, (metrics, state.params if trace_params else None)

    state, (metrics, trajectory) = jax.lax.scan(body, state, None, length=int(steps))
    return state, metrics, trajectory


def _check_run_axis(name, tree, num_runs):
    for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]:
        if np.ndim(leaf) < 1 or np.shape(leaf)[0] != num_runs:
            raise ValueError(
                f"{name}{jax.tree_util.keystr(path)} must have a leading run axis of size num_runs={num_runs}, "
                f"got shape {np.shape(leaf)}"
            )
