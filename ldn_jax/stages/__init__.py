"""The stages one training iteration composes, each a function of (parts, state, key, ...)
that reads only the config section it uses:

- real play, by schedule: `real.episodes` (Algorithm 1 read literally) or `real.steps`;
- the model's fit: `model.fit`;
- imagination, by where it starts and where its rows go: `imagine.episodes` (from initial
  states, learnt from as played: the paper), `imagine.memory` (the same, into PPO's
  imaginary memory), `branch.branches` (short rollouts from real states, learnt from as
  played) or `branch.remembered` (the same, into an off-policy learner's model memory);
- the failure guard: `guard.guarded`.

`ldn_jax.trainer.Trainer` picks them once, when it is built (`pick`); `Parts` holds what they
share (the env, the learner, the model), `TrainState` what a run carries.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ldn_jax.config import Config
from ldn_jax.stages import branch, imagine, real
from ldn_jax.stages.parts import Parts, RealPlay, TrainState

__all__ = ["Parts", "RealPlay", "Stages", "TrainState", "pick"]


@dataclass(frozen=True)
class Stages:
    """The stages of one config's iteration."""

    real: Callable
    """`(parts, state, key) -> (state, RealPlay)`."""
    imagine: Callable | None
    """`(parts, state, key, gain, real) -> (state, imagined Episodes)`; None for a
    model-free algorithm (no model stage either)."""


def pick(config: Config) -> Stages:
    """The stages `config` runs."""
    play = real.steps if config.schedule == "steps" else real.episodes
    if not config.algorithm.uses_model:
        return Stages(play, None)
    if config.imagine.start == "real":
        off_policy = config.algorithm.learner == "sac"
        return Stages(play, branch.remembered if off_policy else branch.branches)
    return Stages(play, imagine.memory if config.imagine.mode == "memory" else imagine.episodes)
