"""SB3's A2C with rl-baselines3-zoo's MuJoCo settings, for side-by-side runs with ours.

    SB3_PYTHON sb3_a2c.py TASK SEED STEPS     (TASK: halfcheetah, hopper or walker2d)

Not part of the package, and not run by the tests: it needs torch, stable-baselines3 and
gymnasium[mujoco] in an interpreter of their own (see sb3_ppo.py). The zoo's MuJoCo entry for
A2C is SB3's defaults (1 env, n_steps 5, learning rate 7e-4, gamma 0.99, GAE lambda 1, RMSprop
with eps 1e-5, value coefficient 0.5, gradient clip 0.5, 64 x 64 tanh nets with orthogonal
init, log std 0) under VecNormalize: the zoo's `normalize: true` is SB3's VecNormalize
defaults, observations and rewards (the discounted return's running std, gamma 0.99, both
clipped at 10), the rewards for training only; its published figures at 1M
steps: HalfCheetah-v3 3,041 (benchmark.md), Hopper-v3 733. Trains one seed on gymnasium's v5
task and prints one JSON line as sb3_ppo.py does.

    SB3_PYTHON sb3_a2c.py TASK SEED STEPS CHECKPOINT_DIR

With a fourth argument the run saves its model and VecNormalize statistics there every
100,000 steps and, started again with the same arguments, goes on from the last save (a 1M-step
run takes about an hour of one core). A resumed run is not the uninterrupted one to the bit:
the env restarts an episode, and torch's and the env's random streams start afresh. Its line
says how many times it resumed.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import torch
from sb3_play import greedy_returns, report
from stable_baselines3 import A2C
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

TASKS = {"halfcheetah": "HalfCheetah-v5", "hopper": "Hopper-v5", "walker2d": "Walker2d-v5"}


CHUNK = 100_000
"""Steps between two saves of a run with a checkpoint directory."""


def main() -> None:
    task, seed, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    folder = Path(sys.argv[4]) if len(sys.argv) > 4 else None
    env_id = TASKS[task]
    torch.set_num_threads(1)
    seconds, resumes = 0.0, 0
    if folder is not None and (folder / "progress.json").exists():
        done = json.loads((folder / "progress.json").read_text())
        env = VecNormalize.load(str(folder / "normalize.pkl"), make_vec_env(env_id, 1, seed=seed))
        model = A2C.load(folder / "model.zip", env=env)
        seconds, resumes = done["train_seconds"], done["resumes"] + 1  # saved chunks only
    else:
        env = VecNormalize(make_vec_env(env_id, n_envs=1, seed=seed))
        model = A2C("MlpPolicy", env, seed=seed, verbose=0)
    while model.num_timesteps < steps:
        start = time.time()
        chunk = steps if folder is None else CHUNK
        model.learn(min(chunk, steps - model.num_timesteps), reset_num_timesteps=False)
        seconds += time.time() - start
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            model.save(folder / "model.zip")
            env.save(str(folder / "normalize.pkl"))
            progress = {"steps": model.num_timesteps, "train_seconds": seconds, "resumes": resumes}
            (folder / "progress.json").write_text(json.dumps(progress))
    report(task, seed, steps, seconds, greedy_returns(model, env, env_id, {}), resumes)


if __name__ == "__main__":
    main()
