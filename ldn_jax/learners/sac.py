"""Soft actor-critic (Haarnoja et al. 2018) as MBPO and SBX train it: a tanh-squashed Gaussian
actor, twin critics with Polyak-averaged targets, and an entropy temperature tuned toward a
target entropy. Its updates read batches of transitions from a replay memory, many per real
step, all of them in one `lax.scan` (`SAC.learn`).

The pure pieces (`squashed_sample`, `critic_loss`, `actor_loss`, `temperature_loss`,
`polyak`) are tested against hand-computed values. `SACLearner` puts SAC behind the
trainer's learner protocol: its state carries the run's replay memory (a ring per run, so
seeds vmap and a checkpoint holds it), and its `update` after each segment of real steps
adds them to the memory and makes `utd` updates per step.
"""

from __future__ import annotations

from collections.abc import Callable

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from flax import struct

from ldn_jax.buffer import Buffer, buffer_add, buffer_sample
from ldn_jax.config import AgentConfig, Config, SACConfig
from ldn_jax.networks import MLP

Array = jax.Array

LOG_STD_BOUNDS = (-20.0, 2.0)
"""The actor's log std is clipped into these (softlearning's, SBX's)."""


@struct.dataclass
class Transitions:
    """A batch of transitions, `[B, ...]`."""

    obs: Array
    action: Array
    """In the policy's range, [-1, 1] per dimension."""
    reward: Array
    next_obs: Array
    terminated: Array
    """True where the episode ended by the task's own termination: no bootstrap. A time
    limit or a stopped imagined rollout is not a termination."""


@struct.dataclass
class SACState:
    params: dict
    """`{"actor", "critic", "target", "log_alpha"}`; critic and target stack the twin
    critics `[2, ...]`."""
    opt_state: optax.OptState


def squashed_sample(mean: Array, log_std: Array, key: Array) -> tuple[Array, Array]:
    """a = tanh(u), u ~ N(mean, exp(log_std)^2) per dimension; returns `(a [..., A], log
    pi(a) [...])`, the change of variables by the stable form of log(1 - tanh(u)^2) =
    2 (log 2 - u - softplus(-2u))."""
    u = mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape)
    gaussian = -0.5 * jnp.square((u - mean) / jnp.exp(log_std)) - log_std
    gaussian = gaussian - 0.5 * jnp.log(2 * jnp.pi)
    correction = 2.0 * (jnp.log(2.0) - u - jax.nn.softplus(-2.0 * u))
    return jnp.tanh(u), (gaussian - correction).sum(axis=-1)


def critic_loss(
    q: Array, batch: Transitions, next_q: Array, next_log_prob: Array, alpha: Array, gamma: float
) -> Array:
    """1/2 of the twin critics' squared errors summed over critics, averaged over the batch:
    target r + gamma (1 - terminated) (min_i Q_i'(s', a') - alpha log pi(a'|s')).
    `q`: `[2, B]`; `next_q`: the target critics at (s', a'), `[2, B]`."""
    soft = next_q.min(axis=0) - alpha * next_log_prob
    target = batch.reward + gamma * (1.0 - batch.terminated) * soft
    target = jax.lax.stop_gradient(target)
    return 0.5 * jnp.square(q - target).mean(axis=-1).sum()


def actor_loss(alpha: Array, log_prob: Array, q: Array) -> Array:
    """mean(alpha log pi(a|s) - min_i Q_i(s, a)), `q` `[2, B]`, reparameterised in a."""
    return (alpha * log_prob - q.min(axis=0)).mean()


def temperature_loss(log_alpha: Array, log_prob: Array, target_entropy: float) -> Array:
    """-mean(log alpha (log pi + target)): alpha grows while the policy's entropy (-log pi)
    is below the target and shrinks above it."""
    return -(log_alpha * jax.lax.stop_gradient(log_prob + target_entropy)).mean()


def polyak(target, online, tau: float):
    """target <- (1 - tau) target + tau online, leaf by leaf."""
    return jax.tree.map(lambda t, o: (1.0 - tau) * t + tau * o, target, online)


class _Actor(nn.Module):
    config: SACConfig
    actions: int

    @nn.compact
    def __call__(self, obs: Array) -> tuple[Array, Array]:
        c = self.config
        out = MLP(c.hidden, 2 * self.actions, "relu", 0.0, c.layers, "fan_in")(obs)
        mean, log_std = out[..., : self.actions], out[..., self.actions :]
        return mean, jnp.clip(log_std, *LOG_STD_BOUNDS)


