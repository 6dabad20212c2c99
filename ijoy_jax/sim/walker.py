"""The MJX biped as a :class:`ijoy_jax.control.Walker`: the joystick loop with physics in place of a perfect robot.

:func:`mjx_walker` implements the Walker's pure functions over a state that
holds the MuJoCo XLA data: ``execute`` runs one step of the walking controller
and the physics (``step_time`` seconds) in a ``lax.scan``, ``stance`` and
``feet`` report the *measured* soles, so the next decision starts from where
the simulated foot really landed. The controller plans in its own frame:
each chosen step, taken relative to the measured stance foot, is applied
to the commanded one (``SimState.planned``), so the joint targets never jump
to the measured soles between steps. Every control tick hands the controller's
stabiliser the measured pelvis pose, mapped into that frame through the stance
sole (:func:`ijoy_jax.sim.controller.stabilise`). The robot stands one step before the
first decision (the Walker's ``warmup`` iteration, so that the step's
physics and dynamics filter are traced and compiled once, not twice).
:func:`rollout` is the control loop of :func:`ijoy_jax.rollout` (the same
selector code) with this walker, jitted as one scan (and usable inside your
own jit or vmap); :func:`rollout_batch` runs B of them in one jitted vmap
(terrains, robots, starts, commands).

The walker's functions are public in parts, so a robot stepped from the host
tick by tick (:class:`ijoy_jax.sim.mjx_biped.MjxBiped`, a live drive's) runs the
same code: :func:`make_world` (the robot's models on a terrain, its dynamics),
:func:`init_state`, :func:`stance_info`, and a step as :func:`begin_step`, one
:func:`tick` per control period, :func:`end_step`.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax import lax
from mujoco import mjx

from ijoy_jax import control, geometry, select
from ijoy_jax import terrain as terrain_mod
from ijoy_jax._struct import is_traced
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.limits import check_num_steps
from ijoy_jax.prng import as_key
from ijoy_jax.progress import compile_and_call
from ijoy_jax.robots import LEFT, Robot
from ijoy_jax.select import METHODS, Targets
from ijoy_jax.sim import controller, dynamics, kinematics, model, physics, preview, swing
from ijoy_jax.sim.controller import WalkConfig
from ijoy_jax.terrain import Terrain


@dataclasses.dataclass(frozen=True, eq=False)
class Sim:
    """A biped for one terrain grid shape: the host model, its MJX twin and the controller settings.

    Build it once with :func:`make_sim` (it compiles nothing); every terrain of
    that grid shape reuses it, its heights go into the height field per call.

    A pytree: its two MJX models are its leaves, traced arguments of every
    compiled program (never constants baked into it), and the rest is static
    metadata compared by value (``params``, ``cfg``, grid and fall limits, of
    which the models are built), so every Sim built with the same settings
    shares one compiled program, and ``jax.jit(f)(sim, ...)`` needs no
    ``static_argnums``.
    """

    params: model.BipedParams
    cfg: WalkConfig
    mj_model: mujoco.MjModel
    mjx_model: mjx.Model
    mjx_free: mjx.Model  # the same robot without constraints, for the dynamics filter's inverse dynamics
    index: model.ModelIndex
    shape: tuple[int, int]
    resolution: float
    fall_height: float  # pelvis height above its ground below which the robot has fallen (m)
    fall_tilt: float  # torso tilt beyond which it has fallen (rad)

    @property
    def substeps(self) -> int:
        return int(round(self.cfg.control_dt / self.mj_model.opt.timestep))


_SIM_MODELS = ("mjx_model", "mjx_free")


class _SimSettings:
    """A Sim's static part (pytree metadata): every field but its MJX models, compared and hashed by the
    settings the rest is built of (``params``, ``cfg``, grid, fall limits), not by the host objects' identity."""

    __slots__ = ("fields",)

    def __init__(self, fields: dict):
        self.fields = fields

    def key(self) -> tuple:
        f = self.fields
        return f["params"], f["cfg"], f["shape"], f["resolution"], f["fall_height"], f["fall_tilt"]

    def __hash__(self) -> int:
        return hash(self.key())

    def __eq__(self, other) -> bool:
        return isinstance(other, _SimSettings) and self.key() == other.key()


def _flatten_sim(sim: Sim):
    static = {f.name: getattr(sim, f.name) for f in dataclasses.fields(Sim) if f.name not in _SIM_MODELS}
    return tuple(getattr(sim, n) for n in _SIM_MODELS), _SimSettings(static)


jax.tree_util.register_pytree_node(
    Sim, _flatten_sim, lambda settings, models: Sim(**settings.fields, **dict(zip(_SIM_MODELS, models, strict=True))))


def make_sim(shape, resolution: float, params: model.BipedParams | None = None, cfg: WalkConfig | None = None,
             *, robot: Robot | None = None) -> Sim:
    """Build the biped and its controller for terrains of ``shape`` (nx, ny) cells of ``resolution`` m.

    ``cfg.com_height`` is replaced by the model's own CoM height at the
    standing posture with the pelvis ``cfg.pelvis_height`` above the ground,
    so the LIPM matches the robot. With ``robot`` given, its footprint sizes
    the feet and its step time must equal ``cfg.step_time``.
    """
    shape = (int(shape[0]), int(shape[1]))
    if min(shape) < 2:
        raise ValueError(f"terrain shape must be at least (2, 2) cells, got {shape}")
    params = model.biped_params(robot) if params is None else params
    cfg = WalkConfig() if cfg is None else cfg
    if robot is not None:
        check_robot(robot, cfg)
    timestep = params.timestep
    ratio = cfg.control_dt / timestep
    if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
        raise ValueError(f"control_dt {cfg.control_dt} must be a whole multiple of the physics timestep {timestep}")
    ratio = cfg.step_time / cfg.control_dt
    if abs(ratio - round(ratio)) > 1e-6:
        raise ValueError(f"step_time {cfg.step_time} must be a whole multiple of control_dt {cfg.control_dt}")
    mj_model = model.build_model(params, terrain_mod.flat(shape, resolution, has_height=True))
    # The LIPM's z_c and the horizontal CoM model (controller.WalkConfig): fitted on the standing robot.
    data = mujoco.MjData(mj_model)
    idx = model.model_index(mj_model)

    def com_of(shift):
        feet = jnp.asarray([[0.0, half, 0.0], [0.0, -half, 0.0]], jnp.float32)
        qpos = model.stand_pose(params, feet, jnp.zeros(2), jnp.float32(cfg.pelvis_height),
                                jnp.asarray(shift, jnp.float32))[0]
        data.qpos[:] = np.asarray(qpos)
        mujoco.mj_forward(mj_model, data)
        return data.subtree_com[idx.pelvis].copy()

    half = params.stand_width / 2
    com0, com1 = com_of([0.0, 0.0]), com_of([0.04, 0.0])
    # Pelvis moved by 0.04 m over fixed soles: the CoM moves by (1 - b) 0.04.
    b = float(np.clip(1.0 - (com1[0] - com0[0]) / 0.04, 0.0, 0.9))
    cfg = dataclasses.replace(cfg, com_height=float(com0[2]), com_offset=float(com0[0]), leg_share=b)
    return Sim(params, cfg, mj_model, model.put_model(mj_model), dynamics.no_contact_model(mj_model), idx, shape,
               float(resolution),
               fall_height=0.5 * cfg.pelvis_height, fall_tilt=0.7)


