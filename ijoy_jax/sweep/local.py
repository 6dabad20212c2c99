"""One sweep as N processes on this machine, one GPU each: the launch recipe of sweeps/README.md in one call.

``ijoy sweep run FILE --local-processes N`` starts N children, process ``i`` of them with
``CUDA_VISIBLE_DEVICES`` set to the ``i``-th visible GPU and the layout flags of
:mod:`ijoy_jax.sweep.distributed` (``--num-processes N --process-id i --coordinator
localhost:PORT``, a free port), each running the same ``ijoy sweep run`` otherwise: one process does
not keep several GPUs busy with short chunks, so N processes run a sweep faster than one process over
the N GPUs (BENCHMARKS.md has the figures).

This process starts no JAX backend (it would take GPU memory from its children): it only checks
its arguments, starts the children, passes their progress lines (stderr) through, collects their
JSON results (stdout) and forwards an interrupt to them.

Example:
  >>> gpus_for(2, env={"CUDA_VISIBLE_DEVICES": "3,5,6"})
  ['3', '5']
  >>> gpus_for(2, env={})
  ['0', '1']
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence

__all__ = ["LAYOUT_FLAGS", "gpus_for", "run"]

LAYOUT_FLAGS = ("--num-processes", "--process-id", "--coordinator", "--distributed", "--devices")
"""Flags that a child's layout sets, refused beside ``--local-processes``."""


def gpus_for(num_processes: int, env: Mapping[str, str] | None = None) -> list[str]:
    """The GPU of each of ``num_processes`` children: the first entries of ``CUDA_VISIBLE_DEVICES`` when set
    (ids or UUIDs), else ``0 .. N-1``. ValueError when it lists fewer than ``num_processes``."""
    env = os.environ if env is None else env
    if isinstance(num_processes, bool) or not isinstance(num_processes, int) or num_processes < 1:
        raise ValueError(f"--local-processes must be a positive int, got {num_processes!r}")
    visible = env.get("CUDA_VISIBLE_DEVICES")
    if visible is None:
        return [str(i) for i in range(num_processes)]
    ids = [v.strip() for v in visible.split(",") if v.strip()]
    if len(ids) < num_processes:
        raise ValueError(f"--local-processes {num_processes} needs as many GPUs, but CUDA_VISIBLE_DEVICES "
                         f"lists {len(ids)} ({visible!r})")
    return ids[:num_processes]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def run(sweep_args: Sequence[str], num_processes: int, *, port: int | None = None,
        env: Mapping[str, str] | None = None, command: Sequence[str] | None = None) -> tuple[int, list[dict | None]]:
    """Run ``ijoy sweep run *sweep_args`` as ``num_processes`` local processes, one GPU each; wait for all.

    Args:
      sweep_args: the arguments after ``ijoy sweep run`` (the file, ``--out``, ``--chunk``, ...), without
        any of :data:`LAYOUT_FLAGS`.
      num_processes: N >= 1 (:func:`gpus_for` picks their GPUs).
      port: the coordinator's port on localhost (default: a free one).
      env: the children's environment (default: this process's).
      command: what runs ``ijoy`` in a child (default: this Python with ``-m ijoy_jax.apps.cli``).

    A child that fails stops the launch: the others are interrupted (SIGINT: each writes the chunk it has
    in flight), since they would wait for it at the final barrier. Every written part stays, so the same
    command resumes.

    Returns:
      (exit code: 0 when every child exited 0, else that of the child that failed first; each child's JSON
      result, None where it printed none).

    Raises:
      ValueError: a bad ``num_processes``, too few GPUs, or a layout flag in ``sweep_args``.
    """
    for a in sweep_args:
        if a.split("=")[0] in LAYOUT_FLAGS:
            raise ValueError(f"{a.split('=')[0]} cannot be combined with --local-processes (it sets each "
                             "process's layout: one GPU each, coordinated on localhost)")
    env = dict(os.environ if env is None else env)
    gpus = gpus_for(num_processes, env)
    coordinator = f"localhost:{port or _free_port()}"
    children: list[subprocess.Popen] = []
    failed = None  # the child that failed first: its exit code is the launch's
    try:
        for i, gpu in enumerate(gpus):
            cmd = [*(command or (sys.executable, "-m", "ijoy_jax.apps.cli")), "sweep", "run", *sweep_args,
                   "--num-processes", str(num_processes), "--process-id", str(i), "--coordinator", coordinator]
            children.append(subprocess.Popen(cmd, env={**env, "CUDA_VISIBLE_DEVICES": gpu},
                                             stdout=subprocess.PIPE, text=True))
        while True:
            codes = [c.poll() for c in children]  # every child polled (reaped) each round
            if all(rc is not None for rc in codes):
                break
            failed = next((c for c, rc in zip(children, codes, strict=True) if rc not in (None, 0)), None)
            if failed is not None:
                _interrupt(children)  # one failed: the others would wait for it at the final barrier
                break
            time.sleep(0.2)
    except KeyboardInterrupt:
        _interrupt(children)
        raise
    finally:
        for c in children:
            if c.poll() is None:
                c.kill()
            c.wait()
    rows: list[dict | None] = []
    for c in children:
        try:
            rows.append(json.loads(c.stdout.read()))
        except ValueError:
            rows.append(None)
        c.stdout.close()
    if failed is None:
        failed = next((c for c in children if c.returncode != 0), None)
    return (0 if failed is None else failed.returncode), rows


def _interrupt(children: list[subprocess.Popen], timeout_s: float = 30.0) -> None:
    """SIGINT to the running children (each writes the chunk it has in flight; a rerun resumes), the
    coordinator's process last; wait up to ``timeout_s`` for them all (the caller kills what is left)."""
    for c in reversed(children):
        if c.poll() is None:
            c.send_signal(signal.SIGINT)
    deadline = time.monotonic() + timeout_s  # one wait for them all, not timeout_s for each in turn
    for c in children:
        try:
            c.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
