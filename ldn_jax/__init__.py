"""MBRL-LDN in JAX: model-based RL whose imagination is stopped by a learning degree."""

from ldn_jax.learning_degree import deviation, learning_degree, stop_draw, stop_probability
from ldn_jax.policy import load_policy

__all__ = ["deviation", "learning_degree", "load_policy", "stop_draw", "stop_probability"]
