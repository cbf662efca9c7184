"""The `ldn-jax` command: gymnasium evaluation, run comparison plots, TensorBoard scalars."""

import importlib
import json
import os
import shutil
import struct
import subprocess
import sys
import tomllib
from collections import defaultdict
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax import envs, load_policy
from ldn_jax.envs.cartpole import EnvState
from ldn_jax.host import gym_eval

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--seeds", "1", "--workers", "4", "--chunk", "2", "--quiet"]


def entry_point():
    """The function pyproject's [project.scripts] names for `ldn-jax`."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    module, function = scripts["ldn-jax"].split(":")
    return getattr(importlib.import_module(module), function)


def ldn_jax(*args, cwd: Path, timeout=300):
    """Run `ldn-jax ARGS` in a new process: the installed console script of this interpreter's
    environment, or `python -m ldn_jax.host.cli` where the editable install predates it."""
    script = shutil.which("ldn-jax", path=str(Path(sys.executable).parent))
    env = dict(os.environ)
    if script:
        command = [script]
    else:
        command = [sys.executable, "-m", "ldn_jax.host.cli"]
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return subprocess.run(
        [*command, *args], capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env
    )


@pytest.fixture(scope="module")
def ldn_run(tmp_path_factory):
    """A few seconds of ldn on cartpole-v1 (40 episodes = 10 iterations), TensorBoard on."""
    out = tmp_path_factory.mktemp("runs") / "ldn"
    args = ["--env", "cartpole-v1", "--algo", "ldn", "--k", "1", "--episodes", "40", *TINY]
    assert entry_point()([*args, "--logger", "tensorboard", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def a2c_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "a2c"
    args = ["--env", "cartpole-v1", "--algo", "a2c", "--episodes", "16", *TINY]
    assert entry_point()([*args, "--out", str(out)]) == 0
    return out


def jax_env_returns(act, name: str, episodes: int) -> np.ndarray:
    """Returns of `act` in our JAX env, stepped one action at a time from the host."""
    env, params = envs.make(name)
    reset = jax.jit(lambda key: env.reset(key, params))
    step = jax.jit(lambda state, action: env.step(jax.random.key(0), state, action, params))
    returns = np.zeros(episodes)
    for i, key in enumerate(jax.random.split(jax.random.key(0), episodes)):
        obs, state = reset(key)
        done = False
        while not done:
            obs, state, reward, terminated, truncated, _ = step(state, act(np.asarray(obs)))
            returns[i] += float(reward)
            done = bool(terminated | truncated)
    return returns


def test_eval_in_gymnasium_matches_our_env(ldn_run, tmp_path):
    n = 30
    result = ldn_jax("eval", str(ldn_run), "--episodes", str(n), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.count("\n") == 1 and "CartPole-v1" in result.stdout, result.stdout
    record = json.loads((ldn_run / "eval.json").read_text())
    assert record["env"] == "cartpole-v1" and record["gymnasium"] == "CartPole-v1"
    (run,) = record["runs"]
    gym = np.array(run["returns"])
    assert (run["seed"], run["k"], run["episodes"]) == (0, 1.0, n) and gym.shape == (n,)
    assert np.all(np.isfinite(gym)) and np.all((gym >= 1) & (gym <= 500))
    assert run["mean_return"] == pytest.approx(gym.mean())
    assert run["std_return"] == pytest.approx(gym.std(ddof=1))

    ours = jax_env_returns(load_policy(ldn_run), "cartpole-v1", n)
    se = np.hypot(gym.std(ddof=1), ours.std(ddof=1)) / np.sqrt(n)
    assert abs(gym.mean() - ours.mean()) <= 4 * se + 1, (gym.mean(), ours.mean(), se)

    # A second evaluation of the same seed and K replaces the first.
    assert entry_point()(["eval", str(ldn_run), "--episodes", "2"]) == 0
    (run,) = json.loads((ldn_run / "eval.json").read_text())["runs"]
    assert run["episodes"] == 2


@pytest.mark.parametrize(
    "physics",
    [[0.1, -0.2, 0.05, 0.3], [-1.0, 0.5, -0.15, -1.2], [2.39, 1.0, 0.0, 0.0]],
    ids=["inside", "tilted", "leaving-track"],
)
def test_gymnasium_v2_wrapper_steps_like_our_env_for_every_action(physics):
    cartpole, params = envs.make("cartpole-v2")
    gym = gym_eval.make_env("cartpole-v2")
    assert gym.action_space.n == 5
    for action in range(5):
        gym.reset(seed=0)
        gym.unwrapped.state = np.array(physics, np.float64)
        obs, reward, terminated, truncated, _ = gym.step(action)
        state = EnvState(physics=jnp.array(physics, jnp.float32), time=jnp.zeros((), jnp.int32))
        ours = cartpole.step(jax.random.key(0), state, jnp.int32(action), params)
        np.testing.assert_allclose(obs, ours[0], rtol=1e-5, atol=1e-7, err_msg=f"{action=}")
        assert (reward, terminated, truncated) == (float(ours[2]), bool(ours[3]), bool(ours[4]))


@pytest.mark.parametrize(("name", "limit"), [("cartpole-v0", 200), ("cartpole-v2", 1000)])
def test_gymnasium_cartpoles_truncate_at_our_step_limit(name, limit):
    gym = gym_eval.make_env(name)
    gym.reset(seed=0)
    for step in range(1, limit + 1):
        gym.unwrapped.state = np.zeros(4)  # keep the pole up whatever the action
        _, _, terminated, truncated, _ = gym.step(0)
        assert not terminated and truncated == (step == limit)


def test_plot_overlays_two_runs(ldn_run, a2c_run, tmp_path, monkeypatch):
    out = tmp_path / "both.png"
    result = ldn_jax("plot", str(ldn_run), str(a2c_run), "--out", str(out), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Default output: comparison.png in the working directory.
    monkeypatch.chdir(tmp_path)
    assert entry_point()(["plot", str(a2c_run)]) == 0
    assert (tmp_path / "comparison.png").stat().st_size > 0


def test_eval_video_is_written_or_refused_in_one_line(ldn_run, tmp_path, capsys):
    videos = tmp_path / "videos"
    code = entry_point()(["eval", str(ldn_run), "--episodes", "1", "--video", str(videos)])
    try:
        import moviepy  # noqa: F401
    except ImportError:  # the `video` extra is not installed
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and err.startswith("error: --video failed"), err
    else:
        assert code == 0 and [p.suffix for p in videos.iterdir()] == [".mp4"]


def read_scalars(log_dir: Path) -> dict[str, list[tuple[int, float]]]:
    """`{tag: [(step, value), ...]}` from TFRecord event files, checking every CRC."""
    from tensorboardX.proto.event_pb2 import Event
    from tensorboardX.record_writer import masked_crc32c

    scalars = defaultdict(list)
    for path in sorted(log_dir.glob("events.out.tfevents.*")):
        data, pos = path.read_bytes(), 0
        while pos < len(data):
            header = data[pos : pos + 8]
            (length,), (header_crc,) = (
                struct.unpack("<Q", header),
                struct.unpack_from("<I", data, pos + 8),
            )
            payload = data[pos + 12 : pos + 12 + length]
            (payload_crc,) = struct.unpack_from("<I", data, pos + 12 + length)
            assert (header_crc, payload_crc) == (masked_crc32c(header), masked_crc32c(payload))
            pos += 12 + length + 4
            event = Event.FromString(payload)
            for value in event.summary.value:
                scalars[value.tag].append((event.step, value.simple_value))
    return scalars


def test_tensorboard_scalars_match_metrics_jsonl(ldn_run):
    scalars = read_scalars(ldn_run / "tensorboard")
    expected = {"moving_return", "episode_return", "ld_mean", "model_loss", "real_actor_loss"}
    assert {f"seed0_k1/{name}" for name in expected} <= set(scalars)
    assert not any(tag.endswith(("/iteration", "/episodes", "/returns")) for tag in scalars)
    lines = [json.loads(line) for line in (ldn_run / "metrics.jsonl").read_text().splitlines()]
    moving = scalars["seed0_k1/moving_return"]
    assert (
        [step for step, _ in moving]
        == [line["episodes"] for line in lines]
        == list(range(4, 41, 4))
    )
    np.testing.assert_allclose([v for _, v in moving], [line["moving_return"] for line in lines])
    assert all(len(points) == 10 for points in scalars.values())


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["eval", "{tmp}/missing"], "no such run directory"),
        (["eval", "{tmp}"], "no config.json"),
        (["eval", "{run}", "--seed", "3"], "seed 3 not in this run"),
        (["eval", "{run}", "--k", "2"], "K=2.0 not in this run"),
        (["eval", "{run}", "--episodes", "0"], "--episodes must be >= 1"),
        (["eval", "{run}", "--seed", "one"], "invalid int value"),
        (["plot", "{tmp}/missing"], "no such run directory"),
        (["plot", "{tmp}"], "no config.json"),
        (["plot", "{run}", "--out", "/proc/forbidden/x.png"], "cannot write"),
        (["plot"], "required: RUN_DIR"),
        (["--logger", "mlflow"], "invalid choice: 'mlflow'"),
        (["--wandb-project", "x"], "--wandb-project needs --logger wandb"),
    ],
)
def test_bad_input_exits_2_with_one_line(args, needle, ldn_run, tmp_path, capsys):
    argv = [a.format(tmp=tmp_path, run=ldn_run) for a in args]
    assert entry_point()(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err


def test_bad_input_from_the_shell_has_no_traceback(tmp_path):
    result = ldn_jax("eval", str(tmp_path / "missing"), cwd=tmp_path, timeout=120)
    assert result.returncode == 2 and result.stderr.startswith("error: no such run directory")
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr


def test_compare_prints_iqm_and_the_probability_of_improvement(ldn_run, a2c_run, tmp_path):
    from ldn_jax.host import stats

    out = tmp_path / "compare.json"
    result = ldn_jax("compare", str(ldn_run), str(a2c_run), "--json", str(out), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    data = json.loads(out.read_text())
    assert [row["run"] for row in data["runs"]] == ["ldn", "a2c"]
    for row, run_dir in zip(data["runs"], (ldn_run, a2c_run), strict=True):
        summary = json.loads((run_dir / "summary.json").read_text())
        finals = [r["final_moving_return"] for r in summary["runs"]]
        assert row["final_moving_return"]["values"] == finals
        assert row["final_moving_return"]["iqm"] == pytest.approx(stats.iqm(np.array(finals)))
        # summary.json carries the same statistics
        (entry,) = summary["statistics"]
        assert entry["final_moving_return"]["iqm"] == row["final_moving_return"]["iqm"]
    (better,) = data["improvement"]
    assert (better["run"], better["baseline"]) == ("a2c", "ldn")
    expected = stats.improvement(
        data["runs"][1]["eval_return"]["values"], data["runs"][0]["eval_return"]["values"]
    )
    assert better["eval_return"] == expected
    assert "| ldn (ldn K=1) | cartpole-v1 |" in result.stdout
    assert "Probability that a seed of the run beats" in result.stdout


def test_compare_pools_runs_of_one_config_on_other_seeds(tmp_path):
    """A run of seeds 3-4 (`--first-seed 3`) beside one of seeds 0-2 is one row of 5 seeds
    per K; a run repeating seeds 0-2, or of another config, stays apart."""
    from ldn_jax.config import from_preset
    from ldn_jax.host.compare import rows
    from ldn_jax.host.run_dir import RunDir

    def run(name, first, seeds, algo="ldn"):
        config = from_preset(
            "paper", env="cartpole-v1", algo=algo, k=(1.0, 2.0), seeds=seeds, first_seed=first
        )
        (tmp_path / name).mkdir()
        RunDir(tmp_path / name).write_config(config)
        results = [
            {"seed": first + i, "k": k, "episodes_to_threshold": None,
             "env_steps_to_threshold": None, "final_moving_return": 10.0 * (first + i) + k,
             "eval_return": 1.0}
            for k in config.k for i in range(seeds)
        ]  # fmt: skip
        (tmp_path / name / "summary.json").write_text(json.dumps({"runs": results}))
        return tmp_path / name

    table = rows([run("a", 0, 3), run("b", 3, 2), run("c", 0, 3), run("d", 3, 2, "a2c")])
    assert [(row["run"], row["k"], row["seeds"]) for row in table] == [
        ("a + b", 1.0, 5), ("a + b", 2.0, 5), ("c", 1.0, 3), ("c", 2.0, 3), ("d", None, 2)
    ]  # fmt: skip
    assert table[1]["final_moving_return"]["values"] == [2.0, 12.0, 22.0, 32.0, 42.0]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["compare", "{tmp}/missing"], "no such run directory"),
        (["compare", "{tmp}"], "no config.json"),
        (["compare"], "required: RUN_DIR"),
    ],
)
def test_compare_bad_input_exits_2_with_one_line(args, needle, tmp_path, capsys):
    argv = [a.format(tmp=tmp_path) for a in args]
    assert entry_point()(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err


def wandb_records(path: Path) -> list:
    """The records of a wandb run file (`run-ID.wandb`: wandb's leveldb-style log of 32 KiB
    blocks, each record a 7-byte header (crc, length, type) and a protobuf `Record`)."""
    from wandb.proto import wandb_internal_pb2

    data, pos, block, records, partial = path.read_bytes(), 7, 32768, [], b""
    assert data[:4] == b":W&B"
    while pos + 7 <= len(data):
        left = block - pos % block
        _, length, kind = struct.unpack_from("<IHB", data, pos)
        if left < 7 or (length, kind) == (0, 0):  # the rest of the block is padding
            pos += left
            continue
        partial += data[pos + 7 : pos + 7 + length]
        pos += 7 + length
        if kind in (1, 4):  # FULL, LAST
            record = wandb_internal_pb2.Record()
            record.ParseFromString(partial)
            records.append(record)
            partial = b""
    return records


def test_wandb_offline_holds_every_metric_and_the_config(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("WANDB_")}
    env |= {f"WANDB_{d}_DIR": str(tmp_path / d.lower()) for d in ("CONFIG", "CACHE", "DATA")}
    out = tmp_path / "run"
    args = ["--env", "cartpole-v1", "--algo", "ldn", "--k", "1", "--episodes", "24", *TINY]
    args[args.index("--seeds") + 1] = "2"
    args += ["--logger", "wandb", "--wandb-project", "ldn-test", "--out", str(out)]
    command = [sys.executable, str(ROOT / "experiments" / "run.py"), *args]
    result = subprocess.run(
        command, capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    assert result.stderr.count("\n") == 1 and "logging offline under" in result.stderr
    (run_file,) = (out / "wandb").glob("offline-run-*/run-*.wandb")
    records = wandb_records(run_file)
    history = [r.history for r in records if r.WhichOneof("record_type") == "history"]
    lines = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert len(history) == len(lines) // 2 == 6  # one wandb step per iteration, 2 seeds each
    key = lambda item: "/".join(item.nested_key) or item.key
    logged = [{key(i): json.loads(i.value_json) for i in h.item} for h in history]
    for line in lines:
        row = logged[line["iteration"] - 1]
        prefix = f"seed{line['seed']}_k1"
        assert row[f"{prefix}/episodes"] == line["episodes"]
        assert row[f"{prefix}/moving_return"] == pytest.approx(line["moving_return"])
        for name, value in line["losses"].items():
            if value is not None:
                assert row[f"{prefix}/{name}"] == pytest.approx(value)
    (run,) = [r.run for r in records if r.WhichOneof("record_type") == "run"]
    assert (
        run.project == "ldn-test" and run.run_id == (out / "wandb" / "run-id").read_text().strip()
    )
    config = {i.key: json.loads(i.value_json) for i in run.config.update}
    assert config["algo"] == "ldn" and config["agent"]["gamma"] == 0.9
