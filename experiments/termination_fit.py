"""How well the learned termination (`--set imagine.termination=learned`) finds a task's own
test, on real data.

    python -m experiments.termination_fit RUN_DIR [--seeds N] [--fits N] [--out FILE]

RUN_DIR is a finished model-based run (its final checkpoint holds each seed's real buffer R).
Each row of R is labelled by the task's own test on its next observation (what the trainer's
default, "known", reads). For each of the first N seeds s, a fresh classifier (the one the
trainer keeps beside the model) is fitted on seed s's R: `--fits` fits of `fit.updates`
steps each, as a run makes one per iteration. It is scored on the next seed's R, data it never
saw: the share of terminal rows it calls terminal (recall), the share of the others it calls
alive (specificity), and the rows of each kind. Writes a JSON document (stdout, and --out).
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
from ldn_jax.buffer import Buffer
from ldn_jax.dynamics import Dynamics


def labelled(buffer: Buffer, is_terminal) -> Buffer:
    """`buffer` with each row's termination from the task's test on its next observation."""
    done = is_terminal(buffer.data.next_obs).astype(jnp.float32)
    return buffer.replace(data=buffer.data.replace(terminated=done))


def score(dynamics: Dynamics, state, buffer: Buffer) -> dict:
    """Recall and specificity of the classifier on `buffer`'s stored rows."""
    size = int(buffer.size)
    truth = np.asarray(buffer.data.terminated[:size]) > 0
    guess = np.asarray(dynamics.is_terminal(state, buffer.data.next_obs[:size]))
    return {
        "terminal_rows": int(truth.sum()),
        "alive_rows": int((~truth).sum()),
        "recall": float(guess[truth].mean()) if truth.any() else None,
        "specificity": float((~guess[~truth]).mean()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--fits", type=int, default=100)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    config, trainer, states = load_run(args.run)
    if config.seeds < 2:
        raise SystemExit("error: the scores read the next seed's buffer: the run needs 2 seeds")
    obs_size = trainer.obs_size
    dynamics = Dynamics(config.model, obs_size, trainer.model_action_size, "learned", config.fit)
    is_terminal = trainer.parts.real.is_terminal
    fit = jax.jit(dynamics.fit_termination)
    rows = []
    for seed in range(min(args.seeds, config.seeds - 1)):
        at = lambda tree, s=seed: jax.tree.map(lambda x: x[0, s], tree)
        buffer = labelled(at(states.buffer), is_terminal)
        test = labelled(at(states.buffer, seed + 1), is_terminal)
        state = dynamics.init(jax.random.key(seed))
        state = state.replace(stats=at(states.model).stats)  # the run's own normaliser
        start = time.perf_counter()
        for i in range(args.fits):
            state, loss = fit(state, buffer, jax.random.key(1000 * seed + i))
        seconds = time.perf_counter() - start
        rows.append(
            {
                "seed": config.first_seed + seed,
                "test_seed": config.first_seed + seed + 1,
                "fits": args.fits,
                "adam_steps": args.fits * config.fit.updates,
                "final_loss": float(loss),
                "train": score(dynamics, state, buffer),
                "test": score(dynamics, state, test),
                "seconds": round(seconds, 1),
            }
        )
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    document = {"run": str(args.run), "env": config.env, "seeds": rows}
    text = json.dumps(document, indent=1)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
