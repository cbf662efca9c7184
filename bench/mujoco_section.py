"""`make bench` section `mujoco`: env steps/s of each physics path and training steps/s,
each measured in a fresh subprocess (`mujoco_envs.py`, `mujoco_drift.py`, `bench.training`)
so that compiles do not pile up in one process's memory."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from bench.stages import ALGOS
from ldn_jax import envs

MUJOCO_TRAIN = {
    "inverted_pendulum": (ALGOS, {"seeds": 10, "episodes": 80}, ("native",)),
    "halfcheetah": (("ppo", "ldn"), {"seeds": 10, "episodes": 8}, ("native", "mjx")),
}
"""What the mujoco section trains: every algorithm on inverted_pendulum (10 seeds, 80
episodes: early, short episodes), ppo and ldn on halfcheetah on both engines (10 seeds, one
iteration of 8 x 1,000 steps each)."""


MUJOCO_ENV_TASKS = ("halfcheetah", "inverted_pendulum", "ant")


MUJOCO_ENV_SIZES = (8, 80, 640)


MUJOCO_ENV_STEPS = {"native": 100, "rollout": 100, "mjx": 20, "generalized": 20}
"""Steps per timed call: MJX is 10-50x slower on CPU, so it takes fewer to keep the section
within minutes; rates are per env step either way."""


def mujoco_section(quick: bool = False, brax_python: str | None = None) -> dict:
    """Raw env steps/s per physics path at 8 / 80 / 640 envs (native, `mujoco.rollout` from
    numpy, mjx, brax generalized when `brax_python` has brax), gymnasium's single env, how far
    native and mjx drift apart (`mujoco_drift.py`), and training steps/s: each in a fresh
    subprocess, so compiles do not pile up in one process's memory. `quick`: native and
    rollout on halfcheetah at 80 envs, ldn on inverted_pendulum."""
    here = Path(__file__).resolve().parent
    rows: dict = {"env": [], "train": [], "ratios": []}
    tasks, sizes = (("halfcheetah",), (80,)) if quick else (MUJOCO_ENV_TASKS, MUJOCO_ENV_SIZES)
    backends = ("native", "rollout") if quick else ("native", "rollout", "mjx", "generalized")
    for task in tasks:
        cmd = [str(here / "mujoco_envs.py"), "--task", task]
        rows["env"].append(
            last_json([sys.executable, *cmd, "--backend", "gymnasium", "--steps", "2000"])
        )
        for n in sizes:
            rates = {}
            for backend in backends:
                python = sys.executable
                if backend == "generalized":
                    if not (brax_python and Path(brax_python).exists()):
                        rates[backend] = None
                        continue
                    python = brax_python
                steps = str(MUJOCO_ENV_STEPS[backend])
                args = [python, *cmd, "--backend", backend, "--envs", str(n), "--steps", steps]
                row = last_json(args, timeout=300)
                rows["env"].append(row)
                rates[backend] = row.get("env_steps_per_second")
            rows["ratios"].append({"task": task, "envs": n, **_ratios(rates)})
    if brax_python is None or not Path(brax_python).exists():
        rows["generalized"] = "not measured: brax is not a dependency; give --brax-python"
    if not quick:
        drift = [sys.executable, str(here / "mujoco_drift.py"), "--task"]
        rows["drift"] = [last_json([*drift, task]) for task in envs.mujoco.TASKS]
    for task, (algos, size, engines) in MUJOCO_TRAIN.items():
        if quick:
            if task != "inverted_pendulum":
                continue
            algos, size = ("ldn",), {"seeds": 1, "episodes": 8}
        for backend in engines:
            for algo in algos:
                code = (
                    f"import json; from bench.bench import training; "
                    f"print(json.dumps(training({algo!r}, env={task!r}, "
                    f"chunk_iterations=1, backend={backend!r}, **{size!r})))"
                )
                rows["train"].append(last_json([sys.executable, "-c", code]))
    rows["train_ratios"] = _train_ratios(rows["train"])
    return rows


def _ratios(rates: dict) -> dict:
    out = {}
    if rates.get("native") and rates.get("mjx"):
        out["native_over_mjx"] = round(rates["native"] / rates["mjx"], 1)
    if rates.get("native") and rates.get("generalized"):
        out["native_over_generalized"] = round(rates["native"] / rates["generalized"], 1)
    if rates.get("native") and rates.get("rollout"):
        out["rollout_over_native"] = round(rates["rollout"] / rates["native"], 2)
    return out


def _train_ratios(rows: list[dict]) -> list[dict]:
    """Training env steps/s native over mjx, per (env, algo) trained on both."""
    rate = {(r.get("env"), r.get("algo"), r.get("backend")): r.get("env_steps_per_s") for r in rows}
    out = []
    for (env, algo, backend), native in rate.items():
        mjx = rate.get((env, algo, "mjx"))
        if backend == "native" and native and mjx:
            out.append({"env": env, "algo": algo, "native_over_mjx": round(native / mjx, 1)})
    return out


def last_json(cmd: list[str], timeout: float = 600) -> dict:
    """The last stdout line of `cmd` as JSON; a failure or a timeout is reported as a row."""
    try:
        root = Path(__file__).resolve().parents[1]  # `python -c` finds the bench package there
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=root)
    except subprocess.TimeoutExpired:
        return {"cmd": " ".join(cmd[1:]), "failed": f"timed out after {timeout:.0f} s"}
    if done.returncode != 0:
        return {"cmd": " ".join(cmd[1:]), "failed": done.stderr.strip().splitlines()[-1:]}
    return json.loads(done.stdout.strip().splitlines()[-1])
