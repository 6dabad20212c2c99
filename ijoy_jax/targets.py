"""The target a decision scores against: the ideal step, the target set F and the ordered lists L_i.

A joystick command asks for the ideal step p_next = p0 + dt * j in the stance foot's frame
(:func:`ideal_step`). The paper quantises it to the nearest f_i of a precomputed lattice F, and its
ordered search walks L_i, the actions sorted by dist to f_i (:class:`Targets`, built once per robot by
:func:`make_targets`); :func:`action_dists` gives every action's dist to the step's target, the same
numbers for every selector so their costs agree. Every selector (:mod:`ijoy_jax.select`), the relaxed
selector of the tuners and the walkers build on these, so they live apart from the search itself.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ijoy_jax.robots import Robot, dist, mirror, side_actions, side_p0, side_sign
from ijoy_jax.struct import pytree_dataclass, static_field


@pytree_dataclass
class Targets:
    """The paper's precomputed target set F and the ordered lists L_i.

    F is a lattice over (dx, dy, dtheta) of the LEFT swing foot (the right
    foot uses the mirror image). Static: ``lo``, ``step``, ``counts`` (tuples
    of 3). Leaves::

      order: (|F|, N) int32, L_i: action indices sorted by (dist to f_i, index).
      dist: (|F|, N) float32, dist(action, f_i) for every pair (same numbers
        in every method, so costs agree bit for bit).
    """

    order: jax.Array
    dist: jax.Array
    lo: tuple = static_field()
    step: tuple = static_field()
    counts: tuple = static_field()

    def points(self) -> jax.Array:
        """(``|F|``, 3) the target footsteps f_i (left swing foot, stance frame)."""
        axes = [
            lo + st * jnp.arange(n, dtype=jnp.float32)
            for lo, st, n in zip(self.lo, self.step, self.counts, strict=True)
        ]
        return jnp.stack(jnp.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)

    def point(self, i) -> jax.Array:
        """(3,) the target footstep f_i of flat index ``i``."""
        k2 = i % self.counts[2]
        k1 = (i // self.counts[2]) % self.counts[1]
        k0 = i // (self.counts[1] * self.counts[2])
        return jnp.stack(
            [lo + st * k.astype(jnp.float32) for lo, st, k in zip(self.lo, self.step, (k0, k1, k2), strict=True)]
        )

    def nearest(self, rel_left: jax.Array) -> jax.Array:
        """Index of the f_i nearest a left-foot target (3,): rounding per axis, clamped to F.

        Per-axis rounding minimises every ``|component|`` of the difference, so it
        minimises dist for any weights.
        """
        idx = []
        for k in range(3):
            i = jnp.round((rel_left[k] - self.lo[k]) / self.step[k])
            idx.append(jnp.clip(i, 0, self.counts[k] - 1).astype(jnp.int32))
        return (idx[0] * self.counts[1] + idx[1]) * self.counts[2] + idx[2]


def make_targets(robot: Robot) -> Targets:
    """Build F and the ordered lists L_i for a robot (traceable: jit/vmap over the robot's leaves).

    F is the lattice ``robot.target_grid`` (static, from
    :func:`ijoy_jax.robots.target_lattice`): the bounding box of S extended by
    one action spacing on each side (commands beyond S's reach map to its
    edge), two points per action spacing along each axis. L_i depends on
    ``robot.actions`` and ``robot.rotation_weight``: rebuild it when they
    change (:func:`select_step` and the rollout build it when not given one).
    """
    lo, step, counts = robot.target_grid
    return _targets_for(robot, lo, step, counts)


def _targets_for(robot: Robot, lo, step, counts) -> Targets:
    shell = Targets(order=jnp.zeros((0, 0), jnp.int32), dist=jnp.zeros((0, 0)), lo=lo, step=step, counts=counts)
    pts = shell.points()
    d = dist(robot.actions[None, :, :], pts[:, None, :], robot.rotation_weight)  # (|F|, N)
    order = jnp.argsort(d, axis=-1, stable=True).astype(jnp.int32)  # ties: lower index first
    return shell.replace(order=order, dist=d.astype(jnp.float32))


def ideal_step(robot: Robot, stance_side, command) -> tuple[jax.Array, jax.Array]:
    """p_next = p0 + step_time * command in the stance frame, and whether the command was finite.

    A command with NaN/inf is replaced by zero (step in place) and flagged.
    """
    command = jnp.asarray(command, jnp.float32)
    ok = jnp.all(jnp.isfinite(command))
    command = jnp.where(ok, command, 0.0)
    swing = -side_sign(stance_side)
    return side_p0(robot, swing) + robot.step_time * command, ok


def action_dists(robot: Robot, stance_side, command, targets: Targets, *, quantize: bool = True):
    """Every action's dist to the step's target, as the selectors score it: ``(dists (N,), target (3,), ok ())``.

    The target is the nearest f_i of F to p_next (``quantize``, the paper's; dists then come from the
    precomputed ``targets.dist``, the same numbers in every method) or p_next itself; it is returned in the
    stance foot's frame, with ``ok`` False when the command had NaN/inf (treated as zero, see
    :func:`ideal_step`). Traceable.

    Example:
      >>> import ijoy_jax as ij
      >>> robot = ij.robots.hrp2()
      >>> d, target, ok = ij.select.action_dists(robot, -1, [0.25, 0.0, 0.0], ij.make_targets(robot))
      >>> d.shape, [round(float(v), 2) for v in target], round(float(d.min()), 6)
      ((496,), [0.2, 0.19, 0.0], 0.0)
    """
    side = side_sign(stance_side)
    swing = -side
    p_next, ok = ideal_step(robot, side, command)
    if quantize:
        fi = targets.nearest(mirror(swing, p_next))  # F is stored for the left foot
        return targets.dist[fi], mirror(swing, targets.point(fi)), ok
    return dist(side_actions(robot, swing), p_next, robot.rotation_weight), p_next, ok
