"""The benchmark script runs end to end (tiny settings; the timings themselves are not tested)."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ijoy_jax.apps import cli
from ijoy_jax.haptics.leg import PAPER_Q, alduro_leg, forward_kinematics, leg_repulsive_force
from ijoy_jax.testing import enable_x64

# float64 reference: central differences (error ~ h^2 |Phi'''| ~ 1e-12) and qhull's facets (a few ulps).
TOL_F64 = 1e-7  # N, for C1 = 1 N and 12 planes
# The benchmarked float32 path: J from float32 autodiff, normals good to ~1e-5 at this pose's angles.
TOL_F32 = 2e-4  # N
FD_STEP = 1e-6  # m of cylinder travel


def reference_leg_force(q, c1, decay_length):
    """``sum -n C1 exp(-d / lambda)`` over the facets of the workspace zonotope, from scratch in float64:
    J by central differences of the forward kinematics, the 16 vertices ``J e`` (e a corner of the travel
    box), and their convex hull's distinct facets from scipy (qhull) with outward normal n and offset d."""
    import itertools

    from scipy.spatial import ConvexHull

    with enable_x64():
        leg = alduro_leg(-1.0, dtype=jnp.float64)
        fk = lambda x: np.asarray(forward_kinematics(leg, jnp.asarray(x, jnp.float64)))  # noqa: E731
        q = np.asarray(q, np.float64)
        jac = np.stack([(fk(q + FD_STEP * e) - fk(q - FD_STEP * e)) / (2 * FD_STEP) for e in np.eye(4)], 1)
        lo, hi = np.asarray(leg.q_min) - q, np.asarray(leg.q_max) - q
    corners = np.array(list(itertools.product(*zip(lo, hi, strict=True))))  # (16, 4)
    hull = ConvexHull(corners @ jac.T)
    _, first = np.unique(np.round(hull.equations, 7), axis=0, return_index=True)  # qhull splits each rhombus
    eqs = hull.equations[np.sort(first)]
    normals, offsets = eqs[:, :3], -eqs[:, 3]
    assert len(eqs) == 12 and np.all(offsets >= 0)  # the paper's dodecahedron, the foot inside it
    return -(c1 * np.exp(-offsets / decay_length)) @ normals


@pytest.mark.parametrize("c1, decay_length", [(1.0, 0.05), (3.0, 0.2)])
def test_benchmarked_function_is_the_leg_force(c1, decay_length):
    """What the benchmark times (jit of leg_repulsive_force) against the force re-derived without autodiff,
    without the library's plane construction and without its force sum."""
    want = reference_leg_force(PAPER_Q, c1, decay_length)
    assert np.linalg.norm(want) > 0.1 * c1 and want[2] < 0  # not a cancelling case; Fig. 8 points down
    got = jax.jit(leg_repulsive_force)(alduro_leg(-1.0), jnp.array(PAPER_Q), c1, decay_length)
    np.testing.assert_allclose(np.asarray(got, np.float64), want, atol=TOL_F32 * c1)
    with enable_x64():
        got64 = jax.jit(leg_repulsive_force)(alduro_leg(-1.0, dtype=jnp.float64),
                                             jnp.array(PAPER_Q, jnp.float64), c1, decay_length)
        np.testing.assert_allclose(np.asarray(got64), want, atol=TOL_F64 * c1)


def test_bench_runs_and_writes_json(tmp_path, capsys):
    path = tmp_path / "bench.json"
    assert cli.main(["bench", "haptics", "--quick", "--calls", "5", "--sizes", "2", "--json", str(path)]) == 0
    text = capsys.readouterr().out
    assert "leg_force:" in text and "B=      2" in text
    loaded = json.loads(path.read_text())
    assert loaded["leg_force"]["calls"] == 5 and loaded["leg_force_batched"][0]["evals_per_s"] > 0
