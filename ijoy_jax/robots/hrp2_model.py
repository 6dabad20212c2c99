"""The paper's HRP-2: its body, its action lattice at a density and a reach, and its leaves' default values.

:func:`~ijoy_jax.robots.hrp2` builds it with :func:`~ijoy_jax.robots.make_robot` from HRP-2's footprint, step
time, step in place and lateral range held here, the action lattice's density
(:func:`~ijoy_jax.robots.density_counts`) and its reach (the paper's, or a longer one for stairs); the ankle and
reach limits are :func:`~ijoy_jax.robots.make_robot`'s defaults, derived for HRP-2 there. The host constants and
host arrays (:data:`~ijoy_jax.robots.HRP2_P0`, :func:`~ijoy_jax.robots.hrp2_actions`,
:func:`~ijoy_jax.robots.hrp2_defaults`) let checks of sweep files run without a device.
"""

from __future__ import annotations

import inspect
import math

import numpy as np

from ijoy_jax.limits import MAX_ACTIONS, MAX_DENSITY
from ijoy_jax.robots.build import default_metrics, make_robot
from ijoy_jax.robots.lattice import lattice_actions
from ijoy_jax.robots.leaves import SCALAR_LEAVES
from ijoy_jax.robots.robot import Robot

DX_SPACING = 0.05
"""m: spacing of HRP-2's dx lattice at density 1 (the paper's 9 values over [-0.2, 0.2] m)."""

PAPER_REACH = 0.20
"""m: the paper's largest forward/backward step of HRP-2 (:func:`hrp2`'s default ``reach``)."""

MIN_DENSITY = 0.1
"""Smallest action-set density (:func:`hrp2`'s and :func:`~ijoy_jax.robots.g1`'s ``density``): 10 actions, the
smallest lattice (3 x 2 x 3 less its 8 corners), which every smaller density gave too, silently (``1e-300``), at
any reach below 0.75 m. The range is ``[MIN_DENSITY, ijoy_jax.limits.MAX_DENSITY]``."""

STAIR_STEP_HEIGHT = 0.15
"""m: HRP-2's ``max_step_height`` with a reach beyond the paper's (:func:`hrp2`): stair risers up to 15 cm."""


def density_counts(density: float, reach: float = PAPER_REACH) -> tuple[int, int, int]:
    """Lattice counts for an action-set density; density 1 gives HRP-2's (9, 8, 7) -> 496 actions.

    dx and dtheta counts stay odd so that straight steps (dx = 0, dtheta = 0)
    stay in the set. Sizes: density 0.1 -> 10, 0.25 -> 19, 0.5 -> 117,
    1 -> 496, 2 -> 3307, 3 -> 10442 actions. ``reach`` (m) is the dx range's
    half width: at density 1 the dx values stay :data:`DX_SPACING` apart,
    ``1 + 2 round(reach / 0.05)`` of them (reach 0.30 -> 13: (13, 8, 7) -> 720 actions).
    """
    if not _positive_finite(density):
        raise ValueError(f"density must be a positive finite number, got {density!r}")
    _check_reach(reach)
    half = max(1, round(reach / DX_SPACING))  # dx values either side of 0 at density 1 (4 for the paper's 0.2 m)
    n_dx = 1 + 2 * max(1, round(half * density))
    n_dy = 1 + max(1, round(7 * density))
    n_dt = 1 + 2 * max(1, round(3 * density))
    return n_dx, n_dy, n_dt


def check_density(density) -> float:
    """``density`` as a float, or ValueError naming it and its range ``[MIN_DENSITY, ijoy_jax.limits.MAX_DENSITY]``
    (below it every density gives the same 10 actions; above it the targets table outgrows the memory budget).
    Checked before a lattice is built."""
    if not _positive_finite(density):
        raise ValueError(f"density must be a positive finite number, got {density!r}")
    if density < MIN_DENSITY:
        raise ValueError(
            f"density must be in [ijoy_jax.robots.MIN_DENSITY, ijoy_jax.limits.MAX_DENSITY] = [{MIN_DENSITY}, "
            f"{MAX_DENSITY}] ({MIN_DENSITY} gives the smallest action set, 10 actions, as every smaller density "
            f"would), got {density!r}"
        )
    if density > MAX_DENSITY:
        raise ValueError(
            f"density must be <= ijoy_jax.limits.MAX_DENSITY = {MAX_DENSITY} ({MAX_ACTIONS} actions; "
            f"the targets table grows as its sixth power), got {density!r}"
        )
    return float(density)


