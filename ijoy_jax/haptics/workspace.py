"""Linearised workspace of a cylinder-driven mechanism and its repulsive force (paper section 3).

For an end-effector ``x = Phi(q)`` driven by ``k`` cylinders with strokes
``q_min <= q <= q_max``, each cylinder moved alone to its ends of stroke moves
the end-effector (to first order) by the generator pair (eq. 5)::

    e_i^- = dq_i^- J_i,   e_i^+ = dq_i^+ J_i,   dq^- = q_min - q <= 0 <= dq^+ = q_max - q,

with ``J = dPhi/dq`` (3, k). The linearised workspace is the zonotope
``Z = {sum_i t_i J_i : dq_i^- <= t_i <= dq_i^+}`` around the current position;
for k = 4 generic columns it has 14 vertices and 12 rhombic facets (the
paper's "dodecahedron"). Every facet normal is a cross product of two
columns (eq. 8), ``n_mn = J_m x J_n / |J_m x J_n|``, and the facet on the
side ``+n`` lies at the support distance (eqs. 9-11)::

    h(n) = sum_i max(e_i^+ . n, e_i^- . n) = sum_i (dq_i^+ if J_i . n > 0 else dq_i^-) (J_i . n),

i.e. each remaining cylinder is taken to the end of stroke picked by the sign
of ``J_i . n`` (the paper's sign rule on ``e_i^+ . n`` is undefined when
``e_i^+ = 0`` at an end of stroke). Each pair gives two planes, ``+n`` at
``h(n)`` and ``-n`` at ``h(-n)``; their side is known from this construction,
so a plane touching the end-effector (distance 0) still pushes (``sgn(0) = 0``
in eq. 12 would drop exactly the strongest term).

Degenerate inputs never give NaN. Pairs of (numerically) parallel columns, or
columns of a cylinder with zero stroke or a zero Jacobian column, define no
plane; pairs that span the same plane (e.g. three coplanar columns) give
coincident planes, merged to one row (to within the rounding error of their
normals, see ``MERGE_FACTOR``). If all columns are coplanar (a flat zonotope)
the in-plane edges ``n x J_i`` are added, and if they are all parallel (or
zero) an orthonormal frame is used, so ``{dx : A dx <= b}`` is always exactly
the zonotope.

Note on eq. 13: it sums over facets, so three nearly coplanar columns give
three nearly coincident facets that each push, while exactly coplanar ones give
one facet: the paper's force is discontinuous at such configurations (e.g. the
ALDURO leg when its foot passes straight below the hip axes). We keep eq. 13
as printed; the merge band is as thin as rounding allows (~2e-5 rad in float32
for columns at right angles), so a sweep meets the jump only at that instant.

Repulsive force (eqs. 12-13), one term per distinct plane with outward unit
normal ``n`` at distance ``d >= 0``::

    f = sum_planes -n C1 C2^d      or, unit-consistent,      f = sum_planes -n C1 exp(-d / lambda)

(``C2^d`` depends on the unit of d; ``lambda = -1 / ln C2`` is the decay length
in metres). The constants must be finite with ``0 <= C1 <= C1_MAX`` (so no sum
of terms overflows), ``0 < C2 <= 1`` and ``lambda > 0``: concrete values outside
raise a ValueError naming them (:func:`check_repulsion`); traced ones give a
zero force, flagged in ``PlaneForces.bad_constants`` (never NaN, never an
attraction or a force that grows with distance). Fixed shapes throughout (``R = k(k-1) + 2k + 6`` candidate rows with
a ``valid`` mask), so everything jits, vmaps and differentiates;
:func:`workspace_halfspaces` returns the compact rows for inspection.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


class Planes(NamedTuple):
    """Limiting planes of a linearised workspace, fixed shape ``R = k(k-1) + 2k + 6``.

    Row layout (static, see :func:`plane_labels`): pair ``p = (m, n)`` gives rows
    ``2p`` (normal ``+J_m x J_n``) and ``2p + 1`` (its opposite); then ``2k`` in-plane
    edge rows (used only for a flat zonotope); then 6 frame rows (used only when
    all columns are parallel or zero).

    Fields::

      normals: (R, 3) unit outward normals; zero rows where not valid.
      offsets: (R,) distance d >= 0 from the current position to each plane along
        its normal, metres (0 where not valid).
      valid: (R,) bool, True for exactly one row per distinct limiting plane.
    """

    normals: jax.Array
    offsets: jax.Array
    valid: jax.Array


class Workspace(NamedTuple):
    """A mechanism's linearised workspace at one configuration.

    Fields (k cylinders)::

      position: (3,) end-effector position x = Phi(q), metres.
      jacobian: (3, k) J = dPhi/dq.
      travel_minus: (k,) dq^- = q_min - q <= 0 (after clamping), cylinder units (m).
      travel_plus: (k,) dq^+ = q_max - q >= 0 (after clamping).
      out_of_range: (k,) bool, True where q was outside [q_min, q_max] (or not
        finite) and was clamped to the stroke before linearising.
      planes: Planes.
    """

    position: jax.Array
    jacobian: jax.Array
    travel_minus: jax.Array
    travel_plus: jax.Array
    out_of_range: jax.Array
    planes: Planes


def pair_indices(k: int) -> np.ndarray:
    """(k(k-1)/2, 2) int array of the column pairs (m, n), m < n, in row order."""
    return np.array(list(itertools.combinations(range(k), 2)), dtype=np.int32).reshape(-1, 2)


def plane_labels(k: int) -> list[str]:
    """Human-readable label of each of the R rows of :class:`Planes` (1-based as in the paper)."""
    labels = []
    for m, n in pair_indices(k):
        labels += [f"+n{m + 1}{n + 1}", f"-n{m + 1}{n + 1}"]
    for i in range(k):
        labels += [f"+edge{i + 1}", f"-edge{i + 1}"]
    return labels + ["+u", "-u", "+v1", "-v1", "+v2", "-v2"]


def num_planes(k: int) -> int:
    """Number of candidate rows R for k cylinders."""
    return k * (k - 1) + 2 * k + 6


#: Merge factor: planes from pairs p, q are one plane when the sine of the angle between their
#: normals is below ``MERGE_FACTOR * eps * (1 / sin_p + 1 / sin_q)``, with ``sin_p`` the sine of the
#: angle between pair p's columns. A normal computed from unit columns carries an error of about
#: ``6 eps / sin_p`` (cross product of rounded unit vectors, then normalised), so 64 leaves a margin
#: of ~4x for inputs that are themselves rounded (e.g. Jacobians by float32 autodiff). The tolerance
#: is as tight as the data allow: the force of eq. 13 (which counts nearly coincident facets
#: separately, but exactly coincident ones once) is exact outside this thin band.
MERGE_FACTOR = 64.0


def _tolerances(dtype):
    """``(eps, sin_tol)``: columns closer than ``sin_tol`` (sine of their angle) define no plane.

    A cross product of columns at an angle with sine s has a direction error ~eps / s, so at
    s >= sqrt(eps) normals are good to ~sqrt(eps) (3.5e-4 in float32, 1.5e-8 in float64); the
    same relative threshold marks a generator segment as zero.
    """
    eps = float(jnp.finfo(dtype).eps)
    return eps, float(np.sqrt(eps))


# Small fixed-size reductions (over the 3 coordinates, the k cylinders or the
# k(k-1)/2 pairs) are written as sums of static slices: XLA then fuses the whole
# plane construction into a handful of kernels, which is what keeps one force
# evaluation well inside a 1 kHz loop's budget on CPU (a reduce ends a fusion).


def _unrolled(op, x):
    """Reduce the last axis of ``x`` with the binary ``op``, unrolled over its static size."""
    out = x[..., 0]
    for i in range(1, x.shape[-1]):
        out = op(out, x[..., i])
    return out


def _dot(a, b):
    """``sum(a * b, axis=-1)`` for a last axis of size 3."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross(a, b):
    return jnp.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _safe_normalize(v, ok):
    """``v / |v|`` along the last axis (size 3) where ``ok``, else 0; finite gradients everywhere."""
    sq = _dot(v, v)
    ok = ok & (sq > 0)
    return jnp.where(ok[..., None], v / jnp.sqrt(jnp.where(ok, sq, 1.0))[..., None], 0.0)


