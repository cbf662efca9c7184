"""The training iteration (Algorithm 1, synchronous reading) and its compiled chunks.

One iteration, per seed and K, composes the stages `ldn_jax.stages.pick` chose for the config
when the trainer was built:
1. real play: each of W workers plays one real episode, the learner updating every n steps
   (schedule "episodes"; under "steps" each plays `iteration_steps` steps instead, its
   episodes carrying over between iterations);
2. the model's fit: M1 takes `fit.updates` minibatch steps on the real buffer;
3. imagination: each worker plays one episode in M1 from a fresh initial state; or, with
   `imagine.start = "real"` (ours), many short branches in M1 from states of the real
   buffer, the learner updating on full batches of them.
`a2c` runs stage 1 only; `a2c-model` runs all three without the LD stop; `ldn` with it.
The PPO family (`ppo`, `ppo-model`, `ppo-ldn`) is the same with PPO as the learner. The
failure guard (`stages.guard`) freezes a run whose numbers went non-finite.
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
from jax.sharding import Mesh

from ldn_jax.buffer import buffer_init
from ldn_jax.config import Config, with_values
from ldn_jax.learning_degree import ld_histogram
from ldn_jax.prng import written_out
from ldn_jax.rollout import workers_init
from ldn_jax.sharding import compiler_options, shard_seeds
from ldn_jax.stages import Parts, RealPlay, TrainState, guard, pick
from ldn_jax.stages.guard import FAILURES, failure_names
from ldn_jax.stages.model import fit as fit_model

__all__ = ["FAILURES", "TrainState", "Trainer", "failure_names"]

Array = jax.Array

GREEDY_STREAM = 0x9E37
"""`jax.random.fold_in` data of the greedy evaluations after each chunk
(`Config.solved_return`): a branch off the run's key that its training never draws."""


