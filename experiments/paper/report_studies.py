"""REPORT.md's sections on the learning degree beyond the paper: its calibration against
the model's true error, the readings of eq. 3, and the stopping rules side by side."""

from __future__ import annotations

from experiments.paper.report_format import (
    TITLES,
    Section,
    Table,
    budget,
    fmt,
    iqm,
    mann_whitney,
    pm,
)
from ldn_jax.host import stats as iqm_stats


def calibration_section(data: dict) -> Section:
    intro = (
        f"MBRL-LDN on {data['env']}, K = 1, {data['seeds']} seeds, "
        f"{data['imagined_episodes_per_seed']} imagined episodes per seed at each point, played "
        "in M1 with the sampled policy from fresh initial states while the real JAX CartPole is "
        "stepped alongside (`experiments/paper/shadow.py`). Errors: " + data["errors"] + ". Steps: "
        "every imagined step before predicted termination (the LD stop not applied; the "
        "compounding error only while the real shadow episode runs). Expected "
        + data["expected"]
        + ". The ensemble: E models of M1's architecture "
        "fitted from fresh initialisations on the final real buffer, as many steps as M1; its "
        "learning degree is "
        + data["ensemble_ld"]
        + ". ![calibration](calibration/calibration.png)"
    )
    num = lambda v: "–" if v is None else f"{v:.3f}"
    scores = Table(
        [
            "episodes",
            "steps",
            "Spearman LD vs 1-step error",
            "AUC of LD",
            "AUC of 1 - LD",
            "Pearson LD vs 1-step",
            "Spearman LD vs compounding",
            "Spearman disagreement vs 1-step",
            "AUC of disagreement",
            "mean LD",
            "mean sigma2",
            "reward's share of sigma2",
        ]
    )
    for p in data["points"]:
        im = p["pooled"]["imagined"]
        one, comp = im["one_step_error"], im["compounding_error"]
        auc = one["ld"]["auc_error_above_median"]
        scores.rows.append(
            [
                f"{p['episodes']:,}",
                f"{im['steps']:,}",
                num(one["ld"]["spearman"]),
                num(auc),
                num(None if auc is None else 1 - auc),
                num(one["ld"]["pearson"]),
                num(comp["ld"]["spearman"]),
                num(one["disagreement"]["spearman"]),
                num(one["disagreement"]["auc_error_above_median"]),
                num(im["ld"]["mean"]),
                num(im["ld"].get("sigma2_mean")),
                num(im["ld"].get("sigma2_reward_share")),
            ]
        )
    horizons_intro = (
        "Imagined horizons (episode lengths in M1) under three stopping rules: predicted "
        "termination only (A3C-Model), the LD draw (MBRL-LDN), and the same draw with the "
        "ensemble's learning degree:"
    )
    horizons = Table(
        [
            "episodes",
            "predicted termination: mean / median / p90",
            "LD rule: mean / median / p90 / max",
            "ensemble rule: mean / median",
            "mean ensemble LD",
            "ensemble final loss",
        ]
    )
    for p in data["points"]:
        h = p["pooled"]["horizons"]
        ens_ld = p["pooled"]["imagined"].get("ensemble_ld", {}).get("mean")
        a, b, c = h["predicted_termination"], h["ld_rule"], h["ensemble_rule"]
        horizons.rows.append(
            [
                f"{p['episodes']:,}",
                f"{a['mean']:.1f} / {a['median']:.0f} / {a['p90']:.0f}",
                f"{b['mean']:.2f} / {b['median']:.0f} / {b['p90']:.0f} / {b['max']}",
                f"{c['mean']:.1f} / {c['median']:.0f}",
                num(ens_ld),
                f"{p['ensemble']['final_loss_mean']:.2e}",
            ]
        )
    sources = "; ".join(f"{p['episodes']:,}: {p['source']}" for p in data["points"])
    blocks = [intro, scores, horizons_intro, horizons, f"Sources of the states: {sources}."]
    training = data.get("training", [])
    if training:
        blocks.append(
            "Training with each estimator (the same config and seeds; `--ld ensemble` with "
            f"E = {training[-1]['ensemble_members']} members):"
        )
        header = ["learning degree", "episodes to threshold: mean ± s.d.", "min", "max"]
        header += ["reached", "mean LD, last 10 iterations", "imagined steps per real step"]
        header.append("train s")
        rows = [
            [
                "M1 vs M0 (the paper)" if r["ld"] == "m0" else "ensemble disagreement",
                pm(r["mean"], r["sd"]),
                fmt(r["min"], 0),
                fmt(r["max"], 0),
                f"{r['reached']}/{r['runs']}",
                f"{r['ld_mean_last_iterations']:.3f}",
                f"{r['imagined_steps_per_real_step']:.2f}",
                f"{r['train_seconds']:.0f}",
            ]
            for r in training
        ]
        blocks.append(Table(header, rows))
    title = TITLES["calibration"]
    return Section(title, blocks, calibration_findings(data))


