"""The Unitree G1 (MuJoCo Menagerie) as the walker's robot: its model on the terrain and what the controller reads.

The robot is Menagerie's G1 as MuJoCo Playground ships it for MJX (:func:`ijoy_jax.sim.menagerie.g1_spec`,
the ``robots`` extra), its links, masses, inertias, leg joint axes, limits, armatures and torque limits
unchanged, made the walker's by :func:`walker_spec`:

* its waist and arms are welded at their ``knees_bent`` angles (the walker holds them still, and MJX's cost
  grows with the degrees of freedom: 18 for 35); every body keeps its mass and inertia, and the robot on the
  keyframe stands exactly as the full model does;

* its world is the project's (:func:`ijoy_jax.sim.scene.terrain_scene`): the terrain's height field in place of
  its floor, the soles as a grid of spheres on the bottom of each foot box, the ankle force/torque sensors and
  the centre-of-mass sensors the controller reads; its own sensors (for learned policies) and the feet's
  contact pair with each other (the selector keeps the footprints apart) are dropped, the hand-thigh pairs kept
  (a swinging thigh may still meet a hand);
* its servos are stiff position servos (:data:`LEG_KP`, ``kv = kp / 100``). Menagerie's gains (kp 75 on the
  hips and knees, 20 and 2 on the ankles) are those its learned policies command through; a ZMP walking
  controller tracks joint positions and needs servos that hold them under load, as the project's own biped
  does (15000-30000 N m/rad on its 58 kg). The G1's own torque limits (88, 139, 88, 139, 50, 50 N m on
  the hip pitch, roll, yaw, knee and ankles) still bound every joint;
* its options are the walker's (``BipedParams``: timestep, implicitfast, Newton with the walker's
  iteration caps, pyramidal cones).

:func:`description` reads that model back (:func:`ijoy_jax.sim.description.describe`): the leg chains the
inverse kinematics solves, the standing posture of the ``knees_bent`` keyframe, the foot's mass and where its
ankle sensor sits.
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np

from ijoy_jax.robots import G1_STEP_TIME
from ijoy_jax.sim import menagerie, model, scene
from ijoy_jax.sim.description import BipedDescription, describe

__all__ = ["LEG_KP", "STAND_WIDTH", "WALK", "description", "foot", "walker_spec"]

LEG_KP = {"hip_pitch": 8000.0, "hip_roll": 8000.0, "hip_yaw": 4000.0, "knee": 8000.0, "ankle_pitch": 4000.0,
          "ankle_roll": 3000.0}
"""N m/rad: the walker's servo stiffness on each leg joint (kv = kp / 100 N m s/rad). Standing on its
``knees_bent`` keyframe they hold every leg joint within 1.7 mrad of its target (0.35 mrad at x2, 7 mrad at
x0.25; all stable at the 2 ms timestep with the G1's own armatures)."""

WALK = {"pelvis_height": 0.72, "step_time": G1_STEP_TIME, "filter_passes": 2, "clearance": 0.03,
        "capture_gain": 2.0, "capture_max": 0.08, "swing_adjust": 1.0, "dcm_gain": 1.5, "stance_anchor": 0.0}
"""The ``WalkConfig`` fields the G1 walks with (:func:`ijoy_jax.sim.bodies.walk_defaults`; the others are the
project's biped's):

* ``pelvis_height``, m: the pelvis origin above the lower sole (its keyframe stands it at 0.758 m, the knees bent
  0.67 rad; lower bends them further, so a long and wide step stays within the legs' reach);
* ``step_time``, s: the selector robot's (:data:`ijoy_jax.robots.G1_STEP_TIME`, which says why 0.5 s);
* ``filter_passes`` 2 and ``clearance`` 3 cm: the G1's legs carry 43 % of its mass (7.2 kg each of 33 kg), so
  the swing foot's lift and descent, 24 cm beside the stance foot, move the pattern's multibody ZMP sideways by
  up to 28 cm. One pass of the dynamics filter with the biped's 5 cm clearance left the pattern's ZMP up to 17 cm
  (rms 3.2 cm) off its reference across the sole (the biped: 1.9 cm, rms 0.29 cm), more than the G1's 6 cm wide
  sole can take, and it fell within a few 0.2 m steps; two passes with a 3 cm lift leave 1.9 cm (rms 0.39 cm);
* ``capture_gain``, ``capture_max``: capture-point stepping on (2, at most 8 cm; off for the biped): with only
  about 2 cm of centre of pressure under its soles, the lateral error a step leaves is caught by where the next
  foot lands;
* ``swing_adjust`` 1: the swing foot's step adjustment on (off for the biped): once the foot has lifted, its
  touch-down moves by the capture point's lead measured then (at most ``capture_max``), where capture-point
  stepping waits for the next step. 1024 G1s x 30 steps on one H200, against the same walker without it
  (measured before the plan's heights were the world's, :func:`ijoy_jax.sim.walker.plan_frame_position`; fell;
  progress m, the perfect robot's in brackets): held forward on flat ground 0 % (0.29 %; 2.97 m, 2.57 m [2.95]),
  up and down slopes to 6 deg 0 % (5 %, 0.94 %), random commands on flat ground 69 % (93 %), held forward on
  ``rough`` 86 % (86 %; 0.47 m, 0.20 m [0.70]). A gain of 2 fell less under random commands
  (50 %) but more on ``rough`` (97 %) and outran the command held forward (3.40 m); the placement error
  counts the moved footholds (p95 2.1 cm on flat ground at 1, 4.4 cm at 2);
* ``dcm_gain`` 1.5 (the biped's 3): half the DCM feedback the ankles' damping control steers by. Traced tick by
  tick while turning in place, the stance foot's ground force swings between 0 and twice the weight at
  12-15 Hz (the robot's vertical mode on its stiff servos: about 17 Hz standing on both feet); the feedback's
  measured capture point carries that oscillation into the centre of pressure: the force's standard deviation
  within a step averaged 129 N at 3, 81 N at 1.5 and 81 N at 0 (10 steps, CPU). 1024 G1s x 30 steps on one
  H200 (fell, against 3 in the previous commit's runs): random commands on flat ground 43 % (50 %; 0: 36 %),
  held forward on ``rough`` 55 % (55 %; 0: 71 %) with 0.60 m of progress (0.51 m), on 2D clutter 61 % (64 %),
  up and down slopes 1.0 % and 6.0 % (1.7 %, 8.9 %; to 6 deg 0 % either way), on flat ground 0 % (0 %; 2.67 m
  of 2.95, against 2.87). A smaller gain trades the rough ground for flat ground's random commands; low-passing
  the DCM error did not help (BENCHMARKS.md, "The DCM feedback's gain").
* ``stance_anchor`` 0 (the biped's 1): the controller reads the pelvis at its world height
  (:func:`ijoy_jax.sim.walker.plan_frame_position`). Measured from its stance sole as it landed, each
  touch-down's 1.3 mm hover carried into the next: turning in place it landed ever higher and fell after 8-10
  steps; at 0, 1024 G1s x 30 steps fell 69 -> 50 % under random commands and 86 -> 55 % held forward on
  ``rough`` (one H200).

BENCHMARKS.md ("The Unitree G1 in MJX") has the batch figures.
"""

STAND_WIDTH = 0.24
"""m: the G1's feet apart when standing (its keyframe's 0.237 m on the action lattice's 2 cm grid,
``robots.g1``'s step in place)."""

_SIDES = ("left", "right")
_SOLES = menagerie.G1_SOLES


def _gain(joint: str) -> float:
    return LEG_KP[joint.removesuffix("_joint").split("_", 1)[1]]


def walker_spec(params, shape=(200, 200), resolution: float = 0.02, origin=(0.0, 0.0), *,
                meshes: bool = False) -> mujoco.MjSpec:
    """The G1 on a terrain height field, as the walker simulates it (see the module docstring).

    Args:
      params: :class:`ijoy_jax.sim.model.BipedParams` (its contact, simulation and terrain fields; the
        geometry and mass fields describe the project's own biped and are not read).
      shape, resolution, origin: the terrain grid, as :func:`ijoy_jax.sim.model.build_spec`.
      meshes: keep the G1's visual meshes (for rendering, :mod:`ijoy_jax.sim.render`). They neither collide
        nor weigh anything, so the model's joints, ``qpos`` layout, masses and contacts are the physics' own
        and a simulated ``qpos`` replays on it as it is; the physics leaves them out (a fraction of the size).

    Raises:
      MissingExtraError: the ``robots`` extra is not installed.
    """
    spec = menagerie.g1_spec(meshes=meshes)
    spec.modelname = "ijoy_g1"
    _weld_upper_body(spec)
    for sensor in list(spec.sensors):
        spec.delete(sensor)
    for pair in [p for p in spec.pairs if {p.geomname1, p.geomname2} == set(_SOLES)]:
        spec.delete(pair)
    scene.terrain_scene(spec, soles=_SOLES, params=params, shape=shape, resolution=resolution, origin=origin)
    model.set_options(spec, params)
    for act in spec.actuators:
        kp = _gain(act.target)
        act.set_to_position(kp=kp, kv=kp / 100.0)
    return spec


def _is_leg(joint: str) -> bool:
    name = joint.removesuffix("_joint")
    return any(name.startswith(side + "_") and name[len(side) + 1:] in LEG_KP for side in _SIDES)


def _weld_upper_body(spec: mujoco.MjSpec) -> None:
    """Fix the waist and the arms rigidly at their :data:`~ijoy_jax.sim.menagerie.G1_KEYFRAME` angles.

    Each body moved by a waist or arm joint gets, as its fixed pose in its parent, the pose the joint gives it
    on the keyframe; the joints, their actuators and their entries in the keyframes go. The bodies, their masses
    and inertias stay, so the robot standing on the keyframe is the same rigid body as before, now with 12
    actuated joints (``nv`` 18 for 35): its upper body is the part the walker holds still, and MJX's cost grows
    with ``nv``.
    """
    full = spec.compile()
    data = mujoco.MjData(full)
    mujoco.mj_resetDataKeyframe(full, data, mujoco.mj_name2id(full, mujoco.mjtObj.mjOBJ_KEY, menagerie.G1_KEYFRAME))
    mujoco.mj_kinematics(full, data)
    welded = [j for j in spec.joints if j.type == mujoco.mjtJoint.mjJNT_HINGE and not _is_leg(j.name)]
    welded_ids = {full.joint(j.name).id for j in welded}
    welded_q = {full.jnt_qposadr[j] for j in welded_ids}  # hinges: one qpos entry each
    keep_q = [adr for adr in range(full.nq) if adr not in welded_q]
    keep_u = [a for a in range(full.nu) if full.actuator_trnid[a, 0] not in welded_ids]
    for joint in welded:
        body = joint.parent
        child = full.body(body.name).id
        parent = full.body_parentid[child]
        rot = data.xmat[parent].reshape(3, 3)
        body.pos = rot.T @ (data.xpos[child] - data.xpos[parent])
        quat = np.zeros(4)
        mujoco.mju_negQuat(quat, data.xquat[parent])
        mujoco.mju_mulQuat(quat, quat, data.xquat[child])
        body.quat = quat
    for act in [a for a in spec.actuators if not _is_leg(a.target)]:
        spec.delete(act)
    for joint in welded:
        spec.delete(joint)
    for key in spec.keys:
        key.qpos = np.asarray(key.qpos)[keep_q]
        key.ctrl = np.asarray(key.ctrl)[keep_u]


@functools.lru_cache(maxsize=4)
def _small_model(params) -> mujoco.MjModel:
    """:func:`walker_spec` on a 2 x 2 flat grid, compiled (what the host reads of the robot; cached per params)."""
    return walker_spec(params, (2, 2), 1.0).compile()


@functools.lru_cache(maxsize=4)
def description(params) -> BipedDescription:
    """The walker's G1 read by :func:`~ijoy_jax.sim.description.describe`, standing on its ``knees_bent``
    keyframe (cached per params)."""
    return describe(_small_model(params), soles=_SOLES, keyframe=menagerie.G1_KEYFRAME)


def foot(params) -> tuple[float, np.ndarray]:
    """The foot below the ankle sensor: its mass (kg) and the sensor's point from the sole centre in the sole's
    frame (3,) m (the G1's ankle lies 4 cm behind the sole centre, 3.7 cm above it)."""
    m = _small_model(params)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    ankle = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "left_ankle")
    sole = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "left_sole")
    rot = d.site_xmat[sole].reshape(3, 3)
    offset = rot.T @ (d.site_xpos[ankle] - d.site_xpos[sole])
    return float(m.body_mass[m.site_bodyid[ankle]]), offset
