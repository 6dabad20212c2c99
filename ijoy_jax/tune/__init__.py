"""Tuning by gradient: a smooth relaxation of step selection and optax tuners.

Modules::

  relax     soft FootCost and the Boltzmann (softmin) selector
  inverse   recover parameters from demonstrations (maximum-entropy likelihood)
  forward   minimise command error + obstacle risk; exact held-out evaluation
  loop      the one tuning loop: jitted optax steps, vmapped runs, in-graph scans, progress, save/load
  relaxed_rollout  the relaxed control-loop rollout, differentiable end to end

Top-level API (one symbol per line below)::

  tune(loss_fn, params0, optimizer, steps, *, key, ...)  -> TuneResult   the generic loop
  make_tuner(loss_fn, optimizer, ...)                    -> Tuner        init/step, for your own loop
  run_steps(tuner, state, steps, ...)                    -> (state, metrics, trajectory)  in one lax.scan
  load(out_dir)                                          -> Saved        params, losses, manifest
  positive(), interval(lo, hi)                           -> Bijector     constrained parameters
  ForwardConfig, tune_forward(robot, cfg, ...)           -> ForwardResult
  compare(tuned, cfg, num=..., key=...)                  -> dict         exact held-out numbers vs the paper's
  fit(demos, robot, names, ...)                          -> FitResult    the inverse problem
  relaxed_select(terrain, robot, stance, side, command, *, sharpness, tau) -> RelaxedChoice

Example:
  >>> import jax.numpy as jnp, optax
  >>> from ijoy_jax import tune
  >>> r = tune.tune(lambda p, b: jnp.sum((p - 1.0) ** 2), jnp.zeros(2), optax.adam(0.1), 5, key=0, progress=False)
  >>> r.losses.shape
  (5,)
"""

from ijoy_jax.optim import Bijector as Bijector
from ijoy_jax.optim import Tuner as Tuner
from ijoy_jax.optim import interval as interval
from ijoy_jax.optim import make_tuner as make_tuner
from ijoy_jax.optim import positive as positive
from ijoy_jax.optim import run_steps as run_steps
from ijoy_jax.tune import forward as forward
from ijoy_jax.tune import inverse as inverse
from ijoy_jax.tune import loop as loop
from ijoy_jax.tune import relax as relax
from ijoy_jax.tune import relaxed_rollout as relaxed_rollout
from ijoy_jax.tune.forward import ForwardConfig as ForwardConfig
from ijoy_jax.tune.forward import ForwardResult as ForwardResult
from ijoy_jax.tune.forward import compare as compare
from ijoy_jax.tune.forward import tune_forward as tune_forward
from ijoy_jax.tune.inverse import FitResult as FitResult
from ijoy_jax.tune.inverse import fit as fit
from ijoy_jax.tune.loop import Saved as Saved
from ijoy_jax.tune.loop import TuneResult as TuneResult
from ijoy_jax.tune.loop import load as load
from ijoy_jax.tune.loop import save as save
from ijoy_jax.tune.loop import tune as tune
from ijoy_jax.tune.relax import RelaxedChoice as RelaxedChoice
from ijoy_jax.tune.relax import relaxed_select as relaxed_select

__all__ = [
    "Bijector",
    "FitResult",
    "ForwardConfig",
    "ForwardResult",
    "RelaxedChoice",
    "Saved",
    "TuneResult",
    "Tuner",
    "compare",
    "fit",
    "forward",
    "interval",
    "inverse",
    "load",
    "loop",
    "make_tuner",
    "positive",
    "relax",
    "relaxed_rollout",
    "relaxed_select",
    "run_steps",
    "save",
    "tune",
    "tune_forward",
]
