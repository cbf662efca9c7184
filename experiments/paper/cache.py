"""The training runs the paper scripts share: where each lives, trained once, resumed when
interrupted, reused when finished, and recorded.

A run lives under `DIR/runs/<scale>/` (not in git). `ensure_run` trains it, or reuses it when a
finished run with the same config is there, or resumes it when one was interrupted; a finished
MuJoCo run also leaves a record under `DIR/records/` (committed), which stands in for its
directory on a machine without it.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np

from experiments.paper.common import (
    CARTPOLE,
    FAMILY_ALGOS,
    MUJOCO,
    ROOT,
    Scale,
    describe,
    family_config,
    run_config,
)
from ldn_jax import envs
from ldn_jax.config import Config
from ldn_jax.host import gym_eval
from ldn_jax.host.policy import load_policy
from ldn_jax.host.run_dir import LOCK_FILE, RunDir, write_json
from ldn_jax.host.training import train


def family_run_dir(results: Path, env: str, algo: str, seeds: int) -> Path:
    return results / "runs" / "family" / f"{env}-{algo}-s{seeds}"


def runs_of(results: Path, scale: Scale, env: str) -> Path:
    """Where a scale keeps its runs of `env`: under its name, but cpu-full's CartPole runs are
    the cpu scale's (the same configs, trained once for both)."""
    shared = scale.name == "cpu-full" and env in CARTPOLE
    return results / "runs" / ("cpu" if shared else scale.name)


def run_dir(results: Path, scale: Scale, config: Config) -> Path:
    """`runs_of`'s folder and a name from the algorithm, the LD reading and K. cpu-full's
    MuJoCo runs that are the family study's (the same config: Table 4 on the four tasks
    whose default budget is 1M steps and whose step limit is the paper's) are its runs."""
    shared = scale.name == "cpu-full" and config.env in MUJOCO and config.algo in FAMILY_ALGOS
    if shared and config == family_config(config.env, config.algo, config.seeds):
        return family_run_dir(results, config.env, config.algo, config.seeds)
    name = f"{config.env}-{config.algo}"
    if config.model.ld != "m0":
        name += f"-{config.model.ld}"
    if len(config.k) > 1 or config.k != (1.0,):
        name += "-k" + ",".join(f"{k:g}" for k in config.k)
    return runs_of(results, scale, config.env) / name


def ensure_run(config: Config, out: Path) -> dict:
    """The summary of the run of `config` in `out`: reused if finished, resumed if it was
    interrupted, trained from scratch otherwise (a run of another config there is replaced).
    A MuJoCo run is also reused from its record (`record_of`) when its directory is gone, and
    leaves one once finished. Holds the directory's lock while it looks and trains:
    `RunDirBusy` if another process (another study, a second `plan --train`) trains there."""
    run = RunDir(out)
    if not run.holds_run() and (summary := _recorded_summary(config, out)) is not None:
        print(f"reusing the record {record_of(out)}", flush=True)
        return summary
    out.mkdir(parents=True, exist_ok=True)
    with run.hold():
        resume = run.holds_run() and _of(run, config)
        if resume and run.is_finished():
            _keep_record(config, out)
            return run.read_summary()
        if resume:
            print(f"resuming {out}", flush=True)
        else:
            _clear(out)  # a run of another config, or nothing
            print(f"training {config.env} {config.algo} K={config.k} -> {out}", flush=True)
        summary = train(config, out, checkpoint_every=10, quiet=True, resume=resume)
        if not resume:
            print(
                f"  done: train {summary['train_seconds']:.0f}s, "
                f"compile {summary['compile_seconds']:.0f}s",
                flush=True,
            )
        _keep_record(config, out)
        return summary


def _clear(out: Path) -> None:
    """Remove everything in `out` but the lock file its caller holds."""
    for child in out.iterdir():
        if child.name == LOCK_FILE:
            continue
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child)
        else:
            child.unlink()


