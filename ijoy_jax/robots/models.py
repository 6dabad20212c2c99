"""The selector's robot for each robot the walker simulates, by the walker's name for it.

The walker (:mod:`ijoy_jax.sim`) names its robots ``"biped"`` (the project's HRP-2-like biped) and ``"g1"`` (the
Unitree G1 of MuJoCo Menagerie) (``ijoy_jax.sim.bodies.MODELS``); the selector steps each with its own footprint,
step in place and action set: :func:`~ijoy_jax.robots.hrp2` and :func:`~ijoy_jax.robots.g1`. A drive or a
rendered walk that picks a robot by name builds both halves from the one name.
"""

from __future__ import annotations

from ijoy_jax.robots.g1_model import g1
from ijoy_jax.robots.hrp2_model import hrp2
from ijoy_jax.robots.robot import Robot

MODELS = ("biped", "g1")
"""The walker's robots by name (``ijoy_jax.sim.bodies.MODELS``, which needs MuJoCo; this one does not)."""

_FACTORIES = {"biped": hrp2, "g1": g1}


def for_model(model: str, margin: float = 0.02, density: float = 1.0, **overrides) -> Robot:
    """The selector's robot for the walker's robot ``model`` (:data:`MODELS`): HRP-2's for ``"biped"``, the
    G1's for ``"g1"``.

    Args:
      model: one of :data:`MODELS`.
      margin: safety margin (m).
      density: action-set density (1.0 -> 496 actions per foot for either robot).
      **overrides: the robot's other options (:func:`~ijoy_jax.robots.hrp2`'s, e.g. ``reach``, or
        :func:`~ijoy_jax.robots.g1`'s: any :func:`~ijoy_jax.robots.make_robot` keyword).

    Raises:
      ValueError: ``model`` is not one of :data:`MODELS` (naming them).

    Example:
      >>> import ijoy_jax as ij
      >>> round(float(ij.robots.for_model("g1").foot_length), 2)
      0.18
    """
    if model not in _FACTORIES:
        raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    return _FACTORIES[model](margin=margin, density=density, **overrides)