def check_robot(robot: Robot, cfg: WalkConfig) -> None:
    """The selector's step time (p_next = p0 + dt j) must be the walker's (one robot's or a batch's, when concrete)."""
    st = robot.step_time
    if isinstance(st, jax.core.Tracer):
        return
    st = np.asarray(st, np.float64)
    if np.any(np.abs(st - cfg.step_time) > 1e-6):
        shown = float(st) if st.ndim == 0 else st
        raise ValueError(f"robot.step_time {shown} s differs from the walking controller's {cfg.step_time} s")


class StepLog(NamedTuple):
    """What one executed step did (recorded per step in ``Trajectory.log``)."""

    landed: jax.Array  # (6,) measured swing sole at the step's end: x, y, z, roll, pitch, yaw
    placement_error: jax.Array  # () m, |landed - commanded| in xy (0 when no step was sent)
    yaw_error: jax.Array  # () rad, |wrap(landed - commanded)| yaw
    tilt_error: jax.Array  # () rad, angle between the landed sole's normal and the commanded one (0 when no step)
    fallen: jax.Array  # () bool, the robot has fallen (now or before)
    obstacle_contact: jax.Array  # () bool, a sole sphere (or shin) touched an obstacle cell during the step
    min_pelvis_height: jax.Array  # () m, lowest pelvis height above the ground during the step
    max_tilt: jax.Array  # () rad, largest torso tilt during the step
    qpos: jax.Array  # (frames_per_step, nq) snapshots of the state through the step, for rendering (0 by default)
    dynamics_invalid: jax.Array  # () bool, a Dynamics value was out of bounds and replaced by its nominal one


class SimState(NamedTuple):
    data: mjx.Data
    ctrl: controller.CtrlState
    soles: jax.Array  # (2, 6) measured soles x, y, z, roll, pitch, yaw (row 0 left)
    planned: jax.Array  # (2, 6) the same soles as the controller commanded them, in its own frame
    swing: jax.Array  # () +1 if the left foot swings next
    anchor: jax.Array  # (2,) the ZMP's current support point (controller frame)
    corr: jax.Array  # (controller.correction_length, 2) the dynamics filter's last correction
    last: StepLog
    fresh: jax.Array  # () bool, nothing simulated yet: the next execute stands (the Walker's warm-up step)
    key: jax.Array  # () PRNG key of the stance noise and the pushes still to come
    belief: jax.Array  # (2,) m, the measured stance's error for the next decision (physics.Dynamics.stance_noise)
    sent: jax.Array  # (latency ticks + 1, nu) the last joint targets, newest first (physics.Dynamics.latency)


def measured_soles(sim: Sim, d: mjx.Data) -> jax.Array:
    """(2, 6) the measured soles x, y, z, roll, pitch, yaw (``R = Rz(yaw) Ry(pitch) Rx(roll)``), row 0 left."""
    pos = d.site_xpos[sim.index.sole_site]  # (2, 3)
    mat = d.site_xmat[sim.index.sole_site].reshape(2, 3, 3)
    yaw = jnp.arctan2(mat[:, 1, 0], mat[:, 0, 0])
    pitch = jnp.arctan2(-mat[:, 2, 0], jnp.hypot(mat[:, 2, 1], mat[:, 2, 2]))
    roll = jnp.arctan2(mat[:, 2, 1], mat[:, 2, 2])
    return jnp.concatenate([pos, roll[:, None], pitch[:, None], yaw[:, None]], axis=1)


def ankle_wrench(sim: Sim, d: mjx.Data) -> jax.Array:
    """(2, 6) the ankles' force/torque sensors (``d.sensordata``): force then torque that the shank exerts on the
    foot, in the foot frame at the ankle point (N, N m), row 0 left."""
    adr = np.asarray(sim.index.ankle_sensor)[:, :, None] + np.arange(3)
    return d.sensordata[adr].reshape(2, 6)


def centre_of_mass(sim: Sim, d: mjx.Data) -> tuple[jax.Array, jax.Array]:
    """The whole robot's centre of mass (3,) and its velocity (3,) (world frame; m, m/s), from the model's
    ``com`` and ``com_vel`` sensors (``d.sensordata``)."""
    adr = np.asarray(sim.index.com_sensor)[:, None] + np.arange(3)
    return d.sensordata[adr[0]], d.sensordata[adr[1]]


def without_sensors(m: mjx.Model) -> mjx.Model:
    """``m`` with MuJoCo's sensor stage disabled (``opt.disableflags``, a static field): a physics step that
    computes no ``sensordata`` and moves the robot exactly as ``m`` does."""
    return m.replace(opt=m.opt.replace(disableflags=m.opt.disableflags | mjx.DisableBit.SENSOR))


def step_start(d: mjx.Data) -> tuple[jax.Array, ...]:
    """The state a physics step integrates: ``(qpos, qvel, act, time)`` of ``d`` (for :func:`read_sensors`)."""
    return d.qpos, d.qvel, d.act, d.time


def read_sensors(m: mjx.Model, d: mjx.Data, start: tuple[jax.Array, ...]) -> mjx.Data:
    """``d`` with ``sensordata`` as ``mjx.step(m, .)`` would have filled it in the step that produced ``d``.

    MuJoCo computes sensors in ``forward``, at the state the step starts from (``start``, its
    :func:`step_start`), then integrates ``qpos``, ``qvel``, ``act`` and ``time``. Every other field the
    sensors read (poses, ``cvel``, ``qacc``, the contacts and their forces) is still the step's own, so the
    sensors are evaluated on ``d`` with the start state put back, and ``d`` keeps its integrated state. The
    physics steps of a control tick run :func:`without_sensors` and this once after the last of them
    (:func:`tick`): the ankles' force/torque sensors cost a second Newton-Euler pass.
    """
    qpos, qvel, act, time = start
    sensed = mjx.sensor_acc(m, mjx.sensor_vel(m, mjx.sensor_pos(m, d.replace(qpos=qpos, qvel=qvel, act=act,
                                                                              time=time))))
    return sensed.replace(qpos=d.qpos, qvel=d.qvel, act=d.act, time=d.time)


