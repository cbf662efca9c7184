"""Where a training iteration's time goes, and the ceiling it is measured against.

`ceiling`: a minimal synchronous A2C on the JAX CartPole (the paper's nets and constants,
auto-reset workers, 10-step segments, one RMSProp step each, no masking, no metrics): what
these cores do when no worker ever waits for another.

`stages`: our trainer's iteration cut into its stages (real episodes with their updates, the
model fit, imagination, and what is left: metrics, moving return, non-finite guard), each
jitted and timed apart on the same vmapped states, with the share of computed steps that were
masked (a worker whose episode had ended, stepping on until the batch's longest ends).
"""

from __future__ import annotations

import math
import time

import jax
import jax.numpy as jnp
import optax

from ldn_jax import envs
from ldn_jax.config import AgentConfig, from_preset
from ldn_jax.learners.a2c import n_step_targets
from ldn_jax.networks import MLP
from ldn_jax.prng import written_out
from ldn_jax.trainer import Trainer

Array = jax.Array

ALGOS = ("a2c", "a2c-model", "ldn", "ppo", "ppo-model", "ppo-ldn")
"""The six algorithms the bench trains (the CLI's names, less the alias a2c-ldn)."""


def _best_seconds(fn, *args, repeats: int = 3) -> float:
    """Fastest of `repeats` calls after one warm-up call (the compile)."""
    jax.block_until_ready(fn(*args))
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - start)
    return best


def minimal_a2c(seeds: int, workers: int, segments: int, env_name: str = "cartpole-v1"):
    """`train(key) -> (a checksum of the final nets [S], episodes ended per segment [S, N])`:
    `segments` x n_steps x `workers` env steps
    per seed, vmapped over `seeds`. Written apart from the trainer on purpose: it is the
    yardstick, so it shares only the env, the network module and the n-step targets."""
    cfg = AgentConfig()
    env, params = envs.make(env_name)
    n_actions = env.action_spec(params).size
    actor = MLP(cfg.actor_hidden, n_actions, cfg.activation, cfg.init_std)
    critic = MLP(cfg.critic_hidden, 1, cfg.activation, cfg.init_std)
    rmsprop = lambda lr: optax.rmsprop(
        lr, decay=cfg.rmsprop_decay, eps=cfg.rmsprop_eps, initial_scale=1.0
    )
    optimizer = optax.multi_transform(
        {"actor": rmsprop(cfg.actor_lr), "critic": rmsprop(cfg.critic_lr)},
        {"actor": "actor", "critic": "critic"},
    )
    reset = jax.vmap(env.reset, (0, None))
    step = jax.vmap(env.step, (0, 0, 0, None))
    obs_size = env.observation_size(params)

    def loss(net, obs, action, reward, next_obs, terminated):
        value = critic.apply(net["critic"], obs)[..., 0]
        next_value = jax.lax.stop_gradient(critic.apply(net["critic"], next_obs)[..., 0])
        targets = n_step_targets(reward, next_value, terminated, terminated, cfg.gamma)
        advantage = targets - value
        log_probs = jax.nn.log_softmax(actor.apply(net["actor"], obs))
        log_prob = jnp.take_along_axis(log_probs, action[..., None], -1)[..., 0]
        entropy = -(jnp.exp(log_probs) * log_probs).sum(-1)
        policy = -(log_prob * jax.lax.stop_gradient(advantage)).mean()
        return policy - cfg.entropy_beta * entropy.mean() + jnp.square(advantage).mean()

    def env_step(carry, key):
        net, obs, state = carry
        k_act, k_step, k_reset = jax.random.split(key, 3)
        action = jax.random.categorical(k_act, actor.apply(net["actor"], obs))
        next_obs, state, reward, terminated, truncated, _ = step(
            jax.random.split(k_step, workers), state, action, params
        )
        fresh_obs, fresh = reset(jax.random.split(k_reset, workers), params)
        done = terminated | truncated
        pick = lambda new, old: jnp.where(done.reshape((-1,) + (1,) * (new.ndim - 1)), new, old)
        carry = (net, pick(fresh_obs, next_obs), jax.tree.map(pick, fresh, state))
        return carry, (obs, action, reward, next_obs, terminated.astype(jnp.float32))

    def segment(carry, key):
        net, opt_state, obs, state = carry
        (_, obs, state), batch = jax.lax.scan(
            env_step, (net, obs, state), jax.random.split(key, cfg.n_steps)
        )
        grads = jax.grad(loss)(net, *batch)
        updates, opt_state = optimizer.update(grads, opt_state, net)
        return (optax.apply_updates(net, updates), opt_state, obs, state), batch[4].sum()

    def train(key):
        k_actor, k_critic, k_reset, k_run = jax.random.split(key, 4)
        dummy = jnp.zeros((1, obs_size))
        net = {"actor": actor.init(k_actor, dummy), "critic": critic.init(k_critic, dummy)}
        obs, state = reset(jax.random.split(k_reset, workers), params)
        carry = (net, optimizer.init(net), obs, state)
        (net, *_), episodes = jax.lax.scan(segment, carry, jax.random.split(k_run, segments))
        # CartPole's reward is always 1, so a sum of rewards would let XLA drop the whole
        # loop: the episode count and the weights depend on every step.
        checksum = sum(leaf.sum() for leaf in jax.tree.leaves(net))
        return checksum, episodes

    return jax.jit(lambda key: jax.vmap(train)(jax.random.split(key, seeds)))


