"""The fused Pallas FootCost kernel against the XLA FootCost (interpreted on the CPU, the same kernel code)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import footcost, select
from ijoy_jax.footcost.pallas import foot_cost_fused
from ijoy_jax.testing import rest_metrics

RES = 0.02
SHAPE = (48, 48)
# Totals are sums of the same float32 terms in a different order (plane-fit sums column by column instead of
# one reduction): a few ulps of the largest term. Measured: 3e-8 on the CPU, 6e-8 on an H200.
ATOL = 1e-5
RTOL = 1e-5


def _terrain(kind: str, seed: int):
    """A small map with obstacles and, for 2.5D, a swell, a 4 cm platform and a 15 cm block."""
    rng = np.random.default_rng(seed)
    free = rng.random(SHAPE) > 0.003
    if kind == "2d":
        return ij.terrain.from_arrays(None, free, RES)
    x = np.arange(SHAPE[0])[:, None] * RES
    h = 0.03 * np.sin(2.0 * x + seed) + 0.002 * rng.standard_normal(SHAPE)
    i, j = rng.integers(8, 30, 2)
    h[i:i + 12, j:j + 14] += 0.04
    h[j:j + 4, i:i + 5] += 0.15
    return ij.terrain.from_arrays(h.astype(np.float32), free, RES)


def _queries(n: int, seed: int):
    """Stances over the map (some steps leave it) and swing starts beside them."""
    rng = np.random.default_rng(seed)
    size = SHAPE[0] * RES
    stance = np.column_stack([rng.uniform(0.1, size - 0.1, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    swing = stance + np.column_stack([rng.uniform(-0.2, 0.2, (n, 2)), np.zeros(n)])
    return jnp.asarray(stance, jnp.float32), jnp.asarray(swing, jnp.float32)


# Every harness call runs this many stances, each with one candidate per action (stances and given steps are
# padded by repetition, the results cut back): one compiled program per terrain kind and swing/no-swing serves
# every test, since the interpreted kernel's compile is what these tests cost, not its run.
BATCH = 6


@functools.partial(jax.jit, static_argnames="fused")
def _totals(terrain, robot, stance, swing, steps, active, fused):
    """Fused totals (B, K), or the XLA path's terms (each (B, K)), of ``steps`` (B, K, 3) from each stance (B, 3);
    ``active`` (B,) bool is the fused kernel's (the XLA path has none)."""
    index = footcost.index_terrain(terrain, robot)
    idx = jnp.arange(steps.shape[1]) % robot.num_actions

    def one(s, w, cand, on):
        if fused:
            return foot_cost_fused(terrain, robot, s, -1, cand, swing_from=w, action_index=idx, index=index,
                                   active=on)
        return footcost.foot_cost_terms(terrain, robot, s, -1, cand, swing_from=w, action_index=idx, index=index)

    return jax.vmap(one, in_axes=(0, 0 if swing is not None else None, 0, 0))(stance, swing, steps, active)


@jax.jit
def _action_steps(robot, stance):
    """(B, N, 3) every action's step from each right-foot stance (B, 3)."""
    return jax.vmap(lambda s: ij.action_steps(robot, s, -1))(stance)


def _both_terms(terrain, robot, stance, swing, steps=None, active=None):
    """(XLA terms, fused totals) of every action of each of the n stances (or of the given (K, 3) steps from each),
    each (n, N) or (n, K): computed on the BATCH x num_actions harness, so shapes never add a compile. ``active``
    (n,) bool: the fused kernel's (None: every query)."""
    n = stance.shape[0]
    assert n <= BATCH
    stance = jnp.asarray(np.resize(np.asarray(stance), (BATCH, 3)))
    swing = None if swing is None else jnp.asarray(np.resize(np.asarray(swing), (BATCH, 3)))
    num = robot.num_actions
    if steps is None:
        k = num
        cand = _action_steps(robot, stance)
    else:
        k = steps.shape[0]
        assert k <= num
        padded = np.concatenate([np.asarray(steps), np.repeat(np.asarray(steps)[:1], num - k, axis=0)])
        cand = jnp.broadcast_to(jnp.asarray(padded), (BATCH, num, 3))
    on = jnp.asarray(np.resize(np.ones(n, bool) if active is None else np.asarray(active, bool), BATCH))
    terms = jax.tree.map(lambda a: np.asarray(a)[:n, :k], _totals(terrain, robot, stance, swing, cand, on, False))
    fused = np.asarray(_totals(terrain, robot, stance, swing, cand, on, True))[:n, :k]
    return terms, fused


def _both(terrain, robot, stance, swing, steps=None):
    """(XLA totals, fused totals) for every action of each stance (or the given steps); one compile per kind."""
    terms, fused = _both_terms(terrain, robot, stance, swing, steps)
    return np.asarray(terms.total), fused


def _assert_same(xla, fused):
    finite = np.isfinite(xla)
    np.testing.assert_array_equal(np.isfinite(fused), finite)
    np.testing.assert_allclose(fused[finite], xla[finite], rtol=RTOL, atol=ATOL)
    assert not np.any(np.isnan(fused))


