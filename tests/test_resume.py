"""Nothing lost: resume equals an uninterrupted run, signals checkpoint, bad run dirs fail
cleanly, and a diverging seed is frozen while the others go on."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest

from ldn_jax.config import from_preset
from ldn_jax.host.run_dir import read_config as read_run_config
from ldn_jax.host.training import Interrupted, Stop, train
from ldn_jax.trainer import Trainer

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, str(ROOT / "experiments" / "run.py")]
CONFIG = dict(env="cartpole-v0", algo="ldn", seeds=2, k=(0.5, 2.0), episodes=48, workers=4)
CONFIG["chunk_iterations"] = 2  # 6 chunks


class StopAfter(Stop):
    """Asks to stop once `chunks` chunks are done, as a SIGINT would."""

    def __init__(self, chunks: int):
        super().__init__()
        self.chunks = chunks

    def requested(self, chunks_done: int) -> bool:
        if chunks_done >= self.chunks:
            self.signum = signal.SIGINT
        return self.signum is not None


def _lines(run_dir: Path) -> list[dict]:
    lines = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in line.items() if k != "wall_seconds"} for line in lines]


def _timeless(summary: dict) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "seconds_to_threshold"} for r in summary["runs"]]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("reference")
    summary = train(from_preset("paper", **CONFIG), out, checkpoint_every=2, quiet=True)
    return out, summary


@pytest.mark.parametrize("stop_after", [1, 4])
def test_resume_after_interrupt_equals_uninterrupted_run_bitwise(reference, tmp_path, stop_after):
    ref_dir, ref_summary = reference
    config = from_preset("paper", **CONFIG)
    with pytest.raises(Interrupted):
        train(config, tmp_path, checkpoint_every=2, quiet=True, stop=StopAfter(stop_after))
    assert not (tmp_path / "summary.json").exists()
    assert len(_lines(tmp_path)) == 2 * 2 * 2 * stop_after  # K x seeds x iterations per chunk
    summary = train(
        read_run_config(tmp_path), tmp_path, checkpoint_every=2, quiet=True, resume=True
    )
    assert _lines(tmp_path) == _lines(ref_dir)
    assert _timeless(summary) == _timeless(ref_summary) and summary["resumes"] == 1
    final = lambda run: np.load(run / "checkpoints" / "final.host.npz")["history/moving_after"]
    np.testing.assert_array_equal(final(tmp_path), final(ref_dir))


def test_a_second_run_of_the_same_config_reuses_its_program_and_equals_the_first(
    reference, tmp_path
):
    ref_dir, ref_summary = reference
    summary = train(from_preset("paper", **CONFIG), tmp_path, checkpoint_every=2, quiet=True)
    assert ref_summary["compile_seconds"] > 0 and summary["compile_seconds"] == 0
    assert _lines(tmp_path) == _lines(ref_dir)
    other = from_preset("paper", **{**CONFIG, "episodes": 40})  # another config: compiled
    assert train(other, tmp_path / "other", quiet=True)["compile_seconds"] > 0


def _start(out: Path, *extra: str) -> subprocess.Popen:
    args = ["--env", "cartpole-v0", "--algo", "a2c", "--seeds", "2", "--episodes", "1600"]
    args += ["--workers", "4", "--chunk", "1", "--quiet", "--out", str(out), *extra]
    return subprocess.Popen([*RUN, *args], stderr=subprocess.PIPE, text=True)


def _wait_for_lines(out: Path, count: int, process: subprocess.Popen) -> None:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        path = out / "metrics.jsonl"
        if path.exists() and len(path.read_text().splitlines()) >= count:
            return
        time.sleep(0.05)
    pytest.fail("the run did not log in time")


def _resume(out: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*RUN, "--resume", str(out), "--quiet"], capture_output=True, text=True, timeout=300
    )


def _assert_complete_without_duplicates(out: Path, iterations: int) -> None:
    keys = [(line["iteration"], line["seed"], line["k"]) for line in _lines(out)]
    assert len(keys) == len(set(keys)), "a metrics line was duplicated"
    assert sorted({key[0] for key in keys}) == list(range(1, iterations + 1))
    assert len(keys) == 2 * iterations


def test_sigterm_checkpoints_and_resumes(tmp_path):
    out = tmp_path / "run"
    process = _start(out)
    _wait_for_lines(out, 2 * 5, process)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 128 + signal.SIGTERM, stderr
    assert f"--resume {out}" in stderr and "Traceback" not in stderr
    assert any((out / "checkpoints").glob("chunk_*.host.npz"))
    result = _resume(out)
    assert result.returncode == 0, result.stderr
    _assert_complete_without_duplicates(out, 1600 // 4)


def test_sigkill_loses_at_most_one_checkpoint_interval(tmp_path):
    out = tmp_path / "run"
    process = _start(out, "--checkpoint-every", "10")
    _wait_for_lines(out, 2 * 35, process)
    process.kill()
    process.wait(timeout=60)
    logged = max(line["iteration"] for line in _lines(out))
    saved = sorted((out / "checkpoints").glob("chunk_*.host.npz"))
    kept = int(saved[-1].name[len("chunk_") :][:5])
    assert logged - kept < 10 + 1  # at most one interval (plus the chunk being written)
    result = _resume(out)
    assert result.returncode == 0, result.stderr
    _assert_complete_without_duplicates(out, 1600 // 4)


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*RUN, *args], capture_output=True, text=True, timeout=120)


def _assert_one_line_error(result: subprocess.CompletedProcess, needle: str) -> None:
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], result.stderr


def test_bad_run_dirs_give_one_line_errors(reference, tmp_path):
    ref_dir, _ = reference
    _assert_one_line_error(_cli("--resume", str(tmp_path / "nothing")), "holds no run")
    _assert_one_line_error(
        _cli("--resume", str(ref_dir), "--seeds", "3"), "does not match the run being resumed"
    )
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "config.json").write_text('{"env": "cartpole-v0", "alg')
    _assert_one_line_error(_cli("--resume", str(corrupt)), "corrupt")
    old = tmp_path / "old"
    old.mkdir()
    (old / "config.json").write_text(json.dumps({"env": "cartpole-v0"}))
    _assert_one_line_error(_cli("--resume", str(old)), "another ldn-jax version")


def test_truncated_checkpoint_gives_a_one_line_error(reference, tmp_path):
    ref_dir, _ = reference
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-r", str(ref_dir), str(copy)], check=True)
    # Every checkpoint damaged (one damaged copy is survived: tests/test_faults.py).
    for state_dir in (p for p in (copy / "checkpoints").iterdir() if p.is_dir()):
        files = [p for p in state_dir.rglob("*") if p.is_file()]
        largest = max(files, key=lambda p: p.stat().st_size)
        largest.write_bytes(largest.read_bytes()[: largest.stat().st_size // 2])
    _assert_one_line_error(_cli("--resume", str(copy)), "unreadable")


def test_diverging_seed_is_frozen_and_flagged_while_others_finish(tmp_path, monkeypatch, capsys):
    # Seed 1 gets an absurd learning rate (the optimiser's injected hyperparameter).
    init_batch = Trainer.init_batch

    def with_absurd_lr(self):
        states = init_batch(self)

        def absurd(path, x):
            if "learning_rate" in jax.tree_util.keystr(path):
                return x.at[:, 1].set(1e30)
            return x

        opt_state = jax.tree_util.tree_map_with_path(absurd, states.learner.opt_state)
        return states.replace(learner=states.learner.replace(opt_state=opt_state))

    monkeypatch.setattr(Trainer, "init_batch", with_absurd_lr)
    config = from_preset("paper", **{**CONFIG, "seeds": 3, "k": (1.0,), "episodes": 32})
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    runs = {run["seed"]: run for run in summary["runs"]}
    assert runs[1]["diverged"]["iteration"] == 1
    assert "real-stage losses" in runs[1]["diverged"]["quantities"]
    assert runs[0]["diverged"] is None and runs[2]["diverged"] is None
    assert runs[0]["final_moving_return"] > 0 and runs[2]["final_moving_return"] > 0
    assert "seed 1 K=1: non-finite" in capsys.readouterr().err
    final = [line for line in _lines(tmp_path) if line["iteration"] == 8]
    assert [line["episodes"] for line in final] == [32, 0, 32]  # seed 1 frozen from the start


def test_a_checkpoint_without_a_settings_arrays_is_refused_not_padded(tmp_path):
    """A checkpoint of the default layout restores into a target that wants the learned
    termination's arrays only by failing: the partial restore (for checkpoints from before a
    None field existed) never invents arrays."""
    from ldn_jax.host import checkpoint

    plain = from_preset("paper", env="cartpole-v1", algo="ldn", seeds=1)
    state = Trainer(plain).init_batch()
    checkpoint.save(tmp_path / "c", state)
    assert checkpoint.restore(tmp_path / "c", state).model.termination is None
    imagine = {"termination": "learned"}
    learned = from_preset("paper", env="cartpole-v1", algo="ldn", seeds=1, imagine=imagine)
    wants = jax.eval_shape(Trainer(learned).init_batch)
    with pytest.raises(ValueError):
        checkpoint.restore(tmp_path / "c", wants)
