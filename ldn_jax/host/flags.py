"""Flags -> config: the training command's flags, and the `Config` they describe.

The config's defaults are `Config`'s (`ldn_jax.config`, per-env ones in `from_preset`): a
config flag left out is None here, so that `--resume` can tell which flags were given.

Every field of the config can be set, by its dotted name in `ldn_jax.config.fields()` (the
table read off the dataclasses' annotations, so a new field is settable the day it is
added): from a file (`--config FILE`, TOML or JSON, nested as config.json is), then the
named flags (`CONFIG_FLAGS`: short names for the fields users set most), then
`--set FIELD=VALUE`, each over the one before (their text is read into values by
`ldn_jax.host.settings`).

    python experiments/run.py --config runs/X/config.json --set agent.actor_lr=3e-4
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from ldn_jax import envs
from ldn_jax.config import (
    ACTION_ENCODINGS,
    ALGORITHMS,
    IMAGINE_MODES,
    LD_ESTIMATORS,
    PRESETS,
    SCHEDULES,
    STOP_RULES,
    Config,
    canonical,
    explain,
    fields,
    from_preset,
    get_field,
    resolution,
    validate,
)
from ldn_jax.host.loggers import LOGGERS
from ldn_jax.host.settings import (
    UsageError,
    as_text,
    parse_sweep,
    parse_value,
    read_config_file,
)


class Parser(argparse.ArgumentParser):
    """argparse whose errors are one line (a `UsageError`), not usage + message."""

    def error(self, message: str):
        raise UsageError(message)


DESCRIPTION = """\
Train the A2C or PPO family (plain, -model, -ldn) on one env, many seeds and K at once.

    python experiments/run.py --env cartpole-v2 --algo ldn --seeds 5 --k 0.5,1,2

Writes config.json, metrics.jsonl, summary.json, curves.png and checkpoints/ into --out.
`--devices N` splits the seeds over N devices, `--distributed` over several hosts;
`--dry-run` compiles the training program and prints its cost without training.
Any config field: `--set agent.actor_lr=3e-4` or `--config FILE` (a run's own config.json
reruns it); `--list-fields` shows them all.
"""

CONFIG_FLAGS = {
    "env": "env",
    "algo": "algo",
    "seeds": "seeds",
    "first_seed": "first_seed",
    "k": "k",
    "episodes": "episodes",
    "steps": "steps",
    "workers": "workers",
    "schedule": "schedule",
    "iteration_steps": "iteration_steps",
    "preset": "preset",
    "threshold": "threshold",
    "chunk": "chunk_iterations",
    "backend": "backend",
    "ld": "model.ld",
    "ensemble_size": "model.ensemble",
    "imagine": "imagine.mode",
    "support": "model.support",
    "stop": "stop.rule",
    "horizon": "stop.horizon",
    "cut": "imagine.cut",
    "m2ac_keep": "stop.m2ac_keep",
    "oracle_error": "stop.oracle_error",
    "action_encoding": "model.action_encoding",
}
"""CLI flag (its argparse name) -> the config field it sets: short names for a few fields of
`fields()` (`model.X`: a `ModelConfig` field); every field also takes `--set` and `--config`."""


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The training command's flags, checked against each other (`UsageError`)."""
    args = parser().parse_args(argv)
    if args.wandb_project is not None and args.logger != "wandb":
        raise UsageError("--wandb-project needs --logger wandb")
    if args.checkpoint_every < 0:
        raise UsageError("--checkpoint-every must be >= 0")
    cluster = [f for f in ("coordinator", "num_processes", "process_id") if getattr(args, f)]
    if cluster and not args.distributed:
        raise UsageError(f"{flag_name(cluster[0])} needs --distributed")
    if args.distributed and not (args.out or args.resume or args.dry_run):
        raise UsageError("--distributed needs --out (every process must name the same run)")
    return args