def _positive_finite(x) -> bool:
    """Whether ``x`` is a number > 0 that a float holds (a Python int beyond float64, 10**400, is not one)."""
    try:
        v = float(x)
    except (TypeError, ValueError, OverflowError):
        return False
    return math.isfinite(v) and v > 0


def _check_reach(reach) -> None:
    if isinstance(reach, bool) or not isinstance(reach, (int, float, np.integer, np.floating)):
        raise ValueError(f"reach must be a number (the largest forward/backward step, m), got {reach!r}")
    if not _positive_finite(reach):
        raise ValueError(
            f"reach must be a positive finite number (the largest forward/backward step, m), got {reach!r}"
        )


HRP2_P0 = (0.0, 0.19, 0.0)
"""HRP-2's step in place (m, m, rad): the swing foot beside the stance foot. A host constant, so checks of
sweep files need no device (nothing may start a JAX backend before ``jax.distributed.initialize``)."""
_HRP2_BODY = {"foot_length": 0.242, "foot_width": 0.13, "step_time": 0.8, "p0": HRP2_P0}
_HRP2_DY = (0.19, 0.33)  # m: HRP-2's lateral range of the swing foot from the stance foot


def hrp2(margin: float = 0.02, density: float = 1.0, *, reach: float = PAPER_REACH, **overrides) -> Robot:
    """The paper's HRP-2: footprint 24.2 x 13 cm, 496 actions per foot.

    Actions: dx in [-20, 20] cm (9 values, 5 cm apart), dy in [19, 33] cm from
    the stance foot (8 values, 2 cm apart), dtheta in [-20, 20] deg (7 values),
    less the 8 corners of that box: 9 x 8 x 7 - 8 = 496. ``density`` scales the
    lattice (:func:`density_counts`) over the same ranges, for action-set size
    sweeps. Step time 0.8 s; step in place p0 = (0, 0.19 m, 0). Safety margin:
    the paper used 2 cm (motion capture), 5 cm (vision) and 10 cm (real robot).

    Stairs. With the paper's reach (steps at most 0.20 m ahead of the stance
    foot) the stance foot's toe is always ahead of the swing foot's heel
    (0.20 - 0.242 / 2 = 0.079 m < 0.242 / 2 + margin), so a riser across both
    lanes can only be crossed by a foot straddling it. The roughness, bump and
    slope terms make that costlier than marking time (at w = 1) from a riser
    of 1.3 to 2 cm, depending on where it falls under the foot, and their
    limits refuse it by 5 cm: the robot marks time before it (the paper's
    geometry: it stepped onto obstacles in one lane). A foot clears a riser
    between the feet only if it lands at least ``foot_length + 2 margin``
    (0.282 m at 2 cm) ahead of the stance foot: ``reach=0.30`` gives dx in
    [-30, 30] cm (13 values, 5 cm apart; 13 x 8 x 7 - 8 = 720 actions) and,
    unless overridden, ``max_step_height`` :data:`STAIR_STEP_HEIGHT` (15 cm
    risers). ``clearance`` stays 0.10 m: the swing corridor is measured from
    the higher foothold, and a stair's nosing between the two footholds is
    never above it. A tread holds a foot with its margin if it is at least
    0.282 m deep; with 5 cm steps the feet's x stay on one 5 cm lattice, and
    the 1.8 cm of slack (0.30 - 0.282) is enough when the risers keep the
    lattice's phase: treads a multiple of 5 cm (0.30 m: a tread per step;
    0.40 m: two steps per tread).

    Args:
      margin: safety margin (m).
      density: action-set density (1.0 -> 496 actions), in ``[MIN_DENSITY, ijoy_jax.limits.MAX_DENSITY]``.
      reach: largest forward/backward step dx (m, > 0; default the paper's
        0.20). The farthest action must stay within ``max_sole_distance``.
      **overrides: any other :func:`make_robot` keyword (w, rotation_weight,
        step_time, action_cost, clearance, max_step_height, metrics, ...).

    Raises:
      ValueError: a reach that is not a positive finite number, or one that
        puts actions beyond ``max_sole_distance``.

    Example:
      >>> import ijoy_jax as ij
      >>> robot = ij.robots.hrp2(margin=0.05)
      >>> robot.actions.shape
      (496, 3)
      >>> stairs = ij.robots.hrp2(reach=0.30)
      >>> stairs.actions.shape, round(float(stairs.max_step_height[0]), 2)
      ((720, 3), 0.15)
    """
    _check_reach(reach)
    kwargs = dict(_HRP2_BODY, margin=margin)
    if reach > PAPER_REACH:
        kwargs["max_step_height"] = STAIR_STEP_HEIGHT
    kwargs.update(overrides)
    try:
        limit = float(kwargs.get("max_sole_distance", _signature_defaults(make_robot)["max_sole_distance"]))
    except (TypeError, ValueError):  # not a number (or traced): make_robot's check names it
        limit = math.nan
    farthest = math.hypot(reach, _HRP2_DY[1])
    if 0 <= limit < farthest:  # NaN, inf or < 0: make_robot's check names it
        raise ValueError(
            f"reach={reach!r} m puts the farthest action ({reach}, {_HRP2_DY[1]}) {farthest:.3f} m from "
            f"the stance foot, beyond max_sole_distance = {float(limit)} m: its steps would always be "
            "refused"
        )
    return make_robot(hrp2_actions(density, reach), **kwargs)


