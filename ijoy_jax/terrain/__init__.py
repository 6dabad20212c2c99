"""The environment e of the paper, and the terrains it is made of.

:mod:`~ijoy_jax.terrain.grid` holds the :class:`Terrain` pytree (a 2D occupancy grid or a 2.5D height map)
and its constructors; :mod:`~ijoy_jax.terrain.scene` rasterises posed boxes and cylinders into a map;
:mod:`~ijoy_jax.terrain.generators` makes thousands of procedural terrains of named families in one jitted
call. Each family's registry record (:mod:`~ijoy_jax.terrain.family`) carries its generator, parameters,
validation and extra metrics; the families live in :mod:`~ijoy_jax.terrain.objects` (walls, obstacles, bars,
platforms), :mod:`~ijoy_jax.terrain.surfaces` (flat, stairs, stepping stones, slope, rough) and
:mod:`~ijoy_jax.terrain.passages` (a corridor with pockets, a path of staggered stones).
:mod:`~ijoy_jax.terrain.walk_families` draws the walking benchmark's batches of maps from those generators.
"""

from ijoy_jax.terrain import generators as generators
from ijoy_jax.terrain import grid as grid
from ijoy_jax.terrain import scene as scene
from ijoy_jax.terrain.grid import Terrain as Terrain
from ijoy_jax.terrain.grid import check_terrain as check_terrain
from ijoy_jax.terrain.grid import flat as flat
from ijoy_jax.terrain.grid import from_arrays as from_arrays
from ijoy_jax.terrain.grid import from_image as from_image
from ijoy_jax.terrain.grid import grid_spec as grid_spec
from ijoy_jax.terrain.grid import terrain_supported as terrain_supported

__all__ = ["Terrain", "check_terrain", "flat", "from_arrays", "from_image", "generators", "grid", "grid_spec", "scene",
           "terrain_supported"]
