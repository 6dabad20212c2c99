"""Several processes (hosts) running one sweep: the process layout, ``jax.distributed`` setup, agreement.

A sweep's chunk plan is a pure function of the sweep file, the chunk size and
``max_scenarios``, so processes need no collectives: process ``I`` of ``N``
runs the chunks with ``chunk_id % N == I`` on its own local devices (split
over them as in one process) and writes its parquet parts into the shared
output folder. The coordination service started by
:func:`jax.distributed.initialize` is used only for two small things, both
optional: process 0's automatic chunk size is handed to the others through its
key-value store (so every process cuts the same plan), and a final barrier lets
process 0 write ``aggregates.parquet`` once every process is done. Neither is
a device collective, so the CPU backend needs no gloo/MPI collectives. At the
end, :func:`shutdown` lets the others leave the service before process 0 stops it.

Layout sources, first match wins per field::

  flags            ``ijoy sweep run --num-processes N --process-id I --coordinator HOST:PORT``
  environment      ``IJOY_NUM_PROCESSES``, ``IJOY_PROCESS_ID``, ``IJOY_COORDINATOR``
  JAX's detection  ``--distributed`` (or ``IJOY_DISTRIBUTED=1``) with fields left unset:
                   :func:`jax.distributed.initialize` fills them from SLURM, Open MPI,
                   Kubernetes/GKE or ``JAX_COORDINATOR_ADDRESS`` (its cluster auto-detection)

Example:
  >>> lay = layout(num_processes=2, process_id=1, coordinator="node0:12355")
  >>> lay.num_processes, lay.process_id, lay.multi
  (2, 1, True)
  >>> layout(env={}).multi
  False
"""

from __future__ import annotations

import dataclasses
import os
import sys
import threading
import time
from collections.abc import Mapping

import jax

__all__ = ["ENV", "Layout", "agree", "barrier", "client", "initialize", "layout", "process_layout", "shutdown"]

ENV = {"num_processes": "IJOY_NUM_PROCESSES", "process_id": "IJOY_PROCESS_ID", "coordinator": "IJOY_COORDINATOR",
       "distributed": "IJOY_DISTRIBUTED"}
"""Environment variables read by :func:`layout` (a flag given on the command line wins)."""


@dataclasses.dataclass(frozen=True)
class Layout:
    """Where this process stands among the processes of one sweep.

    Fields::

      num_processes: N (>= 1), or None to let JAX's cluster detection decide.
      process_id: I in [0, N), or None (JAX's cluster detection).
      coordinator: ``"host:port"`` of process 0's coordination service, or None.
      auto: call :func:`jax.distributed.initialize` even with fields unset
        (SLURM, Open MPI, ... fill them).
    """

    num_processes: int | None = None
    process_id: int | None = None
    coordinator: str | None = None
    auto: bool = False

    @property
    def multi(self) -> bool:
        """Whether :func:`initialize` must start ``jax.distributed`` (more than one process, or auto)."""
        return self.auto or (self.num_processes or 1) > 1


