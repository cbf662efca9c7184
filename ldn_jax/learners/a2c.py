"""Synchronous A3C (A2C): n-step advantage actor-critic with an entropy bonus.

The workers' gradients are averaged (`worker_mean`), which is what A3C's asynchronous
pushes to one global network become when the workers step in lockstep.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from ldn_jax.config import A2CConfig, AgentConfig, Config
from ldn_jax.learners.base import (
    ActorCritic,
    LearnerState,
    Segment,
    canonical,
    gae,
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

    def __init__(
        self,
        config: AgentConfig,
        obs_size: int,
        action_spec,
        workers: int = 1,
        a2c: A2CConfig | None = None,
    ):
        """`a2c`: the family's own constants (None: the paper's); the rest as
        `ActorCritic`'s."""
        super().__init__(config, obs_size, action_spec, workers)
        self.a2c = a2c = a2c or A2CConfig()
        torch = a2c.rmsprop == "torch"
        # Hyperparameters injected into the optimiser state are arrays, so a learning rate
        # can differ between vmapped runs.
        rmsprop = lambda lr: optax.inject_hyperparams(optax.rmsprop)(
            learning_rate=lr,
            decay=config.rmsprop_decay,
            eps=config.rmsprop_eps,
            # TensorFlow 1's RMSProp starts its average at one, eps inside the root;
            # PyTorch's at zero, eps added to the root
            initial_scale=0.0 if torch else 1.0,
            eps_in_sqrt=not torch,
        )
        self.optimizer = self.per_net(rmsprop(config.actor_lr), rmsprop(config.critic_lr))
        if a2c.max_grad_norm is not None:
            self.optimizer = optax.chain(
                optax.clip_by_global_norm(a2c.max_grad_norm), self.optimizer
            )

    @classmethod
    def of(cls, config: Config, obs_size: int, action_spec) -> A2C:
        return cls(config.agent, obs_size, action_spec, config.workers, config.a2c)

    def advantage(self, params: dict, segment: Segment) -> Array:
        """The advantages of a canonical segment, `[n, W]`: n-step targets minus V(s), or
        GAE's under `a2c.gae_lambda` < 1. Only V(s) carries a gradient (the critic's)."""
        cfg = self.config
        reward = self.training_reward(params, segment)
        next_value = jax.lax.stop_gradient(self.value(params, segment.next_obs))
        value = self.value(params, segment.obs)
        lam = self.a2c.gae_lambda
        # a swept lambda is traced: every point then takes GAE's form (at 1, the same returns)
        if isinstance(lam, int | float) and lam == 1.0:
            targets = n_step_targets(
                reward, next_value, segment.terminated, segment.done, cfg.gamma
            )
            return targets - value
        estimates = gae(
            reward,
            jax.lax.stop_gradient(value),
            next_value,
            segment.terminated,
            segment.done,
            (cfg.gamma, lam),
        )
        return jax.lax.stop_gradient(estimates + value) - value

    def loss(self, params: dict, segment: Segment) -> tuple[Array, dict]:
        """The A3C loss of a canonical segment (masked steps zeroed), averaged over workers."""
        cfg = self.config
        weight = segment.weight
        advantage = self.advantage(params, segment)
        log_prob, entropy = self.log_prob_entropy(params, segment.obs, segment.action)
        critic_loss = worker_mean(jnp.square(advantage), weight)
        policy_loss = -worker_mean(log_prob * jax.lax.stop_gradient(advantage), weight)
        entropy_mean = worker_mean(entropy, weight)
        total = policy_loss - cfg.entropy_beta * entropy_mean + self.a2c.value_coef * critic_loss
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
