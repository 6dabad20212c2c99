"""ijoy_jax: the intelligent joystick for legged robots, as batched JAX."""
from ijoy_jax import geometry, scene, terrain
from ijoy_jax.terrain import Terrain

__version__ = "0.1.0"
