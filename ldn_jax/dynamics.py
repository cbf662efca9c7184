"""The dynamics model: M1 (trained) and M0 (its frozen initial copy), fit and predict.

With `ModelConfig.ld = "ensemble"` M1 is E models ("members") whose parameters, optimiser
states and M0 copies are stacked on a leading axis `[E, ...]`; they share the normaliser.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax
from flax import struct

from ldn_jax.buffer import Buffer, Transitions, buffer_sample
from ldn_jax.config import ModelConfig
from ldn_jax.networks import DynamicsModel

Array = jax.Array

MIN_WIDTH = 1e-3
"""The narrowest box side `buffer_bounds` widens from, and the floor of the normaliser's std."""


@struct.dataclass
class Normalizer:
    """Observation and reward statistics the model works in (identity when off)."""

    obs_mean: Array
    obs_std: Array
    reward_mean: Array
    reward_std: Array


@struct.dataclass
class ModelState:
    params: dict
    """M1's parameters: fitted on real transitions. Ensemble: every member's, `[E, ...]`."""
    frozen: dict
    """M0's parameters: M1's initial parameters, never updated. Ensemble: each member's
    initial copy `[E, ...]`, kept (unused by imagination) so the state has one layout."""
    opt_state: optax.OptState
    """M1's Adam state. Ensemble: each member's, `[E, ...]`."""
    stats: Normalizer
    """Shared by M1 and M0 (and all members); refreshed from the buffer before each fit when
    normalising."""
    error_scale: Array | None = None
    """Ensemble only (None otherwise, so the m0 state and its checkpoints keep their layout):
    the members' mean eq. 2 loss of the last fit, in the model's normalised units; 1 until the
    first fit. Disagreement is measured relative to it (`relative_disagreement`)."""
    bounds: tuple[Array, Array] | None = None
    """With `ModelConfig.support` set (None otherwise, so other states keep their layout):
    the lowest and highest real observation per dimension in the buffer, `([D], [D])`,
    refreshed before each fit and widened by `support`; unbounded until the first fit."""