@pytest.mark.parametrize("kind, margin, max_margin, with_swing", [
    ("2d", 0.02, 0.1, False),  # the fast tier's check of the kernel; the 2.5D kernel is the slow tier's
    pytest.param("25d", 0.02, 0.1, True, marks=pytest.mark.slow),  # default windows: columns span <= 16 rows
    pytest.param("25d", 0.1, 0.1, True, marks=pytest.mark.slow),  # 10 cm margin: columns of up to ~28 rows
    pytest.param("25d", 0.0, 0.02, False, marks=pytest.mark.slow),  # no margin, tight windows, no corridor
])
def test_totals_match_the_xla_footcost(kind, margin, max_margin, with_swing):
    robot = ij.robots.hrp2(margin=margin, max_margin=max_margin)
    # The map's 2 mm cell noise leaves soles on a few of their points: with a 2 mm contact tolerance every case
    # keeps both valid steps (59 or more of 2976 at the 10 cm margin) and steps the support term rejects.
    robot = robot.replace(metrics=robot.metrics.replace(contact_tol=jnp.float32(0.002)))
    terrain = _terrain(kind, seed=1)
    stance, swing = _queries(6, seed=2)
    xla, fused = _both(terrain, robot, stance, swing if with_swing else None)
    _assert_same(xla, fused)
    valid = np.isfinite(xla)
    assert valid.sum() >= 50 and valid.mean() < 0.95, valid.mean()  # both valid and invalid steps are probed



@pytest.mark.slow
def test_the_support_term_rejects_the_same_steps_on_both_paths():
    """The rested sole's support (bilinear ground at the sole's six contact points, footcost.sole) is the only term
    that rejects a share of the steps here; the kernel's reads of the padded map reject exactly those, and its
    finite totals agree."""
    robot = ij.robots.hrp2(margin=0.02)
    robot = robot.replace(metrics=robot.metrics.replace(contact_tol=jnp.float32(0.001),
                                                        roughness_limit=jnp.float32(1.0), bump_limit=jnp.float32(1.0)))
    terrain = _terrain("25d", seed=1)
    stance, swing = _queries(6, seed=2)
    terms, fused = _both_terms(terrain, robot, stance, swing)
    xla = terms.total
    _assert_same(xla, fused)
    support_only = np.isinf(np.asarray(terms.support)) & np.all([np.isfinite(np.asarray(getattr(terms, t))) for t in (
        "obstacle", "slope", "roughness", "bump", "step", "band", "swing_path", "ankle", "reach",
        "unsupported")], axis=0)
    assert support_only.sum() >= 50 and np.isfinite(xla).sum() >= 50, (support_only.sum(), np.isfinite(xla).sum())
    assert np.isinf(fused[support_only]).all()


@pytest.mark.slow
def test_plane_fit_keeps_its_precision_at_altitude_and_across_relief():
    """The kernel fits planes from block prefix sums of heights less each block's first height, the XLA path
    from heights less each foot's own: at 50 m altitude (float32 ulp 4e-6 m) on a 20 % ramp they still agree
    to the same tolerance. A map mean computed in the same jit, fused unrounded into that subtraction, lost
    3e-5 here. (One stored offset for the whole map passed here but lost 8e-6 on an H100 over the benchmark
    map's relief: GPU agreement is measured by ``ijoy bench check``.)"""
    robot = ij.robots.hrp2(margin=0.02)
    base = _terrain("25d", seed=4)
    ramp = 0.2 * RES * np.arange(SHAPE[0], dtype=np.float32)[:, None]
    terrain = ij.terrain.from_arrays(np.asarray(base.height) + ramp + np.float32(50.0), np.asarray(base.free), RES)
    stance, swing = _queries(6, seed=8)
    xla, fused = _both(terrain, robot, stance, swing)
    _assert_same(xla, fused)
    assert np.isfinite(xla).sum() >= 50


@pytest.mark.slow
def test_off_map_oversized_and_non_finite_steps_are_inf():
    robot = ij.robots.hrp2(margin=0.02)
    terrain = ij.terrain.from_arrays(np.zeros(SHAPE, np.float32), np.ones(SHAPE, bool), RES)
    stance = jnp.array([[0.5, 0.5, 0.3]], jnp.float32)
    steps = jnp.array([[0.5, 0.7, 0.3], [-0.3, 0.5, 0.0], [5.0, 5.0, 1.0], [jnp.nan, 0.5, 0.0],
                       [0.5, jnp.inf, 0.0], [0.6, 0.6, -jnp.inf]], jnp.float32)
    xla, fused = _both(terrain, robot, stance, stance, steps)
    _assert_same(xla, fused)
    assert np.isfinite(fused[0, 0]) and np.all(np.isinf(fused[0, 1:]))
    # A margin beyond the static windows is flagged unsupported, as in the XLA path.
    wide = robot.replace(margin=jnp.float32(0.2))
    xla, fused = _both(terrain, wide, stance, stance, steps)  # same shapes: no new compile
    assert np.isinf(xla).all() and np.isinf(fused).all()


@pytest.mark.slow
def test_steps_far_off_the_map_are_inf_at_every_magnitude():
    """As in the XLA path (test_footcost.test_off_map_is_an_obstacle_at_every_magnitude): float32 keeps no
    footprint width at 1e7 m, yet such a step is off the map."""
    robot = ij.robots.hrp2(margin=0.02)
    terrain = ij.terrain.from_arrays(np.zeros(SHAPE, np.float32), np.ones(SHAPE, bool), RES)
    stance = jnp.array([[0.5, 0.5, 0.0]], jnp.float32)
    far = [[0.5, 0.7, 0.0]] + [[s * v, 0.5, 0.0] for v in (1e7, 1e30) for s in (1, -1)] + [[0.5, 3e9, 0.3]]
    xla, fused = _both(terrain, robot, stance, None, jnp.asarray(far, jnp.float32))  # no swing: its length flags
    _assert_same(xla, fused)
    assert np.isfinite(fused[0, 0]) and np.all(np.isinf(fused[0, 1:]))


