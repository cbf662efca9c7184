"""Trained policies for use outside JAX."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from ldn_jax.run_dir import RunDir
from ldn_jax.train import Trainer


def load_policy(
    run_dir: str | Path, seed: int = 0, k: float | None = None
) -> Callable[[np.ndarray], int | np.ndarray]:
    """The greedy policy of one seed and K of a finished run.

    Returns `act(obs)`: a numpy observation in; out a Python int (discrete actions) or a
    float32 numpy array within the action bounds (continuous: the Gaussian's mean).
    `k=None` picks the run's only K, or its first one.
    """
    run = RunDir(run_dir)
    config = run.read_config()
    if not 0 <= seed < config.seeds:
        raise ValueError(f"seed {seed} not in this run (it has seeds 0..{config.seeds - 1})")
    k_index = 0 if k is None else _index_of(config.k, k)
    trainer = Trainer(config)
    like = jax.eval_shape(trainer.init_batch)
    state = run.restore_final(like)
    params = jax.tree.map(lambda x: x[k_index, seed], state.learner.params)
    greedy = jax.jit(trainer.learner.greedy)

    if trainer.learner.policy.discrete:

        def act(obs: np.ndarray) -> int:
            return int(greedy(params, np.asarray(obs, np.float32)))

    else:

        def act(obs: np.ndarray) -> np.ndarray:
            return np.asarray(greedy(params, np.asarray(obs, np.float32)), np.float32)

    return act


def _index_of(values: tuple[float, ...], k: float) -> int:
    for i, value in enumerate(values):
        if np.isclose(value, k):
            return i
    raise ValueError(f"K={k} not in this run (it has K in {list(values)})")
