"""`make bench` section `sac`: what one SAC update costs, bare and inside the trainer.

- `probe`: one jitted `SAC.update` (256 x 256 nets, batch 256: MBPO's and SBX's sizes) on a
  batch already in memory, vmapped over the seeds: the floor of any implementation here.
- `learn`: `SAC.learn`, `updates` of them in one `lax.scan`, each drawing its batch from a
  filled replay memory (`SACLearner`'s way): what the scan and the draw add to the floor.
- `trainer`: whole `sac` runs on the task through the trainer (real steps on the native
  engine, replay memory) at UTD 1 and at UTD 4, updates from the first full batch on: their
  difference is what one more update costs inside the trainer (the target: within 1.5x of
  the probe), the rest what one real step costs around its updates (acting, the engine, the
  replay memory).

- `mbpo_fit`: MBPO's model fit as `sac-model` and `sac-ldn` run it (`--preset branched`:
  five 3 x 200 swish members, batch 256, fitted every 250 real steps until the held-out
  error stalls): one minibatch step of all members, timed on a filled buffer, and what the
  fits of a 100k-step run cost at the fewest epochs early stopping allows (patience 5: six
  epochs per fit), each epoch one pass over R's training slots: a floor, as the first fits
  take more.

The projections multiply out: 200k real steps at a UTD of 20 are 4M updates per seed, and
200k real steps.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile

import jax
import jax.numpy as jnp

from bench.stages import _best_seconds
from ldn_jax import envs
from ldn_jax.config import from_preset
from ldn_jax.host.training import train
from ldn_jax.learners.sac import SACLearner, SACState, Transitions
from ldn_jax.prng import written_out


def _batch(key, seeds: int, rows: int, obs: int, actions: int) -> Transitions:
    k = jax.random.split(key, 4)
    return Transitions(
        obs=jax.random.normal(k[0], (seeds, rows, obs)),
        action=jax.random.uniform(k[1], (seeds, rows, actions), minval=-1, maxval=1),
        reward=jax.random.normal(k[2], (seeds, rows)),
        next_obs=jax.random.normal(k[3], (seeds, rows, obs)),
        terminated=jnp.zeros((seeds, rows)),
    )


def sac_costs(seeds: int = 5, env_name: str = "halfcheetah", steps: int = 3000) -> dict:
    """The probe, the scan and the trainer for `seeds` vmapped seeds on `env_name`."""
    config = from_preset("paper", env=env_name, algo="sac", seeds=seeds, steps=steps)
    env, params = envs.make(env_name)
    learner = SACLearner.of(config, env.observation_size(params), env.action_spec(params))
    sac, obs, actions = learner.sac, learner.obs_size, learner.policy.size
    keys = jax.random.split(jax.random.key(0), seeds)
    runs = jax.vmap(learner.init)(keys)
    states = SACState(runs.params, runs.opt_state)
    size = config.sac.batch_size
    batch = _batch(jax.random.key(1), seeds, size, obs, actions)
    update = written_out(jax.jit(jax.vmap(sac.update)))
    probe = _best_seconds(update, states, batch, keys, repeats=20)

    updates = 200
    memory = _batch(jax.random.key(2), seeds, 10_000, obs, actions)

    def learn(state, memory, key):
        draw = lambda k: jax.tree.map(
            lambda x: x[jax.random.randint(k, (size,), 0, 10_000)], memory
        )
        return sac.learn(state, draw, key, updates)

    scan = written_out(jax.jit(jax.vmap(learn)))
    scanned = _best_seconds(scan, states, memory, keys, repeats=3) / updates

    seconds = {utd: _trainer_seconds(config, utd) for utd in (1, HIGH_UTD)}
    updating = steps - size  # the first update waits for one batch of rows
    per_update = (seconds[HIGH_UTD][0] - seconds[1][0]) / ((HIGH_UTD - 1) * updating)
    per_step = seconds[1][0] / steps - per_update * updating / steps
    project = lambda real, utd: round(real * (per_step + utd * per_update) / 3600, 2)
    return {
        "what": f"one SAC update of {config.sac.hidden}x{config.sac.hidden} nets at batch "
        f"{size}, vmapped over {seeds} seeds: bare, in a scan of {updates}, and in "
        f"{steps}-step {env_name} runs at UTD 1 and {HIGH_UTD}",
        "seeds": seeds,
        "probe_ms_per_update": round(1e3 * probe, 3),
        "scan_ms_per_update": round(1e3 * scanned, 3),
        "trainer_ms_per_update": round(1e3 * per_update, 3),
        "trainer_ms_per_real_step_besides_updates": round(1e3 * per_step, 3),
        "trainer_over_probe": round(per_update / probe, 2),
        "trainer_train_s": {f"utd{u}": round(t, 1) for u, (t, _) in seconds.items()},
        "trainer_compile_s": {f"utd{u}": round(c, 1) for u, (_, c) in seconds.items()},
        "projected_hours_200k_utd20": project(200_000, 20),
        "projected_hours_100k_utd20": project(100_000, 20),
        "mbpo_fit": mbpo_fit_costs(seeds, env_name),
    }


def mbpo_fit_costs(seeds: int, env_name: str, rows: int = 20_000) -> dict:
    """One minibatch step of the branched preset's ensemble (all members), vmapped over
    `seeds`, on a buffer of `rows`; and the fits of a 100k-step `sac-model` run at six
    epochs per fit, one every `iteration_steps` real steps, each epoch a pass over the
    buffer's training slots as it then stands."""
    from ldn_jax.buffer import HOLDOUT_EVERY, buffer_add, buffer_init
    from ldn_jax.buffer import Transitions as Rows
    from ldn_jax.dynamics import Dynamics, EarlyStop

    config = from_preset("branched", env=env_name, algo="sac-model", seeds=seeds)
    env, params = envs.make(env_name)
    obs, actions = env.observation_size(params), env.action_spec(params).size
    dynamics = Dynamics(config.model, obs, actions, fit=config.fit)
    keys = jax.random.split(jax.random.key(0), seeds)
    states = jax.vmap(dynamics.init)(keys)
    data = _batch(jax.random.key(1), 1, rows, obs, actions)
    memory = Rows(data.obs[0], data.action[0], data.next_obs[0], data.reward[0])
    buffer = buffer_add(buffer_init(rows, obs, actions), memory, jnp.ones(rows, bool))
    steps, members = 50, config.model.ensemble

    def epoch(state, key):
        fit = jax.vmap(dynamics._pass, (0, 0, None, None, 0, None))
        keys = jax.random.split(key, members)
        return fit(state.params, state.opt_state, state.stats, buffer, keys, steps)

    timed = jax.jit(jax.vmap(epoch))
    step_s = _best_seconds(timed, states, keys, repeats=3) / steps
    every, real = config.iteration_steps, 100_000
    epochs = EarlyStop().patience + 2  # the first epoch gains, then patience + 1 without
    batches = lambda r: math.ceil(max(1.0, r * (1 - 1 / HOLDOUT_EVERY) / config.fit.batch_size))
    fits = [batches(every * i) for i in range(1, real // every + 1)]
    fit_steps = sum(epochs * b for b in fits)
    cap = config.fit.updates  # under early_stop: a fit ends at the first epoch past it
    capped = sum(math.ceil(cap / b) * b for b in fits) if cap else fit_steps
    return {
        "what": f"{members} members of {config.model.hidden_layers} x {config.model.hidden} "
        f"{config.model.activation} units at batch {config.fit.batch_size}, vmapped over "
        f"{seeds} seeds; fits every {every} real steps: uncapped, {epochs} epochs each (MBPO's "
        f"least; runs here took 14-100), and capped at {cap} steps (every fit at its cap)",
        "ms_per_step_all_members": round(1e3 * step_s, 3),
        "fit_steps_100k": round(fit_steps),
        "projected_fit_hours_100k_at_least": round(fit_steps * step_s / 3600, 2),
        "fit_steps_100k_capped_at_most": round(capped),
        "projected_fit_hours_100k_capped_at_most": round(capped * step_s / 3600, 2),
    }


HIGH_UTD = 4


def _trainer_seconds(config, utd: int) -> tuple[float, float]:
    """(training, compile) seconds of `config` at `utd`, its updates from the first batch and
    its policy acting from the first step."""
    sac = dataclasses.replace(
        config.sac, utd=utd, learning_starts=config.sac.batch_size, random_steps=0
    )
    with tempfile.TemporaryDirectory() as out:
        summary = train(dataclasses.replace(config, sac=sac), out, quiet=True)
    return summary["train_seconds"], summary["compile_seconds"]
