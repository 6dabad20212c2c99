"""The walking controller (the paper's Robot Walking Control): a footstep -> joint position targets.

One step of the joystick loop is one :class:`StepPlan`: the stance foot stays,
the swing foot moves from ``swing_from`` to ``swing_to``. Every control tick
(``control_dt``) :func:`control_tick`

1. builds the ZMP reference over the preview horizon from the plan (the next
   step is known one step ahead, the one after is assumed to repeat the
   stride: :func:`plan_step`),
2. advances the LIPM preview controller (Kajita 2003) to get the CoM reference,
3. places the swing foot on its path over the terrain (:mod:`.swing`),
4. stabilises: the pelvis is shifted by a CoM/DCM feedback on the measured
   state (Kajita's CoM-ZMP compliance in its simplest form) and the stance
   ankles are tilted against the measured torso tilt (ankle torque feedback),
5. solves both legs' analytic inverse kinematics for the actuators' position
   targets.

All functions are for one robot and pure; the MJX rollout vmaps them.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ijoy_jax import geometry
from ijoy_jax.sim import kinematics, preview, swing


@dataclasses.dataclass(frozen=True)
class WalkConfig:
    """Static settings of the walking controller (seconds, metres, radians).

    step_time: duration of one step; must equal the selector's
      ``robot.step_time`` (the Delta t of p_next).
    ds_fraction: fraction of a step spent in double support, at its start.
    control_dt: controller period; physics runs ``control_dt / timestep``
      steps per tick with the targets held.
    preview_time: preview horizon of the LIPM controller.
    com_height: z_c of the LIPM, the CoM's height above the ground.
    pelvis_height: the pelvis origin's height above the ground at that CoM.
    clearance: the swing sole rises this far above the highest terrain under
      its swept footprint.
    swing_lift: fraction of the swing spent rising (and as much descending)
      (:func:`swing.swing_pose`).
    swing_shift: fraction of the swing before (after) which the foot moves
      horizontally (<= swing_lift: the horizontal move starts while the foot
      still rises, spreading it over more time and lowering its acceleration).
    swing_comp: gain of the swing-leg ZMP compensation (:func:`swing_zmp_shift`):
      1 models the swing leg as a point mass ``leg_share / 2`` of the robot at
      its sole.
    com_offset, leg_share: the CoM model ``com = (1 - b) pelvis + b/2 (sole_l
      + sole_r) + (com_offset, 0)`` in the horizontal plane (b = leg_share),
      fitted to the robot by :func:`ijoy_jax.sim.walker.make_sim`; the pelvis
      is placed so that this CoM follows the LIPM.
    k_com, k_vel: CoM position (1) and velocity (s) feedback added to the
      pelvis reference.
    k_tilt: stance-ankle correction per radian of measured torso roll/pitch.
    preview_q, preview_r: weights of the preview controller's cost.
    """

    step_time: float = 0.8
    ds_fraction: float = 0.2
    control_dt: float = 0.01
    preview_time: float = 1.6
    com_height: float = 0.80
    pelvis_height: float = 0.68
    clearance: float = 0.05
    swing_lift: float = 0.2
    swing_shift: float = 0.2
    swing_comp: float = 0.0
    swing_level: float = 0.0
    com_offset: float = 0.0
    leg_share: float = 0.0
    k_com: float = 0.0
    k_vel: float = 0.0
    k_tilt: float = 0.0
    k_pos: float = 0.0
    k_vel_state: float = 0.0
    vel_filter: float = 0.3
    k_dcm: float = 0.0
    dcm_damping: float = 10.0
    dcm_leak: float = 4.0
    dcm_limit: float = 0.05
    preview_q: float = 1.0
    preview_r: float = 1e-6

    @property
    def ticks_per_step(self) -> int:
        return int(round(self.step_time / self.control_dt))

    @property
    def horizon(self) -> int:
        return int(round(self.preview_time / self.control_dt))

    @property
    def ds_time(self) -> float:
        return self.ds_fraction * self.step_time


class StepPlan(NamedTuple):
    """One step of the footstep queue (world frame; poses are x, y, z, yaw)."""

    zmp: jax.Array  # (4, 2) ZMP waypoints: previous support, this step's, next, the one after (preview.zmp_reference)
    stance: jax.Array  # (4,) stance sole
    swing_from: jax.Array  # (4,) swing sole at lift-off
    swing_to: jax.Array  # (4,) swing sole at touch-down (== swing_from when not walking)
    apex: jax.Array  # () absolute height the swing sole rises to
    swing_side: jax.Array  # () +1 if the left foot swings
    go: jax.Array  # () bool: False = stand on both feet (StopWalking)


class CtrlState(NamedTuple):
    """The controller's memory between ticks."""

    lipm: jax.Array  # (3, 2) CoM [position, velocity, acceleration] x, y
    err_sum: jax.Array  # (2,) integral of the ZMP tracking error
    t: jax.Array  # () seconds since the current step began
    com: jax.Array  # (2,) measured CoM at the last tick (for its velocity)
    com_vel: jax.Array  # (2,) filtered measured CoM velocity
    dcm_shift: jax.Array  # (2, 2) CoM offset and its velocity added by the DCM stabiliser


