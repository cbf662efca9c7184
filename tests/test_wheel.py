"""The wheel `pip install .` builds: only `ldn_jax`, every module of it, and a command that
trains a MuJoCo task from any directory once installed."""

import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    (path,) = out.glob("ldn_jax-*.whl")
    return path


def _venv(where: Path, wheel: Path, deps: bool) -> Path:
    """A fresh virtual environment with the wheel installed; its dependencies from PyPI
    (`deps`) or, to stay quick, this environment's site-packages behind a .pth file (the
    editable install's finder is not loaded that way, so `ldn_jax` is the wheel's)."""
    subprocess.run([sys.executable, "-m", "venv", str(where)], check=True, timeout=300)
    python = where / "bin" / "python"
    if not deps:
        purelib = subprocess.run(
            [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        ours = sysconfig.get_paths()["purelib"]
        Path(purelib, "ldn_jax_test_deps.pth").write_text(ours + "\n")
    flags = [] if deps else ["--no-deps", "--no-index"]
    done = subprocess.run(
        [python, "-m", "pip", "install", "-q", *flags, str(wheel)],
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return where / "bin"


def _use(bin_dir: Path, cwd: Path):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    python = bin_dir / "python"
    where = subprocess.run(
        [python, "-c", "import ldn_jax.envs.mujoco, ldn_jax; print(ldn_jax.__file__)"],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
    )
    assert where.returncode == 0, where.stderr[-2000:]
    assert Path(where.stdout.strip()).is_relative_to(bin_dir.parent), where.stdout
    for name in ("envs", "experiments"):  # no generic top-level names
        done = subprocess.run([python, "-c", f"import {name}"], cwd=cwd, env=env)
        assert done.returncode != 0, name
    helped = subprocess.run(
        [bin_dir / "ldn-jax", "--help"], capture_output=True, text=True, cwd=cwd, env=env
    )
    assert helped.returncode == 0 and "ldn-jax eval" in helped.stdout, helped.stderr
    run = [bin_dir / "ldn-jax", "--env", "inverted_pendulum", "--algo", "ppo", "--seeds", "1"]
    trained = subprocess.run(
        [*run, "--steps", "1", "--workers", "2", "--quiet", "--out", "run"],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=600,
    )
    assert trained.returncode == 0, trained.stderr[-3000:]
    assert (cwd / "run" / "summary.json").exists() and (cwd / "run" / "metrics.jsonl").exists()


def test_the_wheel_holds_only_ldn_jax_and_every_module_of_it(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {name.split("/")[0] for name in names}
    assert {top for top in tops if not top.endswith(".dist-info")} == {"ldn_jax"}
    package = {str(path.relative_to(ROOT)) for path in (ROOT / "ldn_jax").rglob("*.py")}
    assert package <= set(names), package - set(names)
    assert "ldn_jax/envs/mujoco/native.py" in names


def test_the_installed_wheel_trains_mujoco_from_another_directory(wheel, tmp_path):
    bin_dir = _venv(tmp_path / "venv", wheel, deps=False)
    work = tmp_path / "elsewhere"
    work.mkdir()
    _use(bin_dir, work)


@pytest.mark.slow
def test_the_wheel_installs_with_its_pinned_dependencies_into_a_fresh_venv(wheel, tmp_path):
    bin_dir = _venv(tmp_path / "venv", wheel, deps=True)
    work = tmp_path / "elsewhere"
    work.mkdir()
    _use(bin_dir, work)
