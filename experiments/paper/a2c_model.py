"""Why the model makes the A2C family worse on halfcheetah, and what pays instead
(exploratory: seeds 0-4, which also chose the family's constants).

    python -m experiments.paper.a2c_model [--arms ARM,...] [--report]

Each arm is `ldn-jax --env halfcheetah --algo ALGO [--preset branched] --seeds 5 --k 1` at
1M real steps: the task defaults (`a2c`, `a2c-model`), and the branched preset's imagination
(short rollouts from real states in a probabilistic ensemble) for `a2c-model` and `ldn`,
beside `a2c` under the same preset (its `steps` schedule and iteration length) as their
control. Trains every run (resumed when interrupted, reused when finished; records under
`records/a2c-model/`), replays each seed's greedy policy in gymnasium (10 episodes) into
`a2c-model/arms/ARM.json` (committed) with the steps it imagined, and for the default
`a2c-model` reads its final model and critic (`diagnose`): how far the model's imagined
episodes drift from the real env, step by step; the rewards they credit; and the critic's
value beside the real and imagined returns. `--report` rebuilds `a2c-model/a2c-model.md`
and `.json` from those files.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax
import numpy as np

from experiments.paper import cache, common
from experiments.paper import shadow as cal
from ldn_jax.config import Config, from_preset, validate
from ldn_jax.host import stats

TASK = "halfcheetah"
SEEDS = 5
STEPS = 1_000_000
EPISODES = 10
ARMS: dict[str, tuple[str, str, dict]] = {
    "a2c-model": ("a2c-model", "paper", {}),
    "a2c": ("a2c", "paper", {}),
    "branched-a2c-model": ("a2c-model", "branched", {}),
    "branched-a2c": ("a2c", "branched", {}),
    "branched-ldn": ("ldn", "branched", {}),
    "a2c-model-true": ("a2c-model", "paper", {"model.world": "true"}),
}
"""Arm -> (algorithm, preset, fields by `--set` name). "a2c-model-true" imagines as
`a2c-model` does with the real simulator in the model's place (a perfect model, for the
study): whether the scheme or the model's error costs `a2c-model` its returns."""
SHADOW_EPISODES = 16
"""Imagined (and real) episodes per seed that `diagnose` plays."""
BINS = ((1, 1), (2, 5), (6, 20), (21, 100), (101, 1000))
"""The imagined steps' index ranges (1-based, inclusive) `diagnose` summarises."""


def config_of(arm: str) -> Config:
    algo, preset, fields = ARMS[arm]
    config = from_preset(preset, env=TASK, algo=algo, seeds=SEEDS, steps=STEPS, k=(1.0,), **fields)
    return validate(config)


def run_dir(results: Path, arm: str) -> Path:
    return results / "runs" / "a2c-model" / f"{TASK}-{arm}-s0+{SEEDS}-{STEPS}"


def diagnose(out: Path, key: jax.Array | None = None) -> dict:
    """The finished default `a2c-model` run in `out`, read at its final state per seed:
    `SHADOW_EPISODES` imagined episodes with the real env stepped alongside
    (`shadow.shadow_rollouts`), summarised per range of imagined step (`BINS`), and the
    critic's value of initial states beside the discounted returns of real and imagined
    episodes from them (`shadow.policy_rollouts`)."""
    config, trainer, states = cal.load_run(out)
    states = jax.tree.map(lambda x: x[0], states)  # K = 1
    key = jax.random.key(0) if key is None else key

    def per_seed(state, key):
        k_shadow, k_play = jax.random.split(key)
        steps = cal.shadow_rollouts(trainer, state, k_shadow, SHADOW_EPISODES, 1.0)
        return steps, cal.policy_rollouts(trainer, state, k_play, SHADOW_EPISODES)

    steps, (value, real, imagined) = jax.device_get(
        jax.jit(jax.vmap(per_seed))(states, jax.random.split(key, config.seeds))
    )
    return {
        "shadow_episodes": SHADOW_EPISODES,
        "fit": [
            fit_error(trainer, jax.tree.map(lambda x, s=s: x[s], states))
            for s in range(config.seeds)
        ],
        "bins": bin_summary(steps),
        "value": [float(v.mean()) for v in value],
        "real_return": [float(r.mean()) for r in real],
        "imagined_return": [float(r.mean()) for r in imagined],
    }