def _normal(sole) -> jax.Array:
    """(3,) the unit normal of a sole (6,) x, y, z, roll, pitch, yaw."""
    return kinematics.rpy_to_rot(sole[3:6])[:, 2]


def _tilt(quat) -> jax.Array:
    """Angle between the torso's z axis and the vertical (rad)."""
    x, y = quat[1], quat[2]
    cos = 1 - 2 * (x * x + y * y) / jnp.maximum(jnp.sum(quat**2), 1e-12)
    return jnp.arccos(jnp.clip(cos, -1.0, 1.0))


def _obstacle_contact(sim: Sim, terrain: Terrain, d: mjx.Data) -> jax.Array:
    """A robot geom touches the terrain inside an obstacle cell (looked up half a cell into the ground)."""
    con = model.contacts(d)
    robot_geoms = jnp.asarray(np.concatenate([sim.index.sole_geoms.ravel(), sim.index.shin_geom]))
    g = con.geom  # (ncon, 2)
    involves = jnp.any(g[:, :, None] == robot_geoms[None, None, :], axis=(1, 2))
    with_ground = jnp.any(g == sim.index.hfield_geom, axis=1)
    active = (con.dist < 0) & involves & with_ground
    normal = con.frame[:, 0, :]
    probe = con.pos[:, :2] - 0.5 * terrain.resolution * normal[:, :2]
    ij = jnp.floor((probe - terrain.origin) / terrain.resolution).astype(jnp.int32)
    nx, ny = terrain.free.shape
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
    free = terrain.free[jnp.clip(ij[:, 0], 0, nx - 1), jnp.clip(ij[:, 1], 0, ny - 1)]
    return jnp.any(active & (~free | ~inside))


_PLANAR = np.array([0, 1, 5])  # x, y, yaw of a sole (6,)


def frame_ticks(sim: Sim, frames_per_step: int) -> np.ndarray:
    """The control ticks (0-based, within a step) whose end states ``StepLog.qpos`` keeps: evenly spaced, the last
    tick last (the touch-down)."""
    n = sim.cfg.ticks_per_step
    if not 0 <= frames_per_step <= n:
        raise ValueError(f"frames_per_step must be in [0, {n}] (control ticks per step), got {frames_per_step}")
    return np.round(np.arange(1, frames_per_step + 1) * n / max(frames_per_step, 1)).astype(int) - 1


class World(NamedTuple):
    """What one simulated biped steps on: the terrain, the robot's MJX models on it, its dynamics and the
    controller's gains (a pytree; :func:`make_world` builds it, inside or outside jit).

    Every field is a traced leaf (or a pytree of them), so one compiled step serves every terrain of the
    Sim's grid and every :class:`~ijoy_jax.sim.physics.Dynamics`.
    """

    m: mjx.Model  # the robot on the terrain's height field, with the dynamics' friction, masses and stiffness
    free: mjx.Model  # the controller's own nominal model without contacts (its dynamics filter's)
    terrain: Terrain  # the terrain as given (its obstacle cells: StepLog.obstacle_contact; the start footholds)
    phys: Terrain  # the heights the robot meets: 2D obstacles raised, clipped to the height field's range
    dynamics: physics.Dynamics  # sanitized: scalar float32 leaves, out-of-bounds values replaced by nominal ones
    dynamics_invalid: jax.Array  # () bool, a Dynamics value was out of bounds and replaced by its nominal one
    delay: jax.Array  # () int32 control ticks between the controller's joint targets and the actuators
    push_dv: jax.Array  # () m/s, the velocity change of the whole robot by a step's push
    gains: preview.PreviewGains  # the controller's preview gains (controller.gains)


def make_world(sim: Sim, terrain: Terrain, *, dynamics: physics.Dynamics | None = None, m: mjx.Model | None = None,
               free: mjx.Model | None = None) -> World:
    """The :class:`World` of ``sim``'s robot on ``terrain`` (a grid of ``sim.shape``) with ``dynamics``.

    Args:
      sim: the :class:`Sim`.
      terrain: one :class:`Terrain` of ``sim.shape`` cells at ``sim.resolution`` m.
      dynamics: the robot's :class:`~ijoy_jax.sim.physics.Dynamics` (scalar leaves; sanitized, never
        NaN); None: :func:`nominal_dynamics`.
      m: the model with the terrain's height field (default: ``model.put_terrain`` of ``sim.mjx_model``);
        the dynamics are written into it (:func:`ijoy_jax.sim.physics.put_dynamics`).
      free: the controller's nominal model for its dynamics filter (default ``sim.mjx_free``).
    """
    params, cfg = sim.params, sim.cfg
    # the heights the robot meets: MuJoCo's height field clips them to [z_lo, z_hi] (model.hfield_data)
    phys = terrain.replace(height=jnp.clip(model.physical_heights(terrain, params.obstacle_height), params.z_lo,
                                           params.z_hi), has_height=True)
    m = model.put_terrain(sim.mjx_model, params, terrain) if m is None else m
    free = sim.mjx_free if free is None else free
    dyn, dyn_invalid = physics.sanitize(nominal_dynamics(sim) if dynamics is None else dynamics)
    m = physics.put_dynamics(m, dyn)
    delay = physics.latency_ticks(dyn.latency, cfg.control_dt)
    push_dv = dyn.push / jnp.sum(m.body_mass)  # m/s: the impulse's velocity change of the whole robot
    return World(m, free, terrain, phys, dyn, dyn_invalid, delay, push_dv, controller.gains(cfg))


def _rest(sim: Sim, world: World, foothold) -> jax.Array:
    """The foothold (6,) with z where the tilted sole's spheres first touch the physical terrain."""
    p = sim.params
    points = jnp.asarray(model.sole_points(p)[:, :2], jnp.float32)
    return foothold.at[2].set(swing.resting_height(world.phys, foothold, p.foot_length, p.foot_width, points=points))


def _tilt_drop(sim: Sim, sole) -> jax.Array:
    """How far the lowest sole corner hangs below the centre of a tilted sole (m)."""
    p = sim.params
    return 0.5 * p.foot_length * jnp.abs(jnp.sin(sole[4])) + 0.5 * p.foot_width * jnp.abs(jnp.sin(sole[3]))


def _split(soles, swing_side):
    """(stance, swing) rows of (2, ...) soles for the swing side (+1: the left foot swings)."""
    left_swings = swing_side > 0
    return jnp.where(left_swings, soles[1], soles[0]), jnp.where(left_swings, soles[0], soles[1])


def _believed(pose, s: SimState) -> jax.Array:
    """A planar pose (3,) as the robot believes it: shifted by its current position error."""
    return pose.at[:2].add(s.belief)


def _believed_error(world: World, k) -> jax.Array:
    """(2,) m: the error of the stance position the next decision is given (Dynamics.stance_noise)."""
    return world.dynamics.stance_noise * jax.random.normal(k, (2,), jnp.float32)


