"""The robots a live drive steps in real time: the paper's perfect walker, tick by tick, on the host.

A live robot (a *body*) has the host protocol of :class:`ijoy_jax.sim.native.NativeBiped` (and of
:class:`ijoy_jax.sim.mjx_biped.MjxBiped`, the same biped on MJX):
``stance()``, ``future_stance()`` (Algorithm 1's ComputeStanceLocation while a step executes),
``begin(foothold, go)``, ``tick() -> bool`` (one control period of ``control_dt`` s; False at the
step's end), ``end()``, ``feet()``, ``ticks_per_step`` and ``control_dt``. :class:`PerfectBody` is
:func:`ijoy_jax.control.perfect_walker` with that protocol: each step lands exactly where it was
sent, ``step_time`` after it began (the same float32 feet as the scanned rollout's).

:class:`BodyGeoms` reads any of these bodies' geoms for the live view's 3D scene: every visible geom of a
MuJoCo robot at its world pose (the G1's visual meshes too), or the perfect body's two soles.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from ijoy_jax import control
from ijoy_jax.robots import LEFT, Robot
from ijoy_jax.stick import DEFAULT_CONTROL_DT
from ijoy_jax.terrain import Terrain

__all__ = ["GEOM_TYPES", "HIDDEN_GROUP", "MIN_CONTROL_DT", "SOLE_THICKNESS", "BodyGeoms", "PerfectBody"]

MIN_CONTROL_DT = 1e-4
"""Shortest control period (s) of the perfect body: a shorter one ticks without end in real time."""

_PLANAR = np.array([0, 1, 5])


class PerfectBody:
    """The paper's simulated robot on the host: every commanded step lands exactly, ``robot.step_time`` s later.

    Args:
      robot: the robot (its step time).
      start: (2, 3) feet (x, y, yaw), row 0 left.
      first_swing: +1 if the left foot swings first.
      control_dt: s per tick (``robot.step_time`` must be a whole number of ticks).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax.live import PerfectBody
      >>> body = PerfectBody(ij.robots.hrp2(), ij.robots.start_stance(ij.robots.hrp2(), 0.5, 1.0))
      >>> body.begin(np.array([0.7, 1.095, 0, 0, 0, 0], np.float32), True)
      >>> while body.tick(): pass
      >>> body.end(); body.feet()[0].tolist()
      [0.699999988079071, 1.0950000286102295, 0.0]
    """

    def __init__(self, robot: Robot, start, first_swing=LEFT, control_dt: float = DEFAULT_CONTROL_DT):
        step_time = float(robot.step_time)
        number = isinstance(control_dt, numbers.Real) and not isinstance(control_dt, bool)
        if not (number and math.isfinite(control_dt) and control_dt >= MIN_CONTROL_DT):
            raise ValueError(f"control_dt must be a finite number of seconds >= {MIN_CONTROL_DT:g} (at most "
                             f"{1 / MIN_CONTROL_DT:g} ticks per second), got {control_dt!r}")
        ticks = step_time / control_dt
        if abs(ticks - round(ticks)) > 1e-4:  # float32 step times: 0.8 is 0.80000001
            raise ValueError(f"step_time {step_time} s must be a whole number of control_dt {control_dt} s ticks")
        start = np.array(start, np.float32)
        if start.shape != (2, 3) or not np.all(np.isfinite(start)):
            raise ValueError(f"start must be finite (2, 3) feet (left, right), got shape {start.shape}")
        if float(first_swing) not in (1.0, -1.0):
            raise ValueError(f"first_swing must be +1 (left) or -1 (right), got {first_swing!r}")
        self.control_dt, self.ticks_per_step = float(control_dt), int(round(ticks))
        self._feet = start
        self.swing = np.float32(first_swing)
        self.fallen = False
        self.time = 0.0
        self._step = None

    def feet(self) -> np.ndarray:
        """(2, 3) float32 feet (x, y, yaw), row 0 left (where they stand; a swinging foot counts where it left)."""
        return self._feet.copy()

    def stance(self) -> control.StanceInfo:
        left_swings = self.swing > 0
        st, sw = (self._feet[1], self._feet[0]) if left_swings else (self._feet[0], self._feet[1])
        return control.StanceInfo(st.copy(), np.float32(-self.swing), sw.copy())

    def future_stance(self) -> control.StanceInfo:
        """The next decision's stance: the swinging foot where it was sent (or :meth:`stance` when standing)."""
        st = self.stance()
        if self._step is None or not self._step[1]:
            return st
        return control.StanceInfo(self._step[0].copy(), np.float32(-st.stance_side), st.stance)

    @property
    def stepping(self) -> bool:
        return self._step is not None

    def progress(self) -> float:
        """Fraction of the step in progress (0 when standing)."""
        return 0.0 if self._step is None else self._step[2] / self.ticks_per_step

    def begin(self, foothold, go: bool) -> None:
        if self._step is not None:
            raise RuntimeError("a step is in progress: tick() it to its end and call end() first")
        foothold = np.asarray(foothold, np.float32)
        if foothold.shape != (6,):
            raise ValueError(f"foothold must have shape (6,) (x, y, z, roll, pitch, yaw), got {foothold.shape}")
        self._step = [foothold[_PLANAR], bool(go) and bool(np.all(np.isfinite(foothold))), 0]

    def tick(self) -> bool:
        if self._step is None:
            raise RuntimeError("no step in progress: call begin() first")
        self._step[2] += 1
        self.time += self.control_dt
        return self._step[2] < self.ticks_per_step

    def end(self) -> None:
        if self._step is None or self._step[2] < self.ticks_per_step:
            raise RuntimeError("the step has not run all its ticks: tick() until it returns False")
        pose, go, _ = self._step
        self._step = None
        if go:
            self._feet[0 if self.swing > 0 else 1] = pose
            self.swing = np.float32(-self.swing)
        return None

    def execute(self, foothold, go: bool) -> None:
        """One whole step at once."""
        self.begin(foothold, go)
        while self.tick():
            pass
        return self.end()


