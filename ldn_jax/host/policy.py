"""Trained policies for use outside JAX."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from ldn_jax.host.run_dir import RunDir
from ldn_jax.trainer import Trainer


def load_policy(
    run_dir: str | Path, seed: int | None = None, k: float | None = None, at: dict | None = None
) -> Callable[[np.ndarray], int | np.ndarray]:
    """The greedy policy of one seed and K of a finished run (`seed=None`: its first seed,
    0 unless it was trained with `first_seed`).

    Returns `act(obs)`: a numpy observation in; out a Python int (discrete actions) or a
    float32 numpy array within the action bounds (continuous: the Gaussian's mean).
    `k=None` picks the run's only K, or its first one. In a sweep, `at` picks the point by
    its values (`{"agent.actor_lr": 3e-4}`); a field left out takes its first value.
    """
    run = RunDir(run_dir)
    config = run.read_config()
    first = config.first_seed
    seed = first if seed is None else seed
    if not first <= seed < first + config.seeds:
        raise ValueError(
            f"seed {seed} not in this run (it has seeds {first}..{first + config.seeds - 1})"
        )
    k_index = point_index(config, k, at)
    trainer = Trainer(config)
    like = jax.eval_shape(trainer.init_batch)
    state = run.restore_final(like)
    params = jax.tree.map(lambda x: x[k_index, seed - first], state.learner.params)
    greedy = jax.jit(trainer.learner.greedy)

    if trainer.learner.policy.discrete:

        def act(obs: np.ndarray) -> int:
            return int(greedy(params, np.asarray(obs, np.float32)))

    else:

        def act(obs: np.ndarray) -> np.ndarray:
            return np.asarray(greedy(params, np.asarray(obs, np.float32)), np.float32)

    return act


def point_index(config, k: float | None = None, at: dict | None = None) -> int:
    """The index into `config.points` of K `k` (None: the first) and the sweep values `at`
    (a field left out: its first value); ValueError naming the valid values."""
    wanted = {"k": config.k[0] if k is None else _value_of(config.k, k, "K")}
    swept = dict(config.sweep)
    for name, value in (at or {}).items():
        if name not in swept:
            raise ValueError(
                f"{name} is not swept in this run (swept: {', '.join(swept) or 'none'})"
            )
        wanted[name] = _value_of(swept[name], value, name)
    for name, values in config.sweep:
        wanted.setdefault(name, values[0])
    return next(i for i, p in enumerate(config.points) if p == wanted)


def _value_of(values: tuple[float, ...], value: float, name: str) -> float:
    for candidate in values:
        if np.isclose(candidate, value):
            return candidate
    raise ValueError(f"{name}={value} not in this run (it has {name} in {list(values)})")
