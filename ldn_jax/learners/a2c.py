"""Synchronous A3C (A2C): n-step advantage actor-critic with an entropy bonus.

The workers' gradients are averaged (`worker_mean`), which is what A3C's asynchronous
pushes to one global network become when the workers step in lockstep.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from ldn_jax.config import AgentConfig
from ldn_jax.learners.base import (
    ActorCritic,
    LearnerState,
    Segment,
    canonical,
    keep_if_any,
    worker_mean,
)

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


class A2C(ActorCritic):
    """One RMSProp step per segment on the n-step actor-critic loss."""

    def __init__(self, config: AgentConfig, obs_size: int, action_spec, workers: int = 1):
        super().__init__(config, obs_size, action_spec, workers)
        # Hyperparameters injected into the optimiser state are arrays, so a learning rate
        # can differ between vmapped runs.
        rmsprop = lambda lr: optax.inject_hyperparams(optax.rmsprop)(
            learning_rate=lr,
            decay=config.rmsprop_decay,
            eps=config.rmsprop_eps,
            initial_scale=1.0,  # TensorFlow 1's RMSProp starts its average at one
        )
        self.optimizer = self.per_net(rmsprop(config.actor_lr), rmsprop(config.critic_lr))

    def loss(self, params: dict, segment: Segment) -> tuple[Array, dict]:
        """The A3C loss of a canonical segment (masked steps zeroed), averaged over workers."""
        cfg = self.config
        weight = segment.weight
        next_value = jax.lax.stop_gradient(self.value(params, segment.next_obs))
        targets = n_step_targets(
            self.training_reward(params, segment),
            next_value,
            segment.terminated,
            segment.done,
            cfg.gamma,
        )
        advantage = targets - self.value(params, segment.obs)
        log_prob, entropy = self.log_prob_entropy(params, segment.obs, segment.action)
        critic_loss = worker_mean(jnp.square(advantage), weight)
        policy_loss = -worker_mean(log_prob * jax.lax.stop_gradient(advantage), weight)
        entropy_mean = worker_mean(entropy, weight)
        total = policy_loss - cfg.entropy_beta * entropy_mean + critic_loss
        return total, {
            "actor_loss": policy_loss,
            "critic_loss": critic_loss,
            "entropy": entropy_mean,
        }

    def update(
        self, state: LearnerState, segment: Segment, key: Array | None = None
    ) -> tuple[LearnerState, dict]:
        """One RMSProp step on a segment; a fully masked segment leaves `state` unchanged.

        `key` is unused (the update is deterministic); it is there for the common interface.
        """
        segment = canonical(segment)
        grads, info = jax.grad(self.loss, has_aux=True)(state.params, segment)
        new = self.apply_gradients(state, grads)
        return keep_if_any(new, state, segment.weight), info
