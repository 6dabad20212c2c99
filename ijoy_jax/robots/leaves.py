"""The Robot's scalar leaves by dotted name: what each one is, and reading or replacing it.

:data:`~ijoy_jax.robots.SCALAR_LEAVES` is the registry of every scalar leaf a sweep, a tuner, the server or the
live loop may set (its unit, its lower bound, whether the selector's cost uses it);
:func:`~ijoy_jax.robots.get_leaf`, :func:`~ijoy_jax.robots.set_leaf` and :func:`~ijoy_jax.robots.set_leaves`
reach a leaf of a :class:`~ijoy_jax.robots.Robot` by its dotted path (``"w"``, ``"metrics.slope_limit"``).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, NamedTuple

from ijoy_jax.robots.robot import Robot


class LeafSpec(NamedTuple):
    """What a scalar Robot leaf means: its unit, its lower bound and whether the selector's cost uses it.

    Fields::

      unit: of the value (m, s, rad; cost/m: cost units per metre, m/rad: dist metres per radian).
      positive: True: must be > 0 (sizes, times); False: must be >= 0.
      selector: True for the parameters of the choice (FootCost + w dist), the ones
        ijoy_jax.tune may tune; False for the robot's body (footprint, step time, the
        ankles' tilt and the legs' reach limits).
    """

    unit: str
    positive: bool
    selector: bool


SCALAR_LEAVES: Mapping[str, LeafSpec] = MappingProxyType(
    {
        "w": LeafSpec("1", False, True),
        "rotation_weight": LeafSpec("m/rad", False, True),
        "margin": LeafSpec("m", False, True),
        "step_time": LeafSpec("s", True, False),
        "foot_length": LeafSpec("m", True, False),
        "foot_width": LeafSpec("m", True, False),
        "max_sole_pitch": LeafSpec("rad", False, False),
        "max_sole_roll": LeafSpec("rad", False, False),
        "max_sole_distance": LeafSpec("m", False, False),
        "metrics.slope_weight": LeafSpec("cost/rad", False, True),
        "metrics.slope_limit": LeafSpec("rad", False, True),
        "metrics.roughness_weight": LeafSpec("cost/m", False, True),
        "metrics.roughness_limit": LeafSpec("m", False, True),
        "metrics.bump_weight": LeafSpec("cost/m", False, True),
        "metrics.bump_limit": LeafSpec("m", False, True),
        "metrics.step_weight": LeafSpec("cost/m", False, True),
        "metrics.band_weight": LeafSpec("cost/m", False, True),
        "metrics.band_limit": LeafSpec("m", False, True),
        "metrics.support_weight": LeafSpec("cost/m", False, True),
        "metrics.support_limit": LeafSpec("m", False, True),
        "metrics.contact_inset": LeafSpec("m", False, True),
        "metrics.contact_tol": LeafSpec("m", False, True),
    }
)
"""Every scalar Robot leaf a user may sweep or tune, by dotted name (:func:`get_leaf`), in a fixed order."""

SELECTOR_LEAVES = tuple(n for n, spec in SCALAR_LEAVES.items() if spec.selector)
"""The names of :data:`SCALAR_LEAVES` that parameterise the choice (w, rotation_weight, margin, metrics.*)."""


def get_leaf(robot: Robot, name: str):
    """The leaf of ``robot`` named by a dotted path, e.g. ``"w"`` or ``"metrics.slope_limit"``."""
    obj = robot
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def set_leaf(robot: Robot, name: str, value) -> Robot:
    """A copy of ``robot`` with the leaf at a dotted path (see :func:`get_leaf`) replaced by ``value``."""
    head, _, tail = name.partition(".")
    if tail:
        return robot.replace(**{head: set_leaf(getattr(robot, head), tail, value)})
    return robot.replace(**{name: value})


def set_leaves(robot: Robot, values: Mapping[str, Any]) -> Robot:
    """A copy of ``robot`` with every dotted name of ``values`` set (:func:`set_leaf` for each; traceable).

    Example:
      >>> from ijoy_jax import robots
      >>> r = robots.set_leaves(robots.hrp2(), {"w": 2.0, "metrics.bump_limit": 0.03})
      >>> float(r.w), round(float(r.metrics.bump_limit), 6)  # float32 leaves
      (2.0, 0.03)
    """
    for name, value in values.items():
        robot = set_leaf(robot, name, value)
    return robot
