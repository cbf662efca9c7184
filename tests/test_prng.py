"""`ldn_jax.prng`: inside `written_out` threefry lowers without its loop, to the same bits;
outside it every program lowers as JAX lowers it."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax._src.interpreters import mlir
from jax._src.random import threefry2x32 as threefry

from ldn_jax import prng
from ldn_jax.config import from_preset
from ldn_jax.trainer import Trainer

pytestmark = [
    pytest.mark.skipif(
        not prng.INSTALLED or jax.default_backend() != "cpu", reason="CPU-only lowering"
    ),
    # bit-equality between different programs: XLA's rewrites decide the bits (conftest.py)
    pytest.mark.optimized,
]


def draws(key):
    k1, k2, k3, k4 = jax.random.split(key, 4)
    return (
        jax.random.bits(k1, (7, 33)),
        jax.random.categorical(k2, jnp.zeros((80, 2))),
        jax.random.normal(k3, (5, 200)),
        jax.random.randint(k4, (64,), 0, 49_999),
        jax.random.permutation(k1, 800),
        jax.random.split(k4, 3),  # typed keys: compared by their data
    )


def values(outputs) -> list[np.ndarray]:
    data = lambda x: (
        jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
    )
    return [np.asarray(data(x)) for x in jax.tree.leaves(outputs)]


def test_written_out_threefry_gives_the_loops_bits_and_only_inside_written_out():
    key = jax.random.key(123)
    # A new jitted function each time, so that no traced or lowered program is reused.
    written = prng.written_out(jax.jit(draws))
    written_text = written.lower(key).as_text()
    plain_text = jax.jit(draws).lower(key).as_text()
    assert "while" not in written_text
    assert "while" in plain_text  # JAX's CPU lowering: a loop over the rounds
    for a, b in zip(values(written(key)), values(jax.jit(draws)(key)), strict=True):
        np.testing.assert_array_equal(a, b)


def test_outside_written_out_programs_lower_exactly_as_jaxs_own_rule_lowers_them():
    key = jax.random.key(5)
    ours = jax.jit(draws).lower(key).as_text()
    try:
        rolled = threefry._threefry2x32_cpu_lowering_rule
        mlir.register_lowering(threefry.threefry2x32_p, rolled, platform="cpu")
        jaxs = jax.jit(draws).lower(key).as_text()
    finally:
        assert prng._install()
    assert ours == jaxs


def test_the_trainers_chunk_is_written_out_and_computes_what_jaxs_lowering_computes():
    # ldn: the real stage, M1's fit and LD-stopped imagination, all drawing keys.
    config = from_preset("paper", env="cartpole-v1", algo="ldn", seeds=2, k=(0.5, 1.0))
    trainer = Trainer(config)
    states, k = trainer.init_batch(), trainer.k_values()
    chunk = trainer.batched_chunk()
    loops = lambda lowered: lowered.as_text().count("stablehlo.while")
    # `.jitted` is the same program lowered outside `written_out`, as JAX lowers it.
    assert loops(chunk.lower(states, k)) < loops(chunk.jitted.lower(states, k))
    fresh = lambda: jax.tree.map(jnp.copy, states)  # the chunk donates its states
    for a, b in zip(values(chunk(fresh(), k)), values(chunk.jitted(fresh(), k)), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("preset", "env", "algo"),
    [("branched", "hopper", "sac-model"), ("paper", "cartpole-v0", "ldn")],
)
def test_the_initial_states_are_written_out_and_are_what_jaxs_lowering_gives(preset, env, algo):
    # sac-model: five nets, an ensemble and the workers' resets; ldn: M1, M0 and the buffer.
    # The replay memory at 10,000 rows (the preset's 1M zeros are 350 MB to compare)
    config = from_preset(preset, env=env, algo=algo, seeds=2)
    config = dataclasses.replace(
        config, sac=dataclasses.replace(config.sac, buffer_capacity=10_000)
    )
    trainer = Trainer(config)
    jitted = jax.jit(trainer._init_batch)
    loops = lambda lowered: lowered.as_text().count("stablehlo.while")
    assert loops(prng.written_out(jitted).lower()) < loops(jitted.lower())
    written, own = values(trainer.init_batch()), values(jitted())
    for a, b in zip(written, own, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("n", [1, 2, 800, 1_625, 1_626, 5_000])
def test_permutation_is_jaxs_permutation_bit_for_bit(n):
    # 1,626 is the first size JAX shuffles in two rounds of sorts.
    keys = jax.random.split(jax.random.key(n), 3)
    ours = jax.jit(jax.vmap(lambda key: prng.permutation(key, n)))(keys)
    jaxs = jax.vmap(lambda key: jax.random.permutation(key, n))(keys)
    assert ours.dtype == jaxs.dtype
    np.testing.assert_array_equal(ours, jaxs)


def test_stable_argsort_of_bits_orders_equal_keys_by_index():
    # Few distinct keys, so most are tied: the order among equal keys is the index order.
    bits = jax.random.randint(jax.random.key(0), (2, 1_000), 0, 7).astype(jnp.uint32)
    ours = jax.jit(jax.vmap(prng._stable_argsort_bits))(bits)
    np.testing.assert_array_equal(ours, jnp.argsort(bits, axis=-1, stable=True))
    extremes = jnp.array([0xFFFFFFFF, 0, 0xFFFFFFFF, 1, 0], jnp.uint32)
    np.testing.assert_array_equal(prng._stable_argsort_bits(extremes), [1, 4, 3, 0, 2])
