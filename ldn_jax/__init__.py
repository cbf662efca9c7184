"""MBRL-LDN in JAX: model-based RL whose imagination is stopped by a learning degree.

    import ldn_jax
    config = ldn_jax.from_preset("paper", env="cartpole-v1", algo="ldn", seeds=3)
    summary = ldn_jax.train(config, "runs/mine")     # config.json, metrics.jsonl, ...
    act = ldn_jax.load_policy("runs/mine", seed=0)   # act(obs) -> action

The pure core (config, envs, networks, dynamics, imagination, rollout, learners, trainer) is
importable without the host wing (`ldn_jax.host`: run directories, checkpoints, the command,
logging, plots), which `train` and `load_policy` load on first use.
"""

from ldn_jax.config import Config, from_preset
from ldn_jax.learning_degree import deviation, learning_degree, stop_draw, stop_probability

__all__ = [
    "Config",
    "deviation",
    "from_preset",
    "learning_degree",
    "load_policy",
    "stop_draw",
    "stop_probability",
    "train",
]


def __getattr__(name: str):
    # The host wing (orbax, matplotlib, rich) loads only when its entry points are asked for.
    if name == "train":
        from ldn_jax.host.training import train

        return train
    if name == "load_policy":
        from ldn_jax.host.policy import load_policy

        return load_policy
    raise AttributeError(f"module 'ldn_jax' has no attribute {name!r}")
