"""What a user varies in the simulated robot's physics: the traced :class:`Dynamics` pytree.

The biped's MuJoCo model (:mod:`.model`) is built once per grid shape; everything
a sweep or a domain randomisation varies per robot is a float leaf of a
:class:`Dynamics`, passed beside the terrain, robot, start and command (vmap it
over a batch; a new value never recompiles):

=================  =========  ==========================================================================
field              unit       what it changes
=================  =========  ==========================================================================
``friction``       (ratio)    sliding friction of the ground and of every robot geom that touches it
                              (MuJoCo takes the larger of two geoms' coefficients, so both are set)
``mass_scale``     (factor)   every body's mass and inertia and every joint's rotor inertia (armature):
                              the equations of motion become ``s M(q)`` with gravity's load ``s`` times
``kp_scale``       (factor)   the position actuators' stiffness ``kp`` (their damping ``kv`` stays)
``latency``        s          delay between the controller's joint targets and the actuators, in whole
                              control ticks (``WalkConfig.control_dt``; rounded to the nearest tick)
``stance_noise``   m          std of the error of the stance foot's measured position fed to the
                              selector: each decision sees the robot shifted by a new N(0, s^2) draw
                              per axis, and its step, taken relative to that belief, lands off by it
``push``           N s        an impulse of this size in a random horizontal direction, applied to the
                              whole robot at a random control tick of every step (after the first)
=================  =========  ==========================================================================

The first three are model fields (:func:`put_dynamics` writes them into an
``mjx.Model``; :func:`put_dynamics_batch` batches them the way
``mujoco_playground``'s ``randomize`` does); the last three act in the walker
(:func:`ijoy_jax.sim.walker.mjx_walker`). The walking controller keeps its own
nominal model (its dynamics filter's inverse dynamics), so a heavier or softer
robot is a model mismatch, as on a real robot. :data:`NOMINAL` is the robot as
built (the defaults: friction 1, scales 1, no latency, noise or pushes), the
behaviour of a rollout without dynamics.

Bounds (:data:`BOUNDS`) are checked where values are concrete (:func:`check`:
the rollouts' and the sweep file's boundaries, naming the field); inside jit,
:func:`sanitize` replaces a non-finite or out-of-range value by its nominal one
and flags it (``StepLog.dynamics_invalid``), never a silent NaN. Both compare in
float32, as the walker computes (``float32(0.1)`` s of latency is in bounds). Every
value within the bounds is simulated, the ends included: where the physics
cannot follow (friction below about 0.01 diverges in MJX), the step ends as a
flagged fall with the robot put back to the step's start
(:func:`ijoy_jax.sim.walker.end_step`), never NaN soles or distances.

Example:
  >>> import jax.numpy as jnp
  >>> from ijoy_jax.sim import physics
  >>> d = physics.Dynamics(friction=jnp.array([0.3, 1.0]), mass_scale=jnp.array([1.0, 1.2]))
  >>> round(float(d.friction[0]), 3), float(physics.NOMINAL.kp_scale)
  (0.3, 1.0)
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from ijoy_jax.struct import as_array, is_traced, pytree_dataclass

__all__ = ["BOUNDS", "FIELDS", "MAX_LATENCY", "NOMINAL", "Bound", "Dynamics", "array_leaves", "check", "latency_ticks",
           "max_latency_ticks", "put_dynamics", "put_dynamics_batch", "sanitize"]

MAX_LATENCY = 0.1
"""Largest control delay (s): the walker keeps this many seconds of joint targets (10 ticks of 10 ms)."""


class Bound(NamedTuple):
    """The admissible values of one :class:`Dynamics` field: ``lo <= x <= hi`` (``lo < x`` if ``strict``)."""

    lo: float
    hi: float
    strict: bool
    unit: str
    why: str


BOUNDS = {
    "friction": Bound(0.0, 10.0, False, "", "a sliding friction coefficient; beyond ~2 no contact slips"),
    "mass_scale": Bound(0.0, 10.0, True, "", "a factor on every mass and inertia (0 would leave no robot)"),
    "kp_scale": Bound(0.0, 10.0, True, "", "a factor on the actuators' stiffness (at 2 the stiff joints "
                                           "approach the 2 ms timestep's stability limit)"),
    "latency": Bound(0.0, MAX_LATENCY, False, "s", "the walker keeps MAX_LATENCY s of joint targets"),
    "stance_noise": Bound(0.0, 0.5, False, "m", "a position error's standard deviation (0.5 m: two steps)"),
    "push": Bound(0.0, 200.0, False, "N s", "an impulse (200 N s moves the 58 kg robot at 3.4 m/s)"),
}
"""Every field's bounds, unit and why (the sweep file and the rollouts refuse values outside)."""

FIELDS = tuple(BOUNDS)
"""The :class:`Dynamics` fields in order (the sweep's ``sim.<field>`` keys)."""