class _Critic(nn.Module):
    config: SACConfig

    @nn.compact
    def __call__(self, obs: Array, action: Array) -> Array:
        c = self.config
        x = jnp.concatenate([obs, action], axis=-1)
        return MLP(c.hidden, 1, "relu", 0.0, c.layers, "fan_in")(x)[..., 0]


class SAC:
    """SAC for `obs_size` observations and `actions` continuous actions in [-1, 1]."""

    def __init__(self, config: SACConfig, obs_size: int, actions: int, gamma: float = 0.99):
        self.config, self.gamma = config, gamma
        self.obs_size, self.actions = obs_size, actions
        self.actor = _Actor(config, actions)
        self.critic = _Critic(config)
        target = config.target_entropy
        self.target_entropy = float(-actions if target is None else target)
        adam = optax.adam(config.lr)
        labels = {"actor": "adam", "critic": "adam", "log_alpha": "adam", "target": "fixed"}
        self.optimizer = optax.multi_transform({"adam": adam, "fixed": optax.set_to_zero()}, labels)

    def init(self, key: Array) -> SACState:
        k_actor, k_critic = jax.random.split(key)
        obs, action = jnp.zeros((1, self.obs_size)), jnp.zeros((1, self.actions))
        critics = jax.vmap(lambda k: self.critic.init(k, obs, action))(
            jax.random.split(k_critic, 2)
        )
        params = {
            "actor": self.actor.init(k_actor, obs),
            "critic": critics,
            "target": jax.tree.map(jnp.copy, critics),
            "log_alpha": jnp.log(jnp.float32(self.config.init_alpha)),
        }
        return SACState(params, self.optimizer.init(params))

    def q(self, critics: dict, obs: Array, action: Array) -> Array:
        """Both critics' values, `[2, ...]`."""
        return jax.vmap(self.critic.apply, (0, None, None))(critics, obs, action)

    def act(self, params: dict, key: Array, obs: Array) -> Array:
        """A sampled action in [-1, 1]."""
        return squashed_sample(*self.actor.apply(params["actor"], obs), key)[0]

    def greedy(self, params: dict, obs: Array) -> Array:
        """tanh of the Gaussian's mean."""
        return jnp.tanh(self.actor.apply(params["actor"], obs)[0])

    def losses(
        self, params: dict, batch: Transitions, key: Array, critics: dict | None = None
    ) -> tuple[Array, dict]:
        """The three losses of one batch, summed for one gradient (each reads only its own
        parameters: the others enter through `stop_gradient`). The actor's loss reads
        `critics` where given (the critics after this update's step), else `params`'."""
        k_next, k_now = jax.random.split(key)
        alpha = jnp.exp(jax.lax.stop_gradient(params["log_alpha"]))
        next_action, next_log_prob = squashed_sample(
            *self.actor.apply(jax.lax.stop_gradient(params["actor"]), batch.next_obs), k_next
        )
        next_q = self.q(params["target"], batch.next_obs, next_action)
        q = self.q(params["critic"], batch.obs, batch.action)
        critic = critic_loss(q, batch, next_q, next_log_prob, alpha, self.gamma)
        action, log_prob = squashed_sample(*self.actor.apply(params["actor"], batch.obs), k_now)
        frozen = jax.lax.stop_gradient(params["critic"] if critics is None else critics)
        actor = actor_loss(alpha, log_prob, self.q(frozen, batch.obs, action))
        temperature = temperature_loss(params["log_alpha"], log_prob, self.target_entropy)
        metrics = {"critic_loss": critic, "actor_loss": actor, "alpha": alpha}
        metrics["entropy"] = -jax.lax.stop_gradient(log_prob).mean()
        return critic + actor + temperature, metrics

    def update(self, state: SACState, batch: Transitions, key: Array) -> tuple[SACState, dict]:
        """One gradient step of critics, actor and temperature, then the targets' Polyak step
        (`critic_first`: the actor's gradient read at the critics after their step)."""
        if self.config.critic_first:
            grads, metrics = self._critic_first_grads(state, batch, key)
        else:
            grads, metrics = jax.grad(self.losses, has_aux=True)(state.params, batch, key)
        updates, opt_state = self.optimizer.update(grads, state.opt_state, state.params)
        params = optax.apply_updates(state.params, updates)
        params["target"] = polyak(params["target"], params["critic"], self.config.tau)
        return SACState(params, opt_state), metrics

    def _critic_first_grads(
        self, state: SACState, batch: Transitions, key: Array
    ) -> tuple[dict, dict]:
        """The gradients of `losses` with the actor's read at the critics after this update's
        step. Adam moves each parameter from its own gradient and moments (and the shared
        step count), so the critics' step taken alone is the one the update then applies:
        it is taken once here (the other gradients zero) to read the actor's loss at it."""
        grad = jax.grad(self.losses, has_aux=True)
        critic = grad(state.params, batch, key)[0]["critic"]
        alone = jax.tree.map(jnp.zeros_like, state.params) | {"critic": critic}
        stepped, _ = self.optimizer.update(alone, state.opt_state, state.params)
        critics = optax.apply_updates(state.params["critic"], stepped["critic"])
        return grad(state.params, batch, key, critics)

    def learn(
        self,
        state: SACState,
        sample: Callable[[Array], Transitions],
        key: Array,
        updates: int,
    ) -> tuple[SACState, dict]:
        """`updates` gradient steps in one `lax.scan`, each on `sample(key)`: a batch drawn
        on device (from the replay memory, or a mix of real and imagined rows); the
        metrics averaged over the steps."""

        def step(state, key):
            k_sample, k_update = jax.random.split(key)
            return self.update(state, sample(k_sample), k_update)

        state, metrics = jax.lax.scan(step, state, jax.random.split(key, updates))
        return state, jax.tree.map(jnp.mean, metrics)


