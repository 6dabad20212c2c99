"""An ALDURO-like leg: a non-spherical 3-DOF hip and a knee, each driven by a hydraulic cylinder.

The real ALDURO geometry is not published in the paper (only: legs 1.6 m long,
a 1.8 m x 2.1 m platform, four cylinders per leg, and one example
configuration). Everything below is an *assumed* geometry, chosen to be
plausible and documented so results can be reproduced:

Hip frame at the leg's mount on the platform: x forward, y outward for a left
leg (mirrored for a right leg), z up; metres and radians. The chain, from the
platform::

    R_z(phi)                rotation about the vertical axis through the mount      (q[2])
    translate (0, 0.15, 0)  lateral offset to the abduction axis
    R_x(theta)              abduction, positive swings the foot outward             (q[1])
    translate (0.25, 0, -0.12)  forward and downward offset to the flexion axis
    R_y(-psi)               hip flexion, positive swings the thigh forward          (q[0])
    thigh 0.75 m along -z
    R_y(omega)              knee flexion, positive folds the shank backward         (q[3])
    shank 0.85 m along -z to the foot                      (thigh + shank = 1.6 m)

The three hip axes do not meet in one point (the vertical axis misses the
abduction axis by 0.15 m; the flexion axis sits 0.25 m ahead), so the hip's
Jacobian columns are not coplanar. (With a spherical hip, all three hip
columns are perpendicular to the hip-foot vector and the workspace
degenerates to a prism: 8 facets instead of 12.)

Cylinders: cylinder ``i`` spans a triangle with sides ``arm_a[i]``,
``arm_b[i]`` (its mounts' distances from the joint axis) and its length
``l``; the angle at the joint follows from the law of cosines,
``gamma = arccos((a^2 + b^2 - l^2) / (2 a b))``, and the joint angle is
``angle_at_min + direction * (gamma - gamma_min)``. ``q`` is the piston's
extension from fully retracted, ``0 <= q <= stroke`` (metres).

Calibration: the cylinders' zero angles are set so that the paper's example
``q = [0.15875, 0.10656, 0.08319, 0.04366]`` m of a right leg gives the paper's
foot position ``x = [0.2756, -0.1561, -1.2383]`` m (hip rotation 0 there). In
that pose the foot is almost straight below the flexion and abduction axes, so
only the knee moves it vertically, and the knee cylinder is 4.4 cm from its
retracted end (full flexion): as in the paper's Fig. 8, the repulsive force
points downward.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.haptics.workspace import Workspace, check_repulsion, check_stroke, decay_rate_of, linearize, plane_forces
from ijoy_jax.struct import pytree_dataclass

#: The paper's example (section 3.3): cylinder positions (m) and foot position (m), a right leg.
PAPER_Q = (0.15875, 0.10656, 0.08319, 0.04366)
PAPER_X = (0.2756, -0.1561, -1.2383)


@pytree_dataclass
class LegGeometry:
    """Geometry of one leg (all traced leaves: vmap over legs, differentiate, no recompiles).

    Attributes (metres, radians)::

      hip_lateral: offset from the vertical rotation axis to the abduction axis.
      hip_forward: forward offset of the flexion axis from the abduction axis.
      hip_down: downward offset of the flexion axis from the abduction axis.
      thigh: flexion axis to knee axis.
      shank: knee axis to foot.
      lateral_sign: +1 for a left leg (y outward), -1 for a right leg (mirror image).
      arm_a, arm_b: (4,) the cylinder triangles' sides at each joint, order
        (flexion, abduction, rotation, knee) = the order of q.
      gamma_min: (4,) triangle angle at the joint with the cylinder fully retracted.
      stroke: (4,) cylinder strokes; q ranges over [0, stroke].
      angle_at_min: (4,) joint angle with the cylinder fully retracted.
      direction: (4,) +1 if extending the cylinder increases the joint angle, else -1.
    """

    hip_lateral: jax.Array
    hip_forward: jax.Array
    hip_down: jax.Array
    thigh: jax.Array
    shank: jax.Array
    lateral_sign: jax.Array
    arm_a: jax.Array
    arm_b: jax.Array
    gamma_min: jax.Array
    stroke: jax.Array
    angle_at_min: jax.Array
    direction: jax.Array

    @property
    def q_min(self) -> jax.Array:
        """(4,) lower ends of stroke (zeros), metres."""
        return jnp.zeros_like(self.stroke)

    @property
    def q_max(self) -> jax.Array:
        """(4,) upper ends of stroke, metres."""
        return self.stroke


def cylinder_length(arm_a, arm_b, gamma):
    """Law of cosines: length (m) of a cylinder spanning angle ``gamma`` (rad) between arms a, b (m)."""
    return jnp.sqrt(arm_a**2 + arm_b**2 - 2.0 * arm_a * arm_b * jnp.cos(gamma))


def joint_angles(leg: LegGeometry, q) -> jax.Array:
    """(4,) joint angles (rad) (flexion, abduction, rotation, knee) from cylinder positions q (4,) (m).

    Example:
      >>> leg = alduro_leg()
      >>> [round(v, 1) for v in jnp.rad2deg(joint_angles(leg, jnp.array(PAPER_Q)))[::3].tolist()]
      [50.7, 91.5]
    """
    a, b = leg.arm_a, leg.arm_b
    length = cylinder_length(a, b, leg.gamma_min) + q
    cos_g = (a * a + b * b - length * length) / (2.0 * a * b)
    gamma = jnp.arccos(jnp.clip(cos_g, -1.0, 1.0))
    return leg.angle_at_min + leg.direction * (gamma - leg.gamma_min)


def _rot_x(t, v):
    c, s = jnp.cos(t), jnp.sin(t)
    return (v[0], c * v[1] - s * v[2], s * v[1] + c * v[2])


def _rot_y(t, v):
    c, s = jnp.cos(t), jnp.sin(t)
    return (c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2])


def _rot_z(t, v):
    c, s = jnp.cos(t), jnp.sin(t)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])


def forward_kinematics_angles(leg: LegGeometry, angles) -> jax.Array:
    """Foot position (3,) in the hip frame (m) from joint angles (4,) (rad), order as q."""
    psi, theta, phi, omega = angles[0], angles[1], angles[2], angles[3]
    # Rotations applied to vectors held as (x, y, z) tuples of scalars: elementwise
    # arithmetic only, so XLA fuses the whole chain (and its Jacobian) into few kernels.
    v = _rot_y(omega, (0.0, 0.0, -leg.shank))
    v = _rot_y(-psi, (v[0], v[1], v[2] - leg.thigh))
    v = _rot_x(theta, (v[0] + leg.hip_forward, v[1], v[2] - leg.hip_down))
    v = _rot_z(phi, (v[0], v[1] + leg.hip_lateral, v[2]))
    return jnp.stack([v[0], leg.lateral_sign * v[1], v[2]])


def forward_kinematics(leg: LegGeometry, q) -> jax.Array:
    """Foot position x = Phi(q) (3,) in the hip frame, metres, from cylinder positions q (4,), metres.

    Example:
      >>> leg = alduro_leg(lateral_sign=-1.0)
      >>> [round(v, 4) for v in forward_kinematics(leg, jnp.array(PAPER_Q)).tolist()]  # the paper's x
      [0.2756, -0.1561, -1.2383]
    """
    return forward_kinematics_angles(leg, joint_angles(leg, q))


def leg_workspace(leg: LegGeometry, q) -> Workspace:
    """Linearised workspace of the foot at cylinder positions q (4,) (m): J by autodiff.

    Outside jit, q outside ``[0, stroke]`` raises ValueError; inside jit it is
    clamped to the stroke and flagged in ``out_of_range``.

    Example:
      >>> ws = leg_workspace(alduro_leg(-1.0), jnp.array(PAPER_Q))
      >>> int(ws.planes.valid.sum())
      12
    """
    check_stroke(q, leg.q_min, leg.q_max)
    return _leg_workspace(leg, q)


@jax.jit
def _leg_workspace(leg, q):
    return linearize(lambda x: forward_kinematics(leg, x), q, leg.q_min, leg.q_max)


def leg_repulsive_force(leg: LegGeometry, q, c1, decay_length) -> jax.Array:
    """The foot's repulsive force (3,) (N) at cylinder positions q (4,) (m): the 1 kHz haptic path.

    Forward kinematics, ``J`` by autodiff, limiting planes and ``sum -n C1 exp(-d / lambda)``
    in one jittable function (q outside the stroke is clamped). Concrete invalid
    constants raise a ValueError; traced ones (c1 non-finite, negative or above
    :func:`~ijoy_jax.haptics.workspace.c1_max`, decay_length not finite and > 0)
    give a zero force (see :func:`~ijoy_jax.haptics.workspace.plane_forces`).

    Args:
      leg: LegGeometry.
      q: (4,) cylinder positions, metres.
      c1: C1 (N), a plane's push at distance 0.
      decay_length: lambda (m) > 0.

    Example:
      >>> f = jax.jit(leg_repulsive_force)(alduro_leg(-1.0), jnp.array(PAPER_Q), 1.0, 0.05)
      >>> bool(f[2] < 0)  # Fig. 8: the force points down
      True
    """
    check_repulsion(c1, decay_length=decay_length)
    ws = linearize(lambda x: forward_kinematics(leg, x), q, leg.q_min, leg.q_max)
    return plane_forces(ws.planes, c1, decay_rate_of(decay_length, ws.planes.offsets.dtype)).force


def alduro_leg(lateral_sign: float = 1.0, dtype=None) -> LegGeometry:
    """The assumed ALDURO-like leg geometry (see the module docstring); +1 left, -1 right leg.

    Cylinder triangles (arm_a, arm_b, gamma range over the stroke)::

      flexion (0.30, 0.30, 50-130 deg), abduction (0.40, 0.40, 75-105 deg),
      rotation (0.20, 0.20, 60-120 deg), knee (0.35, 0.25, 40-140 deg).

    Strokes 0.290, 0.148, 0.146, 0.339 m. Joint ranges that follow: flexion 13.9
    to 93.9 deg, abduction -20.5 to 9.5 deg, rotation -30.1 to 29.9 deg, knee
    101.5 down to 1.5 deg (extending the knee cylinder straightens the knee).
    """
    dtype = jnp.result_type(float) if dtype is None else dtype
    deg = np.pi / 180.0
    values = dict(
        hip_lateral=0.15,
        hip_forward=0.25,
        hip_down=0.12,
        thigh=0.75,
        shank=0.85,
        lateral_sign=float(lateral_sign),
        arm_a=[0.30, 0.40, 0.20, 0.35],
        arm_b=[0.30, 0.40, 0.20, 0.25],
        gamma_min=[50 * deg, 75 * deg, 60 * deg, 40 * deg],
        stroke=[_STROKE[0], _STROKE[1], _STROKE[2], _STROKE[3]],
        angle_at_min=list(_ANGLE_AT_MIN),
        direction=[1.0, 1.0, 1.0, -1.0],
    )
    return LegGeometry(**{k: jnp.asarray(v, dtype) for k, v in values.items()})


def _strokes():
    deg = np.pi / 180.0
    a = np.array([0.30, 0.40, 0.20, 0.35])
    b = np.array([0.30, 0.40, 0.20, 0.25])
    lo = np.array([50, 75, 60, 40]) * deg
    hi = np.array([130, 105, 120, 140]) * deg

    def length(g):
        return np.sqrt(a * a + b * b - 2 * a * b * np.cos(g))

    return length(hi) - length(lo)


_STROKE = tuple(float(s) for s in _strokes())
# Joint angles with each cylinder retracted, calibrated (Newton solve of the
# paper's example pose, see tests/test_haptics_leg.py::test_calibration) so that
# PAPER_Q maps to PAPER_X for a right leg with zero hip rotation.
_ANGLE_AT_MIN = (0.24300139704, -0.35805942298, -0.52605597932, 1.77210982884)
