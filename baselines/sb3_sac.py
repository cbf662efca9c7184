"""SB3's SAC with rl-baselines3-zoo's MuJoCo settings, for side-by-side runs with ours.

    SB3_PYTHON sb3_sac.py TASK SEED STEPS [LEARNING_STARTS]
        (TASK: halfcheetah, hopper or inverted_pendulum; LEARNING_STARTS: the zoo's 10,000)

Not part of the package, and not run by the tests: it needs torch, stable-baselines3 and
gymnasium[mujoco] in an interpreter of their own (see sb3_ppo.py). The zoo's MuJoCo entry for
SAC is SB3's defaults (256 x 256 ReLU nets, Adam 3e-4, batch 256, tau 0.005, gamma 0.99, one
gradient step per env step, the temperature tuned toward minus the action dimension, a 1M
replay buffer) with 10,000 steps before the first update; ours (`--algo sac`) takes the same
constants with 1,000. Torch runs on the 2 cores (2 threads). Trains one seed on gymnasium's
v5 task and prints one JSON line as sb3_ppo.py does, with its steps per second. A smaller
LEARNING_STARTS (ours: 1,000) is for timing short runs that update as ours do, not for returns.
"""

from __future__ import annotations

import json
import sys
import time

import torch
from sb3_play import greedy_returns, report
from stable_baselines3 import SAC
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

TASKS = {
    "halfcheetah": "HalfCheetah-v5",
    "hopper": "Hopper-v5",
    "inverted_pendulum": "InvertedPendulum-v5",
}


def main() -> None:
    task, seed, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    learning_starts = int(sys.argv[4]) if len(sys.argv) > 4 else 10_000
    env_id = TASKS[task]
    torch.set_num_threads(2)
    # no normalisation: the wrapper only hands `greedy_returns` its (identity) statistics
    env = VecNormalize(make_vec_env(env_id, n_envs=1, seed=seed), norm_obs=False, norm_reward=False)
    model = SAC("MlpPolicy", env, learning_starts=learning_starts, seed=seed, verbose=0)
    start = time.time()
    model.learn(steps)
    seconds = time.time() - start
    report(task, seed, steps, seconds, greedy_returns(model, env, env_id, {}))
    print(json.dumps({"steps_per_second": round(steps / seconds, 1)}))


if __name__ == "__main__":
    main()