def progress(config: Config, out: Path) -> dict:
    """Where the run of `config` in `out` stands, without training: `{"state": "done",
    "seconds"}` (finished there, or its record stands in: state "record"; seconds of training
    and compile), `{"state": "partial", "steps"}` (interrupted: the fewest real steps of any
    seed at its last logged iteration; `ensure_run` resumes it from its last checkpoint) or
    `{"state": "new"}` (nothing of this config there: trained from scratch)."""
    run = RunDir(out)
    held = run.holds_run()  # as `ensure_run` reads it: a record counts where no run is held
    same = held and _same_config(json.loads(run.config_file.read_text()), config)
    summary = state = None
    if same and run.is_finished():
        summary, state = run.read_summary(), "done"
    elif not held:
        summary, state = _recorded_summary(config, out), "record"
    if summary is not None:
        return {"state": state, "seconds": summary["train_seconds"] + summary["compile_seconds"]}
    if not same:
        return {"state": "new"}
    last: dict[int, list[int]] = {}
    if run.metrics_file.is_file():
        for line in run.metrics_file.read_text().splitlines():
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:  # a line cut by the interruption
                continue
            last.setdefault(entry["iteration"], []).append(entry["env_steps"])
    return {"state": "partial", "steps": min(last[max(last)]) if last else 0}


# A MuJoCo run at 1M steps costs minutes to an hour, and its directory (checkpoints, buffers)
# does not belong in git: a finished one leaves a record, the few files the paper's scripts
# read, that can be committed, so a long scale such as cpu-full accumulates over machines.
HISTORY_FILE = "history.npz"
"""A record's per-iteration metrics (`RunDir.history`); its config and summary keep the run
directory's names (`RunDir.config_file`, `RunDir.summary_file`), and the summary is written
last: a record counts once it is there."""


def record_of(out: Path) -> Path | None:
    """Where the run in `DIR/runs/PATH` keeps its record: `DIR/records/PATH` (None for a
    directory outside a `runs` folder)."""
    for parent in out.parents:
        if parent.name == "runs":
            return parent.parent / "records" / out.relative_to(parent)
    return None


def _recorded(out: Path) -> Path | None:
    """`out`'s record if one is there (whatever its config)."""
    record = record_of(out)
    return record if record is not None and RunDir(record).summary_file.is_file() else None


def _of(run: RunDir, config: Config) -> bool:
    """The run held in `run` is of `config`."""
    return _same_config(json.loads(run.config_file.read_text()), config)


def _reusable(config: Config, out: Path) -> bool:
    """`ensure_run` reuses a finished run of `config` in `out`, or its record."""
    run = RunDir(out)
    if run.is_finished():
        return _of(run, config)
    return _recorded_summary(config, out) is not None


def _resumable(config: Config, out: Path) -> bool:
    """`out` holds an interrupted run of `config`, which `ensure_run` resumes."""
    run = RunDir(out)
    return run.holds_run() and _of(run, config)


def has_finished(out: Path) -> bool:
    """A finished run is in `out`, or its record is there in its place."""
    return RunDir(out).is_finished() or _recorded(out) is not None


def finished_summary(out: Path) -> dict | None:
    """The summary of the finished run in `out`, or of its record when the directory holds
    none (whatever config either has); None if neither is there."""
    if RunDir(out).is_finished():
        return RunDir(out).read_summary()
    record = _recorded(out)
    return None if record is None else RunDir(record).read_summary()


def _recorded_summary(config: Config, out: Path) -> dict | None:
    """The summary kept in `out`'s record if that record is of `config`, else None."""
    record = _recorded(out)
    if config.env not in MUJOCO or record is None:
        return None
    if not _same_config(json.loads(RunDir(record).config_file.read_text()), config):
        return None
    return RunDir(record).read_summary()


def _keep_record(config: Config, out: Path) -> None:
    """Write the finished MuJoCo run's record unless one of the same config is there."""
    record = record_of(out)
    if config.env not in MUJOCO or record is None:
        return
    kept = RunDir(record)
    if _recorded(out) and _same_config(json.loads(kept.config_file.read_text()), config):
        return
    run = RunDir(out)
    record.mkdir(parents=True, exist_ok=True)
    kept.summary_file.unlink(missing_ok=True)
    shutil.copyfile(run.config_file, kept.config_file)
    np.savez_compressed(record / HISTORY_FILE, **run.history())
    temporary = kept.summary_file.with_name(kept.summary_file.name + ".tmp")
    shutil.copyfile(run.summary_file, temporary)
    temporary.replace(kept.summary_file)


def _same_config(stored: dict, config: Config) -> bool:
    """Whether a run directory's config.json is `config`: the same run format and the same
    settings once read back, so that a setting added later with its default still matches."""
    if not RunDir.same_format(stored):
        return False
    try:
        plain = lambda c: _resolved(json.loads(json.dumps(c.to_dict())))
        return plain(Config.from_dict(stored)) == plain(config)
    except TypeError:  # a field this version does not know
        return False


