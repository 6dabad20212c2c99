"""The HRP-2-like biped as a MuJoCo model built with MjSpec, on the terrain's height field.

The robot: a free-floating pelvis (the hips' frame: hip joints at
``(0, +-hip_offset_y, 0)``), the upper body (torso, head, arms) lumped as rigid
geoms on the pelvis, and two 6-DoF legs (hip yaw/roll/pitch, knee, ankle
pitch/roll; see :mod:`ijoy_jax.sim.kinematics`) driven by position actuators.
Only small spheres under each sole (and, optionally, the shin capsules) touch
the terrain: MJX collides a sphere with a height field through a 2 x 2
sub-grid of prisms, a box through ``(ceil(2 rbound / res) + 1)^2`` prisms
(hundreds per foot), so the foot box is visual and inertial only.

The terrain it stands on is a height field (:mod:`ijoy_jax.sim.hfield`, which any robot's spec shares).

Example:
  >>> import mujoco, ijoy_jax as ij
  >>> from ijoy_jax.sim import model
  >>> p = model.biped_params(ij.robots.hrp2())
  >>> m = model.build_model(p, ij.terrain.flat((100, 60)))
  >>> round(float(sum(m.body_mass)), 1), m.nq, m.nu
  (58.0, 19, 12)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from ijoy_jax.robots import models as robots_models
from ijoy_jax.sim import hfield, kinematics
from ijoy_jax.struct import check_real, check_whole

__all__ = [
    "JOINTS",
    "MODELS",
    "SIDES",
    "BipedParams",
    "ModelIndex",
    "biped_params",
    "build_model",
    "build_spec",
    "contacts",
    "model_index",
    "put_model",
    "set_options",
    "sole_points",
    "standing_qpos",
]

SIDES = ("left", "right")
MODELS = robots_models.MODELS
"""The robots the walker drives (``BipedParams.model``; :mod:`ijoy_jax.sim.bodies`), as
:data:`ijoy_jax.robots.MODELS` names them."""
_MODEL_DEFAULTS = {"biped": {}, "g1": {"foot_length": 0.18, "foot_width": 0.06, "stand_width": 0.24}}
"""The fields :func:`biped_params` sets for each model before the robot's footprint and the overrides."""
JOINTS = ("hip_yaw", "hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")
_AXES = ((0, 0, 1), (1, 0, 0), (0, 1, 0), (0, 1, 0), (0, 1, 0), (1, 0, 0))
_FOOT_THICKNESS = 0.03  # visual/inertial foot box height above the sole, metres


# BipedParams' scalar fields: (lower bound, bound allowed); every one must also be finite. Lengths, masses,
# radii, the timestep and the base are divisors or would collapse a body; the offsets and friction may be 0.
_LOWER_BOUNDS: dict[str, tuple[float, bool]] = {
    **{name: (0.0, False) for name in (
        "thigh", "shank", "ankle_height", "foot_length", "foot_width", "stand_height", "stand_width", "pelvis_mass",
        "torso_mass", "head_mass", "arm_mass", "thigh_mass", "shank_mass", "foot_mass", "sole_radius",
        "shin_radius", "thigh_radius", "timestep", "base_depth")},
    "hip_offset_y": (0.0, True), "friction": (0.0, True),
    **{name: (-math.inf, False) for name in ("obstacle_height", "z_lo", "z_hi")},
}
# The per-joint tuples (hip yaw, roll, pitch, knee, ankle pitch, roll); all but the limits must be >= 0.
_JOINT_FIELDS = ("range_lo", "range_hi", "armature", "damping", "kp", "kv", "force")


