"""The learning degree examined: the readings of eq. 3, and the stopping rules of imagination
side by side (ours; the paper has neither study).

    python -m experiments.paper.stops [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]
        [--study readings|rules] [--envs ENV,...]

`--study` runs one of the two studies (default: both); `--envs` runs the rules study on
those envs only and replaces just their rows in an existing rules.json of the same scale.

Readings (cartpole-v2, MBRL-LDN, K = 1): eq. 3's square reduced by the mean over the 5
outputs (the literal reading, the `paper` preset), by the sum, the mean over a 10-step
window, the sum over outputs and window, the sum over outputs and over a batch of 10 samples
(50 times the literal sigma2: `ld_scale` 10 on the sum; the `paper-fig5` preset, the reading
that matches Figure 5), and the literal one with actions given to the model as forces. Per
reading: mean LD, the share of imagined steps with LD >= 0.9 in the first 10k imagined steps
and after, imagined steps per episode, episodes to threshold against A3C-Model with a
Mann-Whitney test, and Figure 5 redrawn.

Stopping rules (`--stop`; cartpole-v2, inverted_pendulum and halfcheetah): the LD draw (the
literal and the Figure 5 reading, and the ensemble estimator), the M2AC-style mask and the
oracle (each one vmapped program over its parameter), fixed horizons h in {1, 5, 25}, and
none (A3C-Model). Per rule: episodes (CartPole) or env steps (MuJoCo) to threshold, final
moving return, imagined steps per real step and training seconds, each as an IQM with a
bootstrap 95% interval (`ldn_jax.host.stats`), and a verdict against A3C-Model.

Writes DIR/stops/stops.json, stops.csv, readings.png and rules.png; REPORT.md's sections
"The readings of eq. 3" and "Stopping rules" are made from them (`report.py`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from scipy import stats as scipy_stats

from experiments.paper import cache, common, figure5
from ldn_jax.config import Config, validate
from ldn_jax.host import stats
from ldn_jax.host.metrics import run_crossing

READINGS = {
    "literal": ("ldn", {}, "mean over outputs, B = 1 (`paper`)", "mean (paper)"),
    "sum": ("ldn", {"ld_reduce": "sum"}, "sum over outputs, B = 1", "sum"),
    "window": ("ldn", {"ld_window": 10}, "mean over outputs, B = 10", "mean, B = 10"),
    "fig5": (
        "ldn",
        {"ld_reduce": "sum", "ld_window": 10},
        "sum over outputs, B = 10",
        "sum, B = 10",
    ),
    "batch": (
        "ldn",
        {"ld_reduce": "sum", "ld_scale": 10.0},
        "sum over outputs and a 10-sample batch (`paper-fig5`)",
        "sum x 10 samples (paper-fig5)",
    ),
    "force": ("ldn", {"action_encoding": "force"}, "literal, actions as forces", "forces"),
}
"""Reading -> (algo, model fields, how the report names it, its figure label)."""

RULES = {
    "ld": ("ldn", {}, (), "LD draw, literal reading"),
    "ld-fig5": ("ldn", {"ld_reduce": "sum", "ld_scale": 10.0}, (), "LD draw, Figure 5 reading"),
    "ld-ensemble": ("ldn", {"ld": "ensemble"}, (), "LD draw, ensemble disagreement"),
    "m2ac": ("a2c-model", {"stop": "m2ac"}, ("stop.m2ac_keep", (0.5, 0.75, 0.9)), "M2AC mask"),
    "horizon-1": ("a2c-model", {"stop": "horizon", "horizon": 1}, (), "horizon h = 1"),
    "horizon-5": ("a2c-model", {"stop": "horizon", "horizon": 5}, (), "horizon h = 5"),
    "horizon-25": ("a2c-model", {"stop": "horizon", "horizon": 25}, (), "horizon h = 25"),
    "oracle": (
        "a2c-model",
        {"stop": "oracle"},
        ("stop.oracle_error", (0.005, 0.01, 0.02)),
        "oracle on the true error",
    ),
    "none": ("a2c-model", {}, (), "none (A3C-Model)"),
}
"""Rule -> (algo, model fields, the swept parameter and its values or (), its name)."""

RULE_ENVS = ("cartpole-v2", "inverted_pendulum", "halfcheetah")

ORACLE_ON_MUJOCO = False
"""The study runs the oracle on CartPole only: it can also run on inverted_pendulum and
halfcheetah (their observation is their state), but the study was set before that, and on
halfcheetah its three points would be 30 more runs of 1M steps."""
"""The envs of the rules study where a scale budgets them (CartPole: the scale's LD env)."""

STUDY_THRESHOLDS = {"inverted_pendulum": 500.0, "halfcheetah": 1000.0}
"""Moving-return thresholds of the rules study where the env has none of the paper's
(MuJoCo), chosen before the study ran: at the CPU scale's 300k steps inverted_pendulum's seeds
peak at 770-930; halfcheetah's default `ldn` run (30 runs, 1M steps) ends at a mean of 1,091
(README), so about half of a rule's seeds cross 1,000."""

RULE_BUDGETS = {"halfcheetah": {"steps": 1_000_000}}
"""Env steps per seed of the rules study where the scale's MuJoCo budget is shorter (the CPU
scale's 200k halfcheetah steps, where A2C still ends between -200 and 400: nothing to compare
imagination on). 1M is the task's default `--steps`."""

RULE_SEEDS = 10
"""Seeds of each MuJoCo run of the rules study where the scale's MuJoCo runs take fewer (the
CPU scale's 5): the study compares rules at 10 seeds everywhere (the smoke scale keeps its
own)."""

SMOKE = {"readings": ("literal",), "rules": ("m2ac", "oracle", "none")}
"""The smoke scale's (tests') share of the study: its code paths, on the LD env only."""
EARLY = figure5.EARLY


def config_of(scale: common.Scale, env: str, algo: str, model: dict, sweep=()) -> Config:
    config = common.run_config(scale, env, algo, (1.0,), **model)
    if env in common.MUJOCO and scale.name != "smoke" and config.seeds < RULE_SEEDS:
        config = validate(dataclasses.replace(config, seeds=RULE_SEEDS))
    steps = RULE_BUDGETS.get(env, {}).get("steps")
    if scale.name != "smoke" and steps and config.steps is not None and config.steps < steps:
        config = validate(dataclasses.replace(config, steps=steps))
    if sweep:
        config = validate(dataclasses.replace(config, sweep=(sweep,)))
    return config


def dir_of(results: Path, scale: common.Scale, config: Config, name: str) -> Path:
    """The Table 2 run's directory where the config is one (the literal reading, the
    ensemble and A3C-Model), else `stops-ENV-NAME` (every MuJoCo rule where `RULE_SEEDS`
    exceeds the scale's MuJoCo seeds: the tables' runs keep theirs)."""
    plain = cache.run_dir(results, scale, config)
    own_budget = config.steps != scale.mujoco_budgets.get(config.env, {}).get("steps")
    if config.env in common.MUJOCO and (config.seeds != scale.mujoco_seeds or own_budget):
        return results / "runs" / scale.name / f"stops-{config.env}-{name}"
    if not config.sweep and config.stop.rule is None and name in ("literal", "ld", "none"):
        return plain
    if name == "ld-ensemble":
        return plain
    name = {"ld-fig5": "batch"}.get(name, name)  # one run, both studies
    return cache.runs_of(results, scale, config.env) / f"stops-{config.env}-{name}"


def ensure(results, scale, env, name, algo, model, sweep=()) -> dict | None:
    """`{config, dir, summary}` of one study run, trained if not cached; None where this
    scale does not run the env, the rule cannot run there, or the study leaves it out (the
    oracle on MuJoCo: `ORACLE_ON_MUJOCO`)."""
    if name == "oracle" and env in common.MUJOCO and not ORACLE_ON_MUJOCO:
        print(f"  {env} {name}: not run (the study runs the oracle on CartPole)", flush=True)
        return None
    try:
        config = config_of(scale, env, algo, model, sweep)
    except ValueError as error:
        print(f"  {env} {name}: not run ({error})", flush=True)
        return None
    out = dir_of(results, scale, config, name)
    return {"config": config, "dir": out, "summary": cache.ensure_run(config, out)}


def _points(entry: dict) -> list[dict]:
    """One record per point of a study run: its label, the seeds' per-run values and the
    run's history at that point."""
    config, summary = entry["config"], entry["summary"]
    history = cache.load_history(entry["dir"])
    budget = config.episodes if config.steps is None else config.steps
    unit = "episodes" if config.steps is None else "env_steps"
    out = []
    for index, point in enumerate(config.points):
        swept = {name: point[name] for name, _ in config.sweep}
        runs = [r for r in summary["runs"] if r.get("sweep", {}) == swept]
        runs = sorted(runs, key=lambda r: r["seed"])
        at = {name: values[index] for name, values in history.items()}
        threshold = config.resolved_threshold
        reached = [r[f"{unit}_to_threshold"] for r in runs]
        seconds = [r["seconds_to_threshold"] for r in runs]
        if threshold is None and config.env in STUDY_THRESHOLDS:
            threshold = STUDY_THRESHOLDS[config.env]
            reached = [steps_to(at, seed, threshold) for seed in range(config.seeds)]
            seconds = [None] * config.seeds  # wall time per episode is not recorded
        out.append(
            {
                "point": swept,
                "unit": unit,
                "threshold": threshold,
                "budget": budget,
                "to_threshold": reached,
                "censored": [budget + 1 if v is None else v for v in reached],
                "seconds_to_threshold": seconds,
                "final_moving_return": at["moving_return"][:, -1].tolist(),
                "imagined_per_real_step": (
                    at["imagined_steps"][:, -1] / np.maximum(at["env_steps"][:, -1], 1)
                ).tolist(),
                "imagined_per_episode": (
                    at["imagined_steps"][:, -1] / np.maximum(at["episodes"][:, -1], 1)
                ).tolist(),
                "ld_mean": _ld_mean(at),
                "history": at,
                "program_seconds": summary["train_seconds"],
                "points": len(config.points),
            }
        )
    return out


def steps_to(at: dict, seed: int, threshold: float) -> int | None:
    """Env steps until one seed's moving return first reaches `threshold` (as summary.json
    counts them, `threshold_crossing`); None if it never does."""
    crossing = run_crossing(at, (seed,), threshold)
    return None if crossing is None else crossing[1]


def _ld_mean(at: dict) -> float | None:
    """The mean LD over every imagined step of every seed (each iteration's mean weighted
    by its imagined steps)."""
    counts = np.diff(at["imagined_steps"], axis=-1, prepend=0).astype(float)
    ld = np.nan_to_num(at["ld_mean"], nan=0.0)
    total = counts.sum()
    return float((ld * counts).sum() / total) if total else None


def _summarise(point: dict, baseline: dict | None) -> dict:
    """A point's estimates, and against the baseline (A3C-Model): the probability that a
    seed reaches the threshold sooner (not reached: the budget + 1), and Mann-Whitney's p."""
    row = {
        "point": point["point"],
        "reached": sum(v is not None for v in point["to_threshold"]),
        "runs": len(point["to_threshold"]),
        "to_threshold": stats.estimate([v for v in point["to_threshold"] if v is not None]),
        "final_moving_return": stats.estimate(point["final_moving_return"]),
        "imagined_per_real_step": stats.estimate(point["imagined_per_real_step"]),
        "imagined_per_episode": stats.estimate(point["imagined_per_episode"]),
        "seconds_to_threshold": stats.estimate(
            [v for v in point["seconds_to_threshold"] if v is not None]
        ),
        "ld_mean": point["ld_mean"],
        "program_seconds": point["program_seconds"],
        "points_in_program": point["points"],
        "seeds": {
            "to_threshold": point["to_threshold"],
            "final_moving_return": point["final_moving_return"],
        },
    }
    if baseline is not None:
        x, y = point["censored"], baseline["censored"]
        better = stats.improvement(x, y, lower_is_better=True)
        p = float(scipy_stats.mannwhitneyu(x, y).pvalue) if x != y else 1.0
        low, high = better["ci95"] or (better["probability"],) * 2
        verdict = "helps" if low > 0.5 else "hurts" if high < 0.5 else "no clear difference"
        row["vs_a3c_model"] = {"p_better": better, "mann_whitney_p": p, "verdict": verdict}
    return row


def _label(name: str, point: dict) -> str:
    values = " ".join(f"{n.split('.')[-1]}={v:g}" for n, v in point.items())
    return f"{name} {values}".strip()


def _chosen(table: dict, study: str, scale: common.Scale) -> dict:
    if scale.name != "smoke":
        return table
    return {name: entry for name, entry in table.items() if name in SMOKE[study]}


def readings_study(results: Path, scale: common.Scale) -> dict:
    env = scale.ld_env
    baseline = ensure(results, scale, env, "none", *RULES["none"][:2])
    base = _points(baseline)[0]
    rows, histograms = {}, {}
    for name, (algo, model, title, label) in _chosen(READINGS, "readings", scale).items():
        entry = ensure(results, scale, env, name, algo, model)
        (point,) = _points(entry)
        rows[name] = {"title": title, "model": model, **_summarise(point, base)}
        histograms[label] = figure5.histograms(point_history(point))
        for key in ("first_10k_fraction_ld_at_least_0.9", "after_10k_fraction_ld_at_least_0.9"):
            rows[name][key] = histograms[label][key]
    rows["a3c-model"] = {"title": "A3C-Model (no stop)", "model": {}, **_summarise(base, None)}
    out = common.out_dir(results, "readings")
    figure5.figure(histograms, env, out / "readings.png")
    record = {
        **common.scale_record(scale),
        "env": env,
        "k": 1.0,
        "early_imagined_steps": EARLY,
        "unit": base["unit"],
        "readings": rows,
    }
    common.write_json(out / "readings.json", record)
    print(f"wrote {out}/readings.json, readings.png")
    return record


def point_history(point: dict) -> dict:
    """A point's history shaped `[1, S, N, ...]` as `figure5.histograms` reads it."""
    return {name: value[None] for name, value in point["history"].items()}


def rules_study(results: Path, scale: common.Scale, only: tuple[str, ...] = ()) -> dict:
    """Every rule on each env of this scale; with `only`, those envs' rules, and the other
    envs' rows as an earlier rules.json of this scale holds them (none where it has none)."""
    envs_here = [scale.ld_env, *[e for e in RULE_ENVS if e in scale.mujoco_budgets]]
    if scale.name == "smoke":
        envs_here = envs_here[:1]
    record = {**common.scale_record(scale), "k": 1.0, "envs": {}}
    out = common.out_dir(results, "rules")
    kept = {}
    if only:
        unknown = sorted(set(only) - set(envs_here))
        if unknown:
            raise SystemExit(f"stops.py: --envs {','.join(unknown)}: this scale's rules study "
                             f"runs {', '.join(envs_here)}")  # fmt: skip
        stored = _stored_envs(out / "rules.json", scale)
        kept = {env: rows for env, rows in stored.items() if env not in only}
    for env in envs_here:
        if env in kept:
            record["envs"][env] = kept[env]
        elif not only or env in only:
            record["envs"][env] = env_rules(results, scale, env)
    common.write_json(out / "rules.json", record)
    common.write_csv(
        out / "rules.csv",
        [_csv_row(env, r) for env, d in record["envs"].items() for r in d["rows"] if "label" in r],
    )
    rules_figure(record, out / "rules.png")
    print(f"wrote {out}/rules.json, rules.csv, rules.png")
    return record


def _stored_envs(path: Path, scale: common.Scale) -> dict:
    """The per-env records of an earlier rules.json of this scale (none if there is none)."""
    if not path.exists():
        return {}
    stored = json.loads(path.read_text())
    return stored["envs"] if stored.get("scale") == scale.name else {}


def env_rules(results: Path, scale: common.Scale, env: str) -> dict:
    """One env's panel of the rules study: every rule's run (trained if not cached) and its
    rows against A3C-Model."""
    entries = {
        name: ensure(results, scale, env, name, algo, model, sweep)
        for name, (algo, model, sweep, _) in _chosen(RULES, "rules", scale).items()
    }
    base = _points(entries["none"])[0]
    rows = []
    for name, entry in entries.items():
        if entry is None:
            rows.append({"rule": name, "title": RULES[name][3], "status": "not run here"})
            continue
        for point in _points(entry):
            row = _summarise(point, None if name == "none" else base)
            rows.append(
                {"rule": name, "title": RULES[name][3], "label": _label(name, row["point"]), **row}
            )
    return {
        "unit": base["unit"],
        "threshold": base["threshold"],
        "budget": base["budget"],
        "seeds": entries["none"]["config"].seeds,
        "rows": rows,
    }


def _csv_row(env: str, row: dict) -> dict:
    flat = {"env": env, "rule": row["label"], "reached": row["reached"], "runs": row["runs"]}
    for name in (
        "to_threshold",
        "final_moving_return",
        "imagined_per_real_step",
        "seconds_to_threshold",
    ):
        flat[f"{name}_iqm"] = row[name]["iqm"]
        flat[f"{name}_ci95"] = row[name]["ci95"]
    versus = row.get("vs_a3c_model")
    flat["p_better_than_a3c_model"] = versus["p_better"]["probability"] if versus else None
    flat["verdict"] = versus["verdict"] if versus else "baseline"
    return flat


def rules_figure(record: dict, path: Path) -> None:
    """Per env: each rule's IQM and 95% interval of steps or episodes to threshold, and of
    imagined steps per real step."""
    envs_here = list(record["envs"])
    fig, axes = plt.subplots(
        len(envs_here), 2, figsize=(11, 0.4 * 14 * len(envs_here) + 1), dpi=120, squeeze=False,
        layout="constrained",
    )  # fmt: skip
    for row_axes, env in zip(axes, envs_here, strict=True):
        data = record["envs"][env]
        rows = [r for r in data["rows"] if "label" in r]
        # The steps panel's IQM is over the seeds that reached the threshold: say how many.
        labels = [f"{r['label']} ({r['reached']}/{r['runs']})" for r in rows]
        y = np.arange(len(rows))[::-1]
        for ax, metric, xlabel in (
            (row_axes[0], "to_threshold", f"{data['unit'].replace('_', ' ')} to threshold"),
            (row_axes[1], "imagined_per_real_step", "imagined steps per real step"),
        ):
            for yi, r in zip(y, rows, strict=True):
                value = r[metric]
                if value["iqm"] is None:
                    continue
                low, high = value["ci95"] or (value["iqm"],) * 2
                color = {"helps": "tab:green", "hurts": "tab:red"}.get(
                    r.get("vs_a3c_model", {}).get("verdict"), "tab:blue"
                )
                ax.errorbar(value["iqm"], yi, xerr=[[value["iqm"] - low], [high - value["iqm"]]],
                            fmt="o", color=color, capsize=3)  # fmt: skip
            ax.set_yticks(y, labels, fontsize=8)
            if metric == "to_threshold" and data["unit"] == "env_steps":
                ax.xaxis.set_major_formatter(lambda v, _: f"{v / 1000:g}k")
            ax.set_xlabel(f"{xlabel} (IQM, 95% CI)")
            ax.grid(axis="x", alpha=0.3)
        row_axes[0].set_title(
            f"{env}, against A3C-Model: green helps, red hurts, blue no clear difference",
            fontsize=9,
        )
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    own = argparse.ArgumentParser(add_help=False)
    own.add_argument("--study", choices=("readings", "rules"))
    own.add_argument("--envs", type=lambda text: tuple(text.split(",")), default=())
    args, rest = own.parse_known_args(argv)
    scale, results = common.parse_args(rest, __doc__)
    if args.study != "rules":
        readings_study(results, scale)
    if args.study != "readings":
        rules_study(results, scale, args.envs)
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
