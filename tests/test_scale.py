"""Scale-out and compile cost: seeds split over devices or hosts give the one-device run (to
the bit with --bitwise), bad device counts fail in one line, --dry-run compiles and writes
nothing, and the persistent compilation cache makes a second process's compile cheap without
changing a bit."""

import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ldn_jax import load_policy
from ldn_jax.config import from_preset
from ldn_jax.host.training import train
from tests.conftest import optimised

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, str(ROOT / "experiments" / "run.py")]
CONFIG = dict(env="cartpole-v0", algo="ldn", seeds=4, k=(0.5, 2.0), episodes=16, workers=4)
CONFIG["chunk_iterations"] = 2
ARGS = ["--env", "cartpole-v0", "--algo", "ldn", "--seeds", "4", "--k", "0.5,2"]
ARGS += ["--episodes", "16", "--workers", "4", "--chunk", "2", "--quiet"]
EXACT = ("iteration", "seed", "k", "episodes", "env_steps", "imagined_steps", "episode_return")
EXACT += ("moving_return",)
"""Metrics that any split leaves exactly as they are: counts and real returns."""
SUMMARY = ("seed", "k", "eval_return", "final_moving_return", "episodes_to_threshold")
SUMMARY += ("env_steps_to_threshold", "diverged")


def _env(devices: int | None) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if devices:  # read when JAX starts, hence a fresh process
        flag = f"--xla_force_host_platform_device_count={devices}"
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} {flag}".strip()
    return env


def _run(*args, devices: int | None = None, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*RUN, *args], capture_output=True, text=True, timeout=300, env=_env(devices), cwd=cwd
    )


def _lines(run_dir: Path) -> list[dict]:
    lines = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in line.items() if k != "wall_seconds"} for line in lines]


def _floats(line: dict) -> list[float]:
    values = [line["ld_mean"], *(line["losses"][name] for name in sorted(line["losses"]))]
    return [np.nan if v is None else v for v in values]


def _runs(run_dir: Path) -> list[dict]:
    return [
        {f: r[f] for f in SUMMARY}
        for r in json.loads((run_dir / "summary.json").read_text())["runs"]
    ]


def _assert_same_run_bitwise(run_dir: Path, reference: Path) -> None:
    """Every metric of every line (losses and LD included) and the summary's runs, exactly."""
    lines = _lines(run_dir)
    assert len(lines) == 2 * 4 * 4  # K x seeds x iterations
    assert lines == _lines(reference)
    assert _runs(run_dir) == _runs(reference)


def _assert_same_run(run_dir: Path, reference: Path) -> None:
    """Counts, returns and evaluation exactly; losses and LD to float rounding.

    Without --bitwise, YNNPACK's fused reductions round according to the batch each device
    holds (and a one-seed block compiles to other kernels), so with several K the losses
    differ in the last bits (relative 1e-7 here).
    """
    lines, expected = _lines(run_dir), _lines(reference)
    assert len(lines) == len(expected) == 2 * 4 * 4  # K x seeds x iterations
    for line, want in zip(lines, expected, strict=True):
        assert {f: line[f] for f in EXACT} == {f: want[f] for f in EXACT}
        np.testing.assert_allclose(_floats(line), _floats(want), rtol=1e-5, atol=1e-7)
    assert _runs(run_dir) == _runs(reference)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("one-device")
    train(from_preset("paper", **CONFIG), out, checkpoint_every=0, quiet=True)
    return out


@pytest.fixture(scope="module")
def bitwise_reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("one-device-bitwise")
    with optimised():  # the `optimized` test below holds other programs to its bits
        train(from_preset("paper", **CONFIG), out, checkpoint_every=0, quiet=True, bitwise=True)
    return out


def test_two_devices_give_the_one_device_run(reference, tmp_path):
    # No XLA_FLAGS: on CPU, `--devices 2` makes the two host devices itself.
    out = tmp_path / "two"
    result = _run(*ARGS, "--devices", "2", "--compile-cache", "none", "--out", str(out))
    assert result.returncode == 0, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["devices"], summary["bitwise"]) == (2, False)
    _assert_same_run(out, reference)
    # This process has one device: the policy loads all the same, each seed its own.
    obs = np.array([0.01, 0.02, 0.03, 0.04], np.float32)
    for seed in range(CONFIG["seeds"]):
        assert load_policy(out, seed=seed, k=2.0)(obs) == load_policy(reference, seed, k=2.0)(obs)


