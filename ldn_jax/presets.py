"""Presets and per-task defaults, as data, in one order of precedence.

A config field takes the value of the last layer that sets it:

1. the field's default (`ldn_jax.config`'s dataclasses: the paper's CartPole constants);
2. the learner's defaults (`LEARNER`: "a2c" or "ppo");
3. continuous control (`CONTINUOUS`, MuJoCo tasks only);
4. the task's own (`TASKS`: its budget, chunk and the values measured on it);
5. the preset (`PRESETS[name]`), then its entry for the learner (`"learners"`), then its entry
   for the env (`"envs"`) and that entry's for the learner;
6. the `--config` file, then the named flags, then `--set` (`ldn_jax.host.flags`).

Then three rules: a budget given in episodes clears the `steps` budget of every layer below it,
and an algorithm whose imagination is not stopped by the learning degree keeps only the first
K (K does nothing there). `--stop m2ac` and `--stop macura` default `model.ld` to "ensemble".
A preset's model fields apply to model-based algorithms only.

`ldn-jax --explain FIELD` prints the layers that set one field. Why each value is what it is,
with the measurements that chose it, is in the docs (`docs/defaults.md`).
"""

from __future__ import annotations

MODEL_SECTIONS = ("model.", "fit.", "stop.", "imagine.")
"""The sections of imagination's settings: a preset's apply to model-based algorithms only."""

Layer = tuple[str, dict[str, object]]
"""A layer's name and the fields it sets, by dotted name (`agent.actor_lr`)."""

LEARNER: dict[str, dict[str, object]] = {
    "a2c": {},
    # The paper gives no PPO2 constants: rejax's published CartPole PPO ones.
    "ppo": {
        "agent.gamma": 0.99,
        "agent.n_steps": 100,
        "ppo.epochs": 5,
        "ppo.minibatches": 5,
        "agent.entropy_beta": 0.01,
        "agent.actor_lr": 7.5e-4,
        "agent.critic_lr": 7.5e-4,
        # PPO learns from full batches of imagined rows, not from LD-stopped scraps.
        "imagine.mode": "memory",
    },
    # SAC as SB3, SBX and MBPO run it: one env, an update after every real step, gamma 0.99;
    # an iteration is 1,000 real steps (a MuJoCo episode's worth) between the host's logs.
    "sac": {
        "agent.gamma": 0.99,
        "agent.n_steps": 1,
        "workers": 1,
        "schedule": "steps",
        "iteration_steps": 1000,
    },
}

CONTINUOUS: dict[str, dict[str, object]] = {
    # Ours: measured on inverted_pendulum (docs/defaults.md, "Continuous control").
    "a2c": {
        "agent.entropy_beta": 0.0,
        "agent.actor_lr": 1e-3,
        "agent.critic_lr": 3e-3,
        "agent.min_std": 0.05,
        "agent.rmsprop_eps": 1e-5,
    },
    # PPO's usual MuJoCo constants with SB3's unclipped value loss and 10 x 10 minibatches.
    "ppo": {
        "agent.entropy_beta": 0.0,
        "agent.actor_lr": 3e-4,
        "agent.critic_lr": 3e-4,
        "ppo.value_clip": None,
        "ppo.epochs": 10,
        "ppo.minibatches": 10,
    },
    "sac": {},
    # The model for 11- to 27-dimensional observations: standardised deltas, ReLU, the box.
    "model": {
        "model.normalize": True,
        "model.predict_delta": True,
        "model.env_reward": True,
        "model.activation": "relu",
        "model.support": 0.1,
    },
}

_LOCOMOTION = {
    # A 1,000-step locomotion task needs gamma 0.99 (halfcheetah; the rest unmeasured).
    "a2c": {"agent.gamma": 0.99, "agent.actor_lr": 3e-4},
    # SB3 zoo's VecNormalize in our terms: a tenth of the reward, standardised observations.
    "ppo": {"agent.reward_scale": 0.1, "agent.normalize_obs": True},
    # 10,000 uniform random steps first, updates from there (the zoo's halfcheetah constants;
    # adopted by experiments/plans/sac-warmup.md on halfcheetah's seeds 0-4, 2026-12-08).
    "sac": {"sac.random_steps": 10_000, "sac.learning_starts": 10_000},
}

