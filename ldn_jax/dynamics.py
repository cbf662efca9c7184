"""The dynamics model: M1 (trained) and M0 (its frozen initial copy), fit and predict."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax
from flax import struct

from ldn_jax.buffer import Buffer, Transitions, buffer_sample
from ldn_jax.config import ModelConfig
from ldn_jax.networks import DynamicsModel

Array = jax.Array


@struct.dataclass
class ModelState:
    params: dict
    """M1's parameters: fitted on real transitions."""
    frozen: dict
    """M0's parameters: M1's initial parameters, never updated."""
    opt_state: optax.OptState


class Dynamics:
    """Pure functions over `ModelState` for one observation/action size; holds no state."""

    def __init__(self, config: ModelConfig, obs_size: int, action_size: int):
        self.config = config
        self.obs_size = obs_size
        self.action_size = action_size
        self.net = DynamicsModel(
            obs_size=obs_size,
            hidden=config.hidden,
            activation=config.activation,
            init_std=config.init_std,
            predict_delta=config.predict_delta,
        )
        self.optimizer = optax.adam(config.lr)

    def init(self, key: Array) -> ModelState:
        params = self.net.init(key, jnp.zeros((1, self.obs_size)), jnp.zeros((1, self.action_size)))
        # M0 is M1 at initialisation: the same values, kept apart and never trained.
        frozen = jax.tree.map(jnp.copy, params)
        return ModelState(params=params, frozen=frozen, opt_state=self.optimizer.init(params))

    def predict(self, params: dict, obs: Array, action: Array) -> tuple[Array, Array]:
        """`[..., obs_size], [..., action_size] -> (next_obs [..., obs_size], reward [...])`."""
        return self.net.apply(params, obs, action)

    def loss(self, params: dict, batch: Transitions) -> Array:
        """Eq. 2: MSE on the target y = [s', r], mean over batch and output dims."""
        next_obs, reward = self.predict(params, batch.obs, batch.action)
        pred = jnp.concatenate([next_obs, reward[..., None]], axis=-1)
        target = jnp.concatenate([batch.next_obs, batch.reward[..., None]], axis=-1)
        return jnp.mean(jnp.square(pred - target))

    def fit(self, state: ModelState, buffer: Buffer, key: Array) -> tuple[ModelState, Array]:
        """`config.updates` minibatch Adam steps on M1; returns the mean loss."""

        def update(state: ModelState, key: Array):
            batch = buffer_sample(buffer, key, self.config.batch_size)
            loss, grads = jax.value_and_grad(self.loss)(state.params, batch)
            updates, opt_state = self.optimizer.update(grads, state.opt_state, state.params)
            params = optax.apply_updates(state.params, updates)
            return state.replace(params=params, opt_state=opt_state), loss

        keys = jax.random.split(key, self.config.updates)
        state, losses = jax.lax.scan(update, state, keys)
        return state, losses.mean() if self.config.updates else jnp.zeros(())
