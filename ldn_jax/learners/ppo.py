"""PPO2: the clipped surrogate with GAE, several epochs of shuffled minibatches, Adam.

PPO's rollout is one segment of n steps from W workers, collected with fixed parameters; at
the segment's end the learner makes `epochs` passes over its `n * W` rows in `minibatches`
shuffled minibatches. Masked rows (workers whose episode had ended, imagined steps after the
LD stop) carry weight 0 into every loss and statistic, so they change nothing.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import jax
import jax.numpy as jnp
import optax
from flax import struct

from ldn_jax import prng
from ldn_jax.config import AgentConfig, Config, PPOConfig
from ldn_jax.learners.base import (
    ActorCritic,
    LearnerState,
    Segment,
    canonical,
    gae,
    keep_if_any,
    weighted_mean,
)

Array = jax.Array


def clipped_surrogate(ratio: Array, advantage: Array, clip_eps: float) -> Array:
    """PPO's objective per sample (to maximise): min(r A, clip(r, 1 - eps, 1 + eps) A)."""
    clipped = jnp.clip(ratio, 1.0 - clip_eps, 1.0 + clip_eps)
    return jnp.minimum(ratio * advantage, clipped * advantage)


@struct.dataclass
class Batch:
    """PPO's training rows, flat `[N, ...]`; the rollout's quantities are fixed."""

    obs: Array
    action: Array
    log_prob: Array
    """log pi_old(a|s) of the parameters that collected the segment."""
    value: Array
    """V_old(s), the centre of PPO2's value clip."""
    advantage: Array
    target: Array
    """Value target: advantage + V_old(s) (the lambda-return)."""
    weight: Array


@struct.dataclass
class Memory:
    """The imaginary memory I (Algorithm 1, line 4): PPO rows waiting until a rollout's
    worth exists (`ImagineConfig.mode = "memory"`)."""

    rows: Batch
    """`[n_steps * workers, ...]`; the first `count` are live, the rest weight 0."""
    count: Array


