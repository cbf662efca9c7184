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
    n_actions: int,
    k: Array,
    ld_stop: bool,
) -> WorldStep:
    """A world that steps M1. Its extras carry each step's learning degree `ld`."""

    def step(key: Array, world: None, obs: Array, action: Array):
        onehot = jax.nn.one_hot(action, n_actions)
        next_obs, reward = dynamics.predict(model.params, obs, onehot)
        next_obs_m0, reward_m0 = dynamics.predict(model.frozen, obs, onehot)
        sigma2 = deviation(
            jnp.concatenate([next_obs, reward[..., None]], axis=-1),
            jnp.concatenate([next_obs_m0, reward_m0[..., None]], axis=-1),
        )
        ld = learning_degree(sigma2, k)
        if ld_stop:
            stop = stop_draw(key, stop_probability(sigma2, k))
        else:
            stop = jnp.zeros_like(ld, bool)
        terminated = is_terminal(next_obs)
        return next_obs, world, reward, terminated, stop, {"ld": ld}

    return step