GEOM_TYPES = {2: "sphere", 3: "capsule", 4: "ellipsoid", 5: "cylinder", 6: "box", 7: "mesh"}
"""MuJoCo's geom types (``mjtGeom``) a 3D view draws as themselves (a mesh with its vertices and faces,
:meth:`BodyGeoms.meshes`); a robot's other geoms (an SDF) are drawn as their bounding box, its planes and
height fields not at all."""
_SKIPPED_TYPES = (0, 1)  # mjGEOM_PLANE, mjGEOM_HFIELD
_MESH = 7  # mjGEOM_MESH
HIDDEN_GROUP = 3
"""Geoms of this group and above are not drawn: MuJoCo's viewers hide them by default (the G1's collision
capsules and foot boxes, which its meshes cover; the project's biped draws everything in group 0)."""
SOLE_THICKNESS = 0.03
"""m: the height of the box the perfect body's soles are drawn as (the robot has no sole thickness)."""
_SOLE_RGBA = {"left_sole": (58 / 255, 123 / 255, 213 / 255, 1.0), "right_sole": (232 / 255, 163 / 255, 61 / 255, 1.0)}
"""The perfect body's soles in the 2D view's feet colours (left blue, right orange)."""
_MUJOCO_RGBA = (0.5, 0.5, 0.5, 1.0)
"""MuJoCo's default geom colour: a geom with a material and this colour shows its material's."""