class PPO(ActorCritic):
    """Clipped-objective PPO (PPO2) on each segment; Adam with global-norm clipping."""

    def __init__(
        self,
        config: AgentConfig,
        obs_size: int,
        action_spec,
        workers: int = 1,
        ppo: PPOConfig | None = None,
    ):
        """`ppo`: PPO's own constants (None: their defaults); the rest as `ActorCritic`'s."""
        super().__init__(config, obs_size, action_spec, workers)
        self.ppo = ppo = ppo or PPOConfig()

        # Injected hyperparameters are arrays in the optimiser state, so a sweep can vary them.
        def adam(lr):
            return optax.inject_hyperparams(optax.adam)(learning_rate=lr, eps=config.adam_eps)

        self.optimizer = optax.chain(
            optax.clip_by_global_norm(ppo.max_grad_norm),
            self.per_net(adam(config.actor_lr), adam(config.critic_lr)),
        )

    @classmethod
    def of(cls, config: Config, obs_size: int, action_spec) -> PPO:
        return cls(config.agent, obs_size, action_spec, config.workers, config.ppo)

    def with_epochs(self, epochs: int) -> PPO:
        """This learner with `epochs` passes per update (0: its own); the optimiser and
        everything else are shared."""
        if epochs == 0 or epochs == self.ppo.epochs:
            return self
        learner = copy.copy(self)
        learner.ppo = dataclasses.replace(self.ppo, epochs=epochs)
        return learner

    def batch(self, params: dict, segment: Segment) -> Batch:
        """GAE and the old policy's quantities of a canonical segment, flattened to rows."""
        value = self.value(params, segment.obs)
        next_value = self.value(params, segment.next_obs)
        advantage = gae(
            self.training_reward(params, segment),
            value,
            next_value,
            segment.terminated,
            segment.done,
            (self.config.gamma, self.ppo.gae_lambda),
        )
        log_prob, _ = self.log_prob_entropy(params, segment.obs, segment.action)
        rows = Batch(
            obs=segment.obs,
            action=segment.action,
            log_prob=log_prob,
            value=value,
            advantage=advantage,
            target=advantage + value,
            weight=segment.weight,
        )
        return jax.tree.map(lambda x: x.reshape((-1, *x.shape[2:])), rows)

    def loss(self, params: dict, batch: Batch) -> tuple[Array, dict]:
        """PPO2's loss on one minibatch: clipped surrogate + clipped value loss - entropy."""
        cfg = self.config
        w = batch.weight
        mean = lambda x: weighted_mean(x, w)
        # Advantages normalised per minibatch, over its live rows.
        centre = mean(batch.advantage)
        scale = jnp.sqrt(mean(jnp.square(batch.advantage - centre)))
        advantage = (batch.advantage - centre) / (scale + 1e-8)

        log_prob, entropy = self.log_prob_entropy(params, batch.obs, batch.action)
        # A masked row's log-ratio is set to 0, not just weighted away: its canonical zero
        # action can lie far in a narrow Gaussian's tail (log pi_old = -1,052 was seen on
        # inverted_pendulum), where exp overflows after one step, and the backward pass's
        # 0 x inf would turn every gradient into NaN.
        log_ratio = jnp.where(w > 0, log_prob - batch.log_prob, 0.0)
        ratio = jnp.exp(log_ratio)
        actor_loss = -mean(clipped_surrogate(ratio, advantage, self.ppo.clip_eps))

        value = self.value(params, batch.obs)
        value_error = jnp.square(value - batch.target)
        if self.ppo.value_clip is not None:
            change = jnp.clip(value - batch.value, -self.ppo.value_clip, self.ppo.value_clip)
            value_error = jnp.maximum(value_error, jnp.square(batch.value + change - batch.target))
        critic_loss = 0.5 * mean(value_error)
        entropy_mean = mean(entropy)
        total = actor_loss + self.ppo.value_coef * critic_loss - cfg.entropy_beta * entropy_mean
        return total, {
            "actor_loss": actor_loss,
            "critic_loss": critic_loss,
            "entropy": entropy_mean,
            "approx_kl": jax.lax.stop_gradient(mean((ratio - 1.0) - log_ratio)),
            "clip_fraction": jax.lax.stop_gradient(
                mean((jnp.abs(ratio - 1.0) > self.ppo.clip_eps).astype(jnp.float32))
            ),
        }

    def minibatch_step(self, state: LearnerState, batch: Batch) -> tuple[LearnerState, tuple]:
        """One Adam step; a minibatch without live rows leaves `state` unchanged."""
        grads, info = jax.grad(self.loss, has_aux=True)(state.params, batch)
        new = self.apply_gradients(state, grads)
        return keep_if_any(new, state, batch.weight), (info, batch.weight.sum() > 0)

    def _guarded_step(self, carry: tuple[LearnerState, Array], batch: Batch):
        """`minibatch_step` under `target_kl`: once a minibatch's approximate KL (at the
        parameters before its step) exceeds 1.5 x target_kl, it and every later minibatch of
        the update leave the state as it is."""
        state, stopped = carry
        new, (info, live) = self.minibatch_step(state, batch)
        stopped = stopped | (live & (info["approx_kl"] > 1.5 * self.ppo.target_kl))
        state = jax.tree.map(lambda a, b: jnp.where(stopped, b, a), new, state)
        return (state, stopped), ({**info, "kl_stopped": stopped.astype(jnp.float32)}, live)

    def update(
        self, state: LearnerState, segment: Segment, key: Array | None = None
    ) -> tuple[LearnerState, dict]:
        """`epochs` passes of `minibatches` shuffled minibatches over one segment's rows.

        `key` shuffles the rows, so PPO needs one. Returns the losses averaged over
        minibatches that had live rows.
        """
        if key is None:
            raise ValueError("PPO's update shuffles minibatches: pass a PRNG key")
        return self.learn(state, self.batch(state.params, canonical(segment)), key)

    def learn(self, state: LearnerState, batch: Batch, key: Array) -> tuple[LearnerState, dict]:
        """PPO's epochs over fixed rows. The row count is padded with weight-0 rows to a
        multiple of `minibatches`, so any count works."""
        cfg = self.ppo
        rows = batch.weight.shape[0]
        size = math.ceil(rows / cfg.minibatches)
        pad = size * cfg.minibatches - rows
        batch = jax.tree.map(lambda x: jnp.pad(x, [(0, pad)] + [(0, 0)] * (x.ndim - 1)), batch)

        step = self.minibatch_step if cfg.target_kl is None else self._guarded_step

        def epoch(state, key: Array):
            order = prng.permutation(key, rows + pad)
            shuffled = jax.tree.map(
                lambda x: x[order].reshape((cfg.minibatches, size, *x.shape[1:])), batch
            )
            return jax.lax.scan(step, state, shuffled)

        carry = state if cfg.target_kl is None else (state, jnp.bool_(False))
        carry, (info, live) = jax.lax.scan(epoch, carry, jax.random.split(key, cfg.epochs))
        state = carry if cfg.target_kl is None else carry[0]
        live = live.astype(jnp.float32)
        info = jax.tree.map(lambda x: (x * live).sum() / jnp.maximum(live.sum(), 1.0), info)
        return state, info

    # -- the imaginary memory -----------------------------------------------------------------

    def memory_init(self, workers: int) -> Memory:
        """An empty memory holding one rollout's worth of rows: `n_steps x workers`."""
        rows = self.config.n_steps * workers
        shapes = {
            "obs": (self.obs_size,),
            "action": () if self.policy.discrete else (self.policy.size,),
        }
        dtype = {"action": jnp.int32 if self.policy.discrete else jnp.float32}
        fields = ("obs", "action", "log_prob", "value", "advantage", "target", "weight")
        batch = Batch(
            **{f: jnp.zeros((rows, *shapes.get(f, ())), dtype.get(f, jnp.float32)) for f in fields}
        )
        return Memory(rows=batch, count=jnp.zeros((), jnp.int32))

    def learn_from_memory(
        self, state: LearnerState, memory: Memory, segment: Segment, key: Array
    ) -> tuple[LearnerState, Memory, dict]:
        """Add a batch of played steps (`[T, W]`, masked, collected with `state`'s
        parameters) to the memory, and learn from each full rollout's worth it then holds.

        The steps become PPO rows at once (GAE, log pi_old and V_old of the parameters that
        played them), so each row keeps the quantities of the policy that collected it, as
        in any PPO rollout; full batches are learnt in the order their rows came. What is
        left (fewer rows than a batch) waits for the next call. Returns the losses averaged
        over this call's updates (zeros and `updates` 0 when there was none).
        """
        capacity = memory.rows.weight.shape[0]
        rows = self.batch(state.params, canonical(segment))
        # Live rows first, in their order; then the memory's rows followed by the new ones
        # (the pool's rows past `total` all have weight 0).
        live_first = jnp.argsort(rows.weight == 0, stable=True)
        rows = jax.tree.map(lambda x: x[live_first], rows)
        total = memory.count + (rows.weight > 0).sum().astype(jnp.int32)
        spare = jax.tree.map(lambda x: jnp.zeros((capacity, *x.shape[1:]), x.dtype), rows)
        pool = jax.tree.map(lambda *x: jnp.concatenate(x), memory.rows, rows, spare)
        pool = jax.tree.map(
            lambda p, x: jax.lax.dynamic_update_slice_in_dim(p, x, memory.count, 0), pool, rows
        )
        take = lambda start: jax.tree.map(
            lambda x: jax.lax.dynamic_slice_in_dim(x, start, capacity, 0), pool
        )
        _, zero_info = jax.eval_shape(self.learn, state, take(0), key)
        zero_info = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), zero_info)

        def full(loop):
            return total - loop[0] >= capacity

        def learn_next(loop):
            start, state, info_sum, updates, key = loop
            key, k_learn = jax.random.split(key)
            state, info = self.learn(state, take(start), k_learn)
            info_sum = jax.tree.map(jnp.add, info_sum, info)
            return start + capacity, state, info_sum, updates + 1, key

        start, state, info_sum, updates, _ = jax.lax.while_loop(
            full, learn_next, (jnp.zeros((), jnp.int32), state, zero_info, jnp.int32(0), key)
        )
        info = jax.tree.map(lambda x: x / jnp.maximum(updates, 1), info_sum)
        info["updates"] = updates.astype(jnp.float32)
        return state, Memory(rows=take(start), count=total - start), info
