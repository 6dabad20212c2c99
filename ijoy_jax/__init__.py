"""ijoy_jax: the intelligent joystick for legged robots, as batched, jit-able JAX.

Conventions: world poses are ``(x, y, theta)`` in metres and radians; terrain
arrays are indexed ``[ix, iy]`` (first axis along world x); sides are +1 for
the left foot and -1 for the right.

Public API:
  Terrain, terrain.from_arrays / from_image / flat   the environment e
  scene.rasterize                                    posed boxes/cylinders -> map
  robots.hrp2 / make_robot / lattice_actions         footprint and action set S
  foot_cost, foot_cost_terms                         FootCost of candidate steps
  action_steps                                       world poses of every action
"""

from ijoy_jax import footcost, geometry, robots, scene, terrain
from ijoy_jax.footcost import FootCostTerms, foot_cost, foot_cost_terms
from ijoy_jax.robots import LEFT, RIGHT, Robot, TerrainMetrics
from ijoy_jax.steps import action_steps
from ijoy_jax.terrain import Terrain

__version__ = "0.1.0"

__all__ = [
    "LEFT",
    "RIGHT",
    "FootCostTerms",
    "Robot",
    "Terrain",
    "TerrainMetrics",
    "action_steps",
    "foot_cost",
    "foot_cost_terms",
    "footcost",
    "geometry",
    "robots",
    "scene",
    "terrain",
]
