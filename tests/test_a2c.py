"""The A2C family's own section (`a2c.*`): GAE, the gradient clip, PyTorch's RMSProp, and
the paper's A2C left as it was."""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.config import A2CConfig, AgentConfig, from_preset, validate
from ldn_jax.learners.a2c import A2C, n_step_targets
from ldn_jax.learners.base import Segment
from ldn_jax.learners.ppo import gae

OBS, ACTIONS, N, W = 5, 2, 6, 3
SPEC = SimpleNamespace(discrete=False, size=ACTIONS, low=(-1.0,) * ACTIONS, high=(1.0,) * ACTIONS)


def segment(key) -> Segment:
    keys = jax.random.split(key, 5)
    done = jax.random.uniform(keys[3], (N, W)) < 0.2
    return Segment(
        obs=jax.random.normal(keys[0], (N, W, OBS)),
        action=jax.random.uniform(keys[1], (N, W, ACTIONS), minval=-1, maxval=1),
        reward=jax.random.normal(keys[2], (N, W)),
        next_obs=jax.random.normal(keys[4], (N, W, OBS)),
        terminated=done & (jax.random.uniform(keys[3], (N, W)) < 0.1),
        done=done,
        weight=jnp.ones((N, W)),
    )


def learner(**a2c) -> A2C:
    agent = AgentConfig(gamma=0.97, log_std_init=0.0, squash_mean=False, rmsprop_eps=1e-5)
    return A2C(agent, OBS, SPEC, W, A2CConfig(**a2c))


def test_advantages_are_n_step_at_lambda_one_and_gae_below():
    seg = segment(jax.random.key(0))
    paper, lam = learner(), learner(gae_lambda=0.9)
    params = paper.init(jax.random.key(1)).params
    value = paper.value(params, seg.obs)
    next_value = paper.value(params, seg.next_obs)
    targets = n_step_targets(seg.reward, next_value, seg.terminated, seg.done, 0.97)
    np.testing.assert_array_equal(paper.advantage(params, seg), targets - value)
    expected = gae(seg.reward, value, next_value, seg.terminated, seg.done, (0.97, 0.9))
    np.testing.assert_allclose(lam.advantage(params, seg), expected, rtol=1e-5, atol=1e-6)
    assert not np.allclose(expected, targets - value, atol=1e-3)


def test_torch_rmsprop_steps_as_pytorch_does():
    """PyTorch: v = (1 - a) g^2 from zero, p <- p - lr g / (sqrt(v) + eps)."""
    net = learner(rmsprop="torch")
    params = net.init(jax.random.key(2)).params
    grads = jax.tree.map(lambda p: jnp.full_like(p, 0.003), params)
    state = net.optimizer.init(params)
    updates, _ = net.optimizer.update(grads, state, params)
    decay, eps, lr = 0.9, 1e-5, net.config.actor_lr
    expected = -lr * 0.003 / (np.sqrt((1 - decay) * 0.003**2) + eps)
    np.testing.assert_allclose(updates["actor"]["params"]["Dense_0"]["kernel"], expected, rtol=1e-5)
    tf1 = learner()  # TensorFlow 1: v = a + (1 - a) g^2 from one, eps inside the root
    updates, _ = tf1.optimizer.update(grads, tf1.optimizer.init(params), params)
    expected = -lr * 0.003 / np.sqrt(decay + (1 - decay) * 0.003**2 + eps)
    np.testing.assert_allclose(updates["actor"]["params"]["Dense_0"]["kernel"], expected, rtol=1e-5)


def test_the_clip_scales_actor_and_critic_gradients_together():
    clipped, free = learner(rmsprop="torch", max_grad_norm=1e-6), learner(rmsprop="torch")
    params = clipped.init(jax.random.key(3)).params
    grads = jax.tree.map(lambda p: jnp.full_like(p, 0.01), params)
    norm = np.sqrt(sum(float(jnp.sum(g**2)) for g in jax.tree.leaves(grads)))
    updates, _ = clipped.optimizer.update(grads, clipped.optimizer.init(params), params)
    scaled = jax.tree.map(lambda g: g * 1e-6 / norm, grads)
    expected, _ = free.optimizer.update(scaled, free.optimizer.init(params), params)
    for a, b in zip(jax.tree.leaves(updates), jax.tree.leaves(expected), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4)
    unclipped, _ = free.optimizer.update(grads, free.optimizer.init(params), params)
    assert not np.allclose(jax.tree.leaves(unclipped)[0], jax.tree.leaves(updates)[0])


