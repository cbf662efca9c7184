"""Every config field from the command line: `--set`, `--config FILE`, `--list-fields`."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ldn_jax.config import SECTIONS, Config, fields, from_preset, get_field
from ldn_jax.host import flags
from ldn_jax.host.settings import UsageError

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, str(ROOT / "experiments" / "run.py")]


def build(*argv: str) -> Config:
    return flags.build_config(flags.parse_args(list(argv)))


def refused(*argv: str) -> str:
    with pytest.raises(UsageError) as error:
        build(*argv)
    message = str(error.value)
    assert "\n" not in message
    return message


def test_the_field_table_is_read_off_the_dataclasses():
    table = fields()
    assert not {"preset", "sweep", *SECTIONS} & set(table)
    assert table["agent.actor_lr"].base is float and table["seeds"].base is int
    assert table["agent.normalize_obs"].base is bool and table["model.ld"].base is str
    assert table["steps"].optional and table["model.support"].optional
    assert table["k"].sequence and table["k"].base is float
    # every field the dataclasses declare, nothing else
    import dataclasses

    declared = {f.name for f in dataclasses.fields(Config)} - {"preset", "sweep", *SECTIONS}
    for section, kind in SECTIONS.items():
        declared |= {f"{section}.{f.name}" for f in dataclasses.fields(kind)}
    assert set(table) == declared
    # no section over 25 fields
    assert max(len(dataclasses.fields(kind)) for kind in SECTIONS.values()) <= 25
    # the named flags are short names for fields of the table
    assert set(flags.CONFIG_FLAGS.values()) - {"preset"} <= set(table)


@pytest.mark.parametrize(
    ("setting", "name", "value"),
    [
        ("agent.actor_lr=3e-4", "agent.actor_lr", 3e-4),
        ("agent.n_steps=20", "agent.n_steps", 20),
        ("agent.normalize_obs=true", "agent.normalize_obs", True),
        ("agent.terminal_reward=none", "agent.terminal_reward", None),
        ("agent.terminal_reward=-5", "agent.terminal_reward", -5.0),
        ("model.activation=relu", "model.activation", "relu"),
        ("model.lr=0.01", "fit.lr", 0.01),  # the name from before the split
        ("fit.weight_decay=1e-4", "fit.weight_decay", 1e-4),
        ("k=0.5,2", "k", (0.5, 2.0)),
        ("threshold=120", "threshold", 120.0),
        ("moving_decay=0.9", "moving_decay", 0.9),
    ],
)
def test_set_reaches_every_kind_of_field(setting, name, value):
    config = build("--set", setting)
    assert get_field(config, name) == value
    assert type(get_field(config, name)) is type(value)


def test_set_over_the_presets_and_per_learner_defaults():
    config = build("--algo", "ppo", "--set", "ppo.epochs=2")
    assert config.ppo.epochs == 2 and config.agent.n_steps == 100  # PPO's other defaults
    config = build("--env", "hopper", "--set", "model.support=none")
    assert config.model.support is None and config.model.normalize  # MuJoCo's model defaults
    config = build("--preset", "tutorial", "--set", "agent.gamma=0.95")
    assert config.agent.gamma == 0.95 and config.agent.terminal_reward == -5.0


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--set", "agent.actor_lrr=3e-4"], "unknown config field 'agent.actor_lrr'; did you mean"),
        (["--set", "agent.actor_lr=fast"], "agent.actor_lr takes float, got 'fast'"),
        (["--set", "seeds=1.5"], "seeds takes int, got '1.5'"),
        (["--set", "agent.normalize_obs=maybe"], "agent.normalize_obs takes bool"),
        (["--set", "agent.gamma=none"], "agent.gamma takes float, got 'none'"),
        (["--set", "agent.gamma=2"], "gamma must be in (0, 1], got 2.0"),
        (["--set", "model.lr=-1"], "fit lr must be > 0"),
        (["--set", "fit.weight_decay=-1"], "fit weight_decay must be >= 0 and finite, got -1"),
        (["--algo", "ppo", "--set", "ppo.target_kl=0"], "target_kl must be > 0 (or None"),
        (["--algo", "ppo", "--set", "agent.obs_clip=0"], "obs_clip must be > 0, got 0"),
        (["--set", "actor_lr"], "--set needs FIELD=VALUE"),
        (["--k", "1", "--set", "k=2"], "k is already given by --k 1"),
        (["--steps", "100", "--set", "episodes=3"], "not both (one budget per run)"),
    ],
)
def test_bad_settings_are_one_line(argv, needle):
    assert needle in refused(*argv)


def test_config_files_in_toml_and_json(tmp_path):
    toml = tmp_path / "ppo.toml"
    toml.write_text('env = "cartpole-v1"\nalgo = "ppo"\n[agent]\nactor_lr = 1e-4\nepochs = 3\n')
    config = build("--config", str(toml))
    assert (config.env, config.algo, config.agent.actor_lr, config.ppo.epochs) == (
        "cartpole-v1",
        "ppo",
        1e-4,
        3,
    )
    assert config.agent.n_steps == 100  # not in the file: PPO's default
    # flags and then --set override the file
    config = build("--config", str(toml), "--env", "cartpole-v0", "--set", "ppo.epochs=7")
    assert (config.env, config.ppo.epochs, config.agent.actor_lr) == ("cartpole-v0", 7, 1e-4)
    as_json = tmp_path / "c.json"
    as_json.write_text(json.dumps({"k": [1, 2], "threshold": 3, "model": {"support": "none"}}))
    config = build("--config", str(as_json))
    assert config.k == (1.0, 2.0) and config.threshold == 3.0 and config.model.support is None


@pytest.mark.parametrize(
    ("text", "suffix", "needle"),
    [
        ('[agent]\nactor_lr = "x"\n', ".toml", "agent.actor_lr takes float, got 'x'"),
        ("[agent\n", ".toml", "not valid TOML"),
        ('{"seeds": true}', ".json", "seeds takes int, got True"),
        ('{"agent": {"gamma": 3}}', ".json", "gamma must be in (0, 1]"),
        ('{"agent": 3}', ".json", "agent must be a table of its fields"),
        ('{"model": {"lrr": 1}}', ".json", "unknown config field 'model.lrr'"),
        ("seeds: 3", ".yaml", "expected a .toml or .json file"),
    ],
)
def test_bad_config_files_are_one_line(tmp_path, text, suffix, needle):
    path = tmp_path / f"c{suffix}"
    path.write_text(text)
    assert needle in refused("--config", str(path))
    assert "No such file" in refused("--config", str(tmp_path / "missing.toml"))


def test_a_runs_own_config_json_gives_back_its_config(tmp_path):
    for argv in (
        ["--env", "halfcheetah", "--algo", "ppo"],
        ["--algo", "a2c", "--preset", "fast", "--env", "cartpole-v1"],
        ["--algo", "ldn", "--k", "0.5,2", "--set", "model.lr=0.003"],
    ):
        config = build(*argv)
        path = tmp_path / "config.json"
        path.write_text(json.dumps({**config.to_dict(), "run_format": 1}))
        assert build("--config", str(path)) == config
    # a budget in episodes replaces the file's budget in steps
    config = build("--config", str(tmp_path / "config.json"), "--episodes", "40")
    assert config.episodes == 40 and config.steps is None


def test_resume_refuses_settings_that_differ(tmp_path):
    stored = from_preset("paper", algo="ldn", seeds=2)
    check = lambda *argv: flags.check_resume_flags(
        flags.parse_args(["--resume", str(tmp_path), *argv]), stored
    )
    check("--set", "agent.gamma=0.9", "--set", "seeds=2")  # equal: fine
    with pytest.raises(UsageError, match=r"--set agent.gamma=0.99 does not match.*gamma = 0.9"):
        check("--set", "agent.gamma=0.99")
    path = tmp_path / "config.json"
    path.write_text(json.dumps(stored.to_dict()))
    check("--config", str(path))
    path.write_text(json.dumps({"model": {"lr": 0.5}}))
    with pytest.raises(UsageError, match=r"fit\.lr = 0\.001"):
        check("--config", str(path))


def test_list_fields_prints_every_field_with_its_value():
    result = subprocess.run(
        [*RUN, "--env", "halfcheetah", "--algo", "ppo", "--list-fields"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    rows = {line.split()[0]: line.split()[1:] for line in result.stdout.splitlines()}
    assert set(rows) == {"preset", "sweep", *fields()}
    assert rows["agent.reward_scale"][:2] == ["float", "0.1"]  # halfcheetah's PPO default
    assert rows["steps"][:4] == ["int", "or", "none", "1000000"]
    assert "Discount factor." in " ".join(rows["agent.gamma"])


def test_a_bad_setting_exits_2_with_one_line_from_the_command():
    result = subprocess.run(
        [*RUN, "--set", "agent.gama=0.99"], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert "did you mean agent.gamma?" in result.stderr


def test_explain_lists_every_layer_that_sets_a_field_in_order(tmp_path):
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"agent": {"actor_lr": 5e-4}}))
    args = ["--env", "halfcheetah", "--algo", "ppo", "--config", str(path)]
    lines = flags.explain_field(
        flags.parse_args([*args, "--set", "agent.actor_lr=1e-4"]), "agent.actor_lr"
    )
    assert lines[0] == "agent.actor_lr = 0.0001   (preset paper)"
    layers = [line.split()[0] for line in lines[1:]]
    assert layers == ["default", "learner", "continuous", "task", "--config", "--set"]
    assert [line.split()[-1] for line in lines[1:]] == [
        "0.001",
        "0.00075",
        "0.0003",
        "2.0633e-05",  # the zoo's HalfCheetah PPO
        "0.0005",
        "0.0001",
    ]
    k = flags.explain_field(flags.parse_args(["--algo", "ppo-model", "--k", "0.5,1"]), "k")
    assert k[-1].split()[-1] == "0.5" and "does not use K" in k[-1]
    sources = flags.field_sources(flags.parse_args(["--env", "hopper", "--algo", "ppo"]))
    assert sources["steps"] == "task hopper" and sources["agent.gamma"] == "learner ppo"
    assert sources["seeds"] == "default"


def test_a_value_no_run_could_use_is_refused_whatever_the_algorithm():
    assert (
        refused("--algo", "a2c", "--set", "model.hidden=-5") == "model hidden must be >= 1, got -5"
    )
    assert "horizon must be >= 1" in refused("--algo", "ldn", "--set", "stop.horizon=0")
    assert "agent.critic_lr must be a finite number" in refused("--set", "agent.critic_lr=inf")


def test_on_mjx_halfcheetahs_a2c_family_takes_more_workers_unless_told():
    """`presets.ON_MJX`: the layer applies where the engine resolves to MJX (a GPU's `auto`,
    or `--backend mjx` here); the native engine keeps the task's workers, and a given
    `--workers` wins over both."""
    workers = lambda *args: flags.explain_field(
        flags.parse_args(["--env", "halfcheetah", *args]), "workers"
    )
    on_mjx = workers("--algo", "ldn", "--backend", "mjx")
    assert on_mjx[0].split()[2] == "16" and "MuJoCo on MJX, halfcheetah, a2c" in on_mjx[-1]
    assert workers("--algo", "ldn", "--backend", "native")[0].split()[2] == "8"
    from ldn_jax.envs.mujoco import resolve_backend

    auto = "16" if resolve_backend("auto") == "mjx" else "8"  # native on a CPU
    assert workers("--algo", "ldn")[0].split()[2] == auto
    assert workers("--algo", "a2c", "--backend", "mjx", "--workers", "4")[0].split()[2] == "4"
    assert workers("--algo", "ppo", "--backend", "mjx")[0].split()[2] == "8"  # PPO: unmeasured
