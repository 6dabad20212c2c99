"""The Unitree G1 (MuJoCo Menagerie) as a selector robot: its footprint, step in place, action lattice and limits.

Every number is derived from the G1's own MJCF (``unitree_g1``; :mod:`ijoy_jax.sim.menagerie`) read by
:func:`ijoy_jax.sim.description.describe`, in the double-support posture of its ``knees_bent`` keyframe (pelvis
0.758 m above the soles, feet 0.237 m apart); ``tests/test_robots_g1.py`` derives them again with
:mod:`ijoy_jax.sim.reach` and holds these constants to the derivation, so the core needs no MuJoCo to build the
robot:

* footprint: the foot box geoms, 0.18 m x 0.06 m;
* step in place: the keyframe's feet 0.237 m apart, on the action lattice's 2 cm grid: (0, 0.24 m, 0);
* actions: dx in [-0.20, 0.20] m (9 values), dy in [0.24, 0.38] m (8 values), dtheta in [-20, 20] deg (7 values),
  less the 8 corners: 496, HRP-2's lattice shifted to the G1's wider stance; every one is realisable by both legs
  with every joint 0.02 rad inside its range (:func:`ijoy_jax.sim.reach.feasible`);
* sole tilts (FootCost's ``ankle`` term): the largest pitch and roll of the swing sole realisable in every stance
  of the set, rounded down: 10 deg and 4.4 deg. The G1's ankle rolls only +-15 deg and a stance wider than its
  hips uses most of that to lean the legs outward, so its roll limit is far below HRP-2's 10 deg;
* sole distance (FootCost's ``reach`` term): 0.48 m, the shortest distance the legs reach along the directions
  the action set spans (50 to 130 deg from the stance foot's heading), level soles;

The step time is the MJX G1's (:data:`G1_STEP_TIME`, 0.5 s; ``ijoy_jax.sim.walker.make_sim(..., model="g1")``
walks with it); the swing clearance and highest step are the walking controller's, as for HRP-2 (BENCHMARKS.md,
"The Unitree G1 in MJX", says how well it walks).
"""

from __future__ import annotations

import inspect
import math

import numpy as np

from ijoy_jax.robots.build import make_robot
from ijoy_jax.robots.hrp2_model import PAPER_REACH, check_density, density_counts, hrp2_defaults
from ijoy_jax.robots.lattice import lattice_actions
from ijoy_jax.robots.robot import Robot

G1_P0 = (0.0, 0.24, 0.0)
"""The G1's step in place (m, m, rad): the swing foot beside the stance foot, its standing width."""

G1_FOOT = (0.18, 0.06)
"""m: the G1's sole, (length, width): its foot box geoms."""

G1_DY = (0.24, 0.38)
"""m: the G1's lateral range of the swing foot from the stance foot (the step in place and 14 cm wider)."""

G1_STEP_TIME = 0.5
"""s: the G1's step time, shorter than HRP-2's 0.8 s. Its soles are 6 cm wide, so its ankles can move the centre
of pressure by only about 2 cm, and a lateral error of the body grows e^(omega t)-fold (omega 3.9/s) through each
single support: 17-fold in the 0.72 s of a 0.8 s step, 6-fold in 0.45 s. At 0.8 s the MJX G1 fell within 5-10
steps of 0.2 m on flat ground (CPU, 2 robots, with or without its other settings, ``sim.g1.WALK``). At 0.5 s the
same 2 robots walked 30 such steps, but of 1024 on the GPU 82 % fell: the full stick is still marginal; held at
0.25 m/s (0.1-0.15 m steps) 0.49 % fell (BENCHMARKS.md, "The Unitree G1 in MJX", has the batch figures)."""

G1_LIMITS = {"max_sole_pitch": math.radians(10.0), "max_sole_roll": math.radians(4.4), "max_sole_distance": 0.48}
"""The sole tilts (rad) and sole distance (m) the G1's legs realise in every stance of its action set."""

_G1_BODY = {"foot_length": G1_FOOT[0], "foot_width": G1_FOOT[1], "step_time": G1_STEP_TIME, "p0": G1_P0, **G1_LIMITS}


def g1_actions(density: float = 1.0) -> np.ndarray:
    """(M, 3) float64 host array of :func:`g1`'s actions (dx, dy, dtheta in m, m, rad) at ``density``.

    Example:
      >>> g1_actions().shape
      (496, 3)

    Raises:
      ValueError: a density outside ``[MIN_DENSITY, ijoy_jax.limits.MAX_DENSITY]``
        (:func:`~ijoy_jax.robots.check_density`), before the lattice is built.
    """
    check_density(density)
    return lattice_actions(density_counts(density, PAPER_REACH), dx_range=(-PAPER_REACH, PAPER_REACH),
                           dy_range=G1_DY)


def g1(margin: float = 0.02, density: float = 1.0, **overrides) -> Robot:
    """The Unitree G1: footprint 18 x 6 cm, 496 actions per foot (see the module docstring for where each
    number comes from).

    Args:
      margin: safety margin (m).
      density: action-set density (1.0 -> 496 actions; :func:`~ijoy_jax.robots.density_counts`), in
        ``[MIN_DENSITY, ijoy_jax.limits.MAX_DENSITY]``.
      **overrides: any other :func:`~ijoy_jax.robots.make_robot` keyword (w, rotation_weight, step_time,
        clearance, max_step_height, metrics, ...).

    Example:
      >>> import ijoy_jax as ij
      >>> robot = ij.robots.g1(margin=0.02)
      >>> robot.actions.shape, round(float(robot.foot_length), 2)
      ((496, 3), 0.18)
    """
    return make_robot(g1_actions(density), **{**_G1_BODY, "margin": margin, **overrides})


def g1_defaults() -> dict[str, float]:
    """name -> value of every :data:`~ijoy_jax.robots.SCALAR_LEAVES` leaf of ``g1()``, and its ``density``, without
    building it (host floats: checks of sweep files run before any backend starts).

    HRP-2's :func:`~ijoy_jax.robots.hrp2_defaults` (the same selector weights and metrics, from
    :func:`~ijoy_jax.robots.make_robot`'s and :func:`~ijoy_jax.robots.default_metrics`' keyword defaults) with the
    G1's body: its footprint, step time and sole limits (the module docstring). No ``reach``: the G1's lattice
    spans the paper's dx range, :data:`~ijoy_jax.robots.PAPER_REACH`, always.

    Example:
      >>> from ijoy_jax import robots
      >>> d = robots.g1_defaults()
      >>> d["foot_length"], d["max_sole_distance"], "reach" in d
      (0.18, 0.48, False)
    """
    params = inspect.signature(g1).parameters
    own = {**{k: v for k, v in _G1_BODY.items() if k != "p0"}, "margin": params["margin"].default,
           "density": params["density"].default}
    return {k: float(own.get(k, v)) for k, v in hrp2_defaults().items() if k != "reach"}