@pytree_dataclass
class Dynamics:
    """The physics a user varies per simulated robot (every field a traced float leaf; see the module docstring).

    Fields (scalars for one robot; a leading batch axis for :func:`ijoy_jax.sim.walker.rollout_batch`)::

      friction: ground sliding friction coefficient (1.0).
      mass_scale: factor on every mass, inertia and rotor inertia (1.0).
      kp_scale: factor on the position actuators' stiffness (1.0).
      latency: control delay, s, rounded to control ticks (0.0; at most :data:`MAX_LATENCY`).
      stance_noise: std of the measured stance position's error per axis, m (0.0).
      push: horizontal impulse per step, N s, in a random direction at a random tick (0.0).
    """

    friction: Any = 1.0
    mass_scale: Any = 1.0
    kp_scale: Any = 1.0
    latency: Any = 0.0
    stance_noise: Any = 0.0
    push: Any = 0.0


NOMINAL = Dynamics()
"""The robot as built: what a rollout without ``dynamics`` simulates."""


def _out_of_bounds(name: str, x, xp=jnp):
    """Whether ``x`` is outside field ``name``'s bounds; ``xp=np`` for concrete values, so that the boundary check
    stages nothing into a caller's trace."""
    b = BOUNDS[name]
    low = x <= b.lo if b.strict else x < b.lo
    return ~xp.isfinite(x) | low | (x > b.hi)


def array_leaves(dynamics):
    """``dynamics`` with each list or tuple leaf as one float32 array, anything else as given.

    A list is a pytree node, not a leaf: ``Dynamics(kp_scale=[1.0, 1.1])`` for two rollouts was mapped value by
    value (one list of two broadcast arrays, then a broadcasting error deep in MJX), and ``[f, 0.5]`` with a
    traced ``f`` reached NumPy (TracerArrayConversionError). The rollouts call this before :func:`check`, so a
    list is one leaf of shape (B,), checked and batched as an array is.
    """
    if not isinstance(dynamics, Dynamics):
        return dynamics  # check() names the type
    return dataclasses.replace(dynamics, **{n: as_array(f"dynamics.{n}", getattr(dynamics, n)) for n in FIELDS})


def check(dynamics: Dynamics, batch: int | None = None) -> None:
    """Refuse a concrete :class:`Dynamics` with a value outside :data:`BOUNDS` or a leaf of the wrong shape.

    Args:
      dynamics: one robot's (scalar leaves) or, with ``batch``, B robots' (each leaf () or (B,)).
      batch: B, or None for one robot.

    Raises:
      TypeError: not a :class:`Dynamics`, or a leaf that is not numbers.
      ValueError: a leaf of another shape, or a value outside its bounds, naming the field and its bounds.
      Traced leaves are skipped (their values are sanitized inside jit instead).
    """
    if not isinstance(dynamics, Dynamics):
        raise TypeError(f"dynamics must be an ijoy_jax.sim.physics.Dynamics, got {type(dynamics).__name__}")
    shapes = ((),) if batch is None else ((), (batch,))
    for name in FIELDS:
        value = getattr(dynamics, name)
        if np.shape(value) not in shapes:
            want = "a scalar" if batch is None else f"a scalar or shape ({batch},) (one per rollout)"
            raise ValueError(f"dynamics.{name} must be {want}, got shape {np.shape(value)}")
        if is_traced(value):
            continue
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf" or arr.dtype.kind == "b":
            raise TypeError(f"dynamics.{name} must be numbers, got {value!r}")
        b = BOUNDS[name]
        # in float32, as the walker computes and sanitize() checks: float32(0.1) is 0.1000000015 in float64,
        # and the documented bound itself was refused
        with np.errstate(invalid="ignore", over="ignore"):
            bad = np.asarray(_out_of_bounds(name, arr.astype(np.float32), np))
        if bad.any():
            shown = arr[bad].ravel()[0]
            lo = f"> {b.lo:g}" if b.strict else f">= {b.lo:g}"
            raise ValueError(f"dynamics.{name} must be finite, {lo} and <= {b.hi:g} {b.unit}".rstrip()
                             + f" ({b.why}), got {shown!r}")


def sanitize(dynamics: Dynamics) -> tuple[Dynamics, jax.Array]:
    """``(dynamics, invalid)``: every leaf as float32, a non-finite or out-of-bounds one replaced by its nominal
    value, and ``invalid`` () bool, whether any was (jit- and vmap-safe; for one robot's scalar leaves)."""
    out, invalid = {}, jnp.bool_(False)
    for name in FIELDS:
        x = jnp.asarray(getattr(dynamics, name), jnp.float32)
        bad = _out_of_bounds(name, x)
        out[name] = jnp.where(bad, jnp.float32(getattr(NOMINAL, name)), x)
        invalid = invalid | bad
    return Dynamics(**out), invalid


