"""The core under ``jax_enable_x64``: a subset of the FootCost, selection and rollout tests in a subprocess.

x64 must be on before JAX makes its first array, so it cannot be switched on for one test of this process;
the subprocess runs the selected tests with ``JAX_ENABLE_X64=1``. The subset covers 2D and 2.5D FootCost,
the swing-path check (``swing_from``), the exhaustive, ordered and naive searches and the rollout at its
defaults (the paths that crashed under x64: int64 shift counts and while-loop carries).
"""

import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import pytest

pytestmark = pytest.mark.slow  # reruns core tests in a subprocess under x64, compiling them again

ROOT = Path(__file__).resolve().parent.parent
SUBSET = " or ".join([
    "test_swing_path_clearance",  # 2.5D, swing_from
    "test_off_map_counts_as_obstacle",  # 2D and 2.5D
    "test_matches_numpy_reference",  # ordered, 2D and 2.5D with swing_from, against NumPy
    "test_no_valid_step",  # every method
    "test_flat_forward_walk",  # rollout at its defaults
    "test_foothold_matches_an_independent_plane_fit",  # StepChoice.foothold against NumPy
    "test_the_walker_gets_the_full_foothold",  # the rollout's footholds on a ramp
    "test_a_sole_tilted_beyond_the_ankles",  # the ankle term
    "test_soles_farther_apart_than_the_legs_reach",  # the reach term, 2D and 2.5D
    "test_an_inactive_query_is_inf_everywhere",  # the fused kernel (interpreted), 2D, against the XLA path
])


def test_core_tests_pass_under_x64():
    env = dict(os.environ, JAX_ENABLE_X64="1")
    cmd = [sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider", "-o", "addopts=",
           "tests/test_footcost.py", "tests/test_select.py", "tests/test_control.py", "tests/test_footcost_kernel.py",
           "-k", SUBSET]
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert " passed" in out.stdout and "failed" not in out.stdout and "deselected" in out.stdout


def test_x64_is_really_on_in_the_subprocess():
    """The check above would pass vacuously if the variable did not switch x64 on."""
    code = "import jax.numpy as jnp; print(jnp.arange(2).dtype)"
    env = dict(os.environ, JAX_ENABLE_X64="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "int64", out.stderr
    assert jnp.arange(2).dtype == jnp.int32 or jax.config.jax_enable_x64  # this process: as configured