def _norm(v):
    sq = _dot(v, v)
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def _pick_best(values, rows):
    """``rows[argmax(values)]`` (first maximum), unrolled; ``values`` (P,), ``rows`` (P, 3)."""
    best_v, best_r = values[0], rows[0]
    for i in range(1, values.shape[0]):
        better = values[i] > best_v
        best_v = jnp.where(better, values[i], best_v)
        best_r = jnp.where(better, rows[i], best_r)
    return best_r


def _repeats(directions, ok, conditioning, eps):
    """(P,) bool: ``ok`` rows whose direction is parallel (either sense) to an earlier ``ok`` row.

    ``directions`` (P, 3) unit vectors; ``conditioning`` (P,) the sine of the angle between the
    columns each direction was computed from; rows a, b are parallel when
    ``|a x b| < MERGE_FACTOR * eps * (1 / conditioning_a + 1 / conditioning_b)``.
    """
    a, b = directions[:, None, :], directions[None, :, :]
    inv = 1.0 / jnp.where(ok, conditioning, 1.0)
    parallel = _norm(_cross(a, b)) < MERGE_FACTOR * eps * (inv[:, None] + inv[None, :])
    earlier = np.tril(np.ones((directions.shape[0],) * 2, bool), k=-1)
    return ok & jnp.any(parallel & earlier & ok[None, :], axis=1)