def latency_ticks(latency, control_dt: float) -> jax.Array:
    """The delay in whole control ticks: ``round(latency / control_dt)``, clipped to ``[0, max_ticks]`` (int32)."""
    return jnp.clip(jnp.round(jnp.asarray(latency, jnp.float32) / control_dt), 0,
                    max_latency_ticks(control_dt)).astype(jnp.int32)


def max_latency_ticks(control_dt: float) -> int:
    """Control ticks of :data:`MAX_LATENCY` (static: the length of the walker's buffer of joint targets)."""
    return int(math.floor(MAX_LATENCY / control_dt + 1e-9))


# The model fields each model-side leaf changes, and how (factor s: multiply; 1 / s: divide).
_MASS_FIELDS = {"body_mass": 1, "body_inertia": 1, "body_subtreemass": 1, "dof_armature": 1, "dof_M0": 1,
                "body_invweight0": -1, "dof_invweight0": -1, "actuator_acc0": -1}


def _model_fields(m, dynamics: Dynamics) -> dict[str, jax.Array]:
    """The ``mjx.Model`` fields :func:`put_dynamics` replaces (one robot's scalar leaves)."""
    s, k = dynamics.mass_scale, dynamics.kp_scale
    out = {}
    for name, power in _MASS_FIELDS.items():
        value = jnp.asarray(getattr(m, name))
        out[name] = (value * s if power > 0 else value / s).astype(value.dtype)
    out["stat"] = m.stat.replace(**{f: (getattr(m.stat, f) * s).astype(getattr(m.stat, f).dtype)
                                   for f in ("meaninertia", "meanmass")})
    touching = np.flatnonzero((np.asarray(m.geom_contype) | np.asarray(m.geom_conaffinity)) != 0)
    out["geom_friction"] = m.geom_friction.at[touching, 0].set(jnp.asarray(dynamics.friction, m.geom_friction.dtype))
    # Position actuators (affine bias): force = kp ctrl - kp q - kv qdot, kp in gainprm[0] and -kp in biasprm[1].
    position = np.flatnonzero(np.asarray(m.actuator_biastype) == int(mujoco.mjtBias.mjBIAS_AFFINE))
    out["actuator_gainprm"] = m.actuator_gainprm.at[position, 0].multiply(k)
    out["actuator_biasprm"] = m.actuator_biasprm.at[position, 1].multiply(k)
    return out


def put_dynamics(m, dynamics: Dynamics):
    """An ``mjx.Model`` with ``dynamics``'s model-side leaves written in (friction, mass_scale, kp_scale).

    What MuJoCo's own compiler gives for that robot: ``geom_friction[:, 0]`` set to ``friction`` on every geom
    that collides (the ground, the soles; shins when they collide); masses, inertias, armatures, ``dof_M0`` and
    the mean mass and inertia (``stat``, which scales the solver's tolerance) times ``mass_scale`` and the
    inverse weights ``body_invweight0``, ``dof_invweight0``, ``actuator_acc0`` divided by it (exactly
    ``mj_setConst``'s values for the scaled robot);
    the affine position actuators' ``kp`` (``gainprm[0]``, ``-biasprm[1]``) times ``kp_scale``. Pure, jit- and
    vmap-able (the latency, stance noise and pushes act in the walker). Leaves of one robot (scalars).

    Example:
      >>> # m2 = put_dynamics(sim.mjx_model, Dynamics(friction=0.4)); m2.geom_friction[:, 0] == 0.4
    """
    return m.replace(**_model_fields(m, dynamics))


def put_dynamics_batch(m, dynamics: Dynamics):
    """B robots' dynamics (leaves with a leading batch axis B) in one ``mjx.Model``.

    Returns:
      ``(model, in_axes)``: the model whose changed fields (:func:`put_dynamics`) have a leading axis B and whose
      other leaves are shared, and the matching ``in_axes`` pytree for ``jax.vmap`` (0 on the batched fields,
      None elsewhere), as ``mujoco_playground``'s ``randomize`` returns.

    Example:
      >>> # mb, axes = put_dynamics_batch(sim.mjx_model, Dynamics(friction=jnp.array([0.3, 1.0])))
      >>> # jax.vmap(mjx.step, in_axes=(axes, 0))(mb, batched_data)
    """
    leaves = {f.name: jnp.asarray(getattr(dynamics, f.name)) for f in dataclasses.fields(Dynamics)}
    b = max((x.shape[0] for x in leaves.values() if x.ndim), default=None)
    if b is None:
        raise ValueError("put_dynamics_batch needs leaves with a leading batch axis; use put_dynamics for one robot")
    batched = Dynamics(**{k: jnp.broadcast_to(v, (b,)) for k, v in leaves.items()})
    fields = jax.vmap(lambda d: _model_fields(m, d))(batched)
    in_axes = jax.tree_util.tree_map(lambda _: None, m).replace(**{k: 0 for k in fields})
    return m.replace(**fields), in_axes
