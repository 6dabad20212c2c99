"""The benchmark script runs end to end (tiny settings; the timings themselves are not tested)."""

import json

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.apps import bench_haptics as bench
from ijoy_jax.haptics.leg import PAPER_Q, alduro_leg, leg_repulsive_force, leg_workspace
from ijoy_jax.haptics.workspace import repulsive_force_decay


def test_benchmarked_function_is_the_leg_force():
    leg = alduro_leg(-1.0)
    ws = leg_workspace(leg, jnp.array(PAPER_Q))
    np.testing.assert_allclose(
        jax.jit(leg_repulsive_force)(leg, jnp.array(PAPER_Q), 1.0, 0.05),
        repulsive_force_decay(ws.jacobian, ws.travel_minus, ws.travel_plus, 1.0, 0.05),
        rtol=1e-6,
        atol=1e-7,
    )


def test_bench_runs_and_writes_json(tmp_path, capsys):
    path = tmp_path / "bench.json"
    result = bench.main(["--quick", "--calls", "5", "--sizes", "2", "--json", str(path)])
    text = capsys.readouterr().out
    assert "leg_force:" in text and "B=      2" in text
    loaded = json.loads(path.read_text())
    assert loaded["leg_force"]["calls"] == 5 and loaded["leg_force_batched"][0]["evals_per_s"] > 0
    assert loaded == json.loads(json.dumps(result))