@dataclasses.dataclass(frozen=True)
class BipedParams:
    """Static parameters of the HRP-2-like biped and its terrain model (hashable; metres, kg, seconds, radians).

    Robot::

      model: which robot the walker simulates (:data:`MODELS`): "biped", the HRP-2-like biped these fields
        describe, or "g1", the Unitree G1 read from its MJCF (:mod:`ijoy_jax.sim.g1`; the ``robots`` extra),
        for which the geometry, mass and joint fields below are not read (the contact, simulation and terrain
        fields are, and ``foot_length``, ``foot_width`` and ``stand_width`` are the G1's,
        :func:`biped_params`).

    Geometry::

      hip_offset_y: lateral distance of each hip point from the pelvis origin.
      thigh, shank: hip-knee and knee-ankle lengths.
      ankle_height: ankle joint centre above the sole.
      foot_length, foot_width: box foot (the footprint), along the foot's x and y.
      stand_height: default height of the pelvis origin (hip joints) above the
        soles in :func:`standing_qpos` (0.68: knees bent about 32 deg, CoM 0.77 m).
      stand_width: default lateral distance between the feet (HRP-2's step in place, 0.19).

    Masses (kg; total 58.0): pelvis, torso, head, arm (each), thigh (with the
      hip motors), shank, foot (with the ankle motors) per leg: legs 10.0 kg each, upper body 38 kg.

    Joints, per leg in :data:`JOINTS` order (6-tuples)::

      range_lo, range_hi: LEFT leg joint limits (the right leg mirrors yaw and
        roll: ``(-hi, -lo)``), HRP-2-like.
      armature: reflected rotor inertia (kg m^2); damping: joint viscous damping (N m s/rad).
      kp (N m/rad), kv (N m s/rad), force (N m): position actuator gains and torque limits. Stiff
        (kp 30000 on the pitch joints): softer gains (3000) let the CoM lag the plan at ~2 Hz
        bandwidth and diverge; twice these is unstable at timestep 0.002.

    Contacts::

      sole_grid: (n along the foot, n across) sole spheres (3 x 2: toe/middle/heel x edges).
      sole_radius: sphere radius; the spheres' bottoms lie on the sole plane. MJX collides
        a sphere with ``(ceil(2 r / res) + 1)^2`` height field cells: 0.009 keeps that 2 x 2 at
        res = 0.02 (at r = res / 2 exactly, float rounding of the grid step makes it 2 x 3 or 3 x 3).
      shin_contacts: shin capsules also collide with the terrain (off by default:
        each capsule-hfield pair costs MJX a sub-grid of prisms as large as the capsule).
      shin_radius, thigh_radius: capsule radii of the shank and thigh.
      friction: sliding friction of the sole spheres and of the ground (MuJoCo takes the larger of two
        geoms' coefficients, so both carry it); per robot and traced: ``sim.physics.Dynamics.friction``.

    Simulation::

      timestep: physics step (0.002 s: stable with these gains and armature);
        integrator implicitfast (implicit in the actuator damping kv).
      iterations, ls_iterations: Newton solver caps (4 and 8): MJX unrolls every
        iteration for every robot, so they bound each step's cost; Newton converges
        in 2-3 iterations on this small system (nv = 18).

    Terrain::

      obstacle_height: height given to obstacle cells of 2D terrains (0.1: a low
        obstacle a foot can be lifted over, as in the paper's stepping-over
        experiments; at 0.3 the swing path must rise 0.35 m and the simulated
        robot clipped a 4 cm obstacle it stepped over, measured).
      z_lo, z_hi: elevation range of the height field (heights outside are clipped).
      base_depth: thickness of the height field's base below z_lo.
    """

    hip_offset_y: float = 0.06
    thigh: float = 0.30
    shank: float = 0.30
    ankle_height: float = 0.105
    foot_length: float = 0.242
    foot_width: float = 0.13
    stand_height: float = 0.68
    stand_width: float = 0.19
    pelvis_mass: float = 6.0
    torso_mass: float = 17.4
    head_mass: float = 3.4
    arm_mass: float = 5.6
    thigh_mass: float = 5.2
    shank_mass: float = 3.1
    foot_mass: float = 1.7
    range_lo: tuple[float, ...] = tuple(math.radians(v) for v in (-30.0, -25.0, -125.0, 0.0, -75.0, -20.0))
    range_hi: tuple[float, ...] = tuple(math.radians(v) for v in (45.0, 35.0, 42.0, 150.0, 42.0, 35.0))
    armature: tuple[float, ...] = (0.1, 0.2, 0.2, 0.2, 0.2, 0.1)
    damping: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    kp: tuple[float, ...] = (15000.0, 30000.0, 30000.0, 30000.0, 30000.0, 20000.0)
    kv: tuple[float, ...] = (150.0, 200.0, 200.0, 200.0, 200.0, 150.0)
    force: tuple[float, ...] = (300.0, 500.0, 500.0, 500.0, 500.0, 400.0)
    sole_grid: tuple[int, int] = (3, 2)
    sole_radius: float = 0.009
    shin_contacts: bool = False
    shin_radius: float = 0.04
    thigh_radius: float = 0.06
    friction: float = 1.0
    timestep: float = 0.002
    iterations: int = 4
    ls_iterations: int = 8
    obstacle_height: float = 0.1
    z_lo: float = -1.0
    z_hi: float = 1.0
    base_depth: float = 0.1
    model: str = "biped"

    def __post_init__(self):
        if self.model not in MODELS:
            raise ValueError(f"BipedParams.model must be one of {MODELS}, got {self.model!r}")
        # Static (hashed into the compiled model): a field is a finite Python/NumPy number in its range, so a
        # string, a bool or a NaN is refused here by name, not by MuJoCo's compiler or a NaN in the physics.
        for name, (lo, lo_in) in _LOWER_BOUNDS.items():
            check_real(f"BipedParams.{name}", getattr(self, name), lo, lo_in=lo_in)
        for name in _JOINT_FIELDS:
            v = getattr(self, name)
            if not isinstance(v, tuple) or len(v) != 6:
                raise ValueError(f"BipedParams.{name} must be a tuple of 6 numbers (one per leg joint), got {v!r}")
            lo = -math.inf if name in ("range_lo", "range_hi") else 0.0
            for j, x in enumerate(v):
                check_real(f"BipedParams.{name}[{j}]", x, lo)
        if not isinstance(self.sole_grid, tuple) or len(self.sole_grid) != 2:
            raise ValueError(f"BipedParams.sole_grid must be a tuple of two counts >= 1, got {self.sole_grid!r}")
        for j, n in enumerate(self.sole_grid):
            check_whole(f"BipedParams.sole_grid[{j}]", n, 1)
        check_whole("BipedParams.iterations", self.iterations, 1)
        check_whole("BipedParams.ls_iterations", self.ls_iterations, 1)
        if not isinstance(self.shin_contacts, (bool, np.bool_)):
            raise ValueError(f"BipedParams.shin_contacts must be True or False, got {self.shin_contacts!r}")
        if any(lo >= hi for lo, hi in zip(self.range_lo, self.range_hi, strict=True)):
            raise ValueError("BipedParams.range_lo must be below range_hi for every joint")
        if self.z_hi <= self.z_lo:
            raise ValueError(f"BipedParams.z_hi ({self.z_hi}) must exceed z_lo ({self.z_lo})")
        if 2 * self.sole_radius > min(self.foot_length, self.foot_width):
            raise ValueError("BipedParams.sole_radius is too large for the foot")
        if self.stand_height >= self.thigh + self.shank + self.ankle_height:
            raise ValueError("BipedParams.stand_height must be below the straight leg's length")

    @property
    def total_mass(self) -> float:
        """Total mass of the robot, kg."""
        upper = self.pelvis_mass + self.torso_mass + self.head_mass + 2 * self.arm_mass
        return upper + 2 * (self.thigh_mass + self.shank_mass + self.foot_mass)

    def joint_range(self, side: Any) -> tuple[np.ndarray, np.ndarray]:
        """(6,) lower and upper joint limits (radians) of one leg; the right leg mirrors yaw and roll."""
        lo, hi = np.array(self.range_lo), np.array(self.range_hi)
        if kinematics.leg_sign(side) < 0:
            mirror = np.array([True, True, False, False, False, True])
            lo, hi = np.where(mirror, -hi, lo), np.where(mirror, -lo, hi)
        return lo, hi


