"""A described robot on the terrain's height field: the contact model and the sensors the walking stack reads.

:func:`terrain_scene` takes any biped's ``mujoco.MjSpec`` (e.g. the Unitree G1's,
:func:`ijoy_jax.sim.menagerie.g1_spec`) and gives it the world of the project's own biped
(:func:`ijoy_jax.sim.model.build_spec`): the terrain height field in place of its floor (floor planes, and the
contact pairs and contact sensors that name them, are removed), the soles as a grid of small spheres on the bottom
face of each foot box (MJX collides a sphere with a height field over a 2 x 2 cell patch, a box over a patch as
large as the box; the boxes themselves stop colliding), and the frames and sensors the controller reads under the
names :func:`ijoy_jax.sim.model.model_index` knows: ``left_sole``/``right_sole`` (the sole centres),
``left_ankle``/``right_ankle`` (each foot body's origin) with force and torque sensors there, ``imu`` (the root's
origin) and the whole robot's centre of mass and its velocity (``com``, ``com_vel``).
"""

from __future__ import annotations

import mujoco
import numpy as np

from ijoy_jax.sim import hfield, model
from ijoy_jax.sim.description import quat_matrix

__all__ = ["terrain_scene"]

SIDES = ("left", "right")


def _drop_floors(spec: mujoco.MjSpec) -> None:
    """Remove the world's plane geoms and every contact pair, exclude and sensor that names one."""
    floors = {g.name for g in spec.worldbody.geoms if g.type == mujoco.mjtGeom.mjGEOM_PLANE}
    for pair in [p for p in spec.pairs if {p.geomname1, p.geomname2} & floors]:
        spec.delete(pair)
    for sensor in [s for s in spec.sensors if {s.objname, s.refname} & floors]:
        spec.delete(sensor)
    for geom in [g for g in spec.worldbody.geoms if g.name in floors]:
        spec.delete(geom)


def terrain_scene(robot: mujoco.MjSpec, *, soles: tuple[str, str] = ("left_foot", "right_foot"),
                  root: str = "pelvis", params: model.BipedParams | None = None, shape=(200, 200),
                  resolution: float = 0.02, origin=(0.0, 0.0)) -> mujoco.MjSpec:
    """``robot`` on a terrain height field, with sole spheres and the walking stack's sensors (edited in place).

    Args:
      robot: the robot's spec (its floor, if any, is removed).
      soles: the (left, right) foot box geoms; each bottom face gets ``params.sole_grid`` spheres of
        ``params.sole_radius``, their bottoms on the face, with ``params.friction``.
      root: the robot's root body (its free joint's): the ``imu`` site and the centre-of-mass sensors.
      params: the terrain's elevation range and base, and the sole contact model (default ``BipedParams()``).
      shape, resolution, origin: the terrain grid, as :func:`ijoy_jax.sim.model.build_spec`.

    Returns:
      ``robot``, for chaining.

    Raises:
      ValueError: a sole that is not a box geom, or names the spec lacks.
    """
    params = model.BipedParams() if params is None else params
    _drop_floors(robot)
    hfield.add_terrain(robot, params, shape, resolution, origin)
    r = params.sole_radius
    nx, ny = params.sole_grid
    for side, name in zip(SIDES, soles, strict=True):
        box = robot.geom(name)
        if box is None or box.type != mujoco.mjtGeom.mjGEOM_BOX:
            raise ValueError(f"sole geom {name!r} must be a box geom of the robot")
        body = box.parent
        half = np.asarray(box.size[:3], np.float64)
        rot, centre = quat_matrix(box.quat), np.asarray(box.pos, np.float64)
        xs = np.linspace(half[0] - r, -(half[0] - r), nx) if nx > 1 else np.zeros(1)
        ys = np.linspace(half[1] - r, -(half[1] - r), ny) if ny > 1 else np.zeros(1)
        for k, (x, y) in enumerate((x, y) for x in xs for y in ys):
            body.add_geom(name=f"{side}_sole{k}", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0],
                          pos=list(centre + rot @ np.array([x, y, -half[2] + r])), contype=1, conaffinity=0,
                          condim=3, friction=[params.friction, 0.005, 0.0001], mass=0.0, rgba=[0.9, 0.3, 0.3, 1])
        box.contype, box.conaffinity = 0, 0
        body.add_site(name=f"{side}_sole", pos=list(centre + rot @ np.array([0.0, 0.0, -half[2]])),
                      quat=list(box.quat))
        body.add_site(name=f"{side}_ankle", pos=[0.0, 0.0, 0.0])
        for kind in ("force", "torque"):
            robot.add_sensor(name=f"{side}_ankle_{kind}", type=getattr(mujoco.mjtSensor, f"mjSENS_{kind.upper()}"),
                             objtype=mujoco.mjtObj.mjOBJ_SITE, objname=f"{side}_ankle")
    robot.body(root).add_site(name="imu", pos=[0.0, 0.0, 0.0])
    for name, kind in (("com", "SUBTREECOM"), ("com_vel", "SUBTREELINVEL")):
        robot.add_sensor(name=name, type=getattr(mujoco.mjtSensor, f"mjSENS_{kind}"),
                         objtype=mujoco.mjtObj.mjOBJ_BODY, objname=root)
    return robot
