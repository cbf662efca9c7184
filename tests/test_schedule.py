"""Schedule "steps": fixed-length iterations whose episodes carry over. Counts equal the sums
of the per-step weights and of the episodes that ended, an episode's return spans
iterations, the moving return advances in completion order, resume and a device split give
the one-device run to the bit, and bad values fail in one line."""

import json
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.config import from_preset, validate
from ldn_jax.host import checkpoint
from ldn_jax.host.metrics import run_crossing, threshold_crossing
from ldn_jax.host.run_dir import read_config as read_run_config
from ldn_jax.host.training import Interrupted, train
from ldn_jax.rollout import Batch, Player, play_batch
from ldn_jax.trainer import Trainer
from tests.conftest import optimised
from tests.test_resume import StopAfter, _lines
from tests.test_scale import _run

ROOT = Path(__file__).resolve().parents[1]
T, W = 20, 4
CONFIG = dict(env="cartpole-v0", algo="ldn", seeds=2, k=(0.5, 2.0), workers=W)
CONFIG |= dict(schedule="steps", iteration_steps=T, chunk_iterations=2, steps=8 * T * W)
ARGS = ["--env", "cartpole-v0", "--algo", "ldn", "--seeds", "2", "--k", "0.5,2"]
ARGS += ["--workers", str(W), "--schedule", "steps", "--iteration-steps", str(T)]
ARGS += ["--steps", str(8 * T * W), "--chunk", "2", "--quiet"]


@pytest.fixture(scope="module")
def played():
    """A few iterations of a2c-model on cartpole-v0 (a model, a buffer and imagination),
    every per-step weight kept: the real stage is replayed from each iteration's state."""
    config = validate(from_preset("paper", **{**CONFIG, "algo": "a2c-model", "seeds": 1}))
    trainer = Trainer(config)
    state = trainer.init_state(jax.random.key(0))
    iteration = jax.jit(lambda s: trainer.iteration(s, 1.0))
    real = jax.jit(lambda s: trainer.real_stage(s, jax.random.split(s.key, 4)[1])[1].episodes)
    states, metrics, weights = [state], [], []
    for _ in range(6):
        weights.append(real(state).steps.weight)
        state, m = iteration(state)
        states.append(state)
        metrics.append(m)
    return config, _host(states), _host(metrics), _host(weights)


def _host(tree):
    """Numpy leaves (keys as their data)."""
    keys = lambda x: jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)
    return jax.tree.map(lambda x: np.asarray(jax.random.key_data(x) if keys(x) else x), tree)


def test_counts_equal_the_sums_of_the_weights_and_of_the_ended_episodes(played):
    _, states, metrics, weights = played
    final = states[-1]
    assert all(w.shape == (T, W) and (w == 1).all() for w in weights)  # nothing masked
    assert final.env_steps == sum(w.sum() for w in weights) == 6 * T * W
    assert final.episodes == sum(m["ended"].sum() for m in metrics) > 0
    assert final.buffer.size == final.env_steps  # every real step fits M1
    assert final.imagined_steps == sum(
        m["imagined_steps"] - s.imagined_steps for m, s in zip(metrics, states, strict=False)
    )
    assert final.iteration == 6
    imagined = np.diff([s.imagined_steps for s in states])
    assert (imagined > 0).all() and (imagined <= T * W).all()  # within the real steps' bound


def test_episodes_carry_over_and_their_returns_span_iterations(played):
    _, states, metrics, _ = played
    ended = np.stack([m["ended"] for m in metrics])  # [I, T * W], (step, worker) order
    lengths = np.stack([m["lengths"] for m in metrics])
    returns = np.stack([m["returns"] for m in metrics])
    np.testing.assert_array_equal(returns[ended], lengths[ended])  # CartPole: 1 per step
    # Per worker: the episodes that ended and the one still running cover every step.
    per_worker = np.where(ended, lengths, 0).reshape(6, T, W).sum(axis=(0, 1))
    np.testing.assert_array_equal(per_worker + states[-1].workers.time, 6 * T)
    assert (lengths[ended] > T).any(), "no episode crossed an iteration boundary"
    np.testing.assert_array_equal(states[-1].workers.total, states[-1].workers.time)


