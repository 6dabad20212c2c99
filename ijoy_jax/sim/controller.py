"""The walking controller (the paper's Robot Walking Control): a footstep -> joint position targets.

One step of the joystick loop is one :class:`StepPlan`: the stance foot stays,
the swing foot moves from ``swing_from`` to ``swing_to``. Every control tick
(``control_dt``) :func:`control_tick`

1. builds the ZMP reference over the preview horizon from the plan (the next
   step is known one step ahead, the one after is assumed to repeat the
   stride: :func:`plan_step`),
2. advances the LIPM preview controller (Kajita 2003) to get the CoM reference,
3. places the swing foot on its path over the terrain (:mod:`.swing`),
4. places the pelvis so that a fitted CoM model of the whole robot follows
   the LIPM's CoM, and solves both legs' analytic inverse kinematics for the
   actuators' position targets,
5. given the measured pelvis, stabilises: the swing leg compensates the
   body's measured tilt so the foot lands as sent (:func:`stabilize`),
6. and, given the ankles' force/torque sensors, lets each loaded sole yield
   to the ground about its ankle while steering its centre of pressure toward
   the ZMP reference (:func:`comply`, a damping control).

Soles are full poses (x, y, z, roll, pitch, yaw): on uneven ground each
foothold's sole is tilted parallel to the plane under it (the walker fits it,
or takes it from the selector's foothold) and rests on the ground there; the
swing sole turns to that tilt during the transfer and descends parallel to
it, its path gains height in stages as the terrain along it asks
(:func:`ijoy_jax.sim.swing.swing_pose`), and the pelvis moves smoothly from
``pelvis_height`` above the lower sole at lift-off to as high above the lower
sole at touch-down (:func:`pattern`).

A dynamics filter (``filter_passes``, on by default) corrects the ZMP
reference by the multibody ZMP error of the planned motion
(:func:`zmp_correction`), so the pattern is dynamically consistent for the
whole robot, not only for the LIPM. The pattern generator reads no
measurement (only the stabiliser does): the plan lives in its own frame (the
commanded footholds; the walker maps each chosen step into it), so its
targets are continuous across steps, and the actuators get them interpolated
at the physics rate
(:func:`ijoy_jax.sim.walker`). All functions are for one robot and pure; the
MJX rollout vmaps them.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import geometry
from ijoy_jax.sim import bodies, dynamics, kinematics, preview, swing
from ijoy_jax.struct import check_real, check_whole

_INF = math.inf
# WalkConfig's numeric fields: (low, high, low allowed, high allowed). The open ends are divisors (times, the
# swing's lift fraction, the CoM model's 1 - leg_share) or would make a mechanism vanish in a way its field's
# own "0 = off" does not describe.
_POSITIVE = (0.0, _INF, False, False)
_NON_NEGATIVE = (0.0, _INF, True, False)
_RANGES: dict[str, tuple[float, float, bool, bool]] = {
    **dict.fromkeys(("step_time", "control_dt", "preview_time", "com_height", "pelvis_height", "preview_r",
                     "land_decay", "land_delay", "ankle_delay", "ankle_leak", "contact_force", "capture_max"),
                    _POSITIVE),
    **dict.fromkeys(("clearance", "preview_q", "land_gain", "stance_gain", "ankle_damping", "cop_edge",
                     "dcm_gain"), _NON_NEGATIVE),
    "ds_fraction": (0.0, 1.0, True, False),
    "leg_share": (0.0, 1.0, True, False),
    "stance_anchor": (0.0, 1.0, True, True),
    "swing_lift": (0.0, 0.5, False, True),
    "land_ramp": (0.0, 1.0, False, True),
    "descent_drop": (0.0, 1.0, True, True),
    "capture_gain": (0.0, 4.0, True, True),
    "swing_adjust": (0.0, 4.0, True, True),
    "com_offset": (-_INF, _INF, False, False),
}


@dataclasses.dataclass(frozen=True)
class WalkConfig:
    """Static settings of the walking controller (seconds, metres, radians).

    The defaults are the settings that fell least in the closed-loop
    measurements of BENCHMARKS.md (MJX, random commands on flat ground, and
    the paper's scenarios); the figures, and the settings they rank, are
    there.

    Fields::

      step_time: duration of one step; must equal the selector's
        ``robot.step_time`` (the Delta t of p_next).
      ds_fraction: fraction of a step spent in double support, at its start
        (0.1: 80 ms at 0.8 s steps). Longer makes the swing faster and harsher,
        shorter moves the ZMP between the feet too fast.
      control_dt: controller period; physics runs ``control_dt / timestep``
        steps per tick with the targets held.
      preview_time: preview horizon of the LIPM controller.
      com_height: z_c of the LIPM, the CoM's height above the ground.
      pelvis_height: the pelvis origin's height above the ground at that CoM
        (0.65: knees bent 0.85 rad standing). Higher, a wide step combined with
        a long one leaves the legs out of reach: the knee straightens before
        the swing foot is down and the weight moves onto a foot still in the air.
      clearance: the swing sole rises this far above the terrain under its
        swept footprint, as high at each part of the path as that part needs
        (:func:`swing.swing_pose`, with the walker's :func:`swing.corridor_profile`).
      swing_lift: fraction of the swing spent rising (and as much descending)
        before (after) the foot moves horizontally, and on each stage of
        height gained or lost in between (:func:`swing.swing_pose`).
      filter_passes: passes of the dynamics filter (:func:`zmp_correction`)
        run at the start of every step, warm-started from the previous step's;
        0 tracks the LIPM's ZMP uncorrected (the robot then falls within a few
        0.2 m steps: the swing leg moves the real ZMP up to 19 cm off).
      com_offset, leg_share: the CoM model ``com = (1 - b) pelvis + b/2 (sole_l
        + sole_r) + (com_offset, 0)`` in the horizontal plane (b = leg_share),
        fitted to the robot by :func:`ijoy_jax.sim.walker.make_sim`; the pelvis
        is placed so that this CoM follows the LIPM.
      preview_q, preview_r: weights of the preview controller's cost.
      land_gain: the stabiliser's swing-leg feedback (0 = off; :func:`stabilize`):
        the fraction of the measured body attitude and position error the swing
        leg compensates, so the foot lands level where it was sent.
      land_ramp: fraction of the swing over which that feedback fades in (none
        at lift-off, so the targets do not jump).
      land_decay: time constant (s) with which a leg's compensation fades once
        it has touched down and carries the body.
      land_delay: the control delay (s) at which that feedback acts at half
        its gain: with a known delay L between the controller's targets and
        the actuators (``physics.Dynamics.latency``), the compensation is
        scaled by ``1 / (1 + L / land_delay)``, so the loop's gain falls as its
        delay grows (a feedback of gain k through a delay L stays stable while
        k L is bounded). 20 ms keeps the full gain without delay, where it
        walks best, and half of it at 20 ms, where the full gain makes robots
        fall on rough ground (docs/walk_families.md, "Control delay and
        pushes", has the figures).
      capture_gain, capture_max: capture-point stepping (0 = off, which
        compiles the walker without it; ``capture_max`` also bounds
        ``swing_adjust``'s shift): at each step's end the next step is
        moved by ``capture_gain`` times how far the measured capture point
        runs ahead of the LIPM's (:func:`dcm_error`), at most ``capture_max``
        metres, before the selector chooses its foothold on the terrain (the
        walker's ``StanceInfo.balance``): a robot pushed ahead of its plan
        steps further that way.
      swing_adjust: the swing foot's step adjustment (0 = off, which compiles
        the walker without it; :func:`ijoy_jax.sim.walker.swing_shift`): once
        the swing foot has lifted (``ds_time`` plus ``swing_lift`` of the
        swing, before it moves across), its touch-down and the ZMP plan after
        it move by ``swing_adjust`` times the DCM error measured then, at most
        ``capture_max`` metres, and the foot comes down at that point's
        resting height (the dynamics filter's correction stays the one of the
        step as planned). It answers within the step, where ``capture_gain``
        waits for the next decision; the moved foothold is not the selector's
        (no candidate check), so ``StepLog.placement_error`` counts the shift.
      stance_anchor: where the controller measures the pelvis's height from
        (:func:`ijoy_jax.sim.walker.plan_frame_position`), in [0, 1]: 1 from
        the stance sole as measured at the step's start (just after its
        touch-down), carried onto the planned one, so a foot that landed
        lower or higher than planned moves the body's reference with it;
        0 the world's height, which the plan's footholds are in. Between,
        that blend. 1 for this biped: at 0, 1024 robots held forward down
        refined stairs fell 0.55 % against 0.05 % (three and two runs of the
        same maps, one H200); 0 for the G1 (``sim.g1.WALK``), which turning
        in place at 1 landed each foot 1.3 mm higher than the last and fell
        (docs/walk_families.md has the figures).
      stance_gain: the same feedback on the legs that carry the body (0 = the
        offsets only fade), low-passed with ``land_decay``: the soles are held
        partly level against the measured body tilt (foot compliance). Off by
        default: it helped on flat ground but not in the paper's scenarios.
      ankle_damping: the ankles' damping control (N m s / rad; 0 = off;
        :func:`comply`): each loaded foot's ankle pitch and roll targets move at
        ``(measured - wanted ground moment) / ankle_damping`` rad/s, so the
        sole yields to the ground (lands flat on a tilt it was not sent to, an
        early or uneven contact does not tip the robot) while its centre of
        pressure is steered toward the ZMP reference. 150 (the ankles yield
        twice as fast as at 300, the value first measured on slopes) is part
        of the combination that fell least on rough ground
        (docs/benchmarks_history.md, "Walking on uneven ground in MJX", and
        docs/walk_families.md have the figures).
      ankle_delay: the control delay (s) at which that damping control moves
        at half its rate: with a known delay L between the controller's
        targets and the actuators (``physics.Dynamics.latency``) the damping
        is ``ankle_damping * (1 + L / ankle_delay)``. Through the stiff ankle
        actuators (30 000 N m/rad) the loop's rate is about kp / damping =
        200 /s, so one 10 ms tick of delay makes it oscillate: with no delay
        0.4 % of robots fell under Playground-like dynamics on flat ground and
        random commands, with 10 or 20 ms 22 %, most on low friction, where
        the rocking soles slip. 10 ms: half the rate at 10 ms, a third at 20
        (the figures, 1024 robots per row: docs/walk_families.md, "The
        ankles' damping through the control delay").
      ankle_leak: time constant (s) with which those offsets return to zero.
      cop_edge: the wanted centre of pressure stays this far inside the sole's
        edges (m).
      contact_force: ground force (N) above which a foot counts as loaded (its
        compliance acts fully; it fades in from half of it).
      descent_drop: on a step down (the lift-off sole above the stance sole at
        the step's start, the stance sole above the touch-down sole at its
        end) the pelvis goes this fraction of the height difference lower
        than ``pelvis_height`` above the lower sole, so the swing leg reaches
        a foothold two risers down; a standing step keeps the height it
        starts at (0 = off, which compiles the pattern without it;
        :func:`pattern`). Without it held forward descents fall far more
        often; 0.15 rather than more, as a larger drop drives the stance
        ankle past its pitch limit on the highest risers
        (docs/walk_families.md has the figures).
      dcm_gain: the DCM feedback (0 = off; :func:`dcm_error`): the centre of
        pressure the ankles' damping control steers to is the ZMP reference
        plus ``dcm_gain`` times how far the measured capture point runs ahead
        of the LIPM's, so a body that falls ahead of its plan (a foot that
        rocks, a tilted or early contact) pushes harder on the side it falls
        to. On rough ground it cut the falls of held forward walks, alone
        and beside the selector's ``support`` limit (docs/walk_families.md
        and docs/benchmarks_history.md have the figures).

    Every field is checked when a config is made, ``dataclasses.replace``
    included: a value that is not a finite number in its field's range
    (times and the CoM height positive, fractions within [0, 1],
    ``swing_lift`` in (0, 0.5], gains and damping >= 0, ``filter_passes`` a
    whole number >= 0, ``preview_time`` at least ``control_dt``) raises
    ValueError naming the field.
    """

    step_time: float = 0.8
    ds_fraction: float = 0.1
    control_dt: float = 0.01
    preview_time: float = 1.6
    com_height: float = 0.80
    pelvis_height: float = 0.65
    clearance: float = 0.05
    swing_lift: float = 0.2
    filter_passes: int = 1
    com_offset: float = 0.0
    leg_share: float = 0.0
    preview_q: float = 1.0
    preview_r: float = 1e-6
    land_gain: float = 1.0
    land_ramp: float = 0.5
    land_decay: float = 0.1
    land_delay: float = 0.02
    stance_gain: float = 0.0
    ankle_damping: float = 150.0
    ankle_delay: float = 0.01
    ankle_leak: float = 0.5
    cop_edge: float = 0.015
    contact_force: float = 50.0
    dcm_gain: float = 3.0
    descent_drop: float = 0.15
    capture_gain: float = 0.0
    capture_max: float = 0.05
    swing_adjust: float = 0.0
    stance_anchor: float = 1.0

    def __post_init__(self):
        # Every field is checked here, so dataclasses.replace is checked too: the config is static (hashed into
        # the compiled programs), so a NaN or a zero time constant would otherwise reach the physics unflagged.
        for name, (lo, hi, lo_in, hi_in) in _RANGES.items():
            check_real(f"WalkConfig.{name}", getattr(self, name), lo, hi, lo_in=lo_in, hi_in=hi_in)
        check_whole("WalkConfig.filter_passes", self.filter_passes, 0)
        if self.preview_time < self.control_dt:
            raise ValueError(f"WalkConfig.preview_time ({self.preview_time} s) must be at least one control period "
                             f"(control_dt {self.control_dt} s)")

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
    """One step of the footstep queue (world frame; sole poses are x, y, z, roll, pitch, yaw: m and rad, the sole
    frame ``Rz(yaw) Ry(pitch) Rx(roll)``, :func:`ijoy_jax.sim.kinematics.rpy_to_rot`)."""

    zmp: jax.Array  # (4, 2) ZMP waypoints: previous support, this step's, next, the one after (preview.zmp_reference)
    stance: jax.Array  # (6,) stance sole
    swing_from: jax.Array  # (6,) swing sole at lift-off
    swing_to: jax.Array  # (6,) swing sole at touch-down (== swing_from when not walking)
    apex: jax.Array  # () absolute height the swing sole rises to, or (n,) its lowest heights along the path
    swing_side: jax.Array  # () +1 if the left foot swings
    go: jax.Array  # () bool: False = stand on both feet (StopWalking)


class CtrlState(NamedTuple):
    """The controller's memory between ticks."""

    lipm: jax.Array  # (3, 2) CoM [position, velocity, acceleration] x, y
    err_sum: jax.Array  # (2,) integral of the ZMP tracking error
    t: jax.Array  # () seconds since the current step began
    offset: jax.Array  # (12,) the stabiliser's joint-target offsets (rad), left leg then right (:func:`stabilize`)
    ankle: jax.Array  # (2, 2) the ankles' compliance offsets (rad): row 0 left, columns pitch, roll (:func:`comply`)