def hrp2_actions(density: float = 1.0, reach: float = PAPER_REACH) -> np.ndarray:
    """(M, 3) float64 host array of :func:`hrp2`'s actions (dx, dy, dtheta in m, m, rad) at ``density`` and
    ``reach``, without building a robot (no device array: checks of sweep files run before any backend starts).

    Example:
      >>> hrp2_actions().shape, hrp2_actions(2.0).shape
      ((496, 3), (3307, 3))

    Raises:
      ValueError: a density outside ``[MIN_DENSITY, ijoy_jax.limits.MAX_DENSITY]`` (:func:`check_density`),
        before the lattice is built (a robot of more than :data:`ijoy_jax.limits.MAX_ACTIONS` actions, at a
        longer reach, is refused by :func:`make_robot`).
    """
    check_density(density)
    counts = density_counts(density, reach)
    return lattice_actions(counts, dx_range=(-reach, reach), dy_range=_HRP2_DY)


def _signature_defaults(fn) -> dict:
    params = inspect.signature(fn).parameters.values()
    return {p.name: p.default for p in params if p.default is not inspect.Parameter.empty}


def hrp2_defaults() -> dict[str, float]:
    """name -> value of every :data:`SCALAR_LEAVES` leaf of ``hrp2()``, and its ``density`` and ``reach``, without
    building it.

    Read from the one source of each number: :func:`hrp2`'s arguments and body,
    :func:`make_robot`'s and :func:`default_metrics`' keyword defaults. The
    robot at the paper's reach (``density`` and ``reach`` shape the action set,
    and ``reach`` sets ``max_step_height``, a per-action leaf: none is a scalar
    leaf).

    Example:
      >>> from ijoy_jax import robots
      >>> d = robots.hrp2_defaults()
      >>> d["foot_length"], d["margin"], d["density"], float(robots.get_leaf(robots.hrp2(), "w")) == d["w"]
      (0.242, 0.02, 1.0, True)
    """
    top = {**_signature_defaults(make_robot), **_HRP2_BODY, **_signature_defaults(hrp2)}
    metrics = _signature_defaults(default_metrics)
    out = {n: float(metrics[n.partition(".")[2]] if n.startswith("metrics.") else top[n]) for n in SCALAR_LEAVES}
    out["density"] = float(top["density"])
    out["reach"] = float(top["reach"])
    return out