def test_the_moving_return_and_the_crossing_follow_completion_order(played):
    _, states, metrics, _ = played
    history = {name: np.stack([m[name] for m in metrics]) for name in metrics[0]}
    history["env_steps"] = np.stack([s.env_steps for s in states[1:]])
    finished = history["returns"][history["ended"]]
    moving, want = np.nan, []
    for r in finished:
        moving = r if np.isnan(moving) else 0.99 * moving + 0.01 * r
        want.append(moving)
    np.testing.assert_allclose(history["moving_after"][history["ended"]], want, rtol=1e-6)
    # The crossing of a threshold just below the k-th episode's moving return is the k-th
    # episode, counted over iterations, at the env steps of the step it ended.
    k = len(want) // 2
    level = max(want[: k + 1])
    k = int(np.argmax(np.asarray(want) >= level))
    episode, steps, iteration = run_crossing(history, (), level)
    assert episode == k + 1
    i, j = divmod(int(np.flatnonzero(history["ended"].reshape(-1))[k]), T * W)
    assert iteration == i and steps == i * T * W + (j // W + 1) * W


def test_threshold_crossing_on_hand_made_episodes():
    ended = np.array([[False, True, False, True], [True, False, False, False]])
    after = np.array([[np.nan, 10.0, 10.0, 12.0], [15.0, 15.0, 15.0, 15.0]])
    steps_at = np.array([[2, 2, 4, 4], [6, 6, 8, 8]])
    lengths = np.zeros((2, 4), int)
    env_steps = np.array([4, 8])
    cross = lambda level: threshold_crossing(after, lengths, env_steps, level, ended, steps_at)
    assert cross(11.0) == (2, 4, 0)
    assert cross(14.0) == (3, 6, 1)  # entries that are not episodes never count
    assert cross(16.0) is None


def test_a_run_is_deterministic(played):
    config, states, _, _ = played
    trainer = Trainer(config)
    again = jax.jit(lambda s: trainer.iteration(s, 1.0))(trainer.init_state(jax.random.key(0)))
    for a, b in zip(jax.tree.leaves(_host(again[0])), jax.tree.leaves(states[1]), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("steps-reference")
    with optimised():  # the `optimized` tests below hold other programs to its bits
        summary = train(
            from_preset("paper", **CONFIG), out, checkpoint_every=1, quiet=True, bitwise=True
        )
    return out, summary


@pytest.mark.optimized
def test_resume_equals_the_uninterrupted_run_bitwise(reference, tmp_path):
    ref_dir, ref_summary = reference
    with pytest.raises(Interrupted):
        train(
            from_preset("paper", **CONFIG),
            tmp_path,
            checkpoint_every=1,
            quiet=True,
            bitwise=True,
            stop=StopAfter(2),
        )
    summary = train(
        read_run_config(tmp_path), tmp_path, checkpoint_every=1, quiet=True, resume=True
    )
    assert _lines(tmp_path) == _lines(ref_dir)
    assert [r["eval_return"] for r in summary["runs"]] == [
        r["eval_return"] for r in ref_summary["runs"]
    ]
    lines = _lines(ref_dir)
    assert max(line["env_steps"] for line in lines) == 8 * T * W
    assert len(lines) == 2 * 2 * 8  # K x seeds x iterations: a steps budget is exact


@pytest.mark.slow  # the default suite splits a schedule "steps" run in test_branched.py
@pytest.mark.optimized
def test_two_devices_give_the_one_device_run_to_the_bit(reference, tmp_path):
    out = tmp_path / "two"
    args = [*ARGS, "--devices", "2", "--bitwise", "--compile-cache", "none", "--out", str(out)]
    result = _run(*args, devices=2)
    assert result.returncode == 0, result.stderr
    assert _lines(out) == _lines(reference[0])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["devices"] == 2


def test_an_episodes_budget_stops_each_run_once_it_has_them(tmp_path):
    config = from_preset("paper", **{**CONFIG, "algo": "a2c", "steps": None, "episodes": 30})
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    lines = _lines(tmp_path)
    for seed in range(2):
        counts = [line["episodes"] for line in lines if line["seed"] == seed]
        first = next(i for i, c in enumerate(counts) if c >= 30)
        assert counts[first:] == [counts[first]] * (len(counts) - first)  # frozen once spent
        assert first == 0 or counts[first - 1] < 30
    assert summary["real_episodes"] >= 2 * 30
    assert len(lines) < 2 * config.iterations  # stopped before the bound


@pytest.mark.parametrize(
    "args, message",
    [
        (["--schedule", "steps", "--iteration-steps", "15"], "multiple of n_steps"),
        (["--iteration-steps", "20"], "iteration_steps is schedule steps'"),
        (["--schedule", "laps"], "invalid choice"),
    ],
)
def test_bad_schedules_fail_in_one_line(tmp_path, args, message):
    result = subprocess.run(
        [
            sys.executable,
            str(ROOT / "experiments" / "run.py"),
            "--algo",
            "a2c",
            *args,
            "--out",
            str(tmp_path / "x"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_quota_of_imagined_episodes_plays_each_workers_owed_episodes(played):
    """A world whose episodes last 3 steps: worker w plays quota[w] of them, then idles
    masked; the one that would overrun the step bound is cut there."""
    config, _, _, _ = played
    learner = Trainer(config).learner
    quota = jnp.array([0, 1, 2, 9])  # 9 x 3 steps > the 2 segments' 20: cut at step 20

    def world_step(key, world, obs, action, alive):
        world = world + 1
        ones = jnp.ones(world.shape)
        return obs, world, ones, world % 3 == 0, jnp.zeros(world.shape, bool), {}

    obs = jnp.zeros((4, 4))
    reset = lambda key: (obs, jnp.zeros(4, jnp.int32))
    params = learner.init(jax.random.key(0))
    player = Player(learner, world_step, 1000, learn=False)
    batch = Batch(reset=reset, quota=quota, segments=2)
    _, episodes = play_batch(
        jax.random.key(1), params, player, (obs, jnp.zeros(4, jnp.int32)), batch
    )
    np.testing.assert_array_equal(episodes.lengths, [0, 3, 6, 20])
    np.testing.assert_array_equal(episodes.ended, [0, 1, 2, 6])


def test_a_mujoco_workers_state_checkpoints_with_its_empty_arrays(tmp_path):
    """The native engine's state has zero-size arrays, which orbax alone refuses."""
    config = validate(
        from_preset(
            "paper",
            env="inverted_pendulum",
            algo="a2c",
            seeds=1,
            schedule="steps",
            iteration_steps=10,
            steps=1000,
        )
    )
    trainer = Trainer(config)
    state = trainer.init_batch()
    assert any(x.size == 0 for x in jax.tree.leaves(state.workers))
    checkpoint.save(tmp_path / "state", state)
    back = checkpoint.restore(tmp_path / "state", jax.eval_shape(trainer.init_batch))
    for a, b in zip(jax.tree.leaves(_host(back)), jax.tree.leaves(_host(state)), strict=True):
        assert a.shape == b.shape
        np.testing.assert_array_equal(a, b)
