"""The dynamics model: M1 (trained) and M0 (its frozen initial copy), fit and predict.

With `ModelConfig.ld = "ensemble"` M1 is E models ("members") whose parameters, optimiser
states and M0 copies are stacked on a leading axis `[E, ...]`; they share the normaliser.
With `ModelConfig.probabilistic` each member outputs a Gaussian (`GaussianDynamicsModel`),
fitted by `gaussian_nll`, and the members are ranked on held-out slots of the buffer.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import optax
from flax import struct

from ldn_jax.buffer import (
    HOLDOUT_EVERY,
    Buffer,
    Transitions,
    buffer_sample,
    buffer_sample_split,
)
from ldn_jax.config import FitConfig, ModelConfig
from ldn_jax.networks import MLP, DynamicsModel, GaussianDynamicsModel

Array = jax.Array

MIN_WIDTH = 1e-3
"""The narrowest box side `buffer_bounds` widens from, and the floor of the normaliser's std."""

BOUND_PENALTY = 0.01
"""Weight of the penalty sum(max_log_var) - sum(min_log_var) in a probabilistic model's loss
(PETS' and MBPO's value): it keeps the learned log-variance bounds tight."""

TERMINATION_STREAM = 7
"""`jax.random.fold_in(key, ...)` of the learned termination's draws (its initial parameters,
its fit's minibatches), so M1's stay as they are."""

HOLDOUT_BATCH = 1024
"""Held-out transitions drawn to rank a probabilistic ensemble's members after each fit."""


def gaussian_nll(mean: Array, log_var: Array, target: Array) -> Array:
    """The negative log-likelihood of `target` under N(mean, exp(log_var)) per output,
    0.5 ((y - mean)^2 exp(-log_var) + log_var + log 2 pi), averaged over every axis."""
    error = jnp.square(target - mean) * jnp.exp(-log_var)
    return 0.5 * jnp.mean(error + log_var + jnp.log(2 * jnp.pi))


@struct.dataclass
class Normalizer:
    """Observation and reward statistics the model works in (identity when off)."""

    obs_mean: Array
    obs_std: Array
    reward_mean: Array
    reward_std: Array


TERMINATION_LAYERS = 2
"""Hidden layers of the learned termination's classifier (`model.hidden` swish units each)."""


@struct.dataclass
class Termination:
    """The learned termination's classifier (`ImagineConfig.termination` "learned")."""

    params: dict
    opt_state: optax.OptState


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
    elites: Array | None = None
    """Probabilistic ensemble only (None otherwise): the indices `[elites]` of the members
    with the lowest held-out squared error at the last fit, those that imagine; all
    members until the first fit."""
    error_scale: Array | None = None
    """Ensemble only (None otherwise, so the m0 state and its checkpoints keep their layout):
    the members' mean eq. 2 loss of the last fit, in the model's normalised units; 1 until the
    first fit. Disagreement is measured relative to it (`relative_disagreement`)."""
    bounds: tuple[Array, Array] | None = None
    """With `ModelConfig.support` set (None otherwise, so other states keep their layout):
    the lowest and highest real observation per dimension in the buffer, `([D], [D])`,
    refreshed before each fit and widened by `support`; unbounded until the first fit."""
    termination: Termination | None = None
    """With a learned termination (None otherwise, so other states keep their layout): the
    classifier of the next observation, in the model's normalised units, fitted after M1."""


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


def kernel_norm(params: dict) -> Array:
    """Half the sum of the squares of every kernel in `params` (biases and the log-variance
    bounds left out): the L2 penalty `FitConfig.weight_decay` weighs."""
    leaves = jax.tree_util.tree_leaves_with_path(params)
    kernels = [x for path, x in leaves if getattr(path[-1], "key", None) == "kernel"]
    return 0.5 * sum(jnp.sum(jnp.square(x)) for x in kernels)


@dataclass(frozen=True)
class EarlyStop:
    """When `Dynamics.fit_until_stalled` ends (MBPO's: patience 5, a 1% gain)."""

    patience: int = 5
    """Epochs in a row without a gain that the fit goes on through."""
    min_gain: float = 0.01
    """A member gains where its held-out error falls by more than this share of its best."""
    max_epochs: int = 1000
    """The fit ends here whatever the errors do."""
    max_steps: int = 0
    """The fit ends at the first epoch that brings its minibatch steps to this many, whatever
    the errors do (0: no cap)."""


