"""A biped read from its MJCF: what a walking controller needs to know of a robot it did not build.

:func:`describe` reads a compiled ``mujoco.MjModel`` (any MJCF: the project's own biped, MuJoCo Menagerie's
Unitree G1, ...) into a :class:`BipedDescription`: each leg's serial chain from the root body (the pelvis) to
its sole, the sole rectangles, the leg actuators and their gains, the joint limits, the standing posture, the
mass and the centre of mass. The legs are found from two names, the root body and each foot's box geom
(whose bottom face is the sole); every joint between them must be a hinge, six per leg.

:func:`leg_fk` and :func:`leg_ik` are the kinematics of such a chain in pure JAX (jit, vmap, grad; they keep
the dtype of their inputs). The forward kinematics follows MuJoCo's own rule (each body's offset from its
parent, then each of its joints rotating about its anchor, counted from ``qpos0``), so it reproduces
``mj_kinematics`` for any chain. The inverse kinematics is damped least squares on the chain's geometric
Jacobian: it works for any 6-DoF leg, whatever the order and placement of its axes (the G1's hip is
pitch-roll-yaw with offsets between the axes, where no closed form applies), in a fixed number of
iterations, with the joint limits enforced and the remaining pose error returned for the caller to flag.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

__all__ = ["BipedDescription", "LegChain", "LegSolution", "describe", "leg_fk", "leg_ik", "quat_matrix", "spd_solve"]

SIDES = ("left", "right")
LEG_DOF = 6
"""Joints per leg the walking controller drives (hip three, knee, ankle two)."""

IK_ITERATIONS = 16
"""Damped least-squares iterations of :func:`leg_ik`. From the G1's standing seed, of 2000 random reachable
walking targets (the sole up to 0.25 m ahead or behind, 6 cm up or down, 0.35 rad of yaw, 0.15 rad of pitch),
6 iterations reach every one within 0.05 mm and 8 within 0.02 mm, the float32 floor. The rest is for the
targets out of reach (38 % of the 2000), where the iterations creep toward the nearest pose: in one case of 20
the sole ends 14 mm further from it after 8 iterations than after 200, 1.4 mm after 16. 8 iterations changed
how the G1 walks (on an H200, of 4096 on rough ground 66 % fell within 10 random commands, 49 % with 16)."""

IK_DAMPING = 1e-3
"""Damping of :func:`leg_ik` (m): the step is ``J^T (J J^T + d^2 I)^-1 e``; small against a leg's reach, so it
only matters near a singular pose (the straight knee), where it keeps the step bounded."""


IK_MAX_STEP = 0.3
"""Largest joint change of one :func:`leg_ik` iteration (rad): far from the target, where the linearisation is
poor, a full step can throw the leg against its limits and stall there; smaller steps keep it on its way."""


class LegChain(NamedTuple):
    """One leg's serial chain from the root body to the sole, as arrays (a pytree: stack it to vmap over legs or
    robots).

    Fields::

      pre_pos: (6, 3) m and pre_rot: (6, 3, 3): the fixed transform before joint k, in the frame after joint
        k - 1 (the root's frame for k = 0): the offsets of the bodies in between (identity for a joint that
        shares its body with the previous joint).
      anchor: (6, 3) m and axis: (6, 3) unit vectors: joint k's point and axis in its body's frame.
      qpos0: (6,) rad: the joint angle MuJoCo counts from (a joint rotates by ``q - qpos0``).
      sole_pos: (3,) m and sole_rot: (3, 3): the sole frame (the centre of the foot box's bottom face, z up out
        of the sole) in the frame after the last joint.
      lower, upper: (6,) rad: the joint limits (-inf, inf for an unlimited joint).
    """

    pre_pos: Any
    pre_rot: Any
    anchor: Any
    axis: Any
    qpos0: Any
    sole_pos: Any
    sole_rot: Any
    lower: Any
    upper: Any


class LegSolution(NamedTuple):
    """Result of :func:`leg_ik`.

    Fields::

      q: (6,) joint angles (rad), inside the chain's limits.
      position_error: () m, the distance from the reached sole position to the target.
      rotation_error: () rad, the angle between the reached sole orientation and the target.
    """

    q: jax.Array
    position_error: jax.Array
    rotation_error: jax.Array


@dataclasses.dataclass(frozen=True)
class BipedDescription:
    """What the walking stack knows of a biped, read from its model by :func:`describe` (host side, NumPy,
    float64; index 0 is the left leg, 1 the right).

    Fields::

      name: the model's name.
      root: the root body's name (the pelvis: the legs hang from it).
      legs: (left, right) :class:`LegChain`.
      joint_names: per leg, the six joint names from the hip down.
      qpos_adr, dof_adr: (2, 6) int: the leg joints' addresses in ``qpos`` and ``qvel``.
      actuators: (2, 6) int: the position actuator driving each leg joint (-1: none).
      kp: (2, 6) N m/rad and kv: (2, 6) N m s/rad: those actuators' gains (0 where there is none).
      damping: (2, 6) N m s/rad: the joints' own viscous damping.
      torque_limit: (2, 6) N m: the actuators' force range (inf: unlimited).
      sole_size: (2,) m: the sole rectangle, (length along the foot, width).
      stand_qpos: (nq,) the standing posture (the keyframe :func:`describe` was given, else ``qpos0``).
      mass: kg, the whole robot (the root's subtree).
      com: (3,) m, the standing centre of mass in the root's frame.
      stand_height: m, the root's height above the soles' mean height when standing.
      soles: (2, 3) m, the standing sole centres in the root's frame.
    """

    name: str
    root: str
    legs: tuple[LegChain, LegChain]
    joint_names: tuple[tuple[str, ...], tuple[str, ...]]
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    actuators: np.ndarray
    kp: np.ndarray
    kv: np.ndarray
    damping: np.ndarray
    torque_limit: np.ndarray
    sole_size: np.ndarray
    stand_qpos: np.ndarray
    mass: float
    com: np.ndarray
    stand_height: float
    soles: np.ndarray

    @property
    def stand_leg_q(self) -> np.ndarray:
        """(2, 6) rad: the leg joints' angles in the standing posture."""
        return self.stand_qpos[self.qpos_adr]


def quat_matrix(quat) -> np.ndarray:
    """(3, 3) float64 rotation matrix of a MuJoCo quaternion (w, x, y, z), on the host (model reading)."""
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.asarray(quat, np.float64))
    return m.reshape(3, 3)