def init_state(sim: Sim, world: World, robot: Robot, start, first_swing, key=None, *,
               frames_per_step: int = 0) -> SimState:
    """The biped standing on ``start`` (2, 3) (x, y, yaw of the feet, row 0 left; m, rad), ``first_swing`` (+1
    left) to swing first: the Walker's ``init``.

    The soles rest on the footholds :func:`ijoy_jax.select.foothold` gives ``robot`` there (the rested sole
    of the selector's), the pelvis ``cfg.pelvis_height`` above the lower one. ``key`` (PRNG key or int seed,
    default 0) draws the stance noise and pushes to come; ``frames_per_step`` (static) sizes ``StepLog.qpos``.
    The first step after it stands (:attr:`SimState.fresh`: the Walker's warm-up).

    Its data holds no sensor readings (``sensordata`` zeros: no physics step has run, so no contact force
    exists yet); :func:`tick` fills them after its physics steps. The first tick reads the zeros, harmlessly:
    the controller uses the sensors only in the ankles' damping control (:func:`ijoy_jax.sim.controller.comply`),
    which a measured load of zero turns off, so that tick runs open loop.
    """
    params, cfg = sim.params, sim.cfg
    keep = frame_ticks(sim, frames_per_step)
    start = jnp.asarray(start, jnp.float32)
    planned = jax.vmap(lambda p: _rest(sim, world, select.foothold(world.terrain, robot, p)))(start)
    # the pelvis cfg.pelvis_height above the lower sole, as the controller holds it
    qpos = model.stand_pose(params, start, planned[:, 2], jnp.min(planned[:, 2]) + cfg.pelvis_height,
                            tilt=planned[:, 3:5])[0]
    m = world.m
    d = mjx.make_data(m)
    d = d.replace(qpos=qpos, ctrl=qpos[7:])
    d = mjx.kinematics(m, d)
    d = mjx.com_pos(m, d)
    swing_side = jnp.asarray(first_swing, jnp.float32)
    cs = controller.init_state(world.gains, d.subtree_com[sim.index.pelvis][:2])
    corr = jnp.zeros((controller.correction_length(cfg), 2), jnp.float32)
    soles = measured_soles(sim, d)
    zero = jnp.float32(0)
    log = StepLog(soles[0], zero, zero, zero, jnp.bool_(False), jnp.bool_(False), jnp.float32(cfg.pelvis_height),
                  zero, jnp.zeros((len(keep), m.nq), jnp.float32), world.dynamics_invalid)
    key, k_belief = jax.random.split(as_key(0 if key is None else key))
    sent = jnp.broadcast_to(d.ctrl, (physics.max_latency_ticks(cfg.control_dt) + 1, m.nu))
    # The first step (the loop's warm-up iteration) stands while the preview sees the first step's weight shift
    # coming; it runs the same code as every step, so it is compiled once.
    return SimState(d, cs, soles, planned, swing_side, 0.5 * (planned[0, :2] + planned[1, :2]), corr, log,
                    jnp.bool_(True), key, _believed_error(world, k_belief), sent)


def stance_info(state: SimState) -> control.StanceInfo:
    """The next decision's stance (the Walker's ``stance``): the measured stance foot and the swing foot (x, y,
    yaw), as the robot believes them (shifted by :attr:`SimState.belief`), and the stance side."""
    st, sw = _split(state.soles, state.swing)
    return control.StanceInfo(_believed(st[_PLANAR], state), -state.swing, _believed(sw[_PLANAR], state))


class Step(NamedTuple):
    """A step in progress: what :func:`begin_step` planned, read by every :func:`tick` and by :func:`end_step`."""

    plan: controller.StepPlan  # the step in the controller's own frame
    target: jax.Array  # (6,) the foothold sent, resting on the physical terrain (world frame)
    go: jax.Array  # () bool, the swing foot steps (False: the robot stands this step)
    stance: jax.Array  # (6,) the stance sole as measured when the step began
    planned_stance: jax.Array  # (6,) the same sole as the controller commanded it, in its own frame
    to_plan: jax.Array  # (3, 3) world -> the plan's frame (the yaw that takes `stance` onto `planned_stance`)
    ground: jax.Array  # () m, the lower of the stance and target soles (the pelvis height's reference)
    corr: jax.Array  # (controller.correction_length, 2) the dynamics filter's correction for this step
    kick_tick: jax.Array  # () int32, the control tick of the step's push
    kick_dv: jax.Array  # (2,) m/s, the push's velocity change of the whole robot (0 without pushes)
    key: jax.Array  # () the PRNG key of the steps after this one
    belief_key: jax.Array  # () the PRNG key of the next decision's stance error


class TickState(NamedTuple):
    """What changes tick by tick during a step (:func:`tick`'s carry)."""

    data: mjx.Data
    ctrl: controller.CtrlState
    touched: jax.Array  # () bool, a sole sphere or shin touched an obstacle cell so far in the step
    low: jax.Array  # () m, the lowest pelvis height above `Step.ground` so far
    tilt: jax.Array  # () rad, the largest torso tilt so far
    sent: jax.Array  # (latency ticks + 1, nu) the last joint targets, newest first