class Observation(NamedTuple):
    """What the controller measures (world frame)."""

    pelvis_pos: jax.Array  # (3,)
    pelvis_quat: jax.Array  # (4,) w, x, y, z
    pelvis_vel: jax.Array  # (3,) linear velocity of the pelvis origin
    com: jax.Array  # (3,) whole-body centre of mass


def init_state(pgains: preview.PreviewGains, com_xy) -> CtrlState:
    """At rest with the CoM at ``com_xy`` (2,) (an equilibrium of the preview servo)."""
    com_xy = jnp.asarray(com_xy, jnp.float32)
    return CtrlState(preview.initial_state(com_xy), preview.rest_err_sum(pgains, com_xy), jnp.zeros((), jnp.float32),
                     com_xy, jnp.zeros(2, jnp.float32), jnp.zeros((2, 2), jnp.float32))


def gains(cfg: WalkConfig) -> preview.PreviewGains:
    """The preview gains for ``cfg`` (compute once, outside the rollout's scan)."""
    return preview.preview_gains(cfg.com_height, cfg.control_dt, cfg.horizon, q=cfg.preview_q, r=cfg.preview_r)


def rot_z(yaw) -> jax.Array:
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    z, o = jnp.zeros_like(c), jnp.ones_like(c)
    return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


def rot_xy(roll, pitch) -> jax.Array:
    """R = Ry(pitch) @ Rx(roll)."""
    cr, sr, cp, sp = jnp.cos(roll), jnp.sin(roll), jnp.cos(pitch), jnp.sin(pitch)
    z, o = jnp.zeros_like(cr), jnp.ones_like(cr)
    rx = jnp.stack([jnp.stack([o, z, z]), jnp.stack([z, cr, -sr]), jnp.stack([z, sr, cr])])
    ry = jnp.stack([jnp.stack([cp, z, sp]), jnp.stack([z, o, z]), jnp.stack([-sp, z, cp])])
    return ry @ rx


