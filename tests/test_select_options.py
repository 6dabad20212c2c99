"""The selector's options as one value (ijoy_jax.SelectOptions): checked as built and by replace, equal options
share a compiled program, and the traced leaves (discount, refine) vary without recompiling."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax import refine, select

TERRAIN = ij.terrain.flat((40, 40), 0.02)
ROBOT = ij.robots.hrp2(margin=0.02, density=0.25)
STANCE, SIDE, COMMAND = [0.3, 0.4, 0.0], -1, [0.2, 0.0, 0.0]
COST_TOL = 1e-6  # float32 rounding of a cost: the same program inlined in a caller's jit folds its constants


def test_defaults_are_the_exhaustive_selector():
    o = ij.SelectOptions()
    assert (o.method, o.kernel, o.quantize, o.swing_path, o.horizon, o.beam, o.chunk, o.refine) == (
        "exhaustive",
        "xla",
        True,
        True,
        1,
        None,
        None,
        None,
    )
    assert o.discount.dtype == jnp.float32 and float(o.discount) == 1.0
    assert select.SelectOptions is ij.SelectOptions


def test_horizon_is_resolved_from_the_method_and_again_by_replace():
    assert ij.SelectOptions(method="lookahead").horizon == 2
    assert ij.SelectOptions(method="lookahead", horizon=3, beam=4).horizon == 3
    assert ij.SelectOptions().replace(method="lookahead").horizon == 2
    assert ij.SelectOptions(method="lookahead", horizon=3).replace(method="ordered").horizon == 1
    assert ij.SelectOptions(method="lookahead", horizon=3).replace(discount=0.5).horizon == 3


def test_refine_true_is_the_default_params_and_false_is_none():
    assert ij.SelectOptions(refine=False).refine is None
    r = ij.SelectOptions(refine=True).refine
    want = refine.params()
    assert isinstance(r, refine.RefineParams) and (r.levels, r.starts) == (want.levels, want.starts)
    assert float(r.span) == float(want.span) and float(r.min_gain) == float(want.min_gain)
    typed = ij.SelectOptions(refine=refine.RefineParams(0.5, 0.0, 3, 2)).refine  # Python numbers: made float32
    assert typed.span.dtype == jnp.float32 and float(typed.span) == 0.5


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(method="astar"), ValueError, "method must be one of"),
        (dict(kernel="cuda"), ValueError, "kernel must be one of"),
        (dict(quantize="yes"), TypeError, "quantize must be True or False"),
        (dict(swing_path=1), TypeError, "swing_path must be True or False"),
        (dict(method="lookahead", horizon=0), ValueError, "horizon must be >= 1"),
        (dict(method="lookahead", horizon=2.5), TypeError, "horizon must be an int"),
        (dict(method="exhaustive", horizon=2), ValueError, "options of method='lookahead'"),
        (dict(method="lookahead", beam=0), ValueError, "beam must be in"),
        (dict(method="lookahead", beam=True), TypeError, "beam must be an int"),
        (dict(method="ordered", beam=4), ValueError, "options of method='lookahead'"),
        (dict(discount=-0.5), ValueError, "discount must be finite and >= 0"),
        (dict(discount=float("nan")), ValueError, "discount must be finite and >= 0"),
        (dict(discount=np.ones(2)), ValueError, "discount must be a scalar"),
        (dict(discount="high"), TypeError, "discount must be a number"),
        (dict(discount=True), TypeError, "discount must be a number"),
        (dict(chunk=0), ValueError, "chunk must be an int >= 1"),
        (dict(refine="yes"), TypeError, "refine must be a bool or an ijoy_jax.refine.RefineParams"),
        (dict(refine=refine.RefineParams(-1.0, 0.0, 5, 4)), ValueError, "refine span must be finite and > 0"),
    ],
)
def test_construction_names_the_bad_field_in_one_line(kwargs, error, match):
    with pytest.raises(error, match=match) as e:
        ij.SelectOptions(**kwargs)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    "changes, error, match",
    [
        (dict(method="astar"), ValueError, "method must be one of"),
        (dict(kernel="triton"), ValueError, "kernel must be one of"),
        (dict(horizon=0), ValueError, "horizon must be >= 1"),
        (dict(beam=0), ValueError, "beam must be in"),
        (dict(discount=-1.0), ValueError, "discount must be finite and >= 0"),
        (dict(discount=float("inf")), ValueError, "discount must be finite and >= 0"),
        (dict(refine="yes"), TypeError, "refine must be a bool"),
    ],
)
def test_replace_checks_what_it_sets(changes, error, match):
    with pytest.raises(error, match=match):
        ij.SelectOptions(method="lookahead").replace(**changes)


def test_the_robots_checks_run_once_at_the_boundary():
    n = ROBOT.num_actions
    with pytest.raises(ValueError, match=rf"beam must be in \[1, {n}\]"):
        ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, ij.SelectOptions(method="lookahead", beam=n + 1))
    with pytest.raises(ValueError, match="refine applies to the terrain-aware methods"):
        ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, ij.SelectOptions(method="naive", refine=True))
    with pytest.raises(ValueError, match="refine starts must be at most"):
        ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, ij.SelectOptions(refine=refine.params(starts=n + 1)))
    with pytest.raises(TypeError, match="options must be an ijoy_jax.SelectOptions"):
        ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, {"method": "ordered"})
    with pytest.raises(TypeError, match="unexpected keyword argument 'method'"):
        ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, method="ordered")


def test_equal_options_compare_and_hash_equal():
    a = ij.SelectOptions(method="lookahead", discount=0.5, refine=True)
    b = ij.SelectOptions(method="lookahead", discount=np.float64(0.5), refine=refine.params())
    assert a == b and hash(a) == hash(b)
    assert a != a.replace(discount=0.25) and hash(a) == hash(a.replace(discount=0.25))  # the leaves: equal statics
    assert a != a.replace(kernel="pallas") and a != a.replace(refine=None) and a != ij.SelectOptions()
    assert len({ij.SelectOptions(), ij.SelectOptions(discount=1.0), ij.SelectOptions(method="ordered")}) == 2
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    assert jax.tree_util.tree_structure(a) != jax.tree_util.tree_structure(a.replace(horizon=3))


def test_traced_leaves_vary_without_recompiling_select_step():
    targets = ij.make_targets(ROBOT)
    options = ij.SelectOptions(method="lookahead", refine=True)
    first = ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, options, targets=targets)
    assert bool(first.valid)
    before = select.compiled_programs()
    for g, span in ((0.0, 0.5), (0.9, 1.0), (2.0, 0.25)):
        again = options.replace(discount=g, refine=refine.params(span=span))
        assert bool(ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, again, targets=targets).valid)
    assert select.compiled_programs() == before
    # Equal options built anew reuse the program too; other static fields compile one more (the naive search:
    # the cheapest program to show it; another lookahead with refinement is among the slowest to compile).
    ij.select_step(
        TERRAIN, ROBOT, STANCE, SIDE, COMMAND, ij.SelectOptions(method="lookahead", refine=True), targets=targets
    )
    assert select.compiled_programs() == before
    ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, options.replace(method="naive", refine=False),
                   targets=targets)
    assert select.compiled_programs() == before + 1


def test_options_pass_through_jit_and_vmap_as_a_pytree():
    options = ij.SelectOptions(method="lookahead")
    leaves, tree = jax.tree_util.tree_flatten(options)
    assert len(leaves) == 1 and jax.tree_util.tree_unflatten(tree, leaves) == options
    step = jax.jit(lambda o: ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, o))
    eager = ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, options)
    traced = step(options)
    assert int(traced.index) == int(eager.index) and float(traced.cost) == pytest.approx(
        float(eager.cost), abs=COST_TOL
    )
    assert jax.jit(lambda o: o)(options) == options  # out of a jit: the same value, not checked again
    # A batch of discounts as one vmapped argument: each is the decision at that discount alone.
    gammas = jnp.array([0.0, 0.5, 1.0], jnp.float32)
    batch = jax.vmap(lambda o: ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, o).index)(
        options.replace(discount=gammas)
    )
    for g, i in zip(gammas, np.asarray(batch), strict=True):
        assert int(i) == int(ij.select_step(TERRAIN, ROBOT, STANCE, SIDE, COMMAND, options.replace(discount=g)).index)
    # A gradient with respect to the options is options-shaped (no check refuses a negative cotangent).
    grad = jax.grad(lambda o: -2.0 * o.discount)(options)
    assert isinstance(grad, ij.SelectOptions) and float(grad.discount) == -2.0


def test_rollout_takes_the_same_value():
    start = ij.robots.start_stance(ROBOT, 0.3, 0.4)
    a = ij.rollout(TERRAIN, ROBOT, start, COMMAND, 3, ij.SelectOptions(method="ordered"))
    b = ij.rollout(TERRAIN, ROBOT, start, COMMAND, 3)
    np.testing.assert_array_equal(np.asarray(a.footsteps), np.asarray(b.footsteps))
    with pytest.raises(TypeError, match="unexpected keyword argument 'refine'"):
        ij.rollout(TERRAIN, ROBOT, start, COMMAND, 3, refine=True)