@pytest.mark.slow
def test_one_rule_for_limits_a_metric_at_its_limit_is_decided_alike_on_both_paths():
    """Limits are set to the XLA path's own metrics, shifted by less than float32 rounding, by half the
    tolerance and by three times it: at the limit (to rounding) and within LIMIT_TOL above it, both paths accept;
    beyond it, both reject. Per-action step limits put every candidate at its limit at once; the slope, the sole's
    pitch and roll and the soles' distance are set at one step's."""
    tol = footcost.xla.LIMIT_TOL
    terrain = _terrain("25d", seed=5)
    loose = ij.robots.hrp2(margin=0.02)
    loose = loose.replace(metrics=loose.metrics.replace(
        slope_limit=jnp.float32(1.5), roughness_limit=jnp.float32(1.0), bump_limit=jnp.float32(1.0),
        band_limit=jnp.float32(1.0), support_limit=jnp.float32(1.0)),
        max_step_height=jnp.full(loose.num_actions, 1.0, jnp.float32),
        max_sole_pitch=jnp.float32(1.5), max_sole_roll=jnp.float32(1.5), max_sole_distance=jnp.float32(1.0))
    stance = jnp.array([[0.45, 0.5, 0.3]], jnp.float32)
    idx = np.arange(0, loose.num_actions, 31)[:16]
    steps = ij.action_steps(loose, stance[0], -1)[idx]
    terms = jax.tree.map(lambda a: a[0], _both_terms(terrain, loose, stance, None, steps)[0])
    open_ = np.isfinite(np.asarray(terms.total))
    assert open_.sum() >= 8
    dh = np.abs(np.asarray(terms.step_height_m))
    slope = np.asarray(terms.slope_angle)
    pitch, roll = np.asarray(terms.sole_pitch_rad), np.asarray(terms.sole_roll_rad)
    distance = np.asarray(terms.sole_distance_m)
    support = np.asarray(terms.support_m)
    i = int(np.flatnonzero(open_ & (slope > 0.05) & (np.abs(pitch) > 0.02) & (np.abs(roll) > 0.02)
                           & (support > 1e-3))[0])

    def totals(robot):
        return _both(terrain, robot, stance, None, steps)  # steps given: action_index cycles over them

    for d, accept in ((0.0, True), (1e-7, True), (-1e-7, True), (0.5 * tol, True), (3 * tol, False)):
        limits = np.full(loose.num_actions, 1.0, np.float32)
        limits[np.arange(len(idx)) % loose.num_actions] = dh - d  # the harness's action_index is arange(N)
        xla, fused = totals(loose.replace(max_step_height=jnp.asarray(limits)))
        np.testing.assert_array_equal(np.isfinite(xla[0]), np.isfinite(fused[0]))
        np.testing.assert_array_equal(np.isfinite(xla[0])[open_], np.full(open_.sum(), accept))
        for name, metric in (("slope_limit", slope[i]), ("support_limit", support[i])):
            xla, fused = totals(loose.replace(metrics=loose.metrics.replace(**{name: jnp.float32(metric - d)})))
            assert np.isfinite(xla[0, i]) == np.isfinite(fused[0, i]) == accept, (name, d, xla[0, i], fused[0, i])
        # The ankle's pitch and roll limits and the legs' reach, at the XLA path's own metrics of step i.
        for leaf, metric in (("max_sole_pitch", abs(pitch[i])), ("max_sole_roll", abs(roll[i])),
                             ("max_sole_distance", distance[i])):
            xla, fused = totals(loose.replace(**{leaf: jnp.float32(metric - d)}))
            assert np.isfinite(xla[0, i]) == np.isfinite(fused[0, i]) == accept, (leaf, d, xla[0, i], fused[0, i])


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["2d", "25d"])
def test_ankle_and_reach_terms_match_the_xla_path(kind):
    """The sole's tilt on the fitted plane against max_sole_pitch / max_sole_roll, and the soles' 3D distance
    against max_sole_distance, decided alike on both paths: on a tilted swell (up to ~20 deg) with limits tightened
    so that each of them alone refuses some steps that every other term accepts."""
    robot = ij.robots.hrp2(margin=0.02)
    robot = robot.replace(metrics=robot.metrics.replace(slope_limit=jnp.float32(1.2), roughness_limit=jnp.float32(1.0),
                                                        bump_limit=jnp.float32(1.0), band_limit=jnp.float32(1.0)),
                          max_step_height=jnp.full(robot.num_actions, 1.0, jnp.float32),
                          max_sole_pitch=jnp.float32(0.2), max_sole_roll=jnp.float32(0.12),
                          max_sole_distance=jnp.float32(0.33))
    x, y = np.meshgrid(np.arange(SHAPE[0]) * RES, np.arange(SHAPE[1]) * RES, indexing="ij")
    h = (0.08 * x + 0.05 * y + 0.05 * np.sin(6 * x) * np.cos(5 * y)).astype(np.float32)
    terrain = ij.terrain.from_arrays(h if kind == "25d" else None, np.ones(SHAPE, bool), RES)
    stance, swing = _queries(4, seed=12)
    stance = jnp.clip(stance, 0.35, 0.6).at[:, 2].set(stance[:, 2])  # every step on the map
    terms, fused = _both_terms(terrain, robot, stance, swing if kind == "25d" else None)
    xla = terms.total
    _assert_same(xla, fused)
    others = sum(np.asarray(getattr(terms, f)) for f in ("action", "obstacle", "slope", "roughness", "bump", "step",
                                                          "band", "unsupported"))
    ankle, reach = np.isinf(np.asarray(terms.ankle)), np.isinf(np.asarray(terms.reach))
    assert (reach & ~ankle & np.isfinite(others)).sum() >= 50  # steps only the reach term refuses
    if kind == "25d":
        assert (ankle & ~reach & np.isfinite(others)).sum() >= 50  # ... and only the ankle term
        pitch_only = np.abs(np.asarray(terms.sole_pitch_rad)) > 0.2 + 1e-4
        roll_only = np.abs(np.asarray(terms.sole_roll_rad)) > 0.12 + 1e-4
        assert (pitch_only & ~roll_only).any() and (roll_only & ~pitch_only).any()
    else:
        assert not ankle.any()  # level soles on a 2D map