@struct.dataclass
class SACRun:
    """`SACLearner`'s state in a run: SAC's and its replay memory."""

    params: dict
    opt_state: optax.OptState
    replay: Buffer
    """The run's real transitions (`Transitions` rows), a ring."""


@struct.dataclass
class MBPORun(SACRun):
    """sac-model's and sac-ldn's: `SACRun` and the model memory (a run of `sac` keeps the
    shorter state, and so the layout its checkpoints were written in)."""

    imagined: Buffer
    """The rows of the model's branches (MBPO's model buffer), a ring of `Memories.imagined`
    rows."""


@struct.dataclass
class Memories:
    """The sizes of `SACLearner`'s memories and how a batch mixes them."""

    real: int = struct.field(pytree_node=False)
    """Real transitions kept (the run's budget at most)."""
    imagined: int = struct.field(pytree_node=False, default=0)
    """Imagined rows kept (0: no model memory)."""
    real_share: float = struct.field(pytree_node=False, default=1.0)
    """With a model memory holding rows: the share of each batch drawn from the real one
    (MBPO's 5%), the rest from the model's."""


@struct.dataclass
class SquashedActions:
    """What the trainer reads of a policy's actions: continuous, `size` of them in [-1, 1]
    (the env maps them onto its actuators)."""

    size: int = struct.field(pytree_node=False)
    discrete: bool = struct.field(pytree_node=False, default=False)

    @property
    def model_action_size(self) -> int:
        return self.size

    def env_action(self, action: Array) -> Array:
        return jnp.clip(action, -1.0, 1.0)

    def model_action(self, action: Array) -> Array:
        return self.env_action(action)


WARMUP_STREAM = 0x3A7
"""Folded into an acting key for the warm-up's uniform actions (`SACConfig.random_steps`),
so that the policy's own draw keeps its key."""


