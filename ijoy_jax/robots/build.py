"""Building a valid Robot, and the rules that say what valid is.

:func:`~ijoy_jax.robots.make_robot` and :func:`~ijoy_jax.robots.default_metrics` validate their arguments and
build the pytrees; :func:`~ijoy_jax.robots.check_robot` applies the same rules, where values are concrete, to a
robot changed since (``replace``, :func:`~ijoy_jax.robots.set_leaves`), and
:func:`~ijoy_jax.robots.robot_supported` folds them into one traced flag: one rule list serves both. The
footprint test (the swing foot's rectangle after an action must not overlap the stance foot's) is one of those
rules; :func:`~ijoy_jax.robots.overlaps_stance` is its traced form for steps off the action set's lattice.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.limits import MAX_ACTIONS
from ijoy_jax.robots.lattice import target_lattice
from ijoy_jax.robots.leaves import get_leaf
from ijoy_jax.robots.robot import Robot, TerrainMetrics


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


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _check_scalar(name, value, positive=False, nonneg=False):
    if not _is_concrete(value):
        return
    try:
        v = np.asarray(value, np.float64)
    except OverflowError:  # a Python int beyond float64 (10**400)
        raise ValueError(f"{name} must be finite, got an integer beyond float64") from None
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
    # The candidate axes: the normals of both rectangles' edges (corner i to i + 1), all eight at once (arrays,
    # not a loop over the edges: robot_supported runs in every selector program, and a loop lowers to many
    # times the operations, which XLA compiles anew in each).
    polys = xp.stack([stance, swing], 1)  # (N, 2, 4, 2)
    e = (xp.roll(polys, -1, axis=2) - polys).reshape(-1, 8, 2)
    n = xp.stack([-e[..., 1], e[..., 0]], -1)[:, :, None, :]  # (N, 8, 1, 2)
    n = n / xp.maximum(xp.sqrt(xp.sum(n * n, -1, keepdims=True)), 1e-12)  # unit axes: tol in metres
    pa, pb = xp.sum(stance[:, None] * n, -1), xp.sum(swing[:, None] * n, -1)  # (N, 8, 4) projections
    separated = (pa.max(-1) <= pb.min(-1) + tol) | (pb.max(-1) <= pa.min(-1) + tol)
    return ~xp.any(separated, axis=1)


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
            f"robot with that margin or size (make_robot(..., max_margin=...), hrp2(margin=...)) instead of replace"
        )
    inset = values.get("metrics.contact_inset")
    if all(v is not None for v in size[:2]) and inset is not None and not _inset_inside(*size[:2], inset):
        raise ValueError(
            f"robot.metrics.contact_inset must be under half the foot's width and length "
            f"({0.5 * float(min(size[:2]))} m): the sole's contact points lie on both sides of its "
            f"centre, got {float(inset)}"
        )
    if all(v is not None for v in size[:2]) and "actions" in values:
        bad = footprints_overlap(values["actions"], float(size[0]), float(size[1]))
        if bad.any():
            raise ValueError(
                f"robot.actions: {int(bad.sum())} action(s) make the swing and stance footprints "
                f"overlap with foot_length {float(size[0])} m, foot_width {float(size[1])} m, e.g. "
                f"action {values['actions'][np.argmax(bad)].tolist()}"
            )


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
        raise ValueError(
            f"{acts.shape[0]} actions are above ijoy_jax.limits.MAX_ACTIONS = {MAX_ACTIONS} (the "
            f"targets table grows with their number)"
        )
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
    for name, v in (
        ("foot_length", foot_length),
        ("foot_width", foot_width),
        ("margin", margin),
        ("max_margin", max_margin),
    ):
        if v is not None and float(v) > MAX_SIZE:
            raise ValueError(
                f"{name} must be <= {MAX_SIZE:g} m (robots.MAX_SIZE: the static windows grow with it), got {float(v)}"
            )
    for name, value in (
        ("max_sole_pitch", max_sole_pitch),
        ("max_sole_roll", max_sole_roll),
        ("max_sole_distance", max_sole_distance),
    ):
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
