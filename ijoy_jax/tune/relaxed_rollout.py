"""A relaxed rollout of the joystick control loop, differentiable end to end over tens of steps.

Each step of :func:`ijoy_jax.control.rollout` (Algorithm 1 with the
perfect walker: the same :func:`ijoy_jax.control.loop`, with the relaxed
:class:`~ijoy_jax.control.Selector` of :func:`relaxed_selector` in place of
the exact one) becomes smooth: the relaxed selector
(:func:`ijoy_jax.tune.relax.relaxed_select`, swing-path check included) gives
a Boltzmann distribution over the action set, the foot is put down at a pose
drawn from it by one of three estimators, and the next decision is taken from
there, so a loss on any step reaches every earlier decision.

Estimators (``estimator=``, static):

* ``"expected"`` (default): the foot lands on the expected pose
  ``sum_i p_i step_i``. Deterministic and smooth, so finite differences check
  its gradient and an optimiser sees no noise. Its bias: an average of
  footholds on both sides of an obstacle may itself be an invalid foothold, and
  later decisions are taken from there; it vanishes as tau -> 0 (the mass
  concentrates on the mode, the exact choice as sharpness grows).
* ``"straight_through"``: the foot lands on the most probable action (forward
  pass = the exact rollout's footholds once the mode is the exact choice, at
  any tau), the gradient is that of the expected pose. Biased gradient, but the
  rollout visits only real footholds: use it to evaluate or when a loss must
  see the footholds actually taken.
* ``"gumbel"``: the Gumbel-softmax (concrete) relaxation of a sample of the
  Boltzmann policy, ``softmax(log p + g)``, g ~ Gumbel(0, 1): a stochastic
  policy for risk-averaged objectives (needs ``key``); noisier gradients.

Memory: the scan stores each step's residuals for the backward pass, which for
the relaxed selector are O(N K^2) (N actions, K window cells) per step. With
``remat=True`` the scanned step is wrapped in :func:`jax.checkpoint`, so only
the carry (two foot poses) is stored per step and the step is recomputed on
the way back: memory grows by a few bytes per step instead of the step's
residuals, for about one extra forward pass of compute. :func:`memory_report`
measures it from XLA's compiled memory analysis.

Not modelled: stopping. The exact loop stops when no step is valid; the relaxed
robot always steps (the invalid mass is reported per step instead).

Units: metres, radians, seconds; costs in FootCost units.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ijoy_jax import control, geometry
from ijoy_jax.prng import as_key
from ijoy_jax.robots import LEFT, Robot, side_actions, side_p0
from ijoy_jax.terrain import Terrain
from ijoy_jax.tune import relax

ESTIMATORS = ("expected", "straight_through", "gumbel")
ROTATION_SCALE = 0.1  # m per rad: weighs the rotation error in :func:`command_error`


class RelaxedTrajectory(NamedTuple):
    """One relaxed rollout (T = num_steps; vmapped rollouts add leading axes).

    footsteps: (T, 3) world pose where the swing foot was put down (m, rad).
    sides: (T,) int32, +1 if the left foot swung, -1 the right.
    probs: (T, N) Boltzmann probabilities over the action set.
    expected_pose: (T, 3) world expected pose of each decision.
    mode_pose: (T, 3) world pose of the most probable action.
    mode: (T,) int32 most probable action.
    expected_cost: (T,) expected relaxed cost (cost units).
    target: (T, 3) world pose p_next each decision was scored against.
    error: (T, 3) footstep minus p_next in the stance frame (m, m, rad wrapped).
    deviation: (T,) ``|error_xy|`` (m), zero gradient (not NaN) at 0.
    feet: (2, 3) final foot poses (row 0 left).
    """

    footsteps: jax.Array
    sides: jax.Array
    probs: jax.Array
    expected_pose: jax.Array
    mode_pose: jax.Array
    mode: jax.Array
    expected_cost: jax.Array
    target: jax.Array
    error: jax.Array
    deviation: jax.Array
    feet: jax.Array


def relaxed_rollout(
    terrain: Terrain,
    robot: Robot,
    start,
    commands,
    num_steps: int,
    *,
    sharpness,
    tau,
    barrier_weight=1.0,
    first_swing=LEFT,
    estimator: str = "expected",
    swing_path: bool = True,
    quantize: bool = False,
    remat: bool = True,
    key=None,
) -> RelaxedTrajectory:
    """Walk the relaxed robot for ``num_steps`` decisions (a ``lax.scan``; jit and grad it whole).

    Args:
      terrain: one Terrain (vmap for batches).
      robot: the Robot; every float leaf gets a gradient.
      start: (2, 3) world poses of the feet, row 0 left, row 1 right (m, rad).
      commands: (3,) one command (xdot m/s, ydot m/s, thetadot rad/s, stance
        frame) held throughout, or (num_steps, 3).
      num_steps: number of decisions (static).
      sharpness: () > 0 relaxation sharpness (see :func:`relax.soft_foot_cost_terms`).
      tau: () > 0 Boltzmann temperature (cost units).
      barrier_weight: () barrier scale (cost units).
      first_swing: +1 if the left foot swings first, -1 the right (static int).
      estimator: "expected", "straight_through" or "gumbel" (static; module docstring).
      swing_path: static; relaxed swing-path check on 2.5D terrains.
      quantize: static; score against F's nearest target (piecewise constant in
        the command and step_time) instead of p_next.
      remat: static; wrap the scanned step in :func:`jax.checkpoint`.
      key: PRNG key or int seed, required by "gumbel" only.

    Returns:
      :class:`RelaxedTrajectory`; dtype of the robot's leaves / commands (float32 by default).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax.tune import relaxed_rollout
      >>> t = ij.terrain.flat((60, 40), 0.02)
      >>> robot = ij.robots.hrp2(density=0.25)
      >>> start = np.array([[0.2, 0.495, 0.0], [0.2, 0.305, 0.0]])
      >>> tr = relaxed_rollout.relaxed_rollout(t, robot, start, [0.25, 0.0, 0.0], 3, sharpness=100.0, tau=0.01)
      >>> tr.footsteps.shape, round(float(tr.feet[0, 0]), 2)
      ((3, 3), 0.8)
    """
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
    if estimator == "gumbel" and key is None:
        raise ValueError('estimator="gumbel" needs a PRNG key')
    commands = jnp.asarray(commands)
    dtype = jnp.result_type(commands.dtype, robot.step_time.dtype, jnp.float32)
    commands = commands.astype(dtype)
    if commands.ndim == 1:
        commands = jnp.broadcast_to(commands, (num_steps, 3))
    commands = commands[:num_steps]
    keys = jax.random.split(as_key(key), num_steps) if estimator == "gumbel" else None
    selector = relaxed_selector(terrain, robot, sharpness=sharpness, tau=tau, barrier_weight=barrier_weight,
                                estimator=estimator, swing_path=swing_path, quantize=quantize)
    walker = control.perfect_walker(dtype)
    state, rec = control.loop(walker, selector, jnp.asarray(start, dtype).reshape(2, 3),
                              jnp.asarray(first_swing, dtype), commands, keys=keys, remat=remat)
    return RelaxedTrajectory(feet=walker.feet(state), **rec)


def relaxed_selector(terrain: Terrain, robot: Robot, *, sharpness, tau, barrier_weight=1.0,
                     estimator: str = "expected", swing_path: bool = True, quantize: bool = False) -> control.Selector:
    """The relaxed GetNextStep as a :class:`ijoy_jax.control.Selector`: the Boltzmann distribution of
    :func:`ijoy_jax.tune.relax.relaxed_select` over the action set, the foot put down at the pose the
    ``estimator`` draws from it (always sendable: the relaxed robot never stops), recording the
    :class:`RelaxedTrajectory` fields per step. Arguments as in :func:`relaxed_rollout`; ``"gumbel"`` needs
    the loop's per-step keys.
    """
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")

    def choose(info, command, key):
        choice = relax.relaxed_select(
            terrain, robot, info.stance, info.stance_side, command, sharpness=sharpness, tau=tau,
            barrier_weight=barrier_weight, quantize=quantize, exact=False,
            swing_from=info.swing_from if swing_path else None,
        )
        steps = geometry.compose(info.stance, side_actions(robot, -info.stance_side).astype(info.stance.dtype))
        mode_pose = steps[choice.mode]
        if estimator == "expected":
            pose = choice.expected_pose
        elif estimator == "straight_through":
            pose = choice.expected_pose + jax.lax.stop_gradient(mode_pose - choice.expected_pose)
        else:
            g = jax.random.gumbel(key, choice.log_probs.shape, info.stance.dtype)
            pose = jax.nn.softmax(choice.log_probs + g) @ steps
        zero = jnp.zeros((3,), pose.dtype)
        foothold = jnp.concatenate([pose[:2], zero, pose[2:]])  # a planar sole: x, y, (z, roll, pitch) 0, yaw
        return foothold, jnp.bool_(True), (choice, pose, mode_pose)

    def record(info, command, decision, go, stopped, before, after):
        choice, pose, mode_pose = decision
        swing = -info.stance_side
        p_next = side_p0(robot, swing).astype(pose.dtype) + robot.step_time * command
        err = geometry.relative(info.stance, pose) - p_next
        err = err.at[2].set(geometry.wrap_angle(err[2]))
        return dict(
            footsteps=pose,
            sides=jnp.where(swing > 0, 1, -1).astype(jnp.int32),
            probs=choice.probs,
            expected_pose=choice.expected_pose,
            mode_pose=mode_pose,
            mode=choice.mode,
            expected_cost=choice.expected_cost,
            target=geometry.compose(info.stance, p_next),
            error=err,
            deviation=geometry.safe_norm(err[0], err[1]),
        )

    return control.Selector(choose, record)


relaxed_rollout_jit = jax.jit(
    relaxed_rollout,
    static_argnames=("num_steps", "first_swing", "estimator", "swing_path", "quantize", "remat"),
)
relaxed_rollout_jit.__doc__ = "``jax.jit(relaxed_rollout)`` (num_steps and the switches static)."


def command_error(traj: RelaxedTrajectory, rotation_scale=ROTATION_SCALE) -> jax.Array:
    """() mean squared command-following error (m^2): ``|error_xy|^2 + (rotation_scale * error_theta)^2``.

    Args:
      traj: a :class:`RelaxedTrajectory` (unbatched).
      rotation_scale: metres per radian of rotation error.
    """
    e = traj.error
    return jnp.mean(e[:, 0] ** 2 + e[:, 1] ** 2 + (rotation_scale * e[:, 2]) ** 2)


def tracking_loss(terrain, robot, start, commands, num_steps: int, *, sharpness, tau, remat=True, **kwargs):
    """() a typical rollout loss: :func:`command_error` plus the mean expected cost / 100 (both over all steps).

    ``kwargs`` go to :func:`relaxed_rollout`. Differentiate with respect to the robot (and start, commands).
    """
    tr = relaxed_rollout(
        terrain, robot, start, commands, num_steps, sharpness=sharpness, tau=tau, remat=remat, **kwargs
    )
    return command_error(tr) + 0.01 * jnp.mean(tr.expected_cost)


def grad_memory(terrain, robot, start, commands, num_steps: int, *, remat: bool, sharpness=30.0, tau=0.1,
                **kwargs) -> dict[str, int]:
    """Bytes XLA reserves for ``jit(grad(tracking_loss))`` w.r.t. the robot, from ``memory_analysis()``.

    Compiles (does not run) the gradient. Returns ``{"temp": temp bytes,
    "argument": ..., "output": ...}``: ``temp`` is the working memory that
    grows with the rollout length (the stored residuals).
    """

    def loss(rb):
        return tracking_loss(terrain, rb, start, commands, num_steps, sharpness=sharpness, tau=tau, remat=remat,
                             **kwargs)

    compiled = jax.jit(jax.grad(loss)).lower(robot).compile()
    m = compiled.memory_analysis()
    return {
        "temp": int(m.temp_size_in_bytes),
        "argument": int(m.argument_size_in_bytes),
        "output": int(m.output_size_in_bytes),
    }


def memory_report(terrain, robot, start, commands, lengths=(5, 10, 20, 40), **kwargs) -> dict[bool, dict[int, int]]:
    """Temp bytes of the compiled rollout gradient against rollout length, with and without remat.

    Args:
      terrain, robot, start, commands: as :func:`relaxed_rollout` (commands (3,)).
      lengths: rollout lengths (static; one compilation each, per remat setting).
      kwargs: to :func:`grad_memory` (sharpness, tau, estimator, swing_path, ...).

    Returns:
      ``{remat: {length: temp_bytes}}`` for remat in (False, True).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax.tune import relaxed_rollout
      >>> t = ij.terrain.flat((40, 30), 0.02)
      >>> rb = ij.robots.hrp2(density=0.1)
      >>> r = relaxed_rollout.memory_report(t, rb, np.array([[0.2, 0.395, 0.0], [0.2, 0.205, 0.0]]), [0.2, 0.0, 0.0],
      ...                                   (2, 8))
      >>> r[True][8] - r[True][2] < r[False][8] - r[False][2]
      True
    """
    return {
        remat: {n: grad_memory(terrain, robot, start, commands, n, remat=remat, **kwargs)["temp"] for n in lengths}
        for remat in (False, True)
    }