# SB3 zoo's HalfCheetah PPO in our options, with PyTorch's fan-in initialiser as SB3 has it
# (the measurements that chose them: docs/defaults.md, "Locomotion tasks").
_ZOO_HALFCHEETAH_PPO = {
    "agent.hidden_layers": 2,
    "agent.actor_hidden": 256,
    "agent.critic_hidden": 256,
    "agent.activation": "relu",
    "agent.init": "fan_in",
    "agent.log_std_init": -2.0,
    "agent.gamma": 0.98,
    "ppo.gae_lambda": 0.92,
    "ppo.clip_eps": 0.1,
    "ppo.epochs": 20,
    "ppo.minibatches": 8,
    "agent.n_steps": 64,
    "agent.actor_lr": 2.0633e-5,
    "agent.critic_lr": 2.0633e-5,
    "agent.entropy_beta": 0.000401762,
    "ppo.value_coef": 0.58096,
    "ppo.max_grad_norm": 0.8,
}

# PPO's MuJoCo constants of OpenAI Baselines and CleanRL in our options: rollouts of 8 workers
# x 256 steps (2,048 rows) in 32 minibatches, 64 x 64 tanh layers, a state-independent log
# std from 0, an unbounded mean, rewards over the running return's std, a clipped value loss
# (docs/defaults.md, "Locomotion tasks").
_MUJOCO_PPO = {
    "schedule": "steps",
    "iteration_steps": 256,
    "agent.n_steps": 256,
    "ppo.minibatches": 32,
    "agent.hidden_layers": 2,
    "agent.actor_hidden": 64,
    "agent.critic_hidden": 64,
    "agent.activation": "tanh",
    "agent.init": "fan_in",
    "agent.log_std_init": 0.0,
    "agent.squash_mean": False,
    "agent.normalize_obs": True,
    "agent.normalize_reward": True,
    "ppo.value_clip": 0.2,
}
_HOPPING = {**_LOCOMOTION, "ppo": _MUJOCO_PPO}
_A2C_OBS = {**_LOCOMOTION["a2c"], "agent.normalize_obs": True}
_A2C_HOPPER = {**_A2C_OBS, "agent.normalize_reward": True}

# The 1M steps MuJoCo results are usually quoted after (rl-baselines3-zoo).
_LONG = {"steps": 1_000_000, "chunk_iterations": 1}

TASKS: dict[str, dict[str, object]] = {
    # The budget within which the A2C and PPO families learn it (docs/defaults.md,
    # "Continuous control").
    "inverted_pendulum": {"steps": 600_000, "chunk_iterations": 1},
    "halfcheetah": {
        **_LONG,
        "learners": {
            # standardised observations (docs/defaults.md, "Locomotion tasks")
            "a2c": _A2C_OBS,
            "ppo": {**_LOCOMOTION["ppo"], **_ZOO_HALFCHEETAH_PPO},
            "sac": _LOCOMOTION["sac"],
        },
    },
    # the A2C family: standardised observations and rewards (docs/defaults.md, "Locomotion
    # tasks"; chosen on seeds 0-4, 2026-12-07)
    "hopper": {**_LONG, "learners": {**_HOPPING, "a2c": _A2C_HOPPER}},
    # the A2C family: standardised observations (chosen on seeds 0-4, 2026-12-07)
    "walker2d": {**_LONG, "learners": {**_HOPPING, "a2c": _A2C_OBS}},
    # No support box: in 105 dimensions imagined episodes leave it at once (docs/defaults.md,
    # "Continuous control").
    "ant": {**_LONG, "learners": _HOPPING, "model.support": None},
    "ant-nocfrc": {**_LONG, "learners": _HOPPING, "model.support": None},
    "reacher": _LONG,
}
"""Per task: top-level and model fields, and `"learners"`: learner -> agent fields."""