def calibration_findings(data: dict) -> list[str]:
    training = data.get("training", [])
    findings = []
    last = data["points"][-1]
    one = last["pooled"]["imagined"]["one_step_error"]
    auc = one["ld"]["auc_error_above_median"]
    if auc is None:
        return findings
    if auc < 0.45:
        how = "LD is lower where the model is more wrong, as the method assumes"
    elif auc > 0.55:
        how = "LD is HIGHER where the model is more wrong, the opposite of the method's premise"
    else:
        how = "LD barely separates high-error from low-error steps"
    d_auc = one["disagreement"]["auc_error_above_median"]
    ens = ""
    if d_auc is not None:
        flags = "it flags high error" if d_auc > 0.55 else "it does not flag high error"
        ens = f"; the ensemble disagreement's AUC is {d_auc:.3f} ({flags})"
    h = last["pooled"]["horizons"]["ld_rule"]
    for population, where in (
        ("ld_rule", "the steps MBRL-LDN imagines"),
        ("imagined", "whole imagined episodes (run to predicted termination)"),
    ):
        ld = last["pooled"][population]["ld"]
        if not ld.get("sigma2_mean"):
            continue
        # tanh(K sigma2 / 2) = 0.9 at K sigma2 = 2 artanh(0.9) = 2.944.
        findings.append(
            f"Why LD stays low ({where}, {last['episodes']:,} episodes): M1 deviates from "
            f"M0 by sigma2 = {ld['sigma2_mean']:.3f} on average, "
            f"{100 * ld['sigma2_reward_share']:.0f}% of it in the reward output; LD = "
            f"tanh(K sigma2 / 2) averages {ld['mean']:.3f}, so a step stops with "
            f"probability about {1 - ld['mean']:.2f}. LD = 0.9 at that sigma2 would need "
            f"K = {2.944 / ld['sigma2_mean']:.0f}."
        )
    ens_ld = last["pooled"]["imagined"].get("ensemble_ld", {}).get("mean")
    if ens_ld is not None:
        e = last["pooled"]["horizons"]["ensemble_rule"]
        findings.append(
            f"Ensemble learning degree (the estimator of `--ld ensemble`, K = 1, "
            f"disagreement relative to the members' fit error) at {last['episodes']:,} "
            f"episodes: it averages {ens_ld:.3f} over imagined steps (M1-vs-M0 LD: "
            f"{last['pooled']['imagined']['ld']['mean']:.3f}), so its rule imagines "
            f"{e['mean']:.1f} steps per episode on average (median {e['median']:.0f}) "
            f"against the LD rule's {h['mean']:.2f}."
        )
    rows = {r["ld"]: r for r in training}
    if {"m0", "ensemble"} <= set(rows) and rows["m0"]["mean"] and rows["ensemble"]["mean"]:
        ours, trained = rows["m0"], rows["ensemble"]
        test = mann_whitney(ours["episodes_to_threshold"], trained["episodes_to_threshold"])
        cost = trained["train_seconds"] / max(ours["train_seconds"], 1e-9)
        per_step = "imagined_steps_per_real_step"
        findings.append(
            f"Training with the ensemble learning degree on {data['env']}: "
            f"{trained['mean']:.0f} ± {trained['sd'] or 0:.0f} episodes to threshold "
            f"({trained['reached']}/{trained['runs']} reached) vs {ours['mean']:.0f} ± "
            f"{ours['sd'] or 0:.0f} with M1 vs M0 ({test}); it imagines "
            f"{trained[per_step]:.2f} steps per real step (M1 vs M0: "
            f"{ours[per_step]:.2f}) at {cost:.1f}x the training time."
        )
    findings.append(
        f"LD calibration at {last['episodes']:,} episodes: AUC of LD for high one-step error "
        f"{auc:.3f} (1 - LD: {1 - auc:.3f}): {how}{ens}. The LD rule's imagined episodes "
        f"last {h['mean']:.2f} steps on average (median {h['median']:.0f})."
    )
    return findings


