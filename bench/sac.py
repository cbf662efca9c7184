"""`make bench` section `sac`: what one SAC update costs, bare and inside the trainer.

- `probe`: one jitted `SAC.update` (256 x 256 nets, batch 256: MBPO's and SBX's sizes) on a
  batch already in memory, vmapped over the seeds: the floor of any implementation here.
- `learn`: `SAC.learn`, `updates` of them in one `lax.scan`, each drawing its batch from a
  filled replay memory (`SACLearner`'s way): what the scan and the draw add to the floor.
- `trainer`: a whole `sac` run on the task through the trainer (real steps on the native
  engine, replay memory, UTD 1), its training seconds per real step and per update: the
  target is within 1.5x of the probe's.

The projections multiply out: 200k real steps at a UTD of 20 are 4M updates per seed.
"""

from __future__ import annotations

import tempfile
import time

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

    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        summary = train(config, out, quiet=True)
        wall = time.perf_counter() - start
    per_step = summary["train_seconds"] / steps
    return {
        "what": f"one SAC update of {config.sac.hidden}x{config.sac.hidden} nets at batch "
        f"{size}, vmapped over {seeds} seeds: bare, in a scan of {updates}, and in a "
        f"{steps}-step {env_name} run at UTD {config.sac.utd}",
        "seeds": seeds,
        "probe_ms_per_update": round(1e3 * probe, 3),
        "scan_ms_per_update": round(1e3 * scanned, 3),
        "trainer_ms_per_real_step": round(1e3 * per_step, 3),
        "trainer_over_probe": round(per_step / (config.sac.utd * probe), 2),
        "trainer_compile_s": summary["compile_seconds"],
        "trainer_wall_s": round(wall, 1),
        "projected_hours_200k_utd20": round(200_000 * 20 * probe / 3600, 2),
        "projected_hours_100k_utd20": round(100_000 * 20 * probe / 3600, 2),
    }
