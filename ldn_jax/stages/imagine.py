"""Imagined episodes from the env's initial states (Algorithm 1, line 17), two stages by
where their rows go: `episodes` (the learner updates on every n imagined steps, as on real
ones; `imagine.mode` "episodes" or "batch") and `memory` (the rows go to the imaginary
memory I, and PPO learns once a whole rollout's worth is there; "memory"). Also the model
as a world (`world_of`), which the branches stage plays in too."""

from __future__ import annotations

import jax

from ldn_jax.imagination import (
    EnvFacts,
    imagined_steps_limit,
    ld_history,
    model_world,
    stop_rule,
)
from ldn_jax.rollout import Batch, Episodes, Player, WorldStep, play_batch, play_episodes
from ldn_jax.stages.parts import Parts, RealPlay, TrainState

Array = jax.Array

IMAGINED_STARTS = 16
"""Under `ImagineConfig.mode = "batch"`, imagined episodes start from a pool of this many
fresh env starts per worker, drawn once per iteration (a MuJoCo reset is a call to the
engine, too dear for every imagined step); each episode picks one at random."""


def world_of(
    parts: Parts, state: TrainState, gain: Array, threshold: Array | None = None
) -> WorldStep:
    """M1 as a world for imagined play, stopped by the run's rule (`threshold`: the macura
    rule's)."""
    config, real = parts.config, parts.real
    rule = config.stop_rule
    world = config.model.world
    is_terminal = real.is_terminal
    if config.imagine.termination == "learned":
        is_terminal = lambda obs: parts.dynamics.is_terminal(state.model, obs)
    facts = EnvFacts(
        is_terminal=is_terminal,
        model_action=parts.model_action,
        env_reward=real.exact_reward(config.model.env_reward),
        true_step=None if world == "model" else real.true_step,
        true_state=world in ("true", "true-state"),
        true_reward=world in ("true", "true-reward"),
    )
    true_next = real.true_next if rule == "oracle" else None
    stop = stop_rule(config.stop, rule, true_next, threshold)
    return model_world(parts.dynamics, state.model, facts, gain, stop)


def episodes(
    parts: Parts, state: TrainState, key: Array, gain: Array, real: RealPlay
) -> tuple[TrainState, Episodes]:
    """Imagined episodes in M1 from fresh initial states, the learner updating on them as
    it plays."""
    k_reset, k_play = jax.random.split(key)
    learner, imagined = _play(parts, state, (k_reset, k_play), gain, real, learn=True)
    return state.replace(learner=learner), imagined


def memory(
    parts: Parts, state: TrainState, key: Array, gain: Array, real: RealPlay
) -> tuple[TrainState, Episodes]:
    """The same episodes played without learning; their rows go to the imaginary memory,
    from which PPO learns each full rollout's worth (n_steps x workers rows)."""
    k_reset, k_play = jax.random.split(key)
    k_play, k_learn = jax.random.split(k_play)
    learner, imagined = _play(parts, state, (k_reset, k_play), gain, real, learn=False)
    learner, kept, losses = parts.learner.learn_from_memory(
        learner, state.memory, imagined.steps, k_learn
    )
    return state.replace(learner=learner, memory=kept), imagined.replace(losses=losses)


def _play(parts: Parts, state: TrainState, keys: tuple, gain: Array, real: RealPlay, learn: bool):
    """One imagined episode per worker from a fresh start; or (`imagine.mode` "batch", or
    schedule "steps": worker w imagines `real.quota[w]` episodes, one per real episode it
    ended, within as many steps as it took real ones) episodes back to back from a pool of
    fresh starts."""
    config = parts.config
    k_reset, k_play = keys
    quota = real.quota if config.imagine.mode != "batch" else None
    history = ld_history(parts.dynamics, config.workers)  # the LD window's start
    batch = None
    if config.imagine.mode == "batch" or quota is not None:
        starts, _ = parts.real.reset(k_reset, IMAGINED_STARTS * config.workers)
        obs = starts[: config.workers]
        pick = lambda key: starts[jax.random.randint(key, obs.shape[:1], 0, len(starts))]
        segments = None
        if quota is not None:
            segments = config.steps_per_iteration // config.agent.n_steps
        batch = Batch(reset=lambda key: (pick(key), history), quota=quota, segments=segments)
    else:
        obs, _ = parts.real.reset(k_reset)
    world = world_of(parts, state, gain)
    limit = imagined_steps_limit(config.stop, config.stop_rule, parts.real.max_steps)
    player = Player(parts.learner, world, limit, learn=learn)
    if batch is None:
        return play_episodes(k_play, state.learner, player, obs, history)
    return play_batch(k_play, state.learner, player, (obs, history), batch)
