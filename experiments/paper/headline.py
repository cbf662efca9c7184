"""The branched headline, confirmed on fresh seeds under a plan written before the runs
(`experiments/plans/headline.md`): PPO, PPO with the model-based arms' gradient steps on its
real data, the `branched` preset's branches cut at its cap with no rule, the preset's LD draw
(ensemble estimator) and the paper's M1-vs-M0 LD draw, on halfcheetah and hopper.

    python -m experiments.paper.headline [--envs ENV,...] [--arms ARM,...] [--report]

Trains every run (one vmapped program of seeds 10-19 per arm and env, 200k real steps;
resumed when interrupted, reused when finished; the records under `records/headline/`), then
replays each finished run's greedy policy in gymnasium (`ldn-jax eval`'s episodes) and counts
its optimiser steps from the final checkpoint, into `headline/arms/ENV-ARM.json` (committed:
the checkpoints are not). `--report` trains nothing and rebuilds `headline.json`,
`headline.md` and `headline.png` from those files and the records. Each run's file names the
commits that trained it: each process's HEAD when it started.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax
import numpy as np

from experiments.paper import cache, common
from ldn_jax.config import Config, from_preset, validate
from ldn_jax.host import stats
from ldn_jax.host.run_dir import RunDir
from ldn_jax.trainer import Trainer

ENVS = ("halfcheetah", "hopper")
SEEDS = 10
FIRST_SEED = 10
"""Seeds 10-19: never used on these tasks before the plan was written."""
STEPS = 200_000
EPISODES = 10
"""Greedy episodes per seed in gymnasium (first reset seeded 0, as `ldn-jax eval`)."""

ARMS = {
    "ppo": ("ppo", {}, False, "PPO alone"),
    "ppo-steps": ("ppo", {}, True, "PPO, epochs doubled (the model-based arms' Adam steps)"),
    "ppo-model": ("ppo-model", {}, False, "branches cut at the preset's cap, no rule"),
    "ppo-ldn": ("ppo-ldn", {}, False, "LD draw under the cap, ensemble estimator (the preset)"),
    "ppo-ldn-m0": ("ppo-ldn", {"ld": "m0"}, False, "LD draw under the cap, M1 vs M0 (eq. 3)"),
}
"""Arm -> (algorithm, model fields over the preset's, epochs doubled, how the report names it)."""

COMPARISONS = (
    ("ppo-ldn", "ppo"),
    ("ppo-ldn", "ppo-steps"),
    ("ppo-model", "ppo"),
    ("ppo-model", "ppo-steps"),
    ("ppo-ldn", "ppo-model"),
    ("ppo-ldn-m0", "ppo"),
    ("ppo-ldn-m0", "ppo-model"),
    ("ppo-steps", "ppo"),
)
"""The plan's one-sided tests per env, "A > B"; Holm's correction over every env's."""

ALPHA = 0.05


def config_of(env: str, arm: str, seeds: int, first_seed: int, steps: int) -> Config:
    """The arm's run: the `branched` preset as a user gets it, seeds `first_seed`.."""
    algo, model, double, _ = ARMS[arm]
    base = from_preset("branched", env=env, algo=algo, seeds=seeds, first_seed=first_seed)
    agent = {"epochs": 2 * base.ppo.epochs} if double else {}
    return validate(
        from_preset(
            "branched",
            env=env,
            algo=algo,
            seeds=seeds,
            first_seed=first_seed,
            steps=steps,
            model=model,
            agent=agent,
        )
    )


def run_dir(results: Path, env: str, arm: str, seeds: int, first: int, steps: int) -> Path:
    return results / "runs" / "headline" / f"{env}-{arm}-s{first}+{seeds}-{steps}"


def adam_steps(out: Path, config: Config) -> dict[str, list[int]]:
    """Each net's optimiser steps per seed over the whole run, from the final checkpoint."""
    trainer = Trainer(config)
    state = RunDir(out).restore_final(jax.eval_shape(trainer.init_batch))
    counts: dict[str, list[int]] = {}
    for path, leaf in jax.tree_util.tree_leaves_with_path(state.learner.opt_state):
        name = jax.tree_util.keystr(path)
        for net in ("actor", "critic"):
            if f"'{net}'" in name and name.endswith(".count") and net not in counts:
                counts[net] = np.asarray(leaf)[0].astype(int).tolist()
    return counts


def ensure(env: str, arm: str, args: argparse.Namespace, code: str) -> None:
    """Train (or resume, or reuse) one arm's run, then write its file: commits, gymnasium
    returns, optimiser steps."""
    config = config_of(env, arm, args.seeds, args.first_seed, args.steps)
    out = run_dir(args.results, env, arm, args.seeds, args.first_seed, args.steps)
    file = common.out_dir(args.results, "headline/arms") / f"{out.name}.json"
    labels = {"env": env, "arm": arm}
    extra = lambda out: {"adam_steps": adam_steps(out, config)}
    cache.ensure_replayed(config, out, file, labels, (code, args.episodes), extra)


def rows_of(results: Path, seeds: int, first: int, steps: int) -> list[dict]:
    """One row per arm and env with a finished file: its scores and costs."""
    rows = []
    for env in ENVS:
        for arm in ARMS:
            out = run_dir(results, env, arm, seeds, first, steps)
            file = results / "headline" / "arms" / f"{out.name}.json"
            if not file.exists() or "gymnasium" not in (data := json.loads(file.read_text())):
                continue
            history = cache.load_history(out)
            real = history["env_steps"][0, :, -1]
            imagined = history["imagined_steps"][0, :, -1]
            scores = [float(np.mean(r)) for r in data["gymnasium"]]
            rows.append(
                {
                    **data,
                    "name": ARMS[arm][3],
                    "scores": scores,
                    "score": stats.estimate(scores),
                    "trainer": stats.estimate(data["trainer_eval"]),
                    "imagined_per_real": float(np.mean(imagined / np.maximum(real, 1))),
                    "adam_per_1k": {
                        net: 1000 * float(np.mean(n)) / float(real.mean())
                        for net, n in data["adam_steps"].items()
                    },
                }
            )
    return rows


def tests(rows: list[dict]) -> list[dict] | None:
    """The plan's comparisons with Holm's correction; None until every one can be made."""
    scores = {(r["env"], r["arm"]): r["scores"] for r in rows}
    return stats.planned_tests(scores, ENVS, COMPARISONS, ALPHA)


def section(rows: list[dict], found: list[dict] | None) -> str:
    lines = [
        "## The branched headline on fresh seeds (confirmatory)",
        "",
        "Planned before the runs in `experiments/plans/headline.md`: seeds 10-19, 200,000 "
        "real steps, the `branched` preset; the score is each seed's greedy return in "
        f"gymnasium ({EPISODES} episodes, `ldn-jax eval`); IQM [95% bootstrap interval]. "
        "Adam steps per 1,000 real steps per net (actor / critic), counted from each run's "
        "optimiser. Code: the commits named per run.",
        "",
    ]
    for env in ENVS:
        mine = [r for r in rows if r["env"] == env]
        if not mine:
            continue
        lines += [
            f"### {env}",
            "",
            "| arm | what | greedy return, gymnasium | trainer's greedy eval | Adam steps "
            "per 1k real (actor / critic) | imagined per real step | training s | code |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in mine:
            steps = r["adam_per_1k"]
            lines.append(
                f"| `{r['arm']}` | {r['name']} | {stats.text(r['score'])} | "
                f"{stats.text(r['trainer'])} | {steps['actor']:.0f} / {steps['critic']:.0f} | "
                f"{r['imagined_per_real']:.2f} | {r['train_seconds']:.0f} | "
                f"{', '.join(r['commits']) or '–'} |"
            )
        lines.append("")
    if found is None:
        lines += ["The tests wait for every arm of both envs (Holm's family is all 16).", ""]
        return "\n".join(lines)
    lines += [
        "### Tests",
        "",
        "One-sided Mann-Whitney, 10 seeds a side; Holm's correction over all 16; "
        f"family-wise alpha {ALPHA}.",
        "",
    ]
    lines += stats.tests_table(found, "env", "P(A > B)", ("A beats B", "not shown at 10 seeds"))
    return "\n".join([*lines, ""])


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    envs = [env for env in ENVS if any(r["env"] == env for r in rows)]
    fig, axes = plt.subplots(1, max(len(envs), 1), figsize=(5 * max(len(envs), 1), 3.2))
    for ax, env in zip(np.atleast_1d(axes), envs, strict=False):
        mine = [r for r in rows if r["env"] == env]
        for i, r in enumerate(mine):
            ax.scatter(r["scores"], [i] * len(r["scores"]), s=12, color="0.6", zorder=2)
            low, high = r["score"]["ci95"] or (r["score"]["iqm"],) * 2
            ax.plot([low, high], [i, i], color="C0", lw=3, zorder=3)
            ax.plot(r["score"]["iqm"], i, "o", color="C0", zorder=4)
        ax.set_yticks(range(len(mine)), [r["arm"] for r in mine])
        ax.set_title(f"{env}, seeds 10-19, 200k steps")
        ax.set_xlabel("greedy return in gymnasium (IQM, 95% interval; dots: seeds)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(args: argparse.Namespace) -> None:
    rows = rows_of(args.results, args.seeds, args.first_seed, args.steps)
    found = tests(rows)
    out = common.out_dir(args.results, "headline")
    plain = [{k: v for k, v in r.items() if k != "gymnasium"} for r in rows]
    common.write_json(out / "headline.json", {"rows": plain, "tests": found})
    (out / "headline.md").write_text(section(rows, found))
    figure(rows, out / "headline.png")
    print(f"wrote {out}/headline.json, headline.md and headline.png")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", default=",".join(ENVS))
    parser.add_argument("--arms", default=",".join(ARMS))
    parser.add_argument("--report", action="store_true", help="train nothing; rebuild the report")
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    # for tests: the plan's seeds, budget and episodes are the defaults
    parser.add_argument("--seeds", type=int, default=SEEDS, help=argparse.SUPPRESS)
    parser.add_argument("--first-seed", type=int, default=FIRST_SEED, help=argparse.SUPPRESS)
    parser.add_argument("--steps", type=int, default=STEPS, help=argparse.SUPPRESS)
    parser.add_argument("--episodes", type=int, default=EPISODES, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    envs, arms = args.envs.split(","), args.arms.split(",")
    unknown = [n for n in envs if n not in ENVS] + [n for n in arms if n not in ARMS]
    if unknown:
        parser.error(f"unknown env or arm: {', '.join(unknown)}")
    if not args.report:
        code = cache.code_version()
        common.compile_cache(args.results)
        for env in envs:
            for arm in arms:
                ensure(env, arm, args, code)
                report(args)
    report(args)
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