def begin_step(sim: Sim, world: World, state: SimState, foothold, go) -> tuple[Step, TickState]:
    """Plan a step to the selector's ``foothold`` (6,) x, y, z, roll, pitch, yaw (stand if not ``go``): the
    start of the Walker's ``execute``.

    The foothold rests on the physical terrain; the swing path clears the swept terrain; the step, taken
    relative to the measured stance sole (as the robot believes it), is applied to the commanded one, so the
    plan stays in the controller's own frame; the dynamics filter's correction is warm-started from the last
    step's; the step's push is drawn. A fallen robot, and a fresh one (the warm-up step), stands.

    Returns:
      ``(step, ticks)``: the :class:`Step` and the :class:`TickState` of its first :func:`tick`.
    """
    params, cfg = sim.params, sim.cfg
    s = state
    go = jnp.asarray(go) & ~s.last.fallen & ~s.fresh
    st, sw = _split(s.soles, s.swing)
    pst, psw = _split(s.planned, s.swing)
    foothold = jnp.asarray(foothold, jnp.float32)
    target = _rest(sim, world, foothold)
    pose = target[_PLANAR]
    # the sole's lowest corner clears the swept terrain by the clearance, whatever the soles' tilts
    top = (swing.corridor_profile(world.phys, sw[_PLANAR], pose, params.foot_length, params.foot_width)
           + jnp.maximum(_tilt_drop(sim, psw), _tilt_drop(sim, target)))
    # The step relative to the measured stance foot, applied to the commanded one: the plan stays
    # continuous (no jump to the measured soles' millimetres), the foot lands where the selector chose
    # relative to where the stance foot really is (as the robot believes it: with stance noise, off by
    # the error the decision was given).
    rel = geometry.relative(_believed(st[_PLANAR], s), pose)
    planar = geometry.compose(pst[_PLANAR], rel)
    ptarget = jnp.concatenate([planar[:2], target[2:5], planar[2:]])
    plan = controller.plan_step(s.anchor, pst, psw, ptarget, go, s.swing, top, cfg.clearance)
    plan = jax.tree_util.tree_map(lambda a, b: jnp.where(s.fresh, a, b),
                                  controller.prepare_plan(pst, psw, s.swing), plan)
    key, k_belief, k_tick, k_dir = jax.random.split(s.key, 4)
    angle = jax.random.uniform(k_dir, (), jnp.float32, 0.0, 2 * jnp.pi)
    dv = jnp.where(s.fresh, 0.0, world.push_dv) * jnp.stack([jnp.cos(angle), jnp.sin(angle)])
    kick_tick = jax.random.randint(k_tick, (), 0, cfg.ticks_per_step)
    ground = jnp.minimum(plan.stance[2], plan.swing_to[2])  # as the controller holds the pelvis above it
    cs = s.ctrl._replace(t=jnp.zeros((), jnp.float32))
    corr = s.corr
    if cfg.filter_passes > 0:
        corr = controller.zmp_correction(world.free, params, cfg, world.gains, plan, cs, cfg.filter_passes,
                                         init=controller.carry_correction(cfg, corr))
    # World -> the plan's frame: the planar transform that takes the measured stance sole onto the planned one.
    to_plan = kinematics.rot_z(pst[5] - st[5])
    step = Step(plan, target, go, st, pst, to_plan, ground, corr, kick_tick, dv, key, k_belief)
    return step, TickState(s.data, cs, jnp.bool_(False), jnp.float32(jnp.inf), jnp.float32(0), s.sent)


def tick(sim: Sim, world: World, step: Step, ticks: TickState, k) -> TickState:
    """One control period (``cfg.control_dt``) of a step: the controller's tick, then its physics steps.

    The controller (:func:`ijoy_jax.sim.controller.control_tick`) gets the measured pelvis pose and centre of
    mass (:func:`centre_of_mass`: the DCM feedback), mapped into the plan's frame through the stance sole,
    and the ankles' force/torque sensors. Its joint targets reach the actuators ``world.delay`` ticks later,
    interpolated linearly over the tick's physics steps from the previous tick's (a servo's first-order hold:
    held as steps every 10 ms, they jolt the stiff joints and the robot falls within a few 0.2 m steps,
    measured on the native loop; interpolated, it walks). At tick ``step.kick_tick`` the robot is pushed.

    Args:
      sim, world, step: the robot, its world and the step (:func:`begin_step`).
      ticks: the :class:`TickState` after the previous tick (or :func:`begin_step`'s).
      k: () int, this tick's index in the step (0 to ``cfg.ticks_per_step - 1``).
    """
    params, cfg = sim.params, sim.cfg
    d, cs, touched, low, tilt, sent = ticks
    window = None if cfg.filter_passes == 0 else lax.dynamic_slice_in_dim(step.corr, k, cfg.horizon)
    st, pst, to_plan = step.stance, step.planned_stance, step.to_plan
    base = (to_plan @ (d.qpos[:3] - st[:3]) + pst[:3], to_plan @ kinematics.quat_to_rot(d.qpos[3:7]))
    c, v = centre_of_mass(sim, d)
    com = ((to_plan @ (c - st[:3]) + pst[:3])[:2], (to_plan @ v)[:2])
    q, cs, _ = controller.control_tick(params, cfg, world.gains, step.plan, cs, window, base, ankle_wrench(sim, d),
                                       com, world.delay * cfg.control_dt)
    sent = jnp.concatenate([q[None], sent[:-1]])
    q = sent[world.delay]  # what the actuators receive now: the targets of `delay` ticks ago
    d = d.replace(qvel=d.qvel.at[:2].add(jnp.where(k == step.kick_tick, step.kick_dv, 0.0)))
    q0 = d.ctrl
    fractions = jnp.arange(1, sim.substeps + 1, dtype=jnp.float32) / sim.substeps

    quiet = without_sensors(world.m)  # the controller reads the sensors once per tick: after the last step

    def step_physics(c, frac):
        d, _, touched, low, tilt = c
        d = d.replace(ctrl=q0 + frac * (q - q0))
        start = step_start(d)
        d = mjx.step(quiet, d)
        low = jnp.minimum(low, d.qpos[2] - step.ground)
        tilt = jnp.maximum(tilt, _tilt(d.qpos[3:7]))
        touched = touched | _obstacle_contact(sim, world.terrain, d)
        return (d, start, touched, low, tilt), None

    (d, start, touched, low, tilt), _ = lax.scan(step_physics, (d, step_start(d), touched, low, tilt), fractions)
    return TickState(read_sensors(world.m, d, start), cs, touched, low, tilt, sent)


def end_step(sim: Sim, world: World, state: SimState, step: Step, ticks: TickState,
             frames: jax.Array | None = None) -> SimState:
    """The robot after a step's last :func:`tick`: the measured soles, the plan's new soles, and the
    :class:`StepLog` (``frames``: its ``qpos`` snapshots, default none). A diverged simulation (a NaN state,
    e.g. a stiffness beyond the timestep's limit, or no friction at all) counts as a fall, and the robot is put
    back to its state at the step's start (its last finite one): no NaN reaches the soles, the log or the
    trajectory."""
    s, d, target, go = state, ticks.data, step.target, step.go
    diverged = ~(jnp.all(jnp.isfinite(d.qpos)) & jnp.all(jnp.isfinite(d.qvel)))
    d, ctrl, sent = jax.tree_util.tree_map(lambda new, old: jnp.where(diverged, old, new),
                                           (d, ticks.ctrl, ticks.sent), (s.data, s.ctrl, s.sent))
    pst = step.planned_stance
    soles = measured_soles(sim, d)
    left_swings = s.swing > 0
    landed = jnp.where(left_swings, soles[0], soles[1])
    planned = jnp.where(left_swings, jnp.stack([step.plan.swing_to, pst]), jnp.stack([pst, step.plan.swing_to]))
    fallen = s.last.fallen | (ticks.low < sim.fall_height) | (ticks.tilt > sim.fall_tilt) | diverged
    err = jnp.where(go, jnp.hypot(landed[0] - target[0], landed[1] - target[1]), 0.0)
    yaw_err = jnp.where(go, jnp.abs(geometry.wrap_angle(landed[5] - target[5])), 0.0)
    cos_tilt = jnp.clip(jnp.dot(_normal(landed), _normal(target)), -1.0, 1.0)
    tilt_err = jnp.where(go, jnp.arccos(cos_tilt), 0.0)
    frames = jnp.zeros((0, sim.mj_model.nq), jnp.float32) if frames is None else frames
    frames = jnp.where(jnp.all(jnp.isfinite(frames), axis=-1, keepdims=True), frames, d.qpos)  # a diverged one's
    low = jnp.where(diverged | jnp.isnan(ticks.low), 0.0, ticks.low)  # the pelvis counted on the ground
    tilt = jnp.where(diverged | jnp.isnan(ticks.tilt), jnp.pi, ticks.tilt)  # and the torso over
    log = StepLog(landed, err, yaw_err, tilt_err, fallen, ticks.touched, low, tilt, frames, world.dynamics_invalid)
    anchor = jnp.where(go, pst[:2], 0.5 * (planned[0, :2] + planned[1, :2]))
    return SimState(d, ctrl, soles, planned, jnp.where(go, -s.swing, s.swing), anchor, step.corr, log,
                    jnp.bool_(False), step.key, _believed_error(world, step.belief_key), sent)


