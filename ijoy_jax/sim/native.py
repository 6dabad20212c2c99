"""The biped on native MuJoCo, stepped by the JAX walking controller tick by tick: a robot for real time on a CPU.

:func:`ijoy_jax.sim.walker.mjx_walker` runs whole steps inside one compiled
``lax.scan`` (the batched, GPU path). A person on a joystick needs one robot
that advances in wall-clock time, tick by tick, so the decision for the next
step can be made while this one executes, and the view can show it moving:
:class:`NativeBiped` is that robot. Its physics is native MuJoCo
(``mujoco.mj_step``, far faster than MJX on a CPU for one robot: docs/drive.md), and
its controller the same functions as the MJX walker's
(:func:`ijoy_jax.sim.controller.control_tick`, :func:`~ijoy_jax.sim.controller.plan_step`,
the dynamics filter :func:`~ijoy_jax.sim.controller.zmp_correction`), compiled
once per :class:`~ijoy_jax.sim.walker.Sim` (:func:`programs`) and shared by
every robot built from it:

* ``begin(foothold, go)`` plans the step (the selector's foothold rested on the
  ground, the swing corridor, the dynamics filter warm-started from the last
  step: one compiled call each),
* ``tick()`` runs one control period (``cfg.control_dt``): one compiled
  controller tick, then its physics steps with the targets interpolated from
  the last tick's (a servo's first-order hold), and
* ``end()`` reports the step (:class:`ijoy_jax.sim.walker.StepLog`).

``execute(foothold, go)`` is the three at once: the
:class:`ijoy_jax.control.Walker` contract (``stance``, ``execute``, ``feet``),
on host arrays. As in the MJX walker the plan lives in the controller's own
frame (the chosen step relative to the measured stance sole, applied to the
commanded one), the stabiliser gets the measured pelvis and the ankles'
damping control the ankle force/torque sensors, and the first ``execute``
after construction stands one step (the walker's warm-up) while the preview
sees the first step coming.

Units: metres, radians, seconds. Soles are (x, y, z, roll, pitch, yaw),
``R = Rz(yaw) Ry(pitch) Rx(roll)``; feet are planar poses (x, y, yaw), row 0
the left foot.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from ijoy_jax import control, geometry, select
from ijoy_jax.robots import LEFT, Robot
from ijoy_jax.sim import bodies, controller, hfield, kinematics
from ijoy_jax.sim.stepped import SteppedBiped
from ijoy_jax.sim.walker import (
    PLANAR,
    Sim,
    StepLog,
    ankle_wrench,
    centre_of_mass,
    check_robot_for_sim,
    plan_frame_com,
    plan_frame_position,
    plan_to,
    resting_foothold,
    swing_shift,
)
from ijoy_jax.terrain import Terrain

__all__ = ["NativeBiped", "Programs", "programs"]



class Programs:
    """The compiled controller functions of one :class:`~ijoy_jax.sim.walker.Sim` (:func:`programs`).

    Attributes:
      tick: ``(plan, ctrl state, correction window, base, wrench) -> (12 joint targets, ctrl state, zmp ref)``:
        :func:`ijoy_jax.sim.controller.control_tick` with the Sim's parameters.
      filter: ``(plan, ctrl state, previous correction) -> correction``: the dynamics filter, warm-started.
      plan: ``(phys terrain, planned (2, 6), soles (2, 6), swing, anchor, foothold (6,), go, fresh)
        -> (StepPlan, target (6,))``: a step's plan, the MJX walker's own (:func:`ijoy_jax.sim.walker.plan_to`,
        without stance noise).
      start: ``(phys terrain, robot, start (2, 3)) -> (2, 6)``: the start feet's soles resting on the ground.
      adjust: ``(phys terrain, StepPlan, target (6,), to_plan (3, 3), ctrl state, com) -> StepPlan``: the plan
        with the swing foot's step adjustment made (``WalkConfig.swing_adjust``, as the MJX walker's
        :func:`~ijoy_jax.sim.walker.tick` makes it at :func:`~ijoy_jax.sim.controller.adjust_tick`); None while
        it is off.
    """

    def __init__(self, sim: Sim):
        params, cfg = sim.params, sim.cfg
        pg = controller.gains(cfg)

        def plan(phys, planned, soles, swing_side, anchor, foothold, go, fresh):
            return plan_to(sim, phys, soles, planned, swing_side, anchor, foothold, go & ~fresh, fresh)

        def start(phys, robot, feet):
            return jax.vmap(lambda f: resting_foothold(sim, phys, select.foothold(phys, robot, f)))(
                jnp.asarray(feet, jnp.float32))

        self.tick = jax.jit(lambda p, cs, window, base, wrench, com: controller.control_tick(
            params, cfg, pg, p, cs, window, base, wrench, com))
        self.filter = jax.jit(lambda p, cs, corr: controller.zmp_correction(
            sim.mjx_free, params, cfg, pg, p, cs, cfg.filter_passes, init=controller.carry_correction(cfg, corr)))
        self.plan = jax.jit(plan)
        self.start = jax.jit(start)
        self.adjust = None if not cfg.swing_adjust else jax.jit(
            lambda phys, p, target, to_plan, cs, com: controller.shift_plan(
                cfg, p, swing_shift(sim, phys, p, target, to_plan, cs, com)))
        self.gains = pg


@functools.lru_cache(maxsize=8)
def programs(sim: Sim) -> Programs:
    """The compiled controller tick, dynamics filter and step planner of ``sim``, built once per Sim (cached).

    Every :class:`NativeBiped` of one Sim shares them: the first robot compiles (about a minute on a
    2-core CPU, less with the persistent compilation cache), the next ones compile nothing.
    """
    return Programs(sim)


def _physical(sim: Sim, terrain: Terrain) -> Terrain:
    """The terrain as the robot meets it (2D obstacles raised, heights clipped to the height field's range)."""
    p = sim.params
    h = np.clip(np.asarray(hfield.physical_heights(terrain, p.obstacle_height)), p.z_lo, p.z_hi)
    return terrain.replace(height=jnp.asarray(h, jnp.float32), has_height=True)


class NativeBiped(SteppedBiped):
    """One simulated biped on native MuJoCo, advanced by control ticks (a host object, not a pytree).

    Args:
      sim: a :class:`~ijoy_jax.sim.walker.Sim` (:func:`~ijoy_jax.sim.walker.make_sim`): the robot, its
        controller settings and the compiled programs' key. Its grid need not match ``terrain``'s: the
        native model is built for ``terrain`` itself.
      terrain: the ground (2D obstacles are raised to ``sim.params.obstacle_height``).
      robot: the selector's robot (its footprint fits the plane under each sole; its step time must be the
        controller's).
      start: (2, 3) feet (x, y, yaw), row 0 left (:func:`ijoy_jax.robots.start_stance`).
      first_swing: +1 if the left foot swings first.

    Attributes:
      m, d: the ``mujoco.MjModel`` and ``mujoco.MjData`` (read them, e.g. ``d.qpos`` to draw the robot;
        ``d.xfrc_applied`` pushes it).
      swing: +1 if the left foot swings next.
      fallen: the robot has fallen (the pelvis below ``sim.fall_height`` above its ground, the torso tilted
        beyond ``sim.fall_tilt``, or a diverged state); a fallen robot stands for good.
      time: simulated seconds.

    Example:
      >>> import ijoy_jax as ij
      >>> from ijoy_jax.sim import native, walker
      >>> robot = ij.robots.hrp2()
      >>> field = ij.terrain.flat((60, 40), 0.04, has_height=True)
      >>> sim = walker.make_sim(field.shape, field.resolution, robot=robot)
      >>> biped = native.NativeBiped(sim, field, robot, ij.robots.start_stance(robot, 0.6, 0.8))
      >>> # biped.execute(ij.select_step(field, robot, *biped.stance()[:2], [0.2, 0, 0]).foothold, True)
    """

    def __init__(self, sim: Sim, terrain: Terrain, robot: Robot, start, first_swing=LEFT):
        check_robot_for_sim(robot, sim.cfg)
        start = np.asarray(start, np.float32)
        if start.shape != (2, 3) or not np.all(np.isfinite(start)):
            raise ValueError(f"start must be finite (2, 3) feet (left, right), got shape {start.shape}")
        if float(first_swing) not in (1.0, -1.0):
            raise ValueError(f"first_swing must be +1 (left) or -1 (right), got {first_swing!r}")
        self.sim, self.cfg, self.params, self.robot = sim, sim.cfg, sim.params, robot
        self.programs = programs(sim)
        self.terrain = terrain
        self.phys = _physical(sim, terrain)
        self.m = bodies.build_model(self.params, terrain)
        self.d = mujoco.MjData(self.m)
        planned = np.array(self.programs.start(self.phys, robot, start), np.float32)  # a writable copy
        pelvis_z = planned[:, 2].min() + self.cfg.pelvis_height
        qpos = bodies.stand_pose(self.params, jnp.asarray(start), jnp.asarray(planned[:, 2]), jnp.float32(pelvis_z),
                                 controller.standing_shift(self.cfg, start), tilt=jnp.asarray(planned[:, 3:5]))[0]
        self.d.qpos[:] = np.asarray(qpos)
        self.d.ctrl[:] = self.d.qpos[7:]
        mujoco.mj_forward(self.m, self.d)
        self.planned = planned
        self.swing = float(first_swing)
        self.anchor = 0.5 * (planned[0, :2] + planned[1, :2])
        self.cs = controller.init_state(self.programs.gains, self.d.subtree_com[sim.index.pelvis][:2].copy())
        self.corr = np.zeros((controller.correction_length(self.cfg), 2), np.float32)  # host: sliced per tick
        self.fresh = True
        self.fallen = False
        self.time = 0.0
        self._step = None  # the step in progress: plan, target, go, tick index, measured stance, extremes
        robot_geoms = np.concatenate([sim.index.sole_geoms.ravel(), np.atleast_1d(sim.index.shin_geom)])
        self._robot_geoms = robot_geoms.astype(int)

    # -- the Walker's view --------------------------------------------------------------------------------------

    def soles(self) -> np.ndarray:
        """(2, 6) float32 the measured soles x, y, z, roll, pitch, yaw (row 0 left)."""
        idx = self.sim.index
        pos = self.d.site_xpos[idx.sole_site]
        mat = self.d.site_xmat[idx.sole_site].reshape(2, 3, 3)
        rpy = np.stack([np.arctan2(mat[:, 2, 1], mat[:, 2, 2]),
                        np.arctan2(-mat[:, 2, 0], np.hypot(mat[:, 2, 1], mat[:, 2, 2])),
                        np.arctan2(mat[:, 1, 0], mat[:, 0, 0])], 1)
        return np.concatenate([pos, rpy], 1).astype(np.float32)

    def stance(self) -> control.StanceInfo:
        """The next decision's stance (ComputeStanceLocation): the measured stance foot, its side, the swing foot.

        Between steps (the robot stands on both feet) this is where the robot will stand when the next step
        starts. During a step the future stance is the foot now swinging, where it was sent
        (:meth:`future_stance`).
        """
        feet = self.feet()
        st, sw = (feet[1], feet[0]) if self.swing > 0 else (feet[0], feet[1])
        return control.StanceInfo(st, np.float32(-self.swing), sw)

    def future_stance(self) -> control.StanceInfo:
        """The stance of the decision after the step in progress (Algorithm 1's ComputeStanceLocation).

        The foot now swinging lands where it was sent and becomes the stance foot; the foot it leaves
        behind is the next swing foot. Outside a step: :meth:`stance`.
        """
        if self._step is None:
            return self.stance()
        st = self.stance()
        if not self._step["go"]:
            return st
        target = self._step["target"][PLANAR]
        return control.StanceInfo(target.astype(np.float32), np.float32(-st.stance_side), st.stance)

    # -- stepping -----------------------------------------------------------------------------------------------

    def begin(self, foothold, go: bool) -> None:
        """Start a step to ``foothold`` (6,) (:attr:`ijoy_jax.select.StepChoice.foothold`), or stand if not ``go``.

        Plans the step in the controller's frame and runs the dynamics filter (warm-started from the last
        step). The first step after construction stands whatever ``go`` (the warm-up). A fallen robot stands.
        """
        if self._step is not None:
            raise RuntimeError("a step is in progress: tick() it to its end and call end() first")
        foothold = np.asarray(foothold, np.float32)
        if foothold.shape != (6,):
            raise ValueError(f"foothold must have shape (6,) (x, y, z, roll, pitch, yaw), got {foothold.shape}")
        go = bool(go) and not self.fallen and not self.fresh and bool(np.all(np.isfinite(foothold)))
        soles = self.soles()
        p = self.programs
        plan, target = p.plan(self.phys, self.planned, soles, np.float32(self.swing), self.anchor,
                              foothold, go, self.fresh)
        self.cs = self.cs._replace(t=jnp.zeros((), jnp.float32))
        if self.cfg.filter_passes:  # the warm-up step stands unfiltered (ijoy_jax.sim.walker.begin_step)
            corr = np.asarray(p.filter(plan, self.cs, self.corr))
            self.corr = np.zeros_like(corr) if self.fresh else corr
        st = soles[1] if self.swing > 0 else soles[0]
        pst = np.asarray(plan.stance)
        self._step = dict(plan=plan, target=np.asarray(target), go=go, k=0, st=st, pst=pst,
                          to_plan=np.asarray(kinematics.rot_z(jnp.float32(pst[5] - st[5]))),
                          ground=min(float(plan.stance[2]), float(plan.swing_to[2])),
                          low=np.inf, tilt=0.0, touched=False)

    def tick(self) -> bool:
        """One control period: the controller's tick, then its physics steps. True while the step goes on."""
        s = self._step
        if s is None:
            raise RuntimeError("no step in progress: call begin() first")
        d, idx, n = self.d, self.sim.index, self.cfg.horizon
        base = (plan_frame_position(d.qpos[:3], s["st"], s["pst"], s["to_plan"], self.cfg.stance_anchor),
                s["to_plan"] @ d.xmat[idx.pelvis].reshape(3, 3))
        base = tuple(np.asarray(b, np.float32) for b in base)
        wrench = np.asarray(ankle_wrench(self.sim, d), np.float32)
        com = tuple(np.asarray(x, np.float32) for x in plan_frame_com(self.sim, d, s["st"], s["pst"], s["to_plan"]))
        window = self.corr[s["k"]:s["k"] + n] if self.cfg.filter_passes else None
        if self.programs.adjust is not None and s["k"] == controller.adjust_tick(self.cfg):
            s["plan"] = self.programs.adjust(self.phys, s["plan"], s["target"], s["to_plan"], self.cs, com)
        q, self.cs, _ = self.programs.tick(s["plan"], self.cs, window, base, wrench, com)
        q0, q = d.ctrl.copy(), np.asarray(q)
        sub = self.sim.substeps
        for j in range(sub):
            d.ctrl[:] = q0 + (j + 1) / sub * (q - q0)
            mujoco.mj_step(self.m, d)
            s["touched"] |= self._obstacle_contact()
        s["low"] = min(s["low"], float(d.qpos[2]) - s["ground"])
        s["tilt"] = max(s["tilt"], _tilt(d.qpos[3:7]))
        s["k"] += 1
        self.time += self.cfg.control_dt
        return s["k"] < self.cfg.ticks_per_step

    def end(self) -> StepLog:
        """Finish the step (after its last tick): the robot's new state and what the step did."""
        s = self._step
        if s is None or s["k"] < self.cfg.ticks_per_step:
            raise RuntimeError("the step has not run all its ticks: tick() until it returns False")
        self._step = None
        plan, target, go = s["plan"], s["target"], s["go"]
        soles = self.soles()
        row = 0 if self.swing > 0 else 1
        landed = soles[row]
        self.planned[row] = np.asarray(plan.swing_to)
        pst = self.planned[1 - row]
        fallen = (self.fallen or s["low"] < self.sim.fall_height or s["tilt"] > self.sim.fall_tilt
                  or not np.all(np.isfinite(self.d.qpos)))
        self.fallen = bool(fallen)
        err = float(np.hypot(*(landed[:2] - target[:2]))) if go else 0.0
        yaw_err = float(abs(geometry.wrap_angle(landed[5] - target[5]))) if go else 0.0
        normals = [np.asarray(kinematics.rpy_to_rot(jnp.asarray(f[3:6])))[:, 2] for f in (landed, target)]
        tilt_err = float(np.arccos(np.clip(normals[0] @ normals[1], -1.0, 1.0))) if go else 0.0
        self.anchor = pst[:2].copy() if go else 0.5 * (self.planned[0, :2] + self.planned[1, :2])
        if go:
            self.swing = -self.swing
        self.fresh = False
        f32 = np.float32
        return StepLog(landed=landed, placement_error=f32(err), yaw_error=f32(yaw_err), tilt_error=f32(tilt_err),
                       fallen=np.bool_(self.fallen), obstacle_contact=np.bool_(s["touched"]),
                       min_pelvis_height=f32(s["low"]), max_tilt=f32(s["tilt"]),
                       qpos=np.zeros((0, self.m.nq), f32), dynamics_invalid=np.bool_(False))

    def warm_up(self) -> None:
        """Compile the step planner, the dynamics filter and the tick now (a drive calls it before its clock
        starts, so the first step is not late by a compile); the robot's state is unchanged."""
        p, f32 = self.programs, np.float32
        plan, _ = p.plan(self.phys, self.planned, self.soles(), f32(self.swing), self.anchor, np.zeros(6, f32),
                         False, True)
        cs = self.cs._replace(t=jnp.zeros((), jnp.float32))
        corr = np.asarray(p.filter(plan, cs, self.corr)) if self.cfg.filter_passes else self.corr
        window = corr[:self.cfg.horizon] if self.cfg.filter_passes else None
        base = (np.asarray(self.d.qpos[:3], f32), np.asarray(self.d.xmat[self.sim.index.pelvis].reshape(3, 3), f32))
        c, v = centre_of_mass(self.sim, self.d)
        p.tick(plan, cs, window, base, np.asarray(ankle_wrench(self.sim, self.d), f32),
               (np.asarray(c[:2], f32), np.asarray(v[:2], f32)))

    # -- helpers ------------------------------------------------------------------------------------------------

    def _obstacle_contact(self) -> bool:
        """A sole sphere or shin touches the ground inside an obstacle cell (as the MJX walker's check)."""
        d = self.d
        if d.ncon == 0:
            return False
        con = d.contact
        g = np.asarray(con.geom)
        involves = np.isin(g, self._robot_geoms).any(axis=1)
        ground = (g == self.sim.index.hfield_geom).any(axis=1)
        active = (np.asarray(con.dist) < 0) & involves & ground
        if not active.any():
            return False
        t = self.terrain
        normal = np.asarray(con.frame)[:, :3]
        probe = np.asarray(con.pos)[:, :2] - 0.5 * t.resolution * normal[:, :2]
        ij = np.floor((probe - np.asarray(t.origin)) / t.resolution).astype(int)
        free = np.asarray(t.free)
        nx, ny = free.shape
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
        ok = free[np.clip(ij[:, 0], 0, nx - 1), np.clip(ij[:, 1], 0, ny - 1)]
        return bool(np.any(active & (~ok | ~inside)))


def _tilt(quat) -> float:
    """Angle between the torso's z axis and the vertical (rad)."""
    x, y = float(quat[1]), float(quat[2])
    cos = 1 - 2 * (x * x + y * y) / max(float(np.sum(np.square(quat))), 1e-12)
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))