def support(normals, jacobian, travel_minus, travel_plus):
    """Support function ``h(n) = sum_i max(e_i^+ . n, e_i^- . n)`` of the zonotope.

    Args:
      normals: (..., 3) directions.
      jacobian: (3, k).
      travel_minus, travel_plus: (k,) with ``travel_minus <= 0 <= travel_plus``.

    Returns:
      (...,) the largest ``n . dx`` over the linearised workspace (metres for unit n).
    """
    jac = jnp.asarray(jacobian)
    a = normals[..., 0:1] * jac[0] + normals[..., 1:2] * jac[1] + normals[..., 2:3] * jac[2]  # (..., k) J_i . n
    # The end of stroke is picked by the sign of J_i . n (equal to the max above
    # for travel_minus <= 0 <= travel_plus; defined even when e_i^+ = 0).
    return _unrolled(jnp.add, jnp.where(a > 0, travel_plus * a, travel_minus * a))


def zonotope_generators(jacobian, travel_minus, travel_plus) -> tuple[jax.Array, jax.Array]:
    """The generator pairs of eq. 5: ``(e_minus, e_plus)``, each (k, 3), metres."""
    cols = jnp.asarray(jacobian).T
    return jnp.asarray(travel_minus)[:, None] * cols, jnp.asarray(travel_plus)[:, None] * cols


def _clean_inputs(jacobian, travel_minus, travel_plus):
    """Clamp travels to the right sign and zero non-finite entries; per-cylinder flags."""
    jac = jnp.asarray(jacobian)
    dtype = jnp.result_type(jac.dtype, float)
    jac = jac.astype(dtype)
    tm = jnp.asarray(travel_minus, dtype)
    tp = jnp.asarray(travel_plus, dtype)
    fin = jnp.isfinite(jac)
    col_ok = fin[0] & fin[1] & fin[2] & jnp.isfinite(tm) & jnp.isfinite(tp)
    jac = jnp.where(col_ok[None, :], jac, 0.0)
    bad = (~col_ok) | (tm > 0) | (tp < 0)
    tm = jnp.where(col_ok, jnp.minimum(tm, 0.0), 0.0)
    tp = jnp.where(col_ok, jnp.maximum(tp, 0.0), 0.0)
    return jac, tm, tp, bad


def _orthonormal_frame(u):
    """Two unit vectors completing the unit vector ``u`` (3,) to an orthonormal frame."""
    au = jnp.abs(u)
    # The coordinate axis least aligned with u (first one on ties).
    ex = (au[0] <= au[1]) & (au[0] <= au[2])
    ey = ~ex & (au[1] <= au[2])
    axis = jnp.stack([ex, ey, ~ex & ~ey]).astype(u.dtype)
    v1 = _cross(u, axis)
    v1 = v1 / jnp.sqrt(_dot(v1, v1))
    return v1, _cross(u, v1)