def biped_params(robot=None, **overrides) -> BipedParams:
    """:class:`BipedParams` with the footprint of ``robot`` (if given) and any field overridden.

    Args:
      robot: an :class:`ijoy_jax.robots.Robot` (concrete; its ``foot_length``
        and ``foot_width`` become the box feet) or None for the model's own (HRP-2's, the G1's).
      **overrides: any :class:`BipedParams` field; ``model="g1"`` also sets the G1's feet and stance width.

    Example:
      >>> import ijoy_jax as ij
      >>> from ijoy_jax.sim import model
      >>> model.biped_params(ij.robots.hrp2(), timestep=0.001).foot_width
      0.13
    """
    kind = overrides.get("model", "biped")
    if kind not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {kind!r}")
    kwargs: dict[str, Any] = dict(_MODEL_DEFAULTS[kind])
    if robot is not None:
        # the Robot stores float32: round to micrometres so 0.13 stays 0.13 (and the params hash alike)
        kwargs["foot_length"] = round(float(robot.foot_length), 6)
        kwargs["foot_width"] = round(float(robot.foot_width), 6)
    names = {f.name for f in dataclasses.fields(BipedParams)}
    unknown = set(overrides) - names
    if unknown:
        raise ValueError(f"unknown BipedParams fields: {sorted(unknown)}")
    kwargs.update(overrides)
    return BipedParams(**kwargs)