def parser() -> Parser:
    """The training command's parser (`ldn-jax train`, `python experiments/run.py`)."""
    d = Config()
    p = Parser(description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "--env",
        help=f"one of: {', '.join(envs.names())} (default {d.env}); a comma list with "
        "--algo's makes a grid: each env x algo trained in turn in this process",
    )
    p.add_argument(
        "--algo", help=f"one of: {', '.join(ALGORITHMS)} (default {d.algo}); or a comma list"
    )
    p.add_argument(
        "--seeds", type=int, help=f"number of vmapped seeds S..S+N-1 (default {d.seeds})"
    )
    p.add_argument(
        "--first-seed",
        type=int,
        help="S, the first seed (default 0): a run of seeds 5..9 adds to one of 0..4",
    )
    p.add_argument("--k", help=f"comma-separated learning-degree gains K (default {_gains(d.k)})")
    p.add_argument(
        "--episodes",
        type=int,
        help=f"real episodes per seed and K (default {d.episodes} for CartPole; MuJoCo tasks "
        "default to --steps instead: 600000 for inverted_pendulum, 1000000 for the others)",
    )
    p.add_argument(
        "--steps",
        type=int,
        help="instead of --episodes: real env steps per seed and K, summed over workers; each "
        "run stops at the first iteration that reaches them (MuJoCo's natural unit)",
    )
    p.add_argument(
        "--backend",
        help="MuJoCo physics: native (MuJoCo's C engine, fast on CPU), mjx (for GPU/TPU) or "
        "auto (default: native on CPU, mjx on GPU/TPU)",
    )
    p.add_argument("--workers", type=int, help=f"synchronous workers (default {d.workers})")
    p.add_argument(
        "--schedule",
        choices=SCHEDULES,
        help="an iteration's real play: episodes (each worker one whole episode, Algorithm 1 "
        "read literally) or steps (each worker --iteration-steps steps, episodes carrying over "
        f"between iterations, nothing idle) (default {d.schedule})",
    )
    p.add_argument(
        "--iteration-steps",
        type=int,
        metavar="T",
        help="--schedule steps: real steps per worker per iteration, a multiple of the "
        "learner's n_steps (default: the env's step limit, in whole segments)",
    )
    p.add_argument("--preset", help=f"one of: {', '.join(PRESETS)} (default {d.preset})")
    p.add_argument("--threshold", type=float, help="moving-return threshold")
    p.add_argument(
        "--chunk", type=int, help=f"iterations per compiled chunk (default {d.chunk_iterations})"
    )
    p.add_argument(
        "--ld",
        choices=LD_ESTIMATORS,
        help="learning-degree estimator: m0 (M1 vs its initial copy M0, the paper), ensemble "
        "(disagreement of --ensemble-size models relative to their fit error) or variance (a "
        "probabilistic ensemble's own predicted variance) (default m0)",
    )
    p.add_argument(
        "--ensemble-size",
        type=int,
        metavar="E",
        help=f"members with --ld ensemble (default {d.model.ensemble})",
    )
    p.add_argument(
        "--imagine",
        choices=IMAGINE_MODES,
        help="how imagined steps reach the learner: episodes (learnt from as they are played: "
        "the paper), memory (PPO only: kept in the imaginary memory until a whole rollout's "
        "worth exists) or batch (back-to-back imagined episodes, a fixed n_steps x workers a "
        "iteration) (default: episodes; memory for the PPO family)",
    )
    p.add_argument(
        "--support",
        metavar="FRACTION|none",
        help="stop an imagined episode where M1 predicts an observation outside the box of "
        "real ones, widened by FRACTION of its width each side; none: never (default: 0.1 "
        "for MuJoCo tasks, none for CartPole)",
    )
    m = d.model
    p.add_argument(
        "--stop",
        choices=STOP_RULES,
        help="what ends an imagined episode early: ld (the learning-degree draw, MBRL-LDN; "
        "--ld picks its estimator), m2ac (keep the --m2ac-keep share of running rollouts the "
        "ensemble is surest of, each step), macura (stop where the ensemble's disagreement "
        "passes a threshold set each iteration from the branches' starts; needs branches), "
        "horizon (cut after --horizon steps), mbpo (MBPO's horizon schedule, growing with "
        "the real steps), oracle (stop where the true one-step error exceeds --oracle-error; "
        "envs whose observation is their state) or none "
        "(A3C-Model) (default: ld for ldn and ppo-ldn, none for a2c-model and ppo-model)",
    )
    p.add_argument(
        "--horizon",
        type=int,
        metavar="H",
        help=f"--stop horizon: imagined steps per episode (default {d.stop.horizon})",
    )
    p.add_argument(
        "--cut",
        type=int,
        metavar="C",
        help="branches (--preset branched): a branch is cut after C steps, or sooner by --stop "
        f"(default {d.imagine.cut}; the branched preset: 15 on halfcheetah and inverted_pendulum)",
    )
    p.add_argument(
        "--m2ac-keep",
        type=float,
        metavar="Q",
        help=f"--stop m2ac: share of running rollouts kept each step (default {d.stop.m2ac_keep})",
    )
    p.add_argument(
        "--oracle-error",
        type=float,
        metavar="E",
        help="--stop oracle: the largest true one-step error (L2, the observation's units) "
        f"that goes on (default {d.stop.oracle_error})",
    )
    p.add_argument(
        "--action-encoding",
        choices=ACTION_ENCODINGS,
        help="how the model takes a discrete action: one-hot, index (one number) or force "
        f"(the force it applies, one number) (default {m.action_encoding})",
    )
    p.add_argument(
        "--config",
        metavar="FILE",
        help="config fields from a TOML or JSON file, nested as config.json is (a run's own "
        "config.json reruns it); the flags and --set override it",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="set any config field by its dotted name, e.g. agent.actor_lr=3e-4, "
        "model.support=none, k=0.5,1 (repeatable; --list-fields names them all)",
    )
    p.add_argument(
        "--sweep",
        action="append",
        default=[],
        metavar="FIELD=V1,V2,...",
        help="vmap a grid of a float field's values beside seeds and K, one compiled program "
        "for the whole grid, e.g. agent.actor_lr=1e-3,3e-4 (repeatable: the grid of all "
        "combinations; ints, bools and strings need separate runs)",
    )
    p.add_argument(
        "--list-fields",
        action="store_true",
        help="print every config field with its type and its value under the other flags "
        "given, and exit",
    )
    p.add_argument(
        "--explain",
        metavar="FIELD",
        help="print which layers (defaults, learner, continuous control, task, preset, "
        "--config, flags, --set, rules) set FIELD under the other flags given, and exit",
    )
    p.add_argument(
        "--out",
        help="run directory (default runs/ENV-ALGO-TIME); of a grid, the directory of its "
        "runs, DIR/ENV-ALGO (default runs/grid-TIME): the same command again keeps the "
        "finished ones and resumes an interrupted one",
    )
    p.add_argument("--resume", metavar="DIR", help="continue the run in DIR from its checkpoint")
    p.add_argument(
        "--checkpoint-every", type=int, default=20, help="chunks between checkpoints (0: end only)"
    )
    p.add_argument("--quiet", action="store_true", help="no live progress display")
    p.add_argument(
        "--logger",
        default="none",
        choices=LOGGERS,
        help="extra metric sink: tensorboard (RUN/tensorboard) or wandb (RUN/wandb; offline "
        "without a login or network, WANDB_MODE respected)",
    )
    p.add_argument("--wandb-project", metavar="NAME", help="wandb project (default ldn-jax)")
    p.add_argument(
        "--devices",
        help="devices to split the seeds over: N or 'all' (default 1; with --distributed, all); "
        "on CPU, N makes N host devices, one thread each, so the seeds use every core",
    )
    p.add_argument(
        "--bitwise",
        action="store_true",
        default=None,
        help="metrics identical to the bit (CPU) whatever --devices, for runs that all use "
        "--bitwise: no YNNPACK reduction fusions (slower: docs/scaling.md), and a device holding "
        "one seed computes it twice; a resumed run keeps what it was started with",
    )
    p.add_argument(
        "--distributed",
        action="store_true",
        help="multi-host: jax.distributed.initialize (coordinator from the flags below, "
        "JAX_COORDINATOR_ADDRESS, or the cluster: SLURM, Open MPI); process 0 writes the files",
    )
    p.add_argument("--coordinator", metavar="HOST:PORT", help="process 0's address")
    p.add_argument("--num-processes", type=int, help="processes in all (one per host)")
    p.add_argument("--process-id", type=int, help="this process's index, 0..num-processes-1")
    p.add_argument(
        "--compile-cache",
        metavar="DIR",
        help="persistent compilation cache, or 'none' (default $XDG_CACHE_HOME/ldn-jax/jax-cache, "
        "else ~/.cache/ldn-jax/jax-cache)",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="compile the training chunk, print compile seconds, FLOPs and memory, write nothing",
    )
    return p


