"""What the SB3 baselines share: the greedy evaluation in gymnasium and the one JSON line each
prints (run as scripts, so this module is imported from their folder)."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np

EPISODES = 5
"""Greedy episodes per trained seed, first resets seeded 100, 101, ..."""


def greedy_returns(model, normalize, env_id: str, env_kwargs: dict) -> list[float]:
    """`model`'s deterministic policy in a fresh gymnasium env, its observations standardised
    by the frozen statistics of `normalize` (SB3's VecNormalize)."""
    normalize.training, normalize.norm_reward = False, False
    play, returns = gym.make(env_id, **env_kwargs), []
    for episode in range(EPISODES):
        obs, _ = play.reset(seed=100 + episode)
        done, total = False, 0.0
        while not done:
            action, _ = model.predict(normalize.normalize_obs(obs[None]), deterministic=True)
            obs, reward, terminated, truncated, _ = play.step(action[0])
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    return returns


def report(
    task: str, seed: int, steps: int, seconds: float, returns: list[float], resumes: int = 0
) -> None:
    """The run's one JSON line: task, seed, steps, training seconds, greedy returns, mean, and
    how many times a run resumed from its checkpoint (only where it did)."""
    line = {"task": task, "seed": seed, "steps": steps, "train_seconds": round(seconds)}
    line |= {"returns": [round(r, 1) for r in returns], "mean": round(float(np.mean(returns)), 1)}
    if resumes:
        line["resumes"] = resumes
    print(json.dumps(line))
