"""The XLA CPU miscompile that importing ijoy_jax works around (ijoy_jax._xla_workaround), against float64
references, and the workaround's handling of the environment in fresh processes."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import jaxlib
import numpy as np
import pytest

from ijoy_jax import _xla_workaround as xw
from ijoy_jax.terrain import generators as gen

FLAG_NAME = xw.FLAG.rstrip("=")


def test_the_smallest_program_that_showed_it_is_right_under_jit():
    """A per-batch factor times a reduction over a large grid (jaxlib 0.10.2 fused them wrongly: 0.198 off)."""
    x = (np.arange(250) + 0.5) * 0.02
    y = (np.arange(100) + 0.5) * 0.02
    c = np.stack(np.meshgrid(x, y, indexing="ij"), axis=-1)  # (250, 100, 2)
    u = np.asarray([[0.0, -1.0], [0.0, 1.0]])
    s = np.asarray([0.1, 0.3])
    got = jax.jit(lambda u, s, c: s[:, None, None] * jnp.sum(c[None] * u[:, None, None, :], axis=-1))(
        jnp.asarray(u, jnp.float32), jnp.asarray(s, jnp.float32), jnp.asarray(c, jnp.float32))
    want = s[:, None, None] * np.einsum("ijk,bk->bij", c, u)
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-6)  # m; float32 of values under 1


@pytest.mark.parametrize("shape", [(250, 100), (200, 200)])
def test_jitted_slopes_of_different_directions_match_the_closed_form(shape):
    """The symptom: a jitted batch of slopes rising along +x, +-y and diagonals, each against
    ``tan(angle) * (centre - start) . (cos direction, sin direction)`` in float64."""
    direction = np.asarray([0.0, 0.5, -0.5, 1.0, 0.25, -0.75], np.float32) * np.pi
    angle = np.asarray([0.1, 0.05, 0.15, 0.1, 0.12, 0.08], np.float32)
    params = gen.SlopeParams(angle=jnp.asarray(angle), direction=jnp.asarray(direction))
    keys = jax.random.split(jax.random.key(0), len(angle))
    height = jax.jit(lambda k, p: gen.batch("slope", k, p, shape=shape, resolution=0.02, has_height=True).height)(
        keys, params)
    start = np.asarray([params.start_x * shape[0], params.start_y * shape[1]], np.float64) * 0.02
    cx = (np.arange(shape[0]) + 0.5) * 0.02 - start[0]
    cy = (np.arange(shape[1]) + 0.5) * 0.02 - start[1]
    d = np.asarray(direction, np.float64)
    want = np.tan(np.asarray(angle, np.float64))[:, None, None] * (
        np.cos(d)[:, None, None] * cx[None, :, None] + np.sin(d)[:, None, None] * cy[None, None, :])
    np.testing.assert_allclose(np.asarray(height), want, atol=2e-6)  # m: float32 of heights under 0.8 m


@pytest.mark.parametrize("version, affected", [
    ("0.10.1", False), ("0.10.2", True), ("0.10.2.dev20261101", True), ("0.11.1", True), ("0.11.2", False),
    ("0.12.0", False), ("1.0", False),
])
def test_which_jaxlib_versions_need_it(version, affected):
    assert xw.needed(version) is affected


def _python(code: str, xla_flags: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env.update(XLA_FLAGS=xla_flags, JAX_PLATFORMS="cpu")
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)


def _without_ours(flags: str) -> str:
    return " ".join(f for f in flags.split() if not f.startswith(FLAG_NAME))


def test_import_sets_the_flag_keeps_a_callers_value_and_warns_when_too_late():
    """Fresh processes: ``import ijoy_jax`` appends the flag (where this jaxlib needs it) to the caller's flags;
    a caller's own value of it stays; after JAX has started its backends it warns and changes nothing."""
    base = _without_ours(os.environ.get("XLA_FLAGS", ""))
    show = "import os, ijoy_jax, ijoy_jax._xla_workaround as w; print(w.APPLIED, repr(os.environ['XLA_FLAGS']))"
    fresh = _python(show, base)
    assert fresh.returncode == 0, fresh.stderr
    if xw.needed(jaxlib.__version__):
        assert fresh.stdout.strip() == f"True {(base + ' ' + xw.FLAG).strip()!r}"
    else:
        assert fresh.stdout.strip() == f"False {base!r}"
    own = (base + " " + xw.FLAG).strip()  # the caller's own setting (here the same value): not appended again
    kept = _python(show, own)
    assert kept.stdout.strip() == f"False {own!r}", kept.stderr
    late = _python("import warnings, jax; jax.devices(); warnings.simplefilter('always')\n"
                   "import os, ijoy_jax._xla_workaround as w; print(w.APPLIED, repr(os.environ['XLA_FLAGS']))", base)
    assert late.returncode == 0, late.stderr
    assert late.stdout.strip() == f"False {base!r}"
    assert ("JAX started its backends before ijoy_jax was imported" in late.stderr) is xw.needed(jaxlib.__version__)


def test_backends_started_reports_this_process():
    """The started case (the fresh-process test's APPLIED True, where this jaxlib needs it, is the other)."""
    jax.devices()
    assert xw.backends_started()
