"""Sweeps: a grid of float fields as a vmap axis beside seeds and K, one compiled program.
It equals the single runs it replaces; ints and host-side fields are refused; it resumes,
splits over devices and names its points in every file."""

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from ldn_jax import load_policy
from ldn_jax.config import from_preset, get_field, sweepable, validate
from ldn_jax.host import flags
from ldn_jax.host.run_dir import read_config as read_run_config
from ldn_jax.host.settings import UsageError
from ldn_jax.host.training import Interrupted, train
from ldn_jax.trainer import Trainer
from tests.test_resume import StopAfter, _lines, _timeless

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, str(ROOT / "experiments" / "run.py")]
GRID = (("agent.actor_lr", (1e-3, 3e-4)), ("agent.gamma", (0.9, 0.99)))
TINY = dict(env="cartpole-v0", seeds=2, k=(1.0,), workers=4, episodes=16, chunk_iterations=2)


def _metrics(config, chunks: int = 2) -> dict[str, np.ndarray]:
    trainer = Trainer(config)
    states, chunk = trainer.init_batch(), trainer.batched_chunk()
    out = []
    for _ in range(chunks):
        states, metrics = chunk(states, trainer.point_values())
        out.append(jax.device_get(metrics))
    return {name: np.concatenate([m[name] for m in out], axis=2) for name in out[0]}


SLOW = pytest.mark.slow
PPO_GRID = (("agent.actor_lr", (7.5e-4, 3e-3)),)


@pytest.mark.optimized
@pytest.mark.parametrize(
    ("algo", "grid", "agent", "singles"),
    [
        # the diagonal of the 2 x 2 grid: both fields change between its two points
        pytest.param("a2c", GRID, {}, (0, 3), marks=SLOW),  # the default suite: ppo's
        pytest.param("a2c", GRID, {}, (0, 1, 2, 3), marks=SLOW),
        # PPO keeps its learning rate in Adam's state (inject_hyperparams): each point must
        # start from its own, so the point off the default is the one that can go wrong
        ("ppo", PPO_GRID, {"n_steps": 20}, (1,)),
        pytest.param("ppo", PPO_GRID, {"n_steps": 20}, (0, 1), marks=SLOW),
    ],
)
def test_a_sweep_equals_the_single_runs_it_replaces(algo, grid, agent, singles):
    config = validate(from_preset("paper", algo=algo, sweep=grid, agent=agent, **TINY))
    assert len(config.points) == int(np.prod([len(v) for _, v in grid]))
    swept = _metrics(config)
    for index in singles:
        single = _metrics(config.at_point(index))
        for name in ("moving_return", "episode_return", "env_steps", "real_actor_loss"):
            np.testing.assert_allclose(
                swept[name][index], single[name][0], rtol=1e-5, atol=1e-6, err_msg=name
            )
    # the values matter: the points did not all train alike
    finals = swept["real_actor_loss"][:, :, -1]
    assert len({round(float(v), 6) for v in finals[:, 0]}) == len(config.points)


@pytest.mark.parametrize(
    ("env", "algo"), [("cartpole-v0", "ldn"), ("inverted_pendulum", "ppo-ldn")]
)
def test_every_sweepable_field_traces_as_a_value(env, algo):
    """Every field `sweepable()` names reaches the program as a traced value (no Python
    `if` on it): the chunk traces with all of them swept at once."""
    base = from_preset("paper", env=env, algo=algo, seeds=1, k=(1.0,), workers=2, episodes=8)
    grid = []
    for name in sweepable():
        value = get_field(base, name)
        grid.append((name, (0.5 if value is None else float(value),)))
    config = validate(from_preset("paper", env=env, algo=algo, seeds=1, sweep=tuple(grid)))
    trainer = Trainer(config)
    states = jax.eval_shape(trainer.init_batch)
    jax.eval_shape(trainer.batched_chunk(), states, trainer.point_values())
    assert {"agent.actor_lr", "agent.gamma", "fit.lr", "agent.entropy_beta"} <= set(sweepable())


def build(*argv: str):
    return flags.build_config(flags.parse_args(list(argv)))


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--sweep", "agent.n_steps=5,10"], "agent.n_steps is int); it needs separate runs"),
        (["--sweep", "agent.normalize_obs=0,1"], "agent.normalize_obs is bool"),
        (["--sweep", "model.hidden=50,100"], "model.hidden is int"),
        (["--sweep", "threshold=100,150"], "read after training"),
        (["--sweep", "agent.init_std=0.1,0.2"], "it shapes the networks"),
        (["--sweep", "k=1,2"], "K is its own axis; give the values with --k"),
        (["--sweep", "agent.actor_lrr=1,2"], "unknown config field 'agent.actor_lrr'"),
        (["--sweep", "agent.actor_lr=fast"], "--sweep needs FIELD=V1,V2,... with numbers"),
        (["--sweep", "agent.gamma=0.9,0.9"], "needs distinct values"),
        (["--sweep", "agent.gamma=0.9,1.5"], "agent.gamma=1.5: gamma must be in (0, 1]"),
        (["--sweep", "agent.gamma=0.9", "--sweep", "agent.gamma=0.99"], "given twice"),
        (["--set", "sweep=1"], "a sweep is given with --sweep"),
    ],
)
def test_bad_sweeps_are_one_line(argv, needle):
    with pytest.raises(UsageError) as error:
        build(*argv)
    assert needle in str(error.value) and "\n" not in str(error.value)


