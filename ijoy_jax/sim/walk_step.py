"""The simulated walker's step in public parts: its state, its world, and a step as begin, ticks, end.

:func:`make_world` puts a :class:`~ijoy_jax.sim.walker.Sim`'s robot on a
terrain with its dynamics (:class:`World`); :func:`init_state` stands it on its
start feet (:class:`SimState`); :func:`stance_info` is the next decision's
stance; a step is :func:`begin_step` (the plan, :class:`Step`), one
:func:`tick` per control period (:class:`TickState`: the controller, then the
physics steps) and :func:`end_step` (the measured soles and the step's
:class:`StepLog`). The jitted walk (:func:`ijoy_jax.sim.walker.mjx_walker`)
and a robot stepped from the host tick by tick
(:class:`ijoy_jax.sim.mjx_biped.MjxBiped`) run these same functions.

Implementation module of :mod:`ijoy_jax.sim.walker`, which exports its public names.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from mujoco import mjx

from ijoy_jax import control, geometry, select
from ijoy_jax.prng import as_key
from ijoy_jax.robots import Robot
from ijoy_jax.sim import bodies, controller, hfield, kinematics, model, physics, preview, swing
from ijoy_jax.sim.sensors import (
    ankle_wrench,
    centre_of_mass,
    measured_soles,
    read_sensors,
    step_start,
    without_sensors,
)
from ijoy_jax.sim.simulator import Sim, nominal_dynamics
from ijoy_jax.terrain import Terrain


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
    balance: jax.Array | None = None  # (2,) m, the next step's capture-point shift (WalkConfig.capture_gain)


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


PLANAR = np.array([0, 1, 5])
"""The x, y and yaw entries of a sole (6,): x, y, z, roll, pitch, yaw."""


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


def make_world(
    sim: Sim,
    terrain: Terrain,
    *,
    dynamics: physics.Dynamics | None = None,
    m: mjx.Model | None = None,
    free: mjx.Model | None = None,
) -> World:
    """The :class:`World` of ``sim``'s robot on ``terrain`` (a grid of ``sim.shape``) with ``dynamics``.

    Args:
      sim: the :class:`Sim`.
      terrain: one :class:`Terrain` of ``sim.shape`` cells at ``sim.resolution`` m.
      dynamics: the robot's :class:`~ijoy_jax.sim.physics.Dynamics` (scalar leaves; sanitized, never
        NaN); None: :func:`nominal_dynamics`.
      m: the model with the terrain's height field (default: ``hfield.put_terrain`` of ``sim.mjx_model``);
        the dynamics are written into it (:func:`ijoy_jax.sim.physics.put_dynamics`).
      free: the controller's nominal model for its dynamics filter (default ``sim.mjx_free``).
    """
    params, cfg = sim.params, sim.cfg
    # the heights the robot meets: MuJoCo's height field clips them to [z_lo, z_hi] (hfield.hfield_data)
    phys = terrain.replace(
        height=jnp.clip(hfield.physical_heights(terrain, params.obstacle_height), params.z_lo, params.z_hi),
        has_height=True,
    )
    m = hfield.put_terrain(sim.mjx_model, params, terrain) if m is None else m
    free = sim.mjx_free if free is None else free
    dyn, dyn_invalid = physics.sanitize(nominal_dynamics(sim) if dynamics is None else dynamics)
    m = physics.put_dynamics(m, dyn)
    delay = physics.latency_ticks(dyn.latency, cfg.control_dt)
    push_dv = dyn.push / jnp.sum(m.body_mass)  # m/s: the impulse's velocity change of the whole robot
    return World(m, free, terrain, phys, dyn, dyn_invalid, delay, push_dv, controller.gains(cfg))


def resting_foothold(sim: Sim, phys: Terrain, foothold) -> jax.Array:
    """The foothold (6,) with z where the tilted sole's spheres first touch the physical terrain ``phys``."""
    p = sim.params
    points = jnp.asarray(model.sole_points(p)[:, :2], jnp.float32)
    return foothold.at[2].set(swing.resting_height(phys, foothold, p.foot_length, p.foot_width, points=points))