def grid(args: argparse.Namespace) -> list[argparse.Namespace] | None:
    """`--env A,B --algo X,Y`: one namespace per (env, algorithm), env-major, the flags
    otherwise as given; None for one env and one algorithm (a plain run)."""

    def names(flag: str) -> list[str | None]:
        text = getattr(args, flag)
        if text is None or "," not in text:
            return [text]
        items = [item.strip() for item in text.split(",")]
        if "" in items:
            raise UsageError(f"--{flag} {text}: an empty name in the list")
        twice = sorted({item for item in items if items.count(item) > 1})
        if twice:
            raise UsageError(f"--{flag} {text}: {', '.join(twice)} given twice")
        return items

    env_names, algos = names("env"), names("algo")
    if len(env_names) * len(algos) == 1:
        return None
    for flag in ("resume", "dry_run", "list_fields", "explain", "distributed"):
        if getattr(args, flag):
            raise UsageError(f"{flag_name(flag)} takes one --env and one --algo, not a list")
    return [
        argparse.Namespace(**{**vars(args), "env": env, "algo": algo})
        for env in env_names
        for algo in algos
    ]


def build_config(args: argparse.Namespace) -> Config:
    """The config the flags describe (defaults for those not given), validated; a MuJoCo
    run's `auto` backend resolved. `UsageError` for anything impossible."""
    preset, settings = requested(args)
    setting = lambda name: settings.get(name, (None,))[0]
    if args.ensemble_size is not None and "ensemble" not in (
        setting("model.ld"),
        "ensemble" if setting("stop.rule") == "m2ac" else None,
    ):
        raise UsageError("--ensemble-size needs --ld ensemble (or --stop m2ac)")
    for flag, rule in (("horizon", "horizon"), ("m2ac_keep", "m2ac"), ("oracle_error", "oracle")):
        if getattr(args, flag) is not None and setting("stop.rule") != rule:
            hint = " (a branch's cut is --cut)" if flag == "horizon" else ""
            raise UsageError(f"{flag_name(flag)} needs --stop {rule}{hint}")
    overrides: dict = {}
    for name, (value, _) in settings.items():
        section, _, sub = name.rpartition(".")
        (overrides.setdefault(section, {}) if section else overrides)[sub] = value
    try:
        config = validate(from_preset(preset or Config.preset, **overrides))
    except ValueError as error:
        raise UsageError(str(error)) from None
    if args.cut is not None and config.imagine.start != "real":
        raise UsageError("--cut needs branches: --preset branched (or imagine.start real)")
    return resolve_physics(config)


