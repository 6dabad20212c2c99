"""Tests of ijoy_jax.optim and ijoy_jax.tune.loop: the jitted tuning step, vmapped runs, minibatches, progress,
saving."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from ijoy_jax import optim
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.tune import loop

TOL = 1e-5  # float32 agreement of vmapped and separate runs (same ops, different batching)


def _quadratic(params, batch):
    """Mean squared distance of params["mu"] (3,) to the batch (16,) of draws."""
    return jnp.mean((params["mu"][:, None] - batch[None, :]) ** 2)


def _batch_fn(key):
    return 2.0 + 0.1 * jax.random.normal(key, (16,))


def test_step_compiles_once_and_loss_falls():
    tuner = optim.make_tuner(_quadratic, optax.adam(0.1), batch_fn=_batch_fn)
    state = tuner.init({"mu": jnp.zeros(3)})
    key = jax.random.key(0)
    losses = []
    for _ in range(30):
        state, m = tuner.step(state, key)
        losses.append(float(m.loss))
    assert compiled_count(tuner.step) == 1
    assert int(state.step) == 30
    assert losses[-1] < 0.1 * losses[0]


def test_minibatches_differ_per_step_and_are_reproducible():
    seen = []

    def loss(p, batch):
        return jnp.sum(p * 0.0) + batch

    tuner = optim.make_tuner(loss, optax.sgd(0.1), batch_fn=lambda k: jax.random.uniform(k))
    for _ in range(2):
        s = tuner.init(jnp.zeros(()))
        vals = []
        for _ in range(3):
            s, m = tuner.step(s, jax.random.key(7))
            vals.append(float(m.loss))
        seen.append(vals)
    assert len(set(seen[0])) == 3
    assert seen[0] == seen[1]


def test_vmapped_runs_match_separate_runs():
    starts = jnp.array([[0.0, 0.0, 0.0], [1.0, -1.0, 5.0]])
    many = loop.tune(_quadratic, {"mu": starts}, optax.adam(0.1), 20, key=3, batch_fn=_batch_fn, num_runs=2,
                     progress=False)
    assert many.losses.shape == (2, 20) and many.params["mu"].shape == (2, 3)
    for r in range(2):
        one = loop.tune(_quadratic, {"mu": starts[r]}, optax.adam(0.1), 20, key=3, batch_fn=_batch_fn,
                        progress=False)
        np.testing.assert_allclose(many.losses[r], one.losses, rtol=TOL, atol=TOL)
        np.testing.assert_allclose(many.params["mu"][r], one.params["mu"], rtol=TOL, atol=TOL)


def test_runs_over_objectives_with_hparams_and_named_terms():
    def loss(p, batch, target):
        d = (p - target) ** 2
        return d, {"sq": d, "target": target}

    res = loop.tune(loss, jnp.zeros(3), optax.adam(0.2), 100, key=0, hparams=jnp.array([1.0, 2.0, 3.0]),
                    num_runs=3, has_aux=True, progress=False)
    np.testing.assert_allclose(res.params, [1.0, 2.0, 3.0], atol=0.05)
    assert set(res.terms) == {"sq", "target"} and res.terms["sq"].shape == (3, 100)
    np.testing.assert_array_equal(res.terms["target"][:, 0], [1.0, 2.0, 3.0])


def test_progress_line_and_quiet(capsys):
    loop.tune(_quadratic, {"mu": jnp.zeros(3)}, optax.adam(0.1), 6, key=0, batch_fn=_batch_fn, log_every=3)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and err[-1].startswith("step 6/6") and "steps/s" in err[-1] and "ETA" in err[-1]
    loop.tune(_quadratic, {"mu": jnp.zeros(3)}, optax.adam(0.1), 6, key=0, batch_fn=_batch_fn, progress=False)
    assert capsys.readouterr().err == ""


def test_save_and_load_round_trip(tmp_path):
    def loss(p, batch):
        v = jnp.sum((p["a"] - 1.0) ** 2) + (p["b"]["c"] + 2.0) ** 2
        return v, {"half": 0.5 * v}

    p0 = {"a": jnp.zeros((2, 3)), "b": {"c": jnp.zeros(2)}}
    res = loop.tune(loss, p0, optax.adam(0.1), 5, key=0, num_runs=2, has_aux=True, progress=False,
                    out_dir=tmp_path / "run", config={"lr": 0.1, "note": "test"})
    assert res.out_dir == tmp_path / "run"
    saved = loop.load(tmp_path / "run")
    assert set(saved.params) == {"a", "b.c"}
    np.testing.assert_array_equal(saved.params["a"], res.params["a"])
    np.testing.assert_allclose(saved.losses, res.losses, rtol=1e-7)
    np.testing.assert_allclose(saved.terms["half"], res.terms["half"], rtol=1e-7)
    m = saved.manifest
    assert m["config"] == {"lr": 0.1, "note": "test"} and m["steps"] == 5 and m["num_runs"] == 2
    assert {"jax", "optax", "numpy", "ijoy_jax", "python"} <= set(m["versions"])
    assert json.loads((tmp_path / "run" / "params.json").read_text())["b.c"] == res.params["b"]["c"].tolist()
    single = loop.tune(lambda p, b: (p - 1.0) ** 2, jnp.float32(0.0), optax.sgd(0.1), 4, key=0, progress=False,
                       out_dir=tmp_path / "one")
    back = loop.load(tmp_path / "one")
    assert back.losses.shape == (4,) and back.manifest["num_runs"] is None
    np.testing.assert_allclose(back.params["params"], single.params)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(steps=0), "steps"),
        (dict(log_every=0), "log_every"),
        (dict(num_runs=3), "leading run axis"),
    ],
)
def test_bad_arguments_raise(kwargs, match):
    args = dict(steps=2, key=0, progress=False)
    args.update(kwargs)
    steps = args.pop("steps")
    with pytest.raises(ValueError, match=match):
        loop.tune(_quadratic, {"mu": jnp.zeros(2)}, optax.sgd(0.1), steps, batch_fn=_batch_fn, **args)


def test_bijectors_round_trip_and_stay_in_range():
    u = jnp.linspace(-30.0, 30.0, 61)
    pos, box = optim.positive(), optim.interval(0.0, 0.06)
    assert bool(jnp.all(pos.forward(u) > 0))
    v = box.forward(u)
    assert bool(jnp.all((v >= 0.0) & (v <= 0.06)))
    for b, x in ((pos, 3.5), (box, 0.02)):
        np.testing.assert_allclose(float(b.forward(b.inverse(x))), x, rtol=1e-6)
    with pytest.raises(ValueError):
        optim.interval(1.0, 1.0)


def _reference_adam_scan(loss_fn, init, steps, learning_rate):
    """The hand-written Adam scan the haptic tuner and the inverse fit used before sharing the loop."""
    opt = optax.adam(learning_rate)

    def body(carry, _):
        p, s = carry
        loss, g = jax.value_and_grad(loss_fn)(p)
        upd, s = opt.update(g, s, p)
        return (optax.apply_updates(p, upd), s), (loss, p)

    (p, _), (losses, traj) = jax.lax.scan(body, (init, opt.init(init)), None, length=steps)
    return p, losses, traj


def test_run_steps_is_the_hand_written_adam_scan():
    def loss(p):
        return jnp.sum(jnp.sin(3.0 * p) + (p - 0.5) ** 2)

    init = jnp.array([0.1, -0.4], jnp.float32)

    @jax.jit
    def shared(init):
        tuner = optim.make_tuner(lambda p, _: loss(p), optax.adam(0.05))
        state, metrics, traj = optim.run_steps(tuner, tuner.init(init), 20, trace_params=True)
        return state.params, metrics.loss, traj

    got = shared(init)
    want = jax.jit(lambda i: _reference_adam_scan(loss, i, 20, 0.05))(init)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(np.asarray(g), np.asarray(w))
    assert got[2].shape == (20, 2) and np.array_equal(np.asarray(got[2][0]), np.asarray(init))


def test_run_steps_matches_the_host_loop_with_minibatches_and_runs():
    p0 = {"mu": jnp.stack([jnp.zeros(3), jnp.ones(3)])}
    host = loop.tune(_quadratic, p0, optax.adam(0.1), 6, key=3, batch_fn=_batch_fn, num_runs=2, progress=False)
    tuner = optim.make_tuner(_quadratic, optax.adam(0.1), batch_fn=_batch_fn, num_runs=2)
    run = jax.jit(lambda s, k: optim.run_steps(tuner, s, 6, key=k))
    state, metrics, traj = run(tuner.init(p0), jax.random.key(3))
    assert traj is None and metrics.loss.shape == (6, 2)
    np.testing.assert_allclose(np.asarray(metrics.loss).T, host.losses, rtol=TOL)
    np.testing.assert_allclose(np.asarray(state.params["mu"]), host.params["mu"], rtol=TOL)
    run(tuner.init(p0), jax.random.key(4))
    assert compiled_count(run) == 1  # a new key does not recompile


@pytest.mark.parametrize("steps", [0, -1, 1.5])
def test_run_steps_rejects_bad_step_counts(steps):
    tuner = optim.make_tuner(lambda p, _: jnp.sum(p**2), optax.sgd(0.1))
    with pytest.raises(ValueError, match="steps"):
        optim.run_steps(tuner, tuner.init(jnp.ones(2)), steps)
