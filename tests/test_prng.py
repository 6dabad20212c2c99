"""Tests of ijoy_jax.prng.as_key: the one reading of an int seed or a PRNG key."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ijoy_jax.prng import as_key


def _bits(key):
    return np.asarray(jax.random.key_data(key))


@pytest.mark.parametrize("seed", [0, 7, np.int64(7), np.uint32(3), jnp.int32(5)])
def test_int_seed_is_jax_random_key(seed):
    k = as_key(seed)
    assert jnp.issubdtype(k.dtype, jax.dtypes.prng_key) and k.shape == ()
    np.testing.assert_array_equal(_bits(k), _bits(jax.random.key(int(seed))))


def test_typed_key_passes_through():
    k = jax.random.split(jax.random.key(1), 4)
    assert as_key(k) is k


@pytest.mark.parametrize("shape", [(), (3,)])
def test_raw_uint32_key_is_wrapped_with_the_same_bits(shape):
    raw = jax.random.PRNGKey(2) if shape == () else jax.random.split(jax.random.PRNGKey(2), 3)
    k = as_key(raw)
    assert jnp.issubdtype(k.dtype, jax.dtypes.prng_key) and k.shape == shape
    np.testing.assert_array_equal(_bits(k), np.asarray(raw))
    # the same draws as the raw key
    np.testing.assert_array_equal(jax.random.uniform(as_key(np.asarray(jax.random.PRNGKey(2))), (4,)),
                                  jax.random.uniform(jax.random.PRNGKey(2), (4,)))


def test_under_jit_and_vmap():
    f = jax.jit(lambda k: jax.random.uniform(as_key(k)))
    assert float(f(jax.random.key(0))) == float(jax.random.uniform(jax.random.key(0)))
    raw = jax.random.split(jax.random.PRNGKey(0), 2)
    out = jax.vmap(lambda k: jax.random.uniform(as_key(k)))(raw)
    assert out.shape == (2,)


@pytest.mark.parametrize(
    "bad, match",
    [
        (1.5, "got float"),
        ("0", "got str"),
        (None, "got NoneType"),
        (True, "bool"),
        (np.zeros(2, np.float32), "dtype float32"),
        (np.zeros((2, 3), np.uint32), r"shape \(\.\.\., 2\)"),
        (np.zeros(2, np.int32), "dtype int32"),
    ],
)
def test_bad_input_is_a_clear_error(bad, match):
    with pytest.raises(TypeError, match=match):
        as_key(bad)
