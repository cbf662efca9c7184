"""The paper scripts: their pure parts by hand-computed numbers, and every script's smoke run
(tiny budget) by its output files and fields, REPORT.md included."""

import csv
import dataclasses
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from experiments.paper import branched, branched_rules, cache, figure5, report, report_branched
from experiments.paper import shadow as cal
from ldn_jax.config import from_preset
from ldn_jax.host.run_dir import RunDir
from ldn_jax.learning_degree import ld_histogram
from ldn_jax.trainer import Trainer

ROOT = Path(__file__).resolve().parents[1]


def test_ld_histogram_counts_weighted_steps_per_bin():
    ld = jnp.array([[0.05, 0.15], [0.95, 1.0], [0.1, 0.5]])
    weight = jnp.array([[1.0, 1.0], [1.0, 0.0], [1.0, 0.0]])
    # 0.05 -> bin 0; 0.15 and 0.1 (a bin's lower edge) -> bin 1; 0.95 -> bin 9; 1.0 and 0.5
    # carry weight 0.
    expected = [1, 2, 0, 0, 0, 0, 0, 0, 0, 1]
    np.testing.assert_array_equal(np.asarray(ld_histogram(ld, weight)), expected)


def test_spread_conserves_counts_in_proportion_to_overlap():
    counts = np.array([[2.0, 0.0], [0.0, 4.0]])
    # Iteration 0 imagines steps [0, 250), iteration 1 steps [250, 1250).
    out = figure5.spread(counts, np.array([250, 1250]), 500)
    np.testing.assert_allclose(out, [[2, 1], [0, 2], [0, 1]])
    placed = figure5.place(counts, np.array([400, 1001]), 500)
    np.testing.assert_allclose(placed, [[2, 0], [0, 0], [0, 4]])


def test_auc_and_association_by_hand():
    score = np.array([0.1, 0.4, 0.35, 0.8])
    positive = np.array([False, False, True, True])
    assert cal.auc(score, positive) == 0.75  # 3 of the 4 (pos, neg) pairs ordered right
    assert cal.auc(np.array([1.0, 1.0]), np.array([True, False])) == 0.5  # a tie counts half
    assert cal.auc(score, np.zeros(4, bool)) is None
    stats = cal.association(np.array([1.0, 2.0, 3.0, 4.0]), np.array([1.0, 2.0, 3.0, 5.0]))
    assert stats["spearman"] == pytest.approx(1.0) and stats["auc_error_above_median"] == 1.0
    assert cal.association(np.ones(5), np.arange(5.0))["pearson"] is None  # constant score


def test_shadow_rollouts_read_eq_3_as_the_run_does():
    """The calibration's sigma2 is the run's reading: the sum over the 5 outputs, scaled by
    2, is 10 times the literal mean on the same imagined steps; a window is refused."""
    readings = {}
    for reduce, scale in (("mean", 1.0), ("sum", 2.0)):
        model = {"ld_reduce": reduce, "ld_scale": scale}
        config = from_preset("paper", env="cartpole-v0", algo="ldn", seeds=1, model=model)
        trainer = Trainer(config)
        state = trainer.init_state(jax.random.key(0))
        state = state.replace(
            model=state.model.replace(params=jax.tree.map(lambda p: p + 0.01, state.model.params))
        )
        readings[reduce] = jax.device_get(
            jax.jit(cal.shadow_rollouts, static_argnums=(0, 3))(
                trainer, state, jax.random.key(1), 4, 1.0
            )
        )
    mean, total = readings["mean"], readings["sum"]
    np.testing.assert_allclose(total.sigma2, 10 * mean.sigma2, rtol=1e-5)
    np.testing.assert_allclose(total.sigma2_reward, 10 * mean.sigma2_reward, rtol=1e-5)
    windowed = Trainer(from_preset("paper", env="cartpole-v0", algo="ldn", model={"ld_window": 3}))
    with pytest.raises(ValueError, match="sums a window of 3 steps"):
        cal.shadow_rollouts(
            windowed, windowed.init_state(jax.random.key(0)), jax.random.key(1), 2, 1.0
        )


def test_shadow_rollouts_of_an_untrained_model():
    config = from_preset("paper", env="cartpole-v0", algo="ldn", seeds=1, workers=2)
    trainer = Trainer(config)
    state = trainer.init_state(jax.random.key(0))
    # An "ensemble" of M1 twice: zero disagreement, so its learning degree is 1 and it never
    # stops an episode.
    twins = jax.tree.map(lambda p: jnp.stack([p, p]), state.model.params)
    steps = jax.device_get(
        jax.jit(cal.shadow_rollouts, static_argnums=(0, 3))(
            trainer, state, jax.random.key(1), 6, 1.0, twins
        )
    )
    assert steps.ld.shape == (200, 6)
    # M1 == M0: LD = 0, so the LD draw stops every imagined episode after its first step.
    np.testing.assert_array_equal(steps.ld, 0.0)
    np.testing.assert_array_equal(steps.ld_live.sum(0), 1)
    np.testing.assert_array_equal(steps.disagreement, 0.0)
    np.testing.assert_array_equal(steps.ensemble_live, steps.live)
    np.testing.assert_array_equal(steps.ensemble_ld, 1.0)
    # Twins that disagree by a little, measured against a smaller fit error: the ensemble rule
    # stops episodes the predicted-termination rule lets run.
    apart = jax.tree.map(lambda p: jnp.stack([p, p * 1.01]), state.model.params)
    spread = jax.device_get(
        jax.jit(cal.shadow_rollouts, static_argnums=(0, 3))(
            trainer, state, jax.random.key(1), 6, 1.0, apart, 1e-9
        )
    )
    assert (spread.ensemble_ld[0] < 1.0).all()
    assert spread.ensemble_live.sum() < spread.live.sum()
    # Imagined and real trajectories start from the same state with the same action.
    np.testing.assert_allclose(steps.compounding_error[0], steps.one_step_error[0], rtol=1e-6)
    assert (steps.one_step_error[0] > 0).all()  # an untrained model is wrong
    for mask in (steps.live, steps.real_live):  # once over, an episode stays over
        assert (np.diff(mask.astype(int), axis=0) <= 0).all()
    assert float(cal.ensemble_learning_degree(jnp.float32(0.0), 2.0)) == 1.0
    summary = cal.calibration_summary(steps)
    assert summary["horizons"]["ld_rule"]["counts"][0] == 6
    assert summary["imagined"]["one_step_error"]["ld"]["spearman"] is None  # LD is constant


def test_policy_rollouts_and_the_shadow_rewards_on_cartpole():
    """CartPole pays 1 per step: a real episode's discounted return is 1 + ... + gamma^(L-1),
    exactly 1 at gamma 0; the shadow's true rewards are the env's for each imagined step."""
    for gamma in (0.0, 0.9):
        config = from_preset("paper", env="cartpole-v0", algo="a2c-model", seeds=1)
        config = dataclasses.replace(config, agent=dataclasses.replace(config.agent, gamma=gamma))
        trainer = Trainer(config)
        state = trainer.init_state(jax.random.key(0))
        value, real, imagined = jax.device_get(
            jax.jit(cal.policy_rollouts, static_argnums=(0, 3))(
                trainer, state, jax.random.key(1), 5
            )
        )
        assert value.shape == real.shape == imagined.shape == (5,)
        if gamma == 0.0:
            np.testing.assert_array_equal(real, 1.0)
        else:  # at least 8 steps before a pole falls from rest, at most the step limit
            assert ((real > (1 - gamma**8) / (1 - gamma)) & (real < 1 / (1 - gamma))).all()
    steps = jax.device_get(
        jax.jit(cal.shadow_rollouts, static_argnums=(0, 3))(
            trainer, state, jax.random.key(1), 4, 1.0
        )
    )
    np.testing.assert_array_equal(steps.true_reward, 1.0)
    assert (steps.step_size > 0).all() and steps.reward.shape == steps.live.shape


def test_the_shadow_predicts_under_the_models_normaliser():
    """A run that standardises its model's data imagines through `ModelState.stats`; the
    shadow's predictions must too (identity stats are not the run's model)."""
    config = from_preset("paper", env="cartpole-v0", algo="ldn", seeds=1, model={"normalize": True})
    trainer = Trainer(config)
    state = trainer.init_state(jax.random.key(0))
    stats = state.model.stats.replace(
        obs_mean=state.model.stats.obs_mean + 0.5, obs_std=2 * state.model.stats.obs_std
    )
    obs, onehot = jnp.ones((3, trainer.obs_size)), trainer.model_action(jnp.array([0, 1, 0]))
    dynamics, params = trainer.dynamics, state.model.params
    shadow = cal._predict(trainer, params, stats, obs, onehot)
    next_obs, reward = dynamics.predict(params, obs, onehot, stats)
    np.testing.assert_allclose(shadow[:, :-1], next_obs, rtol=1e-6)
    np.testing.assert_allclose(shadow[:, -1], reward, rtol=1e-6)
    own = cal._predict(trainer, params, stats, obs, onehot, normalized=True)
    plain = cal._predict(trainer, params, state.model.stats, obs, onehot)
    assert not np.allclose(own, shadow) and not np.allclose(plain, shadow)


