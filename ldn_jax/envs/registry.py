"""Environment names: the only place they are spelled."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ldn_jax.envs import mujoco
from ldn_jax.envs.cartpole import CartPole, EnvParams

_CARTPOLE = {
    "cartpole-v0": EnvParams(max_steps=200, forces=(-10.0, 10.0)),
    "cartpole-v1": EnvParams(max_steps=500, forces=(-10.0, 10.0)),
    "cartpole-v2": EnvParams(max_steps=1000, forces=(-10.0, -5.0, 0.0, 5.0, 10.0)),
}


def _cartpole(name: str) -> Callable[[], tuple[Any, Any]]:
    return lambda: (CartPole(), _CARTPOLE[name])


MUJOCO_NAMES = tuple(mujoco.TASKS)


def _mujoco(name: str) -> Callable[[], tuple[Any, Any]]:
    # Gymnasium's step limits (1,000; reacher 50), so that `ldn-jax eval` plays the task that
    # was trained; the engine is picked by platform until `params.replace(backend=...)`.
    limit = mujoco.TASKS[name].step_limit
    return lambda: (
        mujoco.MujocoEnv(),
        mujoco.EnvParams(task=name, backend="auto", max_steps=limit),
    )


_REGISTRY: dict[str, Callable[[], tuple[Any, Any]]] = {
    **{name: _cartpole(name) for name in _CARTPOLE},
    **{name: _mujoco(name) for name in MUJOCO_NAMES},
}


def names() -> tuple[str, ...]:
    """Every env name `make` accepts."""
    return tuple(_REGISTRY)


def make(name: str) -> tuple[Any, Any]:
    """Return `(env, params)` for a registered name."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown env {name!r}; valid names: {', '.join(names())}")
    return _REGISTRY[name]()
