"""Threefry, the hash behind every `jax.random` draw, lowered without its loop on CPU.

JAX lowers `threefry2x32` on CPU as a `fori_loop` over its 5 double-rounds (on GPU and TPU
it writes the 20 rounds out). On XLA:CPU that loop runs as a while loop whose body is some
twenty small kernels dispatched one by one, for each draw: a categorical action at every env
step, every minibatch index of M1's 100 fits. Written out, XLA fuses the rounds into one
kernel. The hash is integer arithmetic, so both lowerings give the same bits.

Measured on 2 cores (cartpole-v1, 10 seeds x 8 workers, schedule `steps`, one 500-step
iteration after 400 episodes): a2c 49.5 -> 38.7 ms, a2c-model 193 -> 168 ms.

`ldn_jax` applies it on import (`unroll_threefry_on_cpu()`); it changes no result.
"""

from __future__ import annotations


def unroll_threefry_on_cpu() -> bool:
    """Lower `threefry2x32` on CPU as JAX does on other backends (rounds written out);
    returns whether it could (False, and nothing changed, if this JAX has no such rule)."""
    try:
        from jax._src.interpreters import mlir
        from jax._src.random import threefry2x32 as threefry
    except ImportError:
        return False
    rule = getattr(threefry, "_threefry2x32_lowering_rule", None)
    primitive = getattr(threefry, "threefry2x32_p", None)
    if rule is None or primitive is None:
        return False
    mlir.register_lowering(primitive, rule, platform="cpu", inline=False)
    return True