class SACLearner:
    """SAC behind the learner protocol the rollout and the trainer call (`act`, `greedy`,
    `observe`, `update` after each segment of n real steps x W workers)."""

    def __init__(
        self, config: AgentConfig, sac: SACConfig, obs_size: int, action_spec, memories: Memories
    ):
        """`config`: its discount (`gamma`) and segment length (`n_steps`)."""
        if getattr(action_spec, "discrete", True):
            raise ValueError("sac is for continuous actions")
        self.config, self.own, self.memories = config, sac, memories
        self.policy = SquashedActions(action_spec.size)
        self.sac = SAC(sac, obs_size, action_spec.size, gamma=config.gamma)
        self.obs_size = obs_size

    @classmethod
    def of(cls, config: Config, obs_size: int, action_spec) -> SACLearner:
        budget = config.steps or config.sac.buffer_capacity
        memories = Memories(real=min(config.sac.buffer_capacity, budget))
        if config.algorithm.uses_model:
            imagined = config.sac.model_retain * config.remembered_rows
            memories = Memories(memories.real, imagined, config.imagine.real_share)
        return cls(config.agent, config.sac, obs_size, action_spec, memories)

    def _empty(self, capacity: int) -> Buffer:
        zeros = lambda *shape: jnp.zeros((capacity, *shape), jnp.float32)
        obs, size = self.obs_size, self.policy.size
        rows = Transitions(zeros(obs), zeros(size), zeros(), zeros(obs), zeros())
        return Buffer(data=rows, size=jnp.zeros((), jnp.int32), cursor=jnp.zeros((), jnp.int32))

    def init(self, key: Array) -> SACRun:
        state = self.sac.init(key)
        replay = self._empty(self.memories.real)
        if not self.memories.imagined:
            return SACRun(state.params, state.opt_state, replay)
        return MBPORun(state.params, state.opt_state, replay, self._empty(self.memories.imagined))

    def act(self, params: dict, key: Array, obs: Array) -> Array:
        return self.sac.act(params, key, obs)

    def behave(self, state: SACRun, key: Array, obs: Array) -> Array:
        """The action in the real env: uniform in [-1, 1] while the replay memory holds fewer
        than `random_steps` rows (the warm-up), the policy's after."""
        action = self.sac.act(state.params, key, obs)
        if not self.own.random_steps:
            return action
        uniform = jax.random.uniform(
            jax.random.fold_in(key, WARMUP_STREAM), action.shape, action.dtype, -1.0, 1.0
        )
        return jnp.where(state.replay.size < self.own.random_steps, uniform, action)

    def greedy(self, params: dict, obs: Array) -> Array:
        return self.sac.greedy(params, obs)

    def env_action(self, action: Array) -> Array:
        return self.policy.env_action(action)

    def observe(self, state: SACRun, segment) -> SACRun:
        return state

    def update(self, state: SACRun, segment, key: Array) -> tuple[SACRun, dict]:
        """Add the segment's live rows `[n, W]` to the replay memory, then make `utd` updates
        per row of the segment once the memory holds `learning_starts` (none before: the
        losses read 0 there), each on a batch drawn by `sample`. The count is the scan's
        length, so it is fixed: every row counts, live or not (under the `steps` schedule
        every row is live)."""
        replay = _add(state.replay, segment)
        updates = self.own.utd * segment.weight.size
        sample = lambda key: self.sample(replay, getattr(state, "imagined", None), key)
        inner = SACState(state.params, state.opt_state)

        def learn(inner):
            return self.sac.learn(inner, sample, key, updates)

        def wait(inner):
            shapes = jax.eval_shape(learn, inner)[1]
            return inner, jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), shapes)

        ready = replay.size >= max(self.own.learning_starts, 1)
        inner, losses = jax.lax.cond(ready, learn, wait, inner)
        return state.replace(params=inner.params, opt_state=inner.opt_state, replay=replay), losses

    def sample(self, replay: Buffer, imagined: Buffer | None, key: Array) -> Transitions:
        """One batch: from the replay memory alone, or, once the model memory holds rows,
        `real_share` of it real (rounded) and the rest imagined (MBPO's mix)."""
        size = self.own.batch_size
        if imagined is None:
            return buffer_sample(replay, key, size)
        k_all, k_real, k_model = jax.random.split(key, 3)
        alone = buffer_sample(replay, k_all, size)
        real = round(size * self.memories.real_share)
        mixed = jax.tree.map(
            lambda a, b: jnp.concatenate([a, b]),
            buffer_sample(replay, k_real, real),
            buffer_sample(imagined, k_model, size - real),
        )
        return jax.tree.map(lambda m, a: jnp.where(imagined.size > 0, m, a), mixed, alone)

    def remember(self, state: MBPORun, steps) -> MBPORun:
        """The live rows of imagined `steps` `[T, W]` into the model memory."""
        return state.replace(imagined=_add(state.imagined, steps))


def _add(memory: Buffer, steps) -> Buffer:
    """The live rows (weight > 0) of `steps` `[T, W]` appended to `memory`."""
    flat = lambda x: x.reshape((-1, *x.shape[2:]))
    rows = Transitions(
        obs=flat(steps.obs),
        action=flat(steps.action),
        reward=flat(steps.reward),
        next_obs=flat(steps.next_obs),
        terminated=flat(steps.terminated).astype(jnp.float32),
    )
    return buffer_add(memory, rows, flat(steps.weight) > 0)
