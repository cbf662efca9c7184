"""Imagined episodes: the agent acts in M1, and the learning degree decides when to stop.

Predicted termination (the env's own termination test on M1's predicted observation) ends
an imagined episode as terminal: no bootstrap. The LD draw ends it as a truncation: the critic
bootstraps, since the episode itself had not ended.

With an ensemble (`ModelConfig.ld = "ensemble"`) the world steps the members' mean prediction
and the LD comes from their disagreement instead of from M1 vs M0.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from ldn_jax.config import LD_ESTIMATORS
from ldn_jax.dynamics import Dynamics, ModelState
from ldn_jax.learning_degree import (
    deviation,
    disagreement,
    ensemble_learning_degree,
    ensemble_mean,
    ensemble_stop_probability,
    learning_degree,
    relative_disagreement,
    stop_draw,
    stop_probability,
    windowed,
)
from ldn_jax.rollout import WorldStep

Array = jax.Array


def model_world(
    dynamics: Dynamics,
    model: ModelState,
    is_terminal: Any,
    model_action: Any,
    env_reward: Any,
    gain: Array,
    ld_stop: bool,
) -> WorldStep:
    """A world that steps M1 (an ensemble: its members' mean prediction). Its extras carry
    each step's learning degree `ld`.

    `env_reward(obs, action, next_obs)`, if not None, replaces the model's reward (the LD
    still reads the models' whole output). `model_action` encodes the env action as the
    model takes it (one-hot, or the clipped vector). The deviation of eq. 3 is taken in the
    model's normalised output space (the raw one when normalisation is off), so no
    observation dimension dominates it by its units; so is an ensemble's disagreement.
    A prediction outside the real data's box (`ModelConfig.support`) stops the episode as
    the LD draw does; extras then carry `outside`, the steps it stopped that way.

    The world's state is the window of the last `ld_window - 1` deviations of each worker's
    episode (`ld_history`; None for a window of 1), zeros at an episode's start. The
    deviation is scaled by `ld_scale` before the window and K.
    """
    estimate, degree = LD_ESTIMATES[dynamics.config.ld]
    scale = dynamics.config.ld_scale

    def step(key: Array, world: Array | None, obs: Array, action: Array):
        encoded = model_action(action)
        predicted, statistic = estimate(dynamics, model, obs, encoded)
        statistic, world = windowed(scale * statistic, world)
        ld, p_stop = degree(statistic, gain)
        next_obs, reward = dynamics.denormalize(model.stats, *predicted)
        if env_reward is not None:
            reward = env_reward(obs, action, next_obs)
        stop = stop_draw(key, p_stop) if ld_stop else jnp.zeros_like(ld, bool)
        outside = ~dynamics.within_bounds(model, next_obs)
        terminated = is_terminal(next_obs)
        extras = {"ld": ld}
        if model.bounds is not None:
            extras["outside"] = outside & ~terminated
        return next_obs, world, reward, terminated, stop | outside, extras

    return step


def ld_history(dynamics: Dynamics, workers: int) -> Array | None:
    """The model world's state at an episode's start: `ld_window - 1` zeros per worker (no
    steps taken yet), or None for a window of 1."""
    window = dynamics.config.ld_window
    return None if window == 1 else jnp.zeros((workers, window - 1), jnp.float32)


def _m0_estimate(dynamics: Dynamics, model: ModelState, obs: Array, action: Array):
    """M1's normalised prediction, and eq. 3's sigma2 of M1 vs M0."""
    m1 = dynamics.predict_normalized(model.params, model.stats, obs, action)
    m0 = dynamics.predict_normalized(model.frozen, model.stats, obs, action)
    return m1, deviation(_joined(*m1), _joined(*m0), dynamics.config.ld_reduce)


def _m0_degree(sigma2: Array, gain: Array):
    """LD and P(stop) of eq. 4-6."""
    return learning_degree(sigma2, gain), stop_probability(sigma2, gain)


def _ensemble_estimate(dynamics: Dynamics, model: ModelState, obs: Array, action: Array):
    """The members' mean normalised prediction, and their disagreement relative to their
    fit error."""
    members = _joined(*dynamics.predict_members(model.params, model.stats, obs, action))
    mean = ensemble_mean(members)
    d = disagreement(members, dynamics.config.ld_reduce)
    predicted = (mean[..., :-1], mean[..., -1])
    return predicted, relative_disagreement(d, model.error_scale)


def _ensemble_degree(d_rel: Array, gain: Array):
    return ensemble_learning_degree(d_rel, gain), ensemble_stop_probability(d_rel, gain)


LD_ESTIMATES = {
    "m0": (_m0_estimate, _m0_degree),
    "ensemble": (_ensemble_estimate, _ensemble_degree),
}
"""`ModelConfig.ld` -> `(estimate, degree)`: `estimate(dynamics, model, obs, action) ->
(prediction, deviation)` and `degree(deviation, gain) -> (LD, P(stop))`, the deviation
scaled and windowed between them (`model_world`): the learning-degree estimators, as
`LEARNERS` holds the learners. A new estimator is a pair here and its name in
`ldn_jax.config.LD_ESTIMATORS`."""
assert tuple(LD_ESTIMATES) == LD_ESTIMATORS, "estimators and their config names disagree"


def _joined(next_obs: Array, reward: Array) -> Array:
    """The model's output as eq. 2 and 3 see it: `[..., D], [...] -> [..., D + 1]`."""
    return jnp.concatenate([next_obs, reward[..., None]], axis=-1)
