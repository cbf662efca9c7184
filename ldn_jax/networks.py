"""Actor, critic and dynamics-model networks (flax.linen)."""

from __future__ import annotations

from collections.abc import Callable

import flax.linen as nn
import jax
import jax.numpy as jnp

Array = jax.Array

ACTIVATIONS: dict[str, Callable[[Array], Array]] = {
    "linear": lambda x: x,
    "relu": nn.relu,
    "relu6": nn.relu6,
    "tanh": nn.tanh,
}


def normal_init(std: float):
    """flax's `normal(std)` initialiser, kept the same to the bit under `jit` as eagerly.

    The barrier stops XLA from folding `std` into the sampler's own constant factor (its
    sqrt(2) times erfinv), which rounds differently: with it a jitted `Trainer.init_batch`
    gives the weights that op-by-op execution gives.
    """

    def init(key: Array, shape, dtype=jnp.float32) -> Array:
        sample = jax.lax.optimization_barrier(jax.random.normal(key, shape, dtype))
        return sample * jnp.asarray(std, dtype)

    return init


class MLP(nn.Module):
    """Input -> one hidden layer -> output (the paper's "three-layer" net)."""

    hidden: int
    out: int
    activation: str
    init_std: float

    @nn.compact
    def __call__(self, x: Array) -> Array:
        init = normal_init(self.init_std)
        x = nn.Dense(self.hidden, kernel_init=init)(x)
        x = ACTIVATIONS[self.activation](x)
        return nn.Dense(self.out, kernel_init=init)(x)


class DynamicsModel(nn.Module):
    """The paper's model: (s, a) -> s' by one net, then s' -> r by another.

    `a` enters one-hot for discrete actions. With `predict_delta` the first net's output is
    added to `s`, so the reward net still sees the predicted next state.
    """

    obs_size: int
    hidden: int
    activation: str
    init_std: float
    predict_delta: bool

    @nn.compact
    def __call__(self, obs: Array, action: Array) -> tuple[Array, Array]:
        """obs `[..., obs_size]`, action `[..., action_size]` -> (next_obs, reward `[...]`)."""
        mlp = lambda out: MLP(self.hidden, out, self.activation, self.init_std)
        next_obs = mlp(self.obs_size)(jnp.concatenate([obs, action], axis=-1))
        if self.predict_delta:
            next_obs = obs + next_obs
        reward = mlp(1)(next_obs)[..., 0]
        return next_obs, reward
