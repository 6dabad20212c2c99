"""How many programs a ``jax.jit`` function holds compiled: the one place that reads JAX's private jit cache.

Functions users call in loops promise not to recompile (:func:`ijoy_jax.sim.walker.compiled_programs`,
``ijoy bench walk``'s compile counts); they count through :func:`compiled_count`. JAX has no public
counter: ``jax.jit`` objects expose ``_cache_size()`` (jax 0.4 to 0.11; tests/test_jit_cache.py pins it).
"""

from __future__ import annotations

__all__ = ["compiled_count"]


def compiled_count(fn) -> int:
    """The number of programs the jitted function ``fn`` (a ``jax.jit`` object) holds compiled in this process:
    one per input shape and dtype signature and static argument value seen so far."""
    return int(fn._cache_size())
