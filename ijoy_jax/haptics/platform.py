"""Platform workspace with the feet fixed (paper section 3.4): translations and yaw.

Translation: moving the platform by ``dp`` with a foot fixed moves that foot
by ``-dp`` relative to its hip, so a leg plane ``n . dx <= d`` becomes
``-n . dp <= d`` (signs flipped). A pure translation moves every hip alike, so
the platform centre's linearised workspace is the intersection of the four
flipped leg workspaces, all centred at ``dp = 0``: ``4 R`` half-spaces (with
masks), the distance to its boundary is the smallest plane distance, and the
repulsive force is the sum of all legs' plane terms.

Yaw (left open in the paper): rotating the platform by ``alpha`` about the
vertical axis through its centre moves foot ``f_i`` (relative to the centre)
in its hip frame along the circle ``dx_i(alpha) = R_z(-alpha) f_i - f_i``.
The largest yaw each way is the first ``alpha`` where some foot's circle
leaves its leg's linearised workspace, solved in closed form per plane:
``n . dx(alpha) = A (cos alpha - 1) + B sin alpha = d`` with
``A = n_x f_x + n_y f_y`` and ``B = n_x f_y - n_y f_x``.

Assumed platform (the paper gives only its size): 2.1 m long (x) by 1.8 m wide
(y), one hip at each corner, legs in the order front-left, front-right,
rear-left, rear-right, every leg the geometry of :mod:`ijoy_jax.haptics.leg`
(mirrored for right legs), all hip frames parallel to the platform frame.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.haptics.leg import PAPER_Q, LegGeometry, alduro_leg, forward_kinematics
from ijoy_jax.haptics.workspace import Planes, check_repulsion, check_stroke, decay_rate_of, linearize, plane_forces
from ijoy_jax.struct import pytree_dataclass

LEG_NAMES = ("front-left", "front-right", "rear-left", "rear-right")


@pytree_dataclass
class Platform:
    """A walking platform (traced leaves).

    Attributes:
      hips: (L, 3) hip mounts relative to the platform centre, platform frame
        (x forward, y left, z up), metres.
      legs: LegGeometry whose leaves have a leading axis of size L.
    """

    hips: jax.Array
    legs: LegGeometry


def alduro_platform(dtype=None) -> Platform:
    """The assumed 2.1 m x 1.8 m ALDURO-like platform with four legs (see the module docstring)."""
    dtype = jnp.result_type(float) if dtype is None else dtype
    half_l, half_w = 1.05, 0.90
    hips = jnp.array(
        [[half_l, half_w, 0.0], [half_l, -half_w, 0.0], [-half_l, half_w, 0.0], [-half_l, -half_w, 0.0]], dtype
    )
    legs = [alduro_leg(s, dtype) for s in (1.0, -1.0, 1.0, -1.0)]
    return Platform(hips=hips, legs=jax.tree_util.tree_map(lambda *x: jnp.stack(x), *legs))


def nominal_q(dtype=None) -> jax.Array:
    """(4, 4) every leg at the paper's example cylinder positions (m)."""
    return jnp.tile(jnp.asarray(PAPER_Q, jnp.result_type(float) if dtype is None else dtype), (4, 1))


class PlatformWorkspace(NamedTuple):
    """Linearised workspace of the platform centre for translations with the feet fixed.

    Fields (L legs, R rows per leg)::

      feet: (L, 3) foot positions relative to the platform centre, metres.
      planes: Planes with leading axis L: normals (L, R, 3) in ``dp`` space
        (the legs' normals, sign flipped), offsets (L, R) metres, valid (L, R).
      out_of_range: (L, 4) bool, cylinders clamped to their stroke.
      leg_planes: the legs' own Planes (foot motion in each hip frame), (L, R, ...).
    """

    feet: jax.Array
    planes: Planes
    out_of_range: jax.Array
    leg_planes: Planes