def init_state(pgains: preview.PreviewGains, com_xy) -> CtrlState:
    """At rest with the CoM at ``com_xy`` (2,) (an equilibrium of the preview servo)."""
    com_xy = jnp.asarray(com_xy, jnp.float32)
    return CtrlState(preview.initial_state(com_xy), preview.rest_err_sum(pgains, com_xy), jnp.zeros((), jnp.float32),
                     jnp.zeros(12, jnp.float32), jnp.zeros((2, 2), jnp.float32))


def gains(cfg: WalkConfig) -> preview.PreviewGains:
    """The preview gains for ``cfg`` (compute once, outside the rollout's scan)."""
    return preview.preview_gains(cfg.com_height, cfg.control_dt, cfg.horizon, q=cfg.preview_q, r=cfg.preview_r)


def plan_step(anchor, stance, swing_from, pose, go, swing_side, corridor_top, clearance) -> StepPlan:
    """The plan of one step.

    Args:
      anchor: (2,) the previous support (where the ZMP is now).
      stance, swing_from: (6,) soles (x, y, z, roll, pitch, yaw).
      pose: (6,) commanded touch-down of the swing sole (x, y, z, roll, pitch, yaw: the sole resting on the
        ground, parallel to its plane).
      go: () bool, False to stand (StopWalking).
      swing_side: () +1 if the left foot swings.
      corridor_top: () highest terrain under the swept footprint (m), or (n,) its profile along the path
        (:func:`ijoy_jax.sim.swing.corridor_profile`): the swing foot then gains height in stages, as the
        path needs it (:func:`ijoy_jax.sim.swing.swing_pose`).
      clearance: () the swing sole's margin above it (m).
    """
    swing_to = jnp.where(go, pose, swing_from)
    stride = swing_to[:2] - swing_from[:2]
    mid = 0.5 * (stance[:2] + swing_from[:2])
    top = jnp.asarray(corridor_top, jnp.float32)
    if top.ndim == 0:
        apex = jnp.maximum(top, jnp.maximum(swing_from[2], swing_to[2])) + clearance
    else:  # the first footprint is the lift-off sole's, the last the touch-down sole's
        apex = top.at[0].max(swing_from[2]).at[-1].max(swing_to[2]) + clearance
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


