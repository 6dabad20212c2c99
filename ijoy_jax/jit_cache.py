"""How many programs a ``jax.jit`` function holds compiled (the one place that reads JAX's private jit cache),
and how long JAX spends compiling.

Functions users call in loops promise not to recompile (:func:`ijoy_jax.sim.walker.compiled_programs`,
``ijoy bench walk``'s compile counts); they count through :func:`compiled_count`. JAX has no public
counter: ``jax.jit`` objects expose ``_cache_size()`` (jax 0.4 to 0.11; tests/test_jit_cache.py pins it).
"""

from __future__ import annotations

import contextlib

import jax

__all__ = ["COMPILE_EVENTS", "compile_seconds", "compiled_count"]

COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                  "/jax/core/compile/backend_compile_duration")
"""JAX's own events (:mod:`jax.monitoring`) whose durations add up to a program's compile time: tracing of a
top-level program, lowering to MLIR, and the backend's compile (absent on a persistent-cache hit)."""


def compiled_count(fn) -> int:
    """The number of programs the jitted function ``fn`` (a ``jax.jit`` object) holds compiled in this process:
    one per input shape and dtype signature and static argument value seen so far."""
    return int(fn._cache_size())


@contextlib.contextmanager
def compile_seconds():
    """Context manager yielding a one-element list that accumulates the seconds JAX spends compiling inside it
    (:data:`COMPILE_EVENTS`, in any thread of this process)."""
    total = [0.0]

    def listener(event, duration, **_):
        if event in COMPILE_EVENTS:
            total[0] += float(duration)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield total
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