def platform_workspace(platform: Platform, q) -> PlatformWorkspace:
    """Translation workspace of the platform centre at cylinder positions q (L, 4) (m).

    Outside jit, q outside the strokes raises ValueError; inside jit it is
    clamped and flagged.

    Example:
      >>> pw = platform_workspace(alduro_platform(), nominal_q())
      >>> pw.planes.normals.shape, int(pw.planes.valid.sum())
      ((4, 26, 3), 48)
    """
    check_stroke(q, jnp.zeros_like(platform.legs.stroke), platform.legs.stroke)
    return _platform_workspace(platform, jnp.asarray(q))


@jax.jit
def _platform_workspace(platform, q):
    def one(leg, qi):
        return linearize(lambda x: forward_kinematics(leg, x), qi, leg.q_min, leg.q_max)

    ws = jax.vmap(one)(platform.legs, q)
    flipped = ws.planes._replace(normals=-ws.planes.normals)
    return PlatformWorkspace(
        feet=platform.hips + ws.position, planes=flipped, out_of_range=ws.out_of_range, leg_planes=ws.planes
    )


@jax.jit
def boundary_distance(pw: PlatformWorkspace) -> jax.Array:
    """Distance (m) from the current platform position to the boundary of its translation workspace."""
    return jnp.min(jnp.where(pw.planes.valid, pw.planes.offsets, jnp.inf))


class PlatformForce(NamedTuple):
    """Repulsive force on the platform (newtons, units of C1).

    Fields:
      force: (3,) the sum over legs.
      per_leg: (L, 3) each leg's contribution.
      bad_constants: () bool, True when C1 or the decay length was invalid: then all forces are zero.
    """

    force: jax.Array
    per_leg: jax.Array
    bad_constants: jax.Array


def platform_force(pw: PlatformWorkspace, c1, decay_length) -> PlatformForce:
    """Sum of ``-n C1 exp(-d / lambda)`` over every leg's flipped plane (the platform's repulsion).

    Args:
      pw: from :func:`platform_workspace`.
      c1: C1 (N), in ``[0, c1_max()]`` (:func:`~ijoy_jax.haptics.workspace.c1_max`).
      decay_length: lambda (m) > 0.

    Returns:
      PlatformForce. Concrete invalid constants raise a ValueError; traced ones
      give zero forces with ``bad_constants`` set (never NaN, never an attraction).
    """
    check_repulsion(c1, decay_length=decay_length)
    return _platform_force(pw, c1, decay_length)


@jax.jit
def _platform_force(pw, c1, decay_length):
    rate = decay_rate_of(decay_length, pw.planes.offsets.dtype)
    out = jax.vmap(lambda p: plane_forces(p, c1, rate))(pw.planes)
    return PlatformForce(force=jnp.sum(out.force, axis=0), per_leg=out.force, bad_constants=out.bad_constants[0])


def translation_halfspaces(pw: PlatformWorkspace) -> tuple[np.ndarray, np.ndarray]:
    """Host-side ``(A (m, 3), b (m,))`` of all legs' valid flipped planes: ``{dp : A dp <= b}``."""
    valid = np.asarray(pw.planes.valid).reshape(-1)
    return (np.asarray(pw.planes.normals).reshape(-1, 3)[valid], np.asarray(pw.planes.offsets).reshape(-1)[valid])


class YawLimits(NamedTuple):
    """Largest platform yaw each way before a foot leaves its leg's linearised workspace.

    Fields:
      positive: () largest counter-clockwise yaw (rad, >= 0; +inf if never left).
      negative: () largest clockwise yaw (rad, <= 0; -inf if never left).
      positive_leg, negative_leg: () int32 index of the limiting leg (-1 if none).
      per_leg: (L, 2) each leg's own (positive, negative) limits.
    """

    positive: jax.Array
    negative: jax.Array
    positive_leg: jax.Array
    negative_leg: jax.Array
    per_leg: jax.Array


