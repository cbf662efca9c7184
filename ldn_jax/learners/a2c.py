"""Synchronous A3C (A2C): n-step advantage actor-critic with an entropy bonus.

The workers' gradients are averaged (`worker_mean`), which is what A3C's asynchronous
pushes to one global network become when the workers step in lockstep.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from ldn_jax.config import AgentConfig
from ldn_jax.learners.base import LearnerState, Segment, keep_if_any, masked_obs, worker_mean
from ldn_jax.networks import MLP

Array = jax.Array


def n_step_targets(
    reward: Array, next_value: Array, terminated: Array, done: Array, gamma: float
) -> Array:
    """Value targets of one segment, `[n, W] -> [n, W]`.

    G_t = r_t + gamma * (1 - terminated_t) * (V(s'_t) if done_t or t is last else G_{t+1}):
    the segment's last step and every truncation bootstrap from the critic; a terminal
    transition does not.
    """

    def backward(carry, step):
        reward, next_value, terminated, done = step
        follow = jnp.where(done, next_value, carry)
        target = reward + gamma * (1.0 - terminated) * follow
        return target, target

    steps = (reward, next_value, terminated.astype(reward.dtype), done)
    _, targets = jax.lax.scan(backward, next_value[-1], steps, reverse=True)
    return targets


class A2C:
    """Pure functions over `LearnerState` for one env's sizes; holds no state."""

    def __init__(self, config: AgentConfig, obs_size: int, n_actions: int):
        self.config = config
        self.obs_size = obs_size
        self.n_actions = n_actions
        mlp = lambda hidden, out: MLP(hidden, out, config.activation, config.init_std)
        self.actor = mlp(config.actor_hidden, n_actions)
        self.critic = mlp(config.critic_hidden, 1)
        rmsprop = lambda lr: optax.rmsprop(
            lr,
            decay=config.rmsprop_decay,
            eps=config.rmsprop_eps,
            initial_scale=1.0,  # TensorFlow 1's RMSProp starts its average at one
        )
        self.optimizer = optax.multi_transform(
            {"actor": rmsprop(config.actor_lr), "critic": rmsprop(config.critic_lr)},
            {"actor": "actor", "critic": "critic"},
        )

    def init(self, key: Array) -> LearnerState:
        k_actor, k_critic = jax.random.split(key)
        dummy = jnp.zeros((1, self.obs_size))
        params = {
            "actor": self.actor.init(k_actor, dummy),
            "critic": self.critic.init(k_critic, dummy),
        }
        return LearnerState(params=params, opt_state=self.optimizer.init(params))

    def logits(self, params: dict, obs: Array) -> Array:
        return self.actor.apply(params["actor"], obs)

    def value(self, params: dict, obs: Array) -> Array:
        return self.critic.apply(params["critic"], obs)[..., 0]

    def act(self, params: dict, key: Array, obs: Array) -> Array:
        """Sample from the softmax policy, `[W, obs] -> [W]`."""
        return jax.random.categorical(key, self.logits(params, obs))

    def greedy(self, params: dict, obs: Array) -> Array:
        return jnp.argmax(self.logits(params, obs), axis=-1)

    def loss(self, params: dict, segment: Segment) -> tuple[Array, dict]:
        cfg = self.config
        weight = segment.weight
        obs = masked_obs(segment.obs, weight)
        next_obs = masked_obs(segment.next_obs, weight)
        reward = segment.reward
        if cfg.terminal_reward is not None:
            reward = jnp.where(segment.terminated, cfg.terminal_reward, reward)
        next_value = jax.lax.stop_gradient(self.value(params, next_obs))
        targets = n_step_targets(reward, next_value, segment.terminated, segment.done, cfg.gamma)
        value = self.value(params, obs)
        advantage = targets - value
        log_probs = jax.nn.log_softmax(self.logits(params, obs))
        log_prob = jnp.take_along_axis(log_probs, segment.action[..., None], axis=-1)[..., 0]
        entropy = -jnp.sum(jnp.exp(log_probs) * log_probs, axis=-1)
        critic_loss = worker_mean(jnp.square(advantage), weight)
        policy_loss = -worker_mean(log_prob * jax.lax.stop_gradient(advantage), weight)
        entropy_mean = worker_mean(entropy, weight)
        total = policy_loss - cfg.entropy_beta * entropy_mean + critic_loss
        return total, {
            "actor_loss": policy_loss,
            "critic_loss": critic_loss,
            "entropy": entropy_mean,
        }

    def update(self, state: LearnerState, segment: Segment) -> tuple[LearnerState, dict]:
        """One RMSProp step on a segment; a fully masked segment leaves `state` unchanged."""
        grads, info = jax.grad(self.loss, has_aux=True)(state.params, segment)
        updates, opt_state = self.optimizer.update(grads, state.opt_state, state.params)
        new = LearnerState(optax.apply_updates(state.params, updates), opt_state)
        return keep_if_any(new, state, segment.weight), info
