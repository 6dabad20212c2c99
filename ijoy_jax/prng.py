"""PRNG keys: the one reading of "an int seed or a key" (STYLE.md rule 4).

Every public function that draws random numbers accepts an int seed, a typed
key (``jax.random.key``) or a raw uint32 key (``jax.random.PRNGKey``) and
passes it through :func:`as_key` once, at its edge. This module imports nothing
from the package, so terrain, robots, sim, sweep, tune and haptics can all use
it without an import cycle (it is neither geometry nor a pytree helper, so it
is a module of its own).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["as_key"]


def as_key(key) -> jax.Array:
    """A typed PRNG key from an int seed, a typed key or a raw uint32 key (traceable).

    Args:
      key: a Python/NumPy int or an integer () array (a seed); a typed key
        array of any shape (returned as is); or a raw uint32 key array of
        shape (..., 2) (the default threefry implementation), wrapped with
        ``jax.random.wrap_key_data`` (the same random bits).

    Returns:
      A typed key array (dtype ``key<impl>``): () for a seed, else the input's batch shape.

    Raises:
      TypeError: anything else (a float, a bool, a string, None, a float
        array, a uint32 array of the wrong shape), naming what was given.

    Example:
      >>> import jax
      >>> from ijoy_jax.prng import as_key
      >>> a, b = as_key(0), as_key(jax.random.PRNGKey(0))
      >>> bool((jax.random.key_data(a) == jax.random.key_data(b)).all())
      True
    """
    if isinstance(key, (bool, np.bool_)):
        raise TypeError(f"key must be an int seed or a PRNG key, got the bool {key!r}")
    if isinstance(key, (int, np.integer)):
        return jax.random.key(int(key))
    if isinstance(key, (jax.Array, np.ndarray)):
        dtype, shape = key.dtype, np.shape(key)
        if jnp.issubdtype(dtype, jax.dtypes.prng_key):
            return key
        if jnp.issubdtype(dtype, jnp.integer) and dtype != jnp.uint32 and shape == ():
            return jax.random.key(key)
        if dtype == jnp.uint32:
            if shape == ():
                return jax.random.key(key)
            try:
                return jax.random.wrap_key_data(key)
            except (TypeError, ValueError) as e:
                raise TypeError(f"a raw uint32 key must have shape (..., 2), got shape {shape}") from e
        raise TypeError(f"key must be an int seed or a PRNG key, got an array of dtype {dtype} and shape {shape}")
    raise TypeError(f"key must be an int seed or a PRNG key (jax.random.key or PRNGKey), got {type(key).__name__}")