def _rank_deficient_rows(unit, nonzero, seg, ref, flat, eps):
    """(2k + 6, 3) normals and (2k + 6,) mask of the extra rows of a flat or lower-rank zonotope."""
    edge_ok = nonzero & flat
    edge = _safe_normalize(_cross(ref[None, :], unit), edge_ok)
    edge_ok = edge_ok & ~_repeats(edge, edge_ok, jnp.ones_like(seg), eps)
    low_rank = ~flat
    longest = _pick_best(jnp.where(nonzero, seg, -1.0), unit)
    u = jnp.where(_unrolled(jnp.logical_or, nonzero), longest, jnp.array([1.0, 0.0, 0.0], unit.dtype))
    v1, v2 = _orthonormal_frame(u)
    normals = jnp.concatenate(
        [
            jnp.stack([edge, -edge], axis=1).reshape(-1, 3),
            jnp.where(low_rank, jnp.stack([u, -u, v1, -v1, v2, -v2]), 0.0),
        ]
    )
    return normals, jnp.concatenate([jnp.repeat(edge_ok, 2), jnp.broadcast_to(low_rank, (6,))])


@jax.jit
def limiting_planes(jacobian, travel_minus, travel_plus) -> Planes:
    """The distinct limiting planes of the linearised workspace (fixed shape, jit/vmap-able).

    Travels of the wrong sign (q outside its stroke) are clamped to 0 and
    non-finite columns are dropped (see :func:`check_travel` for the flags);
    the result is always finite.

    Args:
      jacobian: (3, k) J = dPhi/dq (metres per cylinder unit).
      travel_minus: (k,) q_min - q <= 0.
      travel_plus: (k,) q_max - q >= 0.

    Returns:
      Planes with ``R = k(k-1) + 2k + 6`` rows: unit normals, distances (m), valid mask.

    Example:
      >>> p = limiting_planes(jnp.eye(3), -jnp.ones(3), jnp.ones(3))  # a cube
      >>> int(p.valid.sum()), float(p.offsets[p.valid].max())
      (6, 1.0)
    """
    jac, tm, tp, _ = _clean_inputs(jacobian, travel_minus, travel_plus)
    k = jac.shape[1]
    dtype = jac.dtype
    eps, sin_tol = _tolerances(dtype)
    cols = jac.T  # (k, 3)
    seg = _norm(cols) * (tp - tm)  # length of each generator segment, metres
    nonzero = seg > sin_tol * _unrolled(jnp.maximum, seg)  # all False when every segment is 0
    unit = _safe_normalize(cols, nonzero)

    pairs = pair_indices(k)
    rows, ok_rows = [], []
    if len(pairs):
        # Static slices, not gathers: they fuse.
        um = jnp.stack([unit[i] for i in pairs[:, 0]])
        un = jnp.stack([unit[i] for i in pairs[:, 1]])
        okm = jnp.stack([nonzero[i] for i in pairs[:, 0]])
        okn = jnp.stack([nonzero[i] for i in pairs[:, 1]])
        cross = _cross(um, un)  # |cross| = sin of the angle between the columns
        sin = _norm(cross)
        pair_ok = okm & okn & (sin > sin_tol)
        nrm = _safe_normalize(cross, pair_ok)
        # Pairs spanning the same plane (e.g. three coplanar columns) give coincident
        # planes: keep the first such pair (both of its sides), drop the others.
        pair_ok = pair_ok & ~_repeats(nrm, pair_ok, sin, eps)
        rows.append(jnp.stack([nrm, -nrm], axis=1).reshape(-1, 3))
        ok_rows.append(jnp.repeat(pair_ok, 2))
        # After merging, the columns span 3D iff at least two distinct pair planes remain.
        n_pair_planes = _unrolled(jnp.add, pair_ok.astype(jnp.int32))
        ref = jnp.sum(jnp.where(pair_ok[:, None], nrm, 0.0), axis=0)  # the single plane's normal when flat
    else:
        n_pair_planes = jnp.array(0, jnp.int32)
        ref = jnp.zeros(3, dtype)
    # Rank-deficient extras (lax.cond: a generic Jacobian skips them): a flat
    # zonotope (one pair plane) gets its in-plane edges; parallel or zero columns
    # (no pair plane) get the segment's direction and a frame around it.
    extra_normals, extra_ok = jax.lax.cond(
        n_pair_planes <= 1,
        _rank_deficient_rows,
        lambda *_: (jnp.zeros((2 * k + 6, 3), dtype), jnp.zeros(2 * k + 6, bool)),
        unit,
        nonzero,
        seg,
        ref,
        n_pair_planes == 1,
        eps,
    )
    rows.append(extra_normals)
    ok_rows.append(extra_ok)
    # The groups never share a plane: edges are perpendicular to the single pair
    # plane's normal, and the frame is used only when no pair plane exists.
    valid = jnp.concatenate(ok_rows, axis=0)
    normals = jnp.where(valid[:, None], jnp.concatenate(rows, axis=0), 0.0)
    h = support(normals, jac, tm, tp)
    # A workspace too large for the dtype (support overflowed): its planes are as far as representable.
    offsets = jnp.where(valid, jnp.where(jnp.isfinite(h), h, jnp.finfo(dtype).max), 0.0)
    return Planes(normals=normals, offsets=offsets, valid=valid)


