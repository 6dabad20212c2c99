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
sole (:func:`ijoy_jax.sim.controller.stabilize`). The robot stands one step before the
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

This module is the walking API's one public face (its ``__all__`` re-exports the parts); the parts are
written in modules of one concept each, beside it: :mod:`.simulator` (:class:`Sim`, :func:`make_sim`),
:mod:`.sensors` (what the robot measures), :mod:`.walk_step` (the step in public parts and its state),
:mod:`.checks` (the rollout's input checks) and :mod:`.metrics` (:func:`summary`). This module holds the Walker
and the jitted rollout programs.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from mujoco import mjx

from ijoy_jax import control
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.prng import as_key
from ijoy_jax.progress import compile_and_call
from ijoy_jax.robots import LEFT, Robot
from ijoy_jax.select_options import SelectOptions, checked
from ijoy_jax.sim import physics
from ijoy_jax.sim.checks import as_flag, check_rollout_inputs, check_terrain_grid, rollout_keys
from ijoy_jax.sim.metrics import summary
from ijoy_jax.sim.sensors import (
    ankle_wrench,
    centre_of_mass,
    measured_soles,
    read_sensors,
    step_start,
    without_sensors,
)
from ijoy_jax.sim.simulator import Sim, check_robot_for_sim, make_sim, nominal_dynamics
from ijoy_jax.sim.walk_step import (
    PLANAR,
    SimState,
    Step,
    StepLog,
    TickState,
    World,
    balance_shift,
    begin_step,
    end_step,
    frame_ticks,
    init_state,
    make_world,
    plan_frame_com,
    plan_frame_position,
    plan_to,
    resting_foothold,
    stance_info,
    swing_shift,
    tick,
)
from ijoy_jax.targets import Targets
from ijoy_jax.terrain import Terrain

__all__ = [
    "PLANAR",
    "Sim",
    "make_sim",
    "check_robot_for_sim",
    "check_terrain_grid",
    "StepLog",
    "SimState",
    "measured_soles",
    "ankle_wrench",
    "centre_of_mass",
    "without_sensors",
    "step_start",
    "read_sensors",
    "frame_ticks",
    "World",
    "make_world",
    "init_state",
    "balance_shift",
    "plan_frame_position",
    "plan_frame_com",
    "resting_foothold",
    "plan_to",
    "stance_info",
    "swing_shift",
    "Step",
    "TickState",
    "begin_step",
    "tick",
    "end_step",
    "mjx_walker",
    "nominal_dynamics",
    "compiled_programs",
    "rollout",
    "rollout_batch",
    "summary",
]


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

    return control.Walker(init, stance_info, execute, lambda s: s.soles[:, PLANAR], lambda s: s.last, warmup=1)


_OPTIONS = ("num_steps", "frames_per_step")


@functools.partial(jax.jit, static_argnames=_OPTIONS)
def _rollout(sim: Sim, terrain: Terrain, robot: Robot, start, commands, first_swing, targets, dynamics, key,
             options: SelectOptions, *, num_steps: int, frames_per_step: int) -> control.Trajectory:
    """The loop of :func:`rollout`, jitted (the Sim's models are traced arguments), its inputs checked by the
    caller; inside a caller's trace it is inlined."""
    # The physics stands on finite heights: a traced NaN height or origin (refused where concrete,
    # check_rollout_inputs) is flagged by the selector on the terrain as given, every decision unsupported, and
    # the robot stands.
    walker = mjx_walker(sim, _finite_terrain(terrain), frames_per_step=frames_per_step, robot=robot,
                        dynamics=dynamics, key=key)
    return control.rollout(terrain, robot, start, commands, num_steps, options, first_swing=first_swing,
                           walker=walker, targets=targets)


def _finite_terrain(terrain: Terrain) -> Terrain:
    """``terrain`` with each non-finite height and origin coordinate replaced by 0 (the physics' stand-in)."""
    return terrain.replace(height=jnp.where(jnp.isfinite(terrain.height), terrain.height, 0.0),
                           origin=jnp.where(jnp.isfinite(terrain.origin), terrain.origin, 0.0))


@functools.partial(jax.jit, static_argnames=_OPTIONS)
def _rollout_batch(sim: Sim, terrains: Terrain, robots: Robot, starts, commands, first_swing, targets, dynamics,
                   keys, options: SelectOptions, *, num_steps: int, frames_per_step: int) -> control.Trajectory:
    """:func:`_rollout` vmapped over terrains, robots, starts, commands, first swings, dynamics and keys, as one
    jitted program (the Sim's models shared)."""

    def one(t, r, s, c, f, d, k):
        return _rollout(sim, t, r, s, c, f, targets, d, k, options, num_steps=num_steps,
                        frames_per_step=frames_per_step)

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


def rollout(sim: Sim, terrain: Terrain, robot: Robot, start, commands, options: SelectOptions | None = None, *,
            num_steps: int, first_swing: int = LEFT, targets: Targets | None = None, frames_per_step: int = 0,
            dynamics: physics.Dynamics | None = None, key=None, progress: bool = False) -> control.Trajectory:
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
      options: each decision's search, a :class:`~ijoy_jax.SelectOptions` (None: its defaults), as in
        :func:`ijoy_jax.rollout` (e.g. ``SelectOptions(refine=True)``: each chosen step refined in continuous
        (dx, dy, dtheta), :mod:`ijoy_jax.refine`).
      first_swing, targets: as in :func:`ijoy_jax.rollout`.
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
    progress = as_flag("progress", progress)
    options = checked(options, robot)
    dynamics = physics.array_leaves(dynamics)  # a list leaf is one array, as for rollout_batch
    check_rollout_inputs(sim, terrain, robot, start, commands, num_steps=num_steps, first_swing=first_swing,
                         frames_per_step=frames_per_step, batch=None, dynamics=dynamics)
    dyn = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32),
                                 nominal_dynamics(sim) if dynamics is None else dynamics)
    args = (sim, terrain, robot, start, commands, first_swing, targets, dyn, rollout_keys(key, None), options)
    static = dict(num_steps=int(num_steps), frames_per_step=int(frames_per_step))
    return _run(_rollout, args, static, progress=progress, batch=None)