def _int(name: str, value, lo: int) -> int | None:
    if value is None or value == "":
        return None
    try:
        v = int(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an integer, got {value!r}") from None
    if isinstance(value, float) and v != value:
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if v < lo:
        raise ValueError(f"{name} must be >= {lo}, got {v}")
    return v


def layout(num_processes=None, process_id=None, coordinator=None, auto: bool = False,
           env: Mapping[str, str] | None = None) -> Layout:
    """The process layout from flags, then ``IJOY_*`` environment variables, validated (no compute, no network).

    Args:
      num_processes, process_id, coordinator, auto: command-line values (None: not given).
      env: environment to read (default ``os.environ``).

    Returns:
      :class:`Layout`.

    Raises:
      ValueError: a non-integer or out-of-range count or id (``process id 2 out of range for 2
        processes``), a coordinator that is not ``host:port``, or several processes without a
        coordinator and without ``--distributed``.
    """
    env = os.environ if env is None else env
    flag = {"num_processes": "--num-processes", "process_id": "--process-id", "coordinator": "--coordinator"}
    src = {k: (flag[k] if v is not None else ENV[k]) for k, v in
           (("num_processes", num_processes), ("process_id", process_id), ("coordinator", coordinator))}
    n = _int(src["num_processes"], num_processes if num_processes is not None else env.get(ENV["num_processes"]), 1)
    i = _int(src["process_id"], process_id if process_id is not None else env.get(ENV["process_id"]), 0)
    coord = coordinator if coordinator is not None else (env.get(ENV["coordinator"]) or None)
    auto = bool(auto) or env.get(ENV["distributed"], "").lower() in ("1", "true", "yes")
    if n is not None and i is not None and i >= n:
        raise ValueError(f"{src['process_id']}: process id {i} out of range for {n} processes (0 to {n - 1})")
    if i is not None and i > 0 and n is None and not auto:
        raise ValueError(f"{src['process_id']} = {i} needs --num-processes (or {ENV['num_processes']})")
    if coord is not None:
        host, sep, port = coord.rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"{src['coordinator']} must be HOST:PORT (e.g. node0:12355), got {coord!r}")
    if n is not None and n > 1 and coord is None and not auto:
        raise ValueError(f"{src['num_processes']} = {n} needs --coordinator HOST:PORT (or {ENV['coordinator']}), "
                         f"or --distributed to let JAX detect the cluster (SLURM, Open MPI, ...)")
    return Layout(n, i, coord, auto)


def initialize(lay: Layout) -> tuple[int, int]:
    """Start ``jax.distributed`` for a multi-process layout (once per process); returns (process id, count).

    A single-process layout starts nothing and returns ``(0, 1)``. Call it
    before anything touches a device (the CLI does so right after parsing).

    The service is started recoverable (JAX's ``jax_enable_recoverability``): by default JAX ends every
    process (SIGABRT) once one of them dies or is relaunched, although a sweep's processes share no
    computation. Recoverable, the others finish their chunks, and the dead process, relaunched with the
    same command, rejoins the run, computes its missing chunks and passes the final barrier with them.

    A process started before process 0 waits for it here (JAX's ``initialization_timeout``, 5 minutes);
    Ctrl-C stops that wait.
    """
    if not lay.multi:
        return 0, 1
    if not jax.distributed.is_initialized():
        jax.config.update("jax_enable_recoverability", True)
        # A process waits here for the coordinator (process 0) for up to 5 minutes: beside the main thread, so
        # that Ctrl-C stops it (see _beside)
        _beside(lambda: jax.distributed.initialize(lay.coordinator, lay.num_processes, lay.process_id))
    return jax.process_index(), jax.process_count()


def process_layout(process_id: int | None = None, num_processes: int | None = None) -> tuple[int, int]:
    """(I, N): which process of how many this one is in a run, checked against ``jax.distributed``.

    A run's process ``I`` of ``N`` computes the chunks with ``chunk_id % N == I``. Both given: they are used,
    once checked (ints, ``0 <= I < N``, and equal to ``jax.process_index()`` / ``jax.process_count()``
    when ``jax.distributed`` runs several processes, so a slice is never computed twice or skipped). Both
    None: ``jax.process_index()`` and ``jax.process_count()`` (0 of 1 without ``jax.distributed``).

    Raises:
      ValueError: one of them None or not an int, I out of range, or a layout that ``jax.distributed``
        contradicts.

    Example:
      >>> process_layout(1, 4)
      (1, 4)
    """
    if process_id is None and num_processes is None:
        return jax.process_index(), jax.process_count()
    for name, v in (("process_id", process_id), ("num_processes", num_processes)):
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"process_id and num_processes must both be ints (or both None), got {name}={v!r}")
    if num_processes < 1 or not 0 <= process_id < num_processes:
        raise ValueError(f"process id {process_id} out of range for {num_processes} processes "
                         f"(0 to {num_processes - 1})")
    if jax.process_count() > 1 and (process_id, num_processes) != (jax.process_index(), jax.process_count()):
        raise ValueError(f"process_id={process_id}, num_processes={num_processes} disagree with jax.distributed "
                         f"(process {jax.process_index()} of {jax.process_count()})")
    return process_id, num_processes