def check_travel(travel_minus, travel_plus) -> jax.Array:
    """(k,) bool: True where a travel has the wrong sign or is not finite (q outside its stroke).

    Two NumPy arrays are checked in NumPy (exact IEEE comparisons: a subnormal travel_minus of 1e-45 m is
    outside its stroke), as the boundary checks do; anything else in JAX, where XLA's CPU backend flushes
    subnormals to zero, so such a travel reads as 0.
    """
    xp = np if isinstance(travel_minus, np.ndarray) and isinstance(travel_plus, np.ndarray) else jnp
    tm, tp = xp.asarray(travel_minus), xp.asarray(travel_plus)
    return ~(xp.isfinite(tm) & xp.isfinite(tp) & (tm <= 0) & (tp >= 0))


def _is_concrete(*xs) -> bool:
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(xs))


def _validate(jacobian, travel_minus, travel_plus):
    """Shape checks always; value checks (clear errors) when called outside jit."""
    jac = jnp.asarray(jacobian)
    tm, tp = jnp.asarray(travel_minus), jnp.asarray(travel_plus)
    if jac.ndim != 2 or jac.shape[0] != 3:
        raise ValueError(f"jacobian must have shape (3, k), got {jac.shape}")
    k = jac.shape[1]
    if tm.shape != (k,) or tp.shape != (k,):
        raise ValueError(f"travel_minus and travel_plus must have shape ({k},), got {tm.shape}, {tp.shape}")
    if _is_concrete(jacobian, travel_minus, travel_plus):
        if not np.all(np.isfinite(np.asarray(jac))):
            raise ValueError("jacobian has non-finite entries")
        # in NumPy: through XLA a subnormal travel of the wrong sign reads as 0 and passed the boundary
        bad = np.flatnonzero(check_travel(np.asarray(travel_minus), np.asarray(travel_plus)))
        if bad.size:
            raise ValueError(
                f"cylinders {bad.tolist()} are outside their stroke: need travel_minus <= 0 <= travel_plus "
                f"(q_min <= q <= q_max), got travel_minus={np.asarray(tm)[bad].tolist()}, "
                f"travel_plus={np.asarray(tp)[bad].tolist()}"
            )


