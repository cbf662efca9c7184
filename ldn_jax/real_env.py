"""The real env as the stages see it: its W workers' resets and steps, the world a `Player`
plays in, the real step from imagined observations (the oracle stop and `model.world`
"true"), its exact reward, and the greedy policy's evaluation."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from ldn_jax import envs
from ldn_jax.config import Config

Array = jax.Array


class RealEnv:
    """One config's env and its parameters (backend and step limit resolved); holds no
    state, so one instance serves every seed, K and sweep point."""

    def __init__(self, config: Config):
        self.env, params = envs.make(config.env)
        self.params = self.env.with_backend(params, config.backend)
        if config.max_steps is not None:
            self.params = self.params.replace(max_steps=config.max_steps)
        self.workers = config.workers
        self.obs_size = self.env.observation_size(self.params)
        self.action_spec = self.env.action_spec(self.params)
        self.max_steps = self.params.max_steps

    def reset(self, key: Array, count: int | None = None) -> tuple[Array, object]:
        """`count` (default: one per worker) fresh starts."""
        keys = jax.random.split(key, count or self.workers)
        return jax.vmap(self.env.reset, (0, None))(keys, self.params)

    def step_workers(self, keys: Array, world, action: Array, alive: Array) -> tuple:
        """The env's step, vmapped over workers: every worker steps and `alive` decides what
        counts; an env with `step_active` skips the physics of the workers not alive."""
        if hasattr(self.env, "step_active"):
            step = jax.vmap(self.env.step_active, (0, 0, 0, None, 0))
            return step(keys, world, action, self.params, alive)
        return jax.vmap(self.env.step, (0, 0, 0, None))(keys, world, action, self.params)

    def world(self, key: Array, world, obs: Array, action: Array, alive: Array):
        """The real env as a `rollout.WorldStep`."""
        keys = jax.random.split(key, action.shape[0])
        next_obs, world, reward, terminated, truncated, _ = self.step_workers(
            keys, world, action, alive
        )
        return next_obs, world, reward, terminated, truncated, {}

    def is_terminal(self, obs: Array) -> Array:
        return self.env.is_terminal(obs, self.params)

    def true_step(self, key: Array, obs: Array, action: Array) -> tuple[Array, Array, Array]:
        """The real env stepped from imagined observations `[W, d]`: next observations,
        rewards and terminations (the oracle stop, `model.world` "true")."""
        states = jax.vmap(self.env.from_observation, (0, None))(obs, self.params)
        keys = jax.random.split(key, obs.shape[0])
        step = jax.vmap(self.env.step, (0, 0, 0, None))
        next_obs, _, reward, terminated, _, _ = step(keys, states, action, self.params)
        return next_obs, reward, terminated

    def true_next(self, key: Array, obs: Array, action: Array) -> Array:
        """The real env's next observations from imagined ones, `[W, d]` (the oracle stop)."""
        return self.true_step(key, obs, action)[0]

    def exact_reward(self, wanted: bool) -> Callable | None:
        """The env's exact reward `(obs, action, next_obs) -> [...]` where `wanted`
        (`model.env_reward`) and the env has one; None otherwise."""
        if not (wanted and self.env.exact_reward(self.params)):
            return None
        return lambda obs, action, next_obs: self.env.reward(obs, action, next_obs, self.params)

    def evaluate(self, act: Callable[[Array], Array], key: Array, episodes: int) -> Array:
        """Mean return of the policy `act(obs [n, d]) -> actions` over `episodes` episodes."""
        n = episodes
        obs, env_state = self.reset(key, n)

        def body(carry, key):
            obs, env_state, alive, total = carry
            action = act(obs)
            obs, env_state, reward, terminated, truncated, _ = self.step_workers(
                jax.random.split(key, n), env_state, action, alive
            )
            total = total + reward * alive
            alive = alive & ~(terminated | truncated)
            return (obs, env_state, alive, total), None

        # A fresh key per env step (the resets keep `key`'s split, as before).
        step_keys = jax.random.split(jax.random.fold_in(key, 1), self.max_steps)
        init = (jnp.int32(0), obs, env_state, jnp.ones((n,), bool), jnp.zeros((n,)))
        # Until every episode has ended (early policies fall within tens of steps); the
        # steps after an episode's end would add nothing.
        playing = lambda carry: (carry[0] < self.max_steps) & carry[3].any()
        step_on = lambda carry: (carry[0] + 1, *body(carry[1:], step_keys[carry[0]])[0])
        total = jax.lax.while_loop(playing, step_on, init)[-1]
        return total.mean()
