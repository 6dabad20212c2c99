"""The robot a sweep walks (``[sweep] model``): the selector's robot and, with ``walker = "mjx"``, the simulated one.

:data:`~ijoy_jax.sweep.schema.MODELS`, the names :class:`ijoy_jax.sim.model.BipedParams` gives them:

* ``"biped"`` (the default): HRP-2 chooses the steps (:func:`ijoy_jax.robots.hrp2`, its ``reach`` from
  ``[robot] reach``) and the project's HRP-2-like biped walks them in MJX
  (``ijoy_jax.sim.walker.make_sim(..., model="biped")``);
* ``"g1"``: the Unitree G1 chooses them (:func:`ijoy_jax.robots.g1`) and MuJoCo Menagerie's G1 walks them
  (``make_sim(..., model="g1")``, the ``robots`` extra). The G1 takes every ``[robot]`` key but ``reach``
  (:data:`HRP2_ONLY`): its lattice spans the paper's dx range, steps of at most
  :data:`~ijoy_jax.robots.PAPER_REACH`, the range its legs were checked to realise. Its simulated feet are its
  MJCF's foot boxes, so a ``walker = "mjx"`` sweep keeps its footprint (0.18 x 0.06 m).

Every robot a sweep builds comes from :func:`build_robot`; the numbers a sweep file's checks need come from
:func:`robot_defaults`, :func:`actions` and :func:`step_in_place`, host values (no device array: sweep files are
checked before any backend starts).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

from ijoy_jax import robots
from ijoy_jax.sweep.schema import MODELS, ROBOT_DEFAULTS

__all__ = ["HRP2_ONLY", "MODEL_NAMES", "actions", "build_robot", "robot_defaults", "robot_keys", "step_in_place"]

HRP2_ONLY = ("reach",)
"""The ``[robot]`` keys of HRP-2's options that the G1 does not take (:func:`ijoy_jax.robots.hrp2`'s ``reach``)."""

MODEL_NAMES = MappingProxyType({"biped": "HRP-2", "g1": "the Unitree G1"})
"""Each model's robot in words, for messages, tables and plots."""

_G1_DEFAULTS = MappingProxyType(
    {k: robots.g1_defaults().get(k, robots.PAPER_REACH) for k in ROBOT_DEFAULTS}  # reach: its lattice's dx range
)


def _check(model: str) -> str:
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    return model


def robot_defaults(model: str) -> Mapping[str, float]:
    """Every sweepable robot parameter of ``model`` and its default (m, s, rad, cost units), in the order of
    :data:`~ijoy_jax.sweep.ROBOT_DEFAULTS` (which are the ``"biped"``'s, HRP-2's). The G1's ``reach`` is its
    lattice's fixed dx range, :data:`~ijoy_jax.robots.PAPER_REACH` (the scenario table's ``robot.reach``).

    Example:
      >>> robot_defaults("g1")["foot_length"], robot_defaults("biped")["foot_length"]
      (0.18, 0.242)
    """
    return ROBOT_DEFAULTS if _check(model) == "biped" else _G1_DEFAULTS


def robot_keys(model: str) -> tuple[str, ...]:
    """The robot parameters a sweep of ``model`` may set (``[robot]``, ``robot.<name>`` in ``[grid]`` and
    ``[random]``): every one of :data:`~ijoy_jax.sweep.ROBOT_DEFAULTS`, less :data:`HRP2_ONLY` for the G1."""
    return tuple(k for k in ROBOT_DEFAULTS if _check(model) == "biped" or k not in HRP2_ONLY)


def actions(model: str, density: float, reach: float | None = None) -> np.ndarray:
    """(M, 3) float64 host array of ``model``'s actions (dx, dy, dtheta in m, m, rad) at ``density`` (and, for
    HRP-2, ``reach`` m; None: the paper's): :func:`ijoy_jax.robots.hrp2_actions` or
    :func:`ijoy_jax.robots.g1_actions`.

    Raises:
      ValueError: a density out of range, or a reach other than the paper's for the G1.
    """
    if _check(model) == "g1":
        _g1_reach(reach)
        return robots.g1_actions(density)
    return robots.hrp2_actions(density, robots.PAPER_REACH if reach is None else reach)


def step_in_place(model: str) -> float:
    """m: ``model``'s feet apart when standing, its step in place's dy (:data:`ijoy_jax.robots.HRP2_P0`,
    :data:`ijoy_jax.robots.G1_P0`), at every footprint and density; the simulated robot stands so too."""
    return (robots.G1_P0 if _check(model) == "g1" else robots.HRP2_P0)[1]


def build_robot(model: str, *, density: float = 1.0, reach: float | None = None, **overrides) -> robots.Robot:
    """The selector's robot of ``model`` (:func:`ijoy_jax.robots.for_model`: ``robots.hrp2(density=..., reach=...,
    **overrides)`` or ``robots.g1(density=..., **overrides)``); the one place a sweep builds a robot.

    Args:
      model: one of :data:`~ijoy_jax.sweep.schema.MODELS`.
      density: action-set density (1.0 -> 496 actions for either).
      reach: HRP-2's largest forward/backward step (m; None: the paper's). The G1 takes only None or the
        paper's (its lattice's range).
      **overrides: any :func:`ijoy_jax.robots.make_robot` keyword (margin, w, foot_length, max_margin, ...).

    Raises:
      ValueError: an unknown model, a reach the G1 does not take, or what the robot's builder refuses.

    Example:
      >>> build_robot("g1", margin=0.05).actions.shape, round(float(build_robot("g1").foot_length), 2)
      ((496, 3), 0.18)
    """
    if _check(model) == "g1":
        _g1_reach(reach)
    else:
        overrides["reach"] = robots.PAPER_REACH if reach is None else reach
    return robots.for_model(model, density=density, **overrides)


def _g1_reach(reach) -> None:
    if reach is not None and reach != robots.PAPER_REACH:
        raise ValueError(f"reach={reach!r}: the G1's action set spans the paper's dx range, steps of at most "
                         f"{robots.PAPER_REACH} m (robots.g1 takes no reach; HRP-2's option, model = \"biped\")")