def mjx_walker(sim: Sim, terrain: Terrain, m: mjx.Model | None = None, frames_per_step: int = 0, *,
               robot: Robot, dynamics: physics.Dynamics | None = None, key=None,
               free: mjx.Model | None = None) -> control.Walker:
    """The Walker of the simulated biped on ``terrain`` (call inside jit; ``m`` = the model with its height field).

    ``execute`` takes the selector's foothold (6,) (:attr:`ijoy_jax.select.StepChoice.foothold`); the start
    feet stand on the footholds :func:`ijoy_jax.select.foothold` gives ``robot`` there (the rested sole).

    The terrain's heights as the robot feels them (2D obstacles raised to
    ``params.obstacle_height``) also place the footholds' heights and the
    swing paths' apexes. ``frames_per_step`` (static) states per step are kept
    in ``StepLog.qpos`` (at :func:`frame_ticks`) for :mod:`ijoy_jax.sim.render`.

    ``dynamics`` (default :data:`ijoy_jax.sim.physics.NOMINAL`, scalar leaves) is written into ``m``
    (:func:`ijoy_jax.sim.physics.put_dynamics`) and sets the walker's control delay, stance noise and pushes,
    drawn from ``key`` (default key 0); ``free`` (default ``sim.mjx_free``) is the controller's own nominal
    model for its dynamics filter.

    Its functions are the public steps of this module, so a robot stepped tick by tick
    (:class:`ijoy_jax.sim.mjx_biped.MjxBiped`) runs the same code: ``init`` is :func:`init_state`,
    ``stance`` :func:`stance_info`, and ``execute`` :func:`begin_step`, one :func:`tick` per control period
    in a ``lax.scan``, then :func:`end_step`.
    """
    keep = frame_ticks(sim, frames_per_step)
    world = make_world(sim, terrain, dynamics=dynamics, m=m, free=free)
    key0 = as_key(0 if key is None else key)

    def init(start, first_swing):
        return init_state(sim, world, robot, start, first_swing, key0, frames_per_step=frames_per_step)

    def execute(s, foothold, go):
        step, ticks = begin_step(sim, world, s, foothold, go)

        def one(ticks, k):
            ticks = tick(sim, world, step, ticks, k)
            return ticks, ticks.data.qpos if frames_per_step else None

        ticks, qs = lax.scan(one, ticks, jnp.arange(sim.cfg.ticks_per_step))
        return end_step(sim, world, s, step, ticks, qs[keep] if frames_per_step else None)

    return control.Walker(init, stance_info, execute, lambda s: s.soles[:, _PLANAR], lambda s: s.last, warmup=1)


_OPTIONS = ("num_steps", "method", "swing_path", "quantize", "frames_per_step", "kernel", "refine")


def nominal_dynamics(sim: Sim) -> physics.Dynamics:
    """The :class:`~ijoy_jax.sim.physics.Dynamics` of the robot as ``sim`` built it (its ``params.friction``,
    :data:`~ijoy_jax.sim.physics.NOMINAL` otherwise): what a rollout without ``dynamics`` simulates."""
    return physics.NOMINAL.replace(friction=float(sim.params.friction))


@functools.partial(jax.jit, static_argnames=_OPTIONS)
def _rollout(sim: Sim, terrain: Terrain, robot: Robot, start, commands, first_swing, targets, dynamics, key, *,
             num_steps: int, method: str, swing_path: bool, quantize: bool, frames_per_step: int,
             kernel: str, refine: bool = False) -> control.Trajectory:
    """The loop of :func:`rollout`, jitted (the Sim's models are traced arguments), its inputs checked by the
    caller; inside a caller's trace it is inlined."""
    # The physics stands on finite heights: a traced NaN height or origin (refused where concrete, _check) is
    # flagged by the selector on the terrain as given, every decision unsupported, and the robot stands.
    walker = mjx_walker(sim, _finite_terrain(terrain), frames_per_step=frames_per_step, robot=robot,
                        dynamics=dynamics, key=key)
    return control.rollout(terrain, robot, start, commands, num_steps, method=method, first_swing=first_swing,
                           walker=walker, swing_path=swing_path, quantize=quantize, targets=targets, kernel=kernel,
                           refine=refine)


def _finite_terrain(terrain: Terrain) -> Terrain:
    """``terrain`` with each non-finite height and origin coordinate replaced by 0 (the physics' stand-in)."""
    return terrain.replace(height=jnp.where(jnp.isfinite(terrain.height), terrain.height, 0.0),
                           origin=jnp.where(jnp.isfinite(terrain.origin), terrain.origin, 0.0))


@functools.partial(jax.jit, static_argnames=_OPTIONS)
def _rollout_batch(sim: Sim, terrains: Terrain, robots: Robot, starts, commands, first_swing, targets, dynamics,
                   keys, *, num_steps: int, method: str, swing_path: bool, quantize: bool, frames_per_step: int,
                   kernel: str, refine: bool = False) -> control.Trajectory:
    """:func:`_rollout` vmapped over terrains, robots, starts, commands, first swings, dynamics and keys, as one
    jitted program (the Sim's models shared)."""

    def one(t, r, s, c, f, d, k):
        return _rollout(sim, t, r, s, c, f, targets, d, k, num_steps=num_steps, method=method, swing_path=swing_path,
                        quantize=quantize, frames_per_step=frames_per_step, kernel=kernel, refine=refine)

    return jax.vmap(one)(terrains, robots, starts, commands, first_swing, dynamics, keys)


