"""Real play, one stage per schedule (`Config.schedule`): `episodes` (each worker one whole
episode from a fresh start, Algorithm 1 read literally) and `steps` (each worker
`iteration_steps` steps from where it stands, episodes carrying over)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ldn_jax.rollout import Player, play_episodes, play_steps
from ldn_jax.stages.parts import Parts, RealPlay, TrainState

Array = jax.Array


def episodes(parts: Parts, state: TrainState, key: Array) -> tuple[TrainState, RealPlay]:
    """One real episode per worker from fresh starts; the learner updates every n steps."""
    k_reset, k_play = jax.random.split(key)
    obs, env_state = parts.real.reset(k_reset)
    player = Player(parts.learner, parts.real.world, parts.real.max_steps, observe=True)
    learner, played = play_episodes(k_play, state.learner, player, obs, env_state)
    # The moving return advances over episodes in completion order (shorter first, ties by
    # worker), as the paper's global counter sees them.
    order = jnp.argsort(played.lengths, stable=True)
    returns, lengths = played.returns[order], played.lengths[order]
    real = RealPlay(
        episodes=played,
        returns=returns,
        lengths=lengths,
        ended=jnp.ones(returns.shape, bool),
        count=parts.config.workers,
        episode_return=played.returns.mean(),
        extra={},
    )
    return state.replace(learner=learner), real


def steps(parts: Parts, state: TrainState, key: Array) -> tuple[TrainState, RealPlay]:
    """`config.steps_per_iteration` real steps per worker from where the workers stand."""
    config = parts.config
    segments = config.steps_per_iteration // config.agent.n_steps
    player = Player(parts.learner, parts.real.world, parts.real.max_steps, observe=True)
    learner, played, completed, workers = play_steps(
        key, state.learner, player, state.workers, segments, parts.real.reset
    )
    state = state.replace(learner=learner, workers=workers)
    # Completion order is (step, worker): flattened row-major.
    ended = completed.ended.reshape(-1)
    returns, lengths = completed.returns.reshape(-1), completed.lengths.reshape(-1)
    at_step = jnp.arange(1, completed.ended.shape[0] + 1, dtype=jnp.int32) * config.workers
    count = ended.sum()
    real = RealPlay(
        episodes=played,
        returns=returns,
        lengths=lengths,
        ended=ended,
        count=count,
        episode_return=jnp.where(count > 0, returns.sum() / jnp.maximum(count, 1), jnp.nan),
        extra={"ended": ended, "steps_at": jnp.repeat(state.env_steps + at_step, config.workers)},
        quota=completed.ended.sum(axis=0),
    )
    return state, real