@pytest.mark.slow
@settings(max_examples=15)  # each example is ~500 interpreted candidates on 2.5D; the CI has 2 cores
@given(seed=st.integers(0, 2**16), margin=st.sampled_from([0.0, 0.01, 0.03, 0.06]))
def test_property_fused_equals_xla_on_random_maps(seed, margin):
    robot = ij.robots.hrp2(margin=margin)
    terrain = _terrain("25d", seed=seed)
    stance, swing = _queries(1, seed=seed + 1)
    xla, fused = _both(terrain, robot, stance, swing)
    _assert_same(xla, fused)


@pytest.mark.slow
def test_vmap_over_terrains_shares_nothing_between_them():
    robot = ij.robots.hrp2(margin=0.02)
    terrains = [_terrain("25d", seed=s) for s in (4, 5)]
    batch = jax.tree.map(lambda *a: jnp.stack(a), *terrains)
    stance, swing = _queries(2, seed=6)
    index_of = jax.vmap(lambda t: footcost.index_terrain(t, robot))

    def one(t, i, s, w):
        return foot_cost_fused(t, robot, s, -1, ij.action_steps(robot, s, -1), swing_from=w,
                               action_index=jnp.arange(robot.num_actions), index=i)

    both = np.asarray(jax.jit(jax.vmap(one))(batch, index_of(batch), stance, swing))
    for b, t in enumerate(terrains):
        xla, _ = _both(t, robot, stance[b:b + 1], swing[b:b + 1])
        _assert_same(xla[0], both[b])


@pytest.mark.slow
@pytest.mark.parametrize("method", ["exhaustive", "ordered"])
def test_select_step_with_the_kernel_chooses_the_same_steps(method):
    robot = ij.robots.hrp2(margin=0.02)
    terrain = _terrain("25d", seed=7)  # no swing corridor here: the exhaustive/ordered agreement is the point
    targets = ij.make_targets(robot)
    index = footcost.index_terrain(terrain, robot)
    rng = np.random.default_rng(8)
    n = 6
    stance = jnp.asarray(np.column_stack([rng.uniform(0.35, 0.6, (n, 2)), rng.uniform(-np.pi, np.pi, n)]),
                         jnp.float32)
    command = jnp.asarray(rng.uniform(-0.3, 0.3, (n, 3)), jnp.float32)

    def one(s, c, kernel):
        ch = select.select_step(terrain, robot, s, -1, c, options=ij.SelectOptions(method=method, kernel=kernel),
                                targets=targets, index=index)
        return ch.index, ch.cost, ch.valid, ch.foothold, ch.evaluated

    run = jax.jit(jax.vmap(one, in_axes=(0, 0, None)), static_argnums=2)
    (ia, ca, va, fa, ea), (ib, cb, vb, fb, eb) = run(stance, command, "xla"), run(stance, command, "pallas")
    np.testing.assert_array_equal(np.asarray(eb), np.asarray(ea))
    if method == "ordered":  # queries that finish before the batch's slowest: the kernel idles on them
        assert len(set(np.asarray(ea).tolist())) > 1, np.asarray(ea)
    np.testing.assert_array_equal(np.asarray(ib), np.asarray(ia))
    np.testing.assert_allclose(np.asarray(fb), np.asarray(fa), atol=1e-6)  # the same step's plane: one XLA fit
    np.testing.assert_array_equal(np.asarray(vb), np.asarray(va))
    assert np.asarray(va).sum() >= n // 2
    np.testing.assert_allclose(np.asarray(cb)[np.asarray(va)], np.asarray(ca)[np.asarray(va)], rtol=RTOL, atol=ATOL)


@pytest.mark.slow
def test_public_select_step_kernel_option_and_no_recompile():
    robot = ij.robots.hrp2(margin=0.02)
    terrain = _terrain("2d", seed=9)
    fused = ij.SelectOptions(method="exhaustive", kernel="pallas")
    a = ij.select_step(terrain, robot, [0.5, 0.5, 0.0], -1, [0.2, 0.0, 0.0], fused)
    b = ij.select_step(terrain, robot, [0.5, 0.5, 0.0], -1, [0.2, 0.0, 0.0],
                       options=ij.SelectOptions(method="exhaustive"))
    assert int(a.index) == int(b.index) and bool(a.valid) == bool(b.valid)
    n = select.compiled_programs()
    ij.select_step(terrain, robot.replace(w=jnp.float32(3.0), margin=jnp.float32(0.05)), [0.6, 0.4, 1.0], -1,
                   [0.0, 0.1, -0.2], fused)
    assert select.compiled_programs() == n
    with pytest.raises(ValueError, match="kernel must be one of"):
        ij.select_step(terrain, robot, [0.5, 0.5, 0.0], -1, [0.2, 0.0, 0.0], options=ij.SelectOptions(kernel="cuda"))