PRESETS: dict[str, dict] = {
    # The paper's algorithm and constants, read literally (docs/paper.md).
    "paper": {},
    # The tutorial code's -5 terminal reward (speeds up CartPole at gamma 0.9).
    "tutorial": {"agent.terminal_reward": -5.0},
    # The reading of eq. 3 under which LD behaves as Figure 5 shows it (mostly near 1).
    "paper-fig5": {"model.ld_reduce": "sum", "model.ld_scale": 10.0},
    # A nonlinear dynamics model predicting state deltas.
    "mlp-model": {"model.activation": "relu", "model.predict_delta": True},
    # Ours, for a solved CartPole rather than a replica: train until the greedy policy
    # plays every evaluation episode to the step limit.
    "fast": {
        "schedule": "steps",
        "k": (1.0,),
        "eval_episodes": 32,
        "learners": {
            "a2c": {
                "agent.gamma": 0.99,
                "agent.reward_scale": 0.1,
                "agent.normalize_obs": True,
                "steps": 600_000,
            },
            "ppo": {"steps": 300_000},
        },
        "envs": {
            "cartpole-v0": {"solved_return": 200.0},
            "cartpole-v1": {"solved_return": 500.0},
            "cartpole-v2": {"solved_return": 1000.0},
        },
    },
}
"""Each preset: fields by dotted name, with optional `"learners"` (learner -> fields) and
`"envs"` (env -> fields) entries applied after it."""

# The on-policy learners' iterations under the branched preset: the A2C family's 100 real steps
# per worker, PPO's one rollout (hopper, walker2d, ant: 256 steps; halfcheetah: two of 64).
_A2C_PPO = lambda ppo, **both: {
    "a2c": {"iteration_steps": 100, **both},
    "ppo": {"iteration_steps": ppo, **both},
}

# SAC's branches in MBPO's manner: a model fit every 250 real steps, until its held-out error
# stalls; then 5,000 rollouts from states of R, each to its horizon (MBPO's 100,000 starts
# per 250 steps at 20 updates per step, scaled to one: each imagined row is drawn as often
# as in MBPO), their rows kept for 4 fits (`sac.model_retain`), 5% real rows in each batch.
# sac-model's horizon is MBPO's schedule (hopper's by default: 1 step until 20k real steps,
# 15 from 100k; halfcheetah's and walker2d's 1 throughout, ant's up to 25), sac-ldn's the LD
# draw under a cap of 15. The model is MBPO's: 7 members of 4 x 200 swish units, 5 elites,
# and no support box. The first 5,000 real steps act uniformly at random and the updates
# start there, as MBPO's exploration steps (docs/logs/mbpo-reference.md).
_MBPO = {
    "iteration_steps": 250,
    "sac.random_steps": 5000,
    "sac.learning_starts": 5000,
    "model.support": None,
    "imagine.branches": 5000,
    "imagine.cut": 15,
    "imagine.real_share": 0.05,
    "fit.early_stop": True,
    # MBPO fits to convergence (14 to 100 epochs per fit here, each a pass over R): tens of
    # hours per 100k-step seed on these 2 cores. A fit stops at 500 steps (docs/training.md).
    "fit.updates": 500,
    "model.ensemble": 7,
    "model.elites": 5,
    "model.hidden_layers": 4,
}
_MBPO_FLAT = {"sac": {"stop.horizon_max": 1}}
_MBPO_ANT = {"sac": {"stop.horizon_max": 25}}

