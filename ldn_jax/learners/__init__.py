"""Learners: loss + update on a batch of (possibly masked) transitions.

Every learner is an `ActorCritic` with `update(state, segment, key) -> (state, losses)`;
the training loop calls it after each segment of n steps, real or imagined.
"""

from ldn_jax.learners.a2c import A2C
from ldn_jax.learners.base import ActorCritic
from ldn_jax.learners.ppo import PPO
from ldn_jax.learners.sac import SACLearner

LEARNERS: dict[str, type] = {"a2c": A2C, "ppo": PPO, "sac": SACLearner}

__all__ = ["A2C", "LEARNERS", "PPO", "ActorCritic", "SACLearner"]
