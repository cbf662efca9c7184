"""Imagined episodes: the agent acts in M1, and the learning degree decides when to stop.

Predicted termination (the env's own termination test on M1's predicted observation) ends
an imagined episode as terminal: no bootstrap. The LD draw ends it as a truncation: the critic
bootstraps, since the episode itself had not ended.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from ldn_jax.dynamics import Dynamics, ModelState
from ldn_jax.learning_degree import deviation, learning_degree, stop_draw, stop_probability
from ldn_jax.rollout import WorldStep

Array = jax.Array


def model_world(
    dynamics: Dynamics,
    model: ModelState,
    is_terminal: Any,
    model_action: Any,
    env_reward: Any,
    k: Array,
    ld_stop: bool,
) -> WorldStep:
    """A world that steps M1. Its extras carry each step's learning degree `ld`.

    `env_reward(obs, action, next_obs)`, if not None, replaces the model's reward (the LD
    still compares both models' whole output). `model_action` encodes the env action as the
    model takes it (one-hot, or the clipped vector). The deviation of eq. 3 is taken in the
    model's normalised output space (the raw one when normalisation is off), so no
    observation dimension dominates it by its units.
    """

    def step(key: Array, world: None, obs: Array, action: Array):
        encoded = model_action(action)
        m1 = dynamics.predict_normalized(model.params, model.stats, obs, encoded)
        m0 = dynamics.predict_normalized(model.frozen, model.stats, obs, encoded)
        next_obs, reward = dynamics.denormalize(model.stats, *m1)
        if env_reward is not None:
            reward = env_reward(obs, action, next_obs)
        sigma2 = deviation(
            jnp.concatenate([m1[0], m1[1][..., None]], axis=-1),
            jnp.concatenate([m0[0], m0[1][..., None]], axis=-1),
        )
        ld = learning_degree(sigma2, k)
        if ld_stop:
            stop = stop_draw(key, stop_probability(sigma2, k))
        else:
            stop = jnp.zeros_like(ld, bool)
        terminated = is_terminal(next_obs)
        return next_obs, world, reward, terminated, stop, {"ld": ld}

    return step
