"""The tests' tiny sweep, shared by tests/test_sweep.py and tests/test_sweep_folders.py, and the child processes
(a killed sweep, a sweep on several forced CPU devices) of tests/test_sweep.py and tests/test_sweep_physics.py.

One static configuration (2D 60 x 50 map at 4 cm, 19 actions at density 0.25, 6 steps, exhaustive search)
for both, so each module compiles the chunk function once; they differ only in the cells of the grid.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

_HEAD = """
[sweep]
name = "tiny"
seed = 3
scenarios_per_cell = 3
num_steps = 6
method = "exhaustive"

[robot]
density = 0.25

[terrain]
family = "obstacles"
shape = [60, 50]
resolution = 0.04
max_count = 8

[terrain.params]
count = 6

[command]
vx = [0.1, 0.3]
vy = [-0.05, 0.05]
wz = 0.0

[grid]
"robot.w" = [0.5, 2.0]
"""


def tiny_sweep(*, margins: bool) -> str:
    """The tiny sweep's TOML text: ``robot.w`` in [0.5, 2.0] crossed, if ``margins``, with ``robot.margin`` in
    [0.0, 0.05] (4 cells, 12 scenarios; else 2 cells, 6 scenarios). It ends in its ``[grid]`` table, so a test
    may append grid keys."""
    return _HEAD + ('"robot.margin" = [0.0, 0.05]\n' if margins else "")


def refused_by(source: str, text: str, key: str, reason: str) -> str:
    """The message of the ``SweepConfigError`` that parsing ``text`` (as the file ``source``) raises: it must name
    ``source`` and ``key`` first, and match the regular expression ``reason``."""
    import pytest

    from ijoy_jax import sweep

    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.parse_config(text, source)
    msg = str(e.value)
    assert msg.startswith(f"{source}: {key}: "), msg
    assert re.search(reason, msg), msg
    return msg


def write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    """Write a sweep file ``name`` with ``text`` into ``tmp_path``; its path."""
    p = tmp_path / name
    p.write_text(text)
    return p


_SLOW_CHILD = """
import os, sys, time
hold_s = float(sys.argv[1])
_replace = os.replace
def slow_replace(src, dst):
    _replace(src, dst)
    if str(dst).endswith(".parquet"):
        time.sleep(hold_s)   # hold after each part: the parent kills the child in this window
os.replace = slow_replace
from ijoy_jax.apps import cli
sys.exit(cli.main(sys.argv[2:]))
"""


def kill_after_first_part(sweep_file: Path, out: Path, *, chunk: int, hold_s: float, timeout_s: float,
                          poll_s: float, extra: tuple[str, ...] = (), part: str = "part-*.parquet") -> None:
    """Run ``ijoy sweep run sweep_file --out out --chunk chunk *extra`` in a child process that sleeps ``hold_s``
    after writing each part, and SIGKILL it as soon as a part matching ``part`` exists (polling every ``poll_s``).
    Fails if the child ends before writing one, or writes none within ``timeout_s``."""
    parts = out / "parts"
    child = subprocess.Popen([sys.executable, "-c", _SLOW_CHILD, str(hold_s), "sweep", "run", str(sweep_file),
                              "--out", str(out), "--chunk", str(chunk), *extra],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + timeout_s
        while not list(parts.glob(part)) if parts.exists() else True:
            assert child.poll() is None, "the sweep ended before any chunk was written"
            assert time.monotonic() < deadline, f"no chunk written in {timeout_s:g} s"
            time.sleep(poll_s)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait()


SPY_ON_DEVICES = """
from ijoy_jax.sweep import devices
seen = []  # per chunk: the device of each slice's outputs
_dispatch = devices.OnDevices.dispatch
def spy(self, run, static, shared, batch):
    where = []
    def run_and_note(*args):
        out = run(*args)
        where.append(next(iter(out.values())).devices())
        return out
    outs = _dispatch(self, run_and_note, static, shared, batch)
    seen.append(sorted(str(d) for ds in where for d in ds))
    return outs
devices.OnDevices.dispatch = spy
"""
"""Child-script code that spies on the sweep's per-device runner: ``seen`` lists, per chunk, the device that
computed each slice (its outputs' device)."""


def run_on_cpu_devices(script: str, *args: str, devices: int, timeout_s: float) -> None:
    """Run the Python ``script`` (``python -c script *args``) in a child process whose CPU backend has ``devices``
    devices (``--xla_force_host_platform_device_count`` added to ``XLA_FLAGS``); fail with its stderr's tail
    unless it exits 0 within ``timeout_s``."""
    flag = f" --xla_force_host_platform_device_count={devices}"
    env = dict(os.environ, JAX_PLATFORMS="cpu", XLA_FLAGS=(os.environ.get("XLA_FLAGS", "") + flag).strip())
    r = subprocess.run([sys.executable, "-c", script, *args], env=env, capture_output=True, text=True,
                       timeout=timeout_s)
    assert r.returncode == 0, r.stderr[-3000:]