def _tilt_drop(sim: Sim, sole) -> jax.Array:
    """How far the lowest sole corner hangs below the centre of a tilted sole (m)."""
    p = sim.params
    return 0.5 * p.foot_length * jnp.abs(jnp.sin(sole[4])) + 0.5 * p.foot_width * jnp.abs(jnp.sin(sole[3]))


def _split(soles, swing_side):
    """(stance, swing) rows of (2, ...) soles for the swing side (+1: the left foot swings)."""
    left_swings = swing_side > 0
    return jnp.where(left_swings, soles[1], soles[0]), jnp.where(left_swings, soles[0], soles[1])


def _believed(pose, belief) -> jax.Array:
    """A planar pose (3,) as the robot believes it: shifted by its current position error ``belief`` (2,) m
    (``SimState.belief``)."""
    return pose.at[:2].add(belief)


def _believed_error(world: World, k) -> jax.Array:
    """(2,) m: the error of the stance position the next decision is given (Dynamics.stance_noise)."""
    return world.dynamics.stance_noise * jax.random.normal(k, (2,), jnp.float32)


def init_state(
    sim: Sim, world: World, robot: Robot, start, first_swing, key=None, *, frames_per_step: int = 0
) -> SimState:
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
    planned = jax.vmap(lambda p: resting_foothold(sim, world.phys, select.foothold(world.terrain, robot, p)))(start)
    # the pelvis cfg.pelvis_height above the lower sole and the CoM above the soles, as the controller holds them
    qpos = bodies.stand_pose(
        params, start, planned[:, 2], jnp.min(planned[:, 2]) + cfg.pelvis_height,
        controller.standing_shift(cfg, start), tilt=planned[:, 3:5]
    )[0]
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
    log = StepLog(
        soles[0],
        zero,
        zero,
        zero,
        jnp.bool_(False),
        jnp.bool_(False),
        jnp.float32(cfg.pelvis_height),
        zero,
        jnp.zeros((len(keep), m.nq), jnp.float32),
        world.dynamics_invalid,
    )
    key, k_belief = jax.random.split(as_key(0 if key is None else key))
    sent = jnp.broadcast_to(d.ctrl, (physics.max_latency_ticks(cfg.control_dt) + 1, m.nu))
    # The first step (the loop's warm-up iteration) stands while the preview sees the first step's weight shift
    # coming; it runs the same code as every step, so it is compiled once.
    return SimState(
        d,
        cs,
        soles,
        planned,
        swing_side,
        0.5 * (planned[0, :2] + planned[1, :2]),
        corr,
        log,
        jnp.bool_(True),
        key,
        _believed_error(world, k_belief),
        sent,
        None if sim.cfg.capture_gain == 0 else jnp.zeros(2, jnp.float32),
    )


def plan_frame_position(p, stance, planned_stance, to_plan, anchor=0.0):
    """(3,) a measured world point ``p`` (3,) (the pelvis, the centre of mass) in the plan's frame: horizontally,
    moved with the measured stance sole ``stance`` (6,) onto the one the controller commanded, ``planned_stance``
    (6,), through ``to_plan`` (3, 3) (:attr:`Step.to_plan`); its height the world's (``anchor`` 0), or moved
    with the stance sole too (``anchor`` 1: measured from the stance sole, carried onto the planned one's
    height), or that blend (``WalkConfig.stance_anchor``; both ends exact). NumPy arrays in, a NumPy array out
    (the native robot's control tick, on the host); JAX arrays otherwise.

    The plan's heights are the terrain's: every foothold rests on the height map as it is. Anchored on the
    stance sole's height as measured when the step began (just after its touch-down, before it carries the
    robot), the pelvis seen by the stabiliser is off by that sole's hover or sink, and the swing foot lands
    off by as much, relative to a frame that the next step anchors on that landing again: an integrator. The
    G1 turning in place at 0.7 rad/s landed each foot about 1.3 mm higher than the last, until a foot touched
    down in the air and the robot fell after 8-10 steps; with the world's height it turned 14 steps
    without falling, and 1024 G1s x 30 steps fell less under random commands (69 % -> 50 %) and held forward
    on ``rough`` (86 % -> 55 %) on one H200. The project's biped, on 13 cm soles, walks down refined stairs
    better anchored (0.05 % fell against 0.55 %): its swing foot lands relative to where its stance foot is.
    """
    moved = to_plan @ (p - stance[:3]) + planned_stance[:3]
    xp = np if isinstance(moved, np.ndarray) else jnp
    # (1 - a) z + a z_moved: exactly the world's height at a = 0 and the moved one at a = 1
    z = (1.0 - anchor) * p[2:3] + anchor * moved[2:3]
    return xp.concatenate([moved[:2], z.astype(moved.dtype)])