def adjust_tick(cfg: WalkConfig) -> int:
    """The control tick (0-based, within a step) at whose start ``WalkConfig.swing_adjust`` moves the swing
    foot's touch-down: the end of its lift (``ds_time`` plus ``swing_lift`` of the swing), when it has risen
    and not yet moved across."""
    lift_end = cfg.ds_time + cfg.swing_lift * (cfg.step_time - cfg.ds_time)
    return min(int(round(lift_end / cfg.control_dt)), cfg.ticks_per_step - 1)


def cap_shift(cfg: WalkConfig, shift) -> jax.Array:
    """A balance step's move ``shift`` (2,) m, at most ``capture_max`` long (then along the same direction): the
    bound of capture-point stepping and of the swing foot's step adjustment alike."""
    norm = geometry.safe_norm(shift[0], shift[1])
    return jnp.where(norm > cfg.capture_max, shift * (cfg.capture_max / jnp.maximum(norm, 1e-9)), shift)


def swing_adjustment(cfg: WalkConfig, cs: CtrlState, com) -> jax.Array:
    """(2,) m: how far ``WalkConfig.swing_adjust`` moves the swing foot's touch-down, ``swing_adjust`` times the
    capture point's lead over the LIPM's (:func:`dcm_error`; ``cs`` the state at the period's start, ``com`` the
    measured centre of mass (position (2,), velocity (2,)), m and m/s, in the plan's frame), at most
    ``capture_max`` long (:func:`cap_shift`)."""
    return cap_shift(cfg, cfg.swing_adjust * dcm_error(cfg, (cs.lipm[0], cs.lipm[1]), com))