def shutdown(timeout_s: float = 120.0) -> None:
    """Leave ``jax.distributed`` so that no process is aborted on its way out (call it once work is done).

    Process 0 hosts the coordination service. A recoverable service (:func:`initialize`) does not hold it
    at JAX's exit barrier, so a process 0 that exits first takes the service down while the others are
    still disconnecting, and they abort (SIGABRT, "Failed to disconnect from coordination service"): two of
    four processes of a sweep did so on four H200s, after their results were written. So here the others
    disconnect at once, and process 0 waits until they have (the service's live tasks are process 0
    alone), for at most ``timeout_s``, before it shuts the service down. Without ``jax.distributed``
    nothing happens.
    """
    c = client()
    if c is None:
        return
    if jax.process_index() != 0:
        jax.distributed.shutdown()
        return
    everyone = list(range(jax.process_count()))

    def wait_alone() -> None:
        # The service answers once every live task in the list has asked or left: a dead task is not live.
        try:
            while set(c.get_live_nodes(everyone)) != {0}:
                time.sleep(0.05)
        except Exception:  # noqa: BLE001 - a service error: nothing to wait for any more
            pass

    waiter = threading.Thread(target=wait_alone, daemon=True)
    waiter.start()
    waiter.join(timeout_s)
    if waiter.is_alive():
        print(f"[ijoy sweep] other processes still connected after {timeout_s:g} s; shutting the coordination "
              "service down anyway", file=sys.stderr)
    jax.distributed.shutdown()


def client():
    """The coordination-service client of ``jax.distributed`` (None when it is not initialized).

    The one reach into JAX's private ``jax._src.distributed`` (the public API
    exposes no key-value store, barrier or live-task query); a test pins it to the JAX versions
    we run (0.10 and 0.11).
    """
    if not jax.distributed.is_initialized():
        return None
    from jax._src import distributed as _dist  # the public API exposes no key-value store or barrier

    return _dist.global_state.client


def agree(name: str, value_fn, process_id: int, timeout_s: float = 600.0) -> int:
    """An int computed by process 0 (``value_fn()``) and read by every process through the key-value store.

    Without ``jax.distributed`` every process computes ``value_fn()`` itself.
    """
    c = client()
    if c is None:
        return int(value_fn())
    if process_id == 0:
        value = int(value_fn())
        c.key_value_set(name, str(value), allow_overwrite=True)
        return value
    return int(_beside(lambda: c.blocking_key_value_get(name, int(timeout_s * 1000))))


def barrier(name: str, timeout_s: float) -> bool:
    """Wait until every process reaches ``name``; False (and a note on stderr) on timeout or a dead peer.

    Without ``jax.distributed`` (one process, or a layout given without it) returns False at once.
    """
    c = client()
    if c is None:
        return False
    try:
        _beside(lambda: c.wait_at_barrier(name, int(timeout_s * 1000)))
    except Exception as e:  # noqa: BLE001 - JaxRuntimeError (deadline, peer failure): not fatal here
        print(f"[ijoy sweep] barrier {name!r} not reached by every process ({str(e).splitlines()[0]}); "
              "continuing without it", file=sys.stderr)
        return False
    return True


def _beside(call):
    """``call()``, a blocking wait of the coordination service, run in a helper thread; its result, or its
    exception raised here.

    The native wait blocks whichever thread calls it, and Python runs signal handlers in the main thread
    only: waited for there, Ctrl-C (and the CLI's SIGTERM handler) would not act until the wait ends, up to
    an hour later at the final barrier. Here the calling thread joins the helper in short slices, free to take
    the signal (tests/test_sweep_multihost.py); the helper, a daemon, ends with the process.
    """
    out: dict = {}

    def run() -> None:
        try:
            out["value"] = call()
        except BaseException as e:  # noqa: BLE001 - handed to the caller as it is
            out["error"] = e

    helper = threading.Thread(target=run, name="ijoy sweep: coordination wait", daemon=True)
    helper.start()
    while helper.is_alive():
        helper.join(0.2)
    if "error" in out:
        raise out["error"]
    return out["value"]
