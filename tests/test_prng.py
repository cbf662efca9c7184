"""`ldn_jax.prng`: threefry written out on CPU gives the rolled loop's bits."""

import jax
import numpy as np
from jax._src.interpreters import mlir
from jax._src.random import threefry2x32 as threefry

import ldn_jax  # noqa: F401  (applies the unrolled lowering)
from ldn_jax.prng import unroll_threefry_on_cpu


def draws(key):
    k1, k2, k3, k4 = jax.random.split(key, 4)
    return (
        jax.random.bits(k1, (7, 33)),
        jax.random.categorical(k2, jax.numpy.zeros((80, 2))),
        jax.random.normal(k3, (5, 200)),
        jax.random.randint(k4, (64,), 0, 49_999),
        jax.random.split(k4, 3),  # typed keys: compared by their data
    )


def lowered(key):
    """The HLO and values of `draws` under the lowering registered now (a new function
    each time, so no cached executable is reused)."""
    fn = jax.jit(lambda key: draws(key))
    text = fn.lower(key).as_text()
    key_data = lambda x: (
        jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
    )
    return text, [np.asarray(key_data(x)) for x in fn(key)]


def test_unrolled_threefry_gives_the_rolled_bits():
    key = jax.random.key(123)
    unrolled_text, unrolled = lowered(key)
    assert "while" not in unrolled_text  # applied on import
    try:
        rolled_rule = threefry._threefry2x32_cpu_lowering_rule
        mlir.register_lowering(threefry.threefry2x32_p, rolled_rule, platform="cpu")
        rolled_text, rolled = lowered(key)
    finally:
        assert unroll_threefry_on_cpu()
    assert "while" in rolled_text  # JAX's own CPU lowering: a loop over the rounds
    for a, b in zip(jax.tree.leaves(rolled), jax.tree.leaves(unrolled), strict=True):
        np.testing.assert_array_equal(a, b)