def test_the_a2c_model_diagnosis_bins_imagined_steps_by_their_index():
    from experiments.paper import a2c_model

    seeds, length, episodes = 1, 1000, 2
    shape = (seeds, length, episodes)
    ones = np.ones(shape)
    steps = cal.ShadowSteps(
        **{name: np.zeros(shape) for name in cal.ShadowSteps.__dataclass_fields__}
    )
    steps = steps.replace(
        live=ones.astype(bool),
        real_live=ones.astype(bool),
        one_step_error=ones,
        step_size=2 * ones,
        compounding_error=np.arange(length)[None, :, None] * ones,
        reward=ones,
        true_reward=-ones,
    )
    bins = a2c_model.bin_summary(steps)
    assert [b["share"] for b in bins] == pytest.approx([0.001, 0.004, 0.015, 0.08, 0.9])
    assert [b["relative_one_step_error"] for b in bins] == [0.5] * 5
    assert [b["drift"] for b in bins] == [0.0, 2.5, 12.0, 59.5, 549.5]  # index - 1, median
    assert bins[0]["reward"] == 1.0 and bins[0]["true_reward"] == -1.0
    # an episode that ended (predicted termination) at step 3 counts in no later bin
    ended = steps.replace(live=np.arange(length)[None, :, None] < 3 * ones)
    assert [b["share"] for b in a2c_model.bin_summary(ended)] == pytest.approx(
        [1 / 3, 2 / 3, 0, 0, 0]
    )


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    """Every script at the smoke scale, in one process (`all.py`), into a fresh directory.

    XLA's optimisations are off: compiling dominates a smoke run and the numbers do not matter.
    """
    results = tmp_path_factory.mktemp("results")
    env = {**os.environ, "JAX_DISABLE_MOST_OPTIMIZATIONS": "1"}
    done = _smoke_script("all", results, timeout=600, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    return results, done.stdout


def _smoke_script(name: str, results: Path, timeout: int, env: dict | None = None):
    """`python -m experiments.paper.NAME --smoke --results RESULTS`, run to its end."""
    command = [sys.executable, "-m", f"experiments.paper.{name}", "--smoke"]
    return subprocess.run(
        [*command, "--results", str(results)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=ROOT,
    )


def test_make_paper_answers_help_and_bad_flags_before_any_script_runs(capsys):
    from experiments.paper import all as every

    with pytest.raises(SystemExit) as bad:
        every.main(["--scale", "nope"])
    assert bad.value.code == 2
    with pytest.raises(SystemExit) as asked:
        every.main(["--help"])
    assert asked.value.code == 0
    out = capsys.readouterr().out
    assert "Every paper script in order" in out and "== table2" not in out


def test_make_paper_and_each_script_stop_with_one_line_at_a_run_another_process_trains(
    tmp_path, monkeypatch, capsys
):
    from experiments.paper import all as every
    from experiments.paper import common, table2

    config = from_preset("paper", env="cartpole-v0", algo="a2c", seeds=1, episodes=2)
    out = tmp_path / "runs" / "smoke" / "cartpole-v0-a2c"  # table2's first run at the smoke scale
    out.mkdir(parents=True)
    with RunDir(out).hold():
        alone = _smoke_script("table2", tmp_path, timeout=300)
        monkeypatch.setattr(cache, "train", lambda *a, **k: pytest.fail("trained"))
        monkeypatch.setattr(table2, "main", lambda argv: cache.ensure_run(config, out))
        paper = ["--smoke", "--results", str(tmp_path)]
        assert common.script(lambda argv: every.main(paper)) == 2
    assert alone.returncode == 2, alone.stderr[-2000:]
    for error in (alone.stderr.strip(), capsys.readouterr().err.strip()):
        assert error.startswith("error: ") and "in use by another training process" in error
        assert "\n" not in error
    assert [p.name for p in out.iterdir()] == [".lock"]  # nothing written there


def _json(results: Path, name: str) -> dict:
    return json.loads((results / name / f"{name}.json").read_text())


_SMOKE_RUNS = [
    "cartpole-v0-a2c",
    "cartpole-v0-a2c-model",
    "cartpole-v0-ldn",
    "cartpole-v0-ldn-ensemble",
    "cartpole-v0-ldn-k0.5,2",
    "inverted_pendulum-a2c",
    "inverted_pendulum-a2c-model",
    "inverted_pendulum-ldn",
    "inverted_pendulum-ldn-k0.5,2",
    "inverted_pendulum-ppo",
    "inverted_pendulum-ppo-ldn",
    "inverted_pendulum-ppo-model",
    "stops-cartpole-v0-m2ac",
    "stops-cartpole-v0-oracle",
]


def test_smoke_trains_each_run_once_and_reuses_it(smoke):
    results, stdout = smoke
    # Table 2's three runs, Figure 9's two of K = 0.5 and 2 (CartPole and inverted_pendulum:
    # K = 1 is Table 2's and Table 4's run), the calibration's
    # ensemble-LD run, the stopping-rule study's two (m2ac and the oracle), Table 4's two,
    # Table 5's three and the targets' a2c; the other scripts reuse them.
    assert stdout.count("training ") == 14, stdout
    finished = sorted(p.name for p in (results / "runs" / "smoke").iterdir())
    assert finished == _SMOKE_RUNS


def test_a_finished_mujoco_run_leaves_a_record_that_stands_in_for_its_directory(
    smoke, tmp_path, monkeypatch
):

    results, _ = smoke
    shutil.copytree(results / "runs" / "smoke", tmp_path / "runs" / "smoke")
    shutil.copytree(results / "records" / "smoke", tmp_path / "records" / "smoke")
    # MuJoCo runs only (CartPole's are minutes, and the calibration reads their checkpoints)
    recorded = sorted(p.name for p in (tmp_path / "records" / "smoke").iterdir())
    assert recorded == [n for n in _SMOKE_RUNS if n.startswith("inverted_pendulum")]
    out = tmp_path / "runs" / "smoke" / "inverted_pendulum-a2c-model"
    record = cache.record_of(out)
    assert record == tmp_path / "records" / "smoke" / "inverted_pendulum-a2c-model"
    kept = RunDir(record)
    files = [kept.config_file, record / cache.HISTORY_FILE, kept.summary_file]
    assert sorted(record.iterdir()) == sorted(files)
    config = RunDir(out).read_config()
    summary, history = RunDir(out).read_summary(), cache.load_history(out)
    shutil.rmtree(out)  # a fresh clone: the record without the run
    monkeypatch.setattr(cache, "train", lambda *a, **k: pytest.fail("trained"))
    assert cache.ensure_run(config, out) == summary
    kept = cache.load_history(out)
    assert kept.keys() == history.keys()
    for name in history:
        np.testing.assert_array_equal(kept[name], history[name])
    # a record of another config is not reused: the run is trained
    trained = []

    def train(config, *args, **kwargs):
        trained.append(config)
        raise KeyboardInterrupt  # the test needs no more than the call

    monkeypatch.setattr(cache, "train", train)
    other = dataclasses.replace(config, seeds=config.seeds + 1)
    with pytest.raises(KeyboardInterrupt):
        cache.ensure_run(other, out)
    assert trained == [other]


def test_the_plan_says_where_each_mujoco_run_stands_without_training(
    smoke, tmp_path, monkeypatch, capsys
):
    from experiments.paper import plan

    results, _ = smoke
    shutil.copytree(results / "runs" / "smoke", tmp_path / "runs" / "smoke")
    shutil.copytree(results / "records" / "smoke", tmp_path / "records" / "smoke")
    monkeypatch.setattr(cache, "train", lambda *a, **k: pytest.fail("trained"))
    monkeypatch.setattr(cache, "ensure_run", lambda *a, **k: pytest.fail("ensured"))
    scale = plan.common.SCALES["smoke"]
    table = plan.rows(scale, tmp_path)
    ours = [(r["result"], r["algo"]) for r in table if r["state"] != "not at this scale"]
    assert ours == [("table4", "a2c-model"), ("table4", "ldn")] + [
        ("table5", algo) for algo in ("ppo", "ppo-model", "ppo-ldn")
    ] + [("figure9", "ldn")]
    assert {r["env"] for r in table if r["state"] == "not at this scale"} == set(
        plan.common.MUJOCO
    ) - {"inverted_pendulum"}
    assert all(
        r["state"] == "done" and r["seconds"] > 0 for r in table if r["env"] == "inverted_pendulum"
    )
    # the record stands in for a run directory that is gone
    gone = tmp_path / "runs" / "smoke" / "inverted_pendulum-ppo"
    shutil.rmtree(gone)
    # an interrupted run: its summary (the last thing a run writes) is not there
    cut = tmp_path / "runs" / "smoke" / "inverted_pendulum-ppo-model"
    (cut / "summary.json").unlink()
    steps = [json.loads(line) for line in (cut / "metrics.jsonl").read_text().splitlines()]
    last = max(s["iteration"] for s in steps)
    fewest = min(s["env_steps"] for s in steps if s["iteration"] == last)
    # a run of another config, with no record: trained from scratch
    other = tmp_path / "runs" / "smoke" / "inverted_pendulum-ppo-ldn"
    config = json.loads((other / "config.json").read_text())
    (other / "config.json").write_text(json.dumps({**config, "seeds": config["seeds"] + 1}))
    shutil.rmtree(tmp_path / "records" / "smoke" / "inverted_pendulum-ppo-ldn")
    table = plan.rows(scale, tmp_path)
    states = {r["algo"]: r for r in table if r["result"] == "table5" and "seeds" in r}
    assert states["ppo"]["state"] == "record" and states["ppo"]["seconds"] > 0
    assert states["ppo-model"] == states["ppo-model"] | {"state": "partial", "steps": fewest}
    assert states["ppo-ldn"]["state"] == "new"
    assert plan.summary(table).startswith("4 of 6 runs finished (1 from records)")
    # a table's `--report` (collect_runs without training): the unfinished runs are pending,
    # with how far each got, and nothing is trained (ensure_run fails above)
    entries = cache.collect_runs(
        ("inverted_pendulum",), ("ppo-model", "ppo-ldn"), scale, tmp_path, train=False
    )
    assert [(e["status"], e["reason"]) for e in entries] == [
        ("pending", f"training at {fewest:,} real steps per seed"),
        ("pending", "not trained at the current defaults"),
    ]
    gone = cache.collect_runs(
        ("inverted_pendulum",), ("ppo-ldn",), scale, tmp_path / "x", train=False
    )
    assert gone[0]["reason"] == "not trained here"  # no run and no record of any config
    rows = [*entries, {**entries[1], "env": "ant"}]
    note = report.report_mujoco._pending_note({"rows": rows})
    assert note == [
        f"Pending at this scale (training at {fewest:,} real steps per seed): inverted_pendulum.",
        "Pending at this scale (not trained at the current defaults): inverted_pendulum, ant.",
    ]
    # --train: the unfinished runs, in order, and nothing else
    trained = []
    monkeypatch.setattr(cache, "ensure_run", lambda config, out: trained.append(out.name))
    plan.main(["--smoke", "--results", str(tmp_path), "--train"])
    assert trained == ["inverted_pendulum-ppo-model", "inverted_pendulum-ppo-ldn"]
    # a run another process trains is passed over (its lock held), untouched, and the
    # next is trained
    monkeypatch.undo()
    trained.clear()

    def train(config, out, **kwargs):
        trained.append(out.name)
        raise KeyboardInterrupt  # the test needs no more than the call

    monkeypatch.setattr(cache, "train", train)
    before = sorted(p.name for p in cut.rglob("*"))
    with RunDir(cut).hold(), pytest.raises(KeyboardInterrupt):
        plan.main(["--smoke", "--results", str(tmp_path), "--train"])
    assert trained == ["inverted_pendulum-ppo-ldn"]
    assert sorted(p.name for p in cut.rglob("*")) == before
    assert "passed over:" in capsys.readouterr().out


def test_smoke_readings_and_stopping_rules(smoke):
    results, _ = smoke
    readings = _json(results, "readings")
    assert list(readings["readings"]) == ["literal", "a3c-model"]
    row = readings["readings"]["literal"]
    assert row["vs_a3c_model"]["verdict"] in ("helps", "hurts", "no clear difference")
    assert 0 <= row["ld_mean"] < 1 and row["imagined_per_episode"]["n"] == 2
    assert (results / "readings" / "readings.png").stat().st_size > 0
    rules = _json(results, "rules")
    rows = rules["envs"]["cartpole-v0"]["rows"]
    # m2ac and the oracle: one vmapped program of three points each
    labels = [r["label"] for r in rows]
    assert labels == [
        "m2ac m2ac_keep=0.5", "m2ac m2ac_keep=0.75", "m2ac m2ac_keep=0.9",
        "oracle oracle_error=0.005", "oracle oracle_error=0.01", "oracle oracle_error=0.02",
        "none",
    ]  # fmt: skip
    # m2ac keeping half of 4 workers' rollouts: at most 4 + 2 + 1 imagined steps an iteration
    assert rows[0]["imagined_per_episode"]["iqm"] <= 7 / 4 < rows[-1]["imagined_per_episode"]["iqm"]
    assert "vs_a3c_model" not in rows[-1] and len(rows[0]["seeds"]["to_threshold"]) == 2
    assert (results / "rules" / "rules.png").stat().st_size > 0
    assert (results / "rules" / "rules.csv").read_text().count("\n") == 1 + 7


def test_smoke_tables_2_and_3(smoke):
    results, _ = smoke
    table2 = _json(results, "table2")
    assert table2["seeds"] == 2 and table2["scale"] == "smoke" and table2["machine"]["cores"]
    assert [(r["env"], r["algo"]) for r in table2["rows"]] == [
        ("cartpole-v0", "a2c"),
        ("cartpole-v0", "a2c-model"),
        ("cartpole-v0", "ldn"),
    ]
    for row in table2["rows"]:
        assert row["runs"] == 2 and len(row["episodes_to_threshold"]) == 2
        assert row["threshold"] == 150.0 and row["paper_mean"] > 0
        assert {"min", "max", "mean", "sd", "reached"} <= set(row)
    with open(results / "table2" / "table2.csv") as f:
        assert len(list(csv.DictReader(f))) == 3
    table3 = _json(results, "table3")
    for row in table3["rows"]:
        assert row["compile_seconds"] > 0 and row["train_seconds"] > 0
        assert len(row["seconds_to_threshold"]) == 2 and row["paper_seconds"] > 0
    for png in ("table2/figure6.png", "table3/table3.png", "figure4/figure4.png"):
        assert (results / png).stat().st_size > 1000, png
    with open(results / "figure4" / "figure4.csv") as f:
        rows = list(csv.DictReader(f))
    assert {r["algo"] for r in rows} == {"a2c", "a2c-model", "ldn"}
    assert all(float(r["low95"]) <= float(r["mean"]) <= float(r["high95"]) for r in rows)


def test_smoke_figure5_places_every_imagined_step(smoke):
    results, _ = smoke
    data = _json(results, "figure5")
    assert set(data["runs"]) == {"ldn", "a2c-model"}
    for run in data["runs"].values():
        total = sum(run["imagined_steps_per_seed"])
        for axis in ("imagined_axis", "real_axis"):
            counts = np.asarray(run[axis]["counts"])
            assert counts.shape[1] == 10
            assert counts.sum() == pytest.approx(total, abs=0.1)
    assert (results / "figure5" / "figure5.png").stat().st_size > 1000


def test_smoke_figure9_has_a_panel_per_env(smoke):
    results, _ = smoke
    figure9 = _json(results, "figure9")
    assert [p["env"] for p in figure9["panels"]] == ["cartpole-v0", "inverted_pendulum"]
    assert figure9["pending"] == []
    cartpole, pendulum = figure9["panels"]
    assert cartpole["threshold"] == 150.0 and pendulum["threshold"] is None
    for panel in figure9["panels"]:
        assert [r["k"] for r in panel["rows"]] == [0.5, 1.0, 2.0]
        for row in panel["rows"]:
            assert len(row["episodes_to_threshold"]) == len(row["final_moving_returns"]) == 2
            assert row["final_moving_return"]["runs"] == 2
    assert all(r["reached"] == 0 for r in pendulum["rows"])  # no threshold, none reached
    table4 = _json(results, "table4")
    ldn = next(r for r in table4["rows"] if r["env"] == "inverted_pendulum" and r["algo"] == "ldn")
    assert pendulum["shared_k"] == [1.0]  # K = 1 is Table 4's run, not trained again
    assert pendulum["rows"][1]["final_moving_returns"] == ldn["final_moving_returns"]
    with open(results / "figure9" / "figure9.csv") as f:
        assert len(list(csv.DictReader(f))) == 6
    assert (results / "figure9" / "figure9.png").stat().st_size > 1000


def test_smoke_mujoco_tables_run_inverted_pendulum_and_list_the_rest(smoke):
    results, _ = smoke
    table4 = _json(results, "table4")
    assert len(table4["rows"]) == 12 and table4["seeds"] == 2
    for row in table4["rows"]:
        if row["env"] == "inverted_pendulum":
            assert row["status"] == "done" and row["episodes"] == 8 and row["runs"] == 2
            assert len(row["final_moving_returns"]) == 2 and row["env_steps_per_seed"] > 0
            assert row["paper"] in (7842.1, 10864.3)
        else:
            assert row["status"] == "pending" and "--scale paper only" in row["reason"]
    table5 = _json(results, "table5")
    done = [r for r in table5["rows"] if r["status"] == "done"]
    assert [r["algo"] for r in done] == ["ppo", "ppo-model", "ppo-ldn"]
    assert len(table5["rows"]) == 9
    # The top is 90% of the best moving return of any run, so some run reaches it.
    assert len({r["top"] for r in done}) == 1 and any(r["reached"] for r in done)
    for row in done:
        assert len(row["episodes_to_top"]) == 2 and row["paper"] in (2463, 2465, 2175)
    for name in ("table4", "table5"):
        assert (results / name / f"{name}.png").stat().st_size > 1000
        with open(results / name / f"{name}.csv") as f:
            assert len(list(csv.DictReader(f))) == len(_json(results, name)["rows"])


def test_smoke_targets_run_every_algorithm_on_inverted_pendulum(smoke):
    results, _ = smoke
    targets = _json(results, "targets")
    done = [r for r in targets["rows"] if r["status"] == "done"]
    assert [r["algo"] for r in done] == ["a2c", "a2c-model", "ldn", "ppo", "ppo-model", "ppo-ldn"]
    assert {r["env"] for r in done} == {"inverted_pendulum"}
    assert [(r["env"], r["status"]) for r in targets["rows"][6:]] == [
        ("halfcheetah", "pending")
    ] * 2
    for row in done:
        assert row["seeds"] == 2 and len(row["highest"]) == 2 and row["budget"] == "8 episodes"
        assert row["met"] == (row["reached"] >= 4 and row["train_seconds"] < 900)
    assert (results / "targets" / "targets.png").stat().st_size > 1000
    text = (results / "REPORT.md").read_text()
    assert "## MuJoCo at the default budgets" in text and "Targets, inverted_pendulum: " in text


def test_default_budget_targets_are_the_users_commands():
    from experiments.paper import locomotion, targets

    scale = report.common.SCALES["cpu"]
    config = targets.run_config(scale, "halfcheetah", "ldn", 10, (0.5, 1.0, 2.0))
    assert config.steps == 1_000_000 and config.seeds == 10 and config.k == (0.5, 1.0, 2.0)
    assert targets.run_config(scale, "inverted_pendulum", "ppo", 5, (1.0,)).steps == 600_000
    out = targets.run_dir(Path("r"), scale, config)
    assert out == Path("r/runs/cpu/targets-halfcheetah-ldn-k0.5,1,2")
    full = report.common.SCALES["cpu-full"]  # default budgets: the same runs at every scale
    assert targets.run_config(full, "halfcheetah", "ldn", 10, (0.5, 1.0, 2.0)) == config
    assert targets.run_dir(Path("r"), full, config) == out
    # PPO on halfcheetah is the locomotion study's run: one config, trained once for both.
    ppo = targets.run_config(scale, "halfcheetah", "ppo", 5, None)
    assert ppo == locomotion.config_of("halfcheetah", 5)
    assert targets.run_dir(Path("r"), scale, ppo) == Path("r/runs/locomotion/halfcheetah-ppo-s5")


def test_targets_runs_one_row_and_keeps_the_others_with_their_dates(tmp_path, capsys, monkeypatch):
    from experiments.paper import targets

    monkeypatch.setattr(targets.common, "compile_cache", lambda results: None)
    earlier = json.loads((ROOT / "experiments/results/targets/targets.json").read_text())
    earlier = {**earlier, "scale": "smoke", "machine": {**earlier["machine"], "date": "2026-11-30"}}
    earlier.pop("curves_date", None)  # written before rows were dated
    for row in earlier["rows"]:
        row.pop("date", None)
    (tmp_path / "targets").mkdir()
    (tmp_path / "targets" / "targets.json").write_text(json.dumps(earlier))
    # At the smoke scale halfcheetah is pending: the row is measured again without training.
    assert targets.main(["--smoke", "--results", str(tmp_path), "--runs", "halfcheetah-ppo"]) == 0
    after = json.loads((tmp_path / "targets" / "targets.json").read_text())
    assert after["rows"][:7] == [{"date": "2026-11-30", **row} for row in earlier["rows"][:7]]
    assert after["rows"][7] == {"env": "halfcheetah", "algo": "ppo", "status": "pending"}
    assert after["curves_date"] == "2026-11-30"
    assert not (tmp_path / "targets" / "targets.png").exists()
    section = report.report_mujoco.targets_section(after)
    assert "(the runs of 2026-11-30)" in section.blocks[0]
    assert "measured 2026-11-30" in " ".join(section.findings)
    for bad in (
        ["--runs", "halfcheetah-sac"],
        ["--runs", ","],
        ["--scale", "cpu", "--runs", "halfcheetah-ppo"],
    ):
        with pytest.raises(SystemExit) as refused:
            targets.main(
                ["--results", str(tmp_path), *(["--smoke"] if "--scale" not in bad else []), *bad]
            )
        assert refused.value.code == 2
        assert capsys.readouterr().err.count("\n") == 1


def test_cpu_scale_runs_every_mujoco_task_on_its_budget():
    common = report.common
    scale = common.SCALES["cpu"]
    assert set(scale.ablation_envs) == set(scale.learning_envs) == set(common.MUJOCO)
    for env in common.MUJOCO:
        config = common.run_config(scale, env, "ldn", k=(0.5, 1.0, 2.0))
        [(unit, n)] = common.MUJOCO_CPU_BUDGETS[env].items()
        assert (config.steps if unit == "steps" else config.episodes) == n and config.seeds == 5
        assert config.steps is None or unit == "steps"
        assert cache.budget_text(config) == f"{n:,} {unit}"


def test_the_halfcheetah_rules_take_their_own_budget_seeds_and_directories():
    from experiments.paper import stops

    scale, results = report.common.SCALES["cpu"], Path("r")
    for name in ("ld", "m2ac", "none"):
        algo, model, sweep, _ = stops.RULES[name]
        config = stops.config_of(scale, "halfcheetah", algo, model, sweep)
        assert config.steps == 1_000_000 and config.seeds == 10 and config.k == (1.0,)
        out = stops.dir_of(results, scale, config, name)
        assert out == Path(f"r/runs/cpu/stops-halfcheetah-{name}")  # not Table 4's 200k run
    # The oracle can run on halfcheetah now, but the study leaves it to CartPole.
    assert stops.config_of(scale, "halfcheetah", *stops.RULES["oracle"][:3]).stop.rule == "oracle"
    assert stops.ensure(results, scale, "halfcheetah", "oracle", *stops.RULES["oracle"][:3]) is None
    # The smoke scale keeps its own budgets; CartPole's rules keep the scale's episodes.
    smoke = stops.config_of(report.common.SCALES["smoke"], "inverted_pendulum", "a2c-model", {})
    assert smoke.steps is None and smoke.episodes == 8
    assert stops.config_of(scale, "cartpole-v2", "a2c-model", {}).episodes == scale.episodes


def test_the_rules_study_on_some_envs_keeps_the_other_envs_rows(tmp_path, monkeypatch):
    """`stops.py --envs E` trains only E's rules and keeps the stored rows of the others."""
    from experiments.paper import stops

    common = report.common
    scale = common.SCALES["cpu"]
    (tmp_path / "rules").mkdir()
    old = {"cartpole-v2": {"rows": ["old v2"]}, "halfcheetah": {"rows": ["old cheetah"]}}
    stored = {**common.scale_record(scale), "k": 1.0, "envs": old}
    (tmp_path / "rules" / "rules.json").write_text(json.dumps(stored))
    with pytest.raises(SystemExit, match="--envs ant: this scale's rules study runs cartpole-v2"):
        stops.rules_study(tmp_path, scale, ("ant",))
    trained = []
    fresh = lambda results, scale, env: trained.append(env) or {"rows": [f"new {env}"]}
    monkeypatch.setattr(stops, "env_rules", fresh)
    monkeypatch.setattr(stops, "rules_figure", lambda record, path: None)
    record = stops.rules_study(tmp_path, scale, ("halfcheetah",))
    assert trained == ["halfcheetah"]  # inverted_pendulum: not asked for and not stored
    assert record["envs"] == {
        "cartpole-v2": old["cartpole-v2"],
        "halfcheetah": {"rows": ["new halfcheetah"]},
    }
    written = json.loads((tmp_path / "rules" / "rules.json").read_text())
    assert list(written["envs"]) == ["cartpole-v2", "halfcheetah"]


def test_smoke_calibration(smoke):
    results, _ = smoke
    data = _json(results, "calibration")
    assert [p["episodes"] for p in data["points"]] == [8, 16]
    first, last = data["points"]
    assert "match" in first["source"] and "final checkpoint" in last["source"]
    for point in data["points"]:
        pooled = point["pooled"]
        for rule in ("predicted_termination", "ld_rule", "ensemble_rule"):
            assert sum(pooled["horizons"][rule]["counts"]) == 2 * 4  # seeds x episodes
        one_step = pooled["imagined"]["one_step_error"]
        assert set(one_step) >= {"ld", "sigma2", "disagreement", "steps", "median"}
        assert one_step["steps"] == pooled["imagined"]["steps"] > 0
        assert point["ensemble"]["members"] == 2 and point["ensemble"]["fit_steps_per_member"] > 0
        assert len(point["per_seed"]) == 2
    m0, ensemble = data["training"]
    assert (m0["ld"], ensemble["ld"], ensemble["ensemble_members"]) == ("m0", "ensemble", 5)
    for row in data["training"]:
        assert row["runs"] == 2 and row["train_seconds"] > 0
        assert row["imagined_steps_per_real_step"] > 0 and 0 <= row["ld_mean_last_iterations"] <= 1
    assert (results / "calibration" / "calibration.png").stat().st_size > 1000


def test_report_is_generated_from_the_result_files(smoke, tmp_path):
    results, _ = smoke
    text = (results / "REPORT.md").read_text()
    for heading in ("## Table 2", "## Table 3", "## Figure 4", "## Figure 5", "## Figure 9"):
        assert heading in text
    assert "## LD calibration" in text and "## What reproduced and what did not" in text
    assert "## Table 4: MuJoCo" in text and "## Table 5: MuJoCo" in text
    assert "## The readings of eq. 3" in text and "## Stopping rules for imagination" in text
    assert "Stopping rules, cartpole-v0, against A3C-Model in episodes to threshold" in text
    assert "346.4 ± 44.5" in text and "625.5" in text  # the paper's numbers beside ours
    assert "10,864.3" in text and "2,175" in text  # Tables 4 and 5 of the paper
    assert "Figure 9, inverted_pendulum: mean final moving return" in text
    assert "Table 5, inverted_pendulum: " in text
    assert "Pending at this scale" in text and "cores" in text
    assert "{'" not in text  # no Python value leaks into the prose
    # Change a result file: the report follows it. Remove one: the report says so.
    table2 = _json(results, "table2")
    table2["rows"][2].update(mean=123.4, sd=5.6, reached=2)
    (tmp_path / "table2").mkdir()
    (tmp_path / "table2" / "table2.json").write_text(json.dumps(table2))
    text = report.render(tmp_path, report.common.SCALES["smoke"])
    assert "123.4 ± 5.6" in text
    assert "Not produced yet (run `figure9.py`)" in text
    assert f"Machine: {table2['machine']['cpu']}, " in text
    # Result files written on two machines: the setup says which wrote which.
    table3 = _json(results, "table3")
    table3["machine"]["cpu"] = "Another CPU"
    (tmp_path / "table3").mkdir()
    (tmp_path / "table3" / "table3.json").write_text(json.dumps(table3))
    text = report.render(tmp_path, report.common.SCALES["smoke"])
    assert f"{table2['machine']['cpu']} (table2); Another CPU (table3); each with " in text


def test_an_underpowered_mujoco_comparison_says_inconclusive_with_its_budget():
    from experiments.paper.report_format import inconclusive
    from experiments.paper.report_mujoco import table5_finding

    assert inconclusive("halfcheetah", steps=200_000) == (
        "inconclusive at this budget (200 episodes per seed, 12% of the paper's >= 1,734)"
    )
    assert inconclusive("hopper", episodes=400).startswith("inconclusive at this budget (400 ")
    assert inconclusive("hopper", episodes=2_000) is None  # the paper's budget or more
    assert inconclusive("cartpole-v2", episodes=10) is None  # the paper's CartPole budgets
    row = {"mean": None, "episodes_per_seed": 400.0, "env_steps_per_seed": 52_000.0}
    finding = table5_finding("hopper", {"ppo": row, "ppo-ldn": row})
    assert finding.endswith("inconclusive at this budget (400 episodes per seed, 23% of the "
                            "paper's >= 1,734).")  # fmt: skip
    assert "NOT reproduced" not in finding


def test_figure_9s_verdict_says_its_power():
    from experiments.paper.report_paper import figure9_findings

    def panel(env, finals, episodes):
        rows = [
            {"k": k, "runs": 5, "episodes_per_seed": episodes,
             "final_moving_return": {"mean": sum(v) / len(v)}, "final_moving_returns": v}
            for k, v in finals.items()
        ]  # fmt: skip
        return {"env": env, "threshold": None, "rows": rows}

    high, low = [900, 910, 920, 930, 940], [100, 110, 120, 130, 140]
    mixed = [880, 150, 930, 120, 950]

    def verdict(p):
        (finding,) = figure9_findings(p)
        return finding

    assert verdict(panel("hopper", {0.5: low, 1.0: high, 2.0: low}, 2_000)).endswith(
        ": REPRODUCED (K = 1 best, as in the paper)."
    )
    assert verdict(panel("hopper", {0.5: mixed, 1.0: high, 2.0: low}, 2_000)).endswith(
        ": K = 1 best, as in the paper, but not significantly: inconclusive at 5 seeds (no "
        "difference significant)."
    )
    assert verdict(panel("hopper", {0.5: low, 1.0: low, 2.0: high}, 2_000)).endswith(
        ": NOT reproduced (K=2 significantly better; the paper: K = 1 best)."
    )
    # Below the paper's episodes, a reversal is not a refutation.
    below = verdict(panel("hopper", {0.5: low, 1.0: low, 2.0: high}, 1_000))
    assert "inconclusive at this budget (1,000 episodes per seed, 58% " in below
    assert "NOT reproduced" not in below


def test_a_comparison_whose_interval_includes_even_odds_says_inconclusive_not_refuted():
    from experiments.paper.report_format import too_wide
    from experiments.paper.report_mujoco import table5_verdict

    overlap = too_wide([1.0, 5.0, 2.0, 8.0, 3.0], [4.0, 2.5, 6.0, 1.5, 7.0])
    assert overlap.startswith("inconclusive at 5 seeds (P(better) ") and "includes 0.5" in overlap
    assert too_wide([10.0, 11.0, 12.0, 13.0, 14.0], [1.0, 2.0, 3.0, 4.0, 5.0]) is None

    def row(tops):
        reached = [t for t in tops if t is not None]
        mean = sum(reached) / len(reached) if reached else None
        return {"episodes_to_top": tops, "mean": mean, "reached": len(reached), "runs": 5}

    fast, slow = [100, 110, 120, 130, 140], [300, 310, 320, 330, 340]
    mixed, behind = [90, 290, 105, 310, 135], [150, 300, 120, 330, 200]
    algos = {"ppo": row(slow), "ppo-model": row(slow), "ppo-ldn": row(fast)}
    assert table5_verdict(algos, True, None) == "REPRODUCED (PPO2-LDN fewest, as in the paper)"
    algos["ppo"] = row(mixed)  # fewest on the mean, not significantly
    assert table5_verdict(algos, True, None) == (
        "PPO2-LDN fewest, as in the paper, but not significantly: inconclusive at 5 seeds "
        "(no difference significant)"
    )
    algos = {"ppo": row(fast), "ppo-model": row(mixed), "ppo-ldn": row(slow)}
    assert table5_verdict(algos, False, None).startswith("NOT reproduced (PPO2 significantly ")
    algos = {"ppo": row(mixed), "ppo-model": row(mixed), "ppo-ldn": row(behind)}
    assert table5_verdict(algos, False, None) == (
        "inconclusive at 5 seeds (no difference significant) (the paper: PPO2-LDN fewest)"
    )


def _table4_row(env, algo, finals, episodes=2_000.0):
    """A finished Table 4 row as table4.py writes it, around per-seed final returns."""
    mean = sum(finals) / len(finals)
    return {
        "env": env, "algo": algo, "status": "done", "paper": 1.0, "budget": "1,000,000 steps",
        "episodes": None,
        "episodes_per_seed": episodes, "env_steps_per_seed": 1e6, "mean": mean, "sd": 1.0,
        "iqm": mean, "ci95": None, "min": min(finals), "max": max(finals),
        "eval_return": {"mean": mean, "sd": 1.0}, "final_moving_returns": finals,
    }  # fmt: skip


def test_table_4s_verdicts_read_the_p_holm_adjusted_over_the_six_tasks():
    from experiments.paper import table4
    from experiments.paper.report_mujoco import table4_section

    ldn, model = [900, 910, 920, 930, 940], [100, 110, 120, 130, 905]  # p = 0.016
    level = [500, 510, 520, 530, 540]
    rows = []
    for env in table4.ENVS:
        rows += [_table4_row(env, "a2c-model", model if env == "ant" else level)]
        rows += [_table4_row(env, "ldn", ldn if env == "ant" else level)]
    table = {"seeds": 5, "rows": rows}
    findings = table4_section(table).findings
    assert len(findings) == 6
    (ant,) = [f for f in findings if f.startswith("Table 4, ant ")]
    # 0.016 alone would pass 0.05; among six tasks its adjusted p is 6 x 0.016 = 0.095
    assert "Mann-Whitney p = 0.016, Holm-adjusted over 6 tasks 0.095" in ant
    assert "REPRODUCED" not in ant
    assert ant.endswith("no significant difference (the paper: MBRL-LDN higher): inconclusive "
                        "at 5 seeds.")  # fmt: skip
    # The same task on its own is a family of one: its p is its own.
    alone = table4_section({"seeds": 5, "rows": rows[:2]}).findings[0]
    assert "Holm-adjusted over 1 tasks 0.016" in alone
    assert alone.endswith("REPRODUCED (MBRL-LDN higher, as in the paper).")
    # Plain A3C of the same config beside it, where table4.py found the family study's run.
    plain = {"seeds": 5, "rows": rows[:2], "plain_a3c": {"ant": [901, 911, 921, 931, 941]}}
    beside = table4_section(plain).findings[0]
    assert "Plain A3C (the family study's run of the same config) ends at 921.0" in beside
    # U = 10 of 25 pairs (each A3C seed 1 above its MBRL-LDN twin): exact two-sided p 0.69
    assert "Mann-Whitney p = 0.69 (descriptive, outside the corrected family)" in beside
    assert "P(better) = 0.40" in beside
    assert "imagined" not in beside  # no share recorded: nothing said
    # An MBRL-LDN run that imagined under 5% of its real steps is called what it is.
    idle = [rows[0], {**rows[1], "imagined_share": 0.004}]
    said = table4_section({"seeds": 5, "rows": idle}).findings[0]
    assert said.endswith(
        "MBRL-LDN imagined 0.4% of its real steps: an A3C run with a model beside it."
    )
    busy = [rows[0], {**rows[1], "imagined_share": 0.3}]
    assert "imagined" not in table4_section({"seeds": 5, "rows": busy}).findings[0]


def test_figure_9s_verdicts_read_the_p_holm_adjusted_over_the_figure():
    from experiments.paper.report_paper import figure9_findings, figure9_section

    high, low = [900, 910, 920, 930, 940], [100, 110, 120, 130, 140]

    def panel(env):
        rows = [
            {"k": k, "runs": 5, "episodes_per_seed": 2_000.0, "mean": None, "sd": None,
             "min": None, "max": None, "reached": 0, "imagined_steps_per_seed": 10.0,
             "ld_mean_last_iterations": 0.5, "final_moving_returns": v,
             "final_moving_return": {"mean": sum(v) / len(v), "sd": 1.0}}
            for k, v in {0.5: low, 1.0: high, 2.0: low}.items()
        ]  # fmt: skip
        return {"env": env, "threshold": None, "seeds": 5, "budget": "1 steps", "rows": rows}

    # On its own a panel is a family of two: 2 x 0.0079 < 0.05.
    (alone,) = figure9_findings(panel("hopper"))
    assert "Holm over 2 comparisons" in alone and alone.endswith("REPRODUCED (K = 1 best, as in "
                                                                 "the paper).")  # fmt: skip
    # Seven panels are 14 comparisons: 14 x 0.0079 > 0.05.
    envs = ("cartpole-v2", "ant", "halfcheetah", "hopper", "reacher", "walker2d", "walker")
    findings = figure9_section({"panels": [panel(env) for env in envs]}).findings
    assert len(findings) == 7
    for finding in findings:
        assert (
            "(Mann-Whitney, Holm over 14 comparisons: K=1 vs K=0.5: p = 0.0079, adjusted "
            in finding
        )
        assert "REPRODUCED" not in finding
        assert finding.endswith("K = 1 best, as in the paper, but not significantly: "
                                "inconclusive at 5 seeds (no difference significant).")  # fmt: skip


def _table5_row(tops, taken, imagined=None):
    """A finished Table 5 row as table5.py writes it: per-seed episodes to the top (None: never
    reached) and the episodes each seed took."""
    reached = [t for t in tops if t is not None]
    row = {
        "episodes_to_top": tops, "episodes_per_run": taken, "reached": len(reached), "runs": 5,
        "mean": sum(reached) / len(reached) if reached else None,
        "episodes_per_seed": sum(taken) / len(taken), "env_steps_per_seed": 1e6,
        "final_moving_return": {"mean": 1.0, "sd": 1.0}, "imagined_steps_per_seed": 0.0,
        "ld_mean_last_iterations": None, "imagined_updates": None,
    }  # fmt: skip
    if imagined:
        steps, updates = imagined
        row |= {"imagined_steps": steps, "imagined_updates": updates,
                "ld_mean_last_iterations": 0.4,
                "imagined_steps_per_seed": sum(steps) / len(steps)}  # fmt: skip
    return row


def test_table_5_counts_a_seed_that_never_reached_the_top_at_the_episodes_it_took():
    from experiments.paper.report_mujoco import table5_finding, table5_section

    fast = [100, 110, 120, 130, 140]
    never = _table5_row([None] * 5, [2_000] * 5)
    algos = {"ppo": never, "ppo-model": never, "ppo-ldn": _table5_row(fast, [2_000] * 5)}
    finding = table5_finding("hopper", algos)
    # The unreached seeds are not dropped (on reached seeds only, there would be nothing to test):
    # PPO2-LDN's five against PPO2's 2,000 x 5, p = 0.0075, Holm over the task's two 0.015.
    assert "too few runs to test" not in finding
    assert "PPO2-LDN vs PPO2: Mann-Whitney p = 0.0075, Holm-adjusted over 2 comparisons 0.015, " \
           "P(better) = 1.00" in finding  # fmt: skip
    assert "over every seed, one that never reached it counted at the episodes it took, " \
           "PPO2-LDN (120) < PPO2 (2000) < PPO2-Model (2000)" in finding  # fmt: skip
    assert ": REPRODUCED (PPO2-LDN fewest, as in the paper)." in finding
    # One early seed of PPO2 and four at the budget: the mean of the reached seeds (50) would
    # put PPO2 first; over every seed PPO2-LDN takes fewer.
    algos["ppo"] = _table5_row([50, None, None, None, None], [2_000] * 5)
    finding = table5_finding("hopper", algos)
    assert "PPO2-LDN vs PPO2: Mann-Whitney p = 0.13, " in finding
    assert "P(better) = 0.80" in finding and "PPO2-LDN (120) < PPO2 (1610)" in finding
    # Table 5's family is every task's comparisons: three tasks, six tests.
    table = {"top": "top", "seeds": 5, "rows": []}
    for env in ("inverted_pendulum", "halfcheetah", "hopper"):
        for algo, row in algos.items():
            fields = {"top": 1.0, "min": 1, "max": 1, "sd": 1, "iqm": 1, "ci95": None,
                      "eval_return": {"mean": 1.0, "sd": 1.0}, "paper": 1}  # fmt: skip
            table["rows"].append({**row, **fields, "env": env, "algo": algo, "status": "done"})
    findings = table5_section(table).findings
    assert all("Holm-adjusted over 6 comparisons" in f for f in findings)
    assert "PPO2-LDN vs PPO2-Model: Mann-Whitney p = 0.0075, Holm-adjusted over 6 comparisons " \
           "0.045" in findings[0]  # fmt: skip
    from experiments.paper.report_mujoco import to_top_or_budget

    assert (
        to_top_or_budget(_table5_row([50, None, None, None, None], [900] * 5)) == [50] + [900] * 4
    )


def test_table_5_always_prints_each_seeds_imagined_steps_and_updates():
    from experiments.paper.report_mujoco import table5_finding

    taken = [2_000] * 5
    tops = [100, 110, 120, 130, 140]
    model = ([9_000, 8_000, 7_000, 6_000, 5_000], [9, 8, 7, 6, 5])
    ldn = ([3_558, 3_923, 3_182, 2_825, 3_628], [1, 2, 1, 1, 3])
    algos = {
        "ppo": _table5_row(tops, taken),
        "ppo-model": _table5_row(tops, taken, model),
        "ppo-ldn": _table5_row(tops, taken, ldn),
    }
    finding = table5_finding("hopper", algos)
    # No run made zero updates, and still each seed's steps and updates are there.
    assert " Imagined steps / updates on imagined rows, per seed: PPO2-Model 9,000/9, 8,000/8, " \
           "7,000/7, 6,000/6, 5,000/5 (mean 7,000 steps); PPO2-LDN 3,558/1, 3,923/2, 3,182/1, " \
           "2,825/1, 3,628/3 (mean 3,423 steps, mean LD 0.40)." in finding  # fmt: skip
    assert "made no update" not in finding
    algos["ppo-ldn"]["imagined_updates"] = [0, 2, 1, 1, 3]
    assert "PPO2-LDN made no update on imagined rows in 1 of 5 runs" in table5_finding(
        "hopper", algos
    )


def test_the_cpu_full_scale_runs_every_mujoco_table_at_1m_steps_with_5_seeds():
    from experiments.paper import common

    scale = common.SCALES["cpu-full"]
    assert set(scale.mujoco_budgets) == set(common.MUJOCO)  # Table 4's six tasks
    assert set(scale.ablation_envs) == set(common.MUJOCO)  # Figure 9's MuJoCo panels
    for env in common.MUJOCO:  # Table 5's inverted_pendulum, halfcheetah, hopper among them
        config = common.run_config(scale, env, "ppo-ldn")
        assert (config.seeds, config.steps, config.episode_limit) == (5, 1_000_000, 1000)
    cartpole = common.run_config(scale, "cartpole-v2", "ldn")
    assert cartpole == common.run_config(common.SCALES["cpu"], "cartpole-v2", "ldn")
    # its CartPole runs are the cpu scale's, trained once; its MuJoCo runs its own
    cpu = common.SCALES["cpu"]
    assert cache.run_dir(Path("r"), scale, cartpole) == cache.run_dir(Path("r"), cpu, cartpole)
    hopper = common.run_config(scale, "hopper", "ppo")
    assert cache.run_dir(Path("r"), scale, hopper) == Path("r/runs/cpu-full/hopper-ppo")
    # Table 4's runs on the tasks whose default budget is 1M steps are the family study's
    shared = {
        (env, algo)
        for env in common.MUJOCO
        for algo in ("a2c-model", "ldn")
        if cache.run_dir(Path("r"), scale, config := common.run_config(scale, env, algo))
        == Path(f"r/runs/family/{env}-{algo}-s5")
        and config == common.family_config(env, algo, 5)
    }
    assert {env for env, _ in shared} == {"halfcheetah", "hopper", "walker2d", "ant"}
    assert len(shared) == 8
    pendulum = common.run_config(scale, "inverted_pendulum", "ldn")
    own = Path("r/runs/cpu-full/inverted_pendulum-ldn")
    assert cache.run_dir(Path("r"), scale, pendulum) == own
    from experiments.paper import stops

    rule = stops.dir_of(Path("r"), scale, cartpole, "m2ac")  # the stopping-rule study's too
    assert (
        rule
        == stops.dir_of(Path("r"), cpu, cartpole, "m2ac")
        == Path("r/runs/cpu/stops-cartpole-v2-m2ac")
    )


def test_the_locomotion_study_states_each_tasks_ratio_to_the_zoo(tmp_path):
    from experiments.paper import locomotion

    hopper = {"env": "hopper", "seeds": 2, "steps": 1_000_000, "zoo": 2410.0, "ratio": 0.5}
    hopper |= {"final_moving_return": [1000.0, 1200.0], "eval_return": [1205.0, 1205.0]}
    ant = {**hopper, "env": "ant", "zoo": 1327.0, "ratio": 1.1, "eval_return": [1460.0, 1460.0]}
    hopper["curve"] = {"env_steps": [0, 500_000], "moving_return": [[0.0, 1000.0], [0.0, 1200.0]]}
    rows = [hopper | {"wall_seconds": 300.0}, ant | {"wall_seconds": 900.0}]
    text = locomotion.section(rows)
    assert (
        "| hopper | 1,000,000 | 2 |" in text and "| 1,205, 1,205 | 2,410 | 0.50 | 0 | 300 |" in text
    )
    assert (
        "At the zoo's figure or above: ant (1 of 2 tasks). Not measured yet: halfcheetah, "
        "walker2d, ant-nocfrc. Not in the figure (its curve was not kept): ant." in text
    )
    assert "Side by side" not in text  # no SB3 runs on these cores: no table
    # SB3's runs on these cores, 1M-step lines only, beside ours, per task both have
    sb3 = [
        {"task": "hopper", "seed": 1, "steps": 1_000_000, "mean": 1000.0},
        {"task": "hopper", "seed": 0, "steps": 1_000_000, "mean": 1300.0},
        {"task": "hopper", "seed": 2, "steps": 200_000, "mean": 9999.0},
        {"task": "walker2d", "seed": 0, "steps": 1_000_000, "mean": 10.0},
    ]
    (tmp_path / locomotion.SB3_RUNS).write_text("".join(json.dumps(r) + "\n" for r in sb3))
    runs = locomotion.sb3_runs(tmp_path)
    assert sorted(runs) == ["hopper", "walker2d"] and len(runs["hopper"]) == 2
    text = locomotion.section(rows, runs)
    # ours 1,205 twice against 1,300 and 1,000: one win and one loss each
    assert (
        "| hopper | 2 | 1,300, 1,000 | 1,150 [1,000, 1,300] | 1,205 [1,205, 1,205] "
        "| 0.50 [0.00, 1.00] |" in text
    )
    assert "| walker2d |" not in text and "| ant | 2 |" not in text
    locomotion.curves(rows, tmp_path / "curves.png")  # from the kept curves, without the runs
    assert (tmp_path / "curves.png").stat().st_size > 0
    config = locomotion.config_of("walker2d", 5)
    assert (config.algo, config.seeds, config.steps) == ("ppo", 5, 1_000_000)


def test_the_branched_study_adds_seeds_to_a_finished_run_and_merges_their_rows(
    tmp_path, monkeypatch
):

    finished = ("hopper-ld-s3-100", "hopper-ld-s5-100", "hopper-ld-s5+5-100")
    for name in (*finished, "hopper-ld-s8-100", "hopper-ld-variance-s9-100"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "config.json").write_text("{}")
    monkeypatch.setattr(branched.RunDir, "is_finished", lambda run: run.path.name in finished)

    def dirs(seeds):
        return [
            (a, b, p.name) for a, b, p in branched.run_dirs(tmp_path, "hopper", "ld", seeds, 100)
        ]

    assert dirs(10) == [(0, 5, "hopper-ld-s5-100"), (5, 5, "hopper-ld-s5+5-100")]
    assert dirs(5) == [(0, 5, "hopper-ld-s5-100")]  # its own run, however many others there are
    assert dirs(8) == [(0, 8, "hopper-ld-s8-100")]  # started: resumed, not split
    assert dirs(4) == [(0, 3, "hopper-ld-s3-100"), (3, 1, "hopper-ld-s3+1-100")]
    assert dirs(15) == [  # the 5 and 5 more, then seeds 10-14
        (0, 5, "hopper-ld-s5-100"), (5, 5, "hopper-ld-s5+5-100"), (10, 5, "hopper-ld-s10+5-100")
    ]  # fmt: skip
    assert dirs(2) == [(0, 2, "hopper-ld-s2-100")]
    # on a fresh clone a finished run's record stands in for its directory
    runs = tmp_path / "results" / "runs" / "branched"
    record = tmp_path / "results" / "records" / "branched" / "hopper-m2ac-s5-100"
    record.mkdir(parents=True)
    whole = [(0, 10, runs / "hopper-m2ac-s10-100")]
    assert branched.run_dirs(runs, "hopper", "m2ac", 10, 100) == whole  # not finished
    (record / "summary.json").write_text("{}")
    assert branched.run_dirs(runs, "hopper", "m2ac", 10, 100) == [
        (0, 5, runs / "hopper-m2ac-s5-100"), (5, 5, runs / "hopper-m2ac-s5+5-100")
    ]  # fmt: skip
    rows = [
        {"seeds": 5, "final_moving_return": [1.0] * 5, "eval_return": [2.0] * 5,
         "steps_to_solve": None, "imagined_per_real": 4.0, "train_seconds": 10.0},
        {"seeds": 3, "final_moving_return": [3.0] * 3, "eval_return": [4.0] * 3,
         "steps_to_solve": None, "imagined_per_real": 0.0, "train_seconds": 5.0},
    ]  # fmt: skip
    row = branched.merged(rows)
    assert row["final_moving_return"] == [1.0] * 5 + [3.0] * 3 and row["eval_return"][-1] == 4.0
    assert (row["seeds"], row["imagined_per_real"], row["train_seconds"]) == (8, 2.5, 15.0)
    assert branched_rules.config_of("hopper", "ld", 5, 100, first_seed=5).first_seed == 5
    # The study's rules keep their meaning whatever the preset's task default: on hopper
    # (whose preset trains the critic only on imagined rows) only the rules that say so do.
    updates = lambda rule: branched_rules.config_of("hopper", rule, 5, 100).imagine.updates
    assert [updates(r) for r in ("cap-5", "ld", "critic-5", "ld-critic-5")] == [
        "all", "all", "critic", "critic"
    ]  # fmt: skip


def test_the_late_training_return_reads_the_last_tenth_of_the_budget():

    # Two seeds, three iterations of two episode slots each (budget 1,000): the episodes
    # that ended past 900 steps count, each once; seed 1 ended none there.
    ended = np.array(
        [
            [
                [[True, False], [True, True], [True, True]],
                [[True, False], [True, False], [False, False]],
            ]
        ]
    )
    steps_at = np.array([[[[300, 0], [600, 905], [950, 1000]], [[300, 0], [600, 0], [0, 0]]]])
    returns = np.array(
        [[[[1.0, 0.0], [2.0, 3.0], [4.0, 8.0]], [[1.0, 0.0], [2.0, 0.0], [0.0, 0.0]]]]
    )
    env_steps = np.array([[[300, 905, 1000], [300, 600, 1000]]])
    history = {"env_steps": env_steps, "returns": returns, "ended": ended, "steps_at": steps_at}
    assert branched.late_returns(history, 1000) == [5.0, None]  # (3 + 4 + 8) / 3
    # Schedule "episodes": every worker's episode of an iteration past the mark counts.
    history = {"env_steps": env_steps, "returns": returns}
    assert branched.late_returns(history, 1000) == [4.25, 0.0]  # (2 + 3 + 4 + 8) / 4
    with pytest.raises(ValueError, match="one K"):
        branched.late_returns({**history, "env_steps": np.repeat(env_steps, 2, 0)}, 1000)
    assert report_branched._late_text({"late_return": None}) == "–"
    assert report_branched._late_text({"late_return": [None, None]}) == "–"
    assert report_branched._late_text({"late_return": [2.0, None, 2.0]}) == "2 [2, 2]"
    parts = [{"late_return": [1.0]}, {"late_return": None}]
    rows = [{**p, "seeds": 1, "imagined_per_real": 0.0, "train_seconds": 1.0,
             "final_moving_return": [0.0], "eval_return": [0.0], "steps_to_solve": None}
            for p in parts]  # fmt: skip
    assert branched.merged(rows)["late_return"] is None


def test_the_branched_study_keeps_earlier_rows_and_names_each_envs_seeds(tmp_path):

    def row(env, rule, seeds, value):
        return {"env": env, "rule": rule, "steps": 100, "name": branched_rules.RULES[rule][2],
                "final_moving_return": [value] * seeds, "eval_return": [value] * seeds,
                "imagined_per_real": 0.0, "steps_to_solve": None, "train_seconds": 1.0}  # fmt: skip

    rows = [row("hopper", "ppo", 3, 10.0), row("hopper", "cap-5", 3, 20.0), row("x", "ppo", 1, 1)]
    (tmp_path / "b.json").write_text(json.dumps({"rows": rows}))
    earlier = branched._earlier(tmp_path / "b.json")
    assert [(r["env"], r["rule"]) for r in earlier] == [("hopper", "ppo"), ("hopper", "cap-5")]
    text = report_branched.section(earlier)
    assert "### hopper, 100 steps, 3 seeds" in text
    assert "| training return, last 10% of steps |" in text and "| 3 | 10 [10, 10] | – |" in text
    text = report_branched.section([*earlier, row("hopper", "mbpo", 5, 40.0)])
    assert "### hopper, 100 steps, 3-5 seeds" in text
    # Mann-Whitney on the greedy returns, Holm over the env's two rules (3 v 3 and 5 v 3)
    assert "Verdicts on hopper (Holm over 2 rules)" in text
    assert "no rule, cut at 5 steps: beats PPO (P 1.00, p 0.047, Holm 0.047)" in text
    assert "1 to 15: beats PPO (P 1.00, p 0.014, Holm 0.027)" in text
    close = [row("hopper", "ppo", 3, 10.0), row("hopper", "cap-5", 3, 20.0)]
    close[1]["eval_return"] = [9.0, 10.0, 11.0]
    assert "cut at 5 steps: no difference shown (P 0.50" in report_branched.section(close)
    assert "LD draw against" not in text  # no LD row, no question asked
    # The study's question: the LD draw against the field's rules and the best fixed cap.
    rows = [*earlier, row("hopper", "ld", 3, 30.0), row("hopper", "mbpo", 3, 40.0)]
    text = report_branched.section(rows)
    assert (
        "The LD draw against the other rules on hopper, P(better): MBPO's horizon schedule, "
        "1 to 15 0.00 [0.00, 0.00]; no rule, cut at 5 steps 1.00 [1.00, 1.00]"
    ) in text


def test_the_branched_studys_targets_say_by_how_much_the_best_rule_misses_them():

    def row(rule, moving, greedy):
        return {"env": "hopper", "rule": rule, "steps": 100, "name": branched_rules.RULES[rule][2],
                "final_moving_return": moving, "eval_return": greedy, "imagined_per_real": 0.0,
                "steps_to_solve": None, "train_seconds": 1.0}  # fmt: skip

    rows = [
        row("ppo", [900.0] * 4, [1000.0] * 4),
        row("cap-5", [1500.0] * 4, [2500.0] * 4),  # the best greedy: meets 2,000
        row("ld", [1800.0] * 4, [800.0] * 4),  # the best moving: 200 short of 2,000
        row("true-5", [5000.0] * 4, [5000.0] * 4),  # a bound, not a method: left out
    ]
    text = report_branched.section(rows)
    assert (
        "The branched preset's targets on hopper, over the best of its 2 model-based rules "
        "(a maximum over rules, so an optimistic reading): final moving return >= 2,000: "
        "missed by 200 (the best IQM, 1,800: LD draw, disagreement, cap 15); greedy return "
        ">= 2,000: met (the best IQM, 2,500: no rule, cut at 5 steps); P(> PPO) above 0.75: "
        "met (the highest, 1.00: no rule, cut at 5 steps)."
    ) in text
    assert "targets on inverted_pendulum" not in report_branched.section(
        [{**r, "env": "inverted_pendulum"} for r in rows]
    )


def test_the_cached_branched_study_rereads_finished_rows_and_trains_nothing(tmp_path, monkeypatch):

    runs = tmp_path / "runs" / "branched"
    for name in ("hopper-ld-s5-100", "hopper-ld-s5+5-100"):
        (runs / name).mkdir(parents=True)
        (runs / name / "config.json").write_text("{}")
    monkeypatch.setattr(branched.RunDir, "is_finished", lambda run: run.path.exists())
    monkeypatch.setattr(branched.RunDir, "read_summary", lambda run: {"seeds": run.path.name})
    read = []

    def results_of(env, rule, out, summary, steps):
        read.append(out.name)
        return {"env": env, "rule": rule, "steps": steps, "name": branched_rules.RULES[rule][2],
                "seeds": 5, "final_moving_return": [7.0] * 5, "eval_return": [7.0] * 5,
                "imagined_per_real": 4.0, "steps_to_solve": None, "train_seconds": 1.0,
                "late_return": [7.0] * 5}  # fmt: skip

    monkeypatch.setattr(branched, "results_of", results_of)
    monkeypatch.setattr(branched.cache, "ensure_run", lambda *a: pytest.fail("trained"))

    def row(rule, seeds):
        return {"env": "hopper", "rule": rule, "steps": 100, "name": branched_rules.RULES[rule][2],
                "seeds": seeds, "final_moving_return": [1.0] * seeds,
                "eval_return": [1.0] * seeds, "imagined_per_real": 4.0, "steps_to_solve": None,
                "train_seconds": 1.0}  # fmt: skip

    (tmp_path / "branched").mkdir()
    (tmp_path / "branched" / "branched.json").write_text(
        json.dumps({"rows": [row("ld", 10), row("mbpo", 5)]})
    )
    real_cached = branched._cached

    def cached_then_rewritten(out, runs, args):
        """Another call rewrites the mbpo row while this one re-reads its runs."""
        found = real_cached(out, runs, args)
        (runs / "hopper-mbpo-s5-100").mkdir()
        found["hopper", "mbpo"] = ({**row("mbpo", 5), "eval_return": [9.0] * 5}, row("mbpo", 5))
        rewritten = {**row("mbpo", 5), "train_seconds": 3.0}
        (out / "branched.json").write_text(json.dumps({"rows": [row("ld", 10), rewritten]}))
        return found

    monkeypatch.setattr(branched, "_cached", cached_then_rewritten)
    assert branched.main(["--cached", "--results", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "branched" / "branched.json").read_text())["rows"]
    assert read == ["hopper-ld-s5-100", "hopper-ld-s5+5-100"]  # the 10-seed row's two parts
    ld, mbpo = (next(r for r in rows if r["rule"] == rule) for rule in ("ld", "mbpo"))
    assert ld["eval_return"] == [7.0] * 10 and ld["late_return"] == [7.0] * 10
    # the other call's row stays; it names no committed record (none in tmp_path)
    assert mbpo == {**row("mbpo", 5), "train_seconds": 3.0, "recorded": False}
    assert ld["recorded"] is False


def test_the_family_study_says_which_model_runs_never_imagined(tmp_path):
    from experiments.paper import common, family, targets

    curve = {"env_steps": [0, 500_000], "moving_return": [[0.0, 100.0], [0.0, 300.0]]}
    a2c = {"env": "hopper", "algo": "a2c", "seeds": 2, "steps": 1_000_000, "diverged": 0}
    a2c |= {"final_moving_return": [100.0, 300.0], "eval_return": [150.0, 250.0]}
    a2c |= {"imagined_steps": None, "wall_seconds": 300.0, "curve": curve}
    ldn = {**a2c, "algo": "ldn", "imagined_steps": [0, 4000]}
    text = family.section([a2c, ldn])
    assert "| hopper | A3C | 1,000,000 | 2 |" in text and "| 150, 250 | – | 0 | 300 |" in text
    assert "| hopper | MBRL-LDN |" in text and "| 2,000 (1 of 2 seeds none) | 0 | 300 |" in text
    assert "Not measured yet: inverted_pendulum a2c," in text and "hopper a2c-model" in text
    assert "| 300 | not recorded |" in text and "stale" not in text  # rows from before the column
    # hopper's family standardises observations and rewards: a row that did not is stale
    fresh = {**a2c, "standardised": "observations and rewards"}
    text = family.section([fresh, {**ldn, "standardised": "nothing"}])
    assert "| 300 | observations and rewards |" in text
    assert "| 300 | nothing (not today's default) |" in text
    assert "default changed (hopper ldn): the column" in text
    assert family.standardised({"normalize_obs": True, "normalize_reward": False}) == "observations"
    family.curves([a2c, ldn], tmp_path / "family.png")  # from the kept curves, without the runs
    assert (tmp_path / "family.png").stat().st_size > 0
    config = family.config_of("ant", "a2c-model", 5)
    assert (config.algo, config.seeds, config.steps) == ("a2c-model", 5, 1_000_000)
    # inverted_pendulum's runs are the targets' (one config, trained once for both)
    cpu = common.SCALES["cpu"]
    for algo in family.ALGOS:
        pendulum = targets.run_config(cpu, "inverted_pendulum", algo, 5, (1.0,))
        assert family.config_of("inverted_pendulum", algo, 5) == pendulum
        assert family.run_dir(Path("r"), "inverted_pendulum", algo, 5) == targets.run_dir(
            Path("r"), cpu, pendulum
        )
    assert family.run_dir(Path("r"), "hopper", "ldn", 5) == Path("r/runs/family/hopper-ldn-s5")
    with pytest.raises(SystemExit) as bad:
        family.main(["--algos", "ppo", "--results", str(tmp_path)])
    assert bad.value.code == 2


def test_the_branched_presets_ppo_ldn_is_the_studys_ld_row_where_it_beat_ppo():
    from ldn_jax.config import from_preset, validate

    for env in ("halfcheetah", "inverted_pendulum"):
        study = branched_rules.config_of(env, "ld", 5, 200_000)
        user = from_preset("branched", env=env, algo="ppo-ldn", seeds=5, steps=200_000)
        solved = branched_rules.SOLVED.get(env)
        assert study == validate(dataclasses.replace(user, solved_return=solved))


def test_the_branched_studys_figure_draws_from_its_rows_alone(tmp_path):

    def row(env, rule, scores, solve=None):
        return {
            "env": env,
            "rule": rule,
            "steps": 1000,
            "eval_return": scores,
            "steps_to_solve": solve,
        }

    rows = [
        row("hopper", "ppo", [1.0, 2.0, 3.0]),
        row("hopper", "ld", [2.0, 3.0, 4.0]),
        row("hopper", "true-5", [5.0, 6.0, 7.0]),
        row("inverted_pendulum", "ppo", [1.0, 1.0], solve=[300, 500]),
        row("inverted_pendulum", "cap-15", [1.0, 1.0], solve=[200, 400]),
    ]
    report_branched.figure(rows, tmp_path / "branched.png")
    assert (tmp_path / "branched.png").stat().st_size > 0
    assert "![branched](branched/branched.png)" in report_branched.section(
        [r | {"name": "", "final_moving_return": [0.0] * 3, "late_return": None,
              "imagined_per_real": 0.0, "train_seconds": 1.0} for r in rows[:3]]
    )  # fmt: skip


def test_a_curve_whose_seeds_end_at_different_episode_counts_is_drawn_at_their_mean():
    from ldn_jax.host.plots import band_panel, pyplot

    # Seed 0 reaches its step budget after 2 iterations and holds; seed 1 goes on.
    episodes = np.array([[8, 16, 16, 16], [8, 16, 24, 32]])
    returns = np.array([[1.0, 2.0, 2.0, 2.0], [1.0, 2.0, 3.0, 4.0]])
    plt = pyplot()
    fig, ax = plt.subplots()
    band_panel(ax, {"a": (episodes, returns)})
    x, y = ax.get_lines()[0].get_data()
    plt.close(fig)
    np.testing.assert_allclose(x, [8, 16, 20, 24])  # not seed 0's 16, 16: a vertical line
    np.testing.assert_allclose(y, [1.0, 2.0, 2.5, 3.0])


def test_a_replayed_runs_file_names_only_the_commits_that_trained_what_it_holds(
    tmp_path, monkeypatch
):
    class Started(Exception):
        pass

    def start(config, out):
        raise Started  # training would start here: the file is written before it

    monkeypatch.setattr(cache, "ensure_run", start)
    config = from_preset("paper", env="inverted_pendulum", algo="a2c")
    file = tmp_path / "arm.json"
    out = tmp_path / "runs" / "arm"  # empty: a new machine, or a run cleared for another config
    old = {"task": "x", "commits": ["old1234"], "gymnasium": [[1.0]], "train_seconds": 9.0}
    for resumable, commits in ((False, ["new5678"]), (True, ["old1234", "new5678"])):
        file.write_text(json.dumps(old))
        monkeypatch.setattr(cache, "_resumable", lambda config, out, r=resumable: r)
        with pytest.raises(Started):
            cache.ensure_replayed(config, out, file, {"task": "x"}, ("new5678", 1))
        # the earlier run's results go: they are not of the run that trains now
        assert json.loads(file.read_text()) == {"task": "x", "commits": commits}
