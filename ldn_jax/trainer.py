"""The training iteration (Algorithm 1, synchronous reading) and its compiled chunks.

One iteration, per seed and K:
1. `real_stage`: each of W workers plays one real episode; the learner updates every n steps
   (schedule "episodes"; under "steps" each plays `iteration_steps` steps instead, its
   episodes carrying over between iterations).
2. `model_stage`: M1 takes `model.updates` minibatch steps on the real buffer.
3. `imagine_stage`: each worker plays one episode in M1 from a fresh initial state; or, with
   `model.imagine_start = "real"` (ours), `branch_stage`: many short rollouts in M1 from
   states of the real buffer, the learner updating on full batches of them.
`a2c` runs stage 1 only; `a2c-model` runs all three without the LD stop; `ldn` with it.
The PPO family (`ppo`, `ppo-model`, `ppo-ldn`) is the same with PPO as the learner.
"""

from __future__ import annotations

import copy
import math

import jax
import jax.numpy as jnp
from flax import struct
from jax.sharding import Mesh

from ldn_jax import envs
from ldn_jax.buffer import Buffer, Transitions, buffer_add, buffer_init, buffer_sample_recent
from ldn_jax.config import Config, with_values
from ldn_jax.dynamics import Dynamics, ModelState, action_encoder
from ldn_jax.imagination import (
    first_step_statistic,
    imagined_steps_limit,
    ld_history,
    macura_threshold,
    model_world,
    scheduled_horizon,
    stop_rule,
)
from ldn_jax.learners import LEARNERS
from ldn_jax.learners.base import LearnerState, Segment
from ldn_jax.learners.ppo import Memory
from ldn_jax.learning_degree import ld_histogram
from ldn_jax.prng import written_out
from ldn_jax.rollout import (
    Completed,
    Episodes,
    Player,
    Workers,
    play_batch,
    play_episodes,
    play_steps,
    workers_init,
)
from ldn_jax.sharding import compiler_options, shard_seeds

Array = jax.Array


@struct.dataclass
class TrainState:
    """Everything one seed x K run carries from one iteration to the next."""

    learner: LearnerState
    model: ModelState | None
    """M1, frozen M0 and M1's optimiser (each `[E, ...]` for an ensemble); None for model-free
    algorithms."""
    buffer: Buffer | None
    """Real transitions for fitting M1; None for model-free algorithms."""
    memory: Memory | None
    """The imaginary memory I of `ModelConfig.imagine = "memory"` (PPO rows waiting for a
    full batch); None otherwise."""
    workers: Workers | None
    """The real env's workers mid-episode (`Config.schedule = "steps"`); None otherwise."""
    moving_return: Array
    """NaN until the first episode completes."""
    episodes: Array
    env_steps: Array
    imagined_steps: Array
    iteration: Array
    key: Array
    failure: Array
    """0 while every quantity is finite; else the `FAILURES` bits of what first became
    non-finite. A failed run is frozen at its last finite state."""
    failed_iteration: Array
    """The iteration whose result was non-finite (0 if none)."""
    greedy_return: Array | None = None
    """The greedy policy's mean return at its latest evaluation, after each chunk (NaN
    before the first); None without `Config.solved_return`."""


FAILURES = (
    "actor-critic parameters",
    "model parameters",
    "real-stage losses",
    "model loss",
    "imagined-stage losses or returns",
    "episode returns",
)
"""What the non-finite guard checks, in the order of the bits of `TrainState.failure`."""


GREEDY_STREAM = 0x9E37
"""`jax.random.fold_in` data of the greedy evaluations after each chunk
(`Config.solved_return`): a branch off the run's key that its training never draws."""


IMAGINED_STARTS = 16
"""Under `ModelConfig.imagine = "batch"`, imagined episodes start from a pool of this many
fresh env starts per worker, drawn once per iteration (a MuJoCo reset is a call to the
engine, too dear for every imagined step); each episode picks one at random."""


def failure_names(failure: int) -> list[str]:
    """The names of the quantities whose bits are set in a `TrainState.failure` value."""
    return [name for bit, name in enumerate(FAILURES) if failure >> bit & 1]


