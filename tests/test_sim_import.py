"""Importing the simulation prints nothing (mujoco.mjx.warp's 'Failed to import warp' lines are dropped)."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]


def run_python(code):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.skipif(importlib.util.find_spec("warp") is not None, reason="warp installed: nothing to silence")
def test_mjx_alone_prints_the_warp_lines():
    """The premise: without warp, a plain import of mujoco.mjx prints them (else the next test proves nothing)."""
    p = run_python("from mujoco import mjx")
    assert "Failed to import warp" in p.stdout + p.stderr


@pytest.mark.parametrize("module", ["ijoy_jax.sim", "ijoy_jax.sim.walker", "ijoy_jax.apps.bench_sim"])
def test_import_prints_nothing(module):
    p = run_python(f"import {module}; from mujoco.mjx import warp; print(warp.WARP_INSTALLED in (True, False))")
    assert p.returncode == 0, p.stderr
    assert p.stdout == "True\n" and p.stderr == ""