def ceiling(seeds: int = 10, workers: int = 8, segments: int = 1000) -> dict:
    """Env steps/s of `minimal_a2c` (best of 5 after its compile: it is every ratio's
    denominator, and on a shared machine 3 runs of 1.5 s were seen to miss by a third)."""
    start = time.perf_counter()
    train = minimal_a2c(seeds, workers, segments)
    jax.block_until_ready(train(jax.random.key(0)))
    compile_s = time.perf_counter() - start
    seconds = _best_seconds(train, jax.random.key(1), repeats=5)
    # The same program with threefry written out, as the trainer's programs lower it
    # (`ldn_jax.prng`); the ratios stay against the program as JAX lowers it.
    written_seconds = _best_seconds(written_out(train), jax.random.key(1), repeats=5)
    n_steps = AgentConfig().n_steps
    env_steps = seeds * workers * segments * n_steps
    _, episodes = train(jax.random.key(1))
    last = episodes[:, -max(segments // 10, 1) :]  # the last tenth of the run
    length = last.shape[1] * n_steps * workers / max(float(last.sum(axis=1).mean()), 1.0)
    return {
        "what": "minimal synchronous A2C, auto-reset workers, no masking (bench/stages.py)",
        "env": "cartpole-v1",
        "seeds": seeds,
        "workers": workers,
        "env_steps": env_steps,
        "compile_s": round(compile_s - seconds, 2),
        "train_s": round(seconds, 3),
        "env_steps_per_s": round(env_steps / seconds),
        "env_steps_per_s_threefry_written_out": round(env_steps / written_seconds),
        "mean_episode_length_last_tenth": round(length, 1),
    }


def ppo_update(seeds: int = 10, env_name: str = "cartpole-v1") -> dict:
    """What PPO's update alone costs, against the gradients it must compute.

    One rollout's rows per seed (`n_steps` x workers, the `paper` preset's PPO: 5 epochs x 5
    minibatches), vmapped over `seeds`: the seconds of `PPO.learn`, and of the bare
    gradient of PPO's loss over the same rows once per epoch (no optimiser, no shuffle, one
    minibatch of all rows). Their ratio says how much of the update is overhead; the rows
    over `learn`'s seconds are the env steps/s PPO could reach if its rollout cost nothing.
    """
    from ldn_jax.learners.ppo import PPO, Batch

    config = from_preset("paper", env=env_name, algo="ppo", seeds=seeds)
    cfg = config.agent
    env, params = envs.make(env_name)
    ppo = PPO(cfg, env.observation_size(params), env.action_spec(params), ppo=config.ppo)
    rows = cfg.n_steps * config.workers
    keys = jax.random.split(jax.random.key(0), 4)
    states = jax.vmap(ppo.init)(jax.random.split(keys[0], seeds))
    normal = lambda key, shape: jax.random.normal(key, (seeds, rows, *shape))
    batch = Batch(
        obs=normal(keys[1], (env.observation_size(params),)),
        action=jax.random.bernoulli(keys[2], 0.5, (seeds, rows)).astype(jnp.int32),
        log_prob=jnp.full((seeds, rows), -0.69),
        value=jnp.zeros((seeds, rows)),
        advantage=normal(keys[3], ()),
        target=normal(keys[1], ()),
        weight=jnp.ones((seeds, rows)),
    )
    shuffle = jax.random.split(keys[2], seeds)
    # Lowered as the trainer lowers its programs (`ldn_jax.prng`).
    learn = written_out(jax.jit(jax.vmap(ppo.learn)))
    learn = _best_seconds(learn, states, batch, shuffle, repeats=10)
    grad = jax.vmap(lambda s, b: jax.grad(ppo.loss, has_aux=True)(s.params, b)[0])
    grad = written_out(jax.jit(grad))
    gradients = _best_seconds(grad, states, batch, repeats=10) * config.ppo.epochs
    return {
        "what": f"PPO.learn on one rollout ({config.ppo.epochs} epochs x {config.ppo.minibatches} "
        f"minibatches of {rows} rows per seed), against its bare gradients",
        "seeds": seeds,
        "rows_per_seed": rows,
        "learn_s": round(learn, 5),
        "gradients_s": round(gradients, 5),
        "learn_over_gradients": round(learn / gradients, 2),
        "update_only_env_steps_per_s": round(seeds * rows / learn),
    }


def ratios_to_ceiling(rows: list[dict], ceiling_row: dict) -> list[dict]:
    """Each training row's real and real + imagined env steps/s over the ceiling's."""
    top = ceiling_row["env_steps_per_s"]
    return [
        {
            "algo": row["algo"],
            "schedule": row.get("schedule", "episodes"),
            "real_over_ceiling": round(row["env_steps_per_s"] / top, 3),
            "real_plus_imagined_over_ceiling": round(
                (row["env_steps_per_s"] + row["imagined_steps_per_s"]) / top, 3
            ),
        }
        for row in rows
    ]


def _masked_share(weight: Array, n_steps: int) -> tuple[float, int]:
    """Share of the steps a vmapped play computed that were masked, and the steps computed.

    `weight` is `[R, T', W]` for R vmapped runs. Under vmap the segment loop runs until the
    run with the most live segments is done, so every run computes that many segments.
    """
    runs, length, workers = weight.shape
    per_segment = weight.reshape(runs, length // n_steps, n_steps, workers).sum(axis=(2, 3))
    segments = int((per_segment > 0).sum(axis=1).max())
    computed = runs * segments * n_steps * workers
    return 1.0 - float(weight.sum()) / max(computed, 1), computed


def _prefix(trainer: Trainer, stages: int):
    """The first `stages` stages of `trainer.iteration` (1: real, 2: + model fit, 3: +
    imagination), with the keys the iteration splits; returns the state and one scalar, so
    that, as inside the iteration, nothing else has to be materialised."""

    def run(state, gain):
        _, k_real, k_model, k_imagine = jax.random.split(state.key, 4)
        state, real = trainer.real_stage(state, k_real)
        if stages >= 2:
            state, _ = trainer.model_stage(state, real, k_model)
        if stages >= 3:
            state, _ = trainer.imagine_stage(state, k_imagine, gain, real)
        return state, real.returns.sum()

    return run


def stages(algo: str, runs: int = 30, warm_episodes: int = 400, env: str = "cartpole-v1") -> dict:
    """Seconds per iteration of each stage for `runs` vmapped runs (10 seeds x 3 K where the
    algorithm uses K, else `runs` seeds), after `warm_episodes` episodes of training (so
    episodes have their mid-training lengths), and the masked share of each play.

    `seconds_up_to[stage]`: the iteration's stages up to and including it, compiled as one
    program that returns the state (timed apart, a stage would also pay for writing out what
    the iteration consumes inside). A stage's own seconds are the difference to the one
    before, bookkeeping the whole iteration's less the last stage's. XLA compiles each prefix
    on its own, so a difference can come out below zero: the real stage alone has measured
    slower than the whole model-free iteration."""
    uses_k = algo.endswith("ldn")
    k = (0.5, 1.0, 2.0) if uses_k else (1.0,)
    config = from_preset(
        "paper",
        env=env,
        algo=algo,
        seeds=runs // len(k),
        k=k,
        episodes=warm_episodes,
        workers=8,
        chunk_iterations=5,
    )
    trainer = Trainer(config)
    states, gains = trainer.init_batch(), trainer.k_values()
    chunk = trainer.batched_chunk()
    for _ in range(config.iterations // config.chunk_iterations):
        states, _ = chunk(states, gains)
    jax.block_until_ready(states)

    # Lowered as the trainer's chunk is (`ldn_jax.prng`).
    per_run = lambda fn: written_out(jax.jit(jax.vmap(jax.vmap(fn, (0, None)), (0, 0))))
    count = 3 if trainer.dynamics is not None else 1
    upto = [_best_seconds(per_run(_prefix(trainer, n)), states, gains) for n in range(1, count + 1)]
    whole = _best_seconds(per_run(trainer.iteration), states, gains)
    names = ("real", "model", "imagine")[:count]
    seconds = {name: upto[i] - (upto[i - 1] if i else 0.0) for i, name in enumerate(names)}
    seconds["bookkeeping"] = whole - upto[-1]

    # What each play computed: the same keys as the iteration's.
    split = jax.vmap(jax.vmap(lambda key: jax.random.split(key, 4)))
    _, k_real, k_model, k_imagine = jnp.moveaxis(split(states.key), -1, 0)
    stage = lambda fn: jax.jit(jax.vmap(jax.vmap(fn)))
    after_real, real = stage(trainer.real_stage)(states, k_real)
    episodes = real.episodes
    flat = lambda w: w.reshape((-1, *w.shape[2:]))
    n_steps = config.agent.n_steps
    share, computed = _masked_share(flat(episodes.steps.weight), n_steps)
    row = {
        "algo": algo,
        "runs": states.env_steps.size,
        "k_values": len(k),
        "after_episodes": warm_episodes,
        "real_mean_episode_length": round(float(episodes.steps.weight.sum(2).mean()), 1),
        "real_masked_share": round(share, 3),
        "real_steps_computed": computed,
    }
    if trainer.dynamics is not None:
        after_model, _ = stage(trainer.model_stage)(after_real, real, k_model)
        grid_gains = jnp.broadcast_to(gains[:, None], states.env_steps.shape)
        _, imagined = stage(trainer.imagine_stage)(after_model, k_imagine, grid_gains, real)
        share, computed = _masked_share(flat(imagined.steps.weight), n_steps)
        row["imagined_masked_share"] = round(share, 3)
        row["imagined_steps_computed"] = computed
        row["imagined_mean_episode_length"] = round(float(imagined.steps.weight.sum(2).mean()), 1)
    row["seconds_up_to"] = {name: round(v, 4) for name, v in zip(names, upto, strict=True)}
    row["seconds_up_to"]["iteration"] = round(whole, 4)
    row["seconds_per_stage"] = {name: round(v, 4) for name, v in seconds.items()}
    row["share_of_iteration"] = {name: round(v / whole, 3) for name, v in seconds.items()}
    return row


def branched_stages(
    env: str = "halfcheetah", algo: str = "ppo-ldn", seeds: int = 5, warm_iterations: int = 20
) -> dict:
    """The `branched` preset's iteration cut into its stages, as `stages` does for the
    paper's: real play with its updates, the model fit (a probabilistic ensemble), the
    branched imagination with its updates, and the bookkeeping; seconds per iteration of
    `seeds` vmapped seeds after `warm_iterations` iterations of training, and each stage's
    share, so that a 200k-step run's cost splits into play, fit, imagination and update."""
    config = from_preset("branched", env=env, algo=algo, seeds=seeds, steps=10**9)
    trainer = Trainer(config)
    states, gains = trainer.init_batch(), trainer.k_values()
    chunk = trainer.batched_chunk()
    for _ in range(warm_iterations):
        states, _ = chunk(states, gains)
    jax.block_until_ready(states)

    def prefix(stages: int):
        def run(state, gain):
            _, k_real, k_model, k_imagine = jax.random.split(state.key, 4)
            state, real = trainer.real_stage(state, k_real)
            if stages >= 2:
                state, _ = trainer.model_stage(state, real, k_model)
            if stages >= 3:
                state, _ = trainer.imagine_stage(state, k_imagine, gain, real)
            return state, real.episodes.returns.sum()

        return run

    per_run = lambda fn: written_out(jax.jit(jax.vmap(jax.vmap(fn, (0, None)), (0, 0))))
    upto = [_best_seconds(per_run(prefix(n)), states, gains) for n in (1, 2, 3)]
    whole = _best_seconds(per_run(trainer.iteration), states, gains)
    names = ("real play and update", "model fit", "imagination and update")
    seconds = {name: upto[i] - (upto[i - 1] if i else 0.0) for i, name in enumerate(names)}
    seconds["bookkeeping"] = whole - upto[-1]
    real_steps = config.steps_per_iteration * config.workers
    return {
        "what": f"the branched preset's {algo} on {env}, {seeds} seeds, one iteration",
        "real_steps_per_iteration": real_steps,
        "imagined_steps_per_iteration": int(
            math.ceil(
                config.imagine.ratio * real_steps / (config.imagine.branches * config.agent.n_steps)
            )
            * config.imagine.branches
            * config.agent.n_steps
        ),
        "seconds_per_iteration": round(whole, 4),
        "seconds_per_stage": {name: round(v, 4) for name, v in seconds.items()},
        "share_of_iteration": {name: round(v / whole, 3) for name, v in seconds.items()},
        "seconds_per_200k_steps": round(whole * 200_000 / real_steps, 1),
    }