# ----------------------------------------------------------------------------------------------------------------
# The robot


def sole_points(p: BipedParams) -> np.ndarray:
    """(K, 3) the sole spheres' centres in the foot frame (origin at the ankle; m), K = n_along * n_across: the
    points at which the simulated foot touches the ground (their x, y are the sole's contact points)."""
    r = p.sole_radius
    nx, ny = p.sole_grid
    xs = np.linspace(p.foot_length / 2 - r, -(p.foot_length / 2 - r), nx) if nx > 1 else np.zeros(1)
    ys = np.linspace(p.foot_width / 2 - r, -(p.foot_width / 2 - r), ny) if ny > 1 else np.zeros(1)
    return np.array([(x, y, -p.ankle_height + r) for x in xs for y in ys])


def _add_robot(spec: mujoco.MjSpec, p: BipedParams) -> None:
    box, sphere, capsule = mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CAPSULE
    visual = dict(contype=0, conaffinity=0)
    pelvis = spec.worldbody.add_body(name="pelvis", pos=[0, 0, p.stand_height])
    pelvis.add_freejoint(name="root")
    pelvis.add_geom(name="pelvis", type=box, size=[0.1, 0.14, 0.06], pos=[0, 0, 0.06], mass=p.pelvis_mass,
                    rgba=[0.6, 0.6, 0.65, 1], **visual)
    pelvis.add_geom(name="torso", type=box, size=[0.12, 0.17, 0.2], pos=[-0.03, 0, 0.34], mass=p.torso_mass,
                    rgba=[0.75, 0.75, 0.8, 1], **visual)
    pelvis.add_geom(name="head", type=sphere, size=[0.1, 0, 0], pos=[0, 0, 0.74], mass=p.head_mass,
                    rgba=[0.8, 0.8, 0.85, 1], **visual)
    for s in (1, -1):
        pelvis.add_geom(name=f"{SIDES[(1 - s) // 2]}_arm", type=capsule, size=[0.045, 0, 0],
                        fromto=[0, s * 0.23, 0.5, 0, s * 0.23, 0.02], mass=p.arm_mass, rgba=[0.7, 0.7, 0.75, 1],
                        **visual)
    pelvis.add_site(name="imu", pos=[0, 0, 0])
    pelvis.add_site(name="torso", pos=[0, 0, 0.34])

    shin_con = dict(contype=1, conaffinity=0) if p.shin_contacts else visual
    for side in SIDES:
        sgn = kinematics.leg_sign(side)
        lo, hi = p.joint_range(side)

        def joint(body, k, pos=(0, 0, 0), side=side, lo=lo, hi=hi):
            body.add_joint(name=f"{side}_{JOINTS[k]}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=list(_AXES[k]),
                           pos=list(pos), range=[lo[k], hi[k]], limited=True, armature=p.armature[k],
                           damping=p.damping[k])

        thigh = pelvis.add_body(name=f"{side}_thigh", pos=[0, sgn * p.hip_offset_y, 0])
        for k in range(3):
            joint(thigh, k)
        thigh.add_geom(name=f"{side}_thigh", type=capsule, size=[p.thigh_radius, 0, 0],
                       fromto=[0, 0, -0.05, 0, 0, -p.thigh + 0.05], mass=p.thigh_mass, rgba=[0.5, 0.5, 0.9, 1],
                       **visual)
        shank = thigh.add_body(name=f"{side}_shank", pos=[0, 0, -p.thigh])
        joint(shank, 3)
        shank.add_geom(name=f"{side}_shin", type=capsule, size=[p.shin_radius, 0, 0],
                       fromto=[0, 0, -0.04, 0, 0, -p.shank + 0.06], mass=p.shank_mass, rgba=[0.5, 0.5, 0.9, 1],
                       **shin_con)
        foot = shank.add_body(name=f"{side}_foot", pos=[0, 0, -p.shank])
        joint(foot, 4)
        joint(foot, 5)
        foot.add_geom(name=f"{side}_foot", type=box,
                      size=[p.foot_length / 2, p.foot_width / 2, _FOOT_THICKNESS / 2],
                      pos=[0, 0, -p.ankle_height + _FOOT_THICKNESS / 2], mass=p.foot_mass, rgba=[0.3, 0.3, 0.35, 1],
                      **visual)
        for k, c in enumerate(sole_points(p)):
            foot.add_geom(name=f"{side}_sole{k}", type=sphere, size=[p.sole_radius, 0, 0], pos=list(c),
                          contype=1, conaffinity=0, condim=3, friction=[p.friction, 0.005, 0.0001], mass=0.0,
                          rgba=[0.9, 0.3, 0.3, 1])
        foot.add_site(name=f"{side}_sole", pos=[0, 0, -p.ankle_height])
        foot.add_site(name=f"{side}_ankle", pos=[0, 0, 0])  # the ankle's force/torque sensor (HRP-2's 6-axis F/T)

    for side in SIDES:
        for kind in ("force", "torque"):
            spec.add_sensor(name=f"{side}_ankle_{kind}", type=getattr(mujoco.mjtSensor, f"mjSENS_{kind.upper()}"),
                            objtype=mujoco.mjtObj.mjOBJ_SITE, objname=f"{side}_ankle")
    # the whole robot's centre of mass and its velocity (world frame), what the controller's DCM feedback reads
    spec.add_sensor(name="com", type=mujoco.mjtSensor.mjSENS_SUBTREECOM, objtype=mujoco.mjtObj.mjOBJ_BODY,
                    objname="pelvis")
    spec.add_sensor(name="com_vel", type=mujoco.mjtSensor.mjSENS_SUBTREELINVEL, objtype=mujoco.mjtObj.mjOBJ_BODY,
                    objname="pelvis")
    for side in SIDES:
        lo, hi = p.joint_range(side)
        for k, name in enumerate(JOINTS):
            act = spec.add_actuator(name=f"{side}_{name}", target=f"{side}_{name}",
                                    trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.set_to_position(kp=p.kp[k], kv=p.kv[k])
            act.ctrllimited = True
            act.ctrlrange = [lo[k], hi[k]]
            act.forcelimited = True
            act.forcerange = [-p.force[k], p.force[k]]


def set_options(spec: mujoco.MjSpec, params: BipedParams) -> None:
    """The walker's physics options on any robot's ``spec``, in place: ``params.timestep``, implicitfast (implicit
    in the actuators' damping), Newton with ``params.iterations`` / ``ls_iterations``, pyramidal friction cones."""
    opt = spec.option
    opt.timestep = params.timestep
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    opt.iterations = params.iterations
    opt.ls_iterations = params.ls_iterations
    opt.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL


def build_spec(params: BipedParams, shape=(200, 200), resolution: float = 0.02, origin=(0.0, 0.0)) -> mujoco.MjSpec:
    """The biped and a height field of a terrain grid as an (uncompiled) :class:`mujoco.MjSpec`.

    The height field has ``nrow = ny`` rows (along y) and ``ncol = nx``
    columns (along x), its samples at the cell centres
    ``origin + (i + 0.5, j + 0.5) * resolution``, elevation
    ``z_lo + data * (z_hi - z_lo)``, and zero data (set it with
    :func:`build_model` or :func:`~ijoy_jax.sim.hfield.put_terrain`). The geom is named "terrain"
    (:func:`~ijoy_jax.sim.hfield.add_terrain`).

    Args:
      params: :class:`BipedParams`.
      shape: (nx, ny) terrain grid, each >= 2 (static).
      resolution: cell size, metres (> 0).
      origin: (2,) world (x, y) of the grid's lower corner, metres (concrete).

    Returns:
      The spec (options: timestep, implicitfast, Newton with ``iterations``/``ls_iterations``),
      with a keyframe "stand" (:func:`standing_qpos` at default feet, ground 0).
    """
    spec = mujoco.MjSpec()
    spec.modelname = "ijoy_biped"
    spec.compiler.degree = False  # every angle here is in radians (MjSpec defaults to degrees for ranges)
    set_options(spec, params)
    hfield.add_terrain(spec, params, shape, resolution, origin)
    _add_robot(spec, params)
    qpos = standing_qpos(params)
    spec.add_key(name="stand", qpos=qpos.tolist(), ctrl=qpos[7:].tolist())
    return spec


def build_model(params: BipedParams, terrain, *, edit=None) -> mujoco.MjModel:
    """The compiled :class:`mujoco.MjModel` of the biped on ``terrain`` (concrete).

    The height field data is written into the compiled model (``hfield_data``
    equals :func:`~ijoy_jax.sim.hfield.hfield_data` exactly); passing it to the spec instead would
    let MuJoCo's compiler rescale it to span [0, 1] (user hfield data is
    min-max normalised at compile time, which would lose the absolute heights).
    Keyframe 0 ("stand") is :func:`standing_qpos` on flat ground at z = 0 with matching ``ctrl``.
    ``edit``, when given, changes the ``mujoco.MjSpec`` in place before it is
    compiled (e.g. textures for :mod:`ijoy_jax.sim.render`).
    """
    spec = build_spec(params, terrain.shape, terrain.resolution, np.asarray(terrain.origin))
    return hfield.compile_with_terrain(spec, params, terrain, edit=edit)


def put_model(mj_model: mujoco.MjModel):
    """``mjx.put_model`` on this process's first local device.

    MJX's default device is ``jax.devices()[0]``: in a multi-process JAX job (``jax.distributed``) that is
    process 0's device, which another process can neither compute on nor read.
    """
    return mjx.put_model(mj_model, device=jax.local_devices()[0])


# ----------------------------------------------------------------------------------------------------------------
# Indices and the standing pose


class ModelIndex(NamedTuple):
    """Addresses in a compiled walker model (NumPy ints; rows: 0 left, 1 right; columns: the leg joints from the
    hip down, :data:`JOINTS` for the biped).

    Fields:
      qpos_adr: (2, 6) qpos addresses of the leg joints.
      qvel_adr: (2, 6) qvel (dof) addresses of the leg joints.
      actuator: (2, 6) actuator ids.
      pelvis: () pelvis body id (the free joint's body).
      foot: (2,) foot body ids.
      sole_site: (2,) sole-centre site ids.
      sole_geoms: (2, K) sole sphere geom ids.
      shin_geom: (2,) shin capsule geom ids.
      hfield_geom: () the terrain geom id.
      imu_site: () site at the pelvis origin.
      ankle_sensor: (2, 2) sensordata addresses of each ankle's force and torque (3 values each, foot frame,
      at the ankle point: what the shank exerts on the foot).
      com_sensor: (2,) sensordata addresses of the whole robot's centre of mass and of its velocity (3 values
      each, world frame; m, m/s).
    """

    qpos_adr: np.ndarray
    qvel_adr: np.ndarray
    actuator: np.ndarray
    pelvis: np.ndarray
    foot: np.ndarray
    sole_site: np.ndarray
    sole_geoms: np.ndarray
    shin_geom: np.ndarray
    hfield_geom: np.ndarray
    imu_site: np.ndarray
    ankle_sensor: np.ndarray
    com_sensor: np.ndarray


def model_index(mj_model: mujoco.MjModel) -> ModelIndex:
    """The :class:`ModelIndex` of a walker's model (:func:`build_model`, or
    :func:`ijoy_jax.sim.bodies.build_model` for any of :data:`MODELS`): each leg's joints are the hinges on the
    chain from the root body ``pelvis`` down to its ``{side}_sole`` site, hip first."""
    def oid(kind, name):
        i = mujoco.mj_name2id(mj_model, kind, name)
        if i < 0:
            raise ValueError(f"model has no {kind.name} named {name!r}; was it built by ijoy_jax.sim.model?")
        return i

    body, site, geom = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_SITE, mujoco.mjtObj.mjOBJ_GEOM
    pelvis = oid(body, "pelvis")
    sole_sites = np.array([oid(site, f"{s}_sole") for s in SIDES])
    jids = np.array([_leg_joints(mj_model, int(mj_model.site_bodyid[i]), pelvis) for i in sole_sites])
    by_joint = {int(mj_model.actuator_trnid[a, 0]): a for a in range(mj_model.nu)
                if mj_model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT}
    sole_geoms = []
    for s in SIDES:
        ids, k = [], 0
        while (g := mujoco.mj_name2id(mj_model, geom, f"{s}_sole{k}")) >= 0:
            ids.append(g)
            k += 1
        sole_geoms.append(ids)
    return ModelIndex(
        qpos_adr=np.asarray(mj_model.jnt_qposadr[jids]),
        qvel_adr=np.asarray(mj_model.jnt_dofadr[jids]),
        actuator=np.array([[by_joint.get(int(j), -1) for j in row] for row in jids]),
        pelvis=np.asarray(pelvis),
        foot=np.asarray(mj_model.site_bodyid[sole_sites]),
        sole_site=sole_sites,
        sole_geoms=np.array(sole_geoms),
        shin_geom=np.array([oid(geom, f"{s}_shin") for s in SIDES]),
        hfield_geom=np.asarray(oid(geom, "terrain")),
        imu_site=np.asarray(oid(site, "imu")),
        ankle_sensor=np.array([[mj_model.sensor_adr[oid(mujoco.mjtObj.mjOBJ_SENSOR, f"{s}_ankle_{k}")]
                                for k in ("force", "torque")] for s in SIDES]),
        com_sensor=np.array([mj_model.sensor_adr[oid(mujoco.mjtObj.mjOBJ_SENSOR, n)] for n in ("com", "com_vel")]),
    )


def _leg_joints(mj_model: mujoco.MjModel, foot: int, root: int) -> list[int]:
    """The joint ids on the chain from body ``root`` down to body ``foot``, hip first."""
    ids, b = [], foot
    while b != root:
        if b == 0:
            raise ValueError("a sole site does not hang from the pelvis; was the model built by ijoy_jax.sim?")
        ids = list(range(mj_model.body_jntadr[b], mj_model.body_jntadr[b] + mj_model.body_jntnum[b])) + ids
        b = int(mj_model.body_parentid[b])
    return ids


def _x64():
    if hasattr(jax, "enable_x64"):
        return jax.enable_x64(True)
    from jax.experimental import enable_x64  # jax < 0.10

    return enable_x64()


@functools.lru_cache(maxsize=8)
def _robot_model(params: BipedParams) -> mujoco.MjModel:
    """The robot over a small flat height field (for CoM queries)."""
    return build_spec(params, (2, 2), 1.0).compile()


def stand_pose(params: BipedParams, feet, ground, pelvis_z, shift=None, *, tilt=None) -> tuple[jax.Array, jax.Array]:
    """qpos (19,) of the robot standing with its soles at ``feet`` (2, 3) on ``ground`` (2,), and whether both
    legs reach (pure JAX: jit/vmap-able; float64 under ``jax.enable_x64``).

    The pelvis is level, yawed to the feet's mean yaw, ``pelvis_z`` high, above
    the feet's midpoint (moved by ``shift`` (2,) m when given); the legs come
    from :func:`ijoy_jax.sim.kinematics.leg_ik`. ``tilt`` (2, 2), roll and
    pitch of each sole (rad, :func:`ijoy_jax.sim.kinematics.rpy_to_rot`),
    stands the soles on sloped ground (default level).
    """
    feet = jnp.asarray(feet)
    dtype = feet.dtype
    ground = jnp.asarray(ground, dtype)
    yaw = jnp.arctan2(jnp.sum(jnp.sin(feet[:, 2])), jnp.sum(jnp.cos(feet[:, 2])))
    xy = jnp.mean(feet[:, :2], axis=0) + (0.0 if shift is None else jnp.asarray(shift, dtype))
    pelvis = jnp.concatenate([xy, jnp.asarray(pelvis_z, dtype)[None]])
    prot = kinematics.rot_z(yaw)
    tilt = jnp.zeros((2, 2), dtype) if tilt is None else jnp.asarray(tilt, dtype)
    legs = [kinematics.leg_ik(params, side, pelvis, prot, jnp.stack([feet[row, 0], feet[row, 1], ground[row]]),
                              kinematics.rpy_to_rot(jnp.stack([tilt[row, 0], tilt[row, 1], feet[row, 2]])))
            for row, side in enumerate(SIDES)]
    zero = jnp.zeros_like(yaw)
    quat = jnp.stack([jnp.cos(yaw / 2), zero, zero, jnp.sin(yaw / 2)])
    return jnp.concatenate([pelvis, quat, legs[0].q, legs[1].q]), legs[0].reachable & legs[1].reachable


def _standing(params: BipedParams, feet: np.ndarray, ground: np.ndarray, pelvis_z: float):
    with _x64():
        qpos, ok = stand_pose(params, jnp.asarray(feet, jnp.float64), jnp.asarray(ground, jnp.float64),
                              jnp.float64(pelvis_z))
        return np.asarray(qpos, np.float64), bool(ok)


def standing_qpos(params: BipedParams, feet=None, ground=(0.0, 0.0), com_height: float | None = None) -> np.ndarray:
    """(19,) float64 qpos of the robot standing with its soles at ``feet`` (host-side, NumPy).

    The pelvis is level, above the feet's midpoint, yawed to the feet's mean
    yaw, at ``stand_height`` above the lower foot's ground (so the legs stay in
    reach on uneven ground; or at the height that puts the whole-body CoM
    ``com_height`` above that ground); the legs come from
    :func:`ijoy_jax.sim.kinematics.leg_ik` in float64, so ``mj_forward`` puts
    each sole site at ``(x, y, ground)`` with yaw ``theta`` (to ~1e-12 m).

    Args:
      params: :class:`BipedParams`.
      feet: (2, 3) sole poses (x, y, theta) in metres/radians; row 0 left, row 1
        right. None: ``(0, +-stand_width / 2, 0)``.
      ground: (2,) ground height under each foot, metres.
      com_height: optional CoM height above the lower foot's ground, metres.

    Returns:
      qpos: (19,) free joint (pos, quat wxyz) then the 12 leg joints (left, right).

    Raises:
      ValueError: if a foot is out of the legs' reach.

    Example:
      >>> from ijoy_jax.sim import model
      >>> q = model.standing_qpos(model.BipedParams(), [[0.0, 0.095, 0.0], [0.0, -0.095, 0.0]])
      >>> round(float(q[2]), 3), q.shape
      (0.68, (19,))
    """
    if feet is None:
        feet = [[0.0, params.stand_width / 2, 0.0], [0.0, -params.stand_width / 2, 0.0]]
    feet = np.asarray(feet, np.float64).reshape(2, 3)
    ground = np.broadcast_to(np.asarray(ground, np.float64), (2,))
    if not (np.all(np.isfinite(feet)) and np.all(np.isfinite(ground))):
        raise ValueError("feet and ground must be finite")
    z0 = float(ground.min())
    pelvis_z = z0 + params.stand_height
    if com_height is not None:
        m = _robot_model(params)
        d = mujoco.MjData(m)
        for _ in range(4):  # the CoM moves slightly with the knee bend: a few fixed-point steps
            d.qpos[:] = _standing(params, feet, ground, pelvis_z)[0]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            pelvis_z += z0 + com_height - d.subtree_com[0, 2]
    qpos, ok = _standing(params, feet, ground, pelvis_z)
    if not ok:
        raise ValueError(f"feet {feet.tolist()} at ground {ground.tolist()} are out of the legs' reach "
                         f"from a pelvis at z = {pelvis_z:.3f} m")
    return qpos


def contacts(d) -> Any:
    """The contacts of an ``mjx.Data`` (an ``mjx.Contact``, one row per potential contact).

    ``dist`` (ncon,) m (negative: penetrating), ``pos`` (ncon, 3) m, ``frame``
    (ncon, 3, 3) (row 0 the normal), ``geom`` (ncon, 2) and ``geom1``,
    ``geom2`` (ncon,) geom ids. mujoco-mjx 3.17 keeps them in its JAX
    implementation's private ``Data._impl`` (its public fields hold no
    contacts), so this one accessor, pinned by a test to that version, is the
    only place that reads it.
    """
    return d._impl.contact