PRESETS["branched"] = {
    # Ours: imagination branched from real states in a probabilistic ensemble (docs/training.md,
    # "Branched imagination"; the measurements that chose it: docs/logs/imagination.md).
    "schedule": "steps",
    "k": (1.0,),
    "imagine.start": "real",
    "model.ld": "ensemble",
    "model.probabilistic": True,
    "model.ensemble": 5,
    "model.elites": 4,
    "model.hidden": 200,
    "model.hidden_layers": 3,
    "model.activation": "swish",
    "fit.batch_size": 256,
    "fit.updates": 50,
    "model.buffer_capacity": 200_000,
    "imagine.branches": 32,
    "imagine.ratio": 4.0,
    "imagine.real_share": 0.05,
    "imagine.cut": 5,
    "learners": {"sac": _MBPO},
    "envs": {
        # A model fit and an imagined batch every 8 workers x 100 real steps (halfcheetah's
        # PPO: x 128, two of its 64-step rollouts).
        # The pendulum's cut: 15 steps (docs/logs/imagination.md).
        "inverted_pendulum": {"imagine.cut": 15, "learners": _A2C_PPO(100)},
        # halfcheetah's cut (ppo-ldn's cap): 15 (the measurements: docs/defaults.md, "The
        # branched preset").
        "halfcheetah": {"imagine.cut": 15, "learners": {**_A2C_PPO(128), **_MBPO_FLAT}},
        # hopper's imagined rows train the on-policy critic only (docs/defaults.md, "The
        # branched preset").
        "hopper": {"learners": _A2C_PPO(256, **{"imagine.updates": "critic"})},
        "walker2d": {"learners": {**_A2C_PPO(256), **_MBPO_FLAT}},
        "ant": {"learners": {**_A2C_PPO(256), **_MBPO_ANT}},
        "ant-nocfrc": {"learners": {**_A2C_PPO(256), **_MBPO_ANT}},
        "reacher": {"learners": _A2C_PPO(100)},
    },
}

ON_MJX: dict[str, dict[str, dict[str, object]]] = {
    # On MJX (`--backend auto` on a GPU or TPU) a seed's workers step side by side in one
    # batched program, so more of them cost little wall clock, where the native engine on a
    # CPU pays for each; halfcheetah's A2C family learns as well on 16 workers as on 8 for the
    # same real steps (1M steps, seeds 0-4, docs/logs/tuning-mujoco.md, 2026-12-07).
    "halfcheetah": {"a2c": {"workers": 16}},
}
"""Task -> learner -> fields for runs whose MuJoCo engine is MJX, over the task's and the
preset's (a field given on the command line still wins)."""

PRESET_PURPOSE = {
    "paper": "the paper's algorithm and constants (the default)",
    "tutorial": "the tutorial code's -5 terminal reward",
    "paper-fig5": "eq. 3 read as Figure 5 shows it (a sum, scaled by 10)",
    "mlp-model": "a ReLU dynamics model predicting state deltas",
    "fast": "CartPole solved: schedule steps, train until the greedy policy solves it",
    "branched": "ours: short imagined rollouts from real states in a probabilistic ensemble",
}
"""One line per preset for `--help`, `--list-fields` and the docs."""


def own_fields(entry: dict) -> dict[str, object]:
    """A preset's or task's own fields, without its `learners` and `envs` entries."""
    return {name: value for name, value in entry.items() if name not in ("learners", "envs")}


def layers(
    preset: str, env: str, learner: str, continuous: bool, model_based: bool = True
) -> list[Layer]:
    """The layers of steps 2-5 for one run, lowest first (empty ones left out). A preset's
    model fields apply to model-based algorithms only (`model_based`), so that its
    model-free learner runs with the same constants beside them."""
    task = TASKS.get(env, {})
    env_entry = PRESETS[preset].get("envs", {}).get(env, {})
    found: list[Layer] = [
        (f"learner {learner}", LEARNER[learner]),
        (
            "continuous control",
            {**CONTINUOUS[learner], **CONTINUOUS["model"]} if continuous else {},
        ),
        (f"task {env}", {**own_fields(task), **task.get("learners", {}).get(learner, {})}),
        (f"preset {preset}", own_fields(PRESETS[preset])),
        (f"preset {preset}, {learner}", PRESETS[preset].get("learners", {}).get(learner, {})),
        (f"preset {preset}, {env}", own_fields(env_entry)),
        (f"preset {preset}, {env}, {learner}", env_entry.get("learners", {}).get(learner, {})),
    ]
    if not model_based:
        model_free = lambda layer, name: (
            not (layer.startswith("preset") and name.startswith(MODEL_SECTIONS))
        )
        found = [
            (layer, {n: v for n, v in vals.items() if model_free(layer, n)})
            for layer, vals in found
        ]
    return [(name, values) for name, values in found if values]