def test_an_inactive_query_is_inf_everywhere_and_leaves_the_batchs_others_alone():
    """``active=False`` (a vmapped ordered search's finished query) makes every total of that query +inf, the
    kernel skipping its loops; the batch's active queries get exactly the totals of an all-active batch."""
    robot = ij.robots.hrp2(margin=0.02)
    terrain = _terrain("2d", seed=3)
    stance, _ = _queries(BATCH, seed=4)
    active = np.arange(BATCH) % 2 == 0
    xla, every = _both(terrain, robot, stance, None)
    _, some = _both_terms(terrain, robot, stance, None, active=active)  # the same program: no compile
    assert np.isfinite(every[~active]).sum() >= 50  # the idle queries had valid steps to skip
    assert np.isinf(some[~active]).all()
    np.testing.assert_array_equal(some[active], every[active])
    _assert_same(xla, every)


@pytest.mark.parametrize("active, why", [(1.0, "float"), (jnp.float32(1.0), "float32\\[\\]"),
                                         (jnp.ones(2, bool), "bool\\[2\\]"), ("yes", "str")])
def test_active_must_be_one_bool(active, why):
    robot = ij.robots.hrp2(margin=0.02)
    terrain = _terrain("2d", seed=0)
    with pytest.raises(ValueError, match=f"active must be a \\(\\) bool.*{why}"):
        foot_cost_fused(terrain, robot, jnp.zeros(3), -1, jnp.zeros((4, 3)), active=active)


def test_block_must_be_a_power_of_two():
    robot = ij.robots.hrp2(margin=0.02)
    terrain = _terrain("2d", seed=0)
    index = footcost.index_terrain(terrain, robot)
    with pytest.raises(ValueError, match="power of two"):
        foot_cost_fused(terrain, robot, jnp.zeros(3), -1, jnp.zeros((4, 3)), index=index, block=48)


@pytest.mark.slow
def test_rollout_with_the_kernel_walks_the_same_steps():
    robot = ij.robots.hrp2(margin=0.02)
    terrain = _terrain("25d", seed=10)
    start = np.array([[0.3, 0.495, 0.0], [0.3, 0.305, 0.0]])
    kw = dict(commands=[0.25, 0.05, 0.2], num_steps=4)
    a = ij.rollout(terrain, robot, start, options=ij.SelectOptions(method="ordered"), **kw)
    b = ij.rollout(terrain, robot, start, options=ij.SelectOptions(method="ordered", kernel="pallas"), **kw)
    assert np.asarray(a.valid).sum() >= 2  # the walk really moves
    np.testing.assert_array_equal(np.asarray(b.valid), np.asarray(a.valid))
    np.testing.assert_allclose(np.asarray(b.footsteps), np.asarray(a.footsteps), atol=1e-6)
    with pytest.raises(ValueError, match="kernel must be one of"):
        ij.rollout(terrain, robot, start, options=ij.SelectOptions(method="ordered", kernel="triton"), **kw)


@pytest.mark.slow
def test_kernel_column_spans_equal_the_geometry_module():
    """The kernel's chain-based spans equal geometry.rect_column_spans at random, axis-aligned, nearly
    axis-aligned, grid-aligned and zero-length rectangles (the swing corridor of a step in place)."""
    from ijoy_jax import geometry
    from ijoy_jax.footcost.pallas import _Rect

    rng = np.random.default_rng(11)
    n, k = 4000, 29
    cx, cy = rng.uniform(0.3, 0.7, n), rng.uniform(0.3, 0.7, n)
    theta = rng.uniform(-np.pi, np.pi, n)
    special = n // 4
    theta[:special] = rng.choice([0.0, np.pi / 2, np.pi, -np.pi / 2, np.pi / 4], special)
    cx[:special // 2] = np.round(cx[:special // 2] / 0.01) * 0.01  # centres on cell edges and centres
    cy[:special // 2] = np.round(cy[:special // 2] / 0.01) * 0.01
    half_length = np.where(rng.random(n) < 0.1, 0.0, 0.141)
    # Nearly axis-aligned (a swing corridor straight ahead, its angle from arctan2 of rounding noise): rounded
    # corners may leave one of two opposite short edges exactly vertical and the other not.
    near = np.random.default_rng(12)
    m = 1000
    cx, cy = np.concatenate([cx, near.uniform(0.3, 0.7, m)]), np.concatenate([cy, near.uniform(0.3, 0.7, m)])
    theta = np.concatenate([theta, near.integers(-2, 3, m) * np.pi / 2 + near.choice([-1, 1], m)
                            * near.choice([1e-7, 2e-7, 5e-7, 1e-6, 1e-5, 1e-4], m)])
    half_length = np.concatenate([half_length, near.choice([0.141, 0.15, 0.2], m)])
    cx, cy, theta, half_length = (jnp.asarray(a, jnp.float32) for a in (cx, cy, theta, half_length))
    ref = jax.vmap(lambda x, y, t, hl: geometry.rect_column_spans(x, y, t, hl, 0.085, RES, k))(
        cx, cy, theta, half_length)
    rect = _Rect(cx, cy, jnp.cos(theta), jnp.sin(theta), half_length, jnp.float32(0.085), RES)
    np.testing.assert_array_equal(np.asarray(rect.ix_first), np.asarray(ref.ix[:, 0]))
    for i in range(k):
        j0, j1, touched = (np.asarray(a) for a in rect.spans(rect.ix_first + i))
        np.testing.assert_array_equal(touched, np.asarray(ref.touched[:, i]))
        np.testing.assert_array_equal(j0[touched], np.asarray(ref.j0[:, i])[touched])
        np.testing.assert_array_equal(j1[touched], np.asarray(ref.j1[:, i])[touched])


@jax.jit
def _corridors(cx, cy, sx, sy, half_width):
    """Column spans of the swing corridors from (sx, sy) to each (cx, cy), as the XLA path builds them."""
    return jax.vmap(lambda x, y: footcost.swing_corridor(sx, sy, x, y, half_width, RES, 64)[0])(cx, cy)


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**16))
def test_corridor_box_holds_every_corridor_cell_and_box_top_is_its_highest_cell(seed):
    """The swing corridor's broad phase: the box of footcost.pallas.corridor_box holds every cell of the
    corridor (geometry.rect_column_spans, as the XLA path builds it) of every set lane, and box_top_height is
    the brute-force highest height in that box (+inf when the box leaves the map)."""
    from ijoy_jax.footcost.pallas import box_top_height, corridor_box

    rng = np.random.default_rng(seed)
    lanes, hw = 32, 0.065
    sx, sy = rng.uniform(0.0, SHAPE[0] * RES, 2)
    cx = np.float32(sx) + rng.uniform(-0.45, 0.45, lanes).astype(np.float32)
    cy = np.float32(sy) + rng.uniform(-0.45, 0.45, lanes).astype(np.float32)
    lane = rng.random(lanes) < 0.7
    box = [int(v) for v in corridor_box(jnp.asarray(lane), jnp.asarray(cx), jnp.asarray(cy), jnp.float32(sx),
                                        jnp.float32(sy), jnp.float32(hw), RES)]
    ix0, ix1, iy0, iy1 = box
    spans = _corridors(jnp.asarray(cx), jnp.asarray(cy), jnp.float32(sx), jnp.float32(sy), jnp.float32(hw))
    t = np.asarray(spans.touched) & lane[:, None]
    assert np.all(np.asarray(spans.ix)[t] >= ix0) and np.all(np.asarray(spans.ix)[t] <= ix1)
    assert np.all(np.asarray(spans.j0)[t] >= iy0) and np.all(np.asarray(spans.j1)[t] <= iy1)
    assert not np.any(np.asarray(spans.overflow)[lane])
    if not lane.any():
        assert ix1 < ix0
    terrain = _terrain("25d", seed=seed)
    index = footcost.index_terrain(terrain, ij.robots.hrp2(margin=0.02))
    top = float(box_top_height(index.height_max, box, SHAPE, lanes))
    inside = ix0 >= 0 and iy0 >= 0 and ix1 < SHAPE[0] and iy1 < SHAPE[1]
    h = np.asarray(terrain.height)
    want = (h[ix0:ix1 + 1, iy0:iy1 + 1].max(initial=-np.inf)) if inside else np.inf
    assert top == want


