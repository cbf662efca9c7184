"""How a halfcheetah policy runs: upright or on its back, and how fast.

    python -m experiments.gaits RUN_DIR [RUN_DIR ...] [--episodes N] [--out FILE]

Each RUN_DIR is a finished halfcheetah run. Each of its seeds' greedy policy (its first K)
plays N episodes in gymnasium (`ldn-jax eval`'s env, first reset seeded 0). Per seed: the
mean return, the mean forward velocity of the torso, and the share of steps with the torso
pitched past 90 degrees either way, i.e. on its back. A halfcheetah that flips early and
learns to run on its back is a known local optimum of the task: its returns stop near 2,000.
Writes a JSON document (stdout, and --out).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from ldn_jax.host.gym_eval import make_env
from ldn_jax.host.policy import load_policy
from ldn_jax.host.run_dir import RunDir


def flipped(pitch: np.ndarray) -> np.ndarray:
    """True where a pitch angle (radians, any winding) is past 90 degrees from upright."""
    return np.abs(np.angle(np.exp(1j * pitch))) > np.pi / 2


def gait(run_dir: Path, seed: int, episodes: int) -> dict:
    """One seed's greedy policy over `episodes` episodes: return, velocity, flip share."""
    act, env = load_policy(run_dir, seed), make_env("halfcheetah")
    data = env.unwrapped.data
    returns, velocity, pitch = [], [], []
    for episode in range(episodes):
        obs, _ = env.reset(seed=0 if episode == 0 else None)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(act(obs))
            total += float(reward)
            velocity.append(float(data.qvel[0]))
            pitch.append(float(data.qpos[2]))
            done = terminated or truncated
        returns.append(total)
    return {
        "run": run_dir.name,
        "seed": seed,
        "episodes": episodes,
        "mean_return": float(np.mean(returns)),
        "forward_velocity": float(np.mean(velocity)),
        "on_its_back": float(flipped(np.array(pitch)).mean()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    rows = []
    for run in args.runs:
        config = RunDir(run).read_config()
        if config.env != "halfcheetah":
            parser.error(f"{run} is a {config.env} run; gaits reads halfcheetah's")
        seeds = range(config.first_seed, config.first_seed + config.seeds)
        rows += [gait(run, seed, args.episodes) for seed in seeds]
    text = json.dumps(rows, indent=1)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