def _resolved(config: dict) -> dict:
    """A MuJoCo config's `backend: auto` as the engine it picks here (the CLI records that
    engine, a script's config says "auto": the same run)."""
    if config.get("backend") == "auto" and config.get("env") in envs.mujoco.TASKS:
        return {**config, "backend": envs.mujoco.resolve_backend("auto")}
    return config


def collect_runs(
    envs: tuple[str, ...],
    algos: tuple[str, ...],
    scale: Scale,
    results: Path,
    k=(1.0,),
    train: bool = True,
) -> list[dict]:
    """Ensure the run of every env x algo; one entry each, in order: `{env, algo, status:
    "done", dir, config, summary}`, or `{env, algo, status: "pending", reason}` for a run this
    scale does not do (`run_config`). `train=False` trains nothing: a run that is not
    finished (nor recorded) is pending, with how far it got."""
    entries = []
    for env in envs:
        for algo in algos:
            try:
                config = run_config(scale, env, algo, k)
            except ValueError as error:
                entries.append(
                    {"env": env, "algo": algo, "status": "pending", "reason": str(error)}
                )
                continue
            out = run_dir(results, scale, config)
            if not train and (unfinished := _unfinished(config, out)):
                pending = {"status": "pending", "reason": unfinished}
                entries.append({"env": env, "algo": algo, **pending})
                continue
            summary = ensure_run(config, out)
            entries.append(
                {
                    "env": env,
                    "algo": algo,
                    "status": "done",
                    "dir": out,
                    "config": config,
                    "summary": summary,
                }
            )
    return entries


def _unfinished(config: Config, out: Path) -> str | None:
    """Why the run of `config` in `out` is not there to read (None where it is)."""
    state = progress(config, out)
    if state["state"] in ("done", "record"):
        return None
    if state["state"] == "partial":
        return f"training at {state['steps']:,} real steps per seed"
    if RunDir(out).holds_run() or _recorded(out) is not None:
        return "not trained at the current defaults"  # a run or record of another config
    return "not trained here"


def load_history(out: Path) -> dict[str, np.ndarray]:
    """The run's per-iteration metrics `{name: [K, S, N, ...]}`, from its record when its
    directory holds no finished run."""
    record = _recorded(out)
    if record is not None and not RunDir(out).is_finished():
        with np.load(record / HISTORY_FILE) as history:
            return {name: history[name] for name in history.files}
    return RunDir(out).history()


def has_history(out: Path) -> bool:
    """`load_history(out)` has a finished run to read (its directory's or its record's)."""
    return RunDir(out).is_finished() or _recorded(out) is not None


def budget_text(config: Config) -> str:
    """A run's budget per seed, as its config states it: "600,000 steps" or "8 episodes"."""
    if config.steps is not None:
        return f"{config.steps:,} steps"
    return f"{config.episodes:,} episodes"


def episodes_per_seed(out: Path) -> float:
    """Mean real episodes per seed (K = 1) over the whole run."""
    return float(load_history(out)["episodes"][0, :, -1].mean())


def env_steps_per_seed(out: Path) -> float:
    """Mean real env steps per seed (K = 1) over the whole run."""
    return float(load_history(out)["env_steps"][0, :, -1].mean())


def run_fields(entry: dict) -> dict:
    """What Tables 4 and 5 record of every finished MuJoCo run besides their own measures:
    its budget, real episodes and steps per seed, greedy return and seconds."""
    out, summary = entry["dir"], entry["summary"]
    return {
        "episodes": entry["config"].episodes,
        "budget": budget_text(entry["config"]),
        "episodes_per_seed": episodes_per_seed(out),
        "eval_return": describe([r["eval_return"] for r in summary["runs"]]),
        "env_steps_per_seed": env_steps_per_seed(out),
        "train_seconds": summary["train_seconds"],
        "compile_seconds": summary["compile_seconds"],
    }


def code_version() -> str:
    """HEAD's commit, with "+dirty" where the package's files differ from it. Read once, when
    a study's process starts: the process trains with the code it imported then, whatever is
    committed while it runs."""
    git = lambda *a: subprocess.run(
        ["git", *a], cwd=ROOT, capture_output=True, text=True, check=False
    ).stdout.strip()
    commit = git("rev-parse", "--short", "HEAD") or "unknown"
    return commit + ("+dirty" if git("status", "--porcelain", "--", "ldn_jax") else "")