def requested(args: argparse.Namespace) -> tuple[str | None, dict[str, tuple[object, str]]]:
    """What the command line asks for: the preset (None: not named) and the fields it sets,
    `{dotted name: (value, where it was given)}`: the `--config` file's, then the named
    flags', then `--set`'s, each over the one before."""
    preset, settings = (None, {}) if args.config is None else read_config_file(args.config)
    given: dict[str, tuple[object, str]] = {}
    for flag, name in CONFIG_FLAGS.items():
        text = getattr(args, flag)
        if text is None or flag == "preset":
            continue
        value = {"k": parse_k, "support": parse_support}.get(flag, lambda v: v)(text)
        given[name] = (value, f"{flag_name(flag)} {text}")
    for item in args.set:
        name, sep, text = item.partition("=")
        name = canonical(name.strip())
        if not sep:
            raise UsageError(f"--set needs FIELD=VALUE, got {item!r}")
        if name in given:
            raise UsageError(f"--set {item}: {name} is already given by {given[name][1]}")
        if name == "sweep":
            raise UsageError(f"--set {item}: a sweep is given with --sweep FIELD=V1,V2,...")
        given[name] = (parse_value(name, text.strip(), f"--set {item}"), f"--set {item}")
    if args.sweep:
        where = " ".join(f"--sweep {item}" for item in args.sweep)
        given["sweep"] = (tuple(parse_sweep(item) for item in args.sweep), where)
    if "steps" in given and "episodes" in given:
        named = lambda where: where if where.startswith("--set") else where.split()[0]
        raise UsageError(
            f"give {named(given['steps'][1])} or {named(given['episodes'][1])}, not both "
            "(one budget per run)"
        )
    if "episodes" in given and "steps" not in given:
        settings.pop("steps", None)  # a budget in episodes replaces the file's in steps
        given["steps"] = (None, given["episodes"][1])
    return args.preset or preset, settings | given


