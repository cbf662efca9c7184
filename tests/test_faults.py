"""The fault campaign: kills at random points, damaged checkpoints, a full disk, two processes
on one run directory, and every flag given bad input the way a new user would."""

import errno
import json
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ldn_jax.config import from_preset
from ldn_jax.host import run as command
from ldn_jax.host import run_dir as run_dirs
from ldn_jax.host import training
from ldn_jax.host.run_dir import RunDir
from ldn_jax.host.training import train

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, str(ROOT / "experiments" / "run.py")]
CONFIG = dict(env="cartpole-v0", algo="ldn", seeds=2, k=(1.0,), episodes=48, workers=4)
CONFIG["chunk_iterations"] = 2  # 6 chunks


def _lines(run: Path) -> list[dict]:
    lines = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in line.items() if k != "wall_seconds"} for line in lines]


def _timeless(summary: dict) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "seconds_to_threshold"} for r in summary["runs"]]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run with a checkpoint after every chunk (the newest 2 are kept)."""
    out = tmp_path_factory.mktemp("reference")
    summary = train(from_preset("paper", **CONFIG), out, checkpoint_every=1, quiet=True)
    return out, summary


def _copy(source: Path, to: Path) -> Path:
    subprocess.run(["cp", "-r", str(source), str(to)], check=True)
    return to


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _flip_a_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


# -- a damaged newest checkpoint ---------------------------------------------------------------


@pytest.mark.parametrize(  # truncation: slow (the default suite's time; one damage suffices)
    "damage",
    [pytest.param(_truncate, marks=pytest.mark.slow), _flip_a_byte],
    ids=["truncated", "flipped byte"],
)
def test_a_damaged_newest_checkpoint_falls_back_to_the_previous_one(reference, tmp_path, damage):
    ref_dir, ref_summary = reference
    copy = _copy(ref_dir, tmp_path / "copy")
    files = [p for p in (copy / "checkpoints" / "final").rglob("*") if p.is_file()]
    damage(max(files, key=lambda p: p.stat().st_size))
    result = subprocess.run(
        [*RUN, "--resume", str(copy), "--quiet", "--compile-cache", "none"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    warning = result.stderr.strip().splitlines()
    assert len(warning) == 1 and "resuming from chunk_00005 instead" in warning[0], warning
    assert "checkpoints/final is unreadable" in warning[0]
    assert _lines(copy) == _lines(ref_dir)
    assert _timeless(json.loads((copy / "summary.json").read_text())) == _timeless(ref_summary)


# -- a full disk ------------------------------------------------------------------------------


def _fail_on_second(monkeypatch, module, name: str, only=lambda path: True):
    """Make `module.name(path, ...)` fail as a full disk does on its second matching call,
    leaving a partial file behind as a killed write would."""
    real, calls = getattr(module, name), []

    def full(path, *args):
        if only(Path(path)):
            calls.append(path)
            if len(calls) == 2:
                Path(path).parent.mkdir(parents=True, exist_ok=True)
                Path(str(path) + ".tmp").write_bytes(b"half")
                raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, *args)

    monkeypatch.setattr(module, name, full)


@pytest.mark.parametrize(  # the orbax write: slow (the default suite's time)
    "fails", [pytest.param("orbax state", marks=pytest.mark.slow), "host file"]
)
def test_a_full_disk_stops_the_run_with_one_line_and_resume_works_afterwards(
    reference, tmp_path, monkeypatch, capsys, fails
):
    ref_dir, ref_summary = reference
    out = tmp_path / "run"
    with monkeypatch.context() as disk:
        if fails == "orbax state":
            _fail_on_second(disk, run_dirs.checkpoint, "save")
        else:
            _fail_on_second(disk, run_dirs, "write_atomic", lambda p: p.name.endswith(".npz"))
        disk.setattr(training.Stop, "install", lambda self: self)  # keep pytest's handlers
        args = ["--env", "cartpole-v0", "--algo", "ldn", "--seeds", "2", "--k", "1"]
        args += ["--episodes", "48", "--workers", "4", "--chunk", "2", "--checkpoint-every", "1"]
        code = command.main([*args, "--out", str(out), "--quiet", "--compile-cache", "none"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1, err
    assert "No space left on device" in err[0] and "chunk_00002" in err[0], err
    assert f"--resume {out}" in err[0]
    assert RunDir(out).checkpoint_names() == ["chunk_00001"]  # the one before is whole
    summary = train(RunDir(out).read_config(), out, checkpoint_every=1, quiet=True, resume=True)
    assert _lines(out) == _lines(ref_dir)
    assert _timeless(summary) == _timeless(ref_summary)
    assert not list((out / "checkpoints").glob("*tmp*"))


# -- two processes on one run directory ------------------------------------------------------


def test_a_second_process_on_a_training_run_is_refused_and_nothing_interleaves(tmp_path):
    out = tmp_path / "run"
    args = ["--env", "cartpole-v0", "--algo", "a2c", "--seeds", "2", "--episodes", "1600"]
    args += ["--workers", "4", "--chunk", "1", "--quiet", "--checkpoint-every", "10"]
    first = subprocess.Popen([*RUN, *args, "--out", str(out)], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (out / "metrics.jsonl").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    pipes = dict(stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    second = subprocess.Popen([*RUN, "--resume", str(out), "--quiet"], **pipes)
    also = subprocess.Popen([*RUN, *args, "--out", str(out)], **pipes)
    refusals = [process.communicate(timeout=120)[1] for process in (second, also)]
    assert first.poll() is None, "the first run ended too soon to test anything"
    _, first_err = first.communicate(timeout=300)
    assert first.returncode == 0, first_err
    for process, err in zip((second, also), refusals, strict=True):
        assert process.returncode == 2 and err.count("\n") == 1, err
        assert "in use by another training process" in err
    keys = [(line["iteration"], line["seed"]) for line in _lines(out)]
    assert sorted(keys) == [(i, s) for i in range(1, 401) for s in range(2)]


# -- kills at random points -------------------------------------------------------------------

KILLS = 20


def _wait(predicate, process: subprocess.Popen, seconds: float = 120) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and process.poll() is None:
        if predicate():
            return True
        time.sleep(0.002)
    return False


def _logged(out: Path) -> int:
    path = out / "metrics.jsonl"
    return len(path.read_text().splitlines()) if path.exists() else 0


@pytest.mark.slow
def test_twenty_kills_each_resumed_end_equal_to_an_uninterrupted_run(tmp_path):
    """SIGKILL and SIGTERM at random points, every fourth one while a checkpoint is being
    written; each followed by --resume. The run ends with every metrics line once, equal to
    an uninterrupted run's to the bit (timings aside)."""
    args = ["--env", "cartpole-v0", "--algo", "ldn", "--seeds", "2", "--k", "1", "--quiet"]
    args += ["--episodes", "2400", "--workers", "4", "--chunk", "1"]
    args += ["--compile-cache", str(tmp_path / "cache")]
    reference, out = tmp_path / "reference", tmp_path / "run"
    once = [*RUN, *args, "--checkpoint-every", "0", "--out", str(reference)]
    done = subprocess.run(once, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    rng = random.Random(0)
    kills = {"SIGKILL": 0, "SIGTERM": 0, "during a save": 0}
    command_line = [*RUN, *args, "--checkpoint-every", "1", "--out", str(out)]
    while sum(kills[s] for s in ("SIGKILL", "SIGTERM")) < KILLS:
        process = subprocess.Popen(command_line, stderr=subprocess.PIPE, text=True)
        command_line = [*RUN, "--resume", str(out), "--quiet"]
        before = _logged(out)
        _wait(lambda before=before: _logged(out) > before, process)
        n = sum(kills[s] for s in ("SIGKILL", "SIGTERM"))
        if n % 4 == 3:  # while orbax writes a checkpoint (its temporary directory exists)
            saving = lambda: any((out / "checkpoints").glob("*tmp*"))
            kills["during a save"] += _wait(saving, process, seconds=10)
        else:
            time.sleep(rng.uniform(0.0, 0.4))
        if process.poll() is not None:
            pytest.fail(f"the run finished after {kills} kills: give it more episodes")
        signum = rng.choice([signal.SIGKILL, signal.SIGTERM])
        process.send_signal(signum)
        _, err = process.communicate(timeout=120)
        stopped = (-signal.SIGKILL, 128 + signal.SIGTERM, -signal.SIGTERM)
        assert process.returncode in stopped, f"after {kills} kills: {err}"
        kills[signal.Signals(signum).name] += 1
    final = subprocess.run(command_line, capture_output=True, text=True, timeout=300)
    assert final.returncode == 0, final.stderr
    print(f"kills: {kills}")
    assert kills["during a save"] >= 1
    ours, theirs = _lines(out), _lines(reference)
    keys = [(line["iteration"], line["seed"]) for line in ours]
    assert len(keys) == len(set(keys)), "a metrics line was duplicated"
    assert ours == theirs
    summary = json.loads((out / "summary.json").read_text())
    assert _timeless(summary) == _timeless(json.loads((reference / "summary.json").read_text()))


# -- bad input, flag by flag ------------------------------------------------------------------

BAD_INPUT = [
    # (flags, what the one line says)
    (["--env", "pong"], "unknown env 'pong'"),
    (["--env", ""], "unknown env ''"),
    (["--algo", "dqn"], "unknown algo 'dqn'"),
    (["--seeds", "0"], "seeds must be >= 1, got 0"),
    (["--seeds", "-3"], "seeds must be >= 1, got -3"),
    (["--seeds", "two"], "argument --seeds: invalid int value: 'two'"),
    (["--seeds", "2.5"], "argument --seeds: invalid int value: '2.5'"),
    (["--k", "0"], "every K must be > 0 and finite"),
    (["--k", "-1"], "every K must be > 0 and finite"),
    (["--k", "nan"], "every K must be > 0 and finite"),
    (["--k", "1,inf"], "every K must be > 0 and finite"),
    (["--k", "one"], "--k must be comma-separated numbers, got 'one'"),
    (["--k", ","], "k needs at least one value"),
    (["--k", "1,1"], "K values must be distinct"),
    (["--episodes", "0"], "episodes must be >= 1, got 0"),
    (["--episodes", "-8"], "episodes must be >= 1, got -8"),
    (["--episodes", "1e3"], "argument --episodes: invalid int value: '1e3'"),
    (["--steps", "0"], "steps must be >= 1, got 0"),
    (["--steps", "-100"], "steps must be >= 1, got -100"),
    (["--steps", "1e6"], "argument --steps: invalid int value: '1e6'"),
    (["--steps", "1000", "--episodes", "10"], "give --steps or --episodes, not both"),
    (["--workers", "0"], "workers must be >= 1, got 0"),
    (["--algo", "ldn", "--imagine", "memory"], "imagine.mode 'memory' needs the PPO learner"),
    (["--imagine", "all"], "argument --imagine: invalid choice: 'all'"),
    (["--support", "-0.1"], "model support must be >= 0 and finite"),
    (["--support", "inf"], "model support must be >= 0 and finite"),
    (["--support", "wide"], "--support must be a number or none, got 'wide'"),
    (["--workers", "many"], "argument --workers: invalid int value: 'many'"),
    (["--preset", "fastest"], "unknown preset 'fastest'"),
    (["--threshold", "nan"], "threshold must be a finite number, got nan"),
    (["--threshold=-inf"], "threshold must be a finite number, got -inf"),
    (["--threshold", "high"], "argument --threshold: invalid float value: 'high'"),
    (["--set", "solved_return=inf"], "solved_return must be a finite number (or none), got inf"),
    (["--chunk", "0"], "chunk_iterations must be >= 1"),
    (["--chunk", "-1"], "chunk_iterations must be >= 1"),
    (["--backend", "warp"], "backend must be one of auto, native, mjx"),
    (["--env", "hopper", "--backend", "gpu"], "backend must be one of auto, native, mjx"),
    (["--ld", "bayes"], "argument --ld: invalid choice: 'bayes'"),
    (["--ld", "ensemble", "--ensemble-size", "1"], "ensemble size must be >= 2, got 1"),
    (["--ld", "ensemble", "--ensemble-size", "-2"], "ensemble size must be >= 2, got -2"),
    (["--ensemble-size", "3"], "--ensemble-size needs --ld ensemble"),
    (["--out", "/proc/forbidden/run"], "cannot write to --out /proc/forbidden/run"),
    (["--resume", "/nonexistent/run"], "/nonexistent/run holds no run"),
    (["--checkpoint-every", "-1"], "--checkpoint-every must be >= 0"),
    (["--checkpoint-every", "often"], "argument --checkpoint-every: invalid int value"),
    (["--logger", "wandb2"], "argument --logger: invalid choice: 'wandb2'"),
    (["--devices", "two"], "--devices must be a number or 'all', got 'two'"),
    (["--devices", "0"], "--devices must be >= 1 or 'all', got 0"),
    (["--devices", "-1"], "--devices must be >= 1 or 'all', got -1"),
    (["--devices", "64"], "--devices 64: 64 devices asked for, 1 cpu device(s) available"),
    (["--coordinator", "h:1"], "--coordinator needs --distributed"),
    (["--num-processes", "2"], "--num-processes needs --distributed"),
    (["--process-id", "1"], "--process-id needs --distributed"),
    (["--distributed"], "--distributed needs --out"),
    (["--compile-cache", "/proc/forbidden"], "cannot use --compile-cache /proc/forbidden"),
    (["--epsiodes", "10"], "unrecognized arguments: --epsiodes 10"),
]


@pytest.mark.parametrize(("flags", "needle"), BAD_INPUT, ids=[" ".join(f) for f, _ in BAD_INPUT])
def test_bad_input_is_one_line_and_exit_2(flags, needle, capsys):
    extra = [] if "--compile-cache" in flags else ["--compile-cache", "none"]
    if not {"--out", "--resume", "--distributed"} & set(flags):
        extra.append("--dry-run")  # should a case be accepted, it trains nothing
    code = command.main([*flags, *extra])
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert err.count("\n") == 1 and err.startswith("error: ") and needle in err, err
    assert out == ""