def shift_plan(cfg: WalkConfig, plan: StepPlan, adjust) -> StepPlan:
    """``plan`` with its touch-down moved by ``adjust`` (3,) = (dx, dy, z) m: by (dx, dy) in the horizontal
    plane, set at height z, the ZMP waypoints on that foot and after it moved alike, and the swing's apex
    kept ``clearance`` above the new touch-down (``WalkConfig.swing_adjust``)."""
    if plan.apex.ndim == 0:
        apex = jnp.maximum(plan.apex, adjust[2] + cfg.clearance)
    else:  # a profile along the path: its last entry is the touch-down's
        apex = plan.apex.at[-1].max(adjust[2] + cfg.clearance)
    return plan._replace(swing_to=plan.swing_to.at[:2].add(adjust[:2]).at[2].set(adjust[2]),
                         zmp=plan.zmp.at[2:].add(adjust[:2]), apex=jnp.where(plan.go, apex, plan.apex))


def swing_phase(cfg: WalkConfig, t) -> jax.Array:
    """0 until the double support ends, 1 at the end of the step."""
    return jnp.clip((t - cfg.ds_time) / (cfg.step_time - cfg.ds_time), 0.0, 1.0)


_XYZ_YAW = np.array([0, 1, 2, 5])  # NumPy: a module constant must not start a JAX backend at import
_GRAVITY = 9.81  # m/s^2, MuJoCo's default


def foot_targets(cfg: WalkConfig, plan: StepPlan, t) -> jax.Array:
    """(2, 6) sole targets x, y, z, roll, pitch, yaw at time t of the step, row 0 left.

    The swing sole follows :func:`ijoy_jax.sim.swing.swing_pose`; its roll and
    pitch turn from lift-off's to touch-down's (quintic) by the end of the
    transfer, so it descends parallel to the ground it lands on.
    """
    s = swing_phase(cfg, t)
    pos, yaw = swing.swing_pose(plan.swing_from[_XYZ_YAW], plan.swing_to[_XYZ_YAW], plan.apex, s,
                                lift=cfg.swing_lift)
    u = swing.smoothstep(s / (1.0 - cfg.swing_lift))
    tilt = (1.0 - u) * plan.swing_from[3:5] + u * plan.swing_to[3:5]
    moving = jnp.concatenate([pos, tilt, yaw[None]])
    moving = jnp.where(plan.go, moving, plan.swing_from)
    left_swings = plan.swing_side > 0
    left = jnp.where(left_swings, moving, plan.stance)
    right = jnp.where(left_swings, plan.stance, moving)
    return jnp.stack([left, right])