@pytest.mark.slow  # the default suite splits a branched run over 2 devices bitwise (test_branched)
@pytest.mark.optimized
@pytest.mark.parametrize("devices", [2, 4])  # 2 seeds per device; 1, run twice
def test_bitwise_devices_give_the_one_device_run_to_the_bit(bitwise_reference, tmp_path, devices):
    out = tmp_path / "split"
    args = [*ARGS, "--devices", str(devices), "--bitwise", "--compile-cache", "none"]
    result = _run(*args, "--out", str(out), devices=devices)
    assert result.returncode == 0, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["devices"], summary["bitwise"]) == (devices, True)
    _assert_same_run_bitwise(out, bitwise_reference)


@pytest.mark.slow
def test_two_hosts_give_the_one_device_run(reference, tmp_path):
    """Two processes on this machine, one CPU device each, joined by jax.distributed."""
    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    out = tmp_path / "hosts"
    cluster = ["--distributed", "--coordinator", f"localhost:{port}", "--num-processes", "2"]
    args = [*RUN, *ARGS, *cluster, "--compile-cache", "none", "--out", str(out)]
    processes = [
        subprocess.Popen([*args, "--process-id", str(i)], env=_env(None), text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        for i in range(2)
    ]  # fmt: skip
    outputs = [p.communicate(timeout=600) for p in processes]
    assert [p.returncode for p in processes] == [0, 0], [err[-2000:] for _, err in outputs]
    assert "summary.json" in outputs[0][0] and "summary.json" not in outputs[1][0]
    assert json.loads((out / "summary.json").read_text())["devices"] == 2
    _assert_same_run(out, reference)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--seeds", "3", "--devices", "2"], "--seeds 3 cannot be split evenly over 2 devices"),
        (["--devices", "3"], "3 devices asked for, 2 cpu device(s) available"),
        (["--devices", "two"], "--devices must be a number or 'all'"),
        (["--process-id", "1"], "--process-id needs --distributed"),
    ],
)
def test_bad_device_flags_fail_in_one_line(tmp_path, args, message):
    out = ["--compile-cache", "none", "--out", str(tmp_path / "x")]
    result = _run("--episodes", "8", "--quiet", *args, *out, devices=2)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], lines
    assert not (tmp_path / "x").exists()


def test_dry_run_prints_compile_cost_and_memory_and_writes_nothing(tmp_path):
    args = ["--env", "cartpole-v0", "--algo", "ldn", "--seeds", "1", "--workers", "2"]
    result = _run(*args, "--dry-run", "--compile-cache", "none", "--out", "never", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert re.search(r"compile: \d+\.\d+ s", out), out
    flops = float(re.search(r"([\d.e+]+) FLOPs", out).group(1))
    accessed = float(re.search(r"([\d.e+]+) bytes accessed", out).group(1))
    assert flops > 0 and accessed > 0
    for field in ("arguments", "outputs", "temporaries"):
        assert re.search(rf"{field} [\d,.]+ MB", out), field
    assert list(tmp_path.iterdir()) == []  # no run directory, default or --out


@pytest.mark.slow
def test_second_process_loads_the_compiled_program_from_the_cache(tmp_path):
    cache = ["--compile-cache", str(tmp_path / "cache")]
    for name in ("cold", "warm"):
        result = _run(*ARGS, *cache, "--out", str(tmp_path / name))
        assert result.returncode == 0, result.stderr
    seconds = {
        name: json.loads((tmp_path / name / "summary.json").read_text())["compile_seconds"]
        for name in ("cold", "warm")
    }
    assert seconds["warm"] < 0.5 * seconds["cold"], seconds
    assert _lines(tmp_path / "warm") == _lines(tmp_path / "cold")  # the same program, bitwise