def plan_frame_com(sim: Sim, d, stance, planned_stance, to_plan) -> tuple[jax.Array, jax.Array]:
    """The measured centre of mass in the plan's frame, as the DCM feedback reads it: its position (2,) m
    (:func:`plan_frame_position`) and velocity (2,) m/s (turned by ``to_plan``), horizontal parts. ``d`` is MJX's
    or MuJoCo's data (NumPy in, NumPy out, as :func:`plan_frame_position`)."""
    c, v = centre_of_mass(sim, d)
    return plan_frame_position(c, stance, planned_stance, to_plan)[:2], (to_plan @ v)[:2]


def balance_shift(sim: Sim, d: mjx.Data, cs: controller.CtrlState, stance, planned_stance) -> jax.Array:
    """(2,) m, world frame: how far the next step moves for balance, ``WalkConfig.capture_gain`` times the
    divergent component of motion's error (:func:`ijoy_jax.sim.controller.dcm_error`: the measured capture point
    minus the LIPM's) at the step's end, at most ``WalkConfig.capture_max`` long.

    A robot pushed ahead of its plan steps further that way, the capture point's classic use (Pratt 2006,
    Englsberger 2015): the next decision's candidates are measured from the stance moved by it
    (:attr:`ijoy_jax.control.StanceInfo.balance`), so the selector chooses that step's foothold on the terrain.
    ``stance`` and ``planned_stance`` are the new stance sole (6,) measured and as the controller commanded it
    (its own frame); ``cs`` the controller's state at the step's end, ``d`` the data after its last tick.
    """
    cfg = sim.cfg
    to_plan = kinematics.rot_z(planned_stance[5] - stance[5])
    com = plan_frame_com(sim, d, stance, planned_stance, to_plan)
    err = controller.dcm_error(cfg, (cs.lipm[0], cs.lipm[1]), com)
    return controller.cap_shift(cfg, cfg.capture_gain * (to_plan[:2, :2].T @ err))


def stance_info(state: SimState) -> control.StanceInfo:
    """The next decision's stance (the Walker's ``stance``): the measured stance foot and the swing foot (x, y,
    yaw), as the robot believes them (shifted by :attr:`SimState.belief`), the stance side, and the next
    step's capture-point shift (:func:`balance_shift`; None while ``WalkConfig.capture_gain`` is 0)."""
    st, sw = _split(state.soles, state.swing)
    return control.StanceInfo(_believed(st[PLANAR], state.belief), -state.swing, _believed(sw[PLANAR], state.belief),
                              state.balance)


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
    # (3,) the touch-down's move dx, dy (m, the plan's frame) and its new height z (m): WalkConfig.swing_adjust's
    # (swing_shift), (0, 0, the planned height) until it acts; None while swing_adjust is 0
    adjust: jax.Array | None = None


def swing_shift(sim: Sim, phys: Terrain, plan: controller.StepPlan, target, to_plan, cs: controller.CtrlState,
                com) -> jax.Array:
    """(3,) the swing foot's step adjustment (``WalkConfig.swing_adjust``): its touch-down moves by
    :func:`ijoy_jax.sim.controller.swing_adjustment` (``swing_adjust`` times the capture point's lead over the
    LIPM's, at most ``capture_max``) in the plan's frame (dx, dy, m), and comes down at the resting height of
    the sole moved there on the physical terrain ``phys`` (z, m); nothing moves when ``plan`` stands.

    A robot running ahead of its plan within a step steps further that way before the foot comes down
    (Englsberger 2015, Khadiv 2020's step adjustment), where :func:`balance_shift` waits for the next decision.

    Args:
      plan: the step's :class:`~ijoy_jax.sim.controller.StepPlan`; target: (6,) the foothold it was sent to,
        resting on ``phys`` (world frame); to_plan: (3, 3) world -> the plan's frame (:attr:`Step.to_plan`).
      cs: the controller's state at the period's start; com: the measured centre of mass (position (2,),
        velocity (2,)) in the plan's frame (m, m/s).
    """
    shift = jnp.where(plan.go, controller.swing_adjustment(sim.cfg, cs, com), 0.0)
    moved = jnp.asarray(target, jnp.float32).at[:2].add(to_plan[:2, :2].T @ shift)
    # the plan's heights are the world's
    z = jnp.where(plan.go, resting_foothold(sim, phys, moved)[2], plan.swing_to[2])
    return jnp.concatenate([shift, z[None]])


