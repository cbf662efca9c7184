"""Trained policies in the real gymnasium environments.

Our JAX envs mirror gymnasium's; evaluating there checks that a policy learned in ours transfers
and gives numbers comparable with other libraries'. CartPole-v1 is gymnasium's own; v0 and v2
are gymnasium's `CartPoleEnv` with our step limit and force table (v2: the paper's five forces).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium.envs.classic_control.cartpole import CartPoleEnv
from gymnasium.wrappers import RecordVideo, RescaleAction, TimeLimit

from ldn_jax import envs
from ldn_jax.envs.mujoco.model import settotalmass_ignored

GYMNASIUM_IDS = {
    "cartpole-v1": "CartPole-v1",
    **{name: task.gymnasium_id for name, task in envs.mujoco.TASKS.items()},
}
"""Our env names whose gymnasium registration is the same task as ours."""

GYMNASIUM_KWARGS = {name: dict(task.gymnasium_kwargs) for name, task in envs.mujoco.TASKS.items()}
"""`gymnasium.make` arguments beside the id, where our task is not the id's default."""

CUSTOM_CARTPOLES = ("cartpole-v0", "cartpole-v2")
"""Built from `CartPoleEnv` and our `EnvParams` (step limit, force table)."""


class ForceTable(gymnasium.Wrapper):
    """CartPole with a table of forces instead of gymnasium's two (+-`force_mag`).

    Action i pushes the cart with `forces[i]` newtons, as `ldn_jax.envs.cartpole.CartPole` does:
    gymnasium's env applies `+force_mag` for action 1 and `-force_mag` for action 0, so each
    step sets `force_mag = |force|` and picks the sign.
    """

    def __init__(self, env: CartPoleEnv, forces: tuple[float, ...]):
        super().__init__(env)
        self.forces = tuple(float(f) for f in forces)
        self.action_space = gymnasium.spaces.Discrete(len(self.forces))

    def step(self, action):
        force = self.forces[int(action)]
        self.env.unwrapped.force_mag = abs(force)
        return self.env.step(1 if force > 0 else 0)


def gymnasium_name(env: str) -> str:
    """How `env` is called on the gymnasium side (for reports)."""
    if env in CUSTOM_CARTPOLES:
        return f"CartPoleEnv+ForceTable({env})"
    kwargs = ", ".join(f"{k}={v}" for k, v in GYMNASIUM_KWARGS.get(env, {}).items())
    return f"{GYMNASIUM_IDS[env]}({kwargs})" if kwargs else GYMNASIUM_IDS[env]


def make_env(
    env: str, render_mode: str | None = None, max_steps: int | None = None
) -> gymnasium.Env:
    """The gymnasium env matching our env `env`, truncated after `max_steps` steps (None:
    gymnasium's own limit, which is ours). Raises ValueError for a name with none."""
    if render_mode == "rgb_array":
        # Offscreen frames need no display; without this, SDL looks for one and complains.
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    if env in CUSTOM_CARTPOLES:
        _, params = envs.make(env)
        base = ForceTable(CartPoleEnv(render_mode=render_mode), params.forces)
        return TimeLimit(base, max_episode_steps=max_steps or params.max_steps)
    if env in GYMNASIUM_IDS:
        with settotalmass_ignored():  # HalfCheetah-v5's model warns on every compile
            limit = {} if max_steps is None else {"max_episode_steps": max_steps}
            kwargs = {**GYMNASIUM_KWARGS.get(env, {}), **limit}
            made = gymnasium.make(GYMNASIUM_IDS[env], render_mode=render_mode, **kwargs)
        ours, params = envs.make(env)
        spec = ours.action_spec(params)
        if not spec.discrete:  # our bounds ([-1, 1]) onto gymnasium's (e.g. [-3, 3])
            made = RescaleAction(made, np.float32(spec.low), np.float32(spec.high))
        return made
    valid = ", ".join(sorted({*GYMNASIUM_IDS, *CUSTOM_CARTPOLES}))
    raise ValueError(f"env {env!r} has no gymnasium counterpart; those with one: {valid}")


def record_video(env: gymnasium.Env, video_dir: Path, name_prefix: str) -> gymnasium.Env:
    """Wrap `env` (made with render_mode="rgb_array") to save videos on gymnasium's schedule
    (episodes 0, 1, 8, 27, ...). Needs moviepy; raises gymnasium.error.DependencyNotInstalled."""
    return RecordVideo(env, str(video_dir), name_prefix=name_prefix, disable_logger=True)


def episode_returns(
    env: gymnasium.Env, act: Callable[[np.ndarray], int | np.ndarray], episodes: int, seed: int
) -> np.ndarray:
    """Undiscounted returns `[episodes]` of `act` in `env`.

    Only the first reset is seeded (gymnasium's convention): later episodes continue the env's
    generator, so the whole evaluation is reproducible from `seed`.
    """
    returns = np.zeros(episodes)
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed if episode == 0 else None)
        done = False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(act(obs))
            returns[episode] += float(reward)
            done = terminated or truncated
    return returns