def test_the_value_weight_scales_the_critic_loss():
    seg = segment(jax.random.key(4))
    one, half = learner(), learner(value_coef=0.5)
    params = one.init(jax.random.key(5)).params
    (total_one, info), (total_half, _) = one.loss(params, seg), half.loss(params, seg)
    np.testing.assert_allclose(total_one - total_half, 0.5 * info["critic_loss"], rtol=1e-5)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("rmsprop", "adam", "a2c rmsprop must be one of tf1, torch"),
        ("gae_lambda", 1.5, "a2c gae_lambda must be in [0, 1]"),
        ("max_grad_norm", 0.0, "a2c max_grad_norm must be > 0"),
        ("value_coef", -1.0, "a2c value_coef must be >= 0"),
    ],
)
def test_bad_a2c_fields_are_refused(field, value, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        validate(from_preset("paper", env="halfcheetah", algo="a2c", a2c={field: value}))


def test_the_tuning_study_arms_are_valid_runs_and_sb3s_is_sb3s_a2c():
    from experiments.paper import a2c as study

    for arm in study.ARMS:
        for task in study.TASKS:
            assert study.config_of(task, arm, 0, 1000).algo == "a2c"
    sb3 = study.config_of("halfcheetah", "sb3", 0, 1000)
    assert (sb3.workers, sb3.agent.n_steps, sb3.schedule) == (1, 5, "steps")
    assert (sb3.a2c.rmsprop, sb3.a2c.max_grad_norm, sb3.a2c.value_coef) == ("torch", 0.5, 0.5)
    assert sb3.agent.normalize_obs and sb3.agent.normalize_reward
    assert (sb3.agent.init, sb3.agent.hidden_layers, sb3.agent.actor_hidden) == (
        "orthogonal",
        2,
        64,
    )
    assert sb3.agent.actor_lr == sb3.agent.critic_lr == 7e-4


def test_the_study_refuses_an_algorithm_outside_the_plan(capsys):
    from experiments.paper import a2c as study

    with pytest.raises(SystemExit) as stop:
        study.main(["--confirm", "ppo"])
    assert stop.value.code == 2
    assert "unknown algorithm for --confirm: ppo" in capsys.readouterr().err


def test_the_a2c_plan_tests_once_its_runs_are_in_and_reads_targets_and_imagination(tmp_path):
    import json

    from experiments.paper import a2c as study

    confirm = tmp_path / "a2c" / "confirm"
    confirm.mkdir(parents=True)
    base = {"hopper": {"a2c": 1100.0, "a2c-model": 800.0, "ldn": 2000.0}}
    base["halfcheetah"] = {"a2c": 3000.0, "a2c-model": 3000.0, "ldn": 3000.0}

    def write(task, algo):
        seeds = list(range(study.CONFIRM_SEEDS, study.CONFIRM_SEEDS + study.SEEDS))
        data = {"task": task, "algo": algo, "seeds": seeds, "steps": 1000, "commits": ["abc"]}
        data["gymnasium"] = [[base[task][algo] + s, base[task][algo] + s] for s in seeds]
        (confirm / f"{task}-{algo}-s10+5-1000.json").write_text(json.dumps(data))

    for task in study.CONFIRM_TASKS:
        for algo in study.CONFIRM_ALGOS:
            if (task, algo) != ("hopper", "a2c-model"):
                write(task, algo)
    rows = [{**r, "imagined_per_real": 0.01} for r in study._scored(confirm)]
    assert study.confirm_tests(rows) is None
    waiting = "\n".join(study.confirm_section(rows, None))
    assert "wait for: hopper `a2c-model`" in waiting
    assert "3,041: not met" in waiting and "1,000: met" in waiting
    assert "1.00% (under 5% of its real steps)" in waiting
    write("hopper", "a2c-model")
    found = study.confirm_tests(study._scored(confirm))
    assert [(t["task"], t["a"], t["b"]) for t in found] == [
        (task, "ldn", b) for task in study.CONFIRM_TASKS for b in ("a2c", "a2c-model")
    ]
    # hopper separates cleanly (p = 1/252, Holm x4 < 0.05); halfcheetah's ties cannot
    assert [t["shown"] for t in found] == [False, False, True, True]
    line = {"task": "hopper", "seed": 0, "steps": 1000, "train_seconds": 10, "mean": 733.4}
    (tmp_path / "a2c" / study.SB3_RUNS).write_text(json.dumps(line) + "\n")
    study.report(tmp_path)
    text = (tmp_path / "a2c" / "a2c.md").read_text()
    # beside SB3's run: ours at the same budget on the fresh seeds (1,110 ... 1,114 each)
    assert "| hopper | 1,000 | 0 | 733 | 10 | 100 | – | – | 1,112 [" in text
    assert "halfcheetah `ldn` vs `a2c`: yes" in text and "hopper `ldn` vs `a2c`: no" in text
