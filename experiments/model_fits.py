"""MBPO's model fit beside the `branched` preset's, on the same data.

    python -m experiments.model_fits RUN_DIR [--seeds N] [--starts N] [--out FILE]

RUN_DIR is a finished branched run (its final checkpoint holds each seed's real buffer R and
the model the preset fitted through the run: `fit.updates` steps after every iteration).
For each of its first N seeds s, a fresh ensemble of the same architecture is fitted on
seed s's final R as MBPO fits it (`Dynamics.fit_until_stalled`: epochs of one pass over the
training slots until no member gains 1% for 5 epochs). Both models are then scored on data
neither saw: chains of 5 consecutive real steps from the next seed's R (a worker's steps are
W rows apart there), each model predicting with its elites' mean:
- one-step: the next observation's error in units of the per-dimension std of R, and the
  reward's absolute error;
- 5-step open loop: the model run from the chain's first state through its 5 real actions,
  the same errors at the fifth step.
Writes a JSON document (stdout, and --out).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from experiments.paper.shadow import load_run
from ldn_jax.dynamics import Dynamics, EarlyStop
from ldn_jax.learning_degree import ensemble_mean

CHAIN = 5
"""Steps of each open-loop chain."""
STOP = EarlyStop()
"""MBPO's: patience 5, a 1% gain."""


def chains(buffer, workers: int, starts: int, key) -> np.ndarray:
    """Indices `[starts, CHAIN]` of rows of `buffer` that are 5 consecutive steps of one
    worker (each row's next observation the following row's observation)."""
    obs = np.asarray(buffer.data.obs[: int(buffer.size)])
    next_obs = np.asarray(buffer.data.next_obs[: int(buffer.size)])
    size = len(obs) - CHAIN * workers
    first = np.arange(size)
    linked = np.ones(size, bool)
    for t in range(CHAIN - 1):
        here, there = first + t * workers, first + (t + 1) * workers
        linked &= np.all(next_obs[here] == obs[there], axis=-1)
    found = first[linked]
    pick = np.asarray(jax.random.choice(key, len(found), (min(starts, len(found)),), False))
    return found[pick][:, None] + workers * np.arange(CHAIN)[None, :]


def mean_step(dynamics: Dynamics, model, obs, action):
    """The elites' mean prediction: `(next_obs, reward)` in the env's units."""
    members = dynamics.predict_members(model.params, model.stats, obs, action)
    next_obs, reward = dynamics.denormalize(model.stats, *members)
    elites = model.elites
    return ensemble_mean(next_obs[elites]), ensemble_mean(reward[elites])


def errors(dynamics: Dynamics, model, data, index: np.ndarray, scale: np.ndarray) -> dict:
    """One-step and 5-step open-loop errors of `model` on the chains `index` of `data`."""
    take = lambda x: jnp.asarray(np.asarray(x)[index])
    obs, action = take(data.obs), take(data.action)
    next_obs, reward = take(data.next_obs), take(data.reward)
    step = jax.jit(lambda o, a: mean_step(dynamics, model, o, a))
    predicted, r = step(obs[:, 0], action[:, 0])
    one_obs = np.abs(np.asarray(predicted - next_obs[:, 0]) / scale).mean()
    one_reward = np.abs(np.asarray(r - reward[:, 0])).mean()
    state = obs[:, 0]
    for t in range(CHAIN):
        state, r = step(state, action[:, t])
    five_obs = np.abs(np.asarray(state - next_obs[:, -1]) / scale).mean()
    five_reward = np.abs(np.asarray(r - reward[:, -1])).mean()
    return {
        "one_step_obs": float(one_obs),
        "one_step_reward": float(one_reward),
        "five_step_obs": float(five_obs),
        "five_step_reward": float(five_reward),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--starts", type=int, default=2000)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    config, trainer, states = load_run(args.run)
    if not config.model.probabilistic or config.imagine.start != "real":
        raise SystemExit(f"error: {args.run} is not a branched run (a probabilistic ensemble)")
    if config.seeds < 2:
        raise SystemExit("error: the scores read the next seed's buffer: the run needs 2 seeds")
    dynamics = trainer.dynamics  # the same architecture, fitted afresh the other way
    fit = jax.jit(lambda state, buffer, key: dynamics.fit_until_stalled(state, buffer, key, STOP))
    rows = []
    for seed in range(min(args.seeds, config.seeds - 1)):
        at = lambda tree, s=seed: jax.tree.map(lambda x: x[0, s], tree)
        own, buffer, test = at(states.model), at(states.buffer), at(states.buffer, seed + 1)
        key = jax.random.key(seed)
        start = time.perf_counter()
        fitted, _, epochs = jax.block_until_ready(fit(dynamics.init(key), buffer, key))
        seconds = time.perf_counter() - start
        scale = np.asarray(own.stats.obs_std)
        index = chains(test, config.workers, args.starts, jax.random.fold_in(key, 1))
        rows.append(
            {
                "seed": config.first_seed + seed,
                "test_seed": config.first_seed + seed + 1,
                "chains": len(index),
                "branched": errors(dynamics, own, test.data, index, scale),
                "mbpo": errors(dynamics, fitted, test.data, index, scale),
                "mbpo_epochs": int(epochs),
                "mbpo_fit_seconds": round(seconds, 1),
                "real_rows": int(buffer.size),
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    document = {"run": str(args.run), "env": config.env, "algo": config.algo, "rows": rows}
    if args.out:
        args.out.write_text(json.dumps(document, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