def quat_tilt(quat) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(roll, pitch, yaw) of a w, x, y, z quaternion (ZYX convention)."""
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    roll = jnp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = jnp.arcsin(jnp.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = jnp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def plan_step(anchor, stance, swing_from, pose, go, swing_side, corridor_top, clearance) -> StepPlan:
    """The plan of one step.

    Args:
      anchor: (2,) the previous support (where the ZMP is now).
      stance, swing_from: (4,) measured soles (x, y, z, yaw).
      pose: (4,) commanded touch-down of the swing sole (x, y, ground z, yaw).
      go: () bool, False to stand (StopWalking).
      swing_side: () +1 if the left foot swings.
      corridor_top: () highest terrain under the swept footprint (m).
      clearance: () the swing sole's margin above it (m).
    """
    swing_to = jnp.where(go, pose, swing_from)
    stride = swing_to[:2] - swing_from[:2]
    mid = 0.5 * (stance[:2] + swing_from[:2])
    apex = jnp.maximum(corridor_top, jnp.maximum(swing_from[2], swing_to[2])) + clearance
    anchor = jnp.asarray(anchor, jnp.float32)
    walking = jnp.stack([anchor, stance[:2], swing_to[:2], stance[:2] + stride])
    standing = jnp.stack([anchor, mid, mid, mid])
    return StepPlan(
        zmp=jnp.where(go, walking, standing),
        stance=stance,
        swing_from=swing_from,
        swing_to=swing_to,
        apex=jnp.where(go, apex, swing_from[2]),
        swing_side=jnp.asarray(swing_side, jnp.float32),
        go=jnp.asarray(go),
    )


def prepare_plan(stance, swing_from, swing_side) -> StepPlan:
    """Stand still for one step while the preview sees the first step coming.

    Started from rest, the first step's ZMP shift would begin at once, which
    the preview cannot anticipate (the LIPM's ZMP then leaves the foot). This
    plan keeps both feet down with the ZMP at their midpoint, and its second
    step is the first real step's double support, so the CoM starts moving
    toward the first stance foot ahead of time, as in a steady gait.
    """
    mid = 0.5 * (stance[:2] + swing_from[:2])
    return StepPlan(
        zmp=jnp.stack([mid, mid, stance[:2], swing_from[:2]]),
        stance=stance,
        swing_from=swing_from,
        swing_to=swing_from,
        apex=swing_from[2],
        swing_side=jnp.asarray(swing_side, jnp.float32),
        go=jnp.bool_(False),
    )


def swing_phase(cfg: WalkConfig, t) -> jax.Array:
    """0 until the double support ends, 1 at the end of the step."""
    return jnp.clip((t - cfg.ds_time) / (cfg.step_time - cfg.ds_time), 0.0, 1.0)


def swing_point(cfg: WalkConfig, start, end, apex, s) -> jax.Array:
    """(4,) swing sole x, y, z, yaw at phase s: z rises over ``swing_lift``, x, y, yaw move over
    ``[swing_shift, 1 - swing_shift]`` of the swing (both quintic, :func:`swing.swing_pose`)."""
    pos_z, _ = swing.swing_pose(start, end, apex, s, lift=cfg.swing_lift)
    pos_h, yaw = swing.swing_pose(start, end, apex, s, lift=cfg.swing_shift)
    return jnp.stack([pos_h[0], pos_h[1], pos_z[2], yaw])


def foot_targets(cfg: WalkConfig, plan: StepPlan, t) -> jax.Array:
    """(2, 4) sole targets x, y, z, yaw at time t of the step, row 0 left."""
    s = swing_phase(cfg, t)
    moving = swing_point(cfg, plan.swing_from, plan.swing_to, plan.apex, s)
    moving = jnp.where(plan.go, moving, plan.swing_from)
    left_swings = plan.swing_side > 0
    left = jnp.where(left_swings, moving, plan.stance)
    right = jnp.where(left_swings, plan.stance, moving)
    return jnp.stack([left, right])


def swing_zmp_shift(cfg: WalkConfig, plan: StepPlan, t, zref) -> jax.Array:
    """(N, 2) ZMP shift the swing leg's motion adds to the LIPM's over the preview horizon (m).

    The swing leg is a point mass ``m_s = r M`` (``r = swing_comp * leg_share / 2``)
    at the swing sole ``p``; the rest of the robot keeps the whole-body CoM on
    the LIPM at height ``z_b = z_c / (1 - r)``. The two-mass ZMP then differs
    from the LIPM's by::

        dp = r ((z_b - p_z) p_xy'' + (p_xy - p_ref) p_z'') / (g + r p_z'')

    The current step's swing and the next one (from the stance foot to
    ``plan.zmp[3]``, the stride repeated) are sampled at ``t + k dt`` and
    differentiated twice; later steps add nothing. Subtract it from the ZMP
    reference so that the multibody ZMP follows the reference.
    """
    n = zref.shape[0]
    dt = cfg.control_dt
    times = t + (jnp.arange(n + 2, dtype=jnp.float32) - 1.0) * dt
    m = jnp.floor(times / cfg.step_time)
    s = swing_phase(cfg, times - m * cfg.step_time)
    rise = plan.apex - jnp.maximum(plan.swing_from[2], plan.swing_to[2])
    next_to = jnp.concatenate([plan.zmp[3], plan.stance[2:3], (plan.stance[3] + plan.swing_to[3]
                                                               - plan.swing_from[3])[None]])
    path0 = jax.vmap(lambda si: swing_point(cfg, plan.swing_from, plan.swing_to, plan.apex, si))(s)
    path1 = jax.vmap(lambda si: swing_point(cfg, plan.stance, next_to, plan.stance[2] + rise, si))(s)
    path = jnp.where((m <= 0)[:, None], path0, jnp.where((m == 1)[:, None], path1, next_to[None, :]))
    acc = (path[2:, :3] - 2.0 * path[1:-1, :3] + path[:-2, :3]) / dt**2
    acc = jnp.where(plan.go, acc, 0.0)
    p = path[1:-1, :3]
    r = cfg.swing_comp * 0.5 * cfg.leg_share
    z_b = cfg.com_height / (1.0 - r)
    h = p[:, 2] - plan.stance[2]
    return r * ((z_b - h)[:, None] * acc[:, :2] + (p[:, :2] - zref) * acc[:, 2:3]) / (9.81 + r * acc[:, 2:3])


def control_tick(params, cfg: WalkConfig, pgains: preview.PreviewGains, plan: StepPlan, cs: CtrlState,
                 obs: Observation) -> tuple[jax.Array, CtrlState, jax.Array]:
    """One controller period: the 12 joint targets (left leg then right), the new state, the ZMP reference (2,)."""
    zref = preview.zmp_reference(plan.zmp, cs.t, cfg.control_dt, cfg.horizon, cfg.step_time, cfg.ds_time)
    # State feedback: pull the LIPM's CoM position and velocity toward the measured ones, so the
    # preview servo plans from where the robot is (an observer-style correction).
    com_vel = (1 - cfg.vel_filter) * cs.com_vel + cfg.vel_filter * (obs.com[:2] - cs.com) / cfg.control_dt
    lipm0 = cs.lipm.at[0].add(cfg.k_pos * (obs.com[:2] - cs.lipm[0]))
    lipm0 = lipm0.at[1].add(cfg.k_vel_state * (com_vel - cs.lipm[1]))
    zlipm = zref - swing_zmp_shift(cfg, plan, cs.t, zref)
    lipm, err_sum, _ = preview.preview_update(pgains, lipm0, cs.err_sum, zlipm)
    # DCM stabiliser: where the measured divergent component of motion runs ahead of the plan's,
    # move the ZMP ahead by k_dcm times the error, realised as an extra CoM acceleration -w^2 dp.
    omega = jnp.sqrt(9.81 / cfg.com_height)
    dcm_err = (obs.com[:2] + com_vel / omega) - (cs.lipm[0] + cs.lipm[1] / omega)
    dacc = -omega**2 * cfg.k_dcm * dcm_err - cfg.dcm_damping * cs.dcm_shift[1] - cfg.dcm_leak * cs.dcm_shift[0]
    dvel = cs.dcm_shift[1] + cfg.control_dt * dacc
    dpos = jnp.clip(cs.dcm_shift[0] + cfg.control_dt * dvel, -cfg.dcm_limit, cfg.dcm_limit)
    shift = jnp.stack([dpos, dvel])
    feet = foot_targets(cfg, plan, cs.t + cfg.control_dt)
    # Ground under the body: the mean of the stance sole and the swing sole's start/end heights.
    s = swing_phase(cfg, cs.t + cfg.control_dt)
    swing_ground = (1 - s) * plan.swing_from[2] + s * plan.swing_to[2]
    ground = 0.5 * (plan.stance[2] + swing_ground)
    yaw_mid = feet[0, 3] + 0.5 * geometry.wrap_angle(feet[1, 3] - feet[0, 3])
    # Stabiliser: move the pelvis by the CoM tracking error (position and velocity).
    com_err = lipm[0] - obs.com[:2]
    vel_err = lipm[1] - obs.pelvis_vel[:2]
    com_cmd = lipm[0] + shift[0] + cfg.k_com * com_err + cfg.k_vel * vel_err
    b = cfg.leg_share
    offset = rot_z(yaw_mid)[:2, 0] * cfg.com_offset
    pelvis_xy = (com_cmd - 0.5 * b * (feet[0, :2] + feet[1, :2]) - offset) / (1.0 - b)
    pelvis_pos = jnp.concatenate([pelvis_xy, (ground + cfg.pelvis_height)[None]])
    roll, pitch, _ = quat_tilt(obs.pelvis_quat)
    # The swing leg solves its IK from the measured pelvis attitude, so the swing sole stays level in the
    # world and lands flat (a tilted torso would otherwise land it on a toe or heel corner).
    q = []
    for row, side in enumerate((1, -1)):
        foot = feet[row]
        swinging = (plan.swing_side == side) & plan.go & (s > 0.0) & (s < 1.0)
        on_ground = ~swinging
        tilt = jnp.where(on_ground, cfg.k_tilt, 0.0)
        sole_rot = rot_z(foot[3]) @ rot_xy(-tilt * roll, -tilt * pitch)
        level = jnp.where(swinging, cfg.swing_level, 0.0)
        prot = rot_z(yaw_mid) @ rot_xy(level * roll, level * pitch)
        qi, _ = kinematics.leg_ik(params, side, pelvis_pos, prot, foot[:3], sole_rot)
        q.append(qi)
    return jnp.concatenate(q), CtrlState(lipm, err_sum, cs.t + cfg.control_dt, obs.com[:2], com_vel, shift), zref[0]
