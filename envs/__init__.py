"""Pure-JAX environments behind one protocol (`envs.base.Env`)."""

from envs import mujoco
from envs.registry import make, names

__all__ = ["make", "mujoco", "names"]