def _name(m: mujoco.MjModel, obj, i: int) -> str:
    return mujoco.mj_id2name(m, obj, i) or f"#{i}"


def _chain(m: mujoco.MjModel, root: int, geom: int, geom_name: str) -> tuple[LegChain, list[int], np.ndarray]:
    """The chain from body ``root`` to the bottom face of box ``geom``; also its joint ids and the box's size."""
    if m.geom_type[geom] != mujoco.mjtGeom.mjGEOM_BOX:
        raise ValueError(
            f"sole geom {geom_name!r} must be a box (its bottom face is the sole), got geom type "
            f"{mujoco.mjtGeom(m.geom_type[geom]).name}"
        )
    path, b = [], int(m.geom_bodyid[geom])
    while b != root:
        if b == 0:
            raise ValueError(
                f"sole geom {geom_name!r} does not hang from root body {_name(m, mujoco.mjtObj.mjOBJ_BODY, root)!r}"
            )
        path.append(b)
        b = int(m.body_parentid[b])
    path.reverse()
    pre_pos, pre_rot, anchor, axis, joints = [], [], [], [], []
    acc_pos, acc_rot = np.zeros(3), np.eye(3)  # the transform since the last joint
    for b in path:
        acc_pos, acc_rot = acc_pos + acc_rot @ m.body_pos[b], acc_rot @ quat_matrix(m.body_quat[b])
        for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b]):
            if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
                raise ValueError(
                    f"leg joint {_name(m, mujoco.mjtObj.mjOBJ_JOINT, j)!r} (to sole {geom_name!r}) must "
                    f"be a hinge, got {mujoco.mjtJoint(m.jnt_type[j]).name}"
                )
            pre_pos.append(acc_pos)
            pre_rot.append(acc_rot)
            anchor.append(m.jnt_pos[j].copy())
            axis.append(m.jnt_axis[j] / np.linalg.norm(m.jnt_axis[j]))
            joints.append(j)
            acc_pos, acc_rot = np.zeros(3), np.eye(3)
    if len(joints) != LEG_DOF:
        raise ValueError(
            f"the leg to sole {geom_name!r} has {len(joints)} hinge joints; the walking controller "
            f"drives legs of {LEG_DOF}"
        )
    g_rot = quat_matrix(m.geom_quat[geom])
    size = m.geom_size[geom]
    sole_pos = acc_pos + acc_rot @ (m.geom_pos[geom] + g_rot @ np.array([0.0, 0.0, -size[2]]))
    limited = m.jnt_limited[joints].astype(bool)
    lower = np.where(limited, m.jnt_range[joints, 0], -np.inf)
    upper = np.where(limited, m.jnt_range[joints, 1], np.inf)
    qpos0 = m.qpos0[m.jnt_qposadr[joints]]
    chain = LegChain(
        np.array(pre_pos),
        np.array(pre_rot),
        np.array(anchor),
        np.array(axis),
        qpos0,
        sole_pos,
        acc_rot @ g_rot,
        lower,
        upper,
    )
    return chain, joints, size