def pattern(params, cfg: WalkConfig, pgains: preview.PreviewGains, plan: StepPlan, cs: CtrlState,
            correction=None) -> tuple[jax.Array, CtrlState, jax.Array]:
    """One controller period of the pattern: the whole planned qpos (nq,) at the period's end (the free joint,
    the legs), the new state, and the ZMP reference (2,) at its start.

    ``correction`` (N, 2), when given, is subtracted from the ZMP reference the
    LIPM tracks over the horizon: the dynamics filter's estimate of how far the
    multibody ZMP of this pattern falls from the LIPM's (:func:`zmp_correction`).
    """
    zref = preview.zmp_reference(plan.zmp, cs.t, cfg.control_dt, cfg.horizon, cfg.step_time, cfg.ds_time)
    ztrack = zref if correction is None else zref - correction
    lipm, err_sum, _ = preview.preview_update(pgains, cs.lipm, cs.err_sum, ztrack)
    t = cs.t + cfg.control_dt
    feet = foot_targets(cfg, plan, t)
    # Ground under the body: the lower of the stance sole and the swing sole (the mean would stretch the lower leg
    # straight, its knee singular, once one foot stands 5 cm higher than the other), at lift-off at the step's
    # start and at touch-down at its end, in between a quintic in time: the pelvis starts and stops its vertical
    # motion at rest. (Following the swing sole's height linearly, with a kink where the two soles' heights
    # cross, jerked the body at every riser: on stairs of 7.5-15 cm the stance foot unloaded and rocked, and more
    # robots fell going up and down than with this profile; docs/walk_families.md has the figures.)
    u = swing.smoothstep(t / cfg.step_time)
    ground = ((1 - u) * jnp.minimum(plan.stance[2], plan.swing_from[2])
              + u * jnp.minimum(plan.stance[2], plan.swing_to[2]))
    if cfg.descent_drop:  # static: off, the pattern has no trace of it
        start = _step_down(plan.stance[2], plan.swing_from[2])
        # Standing (no step: the swing side stays, the next step starts with the same two soles in the same
        # roles, in the walker and in next_plan) the pelvis holds its height; with the touch-down term there,
        # each standing step straddling a riser ended 0.15 x the riser lower than the next began, and robots
        # standing at the foot of stairs rocked and fell (docs/walk_families.md has the figures).
        end = jnp.where(plan.go, _step_down(plan.swing_to[2], plan.stance[2]), start)
        ground = ground - cfg.descent_drop * ((1 - u) * start + u * end)
    yaw_mid = feet[0, 5] + 0.5 * geometry.wrap_angle(feet[1, 5] - feet[0, 5])
    # The pelvis that puts the CoM model (1 - b) pelvis + b mean(soles) + offset on the LIPM's CoM.
    b = cfg.leg_share
    offset = kinematics.rot_z(yaw_mid)[:2, 0] * cfg.com_offset
    pelvis_xy = (lipm[0] - 0.5 * b * (feet[0, :2] + feet[1, :2]) - offset) / (1.0 - b)
    pelvis_pos = jnp.concatenate([pelvis_xy, (ground + cfg.pelvis_height)[None]])
    q = legs_ik(params, pelvis_pos, kinematics.rot_z(yaw_mid), feet)
    quat = jnp.stack([jnp.cos(yaw_mid / 2), jnp.zeros_like(yaw_mid), jnp.zeros_like(yaw_mid), jnp.sin(yaw_mid / 2)])
    return jnp.concatenate([pelvis_pos, quat, q]), cs._replace(lipm=lipm, err_sum=err_sum, t=t), zref[0]


def standing_shift(cfg: WalkConfig, feet) -> jax.Array:
    """(2,) m: where the pelvis stands from the soles' midpoint so that the fitted CoM model (``com_offset``,
    ``leg_share``; :func:`pattern`) puts the centre of mass right above that midpoint, for feet (2, 3) (x, y,
    yaw). A robot started there starts where the pattern's first period holds it: started with the pelvis above
    the midpoint instead, a robot whose CoM lies far ahead of its pelvis (the G1's, 3.6 cm) is thrown back by
    the first targets and bounces on its toes."""
    feet = jnp.asarray(feet, jnp.float32)
    yaw = jnp.arctan2(jnp.sum(jnp.sin(feet[:, 2])), jnp.sum(jnp.cos(feet[:, 2])))
    return -kinematics.rot_z(yaw)[:2, 0] * cfg.com_offset / (1.0 - cfg.leg_share)


def _step_down(front, rear) -> jax.Array:
    """How far the body steps down (m, >= 0) between soles at heights ``rear`` and ``front`` (the sole it moves
    onto: the stance sole at a step's start, the touch-down sole at its end). A step's end and the next step's
    start see the same two soles in the same roles, so ``WalkConfig.descent_drop`` keeps the pelvis height
    continuous (a standing step keeps its start's value: its successor starts with the same roles)."""
    return jnp.maximum(rear - front, 0.0)