def workspace_halfspaces(jacobian, travel_minus, travel_plus) -> tuple[jax.Array, jax.Array]:
    """The linearised workspace as ``{dx : A @ dx <= b}`` around the current end-effector position.

    One row per distinct limiting plane, unit normals. The number of rows
    depends on the data (12 for four generic cylinders), so this is a host-side
    view: under jit/vmap use :func:`limiting_planes` (fixed shape plus mask).

    Args:
      jacobian: (3, k) J = dPhi/dq.
      travel_minus: (k,) travel of each cylinder to its lower end of stroke, <= 0.
      travel_plus: (k,) travel to its upper end of stroke, >= 0.

    Returns:
      ``(A (m, 3), b (m,))``: unit outward normals and distances b >= 0 in metres.

    Raises:
      ValueError: wrong shapes, non-finite values, or a travel of the wrong sign.

    Example:
      >>> J = jnp.array([[1.0, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1]])
      >>> A, b = workspace_halfspaces(J, -0.1 * jnp.ones(4), 0.2 * jnp.ones(4))
      >>> A.shape, b.shape
      ((12, 3), (12,))
    """
    _validate(jacobian, travel_minus, travel_plus)
    p = limiting_planes(jacobian, travel_minus, travel_plus)
    keep = np.asarray(p.valid)
    return p.normals[keep], p.offsets[keep]


class PlaneForces(NamedTuple):
    """Repulsive force and its terms.

    Fields::

      force: (3,) sum of the terms, newtons (units of C1).
      terms: (R,) magnitudes ``C1 exp(-d / lambda)`` of each plane's term (0 where not valid).
      bad_constants: () bool, True when C1 or the decay rate was invalid (non-finite,
        negative, or C1 above :func:`c1_max`): then force and terms are zero.
    """

    force: jax.Array
    terms: jax.Array
    bad_constants: jax.Array


def c1_max(dtype=None) -> float:
    """Largest accepted C1 (N): ``sqrt(finfo(dtype).max)`` (1.8e19 N in float32), so no sum of terms overflows."""
    return float(np.sqrt(jnp.finfo(jnp.result_type(float) if dtype is None else dtype).max))


def _concrete_values(value):
    if isinstance(value, jax.core.Tracer):
        return None
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return np.array(np.nan)  # not a number: reported as out of range, with the value


def check_repulsion(c1, *, decay_length=None, decay_rate=None, c2=None) -> None:
    """Raise ValueError naming the constant if a concrete C1, decay length/rate or C2 is invalid.

    Valid: ``0 <= c1 <= c1_max()`` (N), ``decay_length > 0`` (m), ``decay_rate >= 0`` (1/m),
    ``0 < c2 <= 1``, all finite. Traced values are skipped (they are handled by the
    zero-force rule of :func:`plane_forces`).
    """
    for name, value in (("c1", c1), ("decay_length", decay_length), ("decay_rate", decay_rate), ("c2", c2)):
        if value is not None and jnp.ndim(value) != 0:
            raise ValueError(f"{name} must be a scalar, got shape {jnp.shape(value)}")
    v = _concrete_values(c1)
    if v is not None and not np.all(np.isfinite(v) & (v >= 0) & (v <= c1_max())):
        raise ValueError(f"c1 must be finite and in [0, {c1_max():.3g}] N, got {c1!r}")
    for name, value, ok in (
        ("decay_length", decay_length, lambda x: x > 0),
        ("decay_rate", decay_rate, lambda x: x >= 0),
        ("c2", c2, lambda x: (x > 0) & (x <= 1)),
    ):
        v = None if value is None else _concrete_values(value)
        if v is not None and not np.all(np.isfinite(v) & ok(v)):
            rule = {"decay_length": "finite and > 0 (m)", "decay_rate": "finite and >= 0 (1/m)", "c2": "in (0, 1]"}
            raise ValueError(f"{name} must be {rule[name]}, got {value!r}")


def plane_forces(planes: Planes, c1, decay_rate) -> PlaneForces:
    """Per-plane repulsion ``-n C1 exp(-decay_rate d)`` and its sum (eqs. 12-13).

    Args:
      planes: from :func:`limiting_planes`.
      c1: force scale C1 (N), the magnitude of a plane's push at distance 0,
        ``0 <= c1 <= c1_max()``.
      decay_rate: 1 / lambda in 1/m (= -ln C2 when d is in metres), finite and >= 0.

    Returns:
      PlaneForces; always finite. Invalid constants raise where concrete; traced
      ones give a zero force with ``bad_constants`` set (never NaN or an attraction).

    Example:
      >>> out = plane_forces(limiting_planes(jnp.eye(3), -jnp.ones(3), jnp.ones(3)), 1.0, 20.0)
      >>> bool(jnp.allclose(out.force, 0.0)), bool(out.bad_constants)  # centred in a cube
      (True, False)
    """
    check_repulsion(c1, decay_rate=decay_rate)
    return _plane_forces(planes, c1, decay_rate)