BUFFER_ROWS = 2000
"""Rows of the final buffer R (evenly spaced over what it holds) `fit_error` reads."""


def fit_error(trainer, state) -> dict:
    """M1 on the real transitions it was last fitted to (one seed's final state): its
    one-step error relative to the real step (median) and its reward's absolute error beside
    the rewards' own size (medians)."""
    data, size = state.buffer.data, int(state.buffer.size)
    rows = np.linspace(0, size - 1, min(BUFFER_ROWS, size)).astype(int)
    obs, action, next_obs, reward = (
        np.asarray(x)[rows] for x in (data.obs, data.action, data.next_obs, data.reward)
    )
    predicted = np.asarray(
        cal._predict(trainer, state.model.params, state.model.stats, obs, action)
    )
    error = np.linalg.norm(predicted[:, :-1] - next_obs, axis=-1)
    step = np.linalg.norm(next_obs - obs, axis=-1)
    return {
        "rows": int(rows.size),
        "relative_one_step_error": float(np.median(error / step)),
        "reward_error": float(np.median(np.abs(predicted[:, -1] - reward))),
        "reward_size": float(np.median(np.abs(reward))),
    }


def bin_summary(steps: cal.ShadowSteps) -> list[dict]:
    """Per range of imagined step (`BINS`), over seeds and episodes (`[S, T, N]`, the steps
    before predicted termination): the share of the imagined steps in it, the model's
    one-step error relative to the real step from the same state (median), the drift from
    the real trajectory (median), and the mean reward M1 credits beside the real env's."""
    live = steps.live.astype(bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = steps.one_step_error / steps.step_size
    out = []
    for low, high in BINS:
        window = np.zeros_like(live)
        window[:, low - 1 : high] = True
        mask = live & window
        drift = steps.compounding_error[mask & steps.real_live.astype(bool)]
        finite = lambda x: x[np.isfinite(x)]
        out.append(
            {
                "steps": [low, high],
                "share": float(mask.sum() / max(live.sum(), 1)),
                "relative_one_step_error": _median(finite(relative[mask])),
                "drift": _median(finite(drift)),
                "reward": _mean(finite(steps.reward[mask])),
                "true_reward": _mean(finite(steps.true_reward[mask])),
                "reward_error": _median(finite(np.abs(steps.reward - steps.true_reward)[mask])),
            }
        )
    return out


def _median(x: np.ndarray) -> float | None:
    return float(np.median(x)) if x.size else None


def _mean(x: np.ndarray) -> float | None:
    return float(np.mean(x)) if x.size else None


DIAGNOSED = "a2c-model"
"""The arm `diagnose` reads; its findings go to `a2c-model/diagnosis.json`."""


def ensure(arm: str, results: Path, code: str) -> None:
    out = run_dir(results, arm)
    file = common.out_dir(results, "a2c-model/arms") / f"{arm}.json"
    cache.ensure_replayed(config_of(arm), out, file, {"arm": arm}, (code, EPISODES), cache.imagined)
    if arm == DIAGNOSED:
        ensure_diagnosis(results, code)


def ensure_diagnosis(results: Path, code: str) -> None:
    """`diagnose` the finished `DIAGNOSED` run into `a2c-model/diagnosis.json`, unless that
    file already reads this run (its training seconds) at this commit."""
    out = run_dir(results, DIAGNOSED)
    file = common.out_dir(results, "a2c-model") / "diagnosis.json"
    summary = cache.finished_summary(out)
    kept = json.loads(file.read_text()) if file.exists() else {}
    if summary is None or kept.get("train_seconds") == summary["train_seconds"]:
        return
    print(f"diagnosing {out.name}", flush=True)
    data = {"commit": code, "train_seconds": summary["train_seconds"], **diagnose(out)}
    common.write_json(file, data)


def _number(x: float | None, digits: int = 0) -> str:
    return "–" if x is None else f"{x:,.{digits}f}"


def report(results: Path) -> None:
    order = {arm: i for i, arm in enumerate(ARMS)}
    rows = sorted(cache.replayed(results / "a2c-model" / "arms"), key=lambda r: order[r["arm"]])
    for r in rows:
        r["score"] = stats.estimate(r["scores"])
    lines = [
        "## The model in the A2C family on halfcheetah (`experiments/paper/a2c_model.py`)",
        "",
        f"Exploratory: seeds 0-4, {STEPS:,} real steps, K = 1. Greedy return in gymnasium "
        f"({EPISODES} episodes per seed): IQM [95% bootstrap interval]. Imagined: steps the "
        "model imagined per real step, all seeds together.",
        "",
        "| arm | command | greedy return | per seed | imagined | training s | code |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        algo, preset, fields = ARMS[r["arm"]]
        command = f"`--algo {algo}" + (" --preset branched" if preset == "branched" else "")
        command += "".join(f" --set {name}={value}" for name, value in fields.items()) + "`"
        share = r["imagined_steps"] / r["env_steps"] if algo != "a2c" else None
        lines.append(
            f"| {r['arm']} | {command} | {stats.text(r['score'])} | "
            f"{', '.join(f'{s:,.0f}' for s in r['scores'])} | "
            f"{'–' if share is None else f'{share:.2f}'} | {r['train_seconds']:,.0f} | "
            f"{', '.join(r['commits'])} |"
        )
    diagnosis = results / "a2c-model" / "diagnosis.json"
    if diagnosis.exists():
        d = json.loads(diagnosis.read_text())
        fit = d["fit"]
        lines += [
            "",
            f"Read at {d['commit']}. The default `a2c-model`'s M1 on the real transitions it "
            f"was last fitted to ({fit[0]['rows']:,} rows of R per seed, medians): one-step "
            "error relative to the real step "
            + ", ".join(f"{f['relative_one_step_error']:.2f}" for f in fit)
            + " by seed; reward error "
            + ", ".join(f"{f['reward_error']:.2f}" for f in fit)
            + " against rewards of size "
            + ", ".join(f"{f['reward_size']:.2f}" for f in fit)
            + ".",
            "",
            f"The same runs at their final state, {d['shadow_episodes']} imagined "
            "episodes per seed from fresh initial states, the real env stepped alongside "
            "(pooled over seeds and episodes). Relative error: the model's one-step error on "
            "the next observation over the real step's length from the same state (median); "
            "drift: the imagined observation's distance from the real trajectory played with "
            "the same actions (median); rewards: per step, M1's and the real env's for the "
            "same step.",
            "",
            "| imagined steps | share of imagined steps | relative error | drift "
            "| reward (M1) | reward (real) | reward error |",
            "|---|---|---|---|---|---|---|",
            *(
                f"| {b['steps'][0]}-{b['steps'][1]} | {b['share']:.1%} | "
                f"{_number(b['relative_one_step_error'], 2)} | {_number(b['drift'], 2)} | "
                f"{_number(b['reward'], 2)} | {_number(b['true_reward'], 2)} | "
                f"{_number(b['reward_error'], 2)} |"
                for b in d["bins"]
            ),
            "",
            "The critic's value of initial states beside the discounted returns of the "
            "sampled policy's episodes from them, in the real env and in M1 (per seed, mean "
            f"over {d['shadow_episodes']} episodes):",
            "",
            "| seed | value | real return | imagined return |",
            "|---|---|---|---|",
            *(
                f"| {seed} | {v:,.1f} | {r:,.1f} | {i:,.1f} |"
                for seed, (v, r, i) in enumerate(
                    zip(d["value"], d["real_return"], d["imagined_return"], strict=True)
                )
            ),
        ]
    out = common.out_dir(results, "a2c-model")
    common.write_json(out / "a2c-model.json", {"rows": rows})
    (out / "a2c-model.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out}/a2c-model.json and a2c-model.md")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--arms", default=",".join(ARMS))
    parser.add_argument("--report", action="store_true", help="train nothing; rebuild the report")
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    parser.add_argument(
        "--diagnose", action="store_true", help="diagnose the finished a2c-model run again"
    )
    args = parser.parse_args(argv)
    arms = args.arms.split(",")
    if unknown := [a for a in arms if a not in ARMS]:
        parser.error(f"unknown arm: {', '.join(unknown)}")
    if args.diagnose:
        (common.out_dir(args.results, "a2c-model") / "diagnosis.json").unlink(missing_ok=True)
        ensure_diagnosis(args.results, cache.code_version())
    elif not args.report:
        code = cache.code_version()
        common.compile_cache(args.results)
        for arm in arms:
            ensure(arm, args.results, code)
            report(args.results)
    report(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
