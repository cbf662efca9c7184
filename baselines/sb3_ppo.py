"""SB3's PPO with rl-baselines3-zoo's constants, for side-by-side runs with ours.

    SB3_PYTHON sb3_ppo.py TASK SEED STEPS     (TASK: halfcheetah, hopper, ant or ant-nocfrc)

Not part of the package, and not run by the tests: it needs torch, stable-baselines3 and
gymnasium[mujoco] in an interpreter of their own (`python -m venv V && V/bin/pip install torch
stable-baselines3 "gymnasium[mujoco]"`). Trains one seed on gymnasium's v5 task with the zoo's
VecNormalize (observations and rewards), then plays 5 greedy episodes (env seeds 100-104) and
prints one JSON line: task, seed, steps, training seconds, the greedy returns and their mean.
Its lines are kept, dated, in experiments/results/locomotion/sb3_zoo_ppo.jsonl, which the
locomotion study sets beside our runs (REPORT.md); docs/logs/tuning-mujoco.md discusses them.
"""

from __future__ import annotations

import sys
import time

import torch
from sb3_play import greedy_returns, report
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

# rl-baselines3-zoo's hyperparams/ppo.yml (HalfCheetah-v3, Hopper-v3), 1 env each.
_ZOO_POLICY = dict(log_std_init=-2, ortho_init=False, activation="relu", net_arch=[256, 256])
# Its Ant-v3 entry is SB3's PPO defaults (2 x 64 tanh, orthogonal init, log std 0) with
# VecNormalize; its TimeFeatureWrapper (a time-left input) is left out, as our tasks have none.
_SB3_DEFAULTS = dict(log_std_init=0.0, ortho_init=True, activation="tanh", net_arch=[64, 64])
ZOO = {
    "halfcheetah": (
        "HalfCheetah-v5", {},
        dict(batch_size=64, n_steps=512, gamma=0.98, learning_rate=2.0633e-05,
             ent_coef=0.000401762, clip_range=0.1, n_epochs=20, gae_lambda=0.92,
             max_grad_norm=0.8, vf_coef=0.58096),
        _ZOO_POLICY,
    ),
    "hopper": (
        "Hopper-v5", {},
        dict(batch_size=32, n_steps=512, gamma=0.999, learning_rate=9.80828e-05,
             ent_coef=0.00229519, clip_range=0.2, n_epochs=5, gae_lambda=0.99,
             max_grad_norm=0.7, vf_coef=0.835671),
        _ZOO_POLICY,
    ),
    "ant": ("Ant-v5", {}, {}, _SB3_DEFAULTS),
    "ant-nocfrc": ("Ant-v5", {"include_cfrc_ext_in_observation": False}, {}, _SB3_DEFAULTS),
}  # fmt: skip


def main() -> None:
    task, seed, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    env_id, env_kwargs, constants, net = ZOO[task]
    torch.set_num_threads(1)
    made = make_vec_env(env_id, n_envs=1, seed=seed, env_kwargs=env_kwargs)
    env = VecNormalize(made, gamma=constants.get("gamma", 0.99))
    policy = dict(
        log_std_init=net["log_std_init"],
        ortho_init=net["ortho_init"],
        activation_fn={"relu": torch.nn.ReLU, "tanh": torch.nn.Tanh}[net["activation"]],
        net_arch=dict(pi=net["net_arch"], vf=net["net_arch"]),
    )
    model = PPO("MlpPolicy", env, seed=seed, verbose=0, policy_kwargs=policy, **constants)
    start = time.time()
    model.learn(steps)
    seconds = time.time() - start
    report(task, seed, steps, seconds, greedy_returns(model, env, env_id, env_kwargs))


if __name__ == "__main__":
    main()