def legs_ik(params, pelvis_pos, pelvis_rot, feet) -> jax.Array:
    """(12,) joint angles (left leg then right) that put the soles on ``feet`` (2, 6) (x, y, z, roll, pitch, yaw)
    from the pelvis at ``pelvis_pos`` (3,) with orientation ``pelvis_rot`` (3, 3) (the robot's own inverse
    kinematics, :func:`ijoy_jax.sim.bodies.legs_ik`)."""
    return bodies.legs_ik(params, pelvis_pos, pelvis_rot, feet)[0]


def control_tick(params, cfg: WalkConfig, pgains: preview.PreviewGains, plan: StepPlan, cs: CtrlState,
                 correction=None, base=None, wrench=None, com=None, latency=0.0
                 ) -> tuple[jax.Array, CtrlState, jax.Array]:
    """One controller period: the joint targets (nq - 7,) in ``qpos[7:]`` order (the 12 leg joints, left leg
    then right, then the robot's other joints at rest; one actuator each, in that order), the new state, the ZMP
    reference (2,).

    ``base`` = (position (3,), rotation (3, 3)) of the measured pelvis in the
    plan's frame turns the stabiliser on (:func:`stabilize`); ``wrench`` (2, 6),
    the ankles' measured force and torque (foot frame; what the shank exerts on
    the foot, N and N m; row 0 left), turns on the ankles' damping control
    (:func:`comply`); ``com`` = (position (2,), velocity (2,)) of the measured
    centre of mass in the plan's frame (m, m/s) moves the centre of pressure
    that damping control steers to from the ZMP reference by ``dcm_gain`` times
    the divergent component of motion's error (:func:`dcm_error`). Without them
    the targets are the pattern's alone. ``latency`` () (s, traced) is the known
    delay before the actuators receive the targets; it lowers the stabiliser's
    gain (``WalkConfig.land_delay``) and the ankles' damping rate
    (``WalkConfig.ankle_delay``).
    """
    planned_com = cs.lipm[:2]  # the LIPM's CoM position and velocity at the period's start, where com is measured
    qpos, cs, zref = pattern(params, cfg, pgains, plan, cs, correction)
    q = qpos[7:]
    if base is not None and cfg.land_gain != 0:
        legs, cs = stabilize(params, cfg, plan, cs, qpos, base, latency)
        q = q.at[:12].set(legs)
    if wrench is not None and cfg.ankle_damping > 0:
        want = zref if com is None else zref + cfg.dcm_gain * dcm_error(cfg, planned_com, com)
        cs = comply(params, cfg, plan, cs, want, wrench, latency)
        q = q.at[jnp.array([4, 5, 10, 11])].add(cs.ankle.reshape(-1))
    return q, cs, zref


def dcm_error(cfg: WalkConfig, planned, measured) -> jax.Array:
    """(2,) m: how far the measured divergent component of motion (DCM, the capture point ``c + c' / omega``,
    ``omega = sqrt(g / com_height)``) runs ahead of the LIPM's (Takenaka 2009, Englsberger 2015).

    ``planned`` and ``measured`` are (position (2,), velocity (2,)) of the centre of mass (m, m/s) in one
    frame. The DCM is the part of the CoM's motion that diverges unless the ZMP acts on it: ZMP feedback
    ``zmp = zref + k * dcm_error`` with ``k > 1`` makes the error decay (its rate is ``(1 - k) omega``).
    """
    omega = jnp.sqrt(_GRAVITY / cfg.com_height)
    return (measured[0] - planned[0]) + (measured[1] - planned[1]) / omega


def ground_cop(params, wrench) -> tuple[jax.Array, jax.Array]:
    """Each foot's ground force (N, foot frame) and centre of pressure (m, foot frame xy from the sole centre)
    from the ankles' measured wrench (2, 6) (what the shank exerts on the foot). The ground's force is its
    opposite plus the foot's weight (the sole taken as level for that term: 1 - cos 10 deg = 1.5 % of 17 N),
    its moment about the ankle the opposite (the foot's centre of mass taken under the ankle); the foot's
    inertia is neglected. The ankle sensor's point relative to the sole centre is the robot's
    (:func:`ijoy_jax.sim.bodies.foot`). The CoP is 0 on an unloaded foot."""
    mass, (sx, sy, sz) = bodies.foot(params)
    f = -wrench[:, :3] + jnp.array([0.0, 0.0, mass * _GRAVITY], jnp.float32)
    m = -wrench[:, 3:]
    fz = f[:, 2]
    safe = jnp.where(fz > 1.0, fz, 1.0)
    # the moment about the sole centre is the one about the sensor plus (sensor - centre) x force; the sensor's
    # offset is static, and its zero terms (the biped's ankle lies right above the sole centre) are left out
    mx, my = m[:, 0] - sz * f[:, 1], -m[:, 1] - sz * f[:, 0]
    if sy:
        mx = mx + sy * fz
    if sx:
        my = my + sx * fz
    cop = jnp.stack([my / safe, mx / safe], axis=1)
    return f, jnp.where((fz > 1.0)[:, None], cop, 0.0)


def _delay_slowdown(latency, half) -> jax.Array:
    """() the factor ``1 + latency / half`` by which a feedback loop is slowed for a known control delay
    ``latency`` (s, traced): 1 without a delay, 2 at ``half`` s (``WalkConfig.land_delay`` for the stabiliser,
    ``ankle_delay`` for the ankles' damping). A loop of gain k through a delay L stays stable while k L is
    bounded, so the gain falls as the delay grows."""
    return 1.0 + jnp.asarray(latency, jnp.float32) / half