def _all_finite(tree) -> Array:
    leaves = [jnp.isfinite(x).all() for x in jax.tree.leaves(tree)]
    return jnp.stack(leaves).all() if leaves else jnp.ones((), bool)


class Trainer:
    """Builds the pure training functions for one config; holds no training state."""

    def __init__(self, config: Config):
        self.config = config
        self._jitted: dict = {}  # (program, mesh, bitwise) -> the jitted function, made once
        self.env, params = envs.make(config.env)
        self.env_params = self.env.with_backend(params, config.backend)
        if config.max_steps is not None:
            self.env_params = self.env_params.replace(max_steps=config.max_steps)
        self.obs_size = self.env.observation_size(self.env_params)
        self.action_spec = self.env.action_spec(self.env_params)
        self.max_steps = self.env_params.max_steps
        learner = LEARNERS[config.algorithm.learner]
        self.learner = learner(config.agent, self.obs_size, self.action_spec, config.workers)
        self.model_action, self.model_action_size = action_encoder(
            config.model.action_encoding, self.learner.policy, self.action_spec
        )
        self.dynamics = (
            Dynamics(config.model, self.obs_size, self.model_action_size)
            if config.algorithm.uses_model
            else None
        )

    def at(self, values: dict[str, Array]) -> Trainer:
        """This trainer with the float fields `values` (dotted names: a sweep point's
        values, traced inside the compiled program) set; itself where there are none. The
        learner and the model are rebuilt on the new values; the env is shared."""
        if not values:
            return self
        other = copy.copy(self)
        other.config = with_values(self.config, values)
        learner = LEARNERS[other.config.algorithm.learner]
        other.learner = learner(
            other.config.agent, self.obs_size, self.action_spec, self.config.workers
        )
        if self.dynamics is not None:
            other.dynamics = Dynamics(other.config.model, self.obs_size, self.model_action_size)
        return other

    # -- state -----------------------------------------------------------------------------

    def init_state(self, key: Array) -> TrainState:
        key, k_learner, k_model = jax.random.split(key, 3)
        model = buffer = memory = None
        if self.dynamics is not None:
            model = self.dynamics.init(k_model)
            buffer = buffer_init(
                self.config.model.buffer_capacity, self.obs_size, self.model_action_size
            )
            if self.config.model.imagine == "memory" and not self.branched:
                memory = self.learner.memory_init(self.config.workers)
        workers = None
        if self.config.schedule == "steps":  # a key of its own: the other draws stay as they are
            workers = workers_init(*self._reset(jax.random.fold_in(key, 1)))
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
            greedy_return=None if self.config.solved_return is None else jnp.float32(jnp.nan),
        )

    @property
    def branched(self) -> bool:
        """Imagined rollouts branch from real states (`ModelConfig.imagine_start`)."""
        return self.config.model.imagine_start == "real"

    # -- stages ----------------------------------------------------------------------------

    def _reset(self, key: Array, count: int | None = None) -> tuple[Array, object]:
        """`count` (default: one per worker) fresh starts of the real env."""
        keys = jax.random.split(key, count or self.config.workers)
        return jax.vmap(self.env.reset, (0, None))(keys, self.env_params)

    def _step_workers(self, keys: Array, world, action: Array, alive: Array) -> tuple:
        """The env's step, vmapped over workers: every worker steps and `alive` decides what
        counts; an env with `step_active` skips the physics of the workers not alive."""
        if hasattr(self.env, "step_active"):
            step = jax.vmap(self.env.step_active, (0, 0, 0, None, 0))
            return step(keys, world, action, self.env_params, alive)
        return jax.vmap(self.env.step, (0, 0, 0, None))(keys, world, action, self.env_params)

    def _env_world(self, key: Array, world, obs: Array, action: Array, alive: Array):
        keys = jax.random.split(key, action.shape[0])
        next_obs, world, reward, terminated, truncated, _ = self._step_workers(
            keys, world, action, alive
        )
        return next_obs, world, reward, terminated, truncated, {}

    def real_stage(self, state: TrainState, key: Array) -> tuple[TrainState, Episodes]:
        """One real episode per worker from fresh starts (schedule "episodes")."""
        k_reset, k_play = jax.random.split(key)
        obs, env_state = self._reset(k_reset)
        player = Player(self.learner, self._env_world, self.max_steps, observe=True)
        learner, episodes = play_episodes(k_play, state.learner, player, obs, env_state)
        return state.replace(learner=learner), episodes

    def real_steps(self, state: TrainState, key: Array) -> tuple[TrainState, Episodes, Completed]:
        """`config.steps_per_iteration` real steps per worker from where the workers stand
        (schedule "steps"); the episodes that ended on the way."""
        segments = self.config.steps_per_iteration // self.config.agent.n_steps
        player = Player(self.learner, self._env_world, self.max_steps, observe=True)
        learner, episodes, completed, workers = play_steps(
            key, state.learner, player, state.workers, segments, self._reset
        )
        return state.replace(learner=learner, workers=workers), episodes, completed

    def model_stage(
        self, state: TrainState, episodes: Episodes, key: Array
    ) -> tuple[TrainState, Array]:
        steps = episodes.steps
        flat = lambda x: x.reshape((-1, *x.shape[2:]))
        batch = Transitions(
            obs=flat(steps.obs),
            action=flat(self.model_action(steps.action)),
            next_obs=flat(steps.next_obs),
            reward=flat(steps.reward),
        )
        buffer = buffer_add(state.buffer, batch, flat(steps.weight) > 0)
        value = None
        if self.config.model.value_loss:
            value = lambda obs: self.learner.value(state.learner.params, obs)
        model, loss = self.dynamics.fit(state.model, buffer, key, value)
        return state.replace(model=model, buffer=buffer), loss

    def imagine_stage(
        self, state: TrainState, key: Array, gain: Array, quota: Array | None = None
    ) -> tuple[TrainState, Episodes]:
        """Imagined episodes in M1 from fresh initial states (`ModelConfig.imagine`).

        `quota` (schedule "steps"; `[W]`): worker w imagines `quota[w]` episodes, one per real
        episode it ended in the iteration, as Algorithm 1 imagines one after each real one,
        within as many steps as it took real ones (`Config.steps_per_iteration`)."""
        k_reset, k_play = jax.random.split(key)
        reset = segments = None
        history = ld_history(self.dynamics, self.config.workers)  # the LD window's start
        if self.config.model.imagine == "batch" or quota is not None:
            starts, _ = self._reset(k_reset, IMAGINED_STARTS * self.config.workers)
            obs = starts[: self.config.workers]
            pick = lambda key: starts[jax.random.randint(key, obs.shape[:1], 0, len(starts))]
            reset = lambda key: (pick(key), history)
            if quota is not None:
                segments = self.config.steps_per_iteration // self.config.agent.n_steps
        else:
            obs, _ = self._reset(k_reset)
        rule = self.config.stop_rule
        world = self._model_world(state, gain)
        memory = self.config.model.imagine == "memory"
        if memory:
            k_play, k_learn = jax.random.split(k_play)
        limit = imagined_steps_limit(self.config.model, rule, self.max_steps)
        player = Player(self.learner, world, limit, learn=not memory)
        if reset is None:
            learner, episodes = play_episodes(k_play, state.learner, player, obs, history)
        else:
            learner, episodes = play_batch(
                k_play, state.learner, player, obs, history, reset, quota, segments
            )
        if memory:
            learner, state_memory, losses = self.learner.learn_from_memory(
                learner, state.memory, episodes.steps, k_learn
            )
            state, episodes = state.replace(memory=state_memory), episodes.replace(losses=losses)
        return state.replace(learner=learner), episodes

    def branch_stage(
        self, state: TrainState, key: Array, gain: Array, real: Episodes
    ) -> tuple[TrainState, Episodes]:
        """Branched imagination (`ModelConfig.imagine_start` "real"): `branches` rollouts in
        M1 side by side, each from a state drawn from the real buffer and cut after the
        horizon (or sooner by the stop rule), the next one drawn as one ends, until the
        iteration has imagined `imagined_ratio` steps per real step it played; the learner
        updates on every n steps of them (with `real_share` of real rows beside)."""
        config = self.config.model
        k_start, k_play, k_first = jax.random.split(key, 3)
        history = ld_history(self.dynamics, config.branches)
        buffer = state.buffer

        def draw(key: Array) -> Array:
            if config.start_window:
                return buffer_sample_recent(buffer, key, config.branches, config.start_window).obs
            index = jax.random.randint(key, (config.branches,), 0, jnp.maximum(buffer.size, 1))
            return buffer.data.obs[index]

        obs = draw(k_start)
        rule = self.config.stop_rule
        threshold = None
        if rule == "macura":  # from the first step of this iteration's starts
            k_act, k_model = jax.random.split(k_first)
            action = self.learner.env_action(self.learner.act(state.learner.params, k_act, obs))
            first = first_step_statistic(
                self.dynamics, state.model, obs, self.model_action(action), k_model
            )
            threshold = macura_threshold(first, config.macura_quantile, config.macura_scale)
        world = self._model_world(state, gain, threshold)
        played = real.lengths.sum()
        horizon = config.horizon
        if rule == "mbpo":
            horizon = scheduled_horizon(config, state.env_steps + played)
        frozen = ("actor", "log_std") if config.imagined_updates == "critic" else ()
        player = Player(
            self.learner.freezing(frozen)
            .scaling(("actor", "log_std"), config.imagined_actor_step)
            .with_epochs(config.imagined_epochs),
            world,
            self.max_steps,
            horizon=horizon,
            keep=self._kept_by_imagination,
            mix=self._real_rows(real.steps, real.lengths),
        )
        rows = jnp.ceil(config.imagined_ratio * played)
        learner, episodes = play_batch(
            k_play,
            state.learner,
            player,
            obs,
            history,
            lambda key: (draw(key), history),
            segments=self.branch_segments,
            rows=rows,
        )
        return state.replace(learner=learner), episodes

    @property
    def _kept_by_imagination(self) -> tuple[str, ...]:
        """The learner's parameters that branched updates leave as they were
        (`ModelConfig.imagined_std`, `ModelConfig.imagined_updates`)."""
        config = self.config.model
        if config.imagined_updates == "critic":
            return ("actor", "log_std")
        return ("log_std",) if config.imagined_std == "real" else ()

    @property
    def branch_segments(self) -> int:
        """The most segments a branched stage plays: enough for `imagined_ratio` imagined
        steps per real step of the longest possible iteration."""
        config, n = self.config, self.config.agent.n_steps
        per_worker = config.steps_per_iteration if config.schedule == "steps" else self.max_steps
        real = per_worker * config.workers
        return max(1, math.ceil(config.model.imagined_ratio * real / (config.model.branches * n)))

    def _real_rows(self, steps: Segment, lengths: Array):
        """`Player.mix` for `real_share`: beside the `branches` imagined rollouts of each
        segment, R = round(branches x share / (1 - share)) windows of n real steps of this
        iteration (a worker and a start within its played steps, drawn at random); None for
        a share of 0."""
        config = self.config.model
        share = config.real_share
        count = round(config.branches * share / (1 - share))
        if count == 0:
            return None

        def mix(key: Array, segment: Segment) -> Segment:
            n = segment.weight.shape[0]
            k_worker, k_start = jax.random.split(key)
            worker = jax.random.randint(k_worker, (count,), 0, lengths.shape[0])
            room = jnp.maximum(lengths[worker] - n, 0) + 1
            start = (jax.random.uniform(k_start, (count,)) * room).astype(jnp.int32)
            start = jnp.minimum(start, steps.weight.shape[0] - n)

            def window(x: Array) -> Array:
                one = lambda w, t: jax.lax.dynamic_slice_in_dim(x[:, w], t, n, 0)
                return jax.vmap(one, out_axes=1)(worker, start)

            real = jax.tree.map(window, steps)
            return jax.tree.map(lambda a, b: jnp.concatenate([a, b], axis=1), segment, real)

        return mix

    def _model_world(self, state: TrainState, gain: Array, threshold: Array | None = None):
        """M1 as a world for imagined play, stopped by the run's rule (`threshold`: the
        macura rule's)."""
        rule = self.config.stop_rule
        true_next = self._true_next if rule == "oracle" else None
        return model_world(
            self.dynamics,
            state.model,
            lambda o: self.env.is_terminal(o, self.env_params),
            self.model_action,
            self._env_reward(),
            gain,
            stop_rule(self.config.model, rule, true_next, threshold),
            None if self.config.model.world == "model" else self._true_step,
            true_state=self.config.model.world in ("true", "true-state"),
            true_reward=self.config.model.world in ("true", "true-reward"),
            penalty=self.config.model.penalty,
        )

    def _true_step(self, key: Array, obs: Array, action: Array) -> tuple[Array, Array, Array]:
        """The real env stepped from imagined observations `[W, d]`: next observations,
        rewards and terminations (the oracle stop, `model.world` "true")."""
        states = jax.vmap(self.env.from_observation, (0, None))(obs, self.env_params)
        keys = jax.random.split(key, obs.shape[0])
        step = jax.vmap(self.env.step, (0, 0, 0, None))
        next_obs, _, reward, terminated, _, _ = step(keys, states, action, self.env_params)
        return next_obs, reward, terminated

    def _true_next(self, key: Array, obs: Array, action: Array) -> Array:
        """The real env's next observations from imagined ones, `[W, d]` (the oracle stop)."""
        return self._true_step(key, obs, action)[0]

    def _env_reward(self):
        """The env's exact reward `(obs, action, next_obs) -> [...]`, if used and known."""
        if not (self.config.model.env_reward and self.env.exact_reward(self.env_params)):
            return None
        return lambda obs, action, next_obs: self.env.reward(obs, action, next_obs, self.env_params)

    # -- one iteration and a chunk of them -------------------------------------------------

    def iteration(self, state: TrainState, gain: Array) -> tuple[TrainState, dict]:
        """One iteration of Algorithm 1 for every worker; returns per-iteration metrics.

        If the iteration makes any checked quantity non-finite, the run keeps its previous
        state from then on (frozen) and `failure` says what diverged; other vmapped runs go on.
        """
        new, metrics = self._iteration(state, gain)
        spent = self.spent(state)  # its budget was reached: this iteration does not count
        failure = self._failure(new, metrics)
        first = (state.failure == 0) & (failure != 0) & ~spent
        frozen = (state.failure != 0) | first | spent
        kept = jax.tree.map(lambda n, o: jnp.where(frozen, o, n), new, state)
        state = kept.replace(
            failure=jnp.where(first, failure, state.failure),
            failed_iteration=jnp.where(first, new.iteration, state.failed_iteration),
        )
        metrics["moving_after"] = jnp.where(frozen, state.moving_return, metrics["moving_after"])
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

    def _failure(self, state: TrainState, metrics: dict) -> Array:
        """The `FAILURES` bits of the quantities of one iteration that are not all finite."""
        stage = lambda prefix: {n: v for n, v in metrics.items() if n.startswith(prefix)}
        checks = [
            state.learner.params,
            state.model.params if state.model is not None else (),
            stage("real_"),
            metrics.get("model_loss", ()),
            stage("imagined_"),
            metrics["returns"],
        ]
        bad = jnp.stack([~_all_finite(tree) for tree in checks])
        return (bad.astype(jnp.int32) << jnp.arange(len(checks))).sum()

    def _iteration(self, state: TrainState, gain: Array) -> tuple[TrainState, dict]:
        key, k_real, k_model, k_imagine = jax.random.split(state.key, 4)
        if self.config.schedule == "steps":
            state, real, completed = self.real_steps(state, k_real)
            # Completion order is (step, worker): flattened row-major.
            ended = completed.ended.reshape(-1)
            returns, lengths = completed.returns.reshape(-1), completed.lengths.reshape(-1)
            workers = self.config.workers
            at_step = jnp.arange(1, completed.ended.shape[0] + 1, dtype=jnp.int32) * workers
            count = ended.sum()
            extra = {
                "ended": ended,
                "steps_at": jnp.repeat(state.env_steps + at_step, workers),
            }
            episode_return = jnp.where(count > 0, returns.sum() / jnp.maximum(count, 1), jnp.nan)
        else:
            state, real = self.real_stage(state, k_real)
            # The moving return advances over episodes in completion order (shorter first,
            # ties by worker), as the paper's global counter sees them.
            order = jnp.argsort(real.lengths, stable=True)
            returns, lengths = real.returns[order], real.lengths[order]
            ended, count, extra = jnp.ones(returns.shape, bool), self.config.workers, {}
            episode_return = real.returns.mean()
        decay = self.config.moving_decay

        def advance(m, episode):
            r, valid = episode
            new = jnp.where(jnp.isnan(m), r, decay * m + (1.0 - decay) * r)
            m = jnp.where(valid, new, m)
            return m, m

        moving, moving_after = jax.lax.scan(advance, state.moving_return, (returns, ended))
        metrics = {
            "episode_return": episode_return,
            "returns": returns,
            "lengths": lengths,
            "moving_after": moving_after,
            **extra,
            **{f"real_{name}": value for name, value in real.losses.items()},
        }
        imagined_steps = jnp.zeros((), jnp.int32)
        if self.dynamics is not None:
            state, metrics["model_loss"] = self.model_stage(state, real, k_model)
            quota = None
            if self.config.schedule == "steps" and self.config.model.imagine != "batch":
                quota = completed.ended.sum(axis=0)
            if self.branched:
                state, imagined = self.branch_stage(state, k_imagine, gain, real)
            else:
                state, imagined = self.imagine_stage(state, k_imagine, gain, quota)
            weight = imagined.steps.weight
            imagined_steps = weight.sum().astype(jnp.int32)
            ld = imagined.extras["ld"]
            metrics["ld_mean"] = (ld * weight).sum() / weight.sum()
            metrics["ld_histogram"] = ld_histogram(ld, weight)  # Figure 5's data
            if "outside" in imagined.extras:  # share of imagined episodes that left the box
                outside = (imagined.extras["outside"] * weight).sum()
                metrics["imagined_outside"] = outside / jnp.maximum(imagined.ended.sum(), 1.0)
            length, total = imagined.mean_episode()
            metrics["imagined_length"], metrics["imagined_return"] = length, total
            metrics.update({f"imagined_{n}": v for n, v in imagined.losses.items()})

        state = state.replace(
            moving_return=moving,
            episodes=state.episodes + count,
            env_steps=state.env_steps + real.lengths.sum(),
            imagined_steps=state.imagined_steps + imagined_steps,
            iteration=state.iteration + 1,
            key=key,
        )
        return state, metrics

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
        n = self.config.eval_episodes
        obs, env_state = jax.vmap(self.env.reset, (0, None))(
            jax.random.split(key, n), self.env_params
        )

        def body(carry, key):
            obs, env_state, alive, total = carry
            action = self.learner.greedy(state.learner.params, obs)
            obs, env_state, reward, terminated, truncated, _ = self._step_workers(
                jax.random.split(key, n), env_state, action, alive
            )
            total = total + reward * alive
            alive = alive & ~(terminated | truncated)
            return (obs, env_state, alive, total), None

        # A fresh key per env step (the resets keep `key`'s split, as before).
        step_keys = jax.random.split(jax.random.fold_in(key, 1), self.max_steps)
        init = (jnp.int32(0), obs, env_state, jnp.ones((n,), bool), jnp.zeros((n,)))
        # Until every episode has ended (early policies fall within tens of steps); the
        # steps after an episode's end would add nothing.
        playing = lambda carry: (carry[0] < self.max_steps) & carry[3].any()
        step_on = lambda carry: (carry[0] + 1, *body(carry[1:], step_keys[carry[0]])[0])
        total = jax.lax.while_loop(playing, step_on, init)[-1]
        return total.mean()

    # -- seeds x K -------------------------------------------------------------------------

    def init_batch(self) -> TrainState:
        """States `[P, S]` (P: `config.points`, the K values without a sweep): seed s gets
        key s at every point (common random numbers). In a sweep each point starts from
        its own values (an optimiser state may hold its learning rate).

        Jitted, one program instead of some hundred eager ops (about 1.5 s per process on
        CPU): the same values to the bit (`networks.normal_init`)."""
        return jax.jit(self._init_batch)()

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