def _actuators(m: mujoco.MjModel, joints: list[int]) -> tuple[np.ndarray, ...]:
    """Per joint: the position actuator on it (-1: none), its kp, kv and torque limit."""
    ids, kp, kv, limit = np.full(LEG_DOF, -1), np.zeros(LEG_DOF), np.zeros(LEG_DOF), np.full(LEG_DOF, np.inf)
    for a in range(m.nu):
        if m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or int(m.actuator_trnid[a, 0]) not in joints:
            continue
        k = joints.index(int(m.actuator_trnid[a, 0]))
        gain, bias = m.actuator_gainprm[a], m.actuator_biasprm[a]
        if gain[0] <= 0 or not np.isclose(bias[1], -gain[0]):  # not a position servo: kp q* - kp q - kv qdot
            raise ValueError(
                f"actuator {_name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a)!r} on a leg joint must be a "
                f"position actuator (gain kp > 0, bias (0, -kp, -kv)), got gain {gain[0]} and bias "
                f"{tuple(bias[:3])}"
            )
        ids[k], kp[k], kv[k] = a, gain[0], 0.0 - bias[2]
        if m.actuator_forcelimited[a]:
            limit[k] = np.max(np.abs(m.actuator_forcerange[a]))
    return ids, kp, kv, limit


