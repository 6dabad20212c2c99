"""Linearised workspace planes and repulsive force against scipy.spatial.ConvexHull, LPs and eqs. 7-13."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from jax.test_util import check_grads

from ijoy_jax.haptics import workspace as W
from ijoy_jax.jit_cache import compiled_count

# float64 planes against qhull's facets: both are a few ulps of O(1) numbers.
TOL_F64 = 1e-9
# float32 planes: normals from cross products of unit columns, good to ~eps / sin(angle);
# the float32 cases below keep the angles > 0.1 rad, so 1e-4 covers it.
TOL_F32 = 1e-4
N_RANDOM = 2000  # random Jacobians and strokes compared with ConvexHull

planes64 = jax.jit(jax.vmap(W.limiting_planes))
planes1 = jax.jit(W.limiting_planes)


def zonotope_points(jac, tm, tp):
    """All 2^k sums of one generator per cylinder (the paper's 16 points for k = 4)."""
    k = jac.shape[1]
    choice = np.array(list(itertools.product((0, 1), repeat=k)), bool)
    return np.where(choice, tp, tm) @ jac.T


def hull_facets(points):
    """Distinct facets (unit normal, offset) of scipy's ConvexHull; qhull splits each rhombus in two,
    whose equations agree to rounding, so rounding to 1e-7 identifies them."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points)
    _, first = np.unique(np.round(hull.equations, 7), axis=0, return_index=True)
    eqs = hull.equations[np.sort(first)]
    return [(e[:3], -e[3]) for e in eqs], len(hull.vertices)


def match(planes, facets, tol):
    """Every valid row equals one hull facet and vice versa."""
    valid = np.asarray(planes.valid)
    normals, offsets = np.asarray(planes.normals)[valid], np.asarray(planes.offsets)[valid]
    assert len(normals) == len(facets), (len(normals), len(facets))
    for n, b in facets:
        err = np.abs(normals - n).max(axis=1) + np.abs(offsets - b)
        assert err.min() < tol, err.min()


def random_cases(n, seed, end_of_stroke=0.3):
    rng = np.random.default_rng(seed)
    jac = rng.normal(size=(n, 3, 4))
    tm = -rng.uniform(0.05, 1.0, (n, 4))
    tp = rng.uniform(0.05, 1.0, (n, 4))
    # A cylinder at an end of stroke (e_i^+ = 0 or e_i^- = 0) in a share of the cases.
    at_end = rng.uniform(size=(n, 4)) < end_of_stroke / 4
    side = rng.uniform(size=(n, 4)) < 0.5
    tp = np.where(at_end & side, 0.0, tp)
    tm = np.where(at_end & ~side, 0.0, tm)
    return jac, tm, tp


def well_conditioned(jac, min_sin=1e-3):
    """(...) bool: columns of (..., 3, 4) pairwise at least min_sin apart and no three within min_sin of
    coplanar (a generic zonotope; in float64 our tolerances are ~1e-8, far below)."""
    u = jac / np.linalg.norm(jac, axis=-2, keepdims=True)
    ok = np.ones(jac.shape[:-2], bool)
    for i, j in itertools.combinations(range(4), 2):
        ok &= np.linalg.norm(np.cross(u[..., :, i], u[..., :, j]), axis=-1) >= min_sin
    for c in itertools.combinations(range(4), 3):
        ok &= np.abs(np.linalg.det(u[..., :, list(c)])) >= min_sin
    return ok


def test_planes_equal_convex_hull_facets_float64():
    jac, tm, tp = random_cases(N_RANDOM, seed=0)
    with jax.enable_x64(True):
        p = jax.tree_util.tree_map(np.asarray, planes64(jnp.asarray(jac), jnp.asarray(tm), jnp.asarray(tp)))
    generic = well_conditioned(jac)
    assert generic.mean() > 0.95
    for c in np.flatnonzero(generic):
        facets, n_vertices = hull_facets(zonotope_points(jac[c], tm[c], tp[c]))
        assert (len(facets), n_vertices) == (12, 14)  # the paper's dodecahedron
        match(W.Planes(p.normals[c], p.offsets[c], p.valid[c]), facets, TOL_F64)


def test_planes_equal_convex_hull_facets_float32():
    jac, tm, tp = random_cases(100, seed=1)
    p = jax.tree_util.tree_map(
        np.asarray,
        jax.vmap(planes1)(jnp.asarray(jac, jnp.float32), jnp.asarray(tm, jnp.float32), jnp.asarray(tp, jnp.float32)),
    )
    cases = np.flatnonzero(well_conditioned(jac, 0.1))
    assert len(cases) == 56  # of 100 (seed 1): angles > 0.1 rad, the float32 tolerance's premise
    for c in cases:
        facets, _ = hull_facets(zonotope_points(jac[c], tm[c], tp[c]))
        scale = np.abs(zonotope_points(jac[c], tm[c], tp[c])).max()
        match(W.Planes(p.normals[c], p.offsets[c], p.valid[c]), facets, TOL_F32 * (1 + scale))


def support_brute(jac, tm, tp, u):
    return np.max(zonotope_points(jac, tm, tp) @ u)


def test_offsets_are_the_support_function():
    """d = h(n) = max over the 16 generator sums = sum_i max(e_i^+ . n, e_i^- . n)."""
    jac, tm, tp = random_cases(50, seed=2)
    with jax.enable_x64(True):
        for c in range(50):
            p = planes1(jac[c], tm[c], tp[c])
            for n, d in zip(
                np.asarray(p.normals)[np.asarray(p.valid)], np.asarray(p.offsets)[np.asarray(p.valid)], strict=True
            ):
                e_plus, e_minus = tp[c][:, None] * jac[c].T, tm[c][:, None] * jac[c].T
                assert d == pytest.approx(np.sum(np.maximum(e_plus @ n, e_minus @ n)), abs=TOL_F64)
                assert d == pytest.approx(support_brute(jac[c], tm[c], tp[c], n), abs=TOL_F64)
                assert d >= 0


# --- the paper's literal construction (eqs. 7-11), to show the pitfalls it has -------------------


def paper_planes(jac, tm, tp):
    """Eqs. 7-11 as printed, with normals J_m x J_n: per pair (n, d^-, d^+), signed along n."""
    out = []
    for m, n in itertools.combinations(range(4), 2):
        i, j = [r for r in range(4) if r not in (m, n)]
        nrm = np.cross(jac[:, m], jac[:, n])
        nrm /= np.linalg.norm(nrm)
        ep, em = tp[:, None] * jac.T, tm[:, None] * jac.T
        c = [ep[i] + ep[j], ep[i] + em[j], em[i] + em[j], em[i] + ep[j]]
        d = [ck @ nrm for ck in c]
        s = np.sign(ep[i] @ nrm) * np.sign(ep[j] @ nrm)
        out.append((nrm, d[0] if s > 0 else d[1], d[2] if s > 0 else d[3]))
    return out


def paper_force(jac, tm, tp, c1, c2):
    """Eqs. 12-13 as printed: -sgn(d) n C1 C2^|d| over both planes of each pair."""
    f = np.zeros(3)
    for nrm, dm, dp in paper_planes(jac, tm, tp):
        for d in (dm, dp):
            f += -np.sign(d) * nrm * c1 * c2 ** abs(d)
    return f


def test_paper_rule_agrees_away_from_ends_of_stroke():
    jac, tm, tp = random_cases(200, seed=3, end_of_stroke=0.0)
    with jax.enable_x64(True):
        for c in range(200):
            if not well_conditioned(jac[c]):
                continue
            p = planes1(jac[c], tm[c], tp[c])
            normals, offsets = np.asarray(p.normals), np.asarray(p.offsets)
            for k, (nrm, dm, dp) in enumerate(paper_planes(jac[c], tm[c], tp[c])):
                np.testing.assert_allclose(normals[2 * k], nrm, atol=TOL_F64)
                assert sorted([dm, dp]) == pytest.approx([-offsets[2 * k + 1], offsets[2 * k]], abs=TOL_F64)
            f = W.repulsive_force(jac[c], tm[c], tp[c], 2.0, 0.3)
            np.testing.assert_allclose(np.asarray(f), paper_force(jac[c], tm[c], tp[c], 2.0, 0.3), atol=1e-9)


def test_paper_sign_rule_fails_at_end_of_stroke_ours_does_not():
    """With e_i^+ = 0 the printed rule s = sgn(e_i^+ . n) sgn(e_j^+ . n) is 0 and picks the wrong vertex."""
    jac, tm, tp = random_cases(300, seed=4, end_of_stroke=0.0)
    tp[:, 0] = 0.0  # cylinder 1 at its upper end of stroke
    cases = np.flatnonzero(well_conditioned(jac))
    wrong_cases = 0
    with jax.enable_x64(True):
        for c in cases:
            facets, _ = hull_facets(zonotope_points(jac[c], tm[c], tp[c]))
            match(planes1(jac[c], tm[c], tp[c]), facets, TOL_F64)  # ours: always the hull
            wrong = 0
            for nrm, dm, dp in paper_planes(jac[c], tm[c], tp[c]):
                true = sorted([-support_brute(jac[c], tm[c], tp[c], -nrm), support_brute(jac[c], tm[c], tp[c], nrm)])
                wrong += not np.allclose(sorted([dm, dp]), true, atol=1e-9)
            wrong_cases += wrong > 0
    assert wrong_cases > 0.8 * len(cases)  # the printed rule: 266 of 299 cases have a wrong plane


def test_plane_at_distance_zero_pushes_with_full_strength():
    """sgn(0) = 0 in eq. 12 drops exactly the plane the end-effector touches; ours keeps it (side from
    the construction). Two cylinders at their ends of stroke put a plane through the current position."""
    jac = np.array([[1.0, 0.0, 0.3, 0.2], [0.0, 1.0, 0.2, -0.3], [0.0, 0.0, 1.0, 0.8]])
    tm = np.array([-0.5, -0.5, -0.5, -0.5])
    tp = np.array([0.5, 0.5, 0.0, 0.0])  # cylinders 3 and 4 at their upper ends: nothing can go up
    with jax.enable_x64(True):
        p = planes1(jac, tm, tp)
        top = np.flatnonzero(np.asarray(p.valid) & (np.asarray(p.normals)[:, 2] > 0.99))
        assert len(top) == 1 and float(p.offsets[top[0]]) == 0.0
        f = np.asarray(W.repulsive_force_decay(jac, tm, tp, 1.0, 1e-3))  # far planes negligible
    np.testing.assert_allclose(f, [0.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(paper_force(jac, tm, tp, 1.0, np.exp(-1e3)), 0.0, atol=1e-12)


# --- degenerate Jacobians: merged, never NaN ---------------------------------------------------


def _generic():
    rng = np.random.default_rng(5)
    while True:
        jac = rng.normal(size=(3, 4))
        if well_conditioned(jac, 0.2):
            return jac, -rng.uniform(0.2, 1.0, 4), rng.uniform(0.2, 1.0, 4)


@pytest.mark.parametrize(
    "case,n_facets,n_vertices",
    [
        ("parallel", 6, 8),
        ("antiparallel", 6, 8),
        ("zero_column", 6, 8),
        ("zero_stroke", 6, 8),
        ("coplanar_triple", 8, 12),
        ("two_parallel_pairs", 4, None),
    ],
)
def test_degenerate_jacobians_match_hull(case, n_facets, n_vertices):
    jac, tm, tp = _generic()
    if case == "parallel":
        jac[:, 1] = 2.0 * jac[:, 0]
    elif case == "antiparallel":
        jac[:, 3] = -0.5 * jac[:, 2]
    elif case == "zero_column":
        jac[:, 2] = 0.0
    elif case == "zero_stroke":
        tm[1] = tp[1] = 0.0
    elif case == "coplanar_triple":  # the spherical-hip case: a prism
        jac[:, 2] = 0.7 * jac[:, 0] - 0.4 * jac[:, 1]
    elif case == "two_parallel_pairs":  # rank 2: a flat parallelogram, checked by LP below
        jac[:, 1], jac[:, 3] = 2.0 * jac[:, 0], -jac[:, 2]
    with jax.enable_x64(True):
        p = planes1(jac, tm, tp)
    assert np.all(np.isfinite(np.asarray(p.normals))) and np.all(np.isfinite(np.asarray(p.offsets)))
    if n_vertices is None:
        assert int(p.valid.sum()) == 2 + n_facets  # two faces of the flat set + its edges
        return
    facets, nv = hull_facets(zonotope_points(jac, tm, tp))
    assert (len(facets), nv) == (n_facets, n_vertices)
    match(p, facets, TOL_F64)


def _lp_support(a, b, u):
    from scipy.optimize import linprog

    res = linprog(-u, A_ub=a, b_ub=b, bounds=[(None, None)] * 3, method="highs")
    assert res.status == 0, res.message
    return -res.fun


@pytest.mark.parametrize("case", ["generic", "flat", "flat_with_parallel", "rank1", "zero"])
def test_halfspaces_are_exactly_the_zonotope(case):
    """Support functions equal in many directions <=> same convex set (also where qhull cannot help)."""
    jac, tm, tp = _generic()
    if case == "flat":
        jac[2] = 0.0
    elif case == "flat_with_parallel":
        jac[2] = 0.0
        jac[:, 3] = -jac[:, 1]
    elif case == "rank1":
        jac = np.outer([0.3, -1.0, 2.0], [1.0, -2.0, 0.5, 3.0])
    elif case == "zero":
        jac = np.zeros((3, 4))
    with jax.enable_x64(True):
        a, b = (np.asarray(v) for v in W.workspace_halfspaces(jac, tm, tp))
    rng = np.random.default_rng(6)
    for u in rng.normal(size=(40, 3)):
        assert _lp_support(a, b, u) == pytest.approx(support_brute(jac, tm, tp, u), abs=1e-7)


jac_st = hnp.arrays(np.float64, (3, 4), elements=st.floats(-3, 3, allow_subnormal=False))
travel_st = hnp.arrays(np.float64, (4,), elements=st.floats(0, 1, allow_subnormal=False))


@settings(max_examples=40, derandomize=True, deadline=None)
@given(jac_st, travel_st, travel_st)
def test_planes_are_tight_supporting_planes(jac, tm, tp):
    """For any input (hypothesis finds zeros, parallels, repeats): finite, every generator sum inside,
    every plane touched by one, and the force finite."""
    tm = -tm
    with jax.enable_x64(True):
        p = planes1(jac, tm, tp)
        f = np.asarray(W.plane_forces(p, 1.0, 5.0).force)
    normals, offsets, valid = (np.asarray(v) for v in p)
    assert np.all(np.isfinite(normals)) and np.all(np.isfinite(offsets)) and np.all(np.isfinite(f))
    pts = zonotope_points(jac, tm, tp)
    scale = 1.0 + np.abs(pts).max()
    tight = (pts @ normals[valid].T).max(axis=0)
    np.testing.assert_allclose(tight, offsets[valid], atol=1e-7 * scale)
    np.testing.assert_allclose(np.linalg.norm(normals[valid], axis=1), 1.0, atol=1e-12)
    assert np.all(normals[~valid] == 0) and np.all(offsets[~valid] == 0)


@settings(max_examples=25, derandomize=True, deadline=None)
@given(hnp.arrays(np.float64, (3,), elements=st.floats(-np.pi, np.pi)), st.permutations(range(4)), st.floats(0.1, 10.0))
def test_force_is_equivariant(angles, perm, scale):
    """Rotating J rotates the force; permuting cylinders changes nothing; scaling J by s and the decay
    length by s leaves the force unchanged (the decay-length form is unit-consistent)."""
    from scipy.spatial.transform import Rotation

    jac, tm, tp = _generic()
    rot = Rotation.from_euler("xyz", angles).as_matrix()
    perm = list(perm)
    with jax.enable_x64(True):
        f = np.asarray(W.repulsive_force_decay(jac, tm, tp, 1.5, 0.2))
        np.testing.assert_allclose(
            np.asarray(W.repulsive_force_decay(rot @ jac, tm, tp, 1.5, 0.2)), rot @ f, atol=1e-10
        )
        np.testing.assert_allclose(
            np.asarray(W.repulsive_force_decay(jac[:, perm], tm[perm], tp[perm], 1.5, 0.2)), f, atol=1e-10
        )
        np.testing.assert_allclose(
            np.asarray(W.repulsive_force_decay(scale * jac, tm, tp, 1.5, 0.2 * scale)), f, atol=1e-10
        )


def test_force_equals_sum_over_hull_facets():
    """Eqs. 12-13 with the planes from ConvexHull (independent of our construction)."""
    jac, tm, tp = random_cases(100, seed=7)
    with jax.enable_x64(True):
        for c in range(100):
            if not well_conditioned(jac[c]):
                continue
            facets, _ = hull_facets(zonotope_points(jac[c], tm[c], tp[c]))
            want = sum(-n * 2.0 * 0.2**b for n, b in facets)
            np.testing.assert_allclose(np.asarray(W.repulsive_force(jac[c], tm[c], tp[c], 2.0, 0.2)), want, atol=1e-10)
            np.testing.assert_allclose(
                np.asarray(W.repulsive_force_decay(jac[c], tm[c], tp[c], 2.0, -1.0 / np.log(0.2))), want, atol=1e-10
            )


def test_c2_form_depends_on_length_unit():
    """The same workspace in millimetres: C2^d changes, exp(-d / lambda) with lambda in mm does not."""
    jac, tm, tp = _generic()
    with jax.enable_x64(True):
        f_m = np.asarray(W.repulsive_force(jac, tm, tp, 1.0, 0.2))
        f_mm = np.asarray(W.repulsive_force(1000 * jac, tm, tp, 1.0, 0.2))
        lam = -1.0 / np.log(0.2)
        g_mm = np.asarray(W.repulsive_force_decay(1000 * jac, tm, tp, 1.0, 1000 * lam))
    assert np.linalg.norm(f_m - f_mm) > 0.1 * np.linalg.norm(f_m)
    np.testing.assert_allclose(g_mm, f_m, atol=1e-10)


def test_gradients():
    """Reverse mode against central differences (float64); the force is smooth away from ties of
    J_i . n = 0. (Forward mode is exercised by jacfwd in every Jacobian.)"""
    jac, tm, tp = _generic()
    with jax.enable_x64(True):
        check_grads(
            jax.jit(lambda j, a, b, lam: W.repulsive_force_decay(j, a, b, 1.0, lam)),
            (jac, tm, tp, 0.2),
            order=1,
            modes=("rev",),
            atol=1e-6,
            rtol=1e-6,
        )


@pytest.mark.parametrize("case", ["parallel", "zero_column", "flat", "zero", "nan"])
def test_gradients_finite_at_degenerate_inputs(case):
    jac, tm, tp = _generic()
    if case == "parallel":
        jac[:, 1] = jac[:, 0]
    elif case == "zero_column":
        jac[:, 3] = 0.0
    elif case == "flat":
        jac[2] = 0.0
    elif case == "zero":
        jac[:] = 0.0
    elif case == "nan":
        jac[0, 1] = np.nan

    # float32, the default and the tighter case for the guards.
    value, grad = _value_and_grad(*(jnp.asarray(v, jnp.float32) for v in (jac, tm, tp)))
    assert np.isfinite(float(value))
    assert np.all(np.isfinite(np.asarray(grad)))


@jax.jit
@jax.value_and_grad
def _value_and_grad(jac, tm, tp):
    return jnp.sum(W.plane_forces(W.limiting_planes(jac, tm, tp), 1.0, 3.0).force ** 2)


def test_validation_at_the_boundary_and_clamping_inside_jit():
    jac, tm, tp = _generic()
    with pytest.raises(ValueError, match="outside their stroke"):
        W.workspace_halfspaces(jac, tm, np.where(np.arange(4) == 2, -0.1, tp))
    with pytest.raises(ValueError, match="outside their stroke"):
        W.repulsive_force(jac, np.where(np.arange(4) == 0, 0.1, tm), tp, 1.0, 0.5)
    with pytest.raises(ValueError, match="shape"):
        W.workspace_halfspaces(jac[:2], tm, tp)
    with pytest.raises(ValueError, match="c2"):
        W.repulsive_force(jac, tm, tp, 1.0, 1.5)
    with pytest.raises(ValueError, match="non-finite"):
        W.workspace_halfspaces(np.full((3, 4), np.nan), tm, tp)
    bad_tp = np.where(np.arange(4) == 2, -0.1, tp)
    f = jax.jit(W.repulsive_force)(jnp.asarray(jac, jnp.float32), tm, bad_tp, 1.0, 0.5)
    assert bool(W.check_travel(tm, bad_tp)[2])
    np.testing.assert_allclose(f, W.repulsive_force(jac, tm, np.maximum(bad_tp, 0.0), 1.0, 0.5), atol=1e-6)
    f_nan = jax.jit(W.repulsive_force)(jnp.full((3, 4), jnp.nan), tm, tp, 1.0, 0.5)
    assert np.all(np.isfinite(np.asarray(f_nan)))


def test_no_recompile():
    """New values of J, travels, C1 and C2 reuse the compiled force (jit caches are per function,
    so count entries added after the first call)."""
    f = jax.jit(W.repulsive_force)
    rng = np.random.default_rng(8)

    def call():
        f(
            rng.normal(size=(3, 4)).astype(np.float32),
            -rng.uniform(size=4).astype(np.float32),
            rng.uniform(size=4).astype(np.float32),
            np.float32(rng.uniform(1, 2)),
            np.float32(rng.uniform(0.1, 0.9)),
        )

    call()
    before = compiled_count(f)
    for _ in range(4):
        call()
    assert compiled_count(f) == before


def test_linearise_any_forward_kinematics():
    """J by autodiff of an arbitrary JAX map equals central differences; planes as ConvexHull."""
    rng = np.random.default_rng(9)
    w1, b1, w2 = rng.normal(size=(6, 4)), rng.normal(size=6), rng.normal(size=(3, 6))

    def fk(q):
        return jnp.asarray(w2) @ jnp.tanh(jnp.asarray(w1) @ q + jnp.asarray(b1))

    q, lo, hi = rng.uniform(0.2, 0.8, 4), np.zeros(4), np.ones(4)
    with jax.enable_x64(True):
        ws = W.linearize(fk, q, lo, hi)
        h = 1e-6
        fd = np.stack([(np.asarray(fk(q + h * e)) - np.asarray(fk(q - h * e))) / (2 * h) for e in np.eye(4)], 1)
        np.testing.assert_allclose(np.asarray(ws.jacobian), fd, atol=1e-8)
        np.testing.assert_allclose(np.asarray(ws.position), np.asarray(fk(q)), atol=1e-15)
        facets, _ = hull_facets(zonotope_points(fd, lo - q, hi - q))
        match(ws.planes, facets, 1e-7)
        # Outside the stroke inside jit: clamped and flagged, never NaN.
        q_bad = q.copy()
        q_bad[1] = 1.3
        ws_bad = jax.jit(W.linearize, static_argnums=0)(fk, q_bad, lo, hi)
        assert np.asarray(ws_bad.out_of_range).tolist() == [False, True, False, False]
        assert float(ws_bad.travel_plus[1]) == 0.0
        with pytest.raises(ValueError, match="outside their stroke"):
            W.check_stroke(q_bad, lo, hi)


def test_workspace_halfspaces_generic_shape():
    jac, tm, tp = _generic()
    a, b = W.workspace_halfspaces(jac, tm, tp)
    assert a.shape == (12, 3) and b.shape == (12,)
    assert W.num_planes(4) == 26 and len(W.plane_labels(4)) == 26


# --- issue 22: the repulsion constants (c1 was not checked: NaN gave a NaN force, c1 < 0 an attractive one) ---------

CUBE = (jnp.eye(3), jnp.array([-0.1, -1.0, -1.0]), jnp.ones(3))  # near plane at x = -0.1 pushes towards +x


@pytest.mark.parametrize("c1", [float("nan"), -1.0, float("inf"), -float("inf"), 1e30])
def test_concrete_bad_c1_is_refused(c1):
    with pytest.raises(ValueError, match="c1"):
        W.repulsive_force(*CUBE, c1, 1e-3)
    with pytest.raises(ValueError, match="c1"):
        W.repulsive_force_decay(*CUBE, c1, 0.05)
    with pytest.raises(ValueError, match="c1"):
        W.plane_forces(W.limiting_planes(*CUBE), c1, 20.0)


@pytest.mark.parametrize("decay_length", [0.0, -0.05, float("nan"), float("inf")])
def test_concrete_bad_decay_length_is_refused(decay_length):
    with pytest.raises(ValueError, match="decay_length"):
        W.repulsive_force_decay(*CUBE, 1.0, decay_length)


@pytest.mark.parametrize("c1", [float("nan"), -1.0, float("inf"), 1e30])
def test_bad_c1_inside_jit_gives_zero_force_flagged(c1):
    """The documented rule: non-finite, negative or overflow-prone c1 gives zero force, never NaN or attraction."""
    f = jax.jit(W.repulsive_force)(*CUBE, c1, 1e-3)
    np.testing.assert_array_equal(np.asarray(f), 0.0)
    f = jax.jit(W.repulsive_force_decay)(*CUBE, c1, 0.05)
    np.testing.assert_array_equal(np.asarray(f), 0.0)
    out = jax.jit(W.plane_forces)(W.limiting_planes(*CUBE), c1, 20.0)
    np.testing.assert_array_equal(np.asarray(out.force), 0.0)
    np.testing.assert_array_equal(np.asarray(out.terms), 0.0)
    assert bool(out.bad_constants)


@pytest.mark.parametrize("c2", [float("nan"), 2.0, 0.0, -0.5])
def test_bad_c2_inside_jit_gives_zero_force(c2):
    """c2 > 1 made the force grow with distance; c2 <= 0 or NaN gave NaN."""
    f = jax.jit(W.repulsive_force)(*CUBE, 1.0, c2)
    np.testing.assert_array_equal(np.asarray(f), 0.0)


def test_good_constants_are_not_flagged():
    out = jax.jit(W.plane_forces)(W.limiting_planes(*CUBE), 1.0, 20.0)
    assert not bool(out.bad_constants) and float(out.force[0]) > 0.1
    out = jax.jit(W.plane_forces)(W.limiting_planes(*CUBE), 0.0, 0.0)  # c1 = 0 and no decay: valid, zero
    assert not bool(out.bad_constants)
