"""The MJX biped stepped tick by tick: one simulated robot for a live drive, in real time on a GPU.

:func:`ijoy_jax.sim.walker.rollout` runs whole steps of B robots inside one
compiled ``lax.scan``. A person on a joystick needs one robot that advances in
wall-clock time, control tick by control tick, so the decision for the next
step is made while this one executes and the view shows it moving.
:class:`MjxBiped` is the MJX biped with that protocol (the one of
:class:`ijoy_jax.sim.native.NativeBiped`): its step is the scanned walker's
own code, the public functions of :mod:`ijoy_jax.sim.walker`, each compiled
once and called from the host:

* ``begin(foothold, go)``: :func:`~ijoy_jax.sim.walker.begin_step` (the
  selector's foothold rested on the ground, the swing corridor, the step in the
  controller's frame, the dynamics filter warm-started from the last step),
* ``tick()``: :func:`~ijoy_jax.sim.walker.tick`, one control period
  (``cfg.control_dt``): the controller's tick with the measured pelvis, centre of
  mass (the DCM feedback) and ankle wrenches, then its MJX physics steps; it
  returns once the device has run it, so a drive paced to the wall clock sees
  the robot's real progress,
* ``end()``: :func:`~ijoy_jax.sim.walker.end_step`, the robot after the step and
  its :class:`~ijoy_jax.sim.walker.StepLog`.

So this robot and :func:`ijoy_jax.sim.walker.rollout` simulate the same steps for
the same footholds, with the same :class:`~ijoy_jax.sim.physics.Dynamics`
(friction, mass, stiffness, control delay, stance noise, pushes), to float32
rounding: the rollout compiles the same operations into one program, which XLA
fuses and rounds differently, and the contacts amplify that (feet within 1 mm
and 0.01 rad after three steps, tests/test_sim_mjx_biped.py). One robot is
deterministic: the same footholds give the same state, bit for bit, so a
recorded drive replays identically. The programs are compiled once per Sim
setting and terrain kind (2D or 2.5D) in this process and shared by every robot
(:func:`compiled_programs`); :meth:`MjxBiped.warm_up` compiles them before a
drive's clock starts.

Where it runs: on ``device`` (default: JAX's default device, the GPU when JAX
has one). A CPU runs it too, with less headroom than native MuJoCo: a 10 ms
tick takes a good part of its period, more in a drive (beside the decision
thread), so a loaded machine can make ticks late; the drive measures by how
much (``tick_lag_max_s`` in its summary; docs/drive.md has the figures).
:class:`ijoy_jax.sim.native.NativeBiped` (``ijoy drive --robot native``) is
the biped for real time on a CPU.

Units: metres, radians, seconds. Soles are (x, y, z, roll, pitch, yaw),
``R = Rz(yaw) Ry(pitch) Rx(roll)``; feet are planar poses (x, y, yaw), row 0
the left foot.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import control
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.prng import as_key
from ijoy_jax.robots import LEFT, Robot
from ijoy_jax.sim import physics, walker
from ijoy_jax.sim.stepped import SteppedBiped
from ijoy_jax.sim.walker import PLANAR, Sim, StepLog, check_terrain_grid
from ijoy_jax.terrain import Terrain

__all__ = ["MjxBiped", "compiled_programs"]


# One program each, shared by every MjxBiped (the Sim and the World are traced pytree arguments).
_world = jax.jit(walker.make_world)
_init = jax.jit(walker.init_state)
_begin = jax.jit(walker.begin_step)
_tick = jax.jit(walker.tick)
_end = jax.jit(walker.end_step)
_stance = jax.jit(walker.stance_info)
_soles = jax.jit(walker.measured_soles)
_PROGRAMS = (_world, _init, _begin, _tick, _end, _stance, _soles)


def compiled_programs() -> int:
    """How many programs the :class:`MjxBiped` robots of this process hold compiled (an int).

    A new Sim setting (grid, ``params``, ``cfg``) or terrain kind (2D, 2.5D) compiles each of its seven
    functions once; new terrains of that grid and kind, robots, starts, footholds, dynamics and keys reuse
    them (read it before and after to count compiles; :func:`ijoy_jax.jit_cache.compiled_count`).
    """
    return sum(compiled_count(f) for f in _PROGRAMS)


class MjxBiped(SteppedBiped):
    """One simulated biped on MJX, advanced by control ticks from the host (a host object holding device state).

    Args:
      sim: the :class:`~ijoy_jax.sim.walker.Sim` of the terrain's grid (:func:`~ijoy_jax.sim.walker.make_sim`).
      terrain: the ground: one :class:`~ijoy_jax.terrain.Terrain` of ``sim.shape`` cells at ``sim.resolution``
        m (2D obstacles are raised to ``sim.params.obstacle_height``; heights are clipped to the height
        field's range).
      robot: the selector's robot (its footprint fits the plane under each start sole; its step time must be
        the controller's, ``sim.cfg.step_time`` s).
      start: (2, 3) feet (x, y, yaw; m, rad), row 0 left (:func:`ijoy_jax.robots.start_stance`).
      first_swing: +1 if the left foot swings first, -1 the right.
      dynamics: the robot's :class:`~ijoy_jax.sim.physics.Dynamics` (scalar leaves); None:
        :func:`~ijoy_jax.sim.walker.nominal_dynamics`.
      key: PRNG key or int seed of the stance noise and pushes (default 0), as in
        :func:`~ijoy_jax.sim.walker.rollout`.
      device: the ``jax.Device`` it runs on (default: JAX's default device, the GPU when there is one).

    Raises:
      TypeError: ``sim`` is not a Sim or ``terrain`` not a Terrain.
      ValueError: a batch of terrains, a terrain of another grid, a robot of another step time, a start
        that is not finite (2, 3) feet, ``first_swing`` not +1 or -1, a Dynamics value out of bounds, more
        than one key. All before anything is compiled.

    Attributes:
      state: the :class:`~ijoy_jax.sim.walker.SimState` between steps (device arrays; ``state.data.qpos``).
      world: the :class:`~ijoy_jax.sim.walker.World` it steps in (device arrays).
      swing: +1.0 if the left foot swings next.
      fallen: the robot has fallen (the pelvis below ``sim.fall_height`` above its ground, the torso tilted
        beyond ``sim.fall_tilt``, or a diverged state); a fallen robot stands for good.
      time: simulated seconds.

    Example (the first robot of a Sim compiles its programs: about a minute on a 2-core CPU)::

      import numpy as np
      import ijoy_jax as ij
      from ijoy_jax.sim import mjx_biped, walker

      robot = ij.robots.hrp2()
      field = ij.terrain.flat((40, 32), 0.05, has_height=True)
      sim = walker.make_sim(field.shape, field.resolution, robot=robot)
      biped = mjx_biped.MjxBiped(sim, field, robot, ij.robots.start_stance(robot, 0.5, 0.8))
      biped.execute(np.zeros(6), False)            # the first step stands (the walker's warm-up)
      info = biped.stance()
      choice = ij.select_step(field, robot, info.stance, int(info.stance_side), [0.25, 0, 0],
                              swing_from=info.swing_from)
      biped.begin(choice.foothold, True)
      while biped.tick():                          # one 10 ms control period per call
          pass
      log = biped.end()                            # StepLog: log.landed, log.placement_error, log.fallen
    """

    def __init__(self, sim: Sim, terrain: Terrain, robot: Robot, start, first_swing=LEFT, *,
                 dynamics: physics.Dynamics | None = None, key=None, device: jax.Device | None = None):
        if not isinstance(sim, Sim):
            raise TypeError(f"sim must be an ijoy_jax.sim.walker.Sim (walker.make_sim), got {type(sim).__name__}")
        if not isinstance(terrain, Terrain):
            raise TypeError(f"terrain must be an ijoy_jax.terrain.Terrain, got {type(terrain).__name__}")
        grid = tuple(np.shape(terrain.free))
        if len(grid) != 2:
            raise ValueError(f"MjxBiped steps one robot on one terrain: terrain.free must be (nx, ny), got shape "
                             f"{grid} (a batch of terrains is walker.rollout_batch's)")
        check_terrain_grid(sim, terrain)
        walker.check_robot_for_sim(robot, sim.cfg)
        start = np.asarray(start, np.float32)
        if start.shape != (2, 3) or not np.all(np.isfinite(start)):
            raise ValueError(f"start must be finite (2, 3) feet (left, right), got shape {start.shape}")
        try:
            side = float(first_swing)
        except (TypeError, ValueError):
            side = None
        if side not in (1.0, -1.0):
            raise ValueError(f"first_swing must be +1 (left) or -1 (right), got {first_swing!r}")
        if dynamics is not None:
            physics.check(dynamics)
        dyn = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32),
                                     walker.nominal_dynamics(sim) if dynamics is None else dynamics)
        k = as_key(0 if key is None else key)
        if k.shape != ():
            raise ValueError(f"key must be one PRNG key or int seed, got keys of shape {k.shape}")
        self.device = jax.local_devices()[0] if device is None else device
        put = lambda x: jax.device_put(x, self.device)  # noqa: E731
        self.sim, self.cfg, self.robot = put(sim), sim.cfg, robot
        self.terrain = terrain
        self.world = _world(self.sim, put(terrain), dynamics=put(dyn))
        self.state = _init(self.sim, self.world, put(robot), put(start), put(np.float32(side)), put(k))
        # The calls made every tick get what they read: the terrain's model (world.m), not the Sim's two models
        # nor the dynamics filter's. Each mjx.Model argument is flattened in Python on every call (about 0.2 ms
        # on this project's CPU), a tenth of a 10 ms tick for the three left out.
        self._lean_sim = dataclasses.replace(self.sim, mjx_model=None, mjx_free=None)
        self._lean_world = self.world._replace(free=None)
        self.swing = side
        self.fresh = True
        self.fallen = False
        self.time = 0.0
        self._step = None  # the step in progress: [Step, TickState, ticks run]

    # -- the Walker's view --------------------------------------------------------------------------------------

    def soles(self) -> np.ndarray:
        """(2, 6) float32 the measured soles x, y, z, roll, pitch, yaw (m, rad; row 0 left), now (also during
        a step)."""
        if self._step is None:
            return np.asarray(self.state.soles)
        return np.asarray(_soles(self._lean_sim, self._step[1].data))

    def qpos(self) -> np.ndarray:
        """(nq,) float32 the robot's generalised positions now (pelvis position and quaternion, the joints)."""
        data = self.state.data if self._step is None else self._step[1].data
        return np.asarray(data.qpos)

    def stance(self) -> control.StanceInfo:
        """The next decision's stance as the scanned walker gives it (:func:`ijoy_jax.sim.walker.stance_info`):
        the stance and swing feet (3,) measured when the last step ended (as the robot believes them, with its
        stance noise), and the stance side (host arrays)."""
        info = jax.device_get(_stance(self.state))
        return control.StanceInfo(np.asarray(info.stance, np.float32), np.float32(info.stance_side),
                                  np.asarray(info.swing_from, np.float32))

    def future_stance(self) -> control.StanceInfo:
        """The stance of the decision after the step in progress (Algorithm 1's ComputeStanceLocation).

        The foot now swinging lands where it was sent and becomes the stance foot; the foot it leaves
        behind is the next swing foot. Outside a step, or while the robot stands: :meth:`stance`.
        """
        st = self.stance()
        if self._step is None:
            return st
        step = self._step[0]
        if not bool(step.go):
            return st
        target = np.asarray(step.target, np.float32)[PLANAR]
        return control.StanceInfo(target, np.float32(-st.stance_side), st.stance)

    # -- stepping -----------------------------------------------------------------------------------------------

    def begin(self, foothold, go: bool) -> None:
        """Start a step to ``foothold`` (6,) (:attr:`ijoy_jax.select.StepChoice.foothold`: x, y, z, roll,
        pitch, yaw; m, rad), or stand if not ``go``.

        The first step after construction stands whatever ``go`` (the warm-up), and so does a fallen robot
        and one sent a non-finite foothold.
        """
        if self._step is not None:
            raise RuntimeError("a step is in progress: tick() it to its end and call end() first")
        foothold = np.asarray(foothold, np.float32)
        if foothold.shape != (6,):
            raise ValueError(f"foothold must have shape (6,) (x, y, z, roll, pitch, yaw), got {foothold.shape}")
        go = bool(go)
        if not np.all(np.isfinite(foothold)):  # stand, planning towards where the swing foot is
            go, foothold = False, self._swing_sole()
        step, ticks = _begin(self.sim, self.world, self.state, foothold, np.bool_(go))
        self._step = [step, ticks, 0]

    def tick(self) -> bool:
        """One control period: the controller's tick, then its physics steps. True while the step goes on.

        Returns when the device has run the tick (so a real-time drive's clock measures the robot).
        """
        s = self._step
        if s is None:
            raise RuntimeError("no step in progress: call begin() first")
        if s[2] >= self.cfg.ticks_per_step:
            raise RuntimeError("the step has run all its ticks: call end()")
        s[1] = _tick(self._lean_sim, self._lean_world, s[0], s[1], np.int32(s[2]))
        s[1].low.block_until_ready()
        s[2] += 1
        self.time += self.cfg.control_dt
        return s[2] < self.cfg.ticks_per_step

    def end(self) -> StepLog:
        """Finish the step (after its last tick): the robot's new state and what the step did (a
        :class:`~ijoy_jax.sim.walker.StepLog` of host arrays)."""
        s = self._step
        if s is None or s[2] < self.cfg.ticks_per_step:
            raise RuntimeError("the step has not run all its ticks: tick() until it returns False")
        self.state = _end(self.sim, self.world, self.state, s[0], s[1])
        self._step = None
        log = jax.device_get(self.state.last)
        self.swing = float(self.state.swing)
        self.fallen = bool(log.fallen)
        self.fresh = False
        return log

    def warm_up(self) -> None:
        """Compile the step's programs now (a drive calls it before its clock starts, so the first step is not
        late by a compile: about a minute on a 2-core CPU, less with the persistent compilation cache); the
        robot's state is unchanged (one tick runs on a copy)."""
        step, ticks = _begin(self.sim, self.world, self.state, self._swing_sole(), np.bool_(False))
        ticks = _tick(self._lean_sim, self._lean_world, step, ticks, np.int32(0))
        jax.block_until_ready((_end(self.sim, self.world, self.state, step, ticks),
                               _soles(self._lean_sim, ticks.data), _stance(self.state)))

    def _swing_sole(self) -> np.ndarray:
        """(6,) float32 the swing foot's sole as measured when the last step ended."""
        return np.asarray(self.state.soles)[0 if self.swing > 0 else 1]