class BodyGeoms:
    """A live body's geoms for a 3D view: what each one is (:meth:`describe`, once) and where it is (:meth:`poses`,
    every frame).

    For a MuJoCo robot (:class:`ijoy_jax.sim.native.NativeBiped`, whose ``d.qpos`` is read, or
    :class:`ijoy_jax.sim.mjx_biped.MjxBiped`, whose ``qpos()`` is): its ``qpos`` through MuJoCo's forward
    kinematics on the robot as it is rendered, ``ijoy_jax.sim.bodies.build_model(body.sim.params, terrain,
    meshes=True)`` (the physics' own model for the project's biped; the G1 with its visual meshes, which its
    physics leaves out), and every geom of the robot (those on a body other than the world), in MuJoCo's
    order, less invisible ones (alpha 0, or a group from :data:`HIDDEN_GROUP` on). For :class:`PerfectBody`:
    its two soles as boxes of the robot's footprint, :data:`SOLE_THICKNESS` thick, standing on the terrain.

    Call :meth:`poses` from the thread that steps the body (the drive's ``on_tick``), so that it reads a whole
    tick's state.

    Args:
      body: a live body (:mod:`ijoy_jax.live.bodies`' protocol).
      terrain: the ground (the perfect body's soles stand on its heights).
      robot: the robot (the perfect body's footprint).

    Attributes:
      names: G geom names (an unnamed mesh geom: its mesh's name).
      types: G type names (:data:`GEOM_TYPES`' values).
      sizes: (G, 3) float64 MuJoCo's geom sizes (m): a box's half extents; a sphere's radius; a capsule's and
        a cylinder's radius and half length (along the geom's z); an ellipsoid's radii; a mesh's bounding box's
        half extents (drawn until its vertices arrive).
      mesh: (G,) int the index of each mesh geom's mesh in :meth:`meshes`, -1 for every other geom.
      rgba: (G, 4) float64 colours in [0, 1] (a geom's material's, where its own is MuJoCo's default).
      obstacle_height: m, how high the body meets a 2D map's obstacle cells (its physics' walls), or None (no
        physics: the perfect body).

    Example:
      >>> import ijoy_jax as ij
      >>> from ijoy_jax.live import PerfectBody
      >>> from ijoy_jax.live.bodies import BodyGeoms
      >>> robot, field = ij.robots.hrp2(), ij.terrain.flat((20, 20), 0.05)
      >>> geoms = BodyGeoms(PerfectBody(robot, ij.robots.start_stance(robot, 0.5, 0.5)), field, robot)
      >>> geoms.names, geoms.poses()[0].shape
      (('left_sole', 'right_sole'), (2, 3))
    """

    def __init__(self, body, terrain: Terrain, robot: Robot):
        self._body = body
        self.obstacle_height = None
        if isinstance(body, PerfectBody):
            self._kind = "soles"
            self.names = ("left_sole", "right_sole")
            self.types = ("box", "box")
            half = [0.5 * float(robot.foot_length), 0.5 * float(robot.foot_width), 0.5 * SOLE_THICKNESS]
            self.sizes = np.array([half, half], np.float64)
            self.rgba = np.array([_SOLE_RGBA[n] for n in self.names], np.float64)
            self.mesh = np.full(2, -1)
            self._terrain = terrain
            return
        import mujoco

        sim = getattr(body, "sim", None)
        params = getattr(sim, "params", None)
        if isinstance(getattr(body, "d", None), mujoco.MjData) and params is not None:
            self._kind, self._qpos = "native", lambda: body.d.qpos
        elif callable(getattr(body, "qpos", None)) and params is not None:
            self._kind, self._qpos = "mjx", body.qpos
        else:
            raise TypeError(f"no geoms to read from a {type(body).__name__}: a live body is a PerfectBody, a "
                            "MuJoCo robot with its data (d) or one on MJX (qpos()), and its Sim (sim.params)")
        from ijoy_jax.sim import bodies as sim_bodies

        self.obstacle_height = float(params.obstacle_height)
        self._m = m = sim_bodies.build_model(params, terrain, meshes=True)
        self._d = mujoco.MjData(m)
        keep = [g for g in range(m.ngeom) if m.geom_bodyid[g] != 0 and int(m.geom_type[g]) not in _SKIPPED_TYPES
                and m.geom_rgba[g, 3] > 0 and m.geom_group[g] < HIDDEN_GROUP]
        self._ids = np.asarray(keep, int)
        types = [int(m.geom_type[g]) for g in keep]
        self.names = tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or _unnamed(m, g) for g in keep)
        self.types = tuple(GEOM_TYPES.get(t, "box") for t in types)
        aabb = np.asarray(m.geom_aabb, np.float64)[self._ids]  # (G, 6) centre (geom frame) and half extents
        as_box = np.array([t not in GEOM_TYPES or t == _MESH for t in types], bool)
        self.sizes = np.where(as_box[:, None], aabb[:, 3:], np.asarray(m.geom_size, np.float64)[self._ids])
        # a bounding box's centre in its geom's frame (a mesh's vertices are in its geom's frame)
        self._offset = np.where((as_box & (np.asarray(types) != _MESH))[:, None], aabb[:, :3], 0.0)
        mesh_ids = [int(m.geom_dataid[g]) if t == _MESH else -1 for g, t in zip(keep, types, strict=True)]
        self._mesh_ids = list(dict.fromkeys(k for k in mesh_ids if k >= 0))  # the meshes drawn, in first use
        self.mesh = np.array([self._mesh_ids.index(k) if k >= 0 else -1 for k in mesh_ids], int)
        rgba = np.asarray(m.geom_rgba, np.float64)[self._ids].copy()
        mat = np.asarray(m.geom_matid)[self._ids]
        own = np.all(rgba == np.asarray(_MUJOCO_RGBA, np.float32), axis=1) & (mat >= 0)
        rgba[own] = np.asarray(m.mat_rgba, np.float64)[mat[own]]  # MuJoCo's rule: the material's colour
        self.rgba = rgba

    def describe(self) -> dict:
        """What the geoms are, JSON-ready: ``{"names", "types", "sizes": (G, 3), "rgba": (G, 4), "mesh": (G,)}``
        (lists; ``mesh`` indexes :meth:`meshes`)."""
        return {"names": list(self.names), "types": list(self.types), "sizes": self.sizes.tolist(),
                "rgba": self.rgba.tolist(), "mesh": self.mesh.tolist()}

    def meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The meshes the geoms draw (:attr:`mesh` indexes them): each its (V, 3) float32 vertices (m, in the
        frame of a geom that draws it, as :meth:`poses` places it) and (F, 3) uint32 triangles (vertex indices).
        Empty for the perfect body and the project's biped, whose geoms are all primitives."""
        if self._kind == "soles":
            return []
        m = self._m
        out = []
        for k in self._mesh_ids:
            v0, nv, f0, nf = (int(x[k]) for x in (m.mesh_vertadr, m.mesh_vertnum, m.mesh_faceadr, m.mesh_facenum))
            out.append((np.asarray(m.mesh_vert[v0:v0 + nv], np.float32),
                        np.asarray(m.mesh_face[f0:f0 + nf], np.uint32)))
        return out

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the geoms are now: (G, 3) float64 world positions (m) and (G, 4) float64 unit quaternions (w, x,
        y, z; geom frame to world)."""
        if self._kind == "soles":
            feet = np.asarray(self._body.feet(), np.float64)
            z = _ground(self._terrain, feet[:, :2]) + 0.5 * SOLE_THICKNESS
            half = 0.5 * feet[:, 2]
            quat = np.stack([np.cos(half), np.zeros(2), np.zeros(2), np.sin(half)], 1)
            return np.concatenate([feet[:, :2], z[:, None]], 1), quat
        import mujoco

        d = self._d
        d.qpos[:] = np.asarray(self._qpos(), np.float64)
        mujoco.mj_kinematics(self._m, d)
        mats = np.asarray(d.geom_xmat, np.float64)[self._ids].reshape(-1, 3, 3)
        pos = np.asarray(d.geom_xpos, np.float64)[self._ids] + np.einsum("gij,gj->gi", mats, self._offset)
        quat = np.empty((len(self._ids), 4))
        for k, mat in enumerate(mats):
            mujoco.mju_mat2Quat(quat[k], mat.ravel())
        return pos, quat


def _unnamed(m, g: int) -> str:
    """A name for geom ``g`` of ``m``, which has none: its mesh's (the G1's visual geoms), else ``geom<g>``."""
    import mujoco

    if int(m.geom_type[g]) == _MESH:
        return mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_MESH, int(m.geom_dataid[g])) or f"geom{g}"
    return f"geom{g}"


def _ground(terrain: Terrain, xy) -> np.ndarray:
    """(n,) float64 the terrain's height (m) at the cells under ``xy`` (n, 2) (0 on a 2D map; the nearest cell at
    the map's edge)."""
    if not terrain.has_height:
        return np.zeros(len(xy))
    h = np.asarray(terrain.height, np.float64)
    ij = np.floor((np.asarray(xy, np.float64) - np.asarray(terrain.origin, np.float64)) / float(terrain.resolution))
    ij = np.nan_to_num(ij, nan=0.0, posinf=0.0, neginf=0.0)
    i = np.clip(ij[:, 0], 0, h.shape[0] - 1).astype(int)
    j = np.clip(ij[:, 1], 0, h.shape[1] - 1).astype(int)
    return h[i, j]