def rollout_batch(sim: Sim, terrains: Terrain, robots: Robot, starts, commands,
                  options: SelectOptions | None = None, *, num_steps: int, first_swing=LEFT,
                  targets: Targets | None = None, frames_per_step: int = 0,
                  dynamics: physics.Dynamics | None = None, key=None, progress: bool = False) -> control.Trajectory:
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
      options, targets, frames_per_step, progress: as in :func:`rollout` (one ``options`` for all B).

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
    progress = as_flag("progress", progress)
    b = np.shape(terrains.free)[0] if np.ndim(terrains.free) == 3 else None
    if b is None:
        raise ValueError(f"terrains must have a leading batch axis, got a grid of shape {np.shape(terrains.free)}")
    options = checked(options, robots)
    dynamics = physics.array_leaves(dynamics)  # [1.0, 1.1] or [traced, 0.5]: one (B,) leaf, not B leaves
    check_rollout_inputs(sim, terrains, robots, starts, commands, num_steps=num_steps, first_swing=first_swing,
                         frames_per_step=frames_per_step, batch=b, dynamics=dynamics)
    first = jnp.broadcast_to(jnp.asarray(first_swing, jnp.float32), (b,))
    dyn = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(jnp.asarray(x, jnp.float32), (b,)),
                                 nominal_dynamics(sim) if dynamics is None else dynamics)
    args = (sim, terrains, robots, starts, commands, first, targets, dyn, rollout_keys(key, b), options)
    static = dict(num_steps=int(num_steps), frames_per_step=int(frames_per_step))
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