def comply(params, cfg: WalkConfig, plan: StepPlan, cs: CtrlState, zref, wrench, latency=0.0) -> CtrlState:
    """The ankles' damping control (Kajita et al. 2010): the soles yield to the ground about the ankle.

    Each foot's wanted centre of pressure is the point ``zref`` (2,) (the ZMP
    reference, moved by the DCM feedback in :func:`control_tick`) brought into
    the sole (its frame, kept ``cop_edge`` inside the edges); the ankle pitch
    and roll offsets move at ``(measured - wanted) ground moment / damping``
    while the foot carries load (fading in between half and the whole
    ``contact_force``) and leak back with ``ankle_leak``; ``damping`` is
    ``ankle_damping * (1 + latency / ankle_delay)``, slower through a control
    delay, which would otherwise make this stiff loop oscillate. So a sole that
    lands on one edge (a tilt the plan did not expect, an early or uneven
    contact) turns flat onto the ground instead of tipping the robot about
    that edge, and a loaded foot pushes its centre of pressure toward where
    the pattern needs it.

    Args:
      zref: (2,) where the centre of pressure should be at this period (world x, y; m).
      wrench: (2, 6) measured ankle force and torque per foot (see :func:`control_tick`).
      latency: () s, the known delay before the actuators receive the targets (0: none).
    """
    feet = foot_targets(cfg, plan, cs.t)
    f, cop = ground_cop(params, wrench)
    c, s = jnp.cos(feet[:, 5]), jnp.sin(feet[:, 5])
    d = zref[None, :] - feet[:, :2]
    want = jnp.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
    half = jnp.array([0.5 * params.foot_length, 0.5 * params.foot_width], jnp.float32) - cfg.cop_edge
    want = jnp.clip(want, -half, half)
    err = (cop - want) * f[:, 2:3]  # N m: the measured minus the wanted ground moment about the sole's y, x axes
    load = jnp.clip(f[:, 2] / (0.5 * cfg.contact_force) - 1.0, 0.0, 1.0)[:, None]
    # CoP too far forward (+x): lift the toe (pitch -); too far left (+y): lift the left edge (roll +)
    damping = cfg.ankle_damping * _delay_slowdown(latency, cfg.ankle_delay)
    rate = jnp.stack([-err[:, 0], err[:, 1]], axis=1) / damping
    leak = jnp.exp(-cfg.control_dt / cfg.ankle_leak)
    return cs._replace(ankle=leak * cs.ankle + cfg.control_dt * load * rate)


def stabilize(params, cfg: WalkConfig, plan: StepPlan, cs: CtrlState, qpos, base, latency=0.0
              ) -> tuple[jax.Array, CtrlState]:
    """The stabiliser: the swing foot lands level where it was sent, whatever the body's attitude.

    With stiff position-controlled joints the whole robot tips as one body
    about an edge of its stance foot; the swing foot, placed relative to a
    pelvis assumed upright, then lands tilted by the same angle, on its edge,
    and the next step starts from there: robots walking random commands on
    flat ground fell after a body roll that grew step by step, and with this
    feedback about a tenth as many fell (docs/benchmarks_history.md, "The
    stabiliser", has the figures). Here the swing leg's joint targets are
    blended toward the inverse kinematics from the *measured* pelvis pose
    ``base`` = (position (3,), rotation (3, 3)) in the plan's frame, with
    weight ``land_gain`` faded in over the first ``land_ramp`` of the swing
    and scaled by ``1 / (1 + latency / land_delay)`` for a control delay.
    The foot then lands level; once it carries the body (the next step), its
    offset fades with time constant ``land_decay`` (toward ``stance_gain``
    times the same compensation; 0 by default), and the pattern's targets,
    which hold the body upright over a level foot, right the body through
    the ankles and hips.

    Args:
      qpos: (nq,) the pattern's planned configuration at the period's end (:func:`pattern`).
      base: (pos (3,), rot (3, 3)) the measured pelvis, expressed in the plan's frame.
      latency: () s, the known delay before the actuators receive the targets (0: none).

    Returns:
      The 12 leg joint targets (pattern + offsets), and the state with the new offsets.
    """
    pos, rot = base
    feet = foot_targets(cfg, plan, cs.t)
    q_meas = legs_ik(params, pos, rot, feet)
    q_plan = qpos[7:19]
    s = swing_phase(cfg, cs.t)
    delta = (q_meas - q_plan) / _delay_slowdown(latency, cfg.land_delay)
    w = cfg.stance_gain + (cfg.land_gain - cfg.stance_gain) * jnp.clip(s / cfg.land_ramp, 0.0, 1.0)
    swinging = jnp.repeat(jnp.stack([plan.swing_side > 0, plan.swing_side < 0]), 6)
    decay = jnp.exp(-cfg.control_dt / cfg.land_decay)
    carrying = decay * cs.offset + (1 - decay) * cfg.stance_gain * delta
    offset = jnp.where(swinging & plan.go, w * delta, carrying)
    return q_plan + offset, cs._replace(offset=offset)