def describe(
    mj_model: mujoco.MjModel,
    *,
    root: str = "pelvis",
    soles: tuple[str, str] = ("left_foot", "right_foot"),
    keyframe: str | None = None,
) -> BipedDescription:
    """Read a biped from its compiled model.

    Args:
      mj_model: the compiled ``mujoco.MjModel`` (e.g. ``mujoco.MjModel.from_xml_path(...)``).
      root: the body the legs hang from (the pelvis; normally the body of the free joint).
      soles: the (left, right) foot box geoms; each box's bottom face is the sole.
      keyframe: the keyframe of the standing posture (None: the model's ``qpos0``).

    Returns:
      :class:`BipedDescription`.

    Raises:
      ValueError: a name the model lacks (listing what it has), a sole that is not a box or does not hang from
        ``root``, a leg that is not six hinges, a leg actuator that is not a position servo.
    """
    root_id = _lookup(mj_model, mujoco.mjtObj.mjOBJ_BODY, root, "root body", mj_model.nbody)
    legs, names, qadr, dadr, acts, kps, kvs, damp, limits, sizes, geoms = [], [], [], [], [], [], [], [], [], [], []
    for side, sole in zip(SIDES, soles, strict=True):
        geom = _lookup(mj_model, mujoco.mjtObj.mjOBJ_GEOM, sole, f"{side} sole geom", mj_model.ngeom)
        geoms.append(geom)
        chain, joints, size = _chain(mj_model, root_id, geom, sole)
        legs.append(chain)
        names.append(tuple(_name(mj_model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints))
        qadr.append(mj_model.jnt_qposadr[joints])
        dadr.append(mj_model.jnt_dofadr[joints])
        ids, kp, kv, limit = _actuators(mj_model, joints)
        acts.append(ids)
        kps.append(kp)
        kvs.append(kv)
        limits.append(limit)
        damp.append(mj_model.dof_damping[mj_model.jnt_dofadr[joints]])
        sizes.append(2.0 * size[:2])
    if not np.allclose(sizes[0], sizes[1]):
        raise ValueError(f"the soles differ in size: {_size_str(sizes[0])} and {_size_str(sizes[1])}")

    d = mujoco.MjData(mj_model)
    if keyframe is not None:
        key = _lookup(mj_model, mujoco.mjtObj.mjOBJ_KEY, keyframe, "keyframe", mj_model.nkey)
        mujoco.mj_resetDataKeyframe(mj_model, d, key)
    mujoco.mj_kinematics(mj_model, d)
    mujoco.mj_comPos(mj_model, d)
    root_pos, root_rot = d.xpos[root_id].copy(), d.xmat[root_id].reshape(3, 3).copy()
    soles_world = [d.geom_xpos[g] - d.geom_xmat[g].reshape(3, 3)[:, 2] * mj_model.geom_size[g, 2] for g in geoms]
    soles_root = np.array([root_rot.T @ (s - root_pos) for s in soles_world])
    com = root_rot.T @ (d.subtree_com[root_id] - root_pos)
    return BipedDescription(
        name=mj_model.names[: mj_model.names.index(b"\0")].decode() if mj_model.names else "",
        root=root,
        legs=tuple(legs),
        joint_names=tuple(names),
        qpos_adr=np.array(qadr),
        dof_adr=np.array(dadr),
        actuators=np.array(acts),
        kp=np.array(kps),
        kv=np.array(kvs),
        damping=np.array(damp),
        torque_limit=np.array(limits),
        sole_size=sizes[0],
        stand_qpos=d.qpos.copy(),
        mass=float(mj_model.body_subtreemass[root_id]),
        com=com,
        stand_height=float(root_pos[2] - np.mean([s[2] for s in soles_world])),
        soles=soles_root,
    )


def _size_str(size) -> str:
    """A sole size for a message."""
    return f"{size[0]:.4g} m x {size[1]:.4g} m"


def _lookup(m: mujoco.MjModel, obj, name: str, what: str, count: int) -> int:
    i = mujoco.mj_name2id(m, obj, name)
    if i < 0:
        have = sorted(n for n in (mujoco.mj_id2name(m, obj, k) for k in range(count)) if n)
        raise ValueError(f"the model has no {what} named {name!r}; it has {have}")
    return i


def _axis_angle(axis, angle):
    """Rodrigues' rotation matrix of ``angle`` about unit ``axis``."""
    x, y, z = axis[0], axis[1], axis[2]
    k = jnp.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]], dtype=angle.dtype)
    return jnp.eye(3, dtype=angle.dtype) + jnp.sin(angle) * k + (1.0 - jnp.cos(angle)) * (k @ k)


def _frames(chain: LegChain, q):
    """Sole pose and each joint's anchor and axis, all in the root's frame (positions m)."""
    dt = jnp.result_type(q, jnp.float32)
    chain = LegChain(*(jnp.asarray(x, dt) for x in chain))
    q = jnp.asarray(q, dt)
    pos, rot = jnp.zeros(3, dt), jnp.eye(3, dtype=dt)
    anchors, axes = [], []
    for k in range(LEG_DOF):
        pos, rot = pos + rot @ chain.pre_pos[k], rot @ chain.pre_rot[k]
        anchor = pos + rot @ chain.anchor[k]
        anchors.append(anchor)
        axes.append(rot @ chain.axis[k])
        rot = rot @ _axis_angle(chain.axis[k], q[k] - chain.qpos0[k])
        pos = anchor - rot @ chain.anchor[k]
    return pos + rot @ chain.sole_pos, rot @ chain.sole_rot, jnp.stack(anchors), jnp.stack(axes)


def leg_fk(chain: LegChain, q) -> tuple[jax.Array, jax.Array]:
    """Pose of the sole frame in the root's frame.

    Args:
      chain: one leg (:attr:`BipedDescription.legs`).
      q: (6,) joint angles, rad (MuJoCo's ``qpos`` of the leg's joints).

    Returns:
      pos: (3,) the sole centre, m; rot: (3, 3) the sole frame's axes (columns), both in the root's frame.
    """
    pos, rot, _, _ = _frames(chain, q)
    return pos, rot


def _rotation_vector(r):
    """The rotation vector (axis times angle, rad) of rotation matrix ``r``, finite and smooth at angle 0."""
    v = 0.5 * jnp.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    s = jnp.sqrt(jnp.sum(v * v) + jnp.finfo(v.dtype).tiny)
    angle = jnp.arctan2(s, 0.5 * (jnp.trace(r) - 1.0))
    return v * jnp.where(s > 1e-6, angle / s, 1.0)