def test_sweep_flags_and_files_give_the_grid(tmp_path):
    config = build("--sweep", "agent.actor_lr=1e-3,3e-4", "--sweep", "model.lr=0.01,0.001")
    assert config.sweep == (("agent.actor_lr", (1e-3, 3e-4)), ("fit.lr", (0.01, 0.001)))
    assert len(config.points) == 3 * 4  # ldn's three K x the 2 x 2 grid
    assert config.points[1] == {"k": 0.5, "agent.actor_lr": 1e-3, "fit.lr": 0.001}
    toml = tmp_path / "grid.toml"
    toml.write_text('[sweep]\n"agent.actor_lr" = [1e-3, 3e-4]\n')
    assert build("--config", str(toml)).sweep == (("agent.actor_lr", (1e-3, 3e-4)),)
    own = tmp_path / "config.json"
    own.write_text(json.dumps(config.to_dict()))
    assert build("--config", str(own)) == config


@pytest.fixture(scope="module")
def sweep_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    config = validate(from_preset("paper", algo="ldn", sweep=GRID[:1], **{**TINY, "k": (0.5, 2.0)}))
    summary = train(config, out, checkpoint_every=1, quiet=True)
    return out, summary


def test_a_sweep_run_names_its_points_in_every_file(sweep_run):
    out, summary = sweep_run
    lines = _lines(out)
    assert len(lines) == 4 * 2 * 4  # points (2 K x 2 lr) x seeds x iterations
    points = {(line["k"], line["sweep"]["agent.actor_lr"]) for line in lines}
    assert points == {(0.5, 1e-3), (0.5, 3e-4), (2.0, 1e-3), (2.0, 3e-4)}
    assert {(r["k"], r["sweep"]["agent.actor_lr"], r["seed"]) for r in summary["runs"]} == {
        (*p, s) for p in points for s in (0, 1)
    }
    assert [(s["k"], s["sweep"]) for s in summary["statistics"]] == [
        (0.5, {"agent.actor_lr": 1e-3}),
        (0.5, {"agent.actor_lr": 3e-4}),
        (2.0, {"agent.actor_lr": 1e-3}),
        (2.0, {"agent.actor_lr": 3e-4}),
    ]
    # a point's policy, by its values
    obs = np.array([0.01, 0.0, 0.02, 0.1], np.float32)
    assert load_policy(out, seed=1, k=2.0, at={"agent.actor_lr": 3e-4})(obs) in (0, 1)
    with pytest.raises(ValueError, match=r"agent.gamma is not swept in this run"):
        load_policy(out, at={"agent.gamma": 0.9})
    with pytest.raises(ValueError, match=r"agent.actor_lr=0.5 not in this run"):
        load_policy(out, at={"agent.actor_lr": 0.5})
    from ldn_jax.host.compare import render, rows

    table = rows([out])
    assert [r["point"] for r in table] == [
        "K=0.5 agent.actor_lr=0.001",
        "K=0.5 agent.actor_lr=0.0003",
        "K=2 agent.actor_lr=0.001",
        "K=2 agent.actor_lr=0.0003",
    ]
    assert "K=2 agent.actor_lr=0.0003" in "\n".join(render(table, []))


@SLOW  # 18 s; the default suite keeps resume's own tests (tests/test_resume.py)
def test_a_sweep_resumes_to_the_bit(sweep_run, tmp_path):
    ref_dir, ref_summary = sweep_run
    config = read_run_config(ref_dir)
    with pytest.raises(Interrupted):
        train(config, tmp_path, checkpoint_every=1, quiet=True, stop=StopAfter(1))
    summary = train(
        read_run_config(tmp_path), tmp_path, checkpoint_every=1, quiet=True, resume=True
    )
    assert _lines(tmp_path) == _lines(ref_dir)
    assert _timeless(summary) == _timeless(ref_summary)


@SLOW  # 25 s; the default suite keeps the device tests of tests/test_scale.py
def test_a_sweep_over_two_devices_gives_the_one_device_run(sweep_run, tmp_path):
    ref_dir, _ = sweep_run
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=2"
    env = dict(os.environ, XLA_FLAGS=flags.strip())
    args = ["--config", str(ref_dir / "config.json"), "--devices", "2", "--quiet"]
    args += ["--compile-cache", "none", "--out", str(tmp_path)]
    result = subprocess.run(
        [*RUN, *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert result.returncode == 0, result.stderr
    assert json.loads((tmp_path / "summary.json").read_text())["devices"] == 2
    exact = ("iteration", "seed", "k", "sweep", "episodes", "env_steps", "episode_return")
    ours, reference = _lines(tmp_path), _lines(ref_dir)
    assert [{n: line[n] for n in exact} for line in ours] == [
        {n: line[n] for n in exact} for line in reference
    ]
    moving = lambda lines: [line["moving_return"] for line in lines]
    np.testing.assert_allclose(moving(ours), moving(reference), rtol=1e-5)
