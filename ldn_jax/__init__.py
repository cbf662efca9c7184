"""MBRL-LDN in JAX: model-based RL whose imagination is stopped by a learning degree."""

from ldn_jax.learning_degree import deviation, learning_degree, stop_draw, stop_probability
from ldn_jax.policy import load_policy
from ldn_jax.prng import unroll_threefry_on_cpu

unroll_threefry_on_cpu()  # the same bits, faster on CPU (`ldn_jax.prng`)

__all__ = ["deviation", "learning_degree", "load_policy", "stop_draw", "stop_probability"]
