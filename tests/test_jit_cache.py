"""ijoy_jax.jit_cache: the accessor of JAX's private jit cache size, pinned to the jax this project installs."""

import jax
import jax.numpy as jnp

from ijoy_jax.jit_cache import compiled_count


def test_counts_one_program_per_shape_and_static_value():
    f = jax.jit(lambda x, n: x * n, static_argnums=1)
    assert compiled_count(f) == 0
    f(jnp.ones(3), 2)
    f(jnp.zeros(3), 2)  # new values, same shape: no compile
    assert compiled_count(f) == 1
    f(jnp.ones(4), 2)  # new shape
    f(jnp.ones(3), 3)  # new static value
    assert compiled_count(f) == 3
    jax.clear_caches()
    assert compiled_count(f) == 0