def plane_yaw_limits(normal, offset, valid, foot) -> tuple[jax.Array, jax.Array]:
    """First exit angles (positive, negative) of the circle ``R_z(-a) f - f`` through one plane.

    The closed form :func:`yaw_limits` takes over every leg's planes (module docstring): the smallest yaw each
    way at which a foot fixed on the ground leaves the half-space ``n . dx <= d`` of its leg. One plane, one
    foot; vmap for more.

    Args:
      normal: (3,) the plane's unit normal ``n`` (hip frame).
      offset: () its offset ``d`` (m; >= 0 while the foot is inside, 0 on the plane).
      valid: () bool, the plane exists (an invalid one is never left).
      foot: (3,) the foot relative to the platform centre (m, platform frame).

    Returns:
      ``(positive, negative)``: () the first exit yaw counter-clockwise (rad, >= 0) and clockwise (rad, <= 0);
      +inf and -inf where the circle never reaches the plane, 0 where the foot is on the plane and moving out.

    Example:
      >>> import jax.numpy as jnp
      >>> from ijoy_jax.haptics import platform
      >>> foot = jnp.array([1.0, 0.5, -1.2])
      >>> [float(a) for a in platform.plane_yaw_limits(jnp.array([0.0, 0.0, 1.0]), 0.1, True, foot)]  # level
      [inf, -inf]
    """
    a_coef = normal[0] * foot[0] + normal[1] * foot[1]
    b_coef = normal[0] * foot[1] - normal[1] * foot[0]
    radius = jnp.sqrt(a_coef**2 + b_coef**2)
    moves = valid & (radius > 0)
    r_safe = jnp.where(moves, radius, 1.0)
    kappa = (a_coef + offset) / r_safe  # cos(alpha - phi) on the plane; g(0) = -d <= 0 so kappa >= -1
    reach = moves & (kappa < 1.0)
    delta = jnp.arccos(jnp.clip(jnp.where(reach, kappa, 0.0), -1.0, 1.0))
    phi = jnp.arctan2(jnp.where(moves, b_coef, 0.0), jnp.where(moves, a_coef, 1.0))
    two_pi = 2.0 * jnp.pi
    # The foot is outside on the arc |alpha - phi| < delta; from alpha = 0 turning
    # positive it enters at phi - delta, turning negative at phi + delta (mod 2 pi).
    pos = jnp.mod(phi - delta, two_pi)
    neg = -jnp.mod(-(phi + delta), two_pi)
    on_plane = offset <= 0
    pos = jnp.where(on_plane & (b_coef > 0), 0.0, pos)
    neg = jnp.where(on_plane & (b_coef < 0), 0.0, neg)
    return jnp.where(reach, pos, jnp.inf), jnp.where(reach, neg, -jnp.inf)


@jax.jit
def yaw_limits(pw: PlatformWorkspace) -> YawLimits:
    """Largest yaw each way about the platform centre with the feet fixed (closed form, exact circles).

    Example:
      >>> lim = yaw_limits(platform_workspace(alduro_platform(), nominal_q()))
      >>> bool(lim.positive > 0) and bool(lim.negative < 0)
      True
    """
    lp = pw.leg_planes
    pos, neg = jax.vmap(jax.vmap(plane_yaw_limits, in_axes=(0, 0, 0, None)))(lp.normals, lp.offsets, lp.valid, pw.feet)
    leg_pos, leg_neg = jnp.min(pos, axis=1), jnp.max(neg, axis=1)
    ip, ineg = jnp.argmin(leg_pos), jnp.argmax(leg_neg)
    return YawLimits(
        positive=leg_pos[ip],
        negative=leg_neg[ineg],
        positive_leg=jnp.where(jnp.isfinite(leg_pos[ip]), ip, -1).astype(jnp.int32),
        negative_leg=jnp.where(jnp.isfinite(leg_neg[ineg]), ineg, -1).astype(jnp.int32),
        per_leg=jnp.stack([leg_pos, leg_neg], axis=1),
    )