def plan_to(sim: Sim, phys: Terrain, soles, planned, swing_side, anchor, foothold, go, fresh,
            belief=None) -> tuple[controller.StepPlan, jax.Array]:
    """The step to the selector's ``foothold`` (6,) x, y, z, roll, pitch, yaw, in the controller's own frame: the
    plan of :func:`begin_step` and of the biped stepped tick by tick (:mod:`ijoy_jax.sim.native`).

    The foothold rests on the physical terrain ``phys`` (:func:`resting_foothold`); the swing path clears the
    swept terrain by the clearance, whatever the soles' tilts. The step, taken relative to the measured stance
    sole (as the robot believes it: moved by ``belief`` (2,) m, its position error; None: none), is applied to
    the commanded one, so the plan stays continuous (no jump to the measured soles' millimetres) and the foot
    lands where the selector chose relative to where the stance foot really is. A ``fresh`` robot gets the
    warm-up plan (:func:`ijoy_jax.sim.controller.prepare_plan`).

    Args:
      soles, planned: (2, 6) the measured and the commanded soles (row 0 left); swing_side: () +1 if the left
        foot swings; anchor: (2,) the previous support; go: () bool, False to stand; fresh: () bool.

    Returns:
      ``(plan, target)``: the :class:`~ijoy_jax.sim.controller.StepPlan` and the foothold resting on ``phys``
      (world frame).
    """
    params, cfg = sim.params, sim.cfg
    st, sw = _split(soles, swing_side)
    pst, psw = _split(planned, swing_side)
    target = resting_foothold(sim, phys, jnp.asarray(foothold, jnp.float32))
    pose = target[PLANAR]
    top = swing.corridor_profile(phys, sw[PLANAR], pose, params.foot_length, params.foot_width) + jnp.maximum(
        _tilt_drop(sim, psw), _tilt_drop(sim, target)
    )
    stance = st[PLANAR] if belief is None else _believed(st[PLANAR], belief)
    planar = geometry.compose(pst[PLANAR], geometry.relative(stance, pose))
    ptarget = jnp.concatenate([planar[:2], target[2:5], planar[2:]])
    plan = controller.plan_step(anchor, pst, psw, ptarget, go, swing_side, top, cfg.clearance)
    plan = jax.tree_util.tree_map(
        lambda a, b: jnp.where(fresh, a, b), controller.prepare_plan(pst, psw, swing_side), plan
    )
    return plan, target


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
    plan, target = plan_to(sim, world.phys, s.soles, s.planned, s.swing, s.anchor, foothold, go, s.fresh, s.belief)
    st, _ = _split(s.soles, s.swing)
    pst = plan.stance
    key, k_belief, k_tick, k_dir = jax.random.split(s.key, 4)
    angle = jax.random.uniform(k_dir, (), jnp.float32, 0.0, 2 * jnp.pi)
    dv = jnp.where(s.fresh, 0.0, world.push_dv) * jnp.stack([jnp.cos(angle), jnp.sin(angle)])
    kick_tick = jax.random.randint(k_tick, (), 0, cfg.ticks_per_step)
    ground = jnp.minimum(plan.stance[2], plan.swing_to[2])  # as the controller holds the pelvis above it
    cs = s.ctrl._replace(t=jnp.zeros((), jnp.float32))
    corr = s.corr
    # The warm-up step stands unfiltered: its pattern is the LIPM's own, which starts moving the CoM toward the
    # first stance foot ahead of time (controller.prepare_plan). Filtered, the correction measured on that
    # standing pattern cancelled the anticipation, and the first step began with the LIPM's velocity jumping
    # by 0.15-0.2 m/s in one period: the HRP-2-like biped lagged 1.5 cm and recovered on its 13 cm wide feet,
    # the G1 on its 6 cm wide feet rolled onto an edge and fell.
    if cfg.filter_passes > 0:
        corr = controller.zmp_correction(
            world.free,
            params,
            cfg,
            world.gains,
            plan,
            cs,
            cfg.filter_passes,
            init=controller.carry_correction(cfg, corr),
        )
        corr = jnp.where(s.fresh, jnp.zeros_like(corr), corr)
    # World -> the plan's frame: the planar transform that takes the measured stance sole onto the planned one.
    to_plan = kinematics.rot_z(pst[5] - st[5])
    step = Step(plan, target, go, st, pst, to_plan, ground, corr, kick_tick, dv, key, k_belief)
    adjust = None if cfg.swing_adjust == 0 else jnp.concatenate([jnp.zeros(2, jnp.float32), plan.swing_to[2:3]])
    return step, TickState(s.data, cs, jnp.bool_(False), jnp.float32(jnp.inf), jnp.float32(0), s.sent, adjust)


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
    d, cs, touched, low, tilt, sent, adjust = ticks
    window = None if cfg.filter_passes == 0 else lax.dynamic_slice_in_dim(step.corr, k, cfg.horizon)
    st, pst, to_plan = step.stance, step.planned_stance, step.to_plan
    base = (plan_frame_position(d.qpos[:3], st, pst, to_plan, cfg.stance_anchor),
            to_plan @ kinematics.quat_to_rot(d.qpos[3:7]))
    com = plan_frame_com(sim, d, st, pst, to_plan)
    plan = step.plan
    if adjust is not None:  # static: WalkConfig.swing_adjust is on
        # computed at its one tick only (the tick index is the rollout's scan counter, the same for every robot
        # of a batch, so the cond stays a branch under vmap)
        adjust = lax.cond(k == controller.adjust_tick(cfg),
                          lambda: swing_shift(sim, world.phys, plan, step.target, to_plan, cs, com), lambda: adjust)
        plan = controller.shift_plan(cfg, plan, adjust)
    q, cs, _ = controller.control_tick(
        params, cfg, world.gains, plan, cs, window, base, ankle_wrench(sim, d), com, world.delay * cfg.control_dt
    )
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
    return TickState(read_sensors(world.m, d, start), cs, touched, low, tilt, sent, adjust)


