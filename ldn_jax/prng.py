"""`jax.random`'s draws made faster on CPU, to the same bits: threefry written out, and
permutations by one-operand sorts.

`written_out`: threefry2x32 is the hash behind every `jax.random` draw. JAX lowers it on CPU
as a `fori_loop` over its 5 double-rounds (on GPU and TPU it writes the 20 rounds out). XLA:CPU
runs that loop as a while loop of some twenty small kernels, dispatched one by one, for each
draw: several per env step (the action, the env's keys, the resets) and one per minibatch of
M1's fit. Written out, XLA fuses the rounds into one kernel. The hash is integer arithmetic,
so both lowerings give the same bits (tests/test_prng.py).

It pays most for a2c, where the draws are a larger share of the work (docs/defaults.md).

It applies only inside `written_out(...)`, to the programs the trainer compiles
(`Trainer.batched_chunk`, `Trainer.batched_evaluate`, `Trainer.init_batch`): the draws keep
their bits, but XLA can compile the code around them differently. A single-env CartPole
rollout, jitted on its own, came out 1 ulp apart from its vmapped twin under the written-out
lowering (and equal under JAX's), so every other program keeps JAX's lowering. If this JAX
lacks the rules it uses, nothing changes (`INSTALLED` is False).

`permutation`: `jax.random.permutation` (PPO's shuffle, every epoch), through sorts XLA:CPU
runs with a plain comparison; the same permutation (tests/test_prng.py).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np


def _state():
    """A JAX config state, part of JAX's cache keys, so that a function traced and lowered
    in one setting is never reused in the other; None where this JAX cannot make one."""
    try:
        from jax._src import config

        return config.bool_state(
            name="ldn_jax_threefry_written_out",
            default=False,
            help="Lower threefry2x32 on CPU with its rounds written out (ldn_jax.prng).",
            include_in_jit_key=True,
            include_in_trace_context=True,
        )
    except (ImportError, AttributeError, TypeError):
        return None


_WRITTEN_OUT = _state()


def _install() -> bool:
    """Register, for CPU, a threefry lowering that writes the rounds out while
    `_WRITTEN_OUT` is on and is JAX's own CPU rule otherwise."""
    try:
        from jax._src.interpreters import mlir
        from jax._src.random import threefry2x32 as threefry
    except ImportError:
        return False
    if _WRITTEN_OUT is None:
        return False
    written = getattr(threefry, "_threefry2x32_lowering_rule", None)
    rolled = getattr(threefry, "_threefry2x32_cpu_lowering_rule", None)
    primitive = getattr(threefry, "threefry2x32_p", None)
    if written is None or rolled is None or primitive is None:
        return False

    def rule(ctx, *args, **params):
        return (written if _WRITTEN_OUT.value else rolled)(ctx, *args, **params)

    # Inline, as JAX registers its CPU rule: programs outside `written_out` lower as before.
    mlir.register_lowering(primitive, rule, platform="cpu")
    return True


INSTALLED = _install()
"""Whether this JAX has the rules `written_out` switches between."""


class written_out:
    """A jitted function whose programs lower threefry written out on CPU, whether they are
    compiled by a call or by `.lower(...)`; everything else passes through."""

    def __init__(self, jitted):
        self.jitted = jitted

    def __call__(self, *args, **kwargs):
        if not INSTALLED:
            return self.jitted(*args, **kwargs)
        with _WRITTEN_OUT(True):
            return self.jitted(*args, **kwargs)

    def lower(self, *args, **kwargs):
        if not INSTALLED:
            return self.jitted.lower(*args, **kwargs)
        with _WRITTEN_OUT(True):
            return self.jitted.lower(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self.jitted, name)


def _stable_argsort_bits(bits: jax.Array) -> jax.Array:
    """`jnp.argsort(bits, stable=True)` of one row of `uint32` bits, `[n] -> [n]` int32,
    for n <= 2**16, through two single-operand sorts.

    XLA:CPU sorts one operand of a primitive type with a plain comparison, but a key-value
    sort (JAX's argsort) calls a compiled comparator for every comparison: about 7 times
    slower for 800 keys. Each key's rank among the keys (its first place in the sorted
    keys: equal keys share it) goes in the high 16 bits and its index in the low 16, so one
    sort of these orders by key, then by index, which is the stable order.
    """
    (n,) = bits.shape
    rank = jnp.searchsorted(jax.lax.sort(bits), bits, side="left").astype(jnp.uint32)
    order = jax.lax.sort((rank << 16) | jnp.arange(n, dtype=jnp.uint32))
    return (order & 0xFFFF).astype(jnp.int32)


def permutation(key: jax.Array, n: int) -> jax.Array:
    """`jax.random.permutation(key, n)`, the same bits, faster on CPU for n <= 2**16.

    JAX shuffles by sorting `arange(n)` under fresh random 32-bit keys, in as many rounds as
    its collision bound asks (one up to n = 1,625), each a stable key-value sort; here each
    round's stable order comes from `_stable_argsort_bits`. PPO shuffles its rows with it
    once per epoch. Larger n goes to JAX.
    """
    if n > 1 << 16:
        return jax.random.permutation(key, n)
    rounds = math.ceil(3 * math.log(max(1, n)) / math.log(np.iinfo(np.uint32).max))
    order = jnp.arange(n, dtype=jnp.int32)
    for _ in range(rounds):
        key, k_bits = jax.random.split(key)
        order = order[_stable_argsort_bits(jax.random.bits(k_bits, (n,), jnp.uint32))]
    return order