def spd_solve(a, b) -> jax.Array:
    """``x`` with ``a @ x = b`` for a small symmetric positive definite ``a`` (n, n) and ``b`` (n,), by a
    Cholesky factorisation written out element by element (n static).

    Elementwise operations only, so under jit and vmap it fuses with the code around it, where a batched LU
    solve is a library call of its own (on an H200, :func:`leg_ik` of 4096 legs took a third of the time with
    it, and the G1's closed loop ran 1.27 times as fast; BENCHMARKS.md). Each pivot is kept at least ``n * eps``
    times ``a``'s largest diagonal entry: a matrix positive definite in exact arithmetic whose smallest pivot
    rounding made zero or negative (``J J^T`` plus a small damping, J singular) gets a slightly larger
    regularisation there, and the result stays finite.
    """
    n = a.shape[-1]
    info = jnp.finfo(jnp.result_type(a))
    floor = jnp.maximum(n * info.eps * jnp.max(jnp.abs(jnp.diagonal(a))), info.tiny)
    low = [[None] * n for _ in range(n)]
    for j in range(n):
        low[j][j] = jnp.sqrt(jnp.maximum(a[j, j] - sum(low[j][k] ** 2 for k in range(j)), floor))
        for i in range(j + 1, n):
            low[i][j] = (a[i, j] - sum(low[i][k] * low[j][k] for k in range(j))) / low[j][j]
    y = []
    for i in range(n):
        y.append((b[i] - sum(low[i][k] * y[k] for k in range(i))) / low[i][i])
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = (y[i] - sum(low[k][i] * x[k] for k in range(i + 1, n))) / low[i][i]
    return jnp.stack(x)


def leg_ik(
    chain: LegChain, pos, rot, q_init, *, iterations: int = IK_ITERATIONS, damping: float = IK_DAMPING
) -> LegSolution:
    """Joint angles that put the sole at a pose, by damped least squares (any 6-DoF chain).

    Each iteration steps by ``J^T (J J^T + damping^2 I)^-1 e`` on the geometric Jacobian ``J`` of the sole
    (position in m, orientation in rad) and the pose error ``e``, then clips to the joint limits. The number of
    iterations is fixed (static), so the function jits and vmaps; a target out of reach or beyond the limits
    ends at the nearest pose found, with its errors in the result for the caller to flag.

    Args:
      chain: one leg (:attr:`BipedDescription.legs`).
      pos: (3,) target sole centre in the root's frame, m.
      rot: (3, 3) target sole orientation in the root's frame.
      q_init: (6,) the seed (the standing posture, or the last tick's angles), rad.
      iterations: damped least-squares iterations (static).
      damping: the damping (m); see :data:`IK_DAMPING`.

    Returns:
      :class:`LegSolution` ``(q, position_error, rotation_error)``.
    """
    dt = jnp.result_type(pos, rot, q_init, jnp.float32)
    pos, rot = jnp.asarray(pos, dt), jnp.asarray(rot, dt)
    lower, upper = jnp.asarray(chain.lower, dt), jnp.asarray(chain.upper, dt)

    def error(q):
        p, r, anchors, axes = _frames(chain, q)
        e = jnp.concatenate([pos - p, _rotation_vector(rot @ r.T)])
        jac = jnp.concatenate([jnp.cross(axes, p - anchors).T, axes.T])  # (6, 6): d(p, angle)/dq
        return e, jac

    def step(q, _):
        e, jac = error(q)
        dq = jac.T @ spd_solve(jac @ jac.T + damping**2 * jnp.eye(6, dtype=dt), e)
        dq = dq * jnp.minimum(1.0, IK_MAX_STEP / (jnp.max(jnp.abs(dq)) + jnp.finfo(dt).tiny))  # a trust region
        return jnp.clip(q + dq, lower, upper), None

    q, _ = jax.lax.scan(step, jnp.clip(jnp.asarray(q_init, dt), lower, upper), None, length=iterations)
    e, _ = error(q)
    return LegSolution(q, jnp.linalg.norm(e[:3]), jnp.linalg.norm(e[3:]))