def action_encoder(encoding: str, policy, action_spec) -> tuple:
    """How the model takes the policy's actions (`ModelConfig.action_encoding`): `(encode,
    size)`, `encode(action [...]) -> [..., size]`. Discrete: one-hot, the index as one
    number, or the force the action applies (the env's `action_spec.forces`); continuous:
    the clipped vector whatever the encoding."""
    if not policy.discrete or encoding == "one-hot":
        return policy.model_action, policy.model_action_size
    if encoding == "index":
        return lambda action: action.astype(jnp.float32)[..., None], 1
    forces = tuple(getattr(action_spec, "forces", ()))
    if encoding != "force" or not forces:
        raise ValueError(f"action encoding {encoding!r} is not available for this env")
    return lambda action: jnp.asarray(forces, jnp.float32)[action][..., None], 1


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

    @property
    def ensemble(self) -> bool:
        """M1 is `config.ensemble` stacked members (`ld = "ensemble"`)."""
        return self.config.ld == "ensemble"

    def init(self, key: Array) -> ModelState:
        """M1 and M0; ensemble: member i initialised from `jax.random.split(key, E)[i]`."""
        init = lambda key: self.net.init(
            key, jnp.zeros((1, self.obs_size)), jnp.zeros((1, self.action_size))
        )
        if self.ensemble:
            params = jax.vmap(init)(jax.random.split(key, self.config.ensemble))
            opt_state = jax.vmap(self.optimizer.init)(params)
        else:
            params = init(key)
            opt_state = self.optimizer.init(params)
        # M0 is M1 at initialisation: the same values, kept apart and never trained.
        frozen = jax.tree.map(jnp.copy, params)
        return ModelState(
            params=params,
            frozen=frozen,
            opt_state=opt_state,
            stats=self.init_stats(),
            error_scale=jnp.ones((), jnp.float32) if self.ensemble else None,
            bounds=self._unbounded() if self.config.support is not None else None,
        )

    def predict_normalized(
        self, params: dict, stats: Normalizer, obs: Array, action: Array
    ) -> tuple[Array, Array]:
        """The net's own outputs: next obs and reward in normalised units."""
        return self.net.apply(params, (obs - stats.obs_mean) / stats.obs_std, action)

    def predict_members(
        self, params: dict, stats: Normalizer, obs: Array, action: Array
    ) -> tuple[Array, Array]:
        """`predict_normalized` for every member of stacked `params` `[E, ...]`:
        `[..., obs_size], [..., action_size] -> (next_obs [E, ..., obs_size], reward [E, ...])`."""
        return jax.vmap(self.predict_normalized, (0, None, None, None))(params, stats, obs, action)

    @staticmethod
    def denormalize(stats: Normalizer, next_obs: Array, reward: Array) -> tuple[Array, Array]:
        return (
            next_obs * stats.obs_std + stats.obs_mean,
            reward * stats.reward_std + stats.reward_mean,
        )

    def predict(
        self, params: dict, obs: Array, action: Array, stats: Normalizer | None = None
    ) -> tuple[Array, Array]:
        """`[..., obs_size], [..., action_size] -> (next_obs [..., obs_size], reward [...])`."""
        stats = stats if stats is not None else self.init_stats()
        return self.denormalize(stats, *self.predict_normalized(params, stats, obs, action))

    def init_stats(self) -> Normalizer:
        return Normalizer(
            obs_mean=jnp.zeros(self.obs_size),
            obs_std=jnp.ones(self.obs_size),
            reward_mean=jnp.zeros(()),
            reward_std=jnp.ones(()),
        )

    def loss(self, params: dict, batch: Transitions, stats: Normalizer | None = None) -> Array:
        """Eq. 2: MSE on the target y = [s', r] (normalised when on), mean over batch and
        output dims."""
        stats = stats if stats is not None else self.init_stats()
        next_obs, reward = self.predict_normalized(params, stats, batch.obs, batch.action)
        pred = jnp.concatenate([next_obs, reward[..., None]], axis=-1)
        target = jnp.concatenate(
            [
                (batch.next_obs - stats.obs_mean) / stats.obs_std,
                ((batch.reward - stats.reward_mean) / stats.reward_std)[..., None],
            ],
            axis=-1,
        )
        return jnp.mean(jnp.square(pred - target))

    def _unbounded(self) -> tuple[Array, Array]:
        return jnp.full(self.obs_size, -jnp.inf), jnp.full(self.obs_size, jnp.inf)

    def buffer_bounds(self, buffer: Buffer) -> tuple[Array, Array]:
        """The box of the buffer's valid observations (before and after each step), widened
        on each side by `config.support` times its width (at least `MIN_WIDTH`); unbounded
        while the buffer is empty."""
        valid = jnp.tile(jnp.arange(buffer.capacity) < buffer.size, 2)[:, None]
        obs = jnp.concatenate([buffer.data.obs, buffer.data.next_obs])
        low = jnp.min(jnp.where(valid, obs, jnp.inf), axis=0)
        high = jnp.max(jnp.where(valid, obs, -jnp.inf), axis=0)
        # A dimension the data never varied in (ant's contact forces of bodies that never
        # touch) gets the width of the normaliser's std floor, or every prediction's rounding
        # would leave the box.
        margin = self.config.support * jnp.maximum(high - low, MIN_WIDTH)
        unbounded_low, unbounded_high = self._unbounded()
        empty = buffer.size == 0
        return (
            jnp.where(empty, unbounded_low, low - margin),
            jnp.where(empty, unbounded_high, high + margin),
        )

    def within_bounds(self, state: ModelState, obs: Array) -> Array:
        """`[..., D] -> [...]`: the observation lies in `state.bounds` (always, without)."""
        if state.bounds is None:
            return jnp.ones(obs.shape[:-1], bool)
        low, high = state.bounds
        return jnp.all((obs >= low) & (obs <= high), axis=-1)

    def buffer_stats(self, buffer: Buffer) -> Normalizer:
        """Mean and std of the buffer's valid observations and rewards (std floored)."""
        valid = (jnp.arange(buffer.capacity) < buffer.size).astype(jnp.float32)
        count = jnp.maximum(valid.sum(), 1.0)

        def moments(x: Array) -> tuple[Array, Array]:
            w = valid.reshape((-1,) + (1,) * (x.ndim - 1))
            mean = (x * w).sum(0) / count
            var = (jnp.square(x - mean) * w).sum(0) / count
            return mean, jnp.maximum(jnp.sqrt(var), MIN_WIDTH)

        obs_mean, obs_std = moments(buffer.data.obs)
        reward_mean, reward_std = moments(buffer.data.reward)
        return Normalizer(obs_mean, obs_std, reward_mean, reward_std)

    def fit(self, state: ModelState, buffer: Buffer, key: Array) -> tuple[ModelState, Array]:
        """`config.updates` minibatch Adam steps on M1; returns the mean loss.

        Ensemble: every member takes its own steps (vmapped), member i drawing its minibatches
        with `jax.random.split(key, E)[i]`; the loss returned, and kept as `error_scale`, is
        the members' mean.
        """
        if self.config.normalize:
            state = state.replace(stats=self.buffer_stats(buffer))
        if self.config.support is not None:
            state = state.replace(bounds=self.buffer_bounds(buffer))
        if not self.ensemble:
            params, opt_state, loss = self._fit_one(
                state.params, state.opt_state, state.stats, buffer, key
            )
            return state.replace(params=params, opt_state=opt_state), loss
        keys = jax.random.split(key, self.config.ensemble)
        fit = jax.vmap(self._fit_one, (0, 0, None, None, 0))
        params, opt_state, losses = fit(state.params, state.opt_state, state.stats, buffer, keys)
        loss = losses.mean()
        error_scale = loss if self.config.updates else state.error_scale
        return state.replace(params=params, opt_state=opt_state, error_scale=error_scale), loss

    def _fit_one(
        self, params: dict, opt_state: optax.OptState, stats: Normalizer, buffer: Buffer, key: Array
    ) -> tuple[dict, optax.OptState, Array]:
        """One model's `config.updates` steps: its new params, Adam state and mean loss."""

        def update(carry, key: Array):
            params, opt_state = carry
            batch = buffer_sample(buffer, key, self.config.batch_size)
            loss, grads = jax.value_and_grad(self.loss)(params, batch, stats)
            updates, opt_state = self.optimizer.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), loss

        keys = jax.random.split(key, self.config.updates)
        (params, opt_state), losses = jax.lax.scan(update, (params, opt_state), keys)
        return params, opt_state, losses.mean() if self.config.updates else jnp.zeros(())