def _versus(row: dict) -> tuple[str, str]:
    """P(better than A3C-Model) with its interval and Mann-Whitney's p, and the verdict."""
    versus = row.get("vs_a3c_model")
    if versus is None:
        return "(baseline)", "baseline"
    p_better = iqm_stats.improvement_text(versus["p_better"])
    return f"{p_better}, p = {versus['mann_whitney_p']:.2g}", versus["verdict"]


VERDICTS = ("helps", "hurts", "no clear difference")


def readings_section(data: dict) -> Section:
    unit = data["unit"].replace("_", " ")
    intro = (
        f"{data['env']}, MBRL-LDN, K = 1, {data['seeds']} seeds, {budget(data)} each "
        "(`experiments/paper/stops.py`). Eq. 3's square (M1 - M0)^2 reduced over the model's "
        "5 outputs by the mean (the literal reading, the `paper` preset) or the sum, over the "
        "step's own prediction or a window of the episode's last 10 imagined steps (the "
        'paper: "the input size is 10 batches"), or over a batch of 10 samples (the sum '
        "times 10: `ld_scale`), and the literal reading with the model taking actions as "
        "forces (Table 1) instead of one-hot. Against A3C-Model (no stop): "
        "the probability that a seed of the reading reaches the threshold sooner (a seed "
        "that never does counts as the budget + 1), with its bootstrap 95% interval, and "
        "the Mann-Whitney p. Figure 5 redrawn for each reading: "
        "![readings](readings/readings.png)"
    )
    header = ["reading", "mean LD", "LD >= 0.9, first 10k imagined steps", "after 10k"]
    header += ["imagined steps per episode", "reached", f"{unit} to threshold: IQM [95% CI]"]
    header += ["mean ± s.d.", "vs A3C-Model: P(sooner), p", "verdict"]
    pct = lambda v: "–" if v is None else f"{100 * v:.1f}%"
    rows = []
    for r in data["readings"].values():
        sooner, verdict = _versus(r)
        t = r["to_threshold"]
        rows.append(
            [
                r["title"],
                "–" if r["ld_mean"] is None else f"{r['ld_mean']:.3f}",
                pct(r.get("first_10k_fraction_ld_at_least_0.9")),
                pct(r.get("after_10k_fraction_ld_at_least_0.9")),
                iqm(r["imagined_per_episode"], 1),
                f"{r['reached']}/{r['runs']}",
                iqm(t),
                pm(t["mean"], t["sd"], 0),
                sooner,
                verdict,
            ]
        )
    findings = []
    readings = {n: r for n, r in data["readings"].items() if n != "a3c-model"}
    if readings:
        near_one = max(readings, key=lambda n: readings[n]["ld_mean"] or 0.0)
        best = min(readings, key=lambda n: readings[n]["to_threshold"]["iqm"] or float("inf"))
        base = data["readings"].get("a3c-model")
        base_text = f"; A3C-Model {iqm(base['to_threshold'])}" if base else ""
        findings.append(
            f"Readings of eq. 3 ({data['env']}): mean LD "
            + ", ".join(f"{r['title']} {r['ld_mean'] or 0:.2f}" for r in readings.values())
            + f"; the highest under {readings[near_one]['title']}. Fewest {unit} to threshold: "
            f"{readings[best]['title']}, IQM {iqm(readings[best]['to_threshold'])}{base_text}. "
            + "Against A3C-Model: "
            + "; ".join(f"{r['title']} {_versus(r)[1]}" for r in readings.values())
            + "."
        )
    return Section(TITLES["readings"], [intro, Table(header, rows)], findings)