class Dynamics:
    """Pure functions over `ModelState` for one observation/action size; holds no state."""

    def __init__(
        self,
        config: ModelConfig,
        obs_size: int,
        action_size: int,
        termination: str = "known",
        fit: FitConfig | None = None,
    ):
        """`termination`: "learned" keeps a termination classifier beside M1
        (`ImagineConfig.termination`); `fit`: how M1 is fitted (`FitConfig`'s defaults)."""
        self.config, self.termination = config, termination
        self.fitting = fit if fit is not None else FitConfig()
        self.obs_size = obs_size
        self.action_size = action_size
        if config.probabilistic:
            self.net = GaussianDynamicsModel(
                obs_size=obs_size,
                hidden=config.hidden,
                activation=config.activation,
                layers=config.hidden_layers,
            )
        else:
            self.net = DynamicsModel(
                obs_size=obs_size,
                hidden=config.hidden,
                activation=config.activation,
                init_std=config.init_std,
                predict_delta=config.predict_delta,
            )
        self.optimizer = optax.adam(self.fitting.lr)
        self.termination_net = MLP(config.hidden, 1, "swish", 0.0, TERMINATION_LAYERS, "fan_in")

    @property
    def ensemble(self) -> bool:
        """M1 is `config.ensemble` stacked members (`ld` "ensemble" or "variance", or any
        probabilistic model)."""
        return self.config.ld in ("ensemble", "variance") or self.config.probabilistic

    @property
    def probabilistic(self) -> bool:
        return self.config.probabilistic

    @property
    def elite_count(self) -> int:
        """How many members imagine (`ModelConfig.elites`, or all)."""
        return self.config.elites or self.config.ensemble

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
            elites=jnp.arange(self.elite_count, dtype=jnp.int32) if self.probabilistic else None,
            error_scale=jnp.ones((), jnp.float32) if self.ensemble else None,
            bounds=self._unbounded() if self.config.support is not None else None,
            termination=self._termination_init(key),
        )

    def _termination_init(self, key: Array) -> Termination | None:
        """The classifier where it is learned, from a key of its own (M1 keeps its draws)."""
        if self.termination != "learned":
            return None
        params = self.termination_net.init(
            jax.random.fold_in(key, TERMINATION_STREAM), jnp.zeros((1, self.obs_size))
        )
        return Termination(params, self.optimizer.init(params))

    def terminal_logit(self, params: dict, stats: Normalizer, obs: Array) -> Array:
        """The classifier's log-odds that `obs` `[..., D]` is terminal, `[...]`."""
        return self.termination_net.apply(params, (obs - stats.obs_mean) / stats.obs_std)[..., 0]

    def is_terminal(self, state: ModelState, obs: Array) -> Array:
        """The learned test: `obs [..., D] -> [...]`, terminal where the classifier's
        probability passes one half."""
        return self.terminal_logit(state.termination.params, state.stats, obs) > 0.0

    def termination_loss(
        self, params: dict, stats: Normalizer, batch: Transitions, share: Array
    ) -> Array:
        """The classifier's binary cross-entropy on the batch's next observations, each class
        weighted by one half over its `share` of the buffer (terminations are rare: a hopper
        episode ends once in hundreds of steps), so both count alike."""
        logit = self.terminal_logit(params, stats, batch.next_obs)
        y = batch.terminated
        weight = jnp.where(y > 0, 0.5 / share, 0.5 / (1.0 - share))
        return jnp.mean(weight * optax.sigmoid_binary_cross_entropy(logit, y))

    def fit_termination(
        self, state: ModelState, buffer: Buffer, key: Array
    ) -> tuple[ModelState, Array]:
        """`config.updates` minibatch Adam steps of the termination classifier on the buffer's
        rows (its next observations and terminations); returns the mean loss."""
        valid = jnp.arange(buffer.capacity) < buffer.size
        count = jnp.maximum(buffer.size, 1).astype(jnp.float32)
        share = jnp.where(valid, buffer.data.terminated, 0.0).sum() / count
        share = jnp.clip(share, 1.0 / (count + 1.0), count / (count + 1.0))

        def update(carry, key: Array):
            params, opt_state = carry
            batch = buffer_sample(buffer, key, self.fitting.batch_size)
            loss, grads = jax.value_and_grad(self.termination_loss)(
                params, state.stats, batch, share
            )
            updates, opt_state = self.optimizer.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), loss

        done = state.termination
        keys = jax.random.split(key, self.fitting.updates)
        (params, opt_state), losses = jax.lax.scan(update, (done.params, done.opt_state), keys)
        loss = losses.mean() if self.fitting.updates else jnp.zeros(())
        return state.replace(termination=Termination(params, opt_state)), loss

    def predict_normalized(
        self, params: dict, stats: Normalizer, obs: Array, action: Array
    ) -> tuple[Array, Array]:
        """The net's own outputs: next obs and reward in normalised units (a probabilistic
        model: its mean)."""
        if self.probabilistic:
            mean, _ = self.predict_gaussian(params, stats, obs, action)
            return mean[..., :-1], mean[..., -1]
        return self.net.apply(params, (obs - stats.obs_mean) / stats.obs_std, action)

    def predict_gaussian(
        self, params: dict, stats: Normalizer, obs: Array, action: Array
    ) -> tuple[Array, Array]:
        """A probabilistic model's mean and log variance over [next obs, reward] in
        normalised units, each `[..., obs_size + 1]`."""
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

    def loss(
        self,
        params: dict,
        batch: Transitions,
        stats: Normalizer | None = None,
        value: Callable[[Array], Array] | None = None,
    ) -> Array:
        """Eq. 2: MSE on the target y = [s', r] (normalised when on), mean over batch and
        output dims. A probabilistic model: `gaussian_nll` of y, plus `BOUND_PENALTY` times
        the gap between its log-variance bounds. With `value` (the critic, `obs [..., D] ->
        [...]`) and `config.value_loss` > 0, plus that weight times the value-equivalence
        term (`ModelConfig.value_loss`)."""
        return self.losses(params, batch, stats, value)[0]

    def losses(
        self,
        params: dict,
        batch: Transitions,
        stats: Normalizer | None = None,
        value: Callable[[Array], Array] | None = None,
    ) -> tuple[Array, Array]:
        """`(loss, fit)`: `loss` as above (with `FitConfig.weight_decay`'s penalty), and `fit`
        the same without the value term."""
        stats = stats if stats is not None else self.init_stats()
        target = self.target(batch, stats)
        if self.probabilistic:
            mean, log_var = self.predict_gaussian(params, stats, batch.obs, batch.action)
            bounds = params["params"]
            gap = bounds["max_log_var"].sum() - bounds["min_log_var"].sum()
            loss = gaussian_nll(mean, log_var, target) + BOUND_PENALTY * gap
        else:
            loss = self.squared_error(params, batch, stats)
        if self.fitting.weight_decay:
            loss = loss + self.fitting.weight_decay * kernel_norm(params)
        if value is None or not self.fitting.value_loss:
            return loss, loss
        return loss + self.fitting.value_loss * self.value_error(params, batch, stats, value), loss

    def value_error(
        self, params: dict, batch: Transitions, stats: Normalizer, value: Callable[[Array], Array]
    ) -> Array:
        """The critic at the (mean) predicted next observation against the critic at the
        real one: mean squared difference over the batch, in units of the real values'
        variance (which, like the real values, takes no gradient)."""
        predicted, _ = self.predict(params, batch.obs, batch.action, stats)
        real = jax.lax.stop_gradient(value(batch.next_obs))
        scale = jax.lax.stop_gradient(jnp.var(real)) + 1e-6
        return jnp.mean(jnp.square(value(predicted) - real)) / scale

    def squared_error(self, params: dict, batch: Transitions, stats: Normalizer) -> Array:
        """Eq. 2's MSE of the (mean) prediction, in normalised units."""
        next_obs, reward = self.predict_normalized(params, stats, batch.obs, batch.action)
        pred = jnp.concatenate([next_obs, reward[..., None]], axis=-1)
        return jnp.mean(jnp.square(pred - self.target(batch, stats)))

    @staticmethod
    def target(batch: Transitions, stats: Normalizer) -> Array:
        """y = [s', r] in normalised units, `[..., obs_size + 1]`."""
        return jnp.concatenate(
            [
                (batch.next_obs - stats.obs_mean) / stats.obs_std,
                ((batch.reward - stats.reward_mean) / stats.reward_std)[..., None],
            ],
            axis=-1,
        )

    def _unbounded(self) -> tuple[Array, Array]:
        inf = jnp.float32(jnp.inf)  # strongly typed, as the fitted box: a chunk keeps its layout
        return jnp.full(self.obs_size, -inf), jnp.full(self.obs_size, inf)

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

    def fit(
        self,
        state: ModelState,
        buffer: Buffer,
        key: Array,
        value: Callable[[Array], Array] | None = None,
    ) -> tuple[ModelState, Array]:
        """`config.updates` minibatch Adam steps on M1; returns the mean loss (`value`: the
        critic of `ModelConfig.value_loss`).

        Ensemble: every member takes its own steps (vmapped), member i drawing its minibatches
        with `jax.random.split(key, E)[i]`; the loss returned, and kept as `error_scale`, is
        the members' mean.
        """
        state = self._refreshed(state, buffer)
        if not self.ensemble:
            params, opt_state, loss = self._fit_one(
                state.params, state.opt_state, state.stats, buffer, key, value
            )
            return state.replace(params=params, opt_state=opt_state), loss
        keys = jax.random.split(key, self.config.ensemble)
        fit = jax.vmap(lambda *a: self._fit_one(*a, value), (0, 0, None, None, 0))
        params, opt_state, losses = fit(state.params, state.opt_state, state.stats, buffer, keys)
        loss = losses.mean()
        if self.probabilistic:
            return self._rank(state.replace(params=params, opt_state=opt_state), buffer, key), loss
        error_scale = loss if self.fitting.updates else state.error_scale
        return state.replace(params=params, opt_state=opt_state, error_scale=error_scale), loss

    def _refreshed(self, state: ModelState, buffer: Buffer) -> ModelState:
        """The normaliser and the support box from the buffer, where used, before a fit."""
        if self.config.normalize:
            state = state.replace(stats=self.buffer_stats(buffer))
        if self.config.support is not None:
            state = state.replace(bounds=self.buffer_bounds(buffer))
        return state

    def fit_until_stalled(
        self, state: ModelState, buffer: Buffer, key: Array, stop: EarlyStop
    ) -> tuple[ModelState, Array, Array]:
        """MBPO's fit of a probabilistic ensemble: epochs of one pass over the training slots
        (their count over the batch size, in minibatches drawn with replacement), each
        member scored after every epoch by its squared error on `HOLDOUT_BATCH` held-out
        transitions drawn once per fit. A member's parameters are
        kept as its best where its error falls by more than `stop.min_gain` of its best;
        the fit ends once no member has for more than `stop.patience` epochs in a row (or
        after `stop.max_epochs`, or at the first epoch that brings its steps to
        `stop.max_steps`), each member back at its best, the elites ranked on those
        errors. Returns the state, the last epoch's mean loss and the epochs taken."""
        if not self.probabilistic:
            raise ValueError("fit_until_stalled fits a probabilistic ensemble")
        state = self._refreshed(state, buffer)
        held = buffer_sample_split(buffer, jax.random.fold_in(key, 1), HOLDOUT_BATCH, True)
        scores = lambda params: jax.vmap(self.squared_error, (0, None, None))(
            params, held, state.stats
        )
        fit = jax.vmap(self._pass, (0, 0, None, None, 0, None))
        members = self.config.ensemble
        # an epoch is a pass over the training slots (MBPO's), in minibatches
        training = jnp.ceil(buffer.size * (1.0 - 1.0 / HOLDOUT_EVERY) / self.fitting.batch_size)
        steps = jnp.maximum(training, 1.0).astype(jnp.int32)

        def epoch(carry):
            count, stalled, params, opt_state, best, best_error, _, key = carry
            key, k_fit = jax.random.split(key)
            params, opt_state, losses = fit(
                params,
                opt_state,
                state.stats,
                buffer,
                jax.random.split(k_fit, members),
                steps,
            )
            error = scores(params)
            gained = error < (1.0 - stop.min_gain) * best_error  # the first epoch: inf
            keep = lambda new, old: jnp.where(
                gained.reshape((members,) + (1,) * (new.ndim - 1)), new, old
            )
            best = jax.tree.map(keep, params, best)
            best_error = jnp.where(gained, error, best_error)
            stalled = jnp.where(gained.any(), 0, stalled + 1)
            return count + 1, stalled, params, opt_state, best, best_error, losses.mean(), key

        capped = lambda count: count * steps < stop.max_steps if stop.max_steps else True
        going = lambda carry: (
            (carry[0] < stop.max_epochs) & (carry[1] <= stop.patience) & capped(carry[0])
        )
        zero = jnp.zeros((), jnp.int32)
        start = (zero, zero, state.params, state.opt_state, state.params)
        start += (jnp.full((members,), jnp.inf), jnp.zeros(()), key)
        count, _, _, opt_state, best, best_error, loss, _ = jax.lax.while_loop(going, epoch, start)
        elites = jnp.argsort(best_error, stable=True)[: self.elite_count].astype(jnp.int32)
        state = state.replace(
            params=best, opt_state=opt_state, elites=elites, error_scale=best_error[elites].mean()
        )
        return state, loss, count

    def _rank(self, state: ModelState, buffer: Buffer, key: Array) -> ModelState:
        """A probabilistic ensemble's elites: the members with the lowest squared error on
        `HOLDOUT_BATCH` held-out transitions; their mean error is the scale disagreement is
        read against (`error_scale`)."""
        held = buffer_sample_split(buffer, jax.random.fold_in(key, 1), HOLDOUT_BATCH, True)
        errors = jax.vmap(self.squared_error, (0, None, None))(state.params, held, state.stats)
        elites = jnp.argsort(errors, stable=True)[: self.elite_count].astype(jnp.int32)
        if not self.fitting.updates:
            return state
        return state.replace(elites=elites, error_scale=errors[elites].mean())

    def _fit_one(
        self,
        params: dict,
        opt_state: optax.OptState,
        stats: Normalizer,
        buffer: Buffer,
        key: Array,
        value: Callable[[Array], Array] | None = None,
    ) -> tuple[dict, optax.OptState, Array]:
        """One model's `config.updates` steps: its new params, Adam state and mean loss (eq.
        2's or the NLL, without the value-equivalence term, which only its gradient takes)."""
        update = self._step(stats, buffer, value)
        keys = jax.random.split(key, self.fitting.updates)
        (params, opt_state), losses = jax.lax.scan(update, (params, opt_state), keys)
        return params, opt_state, losses.mean() if self.fitting.updates else jnp.zeros(())

    def _pass(
        self,
        params: dict,
        opt_state: optax.OptState,
        stats: Normalizer,
        buffer: Buffer,
        key: Array,
        steps: Array,
    ) -> tuple[dict, optax.OptState, Array]:
        """One model's `steps` steps, a count known only when it runs (an epoch of
        `fit_until_stalled`): as `_fit_one`."""
        update = self._step(stats, buffer, None)

        def one(i, carry):
            (params, opt_state), total = carry
            carry, loss = update((params, opt_state), jax.random.fold_in(key, i))
            return carry, total + loss

        start = ((params, opt_state), jnp.zeros(()))
        (params, opt_state), total = jax.lax.fori_loop(0, steps, one, start)
        return params, opt_state, total / jnp.maximum(steps, 1)

    def _step(self, stats: Normalizer, buffer: Buffer, value: Callable | None) -> Callable:
        """`update((params, opt_state), key) -> ((params, opt_state), loss)`: one Adam step
        of one model on a minibatch drawn from `buffer` (from its training slots where the
        held-out ones rank the members)."""

        def update(carry, key: Array):
            params, opt_state = carry
            if self.probabilistic:  # the held-out slots rank the members
                batch = buffer_sample_split(buffer, key, self.fitting.batch_size, False)
            else:
                batch = buffer_sample(buffer, key, self.fitting.batch_size)
            objective = lambda p: self.losses(p, batch, stats, value)
            (_, loss), grads = jax.value_and_grad(objective, has_aux=True)(params)
            updates, opt_state = self.optimizer.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), loss

        return update
