"""Pure-JAX environments behind one protocol (`ldn_jax.envs.base.Env`)."""

from ldn_jax.envs import mujoco
from ldn_jax.envs.registry import make, names

__all__ = ["make", "mujoco", "names"]
