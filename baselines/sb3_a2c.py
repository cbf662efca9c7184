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
"""

from __future__ import annotations

import sys
import time

import torch
from sb3_play import greedy_returns, report
from stable_baselines3 import A2C
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

TASKS = {"halfcheetah": "HalfCheetah-v5", "hopper": "Hopper-v5", "walker2d": "Walker2d-v5"}


def main() -> None:
    task, seed, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    env_id = TASKS[task]
    torch.set_num_threads(1)
    env = VecNormalize(make_vec_env(env_id, n_envs=1, seed=seed))
    model = A2C("MlpPolicy", env, seed=seed, verbose=0)
    start = time.time()
    model.learn(steps)
    seconds = time.time() - start
    report(task, seed, steps, seconds, greedy_returns(model, env, env_id, {}))


if __name__ == "__main__":
    main()