@jax.jit
def _plane_forces(planes: Planes, c1, decay_rate) -> PlaneForces:
    dtype = planes.offsets.dtype
    c1 = jnp.asarray(c1, dtype)
    rate = jnp.asarray(decay_rate, dtype)
    ok = jnp.isfinite(c1) & (c1 >= 0) & (c1 <= c1_max(dtype)) & jnp.isfinite(rate) & (rate >= 0)
    c1 = jnp.where(ok, c1, 0.0)  # safe stand-ins: neither value nor gradient sees the bad constants
    rate = jnp.where(ok, rate, 0.0)
    d = jnp.where(planes.valid, planes.offsets, 0.0)
    # No decay (rate 0, i.e. C2 = 1) reaches even a plane at an overflowed (inf) distance: never 0 * inf.
    mag = jnp.where(planes.valid & ok, c1 * jnp.exp(-jnp.where(rate > 0, rate * d, 0.0)), 0.0)
    force = -jnp.sum(mag[:, None] * planes.normals, axis=0)
    return PlaneForces(force=force, terms=mag, bad_constants=~ok)


def repulsive_force(jacobian, travel_minus, travel_plus, c1, c2) -> jax.Array:
    """The paper's repulsive force (eqs. 12-13): ``f = sum_planes -n C1 C2^|d|``.

    Each distinct limiting plane pushes along its inward normal; the side comes
    from the construction, so a plane at distance 0 (two cylinders at their
    ends of stroke) contributes its full ``C1``. ``C2^d`` depends on the unit of
    d (metres here); :func:`repulsive_force_decay` takes a decay length instead.
    Outside jit, travels of the wrong sign raise; inside jit they are clamped
    (see :func:`check_travel`) and the force is always finite.

    Args:
      jacobian: (3, k) J = dPhi/dq.
      travel_minus: (k,) q_min - q <= 0.
      travel_plus: (k,) q_max - q >= 0.
      c1: C1 (N), force of a plane at distance 0, in ``[0, c1_max()]``.
      c2: C2 in (0, 1], the factor per metre of distance.

    Returns:
      (3,) force in newtons (the units of c1).

    Example:
      >>> f = repulsive_force(jnp.eye(3), jnp.array([-0.1, -1.0, -1.0]), jnp.ones(3), 1.0, 1e-3)
      >>> bool(f[0] > 0.1)  # the near plane at x = -0.1 pushes towards +x
      True
    """
    _validate(jacobian, travel_minus, travel_plus)
    check_repulsion(c1, c2=c2)
    return _force_c2(jacobian, travel_minus, travel_plus, c1, c2)


@jax.jit
def _force_c2(jacobian, travel_minus, travel_plus, c1, c2):
    planes = limiting_planes(jacobian, travel_minus, travel_plus)
    c2 = jnp.asarray(c2, planes.offsets.dtype)
    # c2 outside (0, 1] (NaN, <= 0: NaN rate; > 1: a force growing with distance) gives a NaN rate: zero force.
    rate = jnp.where((c2 > 0) & (c2 <= 1), -jnp.log(jnp.where(c2 > 0, c2, 1.0)), jnp.nan)
    return _plane_forces(planes, c1, rate).force