@pytest.mark.slow
def test_corridor_broad_phase_keeps_every_swing_path_rejection():
    """On flat ground the broad phase proves every corridor clear; across a 15 cm wall (above the 10 cm
    clearance) between the swing start and the steps it cannot, and the exact walk must reject the steps whose
    corridor crosses the wall, as the XLA path does. Totals equal the XLA path's and the kernel's own without
    the broad phase (one compile each: the maps differ only in their heights)."""
    robot = ij.robots.hrp2(margin=0.02)
    stance = jnp.array([0.45, 0.4, 0.0], jnp.float32)
    swing = jnp.array([0.25, 0.59, 0.0], jnp.float32)
    steps = ij.action_steps(robot, stance, -1)
    idx = jnp.arange(robot.num_actions)
    xla = jax.jit(lambda t, i: footcost.foot_cost_terms(t, robot, stance, -1, steps, swing_from=swing,
                                                        action_index=idx, index=i))
    fused = {bp: jax.jit(lambda t, i, bp=bp: foot_cost_fused(t, robot, stance, -1, steps, swing_from=swing,
                                                             action_index=idx, index=i, broad_phase=bp))
             for bp in (True, False)}
    for wall in (False, True):
        h = np.zeros(SHAPE, np.float32)
        if wall:
            h[18, 24:44] = 0.15  # x = 0.36-0.38 m, y = 0.48-0.88 m
        terrain = ij.terrain.from_arrays(h, np.ones(SHAPE, bool), RES)
        index = footcost.index_terrain(terrain, robot)
        terms = xla(terrain, index)
        others = sum(np.asarray(getattr(terms, f)) for f in ("action", "obstacle", "slope", "roughness", "bump",
                                                              "step", "band", "unsupported"))
        only_path = np.isinf(np.asarray(terms.swing_path)) & np.isfinite(others)
        assert (only_path.sum() >= 20) == wall, only_path.sum()  # steps that only the swing path rejects
        for f in fused.values():
            _assert_same(np.asarray(terms.total), np.asarray(f(terrain, index)))


# --------------------------------------------------------------------------- issue #22: one flag, both paths

SMALL = ij.robots.hrp2(margin=0.02, density=0.1)  # 10 actions: small interpreted programs
FLAT = ij.terrain.from_arrays(np.zeros(SHAPE, np.float32), np.ones(SHAPE, bool), RES)
STANCE = jnp.array([0.45, 0.4, 0.0], jnp.float32)  # a right foot; the left one swings to y ~ 0.59
SWING = jnp.array([0.45, 0.59, 0.0], jnp.float32)
HOSTILE = [np.nan, np.inf, -np.inf, 1e30, -1e30, 1e-30, -1.0, 0.0, -0.0, 1e39, 0.5, 3.0]
"""Values a careless or hostile user sets by ``replace`` or vmap inside a jit (1e39 is inf in float32)."""
COST_TERMS = ("action", "obstacle", "slope", "roughness", "bump", "step", "band", "support", "swing_path",
              "unsupported")


@jax.jit
def _both_traced(terrain, robot):
    """(XLA terms, fused totals) of SMALL's action steps with terrain and robot traced (one compile each)."""
    steps = ij.action_steps(robot, STANCE, -1)
    idx = jnp.arange(robot.num_actions)
    kw = dict(swing_from=SWING, action_index=idx)
    return (footcost.foot_cost_terms(terrain, robot, STANCE, -1, steps, **kw),
            foot_cost_fused(terrain, robot, STANCE, -1, steps, **kw))


