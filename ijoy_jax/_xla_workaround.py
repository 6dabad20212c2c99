"""Turns off XLA's CPU YNNPACK fusions where they miscompile, before JAX starts its backends.

jaxlib 0.10.2's CPU backend fuses a reduction and a multiply by a per-batch factor into one YNNPACK fusion
that, on large arrays (250 x 100 and 200 x 200 per batch element; 100 x 100 was right), combines one batch
element's operands with another's. Under ``jax.jit`` on the CPU, a batch of slopes whose directions differ
(``terrain.generators`` "slope", the walking benchmark's cross slopes) came out with the wrong sign for half
of them, 0.85 m off on a 5 m map; op by op, on the GPU, with jaxlib 0.10.0 / 0.10.1 and with jaxlib 0.11.2
the same programs are right. The smallest program that shows it::

    jax.jit(lambda u, s, c: s[:, None, None] * jnp.sum(c[None] * u[:, None, None, :], axis=-1))

with ``c`` (250, 100, 2), ``u`` (2, 2) and ``s`` (2,) (tests/test_xla_workaround.py). Without the
fusions (``--xla_cpu_experimental_ynn_fusion_type=``, an empty list of fused kinds) XLA emits its own
loops: correct, and as fast here (a batch of 64 2.5D decisions and one of 64 rough maps, 2-core CPU).

XLA reads ``XLA_FLAGS`` once, when JAX starts its first backend, so importing this module (the first
thing ``import ijoy_jax`` does) runs :func:`apply`: it appends the flag on the jaxlib versions that have
the bug and no fix (0.10.2 up to 0.11.2; all of them know the flag, and XLA aborts the process on a flag
it does not know). It leaves the environment alone where the caller chose a value for the flag, and
warns where JAX's backends have already started (import ijoy_jax first, or set the flag yourself).
"""

from __future__ import annotations

import os
import warnings

FLAG = "--xla_cpu_experimental_ynn_fusion_type="
"""The XLA flag that turns the CPU backend's YNNPACK fusions off."""
AFFECTED = ((0, 10, 2), (0, 11, 2))
"""jaxlib versions ``lo <= v < hi`` that miscompile (0.10.2 measured; 0.11.0 and 0.11.1 not available
here, so taken as affected)."""


def _version(text: str) -> tuple[int, ...]:
    parts = []
    for p in text.split("."):
        digits = "".join(c for c in p if c.isdigit())
        if not digits:
            break
        parts.append(int(digits))
    return tuple(parts)


def backends_started() -> bool:
    """Whether JAX has started a backend in this process (then ``XLA_FLAGS`` is no longer read).

    The one private access of this module: JAX has no public way to ask."""
    from jax._src import xla_bridge

    return bool(xla_bridge.backends_are_initialized())


def needed(jaxlib_version: str) -> bool:
    """Whether this jaxlib version miscompiles the fusion (see the module's docstring)."""
    lo, hi = AFFECTED
    return lo <= _version(jaxlib_version) < hi


def apply() -> bool:
    """Append :data:`FLAG` to ``XLA_FLAGS`` where this jaxlib needs it; returns whether it is in effect.

    Leaves a caller's own setting of the flag as it is (returns False); warns (RuntimeWarning) and changes
    nothing where JAX's backends have already started."""
    import jaxlib

    if not needed(jaxlib.__version__):
        return False
    flags = os.environ.get("XLA_FLAGS", "")
    if FLAG.rstrip("=") in flags:
        return False
    if backends_started():
        warnings.warn(
            f"jaxlib {jaxlib.__version__}'s CPU backend miscompiles some fused reductions under jax.jit "
            f"(ijoy_jax._xla_workaround), and JAX started its backends before ijoy_jax was imported, so "
            f"ijoy_jax could not turn those fusions off: import ijoy_jax first, or set "
            f"XLA_FLAGS={FLAG} yourself",
            RuntimeWarning,
            stacklevel=3,
        )
        return False
    os.environ["XLA_FLAGS"] = (flags + " " + FLAG).strip()
    return True


APPLIED = apply()
"""Whether importing ijoy_jax turned the fusions off in this process."""