def end_step(
    sim: Sim, world: World, state: SimState, step: Step, ticks: TickState, frames: jax.Array | None = None
) -> SimState:
    """The robot after a step's last :func:`tick`: the measured soles, the plan's new soles, and the
    :class:`StepLog` (``frames``: its ``qpos`` snapshots, default none). A diverged simulation (a NaN state,
    e.g. a stiffness beyond the timestep's limit, or no friction at all) counts as a fall, and the robot is put
    back to its state at the step's start (its last finite one): no NaN reaches the soles, the log or the
    trajectory."""
    s, d, target, go = state, ticks.data, step.target, step.go
    diverged = ~(jnp.all(jnp.isfinite(d.qpos)) & jnp.all(jnp.isfinite(d.qvel)))
    d, ctrl, sent = jax.tree_util.tree_map(
        lambda new, old: jnp.where(diverged, old, new), (d, ticks.ctrl, ticks.sent), (s.data, s.ctrl, s.sent)
    )
    pst = step.planned_stance
    plan = step.plan if ticks.adjust is None else controller.shift_plan(sim.cfg, step.plan, ticks.adjust)
    soles = measured_soles(sim, d)
    left_swings = s.swing > 0
    landed = jnp.where(left_swings, soles[0], soles[1])
    planned = jnp.where(left_swings, jnp.stack([plan.swing_to, pst]), jnp.stack([pst, plan.swing_to]))
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
    swing_next = jnp.where(go, -s.swing, s.swing)
    balance = None
    if sim.cfg.capture_gain != 0:
        new_st, _ = _split(soles, swing_next)
        new_pst, _ = _split(planned, swing_next)
        balance = jnp.where(go & ~fallen, balance_shift(sim, d, ctrl, new_st, new_pst), 0.0)
    return SimState(
        d,
        ctrl,
        soles,
        planned,
        swing_next,
        anchor,
        step.corr,
        log,
        jnp.bool_(False),
        step.key,
        _believed_error(world, step.belief_key),
        sent,
        balance,
    )