def _refused(terrain, robot) -> bool:
    """Whether the boundary checks refuse these (concrete) values."""
    try:
        ij.robots.check_robot(robot)
        ij.terrain.check_terrain(terrain)
        footcost.xla.check_frame(terrain)
    except ValueError:
        return True
    return False


def _assert_flagged_alike(terrain, robot):
    """Both paths on traced values: no NaN anywhere, the same steps +inf, and every step +inf with the
    ``unsupported`` term set exactly where query_supported (the one rule) is False, which is exactly where the
    concrete boundary checks refuse the same values."""
    terms, fused = _both_traced(terrain, robot)
    xla, fused = np.asarray(terms.total), np.asarray(fused)
    for name in COST_TERMS:
        assert not np.isnan(np.asarray(getattr(terms, name))).any(), name
    assert not np.isnan(xla).any() and not np.isnan(fused).any()
    supported = bool(footcost.query_supported(terrain, robot))
    assert supported == (not _refused(terrain, robot))
    unsupported = np.isinf(np.asarray(terms.unsupported))
    if not supported:
        assert unsupported.all() and np.isinf(xla).all() and np.isinf(fused).all()
    else:
        assert not unsupported.any() and (xla >= 0).all() and np.isfinite(xla).any()
        _assert_same(xla, fused)
    return supported


ROBOT_FIELDS = ["margin", "foot_length", "foot_width", "w", "rotation_weight", "metrics.slope_weight",
                "metrics.slope_limit", "metrics.band_limit", "metrics.contact_tol", "metrics.contact_inset",
                "action_cost", "clearance", "max_step_height"]


@pytest.mark.slow
# 1e39 overflows to inf as it is cast to float32: NumPy's warning is that hostile value arriving, as meant
@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
@settings(max_examples=30, deadline=None)
@given(field=st.sampled_from([*ROBOT_FIELDS, "origin", "height"]), v=st.sampled_from(HOSTILE),
       cell=st.tuples(st.integers(0, SHAPE[0] - 1), st.integers(0, SHAPE[1] - 1)))
def test_both_paths_flag_hostile_traced_robot_and_terrain_values_alike(field, v, cell):
    """The fused kernel called inside a jit applies the XLA path's rule (footcost.query_supported: the robot's,
    the terrain's and the frame's) for the same hostile traced values, with the same outcome per step."""
    robot, terrain = SMALL, FLAT
    if field in ("action_cost", "clearance", "max_step_height"):
        robot = robot.replace(**{field: jnp.full(robot.num_actions, v, jnp.float32)})
    elif field == "origin":
        terrain = terrain.replace(origin=jnp.array([v, 0.0], jnp.float32))
    elif field == "height":
        terrain = terrain.replace(height=terrain.height.at[cell].set(v))
    else:
        robot = ij.robots.set_leaf(robot, field, jnp.float32(v))
    _assert_flagged_alike(terrain, robot)


@pytest.mark.slow
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("where", ["under the stance foot", "under a step", "in a swing corridor", "far away"])
def test_non_finite_heights_inside_jit_flag_every_step_on_both_paths(value, where):
    """A NaN/inf height that reaches a trace (replace, vmap) is refused where concrete; inside the jit every step
    is +inf with the ``unsupported`` term, on both paths, with every cost term and raw metric free of NaN, and
    select_step reports ``unsupported`` (never a NaN cost, never a valid step); the finite map is not."""
    cell = {"under the stance foot": (22, 20), "under a step": (22, 30), "in a swing corridor": (22, 25),
            "far away": (2, 45)}[where]
    terrain = FLAT.replace(height=FLAT.height.at[cell].set(value))
    assert not _assert_flagged_alike(terrain, SMALL)
    terms, _ = _both_traced(terrain, SMALL)
    for name in ("slope_angle", "roughness_m", "bump_m", "step_height_m", "band_m", "foot_height_m"):
        assert np.isfinite(np.asarray(getattr(terms, name))).all(), name
    choice = _select_traced(terrain, SMALL)
    assert bool(choice.unsupported) and not bool(choice.valid) and np.isinf(float(choice.cost))
    assert np.isfinite(np.asarray(choice.pose)).all()
    assert _assert_flagged_alike(FLAT, SMALL)
    assert not bool(_select_traced(FLAT, SMALL).unsupported) and bool(_select_traced(FLAT, SMALL).valid)


@jax.jit
def _select_traced(terrain, robot):
    return select.select_step(terrain, robot, STANCE, -1, jnp.array([0.1, 0.0, 0.0]), swing_from=SWING,
                              targets=ij.make_targets(SMALL), options=ij.SelectOptions(method="exhaustive"))


@pytest.mark.slow
def test_a_plane_fit_beyond_float32_is_flagged_not_a_flat_valid_step():
    """Heights too large for the plane fit's float32 sums (finite, so the boundary accepts them) gave a NaN fit
    that both paths replaced by a flat plane: the step was valid with zero metrics. Now the steps whose fit
    overflows are flagged ``unsupported`` on the XLA path and +inf on the kernel; the others stay valid."""
    terrain = FLAT.replace(height=FLAT.height.at[22, 36].set(3e38))  # under the three steps to (0.45, 0.73)
    terms, fused = _both_traced(terrain, SMALL)
    xla, fused, unsupported = (np.asarray(a) for a in (terms.total, fused, terms.unsupported))
    np.testing.assert_array_equal(np.isinf(unsupported), np.isin(np.arange(SMALL.num_actions), [5, 6, 7]))
    assert not np.isnan(xla).any() and not np.isnan(fused).any()
    np.testing.assert_array_equal(np.isinf(fused), np.isinf(xla))
    assert np.isfinite(xla).sum() == SMALL.num_actions - 3  # the other steps stay valid