class Trainer:
    """Builds the pure training functions for one config; holds no training state."""

    def __init__(self, config: Config, parts: Parts | None = None):
        self.parts = parts or Parts.build(config)
        self.stages = pick(config)
        self._jitted: dict = {}  # (program, mesh, bitwise) -> the jitted function, made once

    # The built pieces, by the names the host wing and the tests read.
    config = property(lambda self: self.parts.config)
    learner = property(lambda self: self.parts.learner)
    dynamics = property(lambda self: self.parts.dynamics)
    model_action = property(lambda self: self.parts.model_action)
    model_action_size = property(lambda self: self.parts.model_action_size)
    env = property(lambda self: self.parts.real.env)
    env_params = property(lambda self: self.parts.real.params)
    obs_size = property(lambda self: self.parts.real.obs_size)
    action_spec = property(lambda self: self.parts.real.action_spec)
    max_steps = property(lambda self: self.parts.real.max_steps)

    def at(self, values: dict[str, Array]) -> Trainer:
        """This trainer with the float fields `values` (dotted names: a sweep point's
        values, traced inside the compiled program) set; itself where there are none. The
        learner and the model are rebuilt on the new values; the env is shared."""
        if not values:
            return self
        other = copy.copy(self)
        other.parts = Parts.build(with_values(self.config, values), self.parts.real)
        return other

    def init_state(self, key: Array) -> TrainState:
        key, k_learner, k_model = jax.random.split(key, 3)
        config, model, buffer, memory = self.config, None, None, None
        if self.dynamics is not None:
            model = self.dynamics.init(k_model)
            buffer = buffer_init(
                config.model.buffer_capacity,
                self.obs_size,
                self.model_action_size,
                terminated=config.imagine.termination == "learned",
            )
            if config.imagine.mode == "memory" and config.imagine.start != "real":
                memory = self.learner.memory_init(config.workers)
        workers = None
        if config.schedule == "steps":  # a key of its own: the other draws stay as they are
            workers = workers_init(*self.parts.real.reset(jax.random.fold_in(key, 1)))
        zero = jnp.zeros((), jnp.int32)
        return TrainState(
            learner=self.learner.init(k_learner),
            model=model,
            buffer=buffer,
            memory=memory,
            workers=workers,
            moving_return=jnp.full((), jnp.nan, jnp.float32),
            episodes=zero,
            env_steps=zero,
            imagined_steps=zero,
            iteration=zero,
            key=key,
            failure=zero,
            failed_iteration=zero,
            greedy_return=None if config.solved_return is None else jnp.float32(jnp.nan),
        )

    # -- the stages, bound to this trainer's parts ----------------------------------------

    def real_stage(self, state: TrainState, key: Array) -> tuple[TrainState, RealPlay]:
        return self.stages.real(self.parts, state, key)

    def model_stage(self, state: TrainState, real: RealPlay, key: Array):
        return fit_model(self.parts, state, real.episodes, key)

    def imagine_stage(self, state: TrainState, key: Array, gain: Array, real: RealPlay):
        return self.stages.imagine(self.parts, state, key, gain, real)

    # -- one iteration and a chunk of them -------------------------------------------------

    def iteration(self, state: TrainState, gain: Array) -> tuple[TrainState, dict]:
        """One iteration of Algorithm 1 for every worker; returns per-iteration metrics.

        If the iteration makes any checked quantity non-finite, the run keeps its previous
        state from then on (frozen) and `failure` says what diverged; other vmapped runs go on.
        """
        new, metrics = self._iteration(state, gain)
        spent = self.spent(state)  # its budget was reached: this iteration does not count
        state, metrics = guard.guarded(state, new, metrics, spent)
        metrics.update(
            moving_return=state.moving_return,
            episodes=state.episodes,
            env_steps=state.env_steps,
            imagined_steps=state.imagined_steps,
            iteration=state.iteration,
            failure=state.failure,
        )
        return state, metrics

    def spent(self, state: TrainState) -> Array:
        """Whether a run has reached its `config.steps` budget, or under schedule "steps"
        its `config.episodes` (schedule "episodes" without a steps budget: never, the
        iteration count is the budget), or its greedy policy has solved the task
        (`config.solved_return`)."""
        if self.config.steps is not None:
            spent = state.env_steps >= self.config.steps
        elif self.config.schedule == "steps":
            spent = state.episodes >= self.config.episodes
        else:
            spent = jnp.zeros((), bool)
        return spent | self.solved(state)

    def solved(self, state: TrainState) -> Array:
        """Whether a run's latest greedy evaluation reached `config.solved_return`."""
        if self.config.solved_return is None:
            return jnp.zeros((), bool)
        return state.greedy_return >= self.config.solved_return

    def _iteration(self, state: TrainState, gain: Array) -> tuple[TrainState, dict]:
        key, k_real, k_model, k_imagine = jax.random.split(state.key, 4)
        state, real = self.real_stage(state, k_real)
        decay = self.config.moving_decay

        def advance(m, episode):
            r, valid = episode
            new = jnp.where(jnp.isnan(m), r, decay * m + (1.0 - decay) * r)
            m = jnp.where(valid, new, m)
            return m, m

        moving, moving_after = jax.lax.scan(
            advance, state.moving_return, (real.returns, real.ended)
        )
        metrics = {
            "episode_return": real.episode_return,
            "returns": real.returns,
            "lengths": real.lengths,
            "moving_after": moving_after,
            **real.extra,
            **{f"real_{name}": value for name, value in real.episodes.losses.items()},
        }
        imagined_steps = jnp.zeros((), jnp.int32)
        if self.stages.imagine is not None:
            state, fitted = self.model_stage(state, real, k_model)
            metrics.update(fitted)
            state, imagined_steps = self._imagine(state, k_imagine, gain, real, metrics)
        state = state.replace(
            moving_return=moving,
            episodes=state.episodes + real.count,
            env_steps=state.env_steps + real.episodes.lengths.sum(),
            imagined_steps=state.imagined_steps + imagined_steps,
            iteration=state.iteration + 1,
            key=key,
        )
        return state, metrics

    def _imagine(
        self, state: TrainState, key: Array, gain: Array, real: RealPlay, metrics: dict
    ) -> tuple[TrainState, Array]:
        """The imagination stage, its metrics into `metrics`; the steps it imagined."""
        state, imagined = self.imagine_stage(state, key, gain, real)
        weight = imagined.steps.weight
        ld = imagined.extras["ld"]
        metrics["ld_mean"] = (ld * weight).sum() / weight.sum()
        metrics["ld_histogram"] = ld_histogram(ld, weight)  # Figure 5's data
        if "outside" in imagined.extras:  # share of imagined episodes that left the box
            outside = (imagined.extras["outside"] * weight).sum()
            metrics["imagined_outside"] = outside / jnp.maximum(imagined.ended.sum(), 1.0)
        length, total = imagined.mean_episode()
        metrics["imagined_length"], metrics["imagined_return"] = length, total
        metrics.update({f"imagined_{n}": v for n, v in imagined.losses.items()})
        return state, weight.sum().astype(jnp.int32)

    def train_chunk(self, state: TrainState, point) -> tuple[TrainState, dict]:
        """`config.chunk_iterations` iterations; metrics stacked `[N, ...]`. `point` is this
        run's learning-degree gain K (eq. 6), or in a sweep `{"k": K, field: value, ...}`."""
        trainer, gain = self._at_point(point)
        state, metrics = jax.lax.scan(
            lambda s, _: trainer.iteration(s, gain), state, length=self.config.chunk_iterations
        )
        if self.config.solved_return is not None:
            state, metrics = trainer._judge(state, metrics)
        return state, metrics

    def _judge(self, state: TrainState, metrics: dict) -> tuple[TrainState, dict]:
        """The greedy evaluation after a chunk (`config.solved_return`), logged as the
        chunk's last `greedy_return` (NaN before). Its keys branch off the run's own
        without drawing from them; a stopped run, frozen, scores the same again."""
        score = self.evaluate(state, jax.random.fold_in(state.key, GREEDY_STREAM))
        last = jnp.arange(self.config.chunk_iterations) == self.config.chunk_iterations - 1
        metrics["greedy_return"] = jnp.where(last, score, jnp.nan)
        return state.replace(greedy_return=score), metrics

    def _at_point(self, point) -> tuple[Trainer, Array]:
        if not isinstance(point, dict):
            return self, point
        return self.at({n: v for n, v in point.items() if n != "k"}), point["k"]

    def evaluate(self, state: TrainState, key: Array) -> Array:
        """Mean return of the greedy policy over `config.eval_episodes` real episodes."""
        act = lambda obs: self.learner.greedy(state.learner.params, obs)
        return self.parts.real.evaluate(act, key, self.config.eval_episodes)

    # -- seeds x K -------------------------------------------------------------------------

    def init_batch(self) -> TrainState:
        """States `[P, S]` (P: `config.points`, the K values without a sweep): seed s gets
        key s at every point (common random numbers). In a sweep each point starts from
        its own values (an optimiser state may hold its learning rate).

        Jitted, one program instead of some hundred eager ops (seconds per process on CPU):
        the same values to the bit (`networks.normal_init`). Its draws lower threefry written
        out (`prng.written_out`): XLA compiles it in about half the time where the nets are
        many (SAC's five, an ensemble's members), and every leaf of the states came out the
        same to the bit both ways (2026-12-07: sac, sac-model, ppo, ppo-ldn, ldn, a2c, a
        sweep, the `fast` preset)."""
        return written_out(jax.jit(self._init_batch))()

    def _init_batch(self) -> TrainState:
        first = self.config.first_seed
        keys = jax.vmap(jax.random.key)(jnp.arange(first, first + self.config.seeds))
        if self.config.sweep:
            init = lambda point: jax.vmap(self._at_point(point)[0].init_state)(keys)
            return jax.vmap(init)(self.point_values())
        states = jax.vmap(self.init_state)(keys)
        n_k = len(self.config.k)
        return jax.tree.map(lambda x: jnp.broadcast_to(x, (n_k, *x.shape)), states)

    def k_values(self) -> Array:
        """The gain K of each point, `[P]` (`config.k` without a sweep)."""
        return jnp.asarray([p["k"] for p in self.config.points], jnp.float32)

    def point_values(self):
        """The second argument of `batched_chunk`: `k_values()` without a sweep; in a sweep
        `{"k": [P], field: [P], ...}`, each point's K and values."""
        if not self.config.sweep:
            return self.k_values()
        points = self.config.points
        return {name: jnp.asarray([p[name] for p in points], jnp.float32) for name in points[0]}

    def batched_chunk(self, mesh: Mesh | None = None, bitwise: bool = False):
        """`(states [P, S], point_values()) -> (states, metrics [P, S, N, ...])`, jitted (P:
        the points, the K values without a sweep).

        With a mesh, each of its devices runs its block of seeds (`ldn_jax.sharding`);
        states must then be placed with `sharding.place` and k with `sharding.replicate`.
        `bitwise`: compiled so that the metrics do not depend on how the seeds are split
        (`sharding.BITWISE_COMPILER_OPTIONS`; a device with one seed computes it twice).
        Made once per trainer, mesh and `bitwise`: a second call reuses its compiled programs.
        """
        if ("chunk", mesh, bitwise) not in self._jitted:
            per_seed = jax.vmap(self.train_chunk, in_axes=(0, None))
            chunk = jax.vmap(per_seed, in_axes=(0, 0))
            self._jitted["chunk", mesh, bitwise] = _jit_seeds(
                chunk, mesh, bitwise, donate_argnums=0
            )
        return self._jitted["chunk", mesh, bitwise]

    def batched_evaluate(self, mesh: Mesh | None = None, bitwise: bool = False):
        """`(states [K, S], key) -> eval returns [K, S]`, jitted (seeds split as above)."""
        if ("evaluate", mesh, bitwise) not in self._jitted:
            per_seed = jax.vmap(self.evaluate, in_axes=(0, None))
            evaluate = jax.vmap(per_seed, in_axes=(0, None))
            self._jitted["evaluate", mesh, bitwise] = _jit_seeds(evaluate, mesh, bitwise)
        return self._jitted["evaluate", mesh, bitwise]


def _jit_seeds(fn, mesh: Mesh | None, bitwise: bool, **jit_kwargs):
    """`fn` jitted on one device, or split over the mesh's devices, with the XLA options
    of `sharding.compiler_options`; its programs lower threefry written out on CPU
    (`prng.written_out`)."""
    sharded = fn if mesh is None else shard_seeds(fn, mesh, bitwise)
    jitted = jax.jit(sharded, compiler_options=compiler_options(mesh, bitwise), **jit_kwargs)
    return written_out(jitted)  # threefry without its loop on CPU, the same draws (`prng`)