def rules_section(data: dict) -> Section:
    intro = (
        "Every rule ends an imagined episode after the step it judges, as a truncation (the "
        "critic bootstraps), as Algorithm 1's LD draw does: rules differ only in when they "
        "stop (`--stop`, `ldn_jax/imagination.py`). ld: the draw with P(stop) = 1 - LD (the "
        "literal and the Figure 5 reading of eq. 3, and the ensemble estimator); m2ac: of the "
        "running imagined rollouts only the `m2ac_keep` share with the lowest ensemble "
        "disagreement goes on at each step (M2AC's rank mask, Pan et al. 2020; 8 workers make "
        "a small batch to rank); horizon: cut after h steps (MBPO's rollout length); oracle: "
        "stop where the true one-step error ||M1(s, a) - env(s, a)|| exceeds a threshold, the "
        "real env stepped from the imagined state (the ceiling an estimator could reach; "
        "CartPole only: a MuJoCo observation is not its whole state); none: A3C-Model. The "
        "M2AC share and the oracle threshold are each one vmapped program over their values. "
        "K = 1. Verdicts compare each rule with A3C-Model on the steps (MuJoCo) or episodes "
        "(CartPole) to threshold: helps where the 95% interval of P(sooner) lies above 0.5, "
        "hurts where it lies below. Seconds to threshold were measured with other jobs on "
        "the 2 cores: compare them loosely. ![rules](rules/rules.png)"
    )
    section = Section(TITLES["rules"], [intro])
    for env, panel in data["envs"].items():
        unit = panel["unit"].replace("_", " ")
        header = ["rule", "reached", f"{unit} to threshold: IQM [95% CI]"]
        header += ["final moving return", "imagined per real step", "seconds to threshold"]
        header += ["vs A3C-Model: P(sooner), p", "verdict"]
        rows, verdicts = [], {}
        for r in panel["rows"]:
            if "label" not in r:
                rows.append([r["title"], r["status"], *["–"] * (len(header) - 2)])
                continue
            sooner, verdict = _versus(r)
            verdicts.setdefault(verdict, []).append(r["label"])
            rows.append(
                [
                    r["label"],
                    f"{r['reached']}/{r['runs']}",
                    iqm(r["to_threshold"]),
                    iqm(r["final_moving_return"]),
                    iqm(r["imagined_per_real_step"], 3),
                    iqm(r["seconds_to_threshold"], 1),
                    sooner,
                    verdict,
                ]
            )
        size = f"{panel['seeds']} seeds, {panel['budget']:,} {unit.split()[-1]} each"
        if panel.get("threshold") is not None:
            size += f", threshold {panel['threshold']:g} on the moving return"
        section.blocks += [f"**{env}** ({size}):", Table(header, rows)]
        named = {v: ", ".join(verdicts.get(v, [])) or "no rule" for v in VERDICTS}
        section.findings.append(
            f"Stopping rules, {env}, against A3C-Model in {unit} to threshold: helps: "
            f"{named['helps']}; hurts: {named['hurts']}; no clear difference: "
            f"{named['no clear difference']}."
        )
    return section