# --------------------------------------------------------------------------- the band where the paths may differ

BAND_METRICS = {"slope": "slope_angle", "roughness": "roughness_m", "bump": "bump_m", "step": "step_height_m",
                "band": "band_m", "support": "support_m"}


def _at_contact_tolerance(terrain, robot, stance):
    """(N,) bool: one of the rested sole's points under action n lies within 1e-5 m of the contact tolerance, or
    its lowest planes nearly tie (float64, testing.rest_metrics): there the two paths may class it differently."""
    steps = np.asarray(ij.action_steps(robot, stance, -1), np.float64)
    h = np.asarray(terrain.height, np.float64)
    m = robot.metrics
    out = np.zeros(len(steps), bool)
    for n, pose in enumerate(steps):
        r = rest_metrics(h, RES, (0.0, 0.0), pose, float(robot.foot_length), float(robot.foot_width),
                         float(m.contact_inset), float(m.contact_tol))
        out[n] = np.any(np.abs(r["gaps"] - float(m.contact_tol)) < 1e-5)
    return out


def _probe(robot, metric):
    """The robot with every cost 0 but ``metric``'s weight 1 and every limit out of reach: a total is the metric."""
    zero, one, far = jnp.float32(0.0), jnp.float32(1.0), jnp.float32(10.0)
    weights = {f"{k}_weight": one if k == metric else zero for k in BAND_METRICS}
    limits = {f"{k}_limit": far for k in BAND_METRICS if k != "step"}
    return robot.replace(metrics=robot.metrics.replace(**weights, **limits), action_cost=zero * robot.action_cost,
                         max_step_height=jnp.full_like(robot.max_step_height, far), max_sole_pitch=far,
                         max_sole_roll=far, max_sole_distance=far)


def _metric_both(terrain, robot, stance):
    """(XLA terms, kernel totals) of every action at ``stance`` (3,), each (N,), no swing corridor: on the
    shared harness (the same program as the other no-swing 2.5D tests)."""
    terms, fused = _both_terms(terrain, robot, stance[None], None)
    return jax.tree.map(lambda a: a[0], terms), fused[0]


# Measured largest |kernel - XLA| of each metric (CPU, interpreted kernel; 1000 maps like these of 496 steps, and
# 300 of 45 deg ramps): slope 7.7e-6 rad (5.0e-6 on 20 deg ramps), roughness 4.9e-7 m, bump 8.7e-7 m, band
# 1.2e-6 m, step height 1.2e-7 m at altitude 0 plus one float32 ulp of the altitude (3.8e-6 m at 50 m, 6.1e-5 m
# at 1000 m): the numbers in footcost.xla.LIMIT_TOL's comment. Each must stay below LIMIT_TOL, so that a metric
# at its limit is accepted by both paths; the altitudes here stay below 64 m, where one ulp is 3.8e-6 m.
BAND_ALTITUDES = (0.0, 50.0, -60.0)


@pytest.mark.slow
@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**16), altitude=st.sampled_from(BAND_ALTITUDES),
       slope_deg=st.sampled_from([20.0, 0.0, 5.0]) | st.floats(0.0, 45.0),
       noise=st.sampled_from([0.0, 0.005]), step=st.sampled_from([0.0, 0.02, 0.1]))
def test_the_paths_metrics_differ_by_less_than_limit_tol_on_hostile_near_limit_maps(seed, altitude, slope_deg,
                                                                                    noise, step):
    """Ramps at and around the 20 deg limit (and up to 45 deg), roughness near its 1 cm limit, steps near the 10 cm
    limit, at altitude: each metric as both paths compute it (a kernel total with one weight 1 is that metric),
    for every step of a stance. Where they differ, a decision may differ only for a metric within that
    difference of limit + LIMIT_TOL; the largest difference (the band) stays below LIMIT_TOL."""
    rng = np.random.default_rng(seed)
    x = np.arange(SHAPE[0])[:, None] * RES
    y = np.arange(SHAPE[1])[None, :] * RES
    phi = rng.uniform(-np.pi, np.pi)
    h = np.tan(np.radians(slope_deg)) * (x * np.cos(phi) + y * np.sin(phi)) + noise * rng.standard_normal(SHAPE)
    h[rng.integers(10, 38):, :] += step
    terrain = ij.terrain.from_arrays((h + altitude).astype(np.float32), None, RES)
    stance = jnp.asarray([*rng.uniform(0.35, 0.6, 2), rng.uniform(-np.pi, np.pi)], jnp.float32)
    robot = ij.robots.hrp2(margin=0.02)
    tol = footcost.xla.LIMIT_TOL
    for metric, field in BAND_METRICS.items():
        terms, fused = _metric_both(terrain, _probe(robot, metric), stance)
        xla, fused = np.asarray(getattr(terms, field)), np.asarray(fused)
        if metric == "step":
            xla = np.abs(xla)
        both = np.isfinite(fused)
        np.testing.assert_array_equal(both, np.isfinite(np.asarray(terms.total)))  # off the map on both, or neither
        if metric == "support":  # a point at the contact tolerance is classed to rounding: left out
            edge = _at_contact_tolerance(terrain, robot, stance)
            assert edge.sum() <= 0.05 * len(edge), edge.sum()
            both &= ~edge
        assert both.sum() >= 100
        band = float(np.max(np.abs(fused[both] - xla[both])))
        assert band < tol, (metric, band)
