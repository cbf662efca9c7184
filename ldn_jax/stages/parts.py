"""What the stages share: the run's state (`TrainState`), the built pieces of one config
(`Parts`: the env, the learner, the model) and what real play hands the later stages
(`RealPlay`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
from flax import struct

from ldn_jax.buffer import Buffer
from ldn_jax.config import Config
from ldn_jax.dynamics import Dynamics, ModelState, action_encoder
from ldn_jax.learners import LEARNERS
from ldn_jax.learners.base import LearnerState
from ldn_jax.learners.ppo import Memory
from ldn_jax.real_env import RealEnv
from ldn_jax.rollout import Episodes, Workers

Array = jax.Array


@struct.dataclass
class TrainState:
    """Everything one seed x K run carries from one iteration to the next."""

    learner: LearnerState
    model: ModelState | None
    """M1, frozen M0 and M1's optimiser (each `[E, ...]` for an ensemble); None for model-free
    algorithms."""
    buffer: Buffer | None
    """Real transitions for fitting M1; None for model-free algorithms."""
    memory: Memory | None
    """The imaginary memory I of `ImagineConfig.mode = "memory"` (PPO rows waiting for a
    full batch); None otherwise."""
    workers: Workers | None
    """The real env's workers mid-episode (`Config.schedule = "steps"`); None otherwise."""
    moving_return: Array
    """NaN until the first episode completes."""
    episodes: Array
    env_steps: Array
    imagined_steps: Array
    iteration: Array
    key: Array
    failure: Array
    """0 while every quantity is finite; else the `guard.FAILURES` bits of what first became
    non-finite. A failed run is frozen at its last finite state."""
    failed_iteration: Array
    """The iteration whose result was non-finite (0 if none)."""
    greedy_return: Array | None = None
    """The greedy policy's mean return at its latest evaluation, after each chunk (NaN
    before the first); None without `Config.solved_return`."""


@dataclass(frozen=True)
class Parts:
    """The pieces one config builds: pure functions and shapes, no training state."""

    config: Config
    real: RealEnv
    learner: Any
    """The learner (`ldn_jax.learners`)."""
    dynamics: Dynamics | None
    """The model; None for a model-free algorithm."""
    model_action: Callable[[Array], Array]
    """Encodes the env action as the model takes it (`dynamics.action_encoder`)."""
    model_action_size: int

    @classmethod
    def build(cls, config: Config, real: RealEnv | None = None) -> Parts:
        """The parts of `config`; `real` shares another's env (a sweep point's)."""
        real = real or RealEnv(config)
        learner = LEARNERS[config.algorithm.learner].of(config, real.obs_size, real.action_spec)
        encode, size = action_encoder(
            config.model.action_encoding, learner.policy, real.action_spec
        )
        dynamics = None
        if config.algorithm.uses_model:
            termination = config.imagine.termination
            dynamics = Dynamics(config.model, real.obs_size, size, termination, config.fit)
        return cls(config, real, learner, dynamics, encode, size)


@struct.dataclass
class RealPlay:
    """What an iteration's real play hands the later stages."""

    episodes: Episodes
    """Every real step, `[T, W, ...]`."""
    returns: Array
    """The returns of the episodes that ended, in completion order (valid where `ended`)."""
    lengths: Array
    ended: Array
    count: Array | int
    """How many episodes ended."""
    episode_return: Array
    """Their mean return (NaN where none ended)."""
    extra: dict
    """Metrics of schedule "steps": which rows ended an episode and at which real step."""
    quota: Array | None = None
    """Schedule "steps": `[W]`, the episodes each worker ended (each imagines as many)."""
