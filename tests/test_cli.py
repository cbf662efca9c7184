"""The CLI: a tiny run writes every run-dir file; bad input exits 2 with one line."""

import json
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from ldn_jax import load_policy
from ldn_jax.host.training import Stop

ROOT = Path(__file__).resolve().parents[1]
OBS = np.random.default_rng(1).uniform(-0.2, 0.2, (20, 4)).astype(np.float32)
RUN = [sys.executable, str(ROOT / "experiments" / "run.py")]


def _run(*args, timeout=300):
    return subprocess.run([*RUN, *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "ldn"
    # Seeds 3 and 4: every file names the seeds themselves, not their place in the batch.
    args = ["--env", "cartpole-v0", "--algo", "ldn", "--seeds", "2", "--first-seed", "3"]
    args += ["--k", "0.5,2"]
    result = _run(*args, "--episodes", "16", "--workers", "4", "--chunk", "2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "summary.json" in result.stdout
    return out


def test_run_dir_files_and_fields(run_dir):
    for name in ("config.json", "metrics.jsonl", "summary.json", "curves.png"):
        assert (run_dir / name).stat().st_size > 0, name
    assert (run_dir / "checkpoints" / "final").is_dir()
    config = json.loads((run_dir / "config.json").read_text())
    assert config["k"] == [0.5, 2.0] and config["seeds"] == 2 and config["algo"] == "ldn"
    assert config["first_seed"] == 3
    lines = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    assert len(lines) == 2 * 2 * 4  # K x seeds x iterations
    fields = {
        "iteration", "seed", "k", "episodes", "env_steps", "imagined_steps", "episode_return",
        "moving_return", "ld_mean", "losses", "wall_seconds",
    }  # fmt: skip
    assert all(set(line) == fields for line in lines)
    assert {(line["seed"], line["k"]) for line in lines} == {(3, 0.5), (4, 0.5), (3, 2), (4, 2)}
    assert lines[-1]["episodes"] == 16 and 0 <= lines[-1]["ld_mean"] < 1
    summary = json.loads((run_dir / "summary.json").read_text())
    assert {"env", "algo", "threshold", "compile_seconds", "train_seconds"} <= set(summary)
    assert summary["threshold"] == 150.0 and summary["env_steps_per_second"] > 0
    run_fields = {
        "seed", "k", "episodes_to_threshold", "env_steps_to_threshold", "seconds_to_threshold",
        "final_moving_return", "eval_return", "solved", "diverged",
    }  # fmt: skip
    assert len(summary["runs"]) == 4 and all(set(r) == run_fields for r in summary["runs"])
    assert {r["seed"] for r in summary["runs"]} == {3, 4}
    # what computed the bits besides the config: another CPU type may round differently
    assert set(summary["host"]) == {"cpu", "jax", "jaxlib", "mujoco"}
    assert summary["host"]["jax"] == jax.__version__ and summary["host"]["cpu"]


def test_load_policy_returns_python_ints(run_dir):
    act = load_policy(run_dir, seed=4, k=2.0)
    rng = np.random.default_rng(0)
    actions = [act(rng.uniform(-0.05, 0.05, 4).astype(np.float32)) for _ in range(20)]
    assert all(type(a) is int and a in (0, 1) for a in actions)
    obs = np.array([0.01, 0.0, 0.02, 0.1], np.float32)
    assert act(obs) == act(obs)
    with pytest.raises(ValueError, match="K=3"):
        load_policy(run_dir, k=3.0)
    with pytest.raises(ValueError, match=r"seed 1 not in this run \(it has seeds 3\.\.4\)"):
        load_policy(run_dir, seed=1)
    first = load_policy(run_dir, k=2.0)  # the run's first seed, 3
    assert [first(o) for o in OBS] == [load_policy(run_dir, seed=3, k=2.0)(o) for o in OBS]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--env", "pong"], "unknown env 'pong'"),
        (["--algo", "dqn"], "unknown algo 'dqn'"),
        (["--k", "0,1"], "every K must be > 0"),
        (["--k", "-1"], "every K must be > 0"),
        (["--k", "1,inf"], "every K must be > 0 and finite"),
        (["--threshold", "nan"], "threshold must be a finite number, got nan"),
        (["--seeds", "0"], "seeds must be >= 1"),
        (["--seeds", "two"], "invalid int value"),
        (["--out", "/proc/forbidden/run"], "cannot write to --out"),
        (["--ld", "bayes"], "argument --ld: invalid choice: 'bayes'"),
        (["--ld", "ensemble", "--ensemble-size", "1"], "ensemble size must be >= 2, got 1"),
        (["--ensemble-size", "3"], "--ensemble-size needs --ld ensemble"),
        (["--env", "hopper", "--backend", "warp"], "backend must be one of auto, native, mjx"),
        (["--env", "halfcheetah", "--preset", "fast"], "preset 'fast' is for CartPole"),
    ],
)
def test_bad_input_exits_2_with_one_line(args, needle):
    result = _run(*args, timeout=60)
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and needle in result.stderr, result.stderr
    assert "Traceback" not in result.stderr


def test_existing_run_is_never_overwritten(run_dir):
    result = _run("--out", str(run_dir), timeout=60)
    assert result.returncode == 2 and "already holds a run" in result.stderr


def test_ppo_ldn_run_logs_ppo_losses(tmp_path):
    out = tmp_path / "ppo-ldn"
    args = ["--env", "cartpole-v0", "--algo", "ppo-ldn", "--seeds", "1", "--k", "1"]
    result = _run(*args, "--episodes", "8", "--workers", "4", "--chunk", "2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    config = json.loads((out / "config.json").read_text())
    assert config["agent"]["n_steps"] == 100 and config["agent"]["gamma"] == 0.99
    line = json.loads((out / "metrics.jsonl").read_text().splitlines()[-1])
    for name in ("real_actor_loss", "real_approx_kl", "imagined_clip_fraction", "model_loss"):
        assert name in line["losses"], line["losses"]
    assert line["imagined_steps"] > 0


def test_auto_backend_is_recorded_as_what_it_resolved_to():
    from ldn_jax.host import flags as run

    config = run.build_config(run.parse_args(["--env", "hopper"]))
    assert config.backend == "native"  # a CPU machine
    assert (
        run.build_config(run.parse_args(["--env", "hopper", "--backend", "mjx"])).backend == "mjx"
    )
    assert run.build_config(run.parse_args([])).backend == "auto"  # CartPole has no engine


def test_support_flag_sets_the_box_or_turns_it_off():
    from ldn_jax.host import flags as run

    support = lambda *flags: run.build_config(run.parse_args(list(flags))).model.support
    assert support("--env", "hopper") == 0.1 and support() is None  # MuJoCo / CartPole
    assert support("--env", "hopper", "--support", "none") is None
    assert support("--support", "0.25") == 0.25


def test_a_model_mujoco_cannot_load_exits_2_with_one_line(tmp_path):
    (tmp_path / "hopper.xml").write_text("<mujoco><worldbody>")
    code = (
        "import sys\n"
        "from ldn_jax.envs.mujoco import model\n"
        f"model.asset_path = lambda asset: {str(tmp_path)!r} + '/' + asset\n"
        "from experiments import run\n"
        "sys.exit(run.main(['--env', 'hopper', '--backend', 'native', '--quiet']))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and "cannot load" in result.stderr, result.stderr


def test_a_held_run_directory_is_refused_and_a_killed_holder_leaves_no_lock(run_dir, tmp_path):
    import os
    import signal

    from ldn_jax.host import run_dir as run_dirs

    with run_dirs.hold(run_dir):
        result = _run("--resume", str(run_dir), timeout=60)
        assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
        assert f"in use by another training process (pid {os.getpid()})" in result.stderr
        # another open of the lock, same process
        with pytest.raises(run_dirs.RunDirBusy), run_dirs.hold(run_dir):
            pass
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    code = (
        "import sys, time; from pathlib import Path; from ldn_jax.host import run_dir\n"
        f"with run_dir.hold(Path({str(fresh)!r})):\n"
        "    print('held', flush=True); time.sleep(60)\n"
    )
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    result = _run("--env", "cartpole-v0", "--out", str(fresh), timeout=60)
    assert result.returncode == 2 and "in use by another training process" in result.stderr
    assert not (fresh / "config.json").exists()
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    with run_dirs.hold(fresh):  # the lock died with its process
        pass


def test_config_json_of_a_run_reruns_it(run_dir, tmp_path):
    out = tmp_path / "again"
    result = _run("--config", str(run_dir / "config.json"), "--out", str(out), "--quiet")
    assert result.returncode == 0, result.stderr
    read = lambda d: [
        {k: v for k, v in json.loads(line).items() if k != "wall_seconds"}
        for line in (d / "metrics.jsonl").read_text().splitlines()
    ]
    assert read(out) == read(run_dir)
    assert json.loads((out / "config.json").read_text()) == json.loads(
        (run_dir / "config.json").read_text()
    )


GRID = ["--env", "cartpole-v0,cartpole-v2", "--algo", "a2c", "--seeds", "2", "--episodes", "24"]
GRID += ["--workers", "4", "--chunk", "2", "--quiet", "--compile-cache", "none"]


def _metrics(run: Path) -> list[dict]:
    lines = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in line.items() if k != "wall_seconds"} for line in lines]


def test_a_grid_trains_each_run_as_alone_and_the_same_command_goes_on_after_a_stop(
    tmp_path, monkeypatch, capsys
):
    """`--env A,B`: one run per env in DIR/ENV-ALGO, each as its single run; stopped in its
    first run, the same command resumes it, starts the next, and then keeps both; with
    other settings it is refused."""
    from ldn_jax.host import run as command
    from tests.test_resume import StopAfter

    grid, alone = tmp_path / "grid", tmp_path / "alone"
    single = [a if a != "cartpole-v0,cartpole-v2" else "cartpole-v2" for a in GRID]
    assert command.main([*single, "--out", str(alone)]) == 0

    monkeypatch.setattr(command, "Stop", lambda: StopAfter(1))
    assert command.main([*GRID, "--out", str(grid)]) == 128 + 2  # SIGINT after one chunk
    err = capsys.readouterr().err
    assert f"--resume {grid / 'cartpole-v0-a2c'}" in err
    assert "not started: cartpole-v2-a2c; the same command again goes on" in err
    assert not (grid / "cartpole-v2-a2c").exists()

    monkeypatch.setattr(command, "Stop", Stop)
    assert command.main([*GRID, "--out", str(grid)]) == 0
    out = capsys.readouterr().out
    assert "[1/2] cartpole-v0-a2c (resumed)" not in out  # --quiet: no headers
    assert _metrics(grid / "cartpole-v2-a2c") == _metrics(alone)
    assert json.loads((grid / "cartpole-v0-a2c" / "summary.json").read_text())["resumes"] == 1

    before = (grid / "cartpole-v2-a2c" / "metrics.jsonl").stat().st_mtime_ns
    assert command.main([*GRID, "--out", str(grid)]) == 0
    out = capsys.readouterr().out
    assert out.count("kept: ") == 2 and "(finished)" in out
    assert (grid / "cartpole-v2-a2c" / "metrics.jsonl").stat().st_mtime_ns == before
    changed = [a if a != "24" else "32" for a in GRID]  # another budget: not the same grid
    assert command.main([*changed, "--out", str(grid)]) == 2
    assert "does not match the run being resumed" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--env", "cartpole-v0,pong"], "unknown env 'pong'"),
        (["--algo", "a2c,a2c"], "--algo a2c,a2c: a2c given twice"),
        (["--env", "cartpole-v0,"], "--env cartpole-v0,: an empty name in the list"),
        (["--algo", "a2c,ppo", "--dry-run"], "--dry-run takes one --env and one --algo"),
    ],
)
def test_bad_grids_exit_2_with_one_line_before_training(args, needle, tmp_path, capsys):
    from ldn_jax.host import run as command

    code = command.main([*args, "--out", str(tmp_path / "g"), "--compile-cache", "none"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and needle in err, err
    assert not (tmp_path / "g").exists()
