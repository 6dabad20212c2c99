"""Robot models: footprint, safety margin, step timing and the action set S.

An action is a displacement ``(dx, dy, dtheta)`` of the swing foot relative to
the stance foot, in the stance foot's frame (metres, radians). ``Robot.actions``
holds the LEFT swing foot's set relative to a RIGHT stance foot; the right
foot's set is its mirror ``(dx, -dy, -dtheta)`` (:func:`side_actions`).

Every number a user may sweep or tune is a traced leaf of :class:`Robot` (and
its :class:`TerrainMetrics`), so changing it never recompiles and it can be
vmapped over or differentiated. Only the action-set size (an array shape) and
two window sizes that bound the footprint (``max_radius``, ``max_swing``;
Python floats) are static.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import geometry
from ijoy_jax._struct import pytree_dataclass, static_field
from ijoy_jax.limits import MAX_ACTIONS, MAX_DENSITY
from ijoy_jax.prng import as_key

LEFT = 1
RIGHT = -1


@pytree_dataclass
class TerrainMetrics:
    """Weights and hard limits of the 2.5D terrain metrics (traced leaves, scalars).

    The metrics follow the biped planner the paper cites (Chestnutt et al.
    2003): a plane is fitted (least squares) to the heights of the cells under
    the foot, and::

      slope      angle of that plane from horizontal (rad),
      roughness  mean absolute deviation of those cells from the plane (m),
      bump       largest height of a cell above the plane (m),
      step       |height change| from the stance foot's plane to this one (m);
                 its limit is per action (``Robot.max_step_height``),
      band       largest |deviation| from the plane in the safety band, the
                 cells touched by the footprint grown by the margin but not
                 by the footprint itself: catches edges and drop-offs (m),
      support    how much nearer the ankle the rested sole's contact polygon
                 comes than the whole sole's (m). The sole touches the
                 ground at six points (toe, middle and heel of each long
                 edge, ``contact_inset`` in from the edges: the simulated
                 biped's sole spheres; heights interpolated bilinearly
                 between cell centres, as a height field's surface is) and
                 rests on the plane through three of them that stays above
                 the others and lies lowest under the ankle
                 (:mod:`ijoy_jax.footcost.sole`); the points within
                 ``contact_tol`` of it form its contact polygon, and the
                 centre of pressure can move from the ankle to that
                 polygon's nearest edge before the sole rocks. The metric is
                 the whole sole's margin (``min(half length, half width) -
                 contact_inset``) less the polygon's: 0 where the sole rests
                 on all six points, on a plane of any tilt; the whole margin
                 where it rests on two diagonal corners or on its front half
                 (a dome under the middle, a twisted surface, a ridge under
                 it: the footholds the simulated biped fell on). Partial
                 footholds whose polygon holds the ankle with room to spare
                 pass. The rested sole's tilt is the foothold's (the
                 ``ankle`` limits apply to it) and its height the step's.

    A metric beyond its limit makes the cost +inf; otherwise its term is
    ``weight * metric``. Weights are cost units per radian or per metre.
    ``contact_inset`` and ``contact_tol`` (m) are not metrics: where the
    sole's contact points lie, and how close to the rested sole a point
    counts as touching.
    """

    slope_weight: jax.Array
    slope_limit: jax.Array
    roughness_weight: jax.Array
    roughness_limit: jax.Array
    bump_weight: jax.Array
    bump_limit: jax.Array
    step_weight: jax.Array
    band_weight: jax.Array
    band_limit: jax.Array
    support_weight: jax.Array
    support_limit: jax.Array
    contact_inset: jax.Array
    contact_tol: jax.Array


def default_metrics(
    slope_weight=1.0,
    slope_limit=math.radians(20.0),
    roughness_weight=20.0,
    roughness_limit=0.01,
    bump_weight=10.0,
    bump_limit=0.02,
    step_weight=1.0,
    band_weight=5.0,
    band_limit=0.03,
    support_weight=5.0,
    support_limit=0.025,
    contact_inset=0.009,
    contact_tol=0.003,
) -> TerrainMetrics:
    """Default metric weights and limits (float32 scalars); any may be overridden."""
    vals = dict(locals())
    for k, v in vals.items():
        _check_scalar(k, v, nonneg=True)
    return TerrainMetrics(**{k: jnp.asarray(v, jnp.float32) for k, v in vals.items()})


@pytree_dataclass
class Robot:
    """A robot model and its joystick parameters (the paper's footprint and S).

    Leaves (traced; scalars unless noted; metres, radians, seconds)::

      foot_length: footprint length along the foot's own x axis.
      foot_width: footprint width.
      margin: safety margin; validity uses the footprint grown by it on every
        side, a ``(length + 2 margin) x (width + 2 margin)`` rectangle.
      step_time: duration of one step, the Delta t of p_next = p0 + Delta t * j.
      p0: (3,) step-in-place action of the LEFT swing foot (dx, dy, dtheta).
      actions: (N, 3) the action set S of the LEFT swing foot (dx, dy, dtheta).
      action_cost: (N,) cost of taking each action (>= 0; part of FootCost).
      clearance: (N,) swing-path clearance of each action: terrain between
        the start and end footholds higher than this above the higher of the
        two makes the step invalid.
      max_step_height: (N,) allowed |height change| from the stance foothold.
      max_sole_pitch, max_sole_roll: the largest tilt of the sole from
        horizontal, about the foot's own y axis (pitch) and x axis (roll), that
        the ankles can realise (rad): a foothold whose rested sole tilts
        further is refused (FootCost's ``ankle`` term). See
        :func:`make_robot` for HRP-2's values and where they come from.
      max_sole_distance: the largest distance between the stance and swing
        sole centres in 3D (m; the horizontal step and the height change of
        the two rested soles): beyond it the legs cannot stand on both
        footholds (FootCost's ``reach`` term). See :func:`make_robot`.
      metrics: TerrainMetrics weights and limits.
      w: weight of dist against FootCost, cost(p) = FootCost + w dist(p, p_next).
      rotation_weight: dist = |translation| + rotation_weight * |rotation|
        (cost units per radian before w); large, so the commanded rotation is
        preferred whenever such a step is valid.

    Static::

      max_radius: largest half-diagonal of the grown footprint the fixed-size
        windows cover (m); a larger footprint or margin is flagged invalid.
      max_swing: longest swing-path segment the path window covers (m).
      target_grid: the lattice of the paper's target set F, ``(lo, step,
        counts)`` per axis (:func:`target_lattice`).
    """

    foot_length: jax.Array
    foot_width: jax.Array
    margin: jax.Array
    step_time: jax.Array
    p0: jax.Array
    actions: jax.Array
    action_cost: jax.Array
    clearance: jax.Array
    max_step_height: jax.Array
    max_sole_pitch: jax.Array
    max_sole_roll: jax.Array
    max_sole_distance: jax.Array
    metrics: TerrainMetrics
    w: jax.Array
    rotation_weight: jax.Array
    max_radius: float = static_field()
    max_swing: float = static_field()
    target_grid: tuple = static_field()

    @property
    def num_actions(self) -> int:
        """Size N of the action set (static)."""
        return self.actions.shape[-2]


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _check_scalar(name, value, positive=False, nonneg=False):
    if not _is_concrete(value):
        return
    v = np.asarray(value, np.float64)
    if v.shape != ():
        raise ValueError(f"{name} must be a scalar, got shape {v.shape}")
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {float(v)}")
    if positive and v <= 0:
        raise ValueError(f"{name} must be > 0, got {float(v)}")
    if nonneg and v < 0:
        raise ValueError(f"{name} must be >= 0, got {float(v)}")


def footprints_overlap(actions, foot_length: float, foot_width: float) -> np.ndarray:
    """(N,) bool: does the swing footprint of each action overlap the stance footprint?

    Separating-axis test of two rectangles (interiors; touching is no overlap),
    in NumPy float64. The stance foot is at the origin with angle 0.
    """
    return _overlap(np, np.asarray(actions, np.float64).reshape(-1, 3), foot_length, foot_width, 0.0)


def overlaps_stance(robot: Robot, rel) -> jax.Array:
    """(...,) bool: does a swing footprint at ``rel`` (..., 3) overlap the stance footprint (traceable)?

    ``rel`` is the swing foot's pose in the stance foot's frame (either side: the test is symmetric);
    overlaps shallower than :data:`OVERLAP_TOL` (float32 rounding of touching feet) do not count. What a step
    off the action set's lattice (:mod:`ijoy_jax.refine`) must not do; every action of S passes it
    (:func:`check_robot`).
    """
    rel = jnp.asarray(rel, jnp.float32)
    flat = _overlap(jnp, rel.reshape(-1, 3), robot.foot_length, robot.foot_width, OVERLAP_TOL)
    return flat.reshape(rel.shape[:-1])


def _overlap(xp, a, foot_length, foot_width, tol):
    """:func:`footprints_overlap` in NumPy or jnp: overlap deeper than ``tol`` metres."""

    def corners(x, y, t):
        c, s = xp.cos(t)[:, None], xp.sin(t)[:, None]
        lx = np.array([1, -1, -1, 1]) * foot_length / 2
        ly = np.array([1, 1, -1, -1]) * foot_width / 2
        return xp.stack([x[:, None] + c * lx - s * ly, y[:, None] + s * lx + c * ly], -1)

    swing = corners(a[:, 0], a[:, 1], a[:, 2])  # (N, 4, 2)
    zero = xp.zeros_like(a[:1, 0])
    stance = xp.broadcast_to(corners(zero, zero, zero), swing.shape)
    separated = xp.zeros(a.shape[0], bool)
    for poly in (stance, swing):
        for i in range(4):
            e = poly[:, (i + 1) % 4] - poly[:, i]
            n = xp.stack([-e[:, 1], e[:, 0]], -1)[:, None, :]
            n = n / xp.maximum(xp.sqrt(xp.sum(n * n, -1, keepdims=True)), 1e-12)  # unit axes: tol in metres
            pa, pb = xp.sum(stance * n, -1), xp.sum(swing * n, -1)
            separated |= (pa.max(1) <= pb.min(1) + tol) | (pb.max(1) <= pa.min(1) + tol)
    return ~separated


MAX_SIZE = 2.0
"""m: the largest ``foot_length``, ``foot_width``, ``margin`` and ``max_margin`` a robot may have. The static windows
are sized from them (``max_radius``) and FootCost's work per candidate grows with their square, so a larger value
is refused (:func:`make_robot`, :func:`check_robot`; flagged inside a jit, :func:`robot_supported`): it is a unit
mistake (millimetres for metres), not a foot."""

WINDOW_SLACK = 1e-6
"""m: float32 rounding allowed above the float64 static window ``max_radius`` (as FootCost allows)."""

OVERLAP_TOL = 1e-5
"""m: overlap of the feet a traced check ignores (float32 rounding of corners of footprints that touch)."""

_PER_ACTION = ("action_cost", "clearance", "max_step_height")
_LIMITS = ("max_sole_pitch", "max_sole_roll", "max_sole_distance")  # the biped's ankle-tilt and leg-reach limits


def _positive(xp, x):
    return xp.all(xp.isfinite(x) & (x > 0))


def _nonneg(xp, x):
    return xp.all(xp.isfinite(x) & (x >= 0))


def _finite(xp, x):
    return xp.all(xp.isfinite(x))


def _size(xp, x):
    return xp.all(xp.isfinite(x) & (x > 0) & (x <= MAX_SIZE))


def _margin(xp, x):
    return xp.all(xp.isfinite(x) & (x >= 0) & (x <= MAX_SIZE))


def _in_window(xp, robot, length, width, margin):
    return 0.5 * xp.hypot(length + 2 * margin, width + 2 * margin) <= robot.max_radius + WINDOW_SLACK


def _inset_inside(length, width, inset):
    """The sole's contact points lie inside it, each on its own side of the centre: the inset is under half its
    length and half its width."""
    return (inset < 0.5 * length) & (inset < 0.5 * width)


# (leaf names, what they must be, rule(xp, *values) -> bool). One list for both uses: check_robot raises on
# the first rule a concrete robot breaks; robot_supported ANDs them all in jnp inside a trace.
_ROBOT_RULES = (
    *((n, f"finite, > 0 and <= MAX_SIZE = {MAX_SIZE:g} m", _size) for n in ("foot_length", "foot_width")),
    ("margin", f"finite, >= 0 and <= MAX_SIZE = {MAX_SIZE:g} m", _margin),
    ("step_time", "finite and > 0", _positive),
    *((n, "finite and >= 0", _nonneg) for n in ("w", "rotation_weight", *_LIMITS, *_PER_ACTION)),
    *((f"metrics.{n}", "finite and >= 0", _nonneg) for n in TerrainMetrics.__dataclass_fields__),
    *((n, "finite", _finite) for n in ("actions", "p0")),
)


def _leaf_shape(robot: Robot, name: str) -> tuple:
    n = robot.num_actions
    return {"actions": (n, 3), "p0": (3,), **{k: (n,) for k in _PER_ACTION}}.get(name, ())


def check_robot(robot) -> None:
    """Check a :class:`Robot`'s values where they are concrete (tracers are skipped); raise on the first bad one.

    What a constructor (:func:`make_robot`) checks, for a robot changed since by ``replace`` or
    :func:`set_leaves`: leaf shapes and numeric dtypes; sizes and times finite and > 0 (foot sizes and
    the margin at most :data:`MAX_SIZE`); margin, weights, costs, clearances and limits finite and >= 0;
    actions and p0 finite; the grown
    footprint within the static window ``max_radius`` (a larger margin or footprint needs a robot
    built for it, ``make_robot(..., max_margin=...)``); the contact inset under half the foot's width and length; no
    action making the footprints overlap. The public boundaries (:func:`ijoy_jax.foot_cost_terms`,
    :func:`ijoy_jax.select_step`, :func:`ijoy_jax.rollout`) call it; inside a trace the same rules are flagged instead
    (:func:`robot_supported`).

    Raises:
      TypeError: not a Robot, or a non-numeric leaf. ValueError: a bad shape or value, naming the leaf.
    """
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be an ijoy_jax.robots.Robot, got {type(robot).__name__}")
    if not isinstance(robot.metrics, TerrainMetrics):
        raise TypeError(f"robot.metrics must be a TerrainMetrics, got {type(robot.metrics).__name__}")
    values = {}
    for name, *_ in _ROBOT_RULES:
        leaf = get_leaf(robot, name)
        if np.shape(leaf) != _leaf_shape(robot, name):
            raise ValueError(f"robot.{name} must have shape {_leaf_shape(robot, name)}, got {np.shape(leaf)}")
        if not _is_concrete(leaf):
            continue
        arr = np.asarray(leaf)
        if arr.dtype.kind not in "biuf":
            raise TypeError(f"robot.{name} must be a number, got dtype {arr.dtype}")
        values[name] = arr.astype(np.float64)
    for name, must, rule in _ROBOT_RULES:
        if name in values and not rule(np, values[name]):
            shown = values[name].tolist() if values[name].size <= 3 else "an array"
            raise ValueError(f"robot.{name} must be {must}, got {shown}")
    size = [values.get(n) for n in ("foot_length", "foot_width", "margin")]
    if all(v is not None for v in size) and not _in_window(np, robot, *size):
        field = "robot.margin" if _in_window(np, robot, size[0], size[1], 0.0) else "robot.foot_length/foot_width"
        raise ValueError(
            f"{field}: robot's footprint {float(size[0])} x {float(size[1])} m grown by margin {float(size[2])} m "
            f"does not fit its static window (half-diagonal max_radius = {robot.max_radius:.4f} m): build the "
            f"robot with that margin or size (make_robot(..., max_margin=...), hrp2(margin=...)) instead of replace")
    inset = values.get("metrics.contact_inset")
    if all(v is not None for v in size[:2]) and inset is not None and not _inset_inside(*size[:2], inset):
        raise ValueError(f"robot.metrics.contact_inset must be under half the foot's width and length "
                         f"({0.5 * float(min(size[:2]))} m): the sole's contact points lie on both sides of its "
                         f"centre, got {float(inset)}")
    if all(v is not None for v in size[:2]) and "actions" in values:
        bad = footprints_overlap(values["actions"], float(size[0]), float(size[1]))
        if bad.any():
            raise ValueError(f"robot.actions: {int(bad.sum())} action(s) make the swing and stance footprints "
                             f"overlap with foot_length {float(size[0])} m, foot_width {float(size[1])} m, e.g. "
                             f"action {values['actions'][np.argmax(bad)].tolist()}")


def robot_supported(robot: Robot) -> jax.Array:
    """() bool: the robot's values are ones FootCost and the selectors support (traceable).

    The rules of :func:`check_robot` that a traced value can break (a margin, weight or cost below 0, a
    size <= 0, NaN/inf, a grown footprint beyond ``max_radius``, a contact inset of half the foot width or more),
    as one flag: where it is False
    FootCost's ``unsupported`` term is +inf and :func:`ijoy_jax.select_step` reports no valid step, with
    ``unsupported`` set (never a negative cost or a silent stop). An action making the footprints overlap
    (deeper than :data:`OVERLAP_TOL`), e.g. after a longer ``foot_length``, is flagged too.
    """
    ok = [rule(jnp, get_leaf(robot, name)) for name, _, rule in _ROBOT_RULES]
    ok.append(_in_window(jnp, robot, robot.foot_length, robot.foot_width, robot.margin))
    ok.append(_inset_inside(robot.foot_length, robot.foot_width, robot.metrics.contact_inset))
    # float32 corners: overlaps shallower than OVERLAP_TOL (rounding of touching feet) are not flagged
    ok.append(~jnp.any(_overlap(jnp, robot.actions, robot.foot_length, robot.foot_width, OVERLAP_TOL)))
    return jnp.all(jnp.stack(ok))


def make_robot(
    actions,
    *,
    foot_length: float,
    foot_width: float,
    margin: float,
    step_time: float,
    p0=None,
    action_cost=0.0,
    clearance=0.10,
    max_step_height=0.10,
    max_sole_pitch: float = math.radians(20.0),
    max_sole_roll: float = math.radians(10.0),
    max_sole_distance: float = 0.50,
    metrics: TerrainMetrics | None = None,
    w: float = 1.0,
    rotation_weight: float = 100.0,
    max_margin: float | None = None,
) -> Robot:
    """Build and validate a :class:`Robot` from an action set.

    Args:
      actions: (N, 3) LEFT swing-foot actions (dx, dy, dtheta) relative to a
        right stance foot; N >= 1; no action may make the footprints overlap.
      foot_length, foot_width: footprint size (m), > 0 and <= :data:`MAX_SIZE`.
      margin: safety margin (m), >= 0 and <= :data:`MAX_SIZE`.
      step_time: seconds per step, > 0.
      p0: (3,) step-in-place action; default: the action with dx = dtheta = 0
        and the smallest dy, or the action nearest (0, 0.19, 0) if none.
      action_cost, clearance, max_step_height: scalars or (N,) arrays (>= 0).
      max_sole_pitch, max_sole_roll: the sole tilts the ankles can realise
        (rad, >= 0; FootCost's ``ankle`` term). Defaults: HRP-2's, from the
        MJX biped (:class:`ijoy_jax.sim.model.BipedParams`: ankle pitch
        [-75, 42] deg, ankle roll [-20, 35] deg on the left leg, mirrored on
        the right; thigh + shank 0.6 m; ankle 0.105 m above the sole; hips
        0.06 m either side of the pelvis) in the double-support posture its
        controller holds (pelvis level, midway between the feet, 0.65 m above
        the soles), solved by its leg IK within every joint range. Pitch: 20
        deg is realisable in every stance of the action set, at a 0.30 m
        reach too (25 deg is not: the front ankle's 42 deg), and equals the
        default slope limit, so it refuses nothing the slope limit accepts
        unless that is raised. Roll: a stance wider than the hips leans the
        legs outward, using up the narrow 20 deg side of the ankle roll: at
        the step-in-place width (0.19 m) a roll of 11.5 deg is realisable in
        every stance (13.5 deg standing straight), at the widest (0.33 m)
        only 6 deg. 10 deg keeps 1.5 deg at the former; one scalar cannot
        follow the width, so a sole rolled by 6 to 10 deg in a wide stance
        is accepted but beyond this posture's joint range.
      max_sole_distance: the largest 3D distance between the stance and
        swing sole centres (m, >= 0; FootCost's ``reach`` term). Default
        0.50, HRP-2's: with the pelvis 0.65 m above the lower sole and
        midway between the feet, the lower leg (hip to ankle at most 0.6 m,
        0.545 m of it vertical) reaches sqrt(0.6^2 - 0.545^2) = 0.251 m
        sideways or forward from below its hip, so the soles can be
        2 x 0.251 = 0.502 m apart; the hips' 0.12 m spacing is not credited
        and the height change counts in full, so the limit is conservative.
        The paper's farthest action (0.2, 0.33) is 0.386 m away, the 0.3 m
        reach's (0.3, 0.33) 0.446 m: a 15 cm stair riser still fits.
      metrics: TerrainMetrics; default :func:`default_metrics`.
      w: weight of dist (>= 0). rotation_weight: see :class:`Robot` (>= 0).
      max_margin: largest margin the static windows must cover (m, at most
        :data:`MAX_SIZE`); default ``max(margin, 0.10)``, the paper's whole
        2-10 cm range, so a margin sweep never recompiles.

    Raises:
      ValueError: empty or malformed action set, overlapping footprints,
        non-positive sizes or times, sizes or margins above :data:`MAX_SIZE`,
        negative costs, NaN/inf anywhere (naming the argument).
    """
    acts = np.asarray(actions, np.float64)
    if acts.ndim != 2 or acts.shape[1] != 3:
        raise ValueError(f"actions must have shape (N, 3), got {acts.shape}")
    if acts.shape[0] == 0:
        raise ValueError("the action set is empty")
    if acts.shape[0] > MAX_ACTIONS:
        raise ValueError(f"{acts.shape[0]} actions are above ijoy_jax.limits.MAX_ACTIONS = {MAX_ACTIONS} (the "
                         f"targets table grows with their number)")
    if not np.all(np.isfinite(acts)):
        raise ValueError("actions must be finite (no NaN or inf)")
    _check_scalar("foot_length", foot_length, positive=True)
    _check_scalar("foot_width", foot_width, positive=True)
    _check_scalar("margin", margin, nonneg=True)
    _check_scalar("step_time", step_time, positive=True)
    _check_scalar("w", w, nonneg=True)
    _check_scalar("rotation_weight", rotation_weight, nonneg=True)
    if max_margin is not None:
        _check_scalar("max_margin", max_margin, nonneg=True)
    for name, v in (("foot_length", foot_length), ("foot_width", foot_width), ("margin", margin),
                    ("max_margin", max_margin)):
        if v is not None and float(v) > MAX_SIZE:
            raise ValueError(f"{name} must be <= {MAX_SIZE:g} m (robots.MAX_SIZE: the static windows grow with it), "
                             f"got {float(v)}")
    for name, value in (("max_sole_pitch", max_sole_pitch), ("max_sole_roll", max_sole_roll),
                        ("max_sole_distance", max_sole_distance)):
        _check_scalar(name, value, nonneg=True)
    bad = footprints_overlap(acts, float(foot_length), float(foot_width))
    if bad.any():
        raise ValueError(
            f"{int(bad.sum())} action(s) make the swing and stance footprints overlap, "
            f"e.g. action {acts[np.argmax(bad)].tolist()}"
        )
    n = acts.shape[0]

    def per_action(name, v):
        arr = np.broadcast_to(np.asarray(v, np.float64), (n,)) if np.ndim(v) == 0 else np.asarray(v, np.float64)
        if arr.shape != (n,):
            raise ValueError(f"{name} must be a scalar or have shape ({n},), got {arr.shape}")
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ValueError(f"{name} must be finite and >= 0")
        return jnp.asarray(arr, jnp.float32)

    if p0 is None:
        in_place = np.flatnonzero((np.abs(acts[:, 0]) < 1e-9) & (np.abs(acts[:, 2]) < 1e-9))
        if in_place.size:
            p0 = acts[in_place[np.argmin(acts[in_place, 1])]]
        else:
            p0 = acts[np.argmin(np.linalg.norm(acts - [0.0, 0.19, 0.0], axis=1))]
    p0 = np.asarray(p0, np.float64)
    if p0.shape != (3,) or not np.all(np.isfinite(p0)):
        raise ValueError(f"p0 must be a finite (3,) array, got {p0!r}")
    mm = max(float(margin), 0.10) if max_margin is None else float(max_margin)
    if mm < float(margin):
        raise ValueError(f"max_margin ({mm}) must be >= margin ({margin})")
    max_radius = 0.5 * math.hypot(float(foot_length) + 2 * mm, float(foot_width) + 2 * mm)
    reach = float(np.max(np.hypot(acts[:, 0], acts[:, 1])))
    max_swing = 2.0 * reach + float(foot_width)
    f32 = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
    robot = Robot(
        foot_length=f32(foot_length),
        foot_width=f32(foot_width),
        margin=f32(margin),
        step_time=f32(step_time),
        p0=f32(p0),
        actions=f32(acts),
        action_cost=per_action("action_cost", action_cost),
        clearance=per_action("clearance", clearance),
        max_step_height=per_action("max_step_height", max_step_height),
        max_sole_pitch=f32(max_sole_pitch),
        max_sole_roll=f32(max_sole_roll),
        max_sole_distance=f32(max_sole_distance),
        metrics=default_metrics() if metrics is None else metrics,
        w=f32(w),
        rotation_weight=f32(rotation_weight),
        max_radius=max_radius,
        max_swing=max_swing,
        target_grid=target_lattice(acts),
    )
    check_robot(robot)  # as float32 leaves: 1e39 overflows, and what passes here passes every boundary
    return robot


def target_lattice(actions, refine: int = 2) -> tuple[tuple, tuple, tuple]:
    """Lattice ``(lo, step, counts)`` (3-tuples) of the paper's target set F for an action set.

    Spans the bounding box of the actions extended by one action spacing on
    each side, with ``refine`` points per action spacing along each axis
    (spacing = smallest gap between distinct values of that coordinate).
    """
    acts = np.asarray(actions, np.float64)
    lo, step, counts = [], [], []
    for k in range(3):
        vals = np.unique(np.round(acts[:, k], 7))
        spacing = float(np.min(np.diff(vals))) if len(vals) > 1 else (0.05 if k < 2 else math.radians(5.0))
        lo.append(float(vals[0]) - spacing)
        step.append(spacing / refine)
        counts.append(2 * refine + refine * int(round((vals[-1] - vals[0]) / spacing)) + 1)
    return tuple(lo), tuple(step), tuple(counts)


def lattice_actions(
    counts: tuple[int, int, int],
    dx_range=(-0.20, 0.20),
    dy_range=(0.19, 0.33),
    dtheta_range=(-math.radians(20.0), math.radians(20.0)),
    drop_corners: bool = True,
) -> np.ndarray:
    """A lattice of actions: ``counts = (n_dx, n_dy, n_dtheta)`` evenly spaced values per range.

    With ``drop_corners`` the 8 corners of the (dx, dy, dtheta) box (largest
    step, extreme width and extreme rotation all at once) are left out: they
    lie outside a leg's reach. Ordered by dx, then dy, then dtheta.

    Returns:
      (M, 3) float64 array, M = n_dx n_dy n_dtheta (- 8 with drop_corners).
    """
    axes = [np.linspace(lo, hi, n) if n > 1 else np.array([0.5 * (lo + hi)])
            for (lo, hi), n in zip((dx_range, dy_range, dtheta_range), counts, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    if drop_corners and min(counts) > 1:
        corner = np.ones(len(grid), bool)
        for k, ax in enumerate(axes):
            corner &= np.isclose(grid[:, k], ax[0]) | np.isclose(grid[:, k], ax[-1])
        grid = grid[~corner]
    return grid


DX_SPACING = 0.05
"""m: spacing of HRP-2's dx lattice at density 1 (the paper's 9 values over [-0.2, 0.2] m)."""

PAPER_REACH = 0.20
"""m: the paper's largest forward/backward step of HRP-2 (:func:`hrp2`'s default ``reach``)."""

STAIR_STEP_HEIGHT = 0.15
"""m: HRP-2's ``max_step_height`` with a reach beyond the paper's (:func:`hrp2`): stair risers up to 15 cm."""


def density_counts(density: float, reach: float = PAPER_REACH) -> tuple[int, int, int]:
    """Lattice counts for an action-set density; density 1 gives HRP-2's (9, 8, 7) -> 496 actions.

    dx and dtheta counts stay odd so that straight steps (dx = 0, dtheta = 0)
    stay in the set. Sizes: density 0.1 -> 10, 0.25 -> 19, 0.5 -> 117,
    1 -> 496, 2 -> 3307, 3 -> 10442 actions. ``reach`` (m) is the dx range's
    half width: at density 1 the dx values stay :data:`DX_SPACING` apart,
    ``1 + 2 round(reach / 0.05)`` of them (reach 0.30 -> 13: (13, 8, 7) -> 720 actions).
    """
    if not np.isfinite(density) or density <= 0:
        raise ValueError(f"density must be a positive finite number, got {density!r}")
    _check_reach(reach)
    half = max(1, round(reach / DX_SPACING))  # dx values either side of 0 at density 1 (4 for the paper's 0.2 m)
    n_dx = 1 + 2 * max(1, round(half * density))
    n_dy = 1 + max(1, round(7 * density))
    n_dt = 1 + 2 * max(1, round(3 * density))
    return n_dx, n_dy, n_dt


def _check_reach(reach) -> None:
    if isinstance(reach, bool) or not isinstance(reach, (int, float, np.integer, np.floating)):
        raise ValueError(f"reach must be a number (the largest forward/backward step, m), got {reach!r}")
    if not (np.isfinite(reach) and reach > 0):
        raise ValueError(f"reach must be a positive finite number (the largest forward/backward step, m), "
                         f"got {reach!r}")


HRP2_P0 = (0.0, 0.19, 0.0)
"""HRP-2's step in place (m, m, rad): the swing foot beside the stance foot. A host constant, so checks of
sweep files need no device (nothing may start a JAX backend before ``jax.distributed.initialize``)."""
_HRP2_BODY = {"foot_length": 0.242, "foot_width": 0.13, "step_time": 0.8, "p0": HRP2_P0}
_HRP2_DY = (0.19, 0.33)  # m: HRP-2's lateral range of the swing foot from the stance foot


def hrp2(margin: float = 0.02, density: float = 1.0, *, reach: float = PAPER_REACH, **overrides) -> Robot:
    """The paper's HRP-2: footprint 24.2 x 13 cm, 496 actions per foot.

    Actions: dx in [-20, 20] cm (9 values, 5 cm apart), dy in [19, 33] cm from
    the stance foot (8 values, 2 cm apart), dtheta in [-20, 20] deg (7 values),
    less the 8 corners of that box: 9 x 8 x 7 - 8 = 496. ``density`` scales the
    lattice (:func:`density_counts`) over the same ranges, for action-set size
    sweeps. Step time 0.8 s; step in place p0 = (0, 0.19 m, 0). Safety margin:
    the paper used 2 cm (motion capture), 5 cm (vision) and 10 cm (real robot).

    Stairs. With the paper's reach (steps at most 0.20 m ahead of the stance
    foot) the stance foot's toe is always ahead of the swing foot's heel
    (0.20 - 0.242 / 2 = 0.079 m < 0.242 / 2 + margin), so a riser across both
    lanes can only be crossed by a foot straddling it. The roughness, bump and
    slope terms make that costlier than marking time (at w = 1) from a riser
    of 1.3 to 2 cm, depending on where it falls under the foot, and their
    limits refuse it by 5 cm: the robot marks time before it (the paper's
    geometry: it stepped onto obstacles in one lane). A foot clears a riser
    between the feet only if it lands at least ``foot_length + 2 margin``
    (0.282 m at 2 cm) ahead of the stance foot: ``reach=0.30`` gives dx in
    [-30, 30] cm (13 values, 5 cm apart; 13 x 8 x 7 - 8 = 720 actions) and,
    unless overridden, ``max_step_height`` :data:`STAIR_STEP_HEIGHT` (15 cm
    risers). ``clearance`` stays 0.10 m: the swing corridor is measured from
    the higher foothold, and a stair's nosing between the two footholds is
    never above it. A tread holds a foot with its margin if it is at least
    0.282 m deep; with 5 cm steps the feet's x stay on one 5 cm lattice, and
    the 1.8 cm of slack (0.30 - 0.282) is enough when the risers keep the
    lattice's phase: treads a multiple of 5 cm (0.30 m: a tread per step;
    0.40 m: two steps per tread).

    Args:
      margin: safety margin (m).
      density: action-set density (1.0 -> 496 actions).
      reach: largest forward/backward step dx (m, > 0; default the paper's
        0.20). The farthest action must stay within ``max_sole_distance``.
      **overrides: any other :func:`make_robot` keyword (w, rotation_weight,
        step_time, action_cost, clearance, max_step_height, metrics, ...).

    Raises:
      ValueError: a reach that is not a positive finite number, or one that
        puts actions beyond ``max_sole_distance``.

    Example:
      >>> import ijoy_jax as ij
      >>> robot = ij.robots.hrp2(margin=0.05)
      >>> robot.actions.shape
      (496, 3)
      >>> stairs = ij.robots.hrp2(reach=0.30)
      >>> stairs.actions.shape, round(float(stairs.max_step_height[0]), 2)
      ((720, 3), 0.15)
    """
    _check_reach(reach)
    kwargs = dict(_HRP2_BODY, margin=margin)
    if reach > PAPER_REACH:
        kwargs["max_step_height"] = STAIR_STEP_HEIGHT
    kwargs.update(overrides)
    try:
        limit = float(kwargs.get("max_sole_distance", _signature_defaults(make_robot)["max_sole_distance"]))
    except (TypeError, ValueError):  # not a number (or traced): make_robot's check names it
        limit = math.nan
    farthest = math.hypot(reach, _HRP2_DY[1])
    if 0 <= limit < farthest:  # NaN, inf or < 0: make_robot's check names it
        raise ValueError(f"reach={reach!r} m puts the farthest action ({reach}, {_HRP2_DY[1]}) {farthest:.3f} m from "
                         f"the stance foot, beyond max_sole_distance = {float(limit)} m: its steps would always be "
                         "refused")
    return make_robot(hrp2_actions(density, reach), **kwargs)


def hrp2_actions(density: float = 1.0, reach: float = PAPER_REACH) -> np.ndarray:
    """(M, 3) float64 host array of :func:`hrp2`'s actions (dx, dy, dtheta in m, m, rad) at ``density`` and
    ``reach``, without building a robot (no device array: checks of sweep files run before any backend starts).

    Example:
      >>> hrp2_actions().shape, hrp2_actions(2.0).shape
      ((496, 3), (3307, 3))

    Raises:
      ValueError: a density above :data:`ijoy_jax.limits.MAX_DENSITY`, before the lattice is built (a robot
        of more than :data:`ijoy_jax.limits.MAX_ACTIONS` actions, at a longer reach, is refused by
        :func:`make_robot`).
    """
    counts = density_counts(density, reach)
    if density > MAX_DENSITY:
        raise ValueError(f"density must be <= ijoy_jax.limits.MAX_DENSITY = {MAX_DENSITY} ({MAX_ACTIONS} actions; "
                         f"the targets table grows as its sixth power), got {density!r}")
    return lattice_actions(counts, dx_range=(-reach, reach), dy_range=_HRP2_DY)


def start_stance(robot: Robot, x, y, theta=0.0, *, width=None) -> jax.Array:
    """(2, 3) float32 world poses of the feet standing side by side: row 0 left, row 1 right (m, m, rad).

    Both feet face ``theta``; their midpoint is ``(x, y)`` and they stand
    ``width`` metres apart across that heading (default ``robot.p0[1]``, the
    step in place, so the first decision can step in place). Pure JAX: the
    arguments may be traced.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> np.round(ij.robots.start_stance(ij.robots.hrp2(), 0.3, 1.0), 3).tolist()
      [[0.3, 1.095, 0.0], [0.3, 0.905, 0.0]]
    """
    half = 0.5 * (robot.p0[1] if width is None else jnp.asarray(width, jnp.float32))
    x, y, theta = (jnp.asarray(v, jnp.float32) for v in (x, y, theta))
    dx, dy = -half * jnp.sin(theta), half * jnp.cos(theta)  # the half-width along the heading's left
    return jnp.stack([jnp.stack([x + dx, y + dy, theta]), jnp.stack([x - dx, y - dy, theta])])


class LeafSpec(NamedTuple):
    """What a scalar Robot leaf means: its unit, its lower bound and whether the selector's cost uses it.

    Fields::

      unit: of the value (m, s, rad; cost/m: cost units per metre, m/rad: dist metres per radian).
      positive: True: must be > 0 (sizes, times); False: must be >= 0.
      selector: True for the parameters of the choice (FootCost + w dist), the ones
        ijoy_jax.tune may tune; False for the robot's body (footprint, step time, the
        ankles' tilt and the legs' reach limits).
    """

    unit: str
    positive: bool
    selector: bool


SCALAR_LEAVES: Mapping[str, LeafSpec] = MappingProxyType(
    {
        "w": LeafSpec("1", False, True),
        "rotation_weight": LeafSpec("m/rad", False, True),
        "margin": LeafSpec("m", False, True),
        "step_time": LeafSpec("s", True, False),
        "foot_length": LeafSpec("m", True, False),
        "foot_width": LeafSpec("m", True, False),
        "max_sole_pitch": LeafSpec("rad", False, False),
        "max_sole_roll": LeafSpec("rad", False, False),
        "max_sole_distance": LeafSpec("m", False, False),
        "metrics.slope_weight": LeafSpec("cost/rad", False, True),
        "metrics.slope_limit": LeafSpec("rad", False, True),
        "metrics.roughness_weight": LeafSpec("cost/m", False, True),
        "metrics.roughness_limit": LeafSpec("m", False, True),
        "metrics.bump_weight": LeafSpec("cost/m", False, True),
        "metrics.bump_limit": LeafSpec("m", False, True),
        "metrics.step_weight": LeafSpec("cost/m", False, True),
        "metrics.band_weight": LeafSpec("cost/m", False, True),
        "metrics.band_limit": LeafSpec("m", False, True),
        "metrics.support_weight": LeafSpec("cost/m", False, True),
        "metrics.support_limit": LeafSpec("m", False, True),
        "metrics.contact_inset": LeafSpec("m", False, True),
        "metrics.contact_tol": LeafSpec("m", False, True),
    }
)
"""Every scalar Robot leaf a user may sweep or tune, by dotted name (:func:`get_leaf`), in a fixed order."""

SELECTOR_LEAVES = tuple(n for n, spec in SCALAR_LEAVES.items() if spec.selector)
"""The names of :data:`SCALAR_LEAVES` that parameterise the choice (w, rotation_weight, margin, metrics.*)."""


def _signature_defaults(fn) -> dict:
    params = inspect.signature(fn).parameters.values()
    return {p.name: p.default for p in params if p.default is not inspect.Parameter.empty}


def hrp2_defaults() -> dict[str, float]:
    """name -> value of every :data:`SCALAR_LEAVES` leaf of ``hrp2()``, and its ``density`` and ``reach``, without
    building it.

    Read from the one source of each number: :func:`hrp2`'s arguments and body,
    :func:`make_robot`'s and :func:`default_metrics`' keyword defaults. The
    robot at the paper's reach (``density`` and ``reach`` shape the action set,
    and ``reach`` sets ``max_step_height``, a per-action leaf: none is a scalar
    leaf).

    Example:
      >>> from ijoy_jax import robots
      >>> d = robots.hrp2_defaults()
      >>> d["foot_length"], d["margin"], d["density"], float(robots.get_leaf(robots.hrp2(), "w")) == d["w"]
      (0.242, 0.02, 1.0, True)
    """
    top = {**_signature_defaults(make_robot), **_HRP2_BODY, **_signature_defaults(hrp2)}
    metrics = _signature_defaults(default_metrics)
    out = {n: float(metrics[n.partition(".")[2]] if n.startswith("metrics.") else top[n]) for n in SCALAR_LEAVES}
    out["density"] = float(top["density"])
    out["reach"] = float(top["reach"])
    return out


def get_leaf(robot: Robot, name: str):
    """The leaf of ``robot`` named by a dotted path, e.g. ``"w"`` or ``"metrics.slope_limit"``."""
    obj = robot
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def set_leaf(robot: Robot, name: str, value) -> Robot:
    """A copy of ``robot`` with the leaf at a dotted path (see :func:`get_leaf`) replaced by ``value``."""
    head, _, tail = name.partition(".")
    if tail:
        return robot.replace(**{head: set_leaf(getattr(robot, head), tail, value)})
    return robot.replace(**{name: value})


def set_leaves(robot: Robot, values: Mapping[str, Any]) -> Robot:
    """A copy of ``robot`` with every dotted name of ``values`` set (:func:`set_leaf` for each; traceable).

    Example:
      >>> from ijoy_jax import robots
      >>> r = robots.set_leaves(robots.hrp2(), {"w": 2.0, "metrics.bump_limit": 0.03})
      >>> float(r.w), float(r.metrics.bump_limit)
      (2.0, 0.03)
    """
    for name, value in values.items():
        robot = set_leaf(robot, name, value)
    return robot


def side_sign(side) -> jax.Array:
    """() float32 +1 for a side >= 0 (left), -1 otherwise (right): the one reading of a side flag."""
    return jnp.where(jnp.asarray(side) >= 0, 1.0, -1.0).astype(jnp.float32)


def mirror(swing_side, rel) -> jax.Array:
    """(..., 3) a left-foot pose or action ``(dx, dy, dtheta)`` as seen by the foot on ``swing_side``.

    Left (+1): unchanged; right (-1): ``(dx, -dy, -dtheta)``. Its own inverse.
    """
    sign = jnp.asarray(swing_side, jnp.float32)
    return rel * jnp.stack([jnp.ones_like(sign), sign, sign])


def side_actions(robot: Robot, swing_side) -> jax.Array:
    """(N, 3) actions of the swing foot on ``swing_side`` (+1 left, -1 right).

    Left: ``robot.actions``; right: their mirror (dx, -dy, -dtheta).
    """
    return mirror(swing_side, robot.actions)


def side_p0(robot: Robot, swing_side) -> jax.Array:
    """(3,) step-in-place action for the swing foot on ``swing_side`` (+1 left, -1 right)."""
    return mirror(swing_side, robot.p0)


def action_steps(robot: Robot, stance, stance_side) -> jax.Array:
    """(N, 3) world poses of the swing foot for every action of S.

    Args:
      robot: the robot model (N = robot.num_actions).
      stance: (3,) world pose of the stance foot (m, rad).
      stance_side: +1 for a left stance foot (the right foot swings, with the
        mirrored actions), -1 for a right stance foot.

    Example:
      >>> import ijoy_jax as ij
      >>> ij.action_steps(ij.robots.hrp2(), [0.0, 0.0, 0.0], -1).shape
      (496, 3)
    """
    stance = jnp.asarray(stance, jnp.float32)
    return geometry.compose(stance, side_actions(robot, -side_sign(stance_side)))


def dist(a: jax.Array, b: jax.Array, rotation_weight, *, grad_safe: bool = False) -> jax.Array:
    """The paper's dist between poses in one frame: ``|dxy| + rotation_weight * |wrap(dtheta)|``.

    Args:
      a, b: (..., 3) poses (x, y, theta) in one frame (m, rad); broadcast.
      rotation_weight: cost units per radian (``Robot.rotation_weight``).
      grad_safe: static. False (the exact selector): ``|dxy|`` by ``jnp.hypot``.
        True (what is differentiated, :mod:`ijoy_jax.tune`): by
        :func:`ijoy_jax.geometry.safe_norm`, whose gradient at dxy = 0 is 0, not NaN.

    Returns:
      (...) float32 distances (cost units before ``w``).

    Example:
      >>> import jax.numpy as jnp
      >>> from ijoy_jax.robots import dist
      >>> round(float(dist(jnp.array([0.3, 0.4, 0.1]), jnp.zeros(3), 2.0)), 6)
      0.7
    """
    d = a - b
    norm = geometry.safe_norm if grad_safe else jnp.hypot
    return norm(d[..., 0], d[..., 1]) + rotation_weight * jnp.abs(geometry.wrap_angle(d[..., 2]))


def nearest_actions(robot: Robot, stance, stance_side, steps) -> jax.Array:
    """(N,) int32 index of the action of S nearest each world step (:func:`dist` in the stance frame).

    Args:
      robot: the robot model.
      stance: (3,) world pose of the stance foot; stance_side: +1 left, -1 right.
      steps: (N, 3) world poses of the swing foot.
    """
    stance, steps = jnp.asarray(stance, jnp.float32), jnp.asarray(steps, jnp.float32)
    rel = geometry.relative(stance, steps)  # (N, 3)
    acts = side_actions(robot, -side_sign(stance_side))
    return jnp.argmin(dist(rel[:, None, :], acts[None, :, :], robot.rotation_weight), axis=1).astype(jnp.int32)


def command_range(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (3,): the joystick commands (m/s, m/s, rad/s) the action set can realise.

    With p_next = p0 + dt j, the commands span the actions' extent around p0:
    xdot over [min dx - p0x, max dx - p0x] / dt, ydot over +-(max dy - p0y) / dt
    (the lateral room beyond the step in place, either way), thetadot over
    +-max ``|dtheta|`` / dt.
    """
    acts = np.asarray(robot.actions)
    p0, dt = np.asarray(robot.p0), float(robot.step_time)
    lo = np.array([acts[:, 0].min() - p0[0], -(acts[:, 1].max() - p0[1]), -np.abs(acts[:, 2]).max()]) / dt
    hi = np.array([acts[:, 0].max() - p0[0], acts[:, 1].max() - p0[1], np.abs(acts[:, 2]).max()]) / dt
    return lo, hi


def random_commands(key, robot: Robot, batch: int, num_steps: int, hold: int = 1) -> jax.Array:
    """(batch, num_steps, 3) joystick commands, uniform over :func:`command_range`.

    Each command is held for ``hold`` steps (1: a new one every step, the
    harshest joystick; ``num_steps``: one command per robot for the whole run).
    ``key``: PRNG key or int seed.
    """
    if hold < 1:
        raise ValueError(f"hold must be at least 1 step, got {hold}")
    lo, hi = command_range(robot)
    n = -(-num_steps // hold)
    u = jax.random.uniform(as_key(key), (batch, n, 3), jnp.float32)
    u = jnp.repeat(u, hold, axis=1)[:, :num_steps]
    return jnp.asarray(lo, jnp.float32) + u * jnp.asarray(hi - lo, jnp.float32)
