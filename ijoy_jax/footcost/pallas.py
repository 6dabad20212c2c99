"""FootCost of a decision's candidates in one fused Pallas kernel (GPU: Triton; CPU: interpreted).

The XLA path (:func:`ijoy_jax.footcost.foot_cost_terms`) gathers a fixed
K x K height window per candidate (K = 29 cells with the default windows, sized
for margins up to 10 cm) and materialises it with its masks and residuals in
memory: ~12 MB of traffic per 496-candidate decision on a GPU, which bounds it
to a few hundred thousand decisions per second. This kernel computes the same
``total`` with every intermediate in registers: each program takes a block of
candidates, one per lane, and walks the footprint column by column. The plane
fit takes each column's sums from prefix sums of the height map over
overlapping windows (two reads per table and column); the residuals, which need
the plane, walk the rows of each column (as many as the block's longest span
there), so a 2 cm margin costs less than a 10 cm one at the same static window
size. Candidates are grouped by rotation before they are split into blocks, so
a block's footprints are alike and few lanes idle. The swing corridor has a
broad phase: when the highest cell of a box holding all of a block's corridors
is within every step's clearance (on most terrain), the exact walk is skipped.

Same definitions as the XLA path, term by term (exact cell coverage, the
least-squares plane and its metrics, safety band, the rested sole
(:mod:`ijoy_jax.footcost.sole`: the same code), its support, tilt against the
ankles' limits and step height, the reach, swing corridor, unsupported flags);
sums run in a different order, so totals agree to float32 rounding. Validity
follows one rule for every limit on both paths (:func:`~ijoy_jax.footcost.xla.exceeds`: beyond the limit by more than
``LIMIT_TOL``), so a metric at its limit to rounding is valid on both; only one
within the measured band of limit + ``LIMIT_TOL`` (~8e-6 rad for slopes, ~1e-6 m
for the height metrics, plus an ulp of the altitude for step heights:
:mod:`ijoy_jax.footcost.xla`) may be decided differently. The robot's and
terrain's values are flagged by the same rule as the XLA path's
(:func:`~ijoy_jax.footcost.xla.query_supported`): a step of an unsupported
query is +inf, also where the kernel is called directly inside a jit.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as pl_triton

from ijoy_jax.footcost.index import TerrainIndex, centre_off_map, index_terrain, rows_max
from ijoy_jax.footcost.plane import plane_metrics, solve3
from ijoy_jax.footcost.query import (
    check_action_index,
    checked_query,
    poses_supported,
    query_supported,
    safe_action_index,
    safe_poses,
)
from ijoy_jax.footcost.sole import contact_offsets, sole_on_ground
from ijoy_jax.footcost.xla import SLACK, exceeds, metric_term, sole_distance
from ijoy_jax.limits import check_window
from ijoy_jax.robots import Robot, nearest_actions
from ijoy_jax.terrain import Terrain

# Scalars of one decision, packed into one float32 vector (indices into ``par``).
(_OX, _OY, _GHL, _GHW, _FHL, _FHW, _STANCE_H, _START_H, _SWX, _SWY, _SWING_MAX, _FW, _TOO_BIG,
 _SLOPE_W, _SLOPE_L, _ROUGH_W, _ROUGH_L, _BUMP_W, _BUMP_L, _STEP_W, _BAND_W, _BAND_L,
 _STX, _STY, _PITCH_L, _ROLL_L, _DIST_L, _SUPPORT_W, _SUPPORT_L, _CONTACT_INSET, _CONTACT_TOL) = range(31)
_NUM_PAR = 31
# Rows of the per-candidate block ``cand``.
_X, _Y, _T, _COST, _STEP_LIMIT, _CLEARANCE = range(6)
_NUM_CAND = 8
# Row loops run four rows per iteration (one loop test per four rows; LLVM unrolls further): the fastest of 1, 2
# and 4 measured side by side on a GPU (docs/benchmarks_history.md).
_UNROLL = 4


def _floor_i32(x, native: bool):
    """floor(x) as int32 ((C,) float32 -> int32). On the GPU one ``cvt.rmi`` instead of floor, two clamps and a
    convert (the inputs are finite and in range: coordinates in cells); interpreted, ``floor().astype``."""
    if not native:
        return jnp.floor(x).astype(jnp.int32)
    return pl_triton.elementwise_inline_asm("cvt.rmi.s32.f32 $0, $1;", args=[x], constraints="=r,r", pack=1,
                                            result_shape_dtypes=[jax.ShapeDtypeStruct(x.shape, jnp.int32)])[0]


def _ceil_i32(x, native: bool):
    """ceil(x) as int32, as :func:`_floor_i32` (``cvt.rpi`` on the GPU)."""
    if not native:
        return jnp.ceil(x).astype(jnp.int32)
    return pl_triton.elementwise_inline_asm("cvt.rpi.s32.f32 $0, $1;", args=[x], constraints="=r,r", pack=1,
                                            result_shape_dtypes=[jax.ShapeDtypeStruct(x.shape, jnp.int32)])[0]


class _Rect:
    """A rotated rectangle per candidate ((C,) vectors), prepared for column-by-column coverage.

    The same spans as :func:`ijoy_jax.geometry.rect_column_spans`, with the candidates (not the columns)
    as the vector axis: ``spans(ix)`` gives the rows touched in grid column ``ix``. Cheaper per column:
    the corners run counter-clockwise, so the edges going +x form the lower chain and those going -x the
    upper one; a rectangle has one of each in each pair of opposite edges (none if the pair is vertical).
    The lowest y over a slab is then the lower chain at the slab's ends (the larger of its two lines) or
    the bottom corner if it lies in the slab; likewise the highest. The lines are the geometry module's
    (same start corner, same slope), so the spans agree with it up to float rounding at a corner.
    """

    def __init__(self, cx, cy, c, s, half_length, half_width, res, native: bool = False):
        self.res = res
        self.native = native
        lx = (half_length, -half_length, -half_length, half_length)
        ly = (half_width, half_width, -half_width, -half_width)
        px = [cx + c * a - s * b for a, b in zip(lx, ly, strict=True)]
        py = [cy + s * a + c * b for a, b in zip(lx, ly, strict=True)]
        self.xmin = functools.reduce(jnp.minimum, px)
        self.xmax = functools.reduce(jnp.maximum, px)
        self.ix_first = _floor_i32(self.xmin / res, native)
        self.ix_last = _ceil_i32(self.xmax / res, native) - 1
        lines = []
        for v in range(4):
            qx, qy = px[(v + 1) % 4], py[(v + 1) % 4]
            dx = qx - px[v]
            slanted = dx != 0.0
            lines.append((dx, px[v], py[v], (qy - py[v]) / jnp.where(slanted, dx, 1.0)))
        self.lower, self.upper = [], []
        for e, f in ((0, 2), (1, 3)):
            # Opposite edges: exactly, one goes +x and the other -x, or both are vertical. Rounded corners keep
            # the signs apart (the corners' x are monotone in the same products) but may leave one of a nearly
            # vertical pair exactly vertical while the other is not, so each slot checks the edge it takes.
            (dx_e, x0, y0, k0), (dx_f, x1, y1, k1) = lines[e], lines[f]
            for chain, goes in ((self.lower, lambda d: d > 0.0), (self.upper, lambda d: d < 0.0)):
                take_e = goes(dx_e)  # the edge of this chain in the pair: e if it goes that way, else f ...
                used = take_e | goes(dx_f)  # ... if f does (neither: no line, the chain is the other pair's)
                none = -jnp.inf if chain is self.lower else jnp.inf
                chain.append((jnp.where(take_e, x0, x1), jnp.where(used, jnp.where(take_e, y0, y1), none),
                              jnp.where(used, jnp.where(take_e, k0, k1), 0.0)))
        (xb, yb), (xt, yt) = (px[0], py[0]), (px[0], py[0])
        for v in range(1, 4):
            lower, higher = py[v] < yb, py[v] > yt
            xb, yb = jnp.where(lower, px[v], xb), jnp.where(lower, py[v], yb)
            xt, yt = jnp.where(higher, px[v], xt), jnp.where(higher, py[v], yt)
        self.bottom, self.top = (xb, yb), (xt, yt)

    def overflow(self, ix0, num_columns: int):
        return (self.ix_first < ix0) | ((self.ix_last - ix0 + 1) > num_columns)

    def boundary(self, ix):
        """The rectangle at the left edge of grid column ``ix``, clipped to its x range: (x, lowest y, highest y).

        Column ix spans ``boundary(ix)`` to ``boundary(ix + 1)``, so a loop over columns evaluates each
        boundary once and carries it to the next column (the chains are the costliest part of a span).
        """
        x = jnp.minimum(jnp.maximum(ix.astype(jnp.float32) * self.res, self.xmin), self.xmax)

        def chain(lines, pick):
            (x0, y0, k0), (x1, y1, k1) = lines
            return pick(y0 + (x - x0) * k0, y1 + (x - x1) * k1)

        return x, chain(self.lower, jnp.maximum), chain(self.upper, jnp.minimum)

    def between(self, left, right):
        """(j0, j1, touched) ((C,) int32 / bool): the rows touched between two boundaries of one column.

        The slab is [max(ix res, xmin), min((ix + 1) res, xmax)] wherever it has width, as in the geometry
        module; the clipped boundaries differ from it only where it has none.
        """
        (a, lo_a, hi_a), (b, lo_b, hi_b) = left, right
        res = self.res
        ylo, yhi = jnp.minimum(lo_a, lo_b), jnp.maximum(hi_a, hi_b)
        (xb, yb), (xt, yt) = self.bottom, self.top
        ylo = jnp.where((xb >= a) & (xb <= b), jnp.minimum(ylo, yb), ylo)
        yhi = jnp.where((xt >= a) & (xt <= b), jnp.maximum(yhi, yt), yhi)
        touched = (a < b) & (yhi > ylo)
        j0 = _floor_i32(jnp.where(touched, ylo, 0.0) / res, self.native)
        j1 = _ceil_i32(jnp.where(touched, yhi, 0.0) / res, self.native) - 1
        return j0, j1, touched & (j1 >= j0)

    def spans(self, ix):
        """(j0, j1, touched) of grid column ``ix`` ((C,) int32 / bool)."""
        return self.between(self.boundary(ix), self.boundary(ix + 1))


def _column_loop(num_cols, ix0, rects, body, init):
    """``acc = body(ix, spans, acc)`` for columns ix0 .. ix0 + num_cols - 1, ``spans`` one (j0, j1, touched)
    per rectangle; each column boundary is evaluated once, carried from a column to the next."""
    def step(i, carry):
        left, acc = carry
        ix = ix0 + i
        right = tuple(r.boundary(ix + 1) for r in rects)
        spans = tuple(r.between(a, b) for r, a, b in zip(rects, left, right, strict=True))
        return right, body(ix, spans, acc)

    return lax.fori_loop(0, num_cols, step, (tuple(r.boundary(ix0) for r in rects), init))[1]


def _kernel(*refs, shape, res, pad, has_height, has_swing, swing_cols, unroll, window, blocks, native,
            broad_phase):
    """One block of C candidates: FootCost ``total`` (C,)."""
    if has_height:
        par_ref, cand_ref, obs_ref, hp_ref, hmax_ref, pre_ref, hb_ref, out_ref = refs
    else:
        par_ref, cand_ref, obs_ref, out_ref = refs
    nx, ny = shape
    k = pad
    p = [par_ref[i] for i in range(_NUM_PAR)]
    x, y, t = cand_ref[_X, :], cand_ref[_Y, :], cand_ref[_T, :]
    finite = jnp.isfinite(x) & jnp.isfinite(y) & jnp.isfinite(t)
    x, y, t = (jnp.where(finite, v, 0.0) for v in (x, y, t))
    cx = x - p[_OX]
    cy = y - p[_OY]
    c, s = jnp.cos(t), jnp.sin(t)
    zero_f = jnp.zeros_like(cx)
    grown = _Rect(cx, cy, c, s, p[_GHL], p[_GHW], res, native)
    ix0 = grown.ix_first
    idle = p[_TOO_BIG] > 0.0  # the whole query is unsupported or inactive: every total +inf, no loop runs
    too_big = idle | grown.overflow(ix0, k)
    # Columns this block must visit: its widest grown footprint (past ix_last nothing is touched).
    num_cols = jnp.where(idle, 0, jnp.clip(jnp.max(grown.ix_last - ix0 + 1), 0, k))

    def off_map(ix, j0, j1):
        """(C,) bool: rows j0..j1 of column ix reach beyond the map."""
        return (ix < 0) | (ix >= nx) | (j0 < 0) | (j1 >= ny)

    def hits_obstacle(ix, j0, j1, touched):
        """(C,) bool: the grown footprint's cells in column ix hold an obstacle or leave the map."""
        ixc = jnp.clip(ix, 0, nx - 1)
        count = obs_ref[ixc, jnp.clip(j1 + 1, 0, ny)] - obs_ref[ixc, jnp.clip(j0, 0, ny)]
        return touched & (off_map(ix, j0, j1) | (count > 0))

    # A centre off the map is an obstacle (footcost.index.centre_off_map), whatever the spans below find.
    total = cand_ref[_COST, :] + jnp.where(centre_off_map(cx, cy, shape, res), jnp.inf, 0.0)

    def out_of_reach(dz):
        """(C,) bool: the sole centres farther apart in 3D than the legs reach (footcost.xla's ``reach``)."""
        return exceeds(sole_distance(x - p[_STX], y - p[_STY], dz), p[_DIST_L])

    if not has_height:  # 2D: obstacles and reach only, one pass over the grown footprint's columns
        blocked = _column_loop(num_cols, ix0, (grown,), lambda ix, spans, acc: acc | hits_obstacle(ix, *spans[0]),
                               finite & False)
        total = total + jnp.where(blocked | out_of_reach(zero_f), jnp.inf, 0.0)
    else:
        foot = _Rect(cx, cy, c, s, p[_FHL], p[_FHW], res, native)
        stride = ny + 2 * k  # hp_ref is the edge-padded height map, flattened row-major
        reach = -(-k // unroll) * unroll  # rows a column loop may read: its longest span, rounded up

        def padded_column(ix):
            """Map column ix as a column of the padded map (clamped: only off-map footprints, +inf already)."""
            return jnp.clip(ix + k, 0, nx + 2 * k - 1)

        def column_start(ix, j):
            """Flat index of cell (ix, j) in the padded map, clamped so that ``reach`` cells on stay inside.

            A column's loop may read past its span (into the next padded column: those rows are masked). Only
            off-map footprints (+inf already) are ever clamped: their reads are then wrong but harmless."""
            flat = padded_column(ix) * stride + jnp.clip(j + k, 0, stride - 1)
            return jnp.minimum(flat, (nx + 2 * k) * stride - reach)

        def row_loop(rows, row, init):
            """``row(q, acc)`` for q in [0, rows), unrolled by ``unroll`` (past ``rows`` rows must be masked)."""
            def body(t, acc):
                for q in range(unroll):
                    acc = row(t * unroll + q, acc)
                return acc

            return lax.fori_loop(0, (rows + unroll - 1) // unroll, body, init)

        # The cell under the foot centre; heights are taken relative to it (float32 conditioning). Within
        # the map's padded border this is footcost.plane_metrics' window cell; beyond it the step is
        # off the map and already +inf.
        h_ref = hp_ref[column_start(_floor_i32(cx / res, native), _floor_i32(cy / res, native))]

        def rows_of(j0, j1, touched):
            """Rows the block visits in a column: its longest span there (beyond k: too big, +inf anyway)."""
            return jnp.clip(jnp.max(jnp.where(touched, j1 - j0 + 1, 0)), 0, k)

        # Every quantity is a (C,) vector, one candidate per lane, so no sum ever crosses lanes.
        # Pass 1: the normal equations of the plane fit (the sums of footcost.plane_metrics), a column at a
        # time from window prefix sums (footcost.block_sums): a span of at most B rows starting in rows
        # bB .. bB + B - 1 lies in window b, so it takes two reads of each table instead of a loop over its rows.
        log2_window = window.bit_length() - 1

        def sums_column(ix, spans, acc):
            u = (ix.astype(jnp.float32) + 0.5) * res - cx
            ((j0, j1, touched),) = spans
            # Spans are at most k <= B rows unless the footprint is too big (+inf already): clamped to keep
            # the reads inside the table.
            count = jnp.where(touched, jnp.minimum(j1 - j0 + 1, window), 0)
            first = jnp.clip(j0 + k, 0, stride - 1)  # the span's first row in the padded map ...
            b = first >> log2_window
            t0 = first - (b << log2_window)  # ... row t0 of window b
            block_id = padded_column(ix) * blocks + b
            base = block_id * (2 * window + 1) + t0

            def sums(t):  # (sum of h - h_b, sum of (h - h_b) * row from the window's middle) over rows before t
                return pre_ref[2 * t], pre_ref[2 * t + 1]

            (s_end, m_end), (s_first, m_first) = sums(base + count), sums(base)
            s0, m0 = s_end - s_first, m_end - m_first
            d = hb_ref[block_id] - h_ref  # heights relative to the foot's centre cell: (h - h_b) + (h_b - h_ref)
            c0 = count.astype(jnp.float32)
            v0 = (j0.astype(jnp.float32) + 0.5) * res - cy  # v of the span's first row
            v_mid = v0 + 0.5 * (c0 - 1.0) * res
            cv = c0 * v_mid
            cvv = c0 * v_mid * v_mid + (res * res / 12.0) * c0 * (c0 * c0 - 1.0)
            v_b = ((b << log2_window) + (window - k)).astype(jnp.float32) * res - cy  # window b's middle
            c1 = s0 + c0 * d
            cvh = v_b * s0 + res * m0 + d * cv
            terms = (c0, c0 * u, c0 * u * u, cv, cv * u, cvv, c1, c1 * u, cvh)
            return tuple(a + b for a, b in zip(acc, terms, strict=True))

        # Pass 1 visits the foot's columns only (the grown footprint's are up to two more).
        foot_cols = jnp.where(idle, 0, jnp.clip(jnp.max(foot.ix_last - foot.ix_first + 1), 0, k))
        n, su, suu, sv, suv, svv, sh, suh, svh = _column_loop(foot_cols, foot.ix_first, (foot,), sums_column,
                                                              (zero_f,) * 9)
        n = jnp.maximum(n, 1.0)
        ridge = 1e-6 * n * res * res
        a, b, cc = solve3(n, su, sv, suu + ridge, suv, svv + ridge, sh, suh, svh)
        rise = cc * res  # the plane's rise from one row to the next

        # Pass 2: residuals from the plane under the foot (roughness, bump) and in the safety band, row by
        # row: the rows of a column are an inner loop (as many as the block's longest span there), row q at
        # the span's start + q, read at a flat address. These row bodies run ~180 times per candidate, so
        # they test one bound each and carry the plane down the column (relative to h_ref: in map heights it
        # would round to the terrain's altitude). The bump is max(largest residual, 0), so masked rows may
        # count as 0 instead of -inf.

        def resid_column(ix, spans, acc):
            u = (ix.astype(jnp.float32) + 0.5) * res - cx
            (g0, g1, g_touched), (j0, j1, touched) = spans
            # Row q of the column is the grown span's row g0 + q; each lane counts its rows from the foot's
            # first one (rel = q - (j0 - g0)), so that both masks are one 32-bit compare of that count.
            foot_rows = jnp.where(touched, j1 - j0 + 1, 0).astype(jnp.uint32)
            grown_end = jnp.where(g_touched, g1 - g0 + 1, 0) - (j0 - g0)  # the grown span's end, from j0
            start = column_start(ix, g0)
            plane0 = a + b * u + cc * ((g0.astype(jnp.float32) + 0.5) * res - cy)

            def row(q, acc):
                abs_sum, top, band, plane, rel = acc
                resid = (hp_ref[start + q] - h_ref) - plane
                in_foot = rel.astype(jnp.uint32) < foot_rows  # 0 <= rel < foot rows, one unsigned compare
                r_foot = jnp.where(in_foot, resid, 0.0)
                r_band = jnp.where((rel < grown_end) & ~in_foot, resid, 0.0)
                return (abs_sum + jnp.abs(r_foot), jnp.maximum(top, r_foot), jnp.maximum(band, jnp.abs(r_band)),
                        plane + rise, rel + 1)

            blocked = acc[3] | hits_obstacle(ix, g0, g1, g_touched)  # obstacles ride along this pass
            abs_sum, top, band, *_ = row_loop(rows_of(g0, g1, g_touched), row, (*acc[:3], plane0, g0 - j0))
            return abs_sum, top, band, blocked

        abs_sum, top, band, blocked = _column_loop(
            num_cols, ix0, (grown, foot), resid_column, (zero_f, zero_f, zero_f, finite & False))
        total = total + jnp.where(blocked, jnp.inf, 0.0)
        ok = jnp.isfinite(a) & jnp.isfinite(b) & jnp.isfinite(cc)
        too_big = too_big | ~ok  # a fit beyond float32's range (plane_metrics' ``fitted``)
        slope = jnp.where(ok, jnp.arctan(jnp.sqrt(b * b + cc * cc)), 0.0)
        rough = jnp.where(ok, abs_sum / n, 0.0)
        bump = jnp.where(ok, top, 0.0)
        band = jnp.where(ok, band, 0.0)

        def ground_at(du, dv):
            """(C,) the ground at offsets (du, dv) from the foot centre, relative to h_ref: bilinear between cell
            centres, four reads of the padded map, as footcost.xla.plane_metrics' (same clamps on the map)."""
            gx, gy = (cx + du) / res - 0.5, (cy + dv) / res - 0.5
            i0, j0 = _floor_i32(gx, native), _floor_i32(gy, native)
            tx, ty = gx - i0.astype(jnp.float32), gy - j0.astype(jnp.float32)

            def at(di, dj):
                return hp_ref[column_start(i0 + di, j0 + dj)] - h_ref

            return (1.0 - tx) * ((1.0 - ty) * at(0, 0) + ty * at(0, 1)) + tx * ((1.0 - ty) * at(1, 0) + ty * at(1, 1))

        # The rested sole (footcost.sole, plane_metrics' code in the kernel's layout): its height, tilt and support.
        du, dv = contact_offsets(p[_FHL], p[_FHW], p[_CONTACT_INSET], c, s)
        rest = sole_on_ground(tuple(ground_at(du[i], dv[i]) for i in range(6)), p[_FHL], p[_FHW],
                              p[_CONTACT_INSET], p[_CONTACT_TOL], unrolled=True)
        rested = jnp.isfinite(rest.height)
        too_big = too_big | ~rested
        height = jnp.where(rested, rest.height + h_ref, h_ref)  # the rested sole's, as the step's height
        support = jnp.where(rested, rest.support, 0.0)
        dh = height - p[_STANCE_H]
        # The rested sole's tilt against the ankles' limits, and the reach over the height change.
        pitch, roll = jnp.where(rested, rest.pitch, 0.0), jnp.where(rested, rest.roll, 0.0)
        ankle_bad = exceeds(jnp.abs(pitch), p[_PITCH_L]) | exceeds(jnp.abs(roll), p[_ROLL_L])
        total = (total + metric_term(p[_SLOPE_W], slope, p[_SLOPE_L])
                 + metric_term(p[_ROUGH_W], rough, p[_ROUGH_L]) + metric_term(p[_BUMP_W], bump, p[_BUMP_L])
                 + metric_term(p[_STEP_W], jnp.abs(dh), cand_ref[_STEP_LIMIT, :])
                 + metric_term(p[_BAND_W], band, p[_BAND_L])
                 + metric_term(p[_SUPPORT_W], support, p[_SUPPORT_L])
                 + jnp.where(ankle_bad | out_of_reach(dh), jnp.inf, 0.0))

        if has_swing:
            # The swing corridor: the foot-wide rectangle from the swing start to the step.
            dx, dy = cx - p[_SWX], cy - p[_SWY]
            length = jnp.sqrt(dx * dx + dy * dy)
            theta = jnp.arctan2(jnp.where(length > 0, dy, 0.0), jnp.where(length > 0, dx, 1.0))
            path = _Rect(0.5 * (cx + p[_SWX]), 0.5 * (cy + p[_SWY]), jnp.cos(theta), jnp.sin(theta),
                         0.5 * length, p[_FHW], res, native)
            pix0 = path.ix_first
            too_big = too_big | path.overflow(pix0, swing_cols) | (length + p[_FW] > p[_SWING_MAX])
            path_cols = jnp.where(idle, 0, jnp.clip(jnp.max(path.ix_last - pix0 + 1), 0, swing_cols))
            floor_h = jnp.maximum(p[_START_H], height)  # the corridor is measured from the higher foothold
            # Broad phase: every corridor of a lane that can still be valid lies in the box from the swing
            # start to the lanes' steps, grown by the foot's half width and a cell. If that box is on the map
            # and its highest cell is within each such lane's clearance of its foothold, no corridor can fail:
            # the exact walk below is skipped for the block (the test is exact, a bound, not an estimate).
            if broad_phase:
                open_lane = jnp.isfinite(total) & ~too_big & finite
                box = corridor_box(open_lane, cx, cy, p[_SWX], p[_SWY], p[_FHW], res)
                box_top = box_top_height(hmax_ref, box, shape, cx.shape[0])
                clear = ~exceeds(box_top - floor_h, cand_ref[_CLEARANCE, :])
                path_cols = jnp.where(_any(open_lane & ~clear), path_cols, 0)

            def path_column(ix, spans, acc):
                top, off = acc
                ((j0, j1, touched),) = spans
                ixc = jnp.clip(ix, 0, nx - 1)
                hi = rows_max(hmax_ref, ixc, jnp.clip(j0, 0, ny - 1), jnp.clip(j1, 0, ny - 1))
                return jnp.maximum(top, jnp.where(touched, hi, -jnp.inf)), off | (touched & off_map(ix, j0, j1))

            path_top, path_off = _column_loop(path_cols, pix0, (path,), path_column, (zero_f - jnp.inf, finite & False))
            path_height = path_top - floor_h
            path_bad = path_off | exceeds(path_height, cand_ref[_CLEARANCE, :])
            total = total + jnp.where(path_bad, jnp.inf, 0.0)

    out_ref[...] = jnp.where(too_big | ~finite, jnp.inf, total)  # +inf also where an unsupported value made NaN


def _any(flags):
    """Whether any lane's flag is set (a scalar; Triton lowers no boolean reduction, so an integer max)."""
    return jnp.max(flags.astype(jnp.int32)) > 0


def corridor_box(lane, cx, cy, sx, sy, half_width, res):
    """The fused kernel's broad phase, part one: one box of cells that holds a block's swing corridors.

    The cells (ix0, ix1, iy0, iy1), inclusive, that hold every swing corridor of the lanes where ``lane``
    (:func:`ijoy_jax.footcost.index.swing_corridor`'s cells): the bounding box of the swing start and those
    steps, grown by ``half_width`` and by one cell against rounding. With :func:`box_top_height` it lets a
    block skip the exact corridor walk when no corridor can fail.

    Args:
      lane: (L,) bool, the lanes whose corridors the box must hold.
      cx, cy: (L,) float32 m, each lane's step (the corridor's end).
      sx, sy: () float32 m, the swing start (every corridor's start).
      half_width: () float32 m, the corridor's half width (the foot's).
      res: cell size (m).

    Returns:
      Four () int32 cell indices; empty (ix1 < ix0) when no lane is set.
    """
    def cells(v, start):
        low = jnp.minimum(start, jnp.min(jnp.where(lane, v, jnp.inf))) - half_width
        high = jnp.maximum(start, jnp.max(jnp.where(lane, v, -jnp.inf))) + half_width
        return jnp.floor(low / res).astype(jnp.int32) - 1, jnp.floor(high / res).astype(jnp.int32) + 1

    (ix0, ix1), (iy0, iy1) = cells(cx, sx), cells(cy, sy)
    return ix0, jnp.where(_any(lane), ix1, ix0 - 1), iy0, iy1


def box_top_height(hmax_ref, box, shape, lanes: int):
    """The fused kernel's broad phase, part two: the highest height in a box of cells (:func:`corridor_box`).

    The box's columns are spread over the lanes, each column's maximum taken from two reads of the sparse
    table (:func:`ijoy_jax.footcost.index.rows_max`), then the lanes'. A box that leaves the map reads +inf,
    so the exact walk, which knows what off the map costs, decides there.

    Args:
      hmax_ref: (levels, nx, ny) float32 m, :attr:`ijoy_jax.footcost.TerrainIndex.height_max` (an array or
        the kernel's ref).
      box: (ix0, ix1, iy0, iy1) inclusive cell indices, as :func:`corridor_box` returns them.
      shape: (nx, ny), the map's cells (static).
      lanes: how many lanes share the work (static).

    Returns:
      () float32 m: the highest height in the box, +inf if it leaves the map, -inf if it is empty.
    """
    nx, ny = shape
    ix0, ix1, iy0, iy1 = box
    inside = (ix0 >= 0) & (ix1 < nx) & (iy0 >= 0) & (iy1 < ny)
    a0, a1 = jnp.clip(iy0, 0, ny - 1), jnp.clip(iy1, 0, ny - 1)
    lane = lax.broadcasted_iota(jnp.int32, (lanes,), 0)

    def body(r, top):
        ix = ix0 + r * lanes + lane
        hi = rows_max(hmax_ref, jnp.clip(ix, 0, nx - 1), a0, a1)
        return jnp.maximum(top, jnp.where(ix <= ix1, hi, -jnp.inf))

    rounds = (jnp.maximum(ix1 - ix0 + 1, 0) + lanes - 1) // lanes
    top = lax.fori_loop(0, rounds, body, jnp.full((lanes,), -jnp.inf, jnp.float32))
    return jnp.where(inside, jnp.max(top), jnp.inf)


def foot_cost_fused(
    terrain: Terrain,
    robot: Robot,
    stance,
    stance_side,
    steps,
    *,
    swing_from=None,
    action_index=None,
    index: TerrainIndex | None = None,
    block: int = 32,
    num_warps: int | None = 1,
    interpret: bool | None = None,
    broad_phase: bool = True,
    active=True,
) -> jax.Array:
    """(N,) FootCost totals of candidate steps, the same numbers as ``foot_cost_terms(...).total``.

    One terrain, one stance (vmap for batches: the terrain tables are shared,
    not copied, when only the queries are batched). Arguments and checks as in
    :func:`ijoy_jax.footcost.foot_cost_terms` (``index``: the prebuilt
    :class:`TerrainIndex`, built inside when None); no jit of its own: call it
    inside yours.

    Args:
      block: candidates per kernel program (static, a power of two).
      num_warps: warps per program on the GPU (None: Triton's default). The
        defaults put one candidate on each lane of one warp, the fastest
        block shape measured (docs/benchmarks_history.md): a larger block runs
        its loops to a longer longest footprint.
      interpret: run the kernel through the Pallas interpreter (None: on every
        backend but GPU; slow, for tests and CPU use). Compiled, the kernel
        uses inline PTX (float-to-int conversions): NVIDIA GPUs only; ROCm
        was never tried.
      broad_phase: skip the exact swing-corridor walk for a block of
        candidates when a bound proves every corridor clear (the highest cell
        of a box holding them all is within each step's clearance); the
        totals are the same either way. False: always walk (tests, timing).
      active: () bool, may be traced: False returns +inf for every step and
        skips the kernel's loops. A search vmapped over queries gives its
        finished queries False, so they cost no work while the batch's
        slowest query goes on (:func:`ijoy_jax.select_step`'s ordered
        method does).

    Returns:
      (N,) float32: +inf where invalid, else >= 0. Not differentiable (the
      kernel has no derivative rule): take gradients through the XLA path or
      :mod:`ijoy_jax.tune`'s relaxation.
    """
    stance, steps, swing_from = checked_query(terrain, robot, stance, stance_side, steps, swing_from, index)
    check_action_index(robot, action_index, steps.shape[0])
    if block < 1 or block & (block - 1):
        raise ValueError(f"block must be a power of two, got {block}")
    shape, dtype = getattr(active, "shape", None), getattr(active, "dtype", None)
    if not (isinstance(active, bool) or (shape == () and dtype == jnp.bool_)):
        given = type(active).__name__ if shape is None or dtype is None else f"{dtype}{list(shape)}"
        raise ValueError(f"active must be a () bool (one per query: vmap for batches), got {given}")
    active = jnp.asarray(active, jnp.bool_)  # a Python bool's ~ is an integer's
    if index is None:
        index = index_terrain(terrain, robot)
    if interpret is None:
        interpret = jax.default_backend() != "gpu"
    steps = jnp.asarray(steps, jnp.float32).reshape(-1, 3)
    query_ok = poses_supported(stance, stance_side, swing_from)
    stance, swing_from = safe_poses(stance, swing_from)
    num = steps.shape[0]
    if action_index is None:
        action_index = nearest_actions(robot, stance, stance_side, steps)
    action_index, index_ok = safe_action_index(robot, action_index, num)
    res = terrain.resolution
    k = index.pad
    has_height = terrain.has_height
    has_swing = has_height and swing_from is not None
    f32 = functools.partial(jnp.asarray, dtype=jnp.float32)
    zero = f32(0.0)
    stance_h = start_h = zero
    swx = swy = zero
    # the XLA path's rules, for the whole query; an inactive query is refused the same way (no work, +inf)
    unsupported = ~query_supported(terrain, robot) | ~query_ok | ~active
    _, blocks, window, _ = index.height_sums.shape
    window = (window - 1) // 2  # rows per window step (>= k, the longest span)
    if has_height:
        stance_plane = plane_metrics(terrain, index, robot, stance)
        stance_h, unsupported = stance_plane.rest_height, unsupported | ~stance_plane.fitted
        if has_swing:
            start_plane = plane_metrics(terrain, index, robot, swing_from)
            start_h, unsupported = start_plane.rest_height, unsupported | ~start_plane.fitted
            swx, swy = swing_from[0] - terrain.origin[0], swing_from[1] - terrain.origin[1]
    ghl = 0.5 * robot.foot_length + robot.margin
    ghw = 0.5 * robot.foot_width + robot.margin
    m = robot.metrics
    par = [terrain.origin[0], terrain.origin[1], ghl, ghw, 0.5 * robot.foot_length, 0.5 * robot.foot_width,
           stance_h, start_h, swx, swy, robot.max_swing + SLACK, robot.foot_width,
           jnp.where(unsupported, 1.0, 0.0),
           m.slope_weight, m.slope_limit, m.roughness_weight, m.roughness_limit, m.bump_weight, m.bump_limit,
           m.step_weight, m.band_weight, m.band_limit, stance[0], stance[1], robot.max_sole_pitch,
           robot.max_sole_roll, robot.max_sole_distance, m.support_weight, m.support_limit,
           m.contact_inset, m.contact_tol]
    par = jnp.stack([f32(q) for q in par] + [zero] * (_NUM_PAR - len(par)))
    padded = -(-num // block) * block
    order = None
    if num > block:
        # Programs run their loops as long as their longest footprint needs, so a block of alike footprints
        # wastes fewest lane-steps: order candidates by their action's rotation (every step of one rotation
        # has one world orientation; stable, so rows within stay in action order). Unbatched, hence computed
        # once, when the action indices are (as in select_step).
        order = jnp.argsort(robot.actions[action_index, 2], stable=True)
        steps, action_index = steps[order], action_index[order]
    cand = jnp.stack([steps[:, 0], steps[:, 1], steps[:, 2], robot.action_cost[action_index],
                      robot.max_step_height[action_index], robot.clearance[action_index]]
                     + [jnp.zeros(num, jnp.float32)] * (_NUM_CAND - 6))
    cand = jnp.pad(cand, ((0, 0), (0, padded - num)))
    args = [par, cand, index.obstacles_before]
    specs = [pl.BlockSpec((_NUM_PAR,), lambda i: (0,)), pl.BlockSpec((_NUM_CAND, block), lambda i: (0, i)),
             pl.BlockSpec(index.obstacles_before.shape, lambda i: (0, 0))]
    if has_height:
        args += [index.height_padded.reshape(-1), index.height_max, index.height_sums.reshape(-1),
                 index.height_block_first.reshape(-1)]
        specs += [pl.BlockSpec((index.height_padded.size,), lambda i: (0,)),
                  pl.BlockSpec(index.height_max.shape, lambda i: (0, 0, 0)),
                  pl.BlockSpec((index.height_sums.size,), lambda i: (0,)),
                  pl.BlockSpec((index.height_block_first.size,), lambda i: (0,))]
    kernel = functools.partial(
        _kernel, shape=terrain.shape, res=res, pad=k, has_height=has_height,
        has_swing=has_swing, swing_cols=check_window(0.5 * robot.max_swing, res, "swing path"),
        unroll=_UNROLL, window=window, blocks=blocks, native=not interpret,
        broad_phase=broad_phase)
    out = pl.pallas_call(
        kernel,
        out_shape=jax.ShapeDtypeStruct((padded,), jnp.float32),
        grid=(padded // block,),
        in_specs=specs,
        out_specs=pl.BlockSpec((block,), lambda i: (i,)),
        interpret=interpret,
        compiler_params=None if interpret else pl_triton.CompilerParams(num_warps=num_warps),
        name="foot_cost_fused",
    )(*args)
    if order is None:
        out = out[:num]
    else:
        out = out[jnp.zeros_like(order).at[order].set(jnp.arange(num, dtype=order.dtype))]  # inverse permutation
    return jnp.where(index_ok, out, jnp.inf)  # a step whose action index is outside the set is unsupported
