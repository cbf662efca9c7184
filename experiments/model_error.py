"""How wrong a finished run's model is on the branches it imagines: from states of the run's
own real buffer, each seed's model plays H steps with the run's policy, and the true env is
stepped from the same states with the same actions.

    python -m experiments.model_error RUN_DIR [--steps H] [--starts N] [--recent N]

For halfcheetah, hopper and walker2d (their observation is the physics state without the x
position, so the true env can be put in an imagined state; hopper's and walker2d's clipped
velocities make that exact only below 10). Per seed and imagined step t, means over the
starts of:
- one-step errors (the true env stepped from the model's own state at t): observation error
  in units of the whole buffer's per-dimension std, absolute reward error (also of the elites'
  mean prediction, without the drawn member's sampled noise), how often the
  termination test disagrees;
- open-loop errors (the true env run from the same start through the same actions): the
  compounding observation and reward error;
- the "std push": the covariance of the one-step target r + gamma V(s') (the learner's reward
  units and critic) with (z^2 - 1) of the sampled action, z its distance from the policy's
  mean in stds. A log std's policy gradient follows its sign: from the model's prediction
  and from the true env, side by side, it says whether imagined targets push the policy's
  spread down where real ones would not;
- the critic at the cut, open loop: V at the model's state against V at the true state
  reached through the same actions, and the t-step return of a branch's first row (rewards
  to t, then the critic; stopped at a termination) from the model and from the true env,
  each beside its spread over the starts.
Writes model_error.json into RUN_DIR.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax
import jax.numpy as jnp

from experiments.paper.shadow import load_run
from ldn_jax.learning_degree import ensemble_mean
from ldn_jax.stages.imagine import world_of

TASKS = ("halfcheetah", "hopper", "walker2d")


def true_world(env, params):
    """`(key, obs [N, d], action [N, a]) -> (next_obs, reward, terminated)` of the true env
    put in the state each observation describes (`MujocoEnv.from_observation`, x position 0)."""

    def step(key, obs, action):
        states = jax.vmap(env.from_observation, (0, None))(obs, params)
        keys = jax.random.split(key, obs.shape[0])
        next_obs, _, reward, terminated, _, _ = jax.vmap(env.step, (0, 0, 0, None))(
            keys, states, action, params
        )
        return next_obs, reward, terminated

    return step


def reward_units(params):
    """The learner's reward units: 1 over the running return's std where it normalises
    rewards, else 1."""
    if "reward_norm" not in params:
        return 1.0
    return 1.0 / jnp.sqrt(params["reward_norm"]["var"][0] + 1e-8)


def seed_errors(trainer, state, key, steps: int, starts: int, recent: int) -> list[dict]:
    buffer = state.buffer
    size = int(buffer.size)
    low = max(0, size - recent)
    k_start, key = jax.random.split(key)
    obs = buffer.data.obs[jax.random.randint(k_start, (starts,), low, size)]
    # Units: each dimension's std over the whole buffer (the newest states alone can hold a
    # dimension nearly still once the policy is nearly deterministic).
    scale = jnp.std(buffer.data.obs[:size], axis=0) + 1e-6
    model = world_of(trainer.parts, state, jnp.float32(1.0))
    true = true_world(trainer.env, trainer.env_params)
    learner, live = trainer.learner, jnp.ones(starts, bool)
    imagined, real, rows = obs, obs, []
    gamma = trainer.config.agent.gamma
    # The t-step return each branch's first row learns from, sum_i gamma^i r_i + gamma^t V(s_t)
    # (stopped at a termination), accumulated along the model's branch and along the true
    # env's run through the same actions.
    m_sum, r_sum = jnp.zeros(starts), jnp.zeros(starts)
    m_alive, r_alive = jnp.ones(starts), jnp.ones(starts)
    for t in range(steps):
        key, k_act, k_other, k_model, k_env = jax.random.split(key, 5)
        params = state.learner.params
        raw = learner.act(params, k_act, imagined)
        action = learner.env_action(raw)
        centre, spread = learner.policy.mean_std(learner.logits(params, imagined))
        # (z^2 - 1) averaged over the action's dimensions: what a log std's gradient weighs
        # each row's advantage by (positive: the action was far from the mean).
        wide = jnp.mean(jnp.square((raw - centre) / spread), axis=-1) - 1.0
        m_obs, _, m_reward, m_term, _, _ = model(k_model, None, imagined, action, live)
        one_obs, one_reward, one_term = true(k_env, imagined, action)
        # The elites' mean prediction, without the drawn member's sampled noise.
        if trainer.dynamics.probabilistic:
            mean, _ = jax.vmap(trainer.dynamics.predict_gaussian, (0, None, None, None))(
                state.model.params, state.model.stats, imagined, trainer.model_action(action)
            )
            centre = ensemble_mean(mean[state.model.elites])
            e_obs, e_reward = trainer.dynamics.denormalize(
                state.model.stats, centre[..., :-1], centre[..., -1]
            )
        else:
            e_obs, e_reward = m_obs, m_reward
        # What the policy's own noise changes: the true reward of another sampled action.
        other = learner.env_action(learner.act(state.learner.params, k_other, imagined))
        _, other_reward, _ = true(k_env, imagined, other)
        real, real_reward, real_term = true(k_env, real, action)
        # One-step TD targets r + gamma V(s') in the learner's reward units, from the model's
        # prediction and from the true env, and how each covaries with `wide`.
        units = reward_units(params)
        discount = gamma**t
        m_sum = m_sum + m_alive * discount * units * m_reward
        r_sum = r_sum + r_alive * discount * units * real_reward
        m_alive, r_alive = m_alive * (1 - m_term), r_alive * (1 - real_term)
        m_value, r_value = learner.value(params, m_obs), learner.value(params, real)
        m_return = m_sum + m_alive * gamma ** (t + 1) * m_value
        r_return = r_sum + r_alive * gamma ** (t + 1) * r_value
        target_model = units * m_reward + gamma * m_value * (1 - m_term)
        target_true = units * one_reward + gamma * learner.value(params, one_obs) * (1 - one_term)
        covary = lambda x, w=wide: float(jnp.mean((x - jnp.mean(x)) * w))
        rows.append(
            {
                "step": t + 1,
                "std_push_model": covary(target_model),
                "std_push_true": covary(target_true),
                "obs_error": float(jnp.mean(jnp.abs(m_obs - one_obs) / scale)),
                "reward_error": float(jnp.mean(jnp.abs(m_reward - one_reward))),
                "reward_true": float(jnp.mean(one_reward)),
                "reward_spread": float(jnp.mean(jnp.abs(one_reward - other_reward))),
                "obs_error_elite_mean": float(jnp.mean(jnp.abs(e_obs - one_obs) / scale)),
                "reward_error_elite_mean": float(jnp.mean(jnp.abs(e_reward - one_reward))),
                "termination_disagrees": float(jnp.mean(m_term != one_term)),
                "terminated_true": float(jnp.mean(one_term)),
                "obs_error_open_loop": float(jnp.mean(jnp.abs(m_obs - real) / scale)),
                "reward_error_open_loop": float(jnp.mean(jnp.abs(m_reward - real_reward))),
                # The critic at the cut, open loop, in the learner's units: at the model's state
                # against at the true one, beside how much it varies over the starts.
                "value_error_open_loop": float(jnp.mean(jnp.abs(m_value - r_value))),
                "value_spread": float(jnp.std(r_value)),
                # The (t+1)-step return of the branch's first row, model against true env.
                "return_error_open_loop": float(jnp.mean(jnp.abs(m_return - r_return))),
                "return_spread": float(jnp.std(r_return)),
            }
        )
        imagined = m_obs
    return rows


def action_ranking(trainer, state, key, steps: int, starts: int, actions: int, recent: int) -> dict:
    """How well the model's branches tell the first action's worth apart, which is all a
    policy gradient takes from a branch's first row: from each start, `actions` first actions
    of the policy, each followed by `steps` - 1 more of the policy's on the model's states; the
    true env runs through the same actions. Per start, each branch's `steps`-step return
    (rewards, then the critic at the cut) is centred over its actions (an advantage); pooled
    over the starts:
    - `spread`: the true advantages' std, in the learner's units;
    - `reward_share`: the share of the true advantages' variance the rewards carry (the rest
      is the critic at the cut: what the branch learns from its own evidence, against what it
      takes on the critic's word), cov(rewards, G) / var(G);
    - `model_true_correlation`: of the model's advantages with the true ones (1: the model
      ranks actions as the world does);
    - `error`: the mean |model - true| advantage, beside `spread`."""
    buffer = state.buffer
    size = int(buffer.size)
    k_start, key = jax.random.split(key)
    picked = buffer.data.obs[jax.random.randint(k_start, (starts,), max(0, size - recent), size)]
    obs = jnp.repeat(picked, actions, axis=0)  # [starts * actions, d]: each start's copies
    rows = obs.shape[0]
    model = world_of(trainer.parts, state, jnp.float32(1.0))
    true = true_world(trainer.env, trainer.env_params)
    learner, params, live = trainer.learner, state.learner.params, jnp.ones(rows, bool)
    gamma = trainer.config.agent.gamma
    units = reward_units(params)
    imagined, real = obs, obs
    m_sum, r_sum = jnp.zeros(rows), jnp.zeros(rows)
    m_alive, r_alive = jnp.ones(rows), jnp.ones(rows)
    for t in range(steps):
        key, k_act, k_model, k_env = jax.random.split(key, 4)
        action = learner.env_action(learner.act(params, k_act, imagined))
        m_obs, _, m_reward, m_term, _, _ = model(k_model, None, imagined, action, live)
        real, r_reward, r_term = true(k_env, real, action)
        m_sum = m_sum + m_alive * gamma**t * units * m_reward
        r_sum = r_sum + r_alive * gamma**t * units * r_reward
        m_alive, r_alive = m_alive * (1 - m_term), r_alive * (1 - r_term)
        imagined = m_obs
    m_return = m_sum + m_alive * gamma**steps * learner.value(params, imagined)
    r_critic = r_alive * gamma**steps * learner.value(params, real)

    def centred(x):
        x = x.reshape(starts, actions)
        return x - jnp.mean(x, axis=1, keepdims=True)

    m_adv, g_adv, rewards = centred(m_return), centred(r_sum + r_critic), centred(r_sum)
    variance = jnp.mean(jnp.square(g_adv))
    return {
        "steps": steps,
        "actions": actions,
        "spread": float(jnp.sqrt(variance)),
        "reward_share": float(jnp.mean(rewards * g_adv) / variance),
        "model_true_correlation": float(
            jnp.mean(m_adv * g_adv) / jnp.sqrt(jnp.mean(jnp.square(m_adv)) * variance)
        ),
        "error": float(jnp.mean(jnp.abs(m_adv - g_adv))),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--steps", type=int, default=5, help="imagined steps (default 5)")
    parser.add_argument("--starts", type=int, default=512, help="branches per seed")
    parser.add_argument("--recent", type=int, default=20_000, help="draw from the newest N")
    parser.add_argument(
        "--actions", type=int, default=16, help="first actions per start in the ranking test"
    )
    args = parser.parse_args(argv)
    config, trainer, states = load_run(args.run)
    if config.env not in TASKS or not config.algorithm.uses_model:
        print(f"a model-based run on one of {', '.join(TASKS)} is needed", file=sys.stderr)
        return 2
    seeds, ranking = [], []
    for index in range(config.seeds):
        seed = config.first_seed + index
        state = jax.tree.map(lambda x, i=index: x[0, i], states)
        rows = seed_errors(
            trainer, state, jax.random.key(seed), args.steps, args.starts, args.recent
        )
        seeds.append(rows)
        first, last = rows[0], rows[-1]
        print(
            f"seed {seed}: std push at step 1, model {first['std_push_model']:+.4f}, true "
            f"{first['std_push_true']:+.4f}",
            flush=True,
        )
        print(
            f"seed {seed}: step 1 obs {first['obs_error']:.3f} sd, reward "
            f"{first['reward_error']:.3f} of {first['reward_true']:.2f} (another action: "
            f"{first['reward_spread']:.3f}; the elites' mean: obs "
            f"{first['obs_error_elite_mean']:.3f} sd, reward "
            f"{first['reward_error_elite_mean']:.3f}); step {last['step']} "
            f"open loop obs {last['obs_error_open_loop']:.3f} sd, reward "
            f"{last['reward_error_open_loop']:.3f}; termination disagrees "
            f"{max(r['termination_disagrees'] for r in rows):.3f}",
            flush=True,
        )
        print(
            f"seed {seed}: step {last['step']} open loop, learner's units: critic at the cut "
            f"off by {last['value_error_open_loop']:.3f} (its spread over starts "
            f"{last['value_spread']:.3f}); the {last['step']}-step return off by "
            f"{last['return_error_open_loop']:.3f} (spread {last['return_spread']:.3f})",
            flush=True,
        )
        ranks = action_ranking(
            trainer,
            state,
            jax.random.key(1000 + seed),
            args.steps,
            args.starts // 2,
            args.actions,
            args.recent,
        )
        ranking.append(ranks)
        print(
            f"seed {seed}: first actions' {args.steps}-step advantages over {args.actions} "
            f"actions per start: spread {ranks['spread']:.3f}, rewards' share "
            f"{ranks['reward_share']:.2f}, model against true: correlation "
            f"{ranks['model_true_correlation']:.2f}, error {ranks['error']:.3f}",
            flush=True,
        )
    record = {
        "env": config.env,
        "algo": config.algo,
        **vars(args),
        "first_seed": config.first_seed,
        "seeds": seeds,
    }
    record["action_ranking"] = ranking
    record["run"] = str(args.run)
    (args.run / "model_error.json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {args.run / 'model_error.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