def compiled_programs() -> int:
    """How many programs :func:`rollout` and :func:`rollout_batch` hold compiled (in this process).

    Read it before and after a loop of calls to learn how many compiles the
    loop caused: each new input shape, static option or Sim setting (grid,
    ``params``, ``cfg``) compiles once; new terrain heights, robot parameters,
    commands, dynamics or keys reuse the program, and so does a Sim built again
    with the same settings. A call with ``progress=True`` compiles its program
    ahead of time and runs it, outside this count; a later call without
    ``progress`` finds that program compiled and counts it then.
    """
    return compiled_count(_rollout) + compiled_count(_rollout_batch)


def _check(sim: Sim, terrain: Terrain, robot: Robot, start, commands, *, num_steps, method: str, first_swing,
           frames_per_step: int, batch: int | None, dynamics, kernel: str) -> None:
    """The inputs of one rollout (``batch`` None) or of ``batch`` rollouts: shapes and static options always,
    values only where they are concrete (so the checks pass through a caller's jit or vmap)."""
    lead = () if batch is None else (batch,)
    grid = tuple(np.shape(terrain.free)[len(lead):])
    if grid != sim.shape or terrain.resolution != sim.resolution:
        raise ValueError(f"terrain grid {grid} at {terrain.resolution} m does not match "
                         f"the Sim's {sim.shape} at {sim.resolution} m; build a Sim with make_sim for this grid")
    check_robot(robot, sim.cfg)
    # concrete terrain values as ij.rollout's boundary checks them (check_terrain: finite heights and origin)
    for name in ("height", "origin"):
        leaf = getattr(terrain, name)
        if not is_traced(leaf) and not np.all(np.isfinite(np.asarray(leaf))):  # NumPy: no op staged into a trace
            raise ValueError(f"terrain.{name} must be finite (no NaN or inf)")
    check_num_steps(num_steps)
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if kernel not in select.KERNELS:
        raise ValueError(f"kernel must be one of {select.KERNELS}, got {kernel!r}")
    frame_ticks(sim, frames_per_step)
    if dynamics is not None:
        physics.check(dynamics, batch)
    if np.shape(first_swing) not in ((), lead) or (
            not is_traced(first_swing) and not np.all(np.isin(np.asarray(first_swing), (LEFT, -LEFT)))):
        raise ValueError(f"first_swing must be +1 (left) or -1 (right) (one, or one per rollout), got {first_swing!r}")
    if batch is None and np.shape(start) != (2, 3):
        raise ValueError(f"start must have shape (2, 3) (left foot, right foot), got {np.shape(start)}")
    if batch is not None and np.shape(start) != (batch, 2, 3):
        raise ValueError(f"starts must have shape (B, 2, 3) with B = the terrains' batch {batch}, "
                         f"got {np.shape(start)}")
    if not is_traced(start) and not np.all(np.isfinite(np.asarray(start))):
        raise ValueError("start must be finite")
    shapes = (lead + (3,), lead + (num_steps, 3))
    if np.shape(commands) not in shapes:
        raise ValueError(f"commands must have shape {shapes[0]} or {shapes[1]}, got {np.shape(commands)}")


def _keys(key, batch: int | None) -> jax.Array:
    """One rollout's typed key (``batch`` None) or B of them: an int seed or key (split into B), or B keys."""
    k = as_key(0 if key is None else key)
    if batch is None:
        if k.shape != ():
            raise ValueError(f"key must be one PRNG key or int seed, got keys of shape {k.shape}")
        return k
    if k.shape == ():
        return jax.random.split(k, batch)
    if k.shape != (batch,):
        raise ValueError(f"key must be one PRNG key (split into the batch) or {batch} keys, got shape {k.shape}")
    return k


def rollout(sim: Sim, terrain: Terrain, robot: Robot, start, commands, *, num_steps: int, method: str = "exhaustive",
            first_swing: int = LEFT, targets: Targets | None = None, swing_path: bool = True,
            quantize: bool = True, frames_per_step: int = 0, dynamics: physics.Dynamics | None = None, key=None,
            kernel: str = "xla", refine: bool = False, progress: bool = False) -> control.Trajectory:
    """Walk the simulated biped with the joystick for ``num_steps`` steps (jitted as one scan).

    Same arguments and result as :func:`ijoy_jax.rollout`, with the physics in
    place of the perfect robot: ``footsteps`` are the measured touch-downs,
    ``commanded`` the steps sent, and ``log`` a :class:`StepLog` per step
    (placement error, falls, obstacle contacts; ``frames_per_step`` states of
    each step in ``log.qpos`` for :func:`ijoy_jax.sim.render.render`).
    :func:`summary` condenses it.

    Call it inside your own ``jax.jit`` or ``jax.vmap`` as well: the checks
    read shapes and skip traced values (``jax.vmap(lambda c: rollout(sim,
    terrain, robot, start, c, num_steps=n))(commands)`` is one batch). ``sim``
    is a pytree: pass it as an argument of your jitted function and its MJX
    models are traced there too.

    Args:
      sim: the :class:`Sim` of the terrain's grid shape.
      terrain: one :class:`Terrain` of ``sim.shape`` cells at ``sim.resolution`` m.
      robot: a :class:`Robot` whose step time is the controller's.
      start: (2, 3) world foot poses, row 0 left, row 1 right (m, rad; :func:`ijoy_jax.robots.start_stance`).
      commands: (3,) or (num_steps, 3) joystick commands (m/s, m/s, rad/s).
      num_steps: steps (static).
      method, first_swing, targets, swing_path, quantize, kernel, refine: as in :func:`ijoy_jax.rollout`
        (``refine``: each chosen step refined in continuous (dx, dy, dtheta), :mod:`ijoy_jax.refine`; static).
      frames_per_step: states kept per step in ``log.qpos`` (static; at most the control ticks per step).
      dynamics: the robot's :class:`~ijoy_jax.sim.physics.Dynamics` (scalar leaves; traced: new values never
        recompile); None: :func:`nominal_dynamics`.
      key: PRNG key or int seed of the stance noise and pushes (default 0).
      progress: while the walk compiles (a minute or more on a CPU for a new shape or option), write what
        compiles and the seconds elapsed to stderr (:func:`ijoy_jax.progress.compiling`; nothing for a
        compile under 2 s). The same program and result, bit for bit; default False: silent.

    Returns:
      A :class:`ijoy_jax.control.Trajectory` whose ``log`` is a :class:`StepLog` per step.
    """
    progress = _flag("progress", progress)
    _check(sim, terrain, robot, start, commands, num_steps=num_steps, method=method, first_swing=first_swing,
           frames_per_step=frames_per_step, batch=None, dynamics=dynamics, kernel=kernel)
    dyn = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32),
                                 nominal_dynamics(sim) if dynamics is None else dynamics)
    args = (sim, terrain, robot, start, commands, first_swing, targets, dyn, _keys(key, None))
    static = dict(num_steps=int(num_steps), method=method, swing_path=swing_path, quantize=quantize,
                  frames_per_step=int(frames_per_step), kernel=kernel, refine=_refine(refine))
    return _run(_rollout, args, static, progress=progress, batch=None)