def next_plan(cfg: WalkConfig, plan: StepPlan) -> StepPlan:
    """The step after ``plan`` as the ZMP plan assumes it: the other foot repeats the stride (or both stand, the
    feet in the same roles, as the walker keeps them: its swing side changes only with a step taken)."""
    stride_yaw = geometry.wrap_angle(plan.swing_to[5] - plan.swing_from[5])
    target = jnp.concatenate([plan.zmp[3], plan.stance[2:5], (plan.stance[5] + stride_yaw)[None]])
    top = jnp.broadcast_to(jnp.max(plan.apex), plan.apex.shape) - cfg.clearance  # one height: no terrain known
    go = plan.go
    return plan_step(plan.stance[:2], jnp.where(go, plan.swing_to, plan.stance),
                     jnp.where(go, plan.stance, plan.swing_to), target, go,
                     jnp.where(go, -plan.swing_side, plan.swing_side), top, cfg.clearance)


def predict(params, cfg: WalkConfig, pgains: preview.PreviewGains, plan: StepPlan, cs: CtrlState, correction,
            length: int) -> tuple[jax.Array, jax.Array]:
    """The pattern of ``length`` periods from ``cs`` (kinematics only): qpos (length, 19), ZMP reference (length, 2).

    ``correction`` (length + N, 2) is indexed by period (row k is subtracted at
    period k's time); the k-th qpos is at the end of period k, the k-th
    reference at its start. After this step the pattern goes on with the
    assumed next step (:func:`next_plan`).
    """
    n = cfg.horizon
    steps = cfg.ticks_per_step
    after = next_plan(cfg, plan)

    def body(cs, k):
        window = jax.lax.dynamic_slice_in_dim(correction, k, n)
        later = k >= steps
        now = jax.tree_util.tree_map(lambda a, b: jnp.where(later, b, a), plan, after)
        cs = cs._replace(t=jnp.where(k == steps, jnp.zeros_like(cs.t), cs.t))
        qpos, cs, zref = pattern(params, cfg, pgains, now, cs, window)
        return cs, (qpos, zref)

    _, (qpos, zref) = jax.lax.scan(body, cs, jnp.arange(length))
    return qpos, zref


def correction_length(cfg: WalkConfig) -> int:
    """Rows of a step's ZMP correction (:func:`zmp_correction`): the step's periods and two horizons."""
    return cfg.ticks_per_step + 2 * cfg.horizon


def filtered_length(cfg: WalkConfig) -> int:
    """Periods the dynamics filter plays and corrects (:func:`zmp_correction`): this step and the assumed next
    one, or the preview horizon after this step where that is shorter."""
    return cfg.ticks_per_step + min(cfg.horizon, cfg.ticks_per_step)


def carry_correction(cfg: WalkConfig, corr) -> jax.Array:
    """The correction a step leaves for the next one: shifted by one step, zeros where it had none."""
    steps = cfg.ticks_per_step
    return jnp.concatenate([corr[steps:], jnp.zeros((steps, 2), corr.dtype)])


def zmp_correction(m_free, params, cfg: WalkConfig, pgains: preview.PreviewGains, plan: StepPlan, cs: CtrlState,
                   passes: int = 1, init=None) -> jax.Array:
    """The dynamics filter (Kajita et al. 2003, as fixed-point passes): ZMP corrections for one step.

    Plays the step's pattern and the assumed next step's (:func:`next_plan`)
    kinematically, measures its multibody ZMP with inverse dynamics
    (:func:`ijoy_jax.sim.dynamics.motion_zmp` on ``m_free``, the model without
    constraints), and adds the error to the correction the LIPM tracks; each
    pass replans with it. Returns (:func:`correction_length`, 2) corrections
    indexed by control period, for :func:`control_tick`'s windows.

    Only the periods of those two steps are measured (:func:`filtered_length`):
    after them the played pattern takes no further step (its feet stay where
    the second put them while the LIPM, previewing a reference that walks on,
    carries the body past them), so the error measured there comes from a
    motion no robot makes. Corrected there too, that tail fed itself through
    :func:`carry_correction` from step to step: on stairs, where each step
    lifts the body by a riser, it grew to metres within a few steps, the
    LIPM's preview read it and the plan itself ran off at the end of a step,
    and refined climbs fell (docs/walk_families.md has the diagnosis and the
    figures).

    ``init`` warm-starts the passes, normally with the previous step's result
    moved on by one step (:func:`carry_correction`). It matters: the first two
    periods cannot be measured (central differences), and a cold start there
    leaves the LIPM a correction that jumps at every step boundary (spikes of
    tens of centimetres in the planned ZMP, measured), where the warm start
    keeps it continuous. One warm pass brings the pattern's multibody ZMP
    close to its reference (docs/benchmarks_history.md, "Closed loop", has
    the figure).
    """
    length = filtered_length(cfg)
    # the support's height: the stance sole's during this step, the landed swing sole's after it
    ground = jnp.where(jnp.arange(length) < cfg.ticks_per_step, plan.stance[2], plan.swing_to[2])
    # windows of predict() reach period length + N = correction_length
    corr = jnp.zeros((correction_length(cfg), 2), jnp.float32) if init is None else jnp.asarray(init, jnp.float32)
    for _ in range(passes):
        qpos, zref = predict(params, cfg, pgains, plan, cs, corr, length)
        zmp, _ = dynamics.motion_zmp(m_free, qpos, cfg.control_dt, ground[1:length - 1])  # ends of periods 1 .. -2
        # qpos[k] is at the end of period k = the start of period k + 1, whose reference is zref[k + 1].
        err = zmp - zref[2:length]
        corr = corr.at[2:length].add(err)
    return corr
