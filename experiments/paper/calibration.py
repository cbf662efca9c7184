"""LD calibration: does the learning degree know when the model is wrong?

    python -m experiments.paper.calibration [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

MBRL-LDN on cartpole-v2 (the Table 2 run's config and seeds, K = 1) is analysed after a few
numbers of real episodes (cpu: 200, 800, 2000): the earlier points by retraining that config
in-process and stopping there, the last from the Table 2 run's final checkpoint. At each point,
per seed, `experiments.paper.shadow.shadow_rollouts` plays imagined episodes in M1 with the real
env alongside, and `fit_ensemble` fits E extra models on the real buffer for the
ensemble-disagreement learning degree. Reported: Pearson and Spearman correlation of LD (and of
sigma2 and the disagreement) with the true one-step and compounding errors, the ROC AUC of each
score for "error above its median", and the imagined-horizon distributions. Then the same run
is trained with the ensemble's learning degree (`--ld ensemble`) and compared with it.

Expected if LD tracked model quality: error falls as LD rises (negative correlations, AUC of
LD below 0.5, i.e. AUC of 1 - LD above 0.5); disagreement should rise with error (AUC above
0.5). Writes calibration.json and calibration.png into DIR/calibration/.
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import matplotlib.pyplot as plt
import numpy as np

from experiments.paper import cache, common
from experiments.paper import shadow as cal
from ldn_jax.trainer import Trainer

ALGO = "ldn"


def analyse(trainer: Trainer, states, scale: common.Scale, key) -> tuple[cal.ShadowSteps, dict]:
    """Shadow rollouts and ensemble fit for every seed of a K = 1 batch `[1, S]`.

    Returns the steps `[S, T, N]` (numpy) and the ensemble's record.
    """
    states = jax.tree.map(lambda x: x[0], states)
    rounds = int(np.asarray(states.iteration).max())
    k = trainer.k_values()[0]

    def per_seed(state, key):
        k_fit, k_play = jax.random.split(key)
        members, losses = cal.fit_ensemble(trainer, state, k_fit, scale.ensemble_members, rounds)
        steps = cal.shadow_rollouts(
            trainer,
            state,
            k_play,
            scale.calibration_episodes,
            k,
            ensemble=members,
            error_scale=losses.mean(),
        )
        return steps, losses

    seeds = states.iteration.shape[0]
    steps, losses = jax.device_get(
        jax.jit(jax.vmap(per_seed))(states, jax.random.split(key, seeds))
    )
    ensemble = {
        "members": scale.ensemble_members,
        "fit_steps_per_member": rounds * trainer.config.fit.updates,
        "final_loss_mean": float(np.mean(losses)),
    }
    return steps, ensemble


def _pool(steps: cal.ShadowSteps) -> cal.ShadowSteps:
    """`[S, T, N]` -> `[T, S * N]`."""
    return jax.tree.map(lambda x: np.moveaxis(x, 0, 1).reshape(x.shape[1], -1), steps)


def _seed(steps: cal.ShadowSteps, seed: int) -> cal.ShadowSteps:
    return jax.tree.map(lambda x: x[seed], steps)


def point_record(steps: cal.ShadowSteps, episodes: int, source: str, ensemble: dict) -> dict:
    pooled = _pool(steps)
    per_seed = []
    for seed in range(steps.ld.shape[0]):
        summary = cal.calibration_summary(_seed(steps, seed))
        one_step = summary["imagined"]["one_step_error"]
        per_seed.append(
            {
                "seed": seed,
                "ld_spearman": one_step["ld"]["spearman"],
                "ld_auc": one_step["ld"]["auc_error_above_median"],
                "disagreement_spearman": one_step["disagreement"]["spearman"],
                "disagreement_auc": one_step["disagreement"]["auc_error_above_median"],
                "ld_rule_horizon_mean": summary["horizons"]["ld_rule"]["mean"],
            }
        )
    live = pooled.live.astype(bool)
    error = pooled.one_step_error
    keep = live & np.isfinite(error)
    return {
        "episodes": episodes,
        "source": source,
        "ensemble": ensemble,
        "pooled": cal.calibration_summary(pooled),
        "per_seed": per_seed,
        "binned_one_step_error": {
            score: cal.binned_error(getattr(pooled, score)[keep], error[keep])
            for score in ("ld", "disagreement")
        },
    }


def training_row(config, run: Path, summary: dict) -> dict:
    """What one estimator does in training: episodes to threshold, LD, imagined steps."""
    history = cache.load_history(run)
    return {
        "ld": config.model.ld,
        "ensemble_members": config.model.ensemble if config.model.ld == "ensemble" else None,
        **common.describe([r["episodes_to_threshold"] for r in summary["runs"]]),
        "episodes_to_threshold": [r["episodes_to_threshold"] for r in summary["runs"]],
        "final_moving_return": common.describe([r["final_moving_return"] for r in summary["runs"]]),
        "ld_mean_last_iterations": float(np.nanmean(history["ld_mean"][0, :, -10:])),
        "imagined_steps_per_real_step": float(
            history["imagined_steps"][0, :, -1].sum() / history["env_steps"][0, :, -1].sum()
        ),
        "train_seconds": summary["train_seconds"],
        "compile_seconds": summary["compile_seconds"],
    }


def figure(points: list[dict], path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(15, 4), dpi=120)
    for point in points:
        label = f"{point['episodes']} episodes"
        for ax, score in zip(axes[:2], ("ld", "disagreement"), strict=True):
            b = point["binned_one_step_error"][score]
            ax.plot(b["score_mean"], b["error_mean"], "o-", ms=3, label=label)
        horizons = point["pooled"]["horizons"]
        edges = horizons["ld_rule"]["bin_edges"]
        for rule, style in (("ld_rule", "-"), ("predicted_termination", ":")):
            counts = np.asarray(horizons[rule]["counts"], float)
            axes[2].step(
                range(len(counts)),
                counts / max(counts.sum(), 1),
                style,
                where="mid",
                color=axes[0].lines[-1].get_color(),
                label=f"{label}, {rule.replace('_', ' ')}",
            )
    axes[0].set_xlabel("learning degree (M1 vs M0), quantile bins")
    axes[1].set_xlabel("ensemble disagreement, quantile bins")
    axes[1].set_xscale("symlog", linthresh=1e-9)
    for ax in axes[:2]:
        ax.set_ylabel("mean one-step error ||M1(s,a) - env(s,a)||")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[2].set_xticks(range(len(edges)), [f"{e}" for e in edges[:-1]] + [f"{edges[-1]}+"])
    axes[2].set_xlabel("imagined episode length (bin lower edge)")
    axes[2].set_ylabel("fraction of imagined episodes")
    axes[2].legend(fontsize=6)
    axes[2].grid(alpha=0.3)
    fig.suptitle("Does LD know when the model is wrong? (all imagined steps, seeds pooled)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    config = common.run_config(scale, scale.ld_env, ALGO)
    run = cache.run_dir(results, scale, config)
    training = [training_row(config, run, cache.ensure_run(config, run))]
    # The same run trained with the ensemble's learning degree (`--ld ensemble`).
    ensemble_config = common.run_config(scale, scale.ld_env, ALGO, ld="ensemble")
    ensemble_run = cache.run_dir(results, scale, ensemble_config)
    summary = cache.ensure_run(ensemble_config, ensemble_run)
    training.append(training_row(ensemble_config, ensemble_run, summary))
    reference = cache.load_history(run)["moving_return"][0]  # [S, N]

    trainer = Trainer(config)
    points = []
    states = trainer.init_batch()
    chunk = trainer.batched_chunk()
    k = trainer.k_values()
    for target in scale.calibration_points[:-1]:
        while int(np.asarray(states.episodes).min()) < target:
            states, _ = chunk(states, k)
        episodes = int(np.asarray(states.episodes).min())
        iteration = int(np.asarray(states.iteration).min())
        same = np.allclose(
            np.asarray(states.moving_return[0]), reference[:, iteration - 1], equal_nan=True
        )
        steps, ensemble = analyse(trainer, states, scale, jax.random.key(1000 + target))
        source = "in-process retraining of the Table 2 run's config, stopped here"
        source += " (its moving returns match that run's)" if same else " (DIFFERS from that run)"
        points.append(point_record(steps, episodes, source, ensemble))
        print(f"analysed {episodes} episodes", flush=True)
    del states

    _, trainer, states = cal.load_run(run)
    episodes = int(np.asarray(states.episodes).min())
    steps, ensemble = analyse(trainer, states, scale, jax.random.key(1000 + episodes))
    points.append(point_record(steps, episodes, "the Table 2 run's final checkpoint", ensemble))

    out = common.out_dir(results, "calibration")
    record = {
        **common.scale_record(scale),
        "env": scale.ld_env,
        "algo": ALGO,
        "k": 1.0,
        "imagined_episodes_per_seed": scale.calibration_episodes,
        "expected": "if LD tracks model quality: error falls as LD rises (negative "
        "correlation, AUC of LD < 0.5, AUC of 1 - LD = 1 - AUC of LD > 0.5); error rises "
        "with the ensemble disagreement (AUC > 0.5)",
        "errors": "one_step_error: ||M1(s_t, a_t) - env(s_t, a_t)|| on the next state from the "
        "imagined state; compounding_error: ||imagined s_t+1 - real s_t+1|| along the real "
        "trajectory from the same start with the same actions (while that one is running)",
        "populations": "imagined: every imagined step before predicted termination (LD not "
        "applied); ld_rule: the steps before the LD draw stops the episode",
        "ensemble_ld": "2 sigmoid(-K d / e), d = 1/2 variance over members, mean over [s', r], "
        "e = the members' mean final fit MSE (the estimator of `--ld ensemble`)",
        "points": points,
        "training": training,
    }
    common.write_json(out / "calibration.json", record)
    figure(points, out / "calibration.png")
    print(f"wrote {out}/calibration.json, calibration.png")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