def rollout_batch(sim: Sim, terrains: Terrain, robots: Robot, starts, commands, *, num_steps: int,
                  method: str = "exhaustive", first_swing=LEFT, targets: Targets | None = None,
                  swing_path: bool = True, quantize: bool = True, frames_per_step: int = 0,
                  dynamics: physics.Dynamics | None = None, key=None, kernel: str = "xla",
                  refine: bool = False, progress: bool = False) -> control.Trajectory:
    """:func:`rollout` for B robots at once: one jitted ``vmap`` of the simulated joystick loop.

    Args:
      sim: the :class:`Sim` of the terrains' grid shape.
      terrains: a :class:`Terrain` whose arrays have a leading batch axis B (stack B terrains).
      robots: a :class:`Robot` with a leading batch axis on every leaf (stack B robots, e.g. margins).
      starts: (B, 2, 3) world foot poses (left, right), m and rad.
      commands: (B, 3) or (B, num_steps, 3) joystick commands (m/s, m/s, rad/s).
      num_steps: steps per rollout (static).
      first_swing: () or (B,), +1 for the left foot first.
      dynamics: a batched :class:`~ijoy_jax.sim.physics.Dynamics`, each leaf () (shared) or (B,) (one per
        robot: frictions, mass and stiffness scales, latencies, stance noises, pushes); None:
        :func:`nominal_dynamics` for all.
      key: PRNG key or int seed, split into B keys, or (B,) keys: each robot's stance noise and pushes
        (default 0).
      method, targets, swing_path, quantize, frames_per_step, kernel, refine, progress: as in :func:`rollout`.

    Returns:
      A :class:`ijoy_jax.control.Trajectory` with a leading axis B on every leaf.

    Shapes and static arguments key the compile cache: batches of the same B,
    grid and ``num_steps`` reuse one compiled program whatever the terrains,
    robots' parameters (margins, weights), commands or dynamics
    (:func:`compiled_programs` counts them).

    Example:
      >>> # friction 0.3 and 1.0, the second robot 20 % heavier, in one compiled batch:
      >>> # dyn = physics.Dynamics(friction=jnp.array([0.3, 1.0]), mass_scale=jnp.array([1.0, 1.2]))
      >>> # traj = rollout_batch(sim, terrains, robots, starts, commands, num_steps=8, dynamics=dyn)
    """
    progress = _flag("progress", progress)
    b = np.shape(terrains.free)[0] if np.ndim(terrains.free) == 3 else None
    if b is None:
        raise ValueError(f"terrains must have a leading batch axis, got a grid of shape {np.shape(terrains.free)}")
    _check(sim, terrains, robots, starts, commands, num_steps=num_steps, method=method, first_swing=first_swing,
           frames_per_step=frames_per_step, batch=b, dynamics=dynamics, kernel=kernel)
    first = jnp.broadcast_to(jnp.asarray(first_swing, jnp.float32), (b,))
    dyn = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(jnp.asarray(x, jnp.float32), (b,)),
                                 nominal_dynamics(sim) if dynamics is None else dynamics)
    args = (sim, terrains, robots, starts, commands, first, targets, dyn, _keys(key, b))
    static = dict(num_steps=int(num_steps), method=method, swing_path=swing_path, quantize=quantize,
                  frames_per_step=int(frames_per_step), kernel=kernel, refine=_refine(refine))
    return _run(_rollout_batch, args, static, progress=progress, batch=b)


def _run(program, args: tuple, static: dict, *, progress: bool, batch: int | None) -> control.Trajectory:
    """``program(*args, **static)`` (``_rollout`` or ``_rollout_batch``; ``args[0]`` is the Sim), compiled
    ahead of time under progress lines when ``progress`` (:func:`ijoy_jax.progress.compile_and_call`)."""
    if not progress:
        return program(*args, **static)
    return compile_and_call(program, *args, what=_compiling(args[0], static["num_steps"], batch), **static)


def _compiling(sim: Sim, num_steps: int, batch: int | None) -> str:
    """What a rollout's progress lines say compiles: ``the MJX walk (12 steps on a 200x100 map)``, or for a
    batch ``the MJX walk of 64 robots (12 steps on 200x100 maps)``."""
    nx, ny = sim.shape
    steps = f"{num_steps} step{'' if num_steps == 1 else 's'}"
    if batch is None:
        return f"the MJX walk ({steps} on a {nx}x{ny} map)"
    return f"the MJX walk of {batch} robot{'' if batch == 1 else 's'} ({steps} on {nx}x{ny} maps)"


def _flag(name: str, value) -> bool:
    """A boolean option, True or False (NumPy's too); ValueError names it otherwise."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _refine(refine) -> bool:
    """``refine`` is a static option here: True or False (:func:`ijoy_jax.rollout` also takes a
    :class:`~ijoy_jax.refine.RefineParams`; its method check applies, in ``select.search_options``)."""
    return _flag("refine", refine)


def summary(traj: control.Trajectory) -> dict[str, jax.Array]:
    """Per-rollout totals of a simulated rollout, on top of ``traj.summary()``.

    fell: the robot fell; obstacle_contacts: steps during which a foot (or
    shin) touched an obstacle cell; collided: any did (bool); placement_error_mean / _p95 (m): the
    touch-down error of the steps taken; yaw_error_mean (rad); tilt_error_p95 (rad): the angle between a
    landed sole's normal and the commanded foothold's; dynamics_invalid: a
    :class:`~ijoy_jax.sim.physics.Dynamics` value was out of bounds and simulated as its nominal one.
    """
    log: StepLog = traj.log
    taken = traj.taken
    n = jnp.maximum(jnp.sum(taken, axis=-1), 1)
    err = jnp.where(taken, log.placement_error, jnp.nan)
    out = dict(traj.summary())
    out.update(
        fell=jnp.any(log.fallen, axis=-1),
        obstacle_contacts=jnp.sum(log.obstacle_contact, axis=-1, dtype=jnp.int32),
        collided=jnp.any(log.obstacle_contact, axis=-1),
        placement_error_mean=jnp.sum(jnp.where(taken, log.placement_error, 0.0), axis=-1) / n,
        placement_error_p95=jnp.where(jnp.any(taken, axis=-1), jnp.nanpercentile(err, 95, axis=-1), 0.0),
        yaw_error_mean=jnp.sum(jnp.where(taken, log.yaw_error, 0.0), axis=-1) / n,
        tilt_error_p95=jnp.where(jnp.any(taken, axis=-1),
                                 jnp.nanpercentile(jnp.where(taken, log.tilt_error, jnp.nan), 95, axis=-1), 0.0),
        dynamics_invalid=jnp.any(log.dynamics_invalid, axis=-1),
    )
    return out
