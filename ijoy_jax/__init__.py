"""ijoy_jax: the intelligent joystick for legged robots, as batched, jit-able JAX.

Conventions: world poses are ``(x, y, theta)`` in metres and radians; terrain
arrays are indexed ``[ix, iy]`` (first axis along world x); sides are +1 for
the left foot and -1 for the right.

Public API:
  Terrain, terrain.from_arrays / from_image / flat   the environment e
  terrain.scene.rasterize                            posed boxes/cylinders -> map
  terrain.generators.FAMILIES / generate / batch     procedural terrains (jit/vmap)
  robots.hrp2 / make_robot / lattice_actions         footprint and action set S
  foot_cost, foot_cost_terms                         FootCost of candidate steps
  action_steps                                       world poses of every action
  select_step, StepChoice, make_targets              the next foothold for a command
  SelectOptions                                      how it is searched for (method, kernel, lookahead, refinement)
  lookahead, refine                                  beyond the paper: H-step lookahead, continuous refinement
  rollout, Trajectory, perfect_walker, Walker        the control loop (Algorithm 1)
  turning                                            a turning mode that does not overshoot on release
  haptics                                            the ALDURO force-feedback joystick
  cue                                                both joined: a force on the stick where the biped cannot go
  tune                                               tuning by gradient (relaxed selector, optax tuners)
"""

# _xla_workaround comes first (and sorts first): importing it sets XLA_FLAGS before any module below starts
# JAX's backends, which read them once.
from ijoy_jax import (
    _xla_workaround,  # noqa: F401
    control,
    cue,
    footcost,
    geometry,
    haptics,
    lookahead,
    plot,
    refine,
    robots,
    select,
    terrain,
    tune,
    turning,
)
from ijoy_jax._version import __version__ as __version__
from ijoy_jax.control import Trajectory, Walker, perfect_walker, rollout
from ijoy_jax.footcost import FootCostTerms, foot_cost, foot_cost_terms
from ijoy_jax.robots import LEFT, RIGHT, Robot, TerrainMetrics, action_steps
from ijoy_jax.select import StepChoice, make_targets, select_step
from ijoy_jax.select_options import SelectOptions
from ijoy_jax.terrain import Terrain

__all__ = [
    "LEFT",
    "RIGHT",
    "FootCostTerms",
    "Robot",
    "SelectOptions",
    "StepChoice",
    "Terrain",
    "TerrainMetrics",
    "Trajectory",
    "Walker",
    "action_steps",
    "control",
    "cue",
    "foot_cost",
    "foot_cost_terms",
    "footcost",
    "geometry",
    "haptics",
    "lookahead",
    "make_targets",
    "perfect_walker",
    "plot",
    "refine",
    "robots",
    "rollout",
    "select",
    "select_step",
    "terrain",
    "tune",
    "turning",
]