def repulsive_force_decay(jacobian, travel_minus, travel_plus, c1, decay_length) -> jax.Array:
    """Repulsive force with a unit-consistent decay length: ``sum -n C1 exp(-d / lambda)``.

    Same as :func:`repulsive_force` with ``C2 = exp(-1 / lambda)`` for d in metres.

    Args:
      jacobian, travel_minus, travel_plus: as in :func:`repulsive_force`.
      c1: C1 (N), in ``[0, c1_max()]``.
      decay_length: lambda (m) > 0: the force of a plane falls by 1/e per lambda.

    Returns:
      (3,) force in newtons.

    Example:
      >>> f = repulsive_force_decay(jnp.eye(3), -jnp.ones(3), jnp.ones(3), 1.0, 0.05)
      >>> bool(jnp.allclose(f, 0.0))  # centred in a cube: the planes cancel
      True
    """
    _validate(jacobian, travel_minus, travel_plus)
    check_repulsion(c1, decay_length=decay_length)
    return _force_decay(jacobian, travel_minus, travel_plus, c1, decay_length)


@jax.jit
def _force_decay(jacobian, travel_minus, travel_plus, c1, decay_length):
    planes = limiting_planes(jacobian, travel_minus, travel_plus)
    return _plane_forces(planes, c1, decay_rate_of(decay_length, planes.offsets.dtype)).force


def decay_rate_of(decay_length, dtype=None) -> jax.Array:
    """``1 / decay_length`` (1/m), NaN where ``decay_length`` is not finite and > 0 (:func:`plane_forces` flags it)."""
    lam = jnp.asarray(decay_length, jnp.result_type(float) if dtype is None else dtype)
    ok = jnp.isfinite(lam) & (lam > 0)
    return jnp.where(ok, 1.0 / jnp.where(ok, lam, 1.0), jnp.nan)


def linearize(forward_kinematics: Callable[[jax.Array], jax.Array], q, q_min, q_max) -> Workspace:
    """Linearised workspace of any JAX forward kinematics ``x = Phi(q)`` at ``q``.

    ``J = jax.jacfwd(Phi)(q)``. Inside jit, ``q`` outside ``[q_min, q_max]`` is
    clamped to the stroke first and flagged in ``out_of_range`` (validate at the
    boundary with :func:`check_stroke`); non-finite ``q`` is treated the same way
    (replaced by the middle of the stroke).

    Args:
      forward_kinematics: callable (k,) -> (3,) in JAX (closes over its parameters).
      q: (k,) cylinder positions.
      q_min, q_max: (k,) strokes' ends.

    Returns:
      Workspace (position, J, travels, flags, planes).

    Example:
      >>> ws = linearize(lambda q: jnp.array([q[0], q[1], q[0] * q[1]]), jnp.array([0.2, 0.3]),
      ...                jnp.zeros(2), jnp.ones(2))
      >>> ws.jacobian.shape, int(ws.planes.valid.sum())  # a parallelogram: 2 faces + 4 edges
      ((3, 2), 6)
    """
    q = jnp.asarray(q, jnp.result_type(float))
    q_min = jnp.broadcast_to(jnp.asarray(q_min, q.dtype), q.shape)
    q_max = jnp.broadcast_to(jnp.asarray(q_max, q.dtype), q.shape)
    finite = jnp.isfinite(q)
    out = ~finite | (q < q_min) | (q > q_max)
    qc = jnp.clip(jnp.where(finite, q, 0.5 * (q_min + q_max)), q_min, q_max)
    jac, position = jax.jacfwd(lambda x: (forward_kinematics(x),) * 2, has_aux=True)(qc)
    tm, tp = q_min - qc, q_max - qc
    return Workspace(
        position=position,
        jacobian=jac,
        travel_minus=tm,
        travel_plus=tp,
        out_of_range=out,
        planes=limiting_planes(jac, tm, tp),
    )


def check_stroke(q, q_min, q_max) -> None:
    """Raise ValueError if a concrete ``q`` is non-finite or outside ``[q_min, q_max]``."""
    if not _is_concrete(q, q_min, q_max):
        return
    q, lo, hi = (np.broadcast_to(np.asarray(v, float), np.shape(q)) for v in (q, q_min, q_max))
    bad = ~np.isfinite(q) | (q < lo) | (q > hi)
    if np.any(bad):
        where = [tuple(i) if len(i) > 1 else int(i[0]) for i in np.argwhere(bad).tolist()]
        raise ValueError(
            f"cylinder positions {where} outside their stroke: q={q[bad].tolist()}, "
            f"q_min={lo[bad].tolist()}, q_max={hi[bad].tolist()}"
        )
