"""The :class:`Sim`: one biped built for one terrain grid shape, and what it is built of.

:func:`make_sim` builds the host MuJoCo model, its MJX twin, the controller's
nominal model without contacts and the walking controller's settings fitted to
the standing robot, once per grid shape; every terrain of that shape reuses it.
A :class:`Sim` is a pytree whose MJX models are its leaves and whose settings
are static metadata compared by value, so every program that takes one is
compiled once per setting. :func:`check_robot_for_sim` checks that a robot's
step time is the controller's, and :func:`nominal_dynamics` is the robot's
dynamics as built (what a walk without ``dynamics`` simulates).

Implementation module of :mod:`ijoy_jax.sim.walker`, which exports its public names.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from ijoy_jax import terrain as terrain_mod
from ijoy_jax.robots import Robot
from ijoy_jax.sim import bodies, dynamics, physics
from ijoy_jax.sim import model as model_mod
from ijoy_jax.sim.controller import WalkConfig


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

    params: model_mod.BipedParams
    cfg: WalkConfig
    mj_model: mujoco.MjModel
    mjx_model: mjx.Model
    mjx_free: mjx.Model  # the same robot without constraints, for the dynamics filter's inverse dynamics
    index: model_mod.ModelIndex
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
    Sim, _flatten_sim, lambda settings, models: Sim(**settings.fields, **dict(zip(_SIM_MODELS, models, strict=True)))
)


def make_sim(
    shape,
    resolution: float,
    params: model_mod.BipedParams | None = None,
    cfg: WalkConfig | None = None,
    *,
    robot: Robot | None = None,
    model: str | None = None,
) -> Sim:
    """Build the biped and its controller for terrains of ``shape`` (nx, ny) cells of ``resolution`` m.

    ``model`` picks the robot (:data:`ijoy_jax.sim.bodies.MODELS`): ``"biped"`` (the project's HRP-2-like
    biped, the default) or ``"g1"`` (the Unitree G1 of MuJoCo Menagerie; the ``robots`` extra); it sets
    ``params.model`` (when both are given they must agree). ``cfg`` defaults to :class:`WalkConfig` with the
    robot's walking height and step time (:func:`ijoy_jax.sim.bodies.walk_defaults`).
    ``cfg.com_height`` is replaced by the model's own CoM height at the
    standing posture with the pelvis ``cfg.pelvis_height`` above the ground,
    so the LIPM matches the robot. With ``robot`` given, its footprint sizes
    the feet and its step time must equal ``cfg.step_time``.
    """
    shape = (int(shape[0]), int(shape[1]))
    if min(shape) < 2:
        raise ValueError(f"terrain shape must be at least (2, 2) cells, got {shape}")
    if model is not None and model not in bodies.MODELS:
        raise ValueError(f"model must be one of {bodies.MODELS}, got {model!r}")
    if params is None:
        params = model_mod.biped_params(robot, model=model or "biped")
    elif model is not None and params.model != model:
        raise ValueError(f"model {model!r} differs from params.model {params.model!r}")
    cfg = WalkConfig(**bodies.walk_defaults(params)) if cfg is None else cfg
    if robot is not None:
        check_robot_for_sim(robot, cfg)
    timestep = params.timestep
    ratio = cfg.control_dt / timestep
    if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
        raise ValueError(f"control_dt {cfg.control_dt} must be a whole multiple of the physics timestep {timestep}")
    ratio = cfg.step_time / cfg.control_dt
    if abs(ratio - round(ratio)) > 1e-6:
        raise ValueError(f"step_time {cfg.step_time} must be a whole multiple of control_dt {cfg.control_dt}")
    mj_model = bodies.build_model(params, terrain_mod.flat(shape, resolution, has_height=True))
    # The LIPM's z_c and the horizontal CoM model (controller.WalkConfig): fitted on the standing robot.
    data = mujoco.MjData(mj_model)
    idx = model_mod.model_index(mj_model)

    def com_of(shift):
        feet = jnp.asarray([[0.0, half, 0.0], [0.0, -half, 0.0]], jnp.float32)
        qpos = bodies.stand_pose(
            params, feet, jnp.zeros(2), jnp.float32(cfg.pelvis_height), jnp.asarray(shift, jnp.float32)
        )[0]
        data.qpos[:] = np.asarray(qpos)
        mujoco.mj_forward(mj_model, data)
        return data.subtree_com[idx.pelvis].copy()

    half = params.stand_width / 2
    com0, com1 = com_of([0.0, 0.0]), com_of([0.04, 0.0])
    # Pelvis moved by 0.04 m over fixed soles: the CoM moves by (1 - b) 0.04.
    b = float(np.clip(1.0 - (com1[0] - com0[0]) / 0.04, 0.0, 0.9))
    cfg = dataclasses.replace(cfg, com_height=float(com0[2]), com_offset=float(com0[0]), leg_share=b)
    return Sim(
        params,
        cfg,
        mj_model,
        model_mod.put_model(mj_model),
        dynamics.no_contact_model(mj_model),
        idx,
        shape,
        float(resolution),
        fall_height=0.5 * cfg.pelvis_height,
        fall_tilt=0.7,
    )


def check_robot_for_sim(robot: Robot, cfg: WalkConfig) -> None:
    """The selector's step time (p_next = p0 + dt j) must be the walker's (one robot's or a batch's, when concrete)."""
    st = robot.step_time
    if isinstance(st, jax.core.Tracer):
        return
    st = np.asarray(st, np.float64)
    if np.any(np.abs(st - cfg.step_time) > 1e-6):
        shown = float(st) if st.ndim == 0 else st
        raise ValueError(f"robot.step_time {shown} s differs from the walking controller's {cfg.step_time} s")


def nominal_dynamics(sim: Sim) -> physics.Dynamics:
    """The :class:`~ijoy_jax.sim.physics.Dynamics` of the robot as ``sim`` built it (its ``params.friction``,
    :data:`~ijoy_jax.sim.physics.NOMINAL` otherwise): what a rollout without ``dynamics`` simulates."""
    return physics.NOMINAL.replace(friction=float(sim.params.friction))