def package_commit() -> str:
    """The last commit that changed the package or its pins: the code a reused run was
    trained with, where the tree has not changed them since."""
    git = ["git", "log", "-1", "--format=%h", "--", "ldn_jax", "pyproject.toml"]
    return subprocess.run(git, cwd=ROOT, capture_output=True, text=True).stdout.strip()


def replay(out: Path, config: Config, episodes: int, k: float | None = None) -> list[list[float]]:
    """Each seed's greedy returns in gymnasium at `k` (None: the run's first K), `[seeds]
    [episodes]` (`ldn-jax eval`'s)."""
    returns = []
    for seed in range(config.first_seed, config.first_seed + config.seeds):
        env = gym_eval.make_env(config.env, max_steps=config.episode_limit)
        try:
            act = load_policy(out, seed, k)
            returns.append(gym_eval.episode_returns(env, act, episodes, 0).tolist())
        finally:
            env.close()
    return returns


def ensure_replayed(
    config: Config,
    out: Path,
    file: Path,
    labels: dict,
    run: tuple[str, int],
    extra: Callable[[Path], dict] | None = None,
) -> None:
    """Train (or resume, or reuse) the run of `config` in `out`, then write `file` (committed,
    where `out` is not): `labels`, the commits that trained it, its seeds, steps and seconds,
    the trainer's evaluation, each seed's greedy returns in gymnasium and `extra(out)`'s
    fields. `run`: (this process's `code_version`, the greedy episodes per seed). While the
    run trains, `file` names the commits that have trained it so far; a file whose run is
    unchanged since it was written is left as it is."""
    code, episodes = run
    kept = json.loads(file.read_text()) if file.exists() else {}
    commits = kept.get("commits", [])
    if not _reusable(config, out):
        if not _resumable(config, out):  # from scratch: what earlier commits trained is gone
            commits = []
        if code not in commits or "gymnasium" in kept:
            commits = [*dict.fromkeys([*commits, code])]
            kept = {}  # the results of a run that is not the one about to train
            write_json(file, {**labels, "commits": commits})
    summary = ensure_run(config, out)
    if kept.get("train_seconds") == summary["train_seconds"] and "gymnasium" in kept:
        return
    if not RunDir(out).is_finished():
        raise SystemExit(f"error: {out} is a record without checkpoints: replay it where it ran")
    print(f"replaying {out.name} in gymnasium", flush=True)
    write_json(
        file,
        {
            **labels,
            "commits": commits,
            "seeds": list(range(config.first_seed, config.first_seed + config.seeds)),
            "steps": config.steps,
            "train_seconds": summary["train_seconds"],
            "env_steps_per_second": summary["env_steps_per_second"],
            "trainer_eval": [r["eval_return"] for r in summary["runs"]],
            "gymnasium": replay(out, config, episodes),
            **(extra(out) if extra else {}),
        },
    )


def imagined(out: Path) -> dict:
    """The imagined and real steps of the finished run in `out`, all seeds together (an
    `extra` of `ensure_replayed`)."""
    summary = json.loads((out / "summary.json").read_text())
    return {"imagined_steps": summary["imagined_steps"], "env_steps": summary["env_steps"]}


def replayed(folder: Path) -> list[dict]:
    """The files `ensure_replayed` wrote in `folder` whose runs are replayed, in name order,
    each with `scores`: its seeds' mean greedy returns."""
    found = []
    for file in sorted(folder.glob("*.json")):
        data = json.loads(file.read_text())
        if "gymnasium" in data:
            found.append({**data, "scores": [float(np.mean(g)) for g in data["gymnasium"]]})
    return found


def pool(runs: list[dict]) -> dict:
    """Runs of one row (from `replayed`; a seed each, or several) pooled in seed order: their
    seeds, scores and the commits that trained them, each named once."""
    runs = sorted(runs, key=lambda r: r["seeds"][0])
    return {
        "seeds": [s for r in runs for s in r["seeds"]],
        "scores": [s for r in runs for s in r["scores"]],
        "commits": list(dict.fromkeys(c for r in runs for c in r["commits"])),
    }