def explain_field(args: argparse.Namespace, name: str) -> list[str]:
    """`--explain FIELD`: each layer that sets the field under these flags, lowest first,
    with its value; the last one is the run's."""
    name = canonical(name)
    if name != "preset" and name not in fields():
        raise UsageError(f"--explain {name}: unknown config field (--list-fields names them)")
    preset, given = requested(args)
    preset = preset or Config.preset
    if name == "preset":
        return [f"preset = {preset}"]
    try:
        found = explain(preset, given, name)
    except ValueError as error:
        raise UsageError(str(error)) from None
    if args.config is not None and name in given:  # the file's value, if a flag replaced it
        _, from_file = read_config_file(args.config)
        if name in from_file and from_file[name][1] != given[name][1]:
            at = next(i for i, (layer, _) in enumerate(found) if layer == given[name][1])
            found.insert(at, (from_file[name][1], from_file[name][0]))
    width = max(len(layer) for layer, _ in found)
    lines = [f"{name} = {as_text(found[-1][1])}   (preset {preset})"]
    lines += [f"  {layer:<{width}}  {as_text(value)}" for layer, value in found]
    return lines


def field_sources(args: argparse.Namespace) -> dict[str, str]:
    """The layer that set each config field under these flags (`--list-fields`)."""
    preset, given = requested(args)
    sources = {}
    for layer, values in resolution(preset or Config.preset, given):
        sources |= dict.fromkeys(values, layer)
    return sources


def resolve_physics(config: Config) -> Config:
    """A MuJoCo run records the engine `auto` picked, and its model must load (one line
    otherwise); other envs keep the config as it is."""
    if config.env not in envs.mujoco.TASKS:
        return config
    backend = envs.mujoco.resolve_backend(config.backend)
    try:
        envs.mujoco.engine(config.env, backend)
    except envs.mujoco.ModelError as error:
        raise UsageError(f"--backend {backend}: {error}") from None
    return dataclasses.replace(config, backend=backend)


def check_resume_flags(args: argparse.Namespace, config: Config) -> None:
    """Settings given with `--resume` (flags, `--set`, `--config`) must agree with the stored
    config."""
    preset, settings = requested(args)
    if preset is not None and preset != config.preset:
        raise UsageError(
            f"preset {preset} does not match the run being resumed (preset = {config.preset}); "
            "drop it to resume"
        )
    for name, (value, where) in settings.items():
        stored = get_field(config, name)
        if name == "backend" and value == "auto" and config.env in envs.mujoco.TASKS:
            value = envs.mujoco.resolve_backend(value)
        if name == "k":
            value, stored = tuple(value), tuple(stored)
            if not config.uses_k:
                value = value[:1]
        if name == "steps" and value is None and "episodes" in where:
            continue  # `--episodes N` clears steps; episodes itself is compared
        if value != stored:
            raise UsageError(
                f"{where} does not match the run being resumed ({name} = {stored}); "
                "drop it to resume"
            )
    if args.out is not None and Path(args.out).resolve() != Path(args.resume).resolve():
        raise UsageError("--out and --resume name different directories; give --resume alone")


def parse_k(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise UsageError(f"--k must be comma-separated numbers, got {text!r}") from None


def parse_support(text: str) -> float | None:
    if text.strip().lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise UsageError(f"--support must be a number or none, got {text!r}") from None


def flag_name(name: str) -> str:
    """argparse's name of a flag -> how the user types it (`ensemble_size` -> --ensemble-size)."""
    return "--" + name.replace("_", "-")


def _gains(k: tuple[float, ...]) -> str:
    return ",".join(f"{v:g}" for v in k)
