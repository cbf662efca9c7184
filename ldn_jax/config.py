"""Typed, frozen configuration: one dataclass per part, presets as data, one-line validation.

The defaults are the `paper` preset: the paper's network sizes and the public A3C CartPole
code's constants it matches (gamma 0.9, RMSProp 1e-3, n-step 10, entropy 0.001, ReLU6 hidden
layers, N(0, 0.1) weights, 8 workers; docs/paper.md). Presets and per-task defaults are data in
`ldn_jax.presets`; `resolution` applies them in their one order of precedence.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import types
import typing
from dataclasses import dataclass, field

from ldn_jax import envs, networks, presets
from ldn_jax.envs.mujoco import BACKEND_CHOICES, resolve_backend
from ldn_jax.presets import Layer

ACTIVATIONS = tuple(networks.ACTIVATIONS)
"""Hidden activations the networks know (`ldn_jax.networks` owns them)."""

INITS = tuple(networks.INITS)
"""Weight initialisers of actor and critic (`AgentConfig.init`)."""

IMAGINE_MODES = ("episodes", "memory", "batch")
"""How the imagined stage feeds the learner (`ImagineConfig.mode`)."""

IMAGINE_STARTS = ("initial", "real")
"""Where imagined rollouts start (`ImagineConfig.start`): a fresh initial state (the
paper's), or a state of the real buffer (branched, ours in the style of MBPO)."""

IMAGINED_STEPS = ("sample", "mean")
"""What a probabilistic ensemble's imagined step is (`ModelConfig.imagined_step`)."""

WORLDS = ("model", "true", "true-reward", "true-state")
"""What steps imagined rollouts (`ModelConfig.world`)."""

TERMINATIONS = ("known", "learned")
"""What ends an imagined episode as a termination (`ImagineConfig.termination`)."""

IMAGINED_STD = ("learn", "real")
"""What branched imagination's updates do to a state-independent log std
(`ImagineConfig.std`)."""

IMAGINED_UPDATES = ("all", "critic")
"""What branched imagination's updates train (`ImagineConfig.updates`)."""

SCHEDULES = ("episodes", "steps")
"""What one iteration of real play is (`Config.schedule`)."""

LD_REDUCTIONS = ("mean", "sum")
"""How eq. 3's square is reduced over the model's outputs (`ModelConfig.ld_reduce`)."""

STOP_RULES = ("ld", "m2ac", "macura", "horizon", "mbpo", "oracle", "none")
"""What ends an imagined episode early (`StopConfig.rule`; predicted termination and the
step limit always do): the learning-degree draw (MBRL-LDN), an M2AC-style rank mask on
ensemble disagreement, a MACURA-style adaptive threshold on it, a fixed horizon (MBPO's
rollout length), MBPO's horizon schedule, an oracle on the true one-step error, or nothing
(A3C-Model)."""

ENSEMBLE_RULES = ("m2ac", "macura")
"""The stopping rules that read an ensemble's disagreement (they need `ld` "ensemble")."""

ACTION_ENCODINGS = ("one-hot", "index", "force")
"""How the dynamics model takes a discrete action (`ModelConfig.action_encoding`)."""

LD_ESTIMATORS = ("m0", "ensemble", "variance")
"""How the learning degree is estimated: M1 against its frozen initial copy M0 (eq. 3-6), the
disagreement of an ensemble of models, or a probabilistic ensemble's own predicted variance
(`ldn_jax.learning_degree`)."""


@dataclass(frozen=True)
class Algorithm:
    """What an algorithm name switches on. The algorithms share one code path."""

    learner: str
    """Which learner trains the actor-critic: "a2c" (synchronous A3C), "ppo" or "sac"."""
    uses_model: bool
    """Fit M1 on real transitions and train the agent on imagined episodes too."""
    ld_stop: bool
    """Stop imagined episodes by the learning-degree draw (MBRL-LDN)."""
    own_stop: str = ""
    """The stop rule where none is given (`StopConfig.rule` None): "ld" for an LD algorithm,
    "none" for the other model-based ones, MBPO's schedule ("mbpo") for sac-model."""

    @property
    def stop(self) -> str:
        return self.own_stop or ("ld" if self.ld_stop else "none")


ALGORITHMS: dict[str, Algorithm] = {
    "a2c": Algorithm("a2c", uses_model=False, ld_stop=False),
    "a2c-model": Algorithm("a2c", uses_model=True, ld_stop=False),
    "ldn": Algorithm("a2c", uses_model=True, ld_stop=True),
    "a2c-ldn": Algorithm("a2c", uses_model=True, ld_stop=True),
    "ppo": Algorithm("ppo", uses_model=False, ld_stop=False),
    "ppo-model": Algorithm("ppo", uses_model=True, ld_stop=False),
    "ppo-ldn": Algorithm("ppo", uses_model=True, ld_stop=True),
    "sac": Algorithm("sac", uses_model=False, ld_stop=False),
    "sac-model": Algorithm("sac", uses_model=True, ld_stop=False, own_stop="mbpo"),
    "sac-ldn": Algorithm("sac", uses_model=True, ld_stop=True),
}

THRESHOLDS = {"cartpole-v0": 150.0, "cartpole-v1": 150.0, "cartpole-v2": 100.0}
"""The paper's Table 2/3 thresholds on the moving return."""


@dataclass(frozen=True)
class AgentConfig:
    """The actor-critic and what its learners share."""

    gamma: float = 0.9
    """Discount factor."""
    n_steps: int = 10
    """Update the actor-critic every this many steps (and at episode end), n-step bootstrap."""
    entropy_beta: float = 0.001
    """Weight of the policy entropy bonus."""
    actor_lr: float = 1e-3
    """Learning rate of the actor (RMSProp for A2C, Adam for PPO)."""
    critic_lr: float = 1e-3
    """Learning rate of the critic (RMSProp for A2C, Adam for PPO)."""
    rmsprop_decay: float = 0.9
    """RMSProp decay of the squared-gradient average (TensorFlow 1's default)."""
    rmsprop_eps: float = 1e-10
    """RMSProp epsilon (TensorFlow 1's default)."""
    adam_eps: float = 1e-8
    """PPO: Adam's epsilon (optax's and PyTorch's default; SB3's PPO uses 1e-5, which damps
    the steps of weights whose gradients are smaller than about it)."""
    actor_hidden: int = 200
    """Hidden units of the actor's single hidden layer."""
    critic_hidden: int = 100
    """Hidden units of the critic's single hidden layer."""
    hidden_layers: int = 1
    """Hidden layers of actor and critic, each `actor_hidden` / `critic_hidden` wide (1: the
    paper's three-layer nets; SB3's zoo uses 2 of 256 for MuJoCo)."""
    activation: str = "relu6"
    """Hidden activation of actor and critic."""
    init_std: float = 0.1
    """Standard deviation of the normal weight initialiser."""
    init: str = "normal"
    """How actor and critic weights start, one of `INITS`: "normal", a normal of `init_std`
    in every layer (the tutorial code's); "fan_in", uniform in +-1/sqrt(fan_in), PyTorch's
    default for a linear layer's weights, biases at zero; "torch", PyTorch's default in full,
    biases uniform in +-1/sqrt(fan_in) too (SB3's PPO without its orthogonal init);
    "orthogonal", SB3's own: orthogonal weights of gain sqrt(2) in the hidden layers, 0.01 in
    the actor's output and 1 in the critic's, biases at zero."""
    normalize_obs: bool = False
    """Actor and critic see observations standardised by the running mean and variance of
    the real observations seen so far, clipped to +-`obs_clip` standard deviations, as SB3's
    VecNormalize does. The statistics live in the parameters (`params["obs_norm"]`), so a
    saved policy carries them; imagined observations do not move them."""
    obs_clip: float = 10.0
    """Under `normalize_obs`, standardised observations are clipped to +-this (SB3's
    VecNormalize default, 10)."""
    normalize_reward: bool = False
    """The learner trains on the reward divided by the running standard deviation of each
    real worker's discounted return (discounted by `gamma`, reset at each episode's end),
    clipped to +-10 (`REWARD_CLIP` in `ldn_jax.learners.base`), as SB3's VecNormalize does;
    then times `reward_scale`. The statistics live in the parameters
    (`params["reward_norm"]`); imagined rewards are divided by them but do not move them."""
    min_std: float = 1e-4
    """Continuous actions: the Gaussian policy's std is softplus(.) + min_std."""
    log_std_init: float | None = None
    """Continuous actions: None, the std is an output of the actor (softplus(.) + `min_std`,
    the tutorial code's); a number, the std is exp of a learned log std per action
    dimension, the same in every state, starting at this value (SB3's PPO: 0; its zoo's
    MuJoCo runs: -2)."""
    squash_mean: bool = True
    """Continuous actions: the Gaussian's mean is tanh(.) scaled into the action bounds (the
    tutorial code's); False: the mean is the actor's output scaled by the bounds' half-width
    and unbounded, and the env gets the sampled action clipped to the bounds (SB3's PPO), so
    a policy can push an action to its bound and keep it there."""
    terminal_reward: float | None = None
    """If set, the training reward of a terminating step is replaced by this value (the
    tutorial code uses -5). Reported returns are always the environment's own."""
    reward_scale: float = 1.0
    """The learner trains on the env's reward times this (after `terminal_reward`), so the
    critic's targets stay near 1 where returns run to thousands. Reported returns are the
    environment's own."""


@dataclass(frozen=True)
class A2CConfig:
    """The A2C family's own constants (a2c, a2c-model, ldn). The defaults are the paper's
    (A3C as its tutorial code runs it in TensorFlow 1); the other values are SB3's A2C, which
    rl-baselines3-zoo runs on MuJoCo."""

    gae_lambda: float = 1.0
    """Lambda of generalised advantage estimation; 1: the n-step return (A3C, the paper;
    SB3's A2C too)."""
    value_coef: float = 1.0
    """Weight of the value loss in the one loss (the paper: 1; SB3: 0.5). Under the per-net
    RMSProp steps it matters only through `max_grad_norm`."""
    max_grad_norm: float | None = None
    """None: no clip (the paper); a number: the gradients of actor and critic together are
    clipped to this global norm before the RMSProp step (SB3: 0.5)."""
    rmsprop: str = "tf1"
    """One of `RMSPROPS`. "tf1": TensorFlow 1's RMSProp, the paper's code (`agent.rmsprop_eps`
    inside the square root, the average of squared gradients starting at one); "torch":
    PyTorch's, SB3's (eps added to the root, the average starting at zero)."""


RMSPROPS = ("tf1", "torch")
"""The RMSProp variants of the A2C family (`A2CConfig.rmsprop`)."""


@dataclass(frozen=True)
class PPOConfig:
    """PPO's own constants (the `ppo` learner: ppo, ppo-model, ppo-ldn)."""

    gae_lambda: float = 0.95
    """PPO: lambda of generalised advantage estimation."""
    clip_eps: float = 0.2
    """PPO: clip range of the probability ratio."""
    value_clip: float | None = 0.2
    """PPO: clip range of the value change from V_old, in the critic's units (PPO2's value
    clip); None: an unclipped value loss."""
    epochs: int = 4
    """PPO: passes over each segment's transitions."""
    minibatches: int = 4
    """PPO: minibatches per pass (the segment's W * n_steps rows, shuffled)."""
    value_coef: float = 0.5
    """PPO: weight of the value loss."""
    max_grad_norm: float = 0.5
    """PPO: gradients are clipped to this global norm before the Adam step."""
    target_kl: float | None = None
    """PPO: None, every epoch runs; a number, an update stops (skips its remaining minibatch
    steps) at the first minibatch whose approximate KL from the rollout's policy exceeds 1.5
    times it, as SB3's `target_kl` does. The losses then report `kl_stopped`, the share of
    the update's minibatch steps skipped."""


@dataclass(frozen=True)
class SACConfig:
    """Soft actor-critic's own constants (the `sac` learner); the defaults are MBPO's and
    SBX's for MuJoCo (docs/logs/mbpo-reference.md). Its discount is `agent.gamma`."""

    hidden: int = 256
    """Units of each hidden layer (ReLU) of the actor and of each of the twin critics."""
    layers: int = 2
    """Hidden layers of the actor and of each critic."""
    lr: float = 3e-4
    """Adam's learning rate of the actor, the critics and the temperature."""
    tau: float = 0.005
    """Polyak step of the target critics after every critic update."""
    batch_size: int = 256
    """Transitions in each update's batch, drawn uniformly from the replay memory."""
    utd: int = 1
    """Updates per real step (the update-to-data ratio): each segment of n steps x W
    workers is followed by utd x n x W updates, all in one `lax.scan`."""
    learning_starts: int = 1000
    """Real transitions in the replay memory before the first update (per run)."""
    random_steps: int = 0
    """Real transitions at the start of a run played with actions drawn uniformly from
    [-1, 1] instead of the policy's (SB3's and Spinning Up's warm-up; the zoo's halfcheetah
    run: 10,000, with `learning_starts` 10,000); 0: the policy acts from the first step.
    The locomotion tasks set both to 10,000 (`presets.TASKS`), the `branched` preset to
    5,000 (MBPO's)."""
    buffer_capacity: int = 1_000_000
    """Real transitions the replay memory keeps per run (a ring); a run allocates at most
    its steps budget."""
    target_entropy: float | None = None
    """The entropy the temperature steers toward; None: minus the action dimension."""
    init_alpha: float = 1.0
    """The temperature at the start."""
    critic_first: bool = False
    """True: each update steps the critics first and then the actor and the temperature, the
    actor against the critics after that step (SB3's, SBX's and CleanRL's order). False: one
    gradient of the three summed losses, the actor against the critics before the step (the
    three train ops of one step, as softlearning, MBPO's SAC, runs them)."""
    model_retain: int = 4
    """sac-model, sac-ldn: the model memory keeps the imagined rows of this many iterations'
    branches (a ring of that many times the most one iteration imagines), MBPO's retention
    (one epoch of 1,000 steps = 4 model fits of 250)."""


@dataclass(frozen=True)
class ModelConfig:
    """The dynamics model M1, its frozen twin M0 and how its learning degree is read (how M1
    is fitted: `FitConfig`)."""

    ld: str = "m0"
    """Learning-degree estimator, one of `LD_ESTIMATORS`: "m0" compares M1 with M0 (eq. 3-6;
    with `probabilistic`, the drawn elite's mean prediction with that member's own frozen
    initial copy);
    "ensemble" fits `ensemble` independently initialised models instead of one, imagines with
    their mean prediction, and takes LD = 2 sigmoid(-K d_rel) from their disagreement relative
    to their fit error."""
    ensemble: int = 5
    """Members E of the ensemble (used only when `ld` is "ensemble")."""
    ld_reduce: str = "mean"
    """How eq. 3's square (M1 - M0)^2 is reduced over the model's outputs (the next
    observation's dimensions and the reward), one of `LD_REDUCTIONS`: "mean" (the literal
    reading, the `paper` preset) or "sum" (D + 1 times larger; `paper-fig5`). An ensemble's
    disagreement is reduced the same way."""
    ld_window: int = 1
    """The deviation an imagined step's LD reads is the sum over the last B steps of its
    episode, the steps taken so far where fewer (the paper: "the input size is 10
    batches"); 1: the step's own (the literal reading)."""
    ld_scale: float = 1.0
    """The deviation is multiplied by this before K (eq. 6): a reading's scale, kept apart
    from K so that Figure 9's K in {0.5, 1, 2} keeps its meaning."""
    action_encoding: str = "one-hot"
    """How the model takes a discrete action, one of `ACTION_ENCODINGS`: "one-hot" (ours,
    the default), "index" (the action's index as one number) or "force" (the force it
    applies, as one number: Table 1 gives CartPole's actions as forces). Continuous actions
    always go in as the clipped vector."""
    probabilistic: bool = False
    """Each member of the ensemble (`ld` "ensemble" or "variance") outputs a Gaussian over
    the standardised next observation and reward, fitted by negative log-likelihood with
    learned bounds on its log variance (PETS, MBPO); an imagined step samples from one
    elite member drawn at random. A tenth of the buffer's slots is held out to rank the
    members (`elites`). False: each member predicts a point, trained by eq. 2's squared
    error, and imagination steps their mean."""
    elites: int | None = None
    """`probabilistic`: the members with the lowest held-out error that imagine (None: all)."""
    imagined_step: str = "sample"
    """`probabilistic`, one of `IMAGINED_STEPS`: "sample" (MBPO's, PETS's): a draw from the
    Gaussian of one elite picked at random; "mean": the elites' mean prediction, no draw (a
    simulator is deterministic, and the drawn noise is about half of a hopper model's
    one-step reward error: docs/logs/imagination.md)."""
    world: str = "model"
    """One of `WORLDS`. "model": imagined steps are the model's predictions (the method).
    "true", for studies: the real simulator stepped from each imagined observation stands in
    for the model's prediction (next observation, reward, termination), so imagination is
    what a perfect model would give, an upper bound, at no cost in real steps; the model is
    still fitted, and the learning degree and the stopping rules still read it. Needs an env
    whose observation is its state (`Env.from_observation`). "true-reward": the model's next
    observation with the real env's reward and termination from the imagined state (which of
    the two a perfect model's gain comes from); "true-state": the real next observation and
    termination with the model's reward."""
    hidden_layers: int = 1
    """`probabilistic`: hidden layers of each member's net, `hidden` units each (the
    paper's model is two nets of one hidden layer, kept when not probabilistic)."""
    hidden: int = 200
    """Hidden units of each of the two model nets ((s, a) -> s' and s' -> r)."""
    activation: str = "linear"
    """Hidden activation; the paper's nets have none ("linear")."""
    predict_delta: bool = False
    """Predict s' - s instead of s'."""
    env_reward: bool = False
    """Imagined rewards from the env's exact reward function where it has one (MuJoCo:
    inverted_pendulum, reacher); the learned reward net otherwise and always when False."""
    normalize: bool = False
    """Work in standardised units (observation and reward mean/std of the real buffer,
    refreshed before each fit): for MuJoCo's 11- to 27-dimensional observations."""
    init_std: float = 0.1
    """Standard deviation of the normal weight initialiser of M1 (and so of M0)."""
    penalty: float = 0.0
    """Pessimism (MOPO's reward penalty, Yu et al. 2020, read on our estimator): each imagined
    reward minus `penalty` times the step's uncertainty, the ensemble estimator's statistic
    (`ld` "ensemble": the members' disagreement relative to their fit error, about 1 where
    they disagree as much as they err; "variance": the drawn member's predicted variance)
    before `ld_scale` and the window. Needs `ld` "ensemble" or "variance" and `world`
    "model"; the logged imagined returns include it, and `agent.terminal_reward` replaces it
    on terminal steps. It lowers the value
    of states the model is unsure of, where a policy would otherwise exploit its errors.
    0: off."""
    buffer_capacity: int = 50_000
    """Real transitions kept per seed and K (a ring buffer: the oldest are overwritten)."""
    support: float | None = None
    """An imagined episode stops (a truncation: the critic bootstraps) at a predicted
    observation outside the box of real observations in the buffer, widened on each side
    by this fraction of the box's width; None: never. M1 is fitted on real transitions
    only, so outside that box its prediction is extrapolation (the paper's linear nets drive
    inverted_pendulum's cart through its rails: docs/defaults.md)."""


@dataclass(frozen=True)
class FitConfig:
    """How M1 is fitted on R (the model's stage): its optimiser, its steps, MBPO's early
    stopping. Split from `ModelConfig` on 2026-12-07; `model.lr` and the others still read."""

    lr: float = 1e-3
    """Adam learning rate of M1."""
    updates: int = 100
    """Minibatch gradient steps on M1 per iteration (the paper: 100 per episode). Under
    `early_stop`, the most one fit takes: it ends at the first epoch that reaches this many
    steps, converged or not (0: no cap, MBPO's fit). MBPO's own code caps a fit by seconds
    (`max_model_t`); a count of steps keeps a run's bits."""
    early_stop: bool = False
    """`model.probabilistic`: fit as MBPO does, toward convergence: epochs of one pass over R's
    training slots, until no member's error on held-out transitions has fallen by 1% for 5
    epochs in a row (at most 1,000 epochs, and `updates` steps where that is not 0), each
    member back at its best (`Dynamics.fit_until_stalled`)."""
    value_loss: float = 0.0
    """Weight of a value-equivalence term in M1's fit (ours, for studies, in the style of
    value-aware model learning, Farahmand et al. 2017): the squared difference between the
    learner's critic at the predicted (mean) next observation and at the real one, over the
    critic's variance on the batch's real next observations, added to each step's loss. It
    asks the model to be right where the critic at a branch's cut reads it. 0: off."""
    batch_size: int = 64
    """Minibatch size of each model step, drawn uniformly from the real buffer."""
    weight_decay: float = 0.0
    """L2 penalty on M1's weights: this times half the sum of the squares of every layer's
    kernel (not its biases) is added to each step's loss, one value for all layers (MBPO
    weighs its layers 2.5e-5 at the input to 1e-4 at the output). 0: off."""


@dataclass(frozen=True)
class StopConfig:
    """What ends an imagined rollout early, and the parameters of each rule."""

    rule: str | None = None
    """What ends an imagined episode early, one of `STOP_RULES` (None: the algorithm's own,
    "ld" for ldn and ppo-ldn, "none" for a2c-model and ppo-model; `Config.stop_rule`).
    Every rule ends the episode after the step it judges, as a truncation (the critic
    bootstraps from the predicted state), as Algorithm 1's LD draw does: rules differ only
    in when they stop.
    "ld": stop with probability 1 - LD (eq. 5), LD from `ld`'s estimator and K.
    "m2ac": at each imagined step, of the rollouts still running only the `m2ac_keep` share
    the ensemble is most confident about (lowest disagreement, nearest whole count) goes on,
    in the style of M2AC (Pan et al. 2020); needs `ld` "ensemble".
    "macura": stop where the ensemble's disagreement passes a threshold set afresh each
    iteration, `macura_scale` times the `macura_quantile` quantile of the disagreement on
    the first imagined step from the rollouts' start states, in the style of MACURA
    (Frauenknecht et al. 2024); needs `ld` "ensemble".
    "horizon": every imagined episode is cut after `horizon` steps (MBPO's rollout length).
    "mbpo": the cut grows with the real steps taken, MBPO's schedule: `horizon_min` steps
    until `horizon_from` real steps, `horizon_max` from `horizon_to`, linear between.
    "oracle": stop where the true one-step error, ||M1(s, a) - env(s, a)|| on the next
    observation with the real env stepped from the imagined state, exceeds `oracle_error`:
    the ceiling of any estimator (envs whose observation is their state: CartPole,
    inverted_pendulum, halfcheetah, hopper, walker2d).
    "none": only predicted termination and the step limit (A3C-Model)."""
    horizon: int = 5
    """`stop` "horizon": imagined steps per episode from initial states (MBPO's h; h in
    {1, 5, 25} is the study). Branches are cut by `cut`."""
    m2ac_keep: float = 0.5
    """`stop` "m2ac": the share of running imagined rollouts kept at each step."""
    macura_quantile: float = 0.95
    """`stop` "macura": the quantile of the first step's disagreement the threshold scales."""
    macura_scale: float = 1.0
    """`stop` "macura": the threshold is this times that quantile."""
    horizon_min: int = 1
    """`stop` "mbpo": the horizon until `horizon_from` real steps."""
    horizon_max: int = 15
    """`stop` "mbpo": the horizon from `horizon_to` real steps on."""
    horizon_from: int = 20_000
    """`stop` "mbpo": real steps (per run) where the horizon starts to grow."""
    horizon_to: int = 100_000
    """`stop` "mbpo": real steps where it reaches `horizon_max`."""
    oracle_error: float = 0.01
    """`stop` "oracle": the largest true one-step error (L2, the observation's units) that
    does not stop; about 3 times the median one-step error of an ldn model on cartpole-v2
    after 200 episodes (docs/defaults.md)."""


@dataclass(frozen=True)
class ImagineConfig:
    """Where imagined rollouts start, how many there are, and what their updates move."""

    mode: str = "episodes"
    """How imagined steps reach the learner, one of `IMAGINE_MODES`:
    "episodes": each worker plays one imagined episode and the learner updates on every n
    steps of it, as on real ones (Algorithm 1 read literally; workers whose episode the LD
    stopped idle as weight-0 rows).
    "memory" (PPO only): the same episodes, but their steps go to the imaginary memory I
    (Algorithm 1, line 4: "train with batch data in I", line 26) as PPO rows, and PPO
    learns from each full rollout's worth (n_steps x workers rows) once it exists. The LD
    still sets how much is imagined; only the batch PPO learns from is whole.
    "batch": a worker whose imagined episode ends starts the next from a fresh initial
    state, until every worker has ended one and at least one segment is full: a fixed
    quota of n_steps x workers imagined steps per iteration, whatever the LD.
    The PPO family uses "memory" (`ldn_jax.presets.LEARNER`)."""
    start: str = "initial"
    """Where an imagined rollout starts, one of `IMAGINE_STARTS`.
    "initial": a fresh initial state of the env (Algorithm 1, line 17; the paper's).
    "real" (ours, branched in the style of MBPO): a state drawn uniformly from the real
    buffer R. `branches` rollouts run side by side, each cut after `cut` steps (stop
    "mbpo": its scheduled horizon) or sooner by `stop`, as a truncation, and followed at
    once by another from a fresh draw, until the iteration has imagined `ratio`
    steps per real step (whole segments). The learner updates on every n steps of the
    `branches` rollouts, so every update is a full batch; `imagine` is not read. The
    off-policy learners (sac-model, sac-ldn) play MBPO's layout instead: `branches` rollouts,
    one from each start, each until its cut, rule or predicted termination ends it, none
    after it; `ratio` is not read there."""
    branches: int = 64
    """`start` "real": the imagined rollouts played side by side (sac-model, sac-ldn: the
    starts per iteration)."""
    cut: int = 5
    """`start` "real": a branch is cut after this many steps (stop "mbpo": after its
    scheduled horizon instead), or sooner by `stop`."""
    start_window: int = 0
    """`start` "real": branches start from states of the newest `start_window` real
    transitions in R; 0 draws from all of R (MBPO's way, for an off-policy learner). An
    on-policy learner's updates are meant for the states its current policy visits, where
    all of R holds every earlier policy's (on hopper at 200k steps, half of it from the
    first 100k: mostly falls)."""
    ratio: float = 4.0
    """`start` "real": imagined steps per real step of the iteration (at least; in
    whole segments of `branches` x n steps)."""
    real_share: float = 0.0
    """`start` "real": the share of real rows in each update on imagined ones, in
    [0, 1): beside the `branches` imagined rollouts the learner gets the nearest whole
    number of n-step windows of this iteration's real play (MBPO mixes in 5%)."""
    std: str = "learn"
    """`start` "real", for a policy with a state-independent log std
    (`AgentConfig.log_std_init`), one of `IMAGINED_STD`. "learn": the updates on imagined
    rows move the log std like every other parameter. "real": they leave it (and its
    optimiser moments) as it was, so the policy's spread is set by the real updates alone;
    imagined updates can otherwise shrink it far faster than real ones do (docs/training.md).
    Two things still see the imagined updates: the step count of the actor's Adam, which
    the log std shares (its bias correction fades a little sooner), and the actor's
    gradient-norm clip, which includes the log std's gradient."""
    updates: str = "all"
    """`start` "real", one of `IMAGINED_UPDATES`: what the branched updates train.
    "all": the whole learner. "critic" (ours, for studies; in the spirit of model-based value
    expansion, Feinberg et al. 2018): the critic only; the actor's and log std's gradients
    and steps are zero there (so a global-norm clip and PPO's KL guard see the critic alone),
    and their optimiser moments stay as the real updates left them. The model's errors then
    reach the policy only through the critic's values, not through advantages on imagined
    rows. The `real_share` rows mixed into those updates train the critic only too."""
    actor_step: float = 1.0
    """`start` "real", in [0, 1] (ours, for studies): the size of the actor's and
    log std's steps on imagined rows, as a share of their own (a learning rate that much
    smaller there); 1 is the whole step. Between `updates` "critic" (no step) and
    "all" (the whole step): the imagined advantages still move the policy, less far than
    the real ones move it per update. Unlike "critic", the imagined gradients enter the
    actor's optimiser moments, its global-norm clip and PPO's KL guard whole."""
    epochs: int = 0
    """`start` "real", for PPO: the epochs of each update on imagined rows; 0 takes
    the learner's own (`PPOConfig.epochs`). Imagined rows are fresh every iteration, so
    fewer passes over more of them is a trade the learner's epochs, chosen for scarce real
    rows, do not make: at halfcheetah's 20 epochs, imagination and its updates are the
    largest share of a branched run's time (docs/logs/imagination.md)."""
    termination: str = "known"
    """What says an imagined step terminated (no bootstrap), one of `TERMINATIONS`: "known":
    the task's own test on the predicted observation (MBPO's static functions; halfcheetah
    never terminates); "learned": a classifier of the next observation fitted beside M1 on
    the real buffer's terminations (a class-balanced cross-entropy, as many Adam steps as
    `fit.updates`; `Dynamics.fit_termination`), for tasks whose test is not known. The real
    buffer then keeps each row's termination."""


@dataclass(frozen=True)
class Config:
    """One training run: an env, an algorithm, and every seed x K it runs in one program."""

    env: str = "cartpole-v2"
    """Environment name (see `ldn_jax.envs.names()`)."""
    algo: str = "ldn"
    """Algorithm: one of `ALGORITHMS`."""
    preset: str = "paper"
    """The preset these values started from (recorded for provenance)."""
    seeds: int = 5
    """Number of seeds, vmapped: seeds `first_seed` .. `first_seed + seeds - 1`."""
    first_seed: int = 0
    """The batch's first seed; seed s starts from PRNG key s, so a run of seeds 5..9 (`--seeds
    5 --first-seed 5`) trains what seeds 5..9 of a 10-seed run train (to float rounding: the
    batch sizes differ) and adds to one of 0..4. Its greedy evaluation draws the episode
    starts every run of 5 seeds draws."""
    k: tuple[float, ...] = (0.5, 1.0, 2.0)
    """Learning-degree gains K (eq. 6), vmapped; K=1 is eq. 4. An algorithm that does not
    stop by the learning degree keeps only the first (`from_preset`): K does nothing there."""
    episodes: int = 1600
    """Real episodes per seed and K, summed over workers. Ignored when `steps` is set."""
    steps: int | None = None
    """Budget in real env steps per seed and K, summed over workers, instead of `episodes`
    (the natural unit where early episodes last 5 steps and late ones 1,000): each run stops
    at the first iteration that reaches it, the batch once every run has."""
    workers: int = 8
    """Synchronous workers (vmapped); one real and one imagined episode each per iteration."""
    schedule: str = "episodes"
    """What an iteration's real play is, one of `SCHEDULES`:
    "episodes": each worker plays one whole episode from a fresh start (Algorithm 1 read
    literally, the `paper` preset): under vmap every worker of every seed and K computes
    until the longest episode of the batch has ended, the rest as weight-0 rows.
    "steps": each worker plays `iteration_steps` real steps, starting its next episode at
    once when one ends; episodes carry over between iterations (the workers' env states
    live in the run's state), are counted as they complete (in the order (step, worker)),
    and no step is masked. M1 is fitted once per iteration, and each worker imagines one
    episode per real episode it ended in the iteration (Algorithm 1's one after each),
    within `iteration_steps` imagined steps (`ImagineConfig.mode` "batch": its fixed
    quota instead).
    The `paper` preset keeps "episodes", the literal reading; `fast` uses "steps", which
    trains faster per run but takes more episodes to the threshold (docs/defaults.md)."""
    iteration_steps: int | None = None
    """Schedule "steps": real steps per worker per iteration, a multiple of `agent.n_steps`
    (None: the env's step limit rounded up to whole segments, so that an iteration is as
    long as the longest episode and M1 is fitted once per episode's worth of steps, as the
    paper fits it once per episode late in training)."""
    max_steps: int | None = None
    """Episode step limit; None: the env's own (gymnasium's: 1,000 for the MuJoCo tasks but
    reacher's 50, CartPole v0/v1/v2 200/500/1,000). The paper ran reacher for 1,000 steps:
    its reproduction sets that here. `ldn-jax eval` plays gymnasium's env with this limit."""
    backend: str = "auto"
    """MuJoCo tasks: physics engine, "native" (MuJoCo's C engine, the fast one on CPU), "mjx"
    (MJX, for GPU/TPU) or "auto" (native on CPU, mjx elsewhere; a run records what it
    resolved to). CartPole ignores it."""
    threshold: float | None = None
    """Moving-return threshold for "episodes to threshold"; None: the env's paper value."""
    moving_decay: float = 0.99
    """Moving return m <- decay * m + (1 - decay) * R, started at the first return."""
    eval_episodes: int = 10
    """Episodes of the deterministic policy evaluated at the end of training (and after
    each chunk where `solved_return` is set)."""
    solved_return: float | None = None
    """Train a run until its greedy policy solves the task: after each chunk (every
    `chunk_iterations` iterations) the greedy policy plays `eval_episodes` episodes in the
    JAX env from fresh starts, and a run whose mean return is at least this stops there
    (frozen, as at its budget); the batch ends once every run has stopped. SB3's
    `StopTrainingOnRewardThreshold` on an `EvalCallback` is the same rule. None: train to
    the budget. The evaluation draws from its own keys, so the training up to the stop is
    the run without it, bit for bit."""
    chunk_iterations: int = 5
    """Iterations per compiled chunk: the host logs and checkpoints between chunks (MuJoCo
    tasks: 1, an iteration there is long)."""
    sweep: tuple[tuple[str, tuple[float, ...]], ...] = ()
    """A grid of float fields, `((name, values), ...)` (`agent.actor_lr`, `fit.lr`, ...: one
    of `SWEEPABLE`): every combination of the values, for every K, is one point of the
    vmapped program (`points`), so a sweep compiles once. Empty: no sweep."""
    agent: AgentConfig = field(default_factory=AgentConfig)
    a2c: A2CConfig = field(default_factory=A2CConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    sac: SACConfig = field(default_factory=SACConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    fit: FitConfig = field(default_factory=FitConfig)
    stop: StopConfig = field(default_factory=StopConfig)
    imagine: ImagineConfig = field(default_factory=ImagineConfig)

    @classmethod
    def from_preset(cls, name: str, **overrides) -> Config:
        """Build a config from a preset plus overrides (top-level fields; agent and model as
        dicts): every field takes the last value `resolution` gives it."""
        given = {name: (value, "given") for name, value in _flat(overrides).items()}
        merged: dict[str, object] = {}
        for _, values in resolution(name, given):
            merged |= values
        top = {n: v for n, v in merged.items() if "." not in n}
        top["k"] = tuple(top["k"])
        parts = {
            section: kind(
                **{n.split(".", 1)[1]: v for n, v in merged.items() if n.startswith(f"{section}.")}
            )
            for section, kind in SECTIONS.items()
        }
        return cls(preset=name, **top, **parts)

    @property
    def uses_k(self) -> bool:
        """Whether K means anything to this run (its imagined episodes stop by the
        learning-degree draw); only then do K values appear in what the run prints."""
        return self.stop_rule == "ld"

    @property
    def stop_rule(self) -> str | None:
        """What ends this run's imagined episodes early (`StopConfig.rule`, or the
        algorithm's own); None for a model-free algorithm."""
        if self.algo not in ALGORITHMS or not ALGORITHMS[self.algo].uses_model:
            return None
        if self.stop.rule is not None:
            return self.stop.rule
        return ALGORITHMS[self.algo].stop

    @property
    def algorithm(self) -> Algorithm:
        return ALGORITHMS[self.algo]

    @property
    def points(self) -> list[dict[str, float]]:
        """The vmapped runs beside the seeds: one `{"k": K, field: value, ...}` per K and
        combination of the sweep's values, K outermost, the sweep's fields in their order
        (the last varying fastest). Without a sweep, `[{"k": K}]` for each K."""
        names = [name for name, _ in self.sweep]
        grid = itertools.product(*(values for _, values in self.sweep))
        combos = [dict(zip(names, combo, strict=True)) for combo in grid]
        return [{"k": k, **combo} for k in self.k for combo in combos]

    def point_name(self, index: int) -> str:
        """How messages and logs name a point: `K=0.5 agent.actor_lr=0.0003`, the parts
        that vary (K only where it matters); "" for a run of one point."""
        point = self.points[index]
        parts = [f"K={point['k']:g}"] if self.uses_k else []
        parts += [f"{name}={point[name]:g}" for name, _ in self.sweep]
        return " ".join(parts)

    def at_point(self, index: int) -> Config:
        """The config of one point: its K alone and its sweep values set, no sweep (a single
        run of the sweep)."""
        point = self.points[index]
        config = dataclasses.replace(self, k=(point["k"],), sweep=())
        return with_values(config, {n: v for n, v in point.items() if n != "k"})

    @property
    def steps_per_iteration(self) -> int:
        """Schedule "steps": real steps per worker per iteration (`iteration_steps`)."""
        if self.iteration_steps is not None:
            return self.iteration_steps
        n = self.agent.n_steps
        return math.ceil(self.episode_limit / n) * n

    def branch_segments(self, max_steps: int) -> int:
        """The most segments a branched stage plays: enough for `imagine.ratio` imagined
        steps per real step of the longest possible iteration (`max_steps`: the episode
        limit, one iteration's real steps per worker under schedule "episodes")."""
        n = self.agent.n_steps
        per_worker = self.steps_per_iteration if self.schedule == "steps" else max_steps
        real = per_worker * self.workers
        return max(1, math.ceil(self.imagine.ratio * real / (self.imagine.branches * n)))

    def branch_rows(self, max_steps: int) -> int:
        """The most imagined rows one branched stage plays (its segments x branches x n)."""
        return self.branch_segments(max_steps) * self.imagine.branches * self.agent.n_steps

    @property
    def branch_horizon(self) -> int:
        """The longest one branch may run: stop "mbpo"'s `horizon_max`, else `imagine.cut`,
        within the episode limit."""
        longest = self.stop.horizon_max if self.stop_rule == "mbpo" else self.imagine.cut
        return min(longest, self.episode_limit)

    @property
    def remembered_rows(self) -> int:
        """The most imagined rows one off-policy branched stage plays (sac-model, sac-ldn):
        `branches` rollouts of at most `branch_horizon` steps, one from each start."""
        return self.imagine.branches * self.branch_horizon

    @property
    def episode_limit(self) -> int:
        """The episode step limit this run plays with (`max_steps`, or the env's)."""
        return self.max_steps or envs.make(self.env)[1].max_steps

    @property
    def iterations(self) -> int:
        """Iterations needed for `episodes` real episodes, rounded up to whole chunks; with a
        `steps` budget, the most it can take (every episode one step long): runs stop as
        they reach it, usually far sooner. Under schedule "steps" a steps budget takes
        exactly its iterations, and an episodes budget at most those of episodes of the
        env's step limit (runs stop as they reach it)."""
        per_chunk = self.workers * self.chunk_iterations
        if self.schedule == "steps":
            steps = self.steps
            if steps is None:
                steps = self.episodes * self.episode_limit
            per_chunk *= self.steps_per_iteration
            return math.ceil(steps / per_chunk) * self.chunk_iterations
        real_episodes = self.episodes if self.steps is None else self.steps
        return math.ceil(real_episodes / per_chunk) * self.chunk_iterations

    @property
    def resolved_threshold(self) -> float | None:
        return self.threshold if self.threshold is not None else THRESHOLDS.get(self.env)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> Config:
        data = dict(data)
        data.pop("run_format", None)  # the run directory's format version, not a setting
        if data.get("env") == "reacher" and "max_steps" not in data:
            data["max_steps"] = 1000  # a run from before reacher took gymnasium's 50 steps
        sections = {name: dict(data.pop(name, {})) for name in SECTIONS}
        sections["model"] = _branch_cut(sections["model"])
        for old, new in ALIASES.items():  # a config from before the split
            (was, key), (now, new_key) = old.split("."), new.split(".")
            if key in sections[was]:
                sections[now][new_key] = sections[was].pop(key)
        parts = {name: kind(**sections[name]) for name, kind in SECTIONS.items()}
        data["k"] = tuple(data.get("k", (1.0,)))
        data["sweep"] = tuple(
            (canonical(name), tuple(values)) for name, values in data.get("sweep", ())
        )
        return cls(**data, **parts)


def _branch_cut(model: dict) -> dict:
    """A model section as this version reads it: a run from before `cut` was its own field
    cut its branches at `horizon`."""
    if model.get("imagine_start") == "real" and "cut" not in model:
        model = {**model, "cut": model.get("horizon", StopConfig.horizon)}
        model.pop("horizon", None)
    return model


from_preset = Config.from_preset
"""`Config.from_preset`, the name callers import."""

SECTIONS = {
    "agent": AgentConfig,
    "a2c": A2CConfig,
    "ppo": PPOConfig,
    "sac": SACConfig,
    "model": ModelConfig,
    "fit": FitConfig,
    "stop": StopConfig,
    "imagine": ImagineConfig,
}
"""`Config`'s nested parts: their fields are named `agent.X`, `ppo.X`, `model.X`, ..."""

_MOVED_STOP = (
    "horizon",
    "m2ac_keep",
    "macura_quantile",
    "macura_scale",
    "horizon_min",
    "horizon_max",
    "horizon_from",
    "horizon_to",
    "oracle_error",
)
_MOVED_IMAGINE = {
    "imagine": "mode",
    "imagine_start": "start",
    "branches": "branches",
    "cut": "cut",
    "start_window": "start_window",
    "imagined_ratio": "ratio",
    "real_share": "real_share",
    "imagined_std": "std",
    "imagined_updates": "updates",
    "imagined_actor_step": "actor_step",
    "imagined_epochs": "epochs",
}
_MOVED_FIT = ("lr", "updates", "early_stop", "batch_size", "value_loss")
ALIASES: dict[str, str] = {
    "model.stop": "stop.rule",
    **{f"model.{name}": f"stop.{name}" for name in _MOVED_STOP},
    **{f"model.{old}": f"imagine.{new}" for old, new in _MOVED_IMAGINE.items()},
    **{f"agent.{name}": f"ppo.{name}" for name in (f.name for f in dataclasses.fields(PPOConfig))},
    **{f"model.{name}": f"fit.{name}" for name in _MOVED_FIT},
}
"""The dotted names of fields that moved when `ModelConfig` and `AgentConfig` were split
(`model.imagine_start` is `imagine.start`; `model.lr` is `fit.lr` since 2026-12-07):
`--set`, `--config`, `--sweep`, `--explain` and a run directory's config.json from before
still read them."""


def canonical(name: str) -> str:
    """A dotted field name as this version spells it (`ALIASES`)."""
    return ALIASES.get(name, name)


PRESETS = presets.PRESETS
"""The presets by name (`ldn_jax.presets`)."""


def resolution(preset: str, given: dict[str, tuple[object, str]]) -> list[Layer]:
    """Every layer that sets fields of one run, lowest first (`ldn_jax.presets`' order), for
    the fields `given` as `{dotted name: (value, where it was given)}`: the defaults, the
    learner's, continuous control's, the task's, the preset's, each source of `given`, then
    the rules. A field's value is the last layer's that sets it."""
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; valid presets: {', '.join(PRESETS)}")
    value = lambda name, default: given[name][0] if name in given else default
    env, algo = value("env", Config.env), value("algo", Config.algo)
    algorithm = ALGORITHMS.get(algo, ALGORITHMS["ldn"])
    found = [("default", _defaults())]
    found += presets.layers(
        preset, env, algorithm.learner, _continuous(env), model_based=algorithm.uses_model
    )
    backend = value("backend", Config.backend)
    on_mjx = presets.ON_MJX.get(env, {}).get(algorithm.learner)
    if on_mjx and backend in BACKEND_CHOICES and resolve_backend(backend) == "mjx":
        found.append((f"MuJoCo on MJX, {env}, {algorithm.learner}", on_mjx))
    sources: dict[str, dict[str, object]] = {}
    for name, (setting, where) in given.items():
        sources.setdefault(where, {})[name] = setting
    found += list(sources.items())
    merged: dict[str, object] = {}
    for _, values in found:
        merged |= values
    if "episodes" in given and "steps" not in given:
        found.append(("rule: a budget in episodes replaces the steps budget", {"steps": None}))
    stop = merged["stop.rule"] or algorithm.stop
    set_ld = any("model.ld" in values for _, values in found[1:])
    if stop in ENSEMBLE_RULES and not set_ld:
        found.append((f"rule: stop {stop} reads ensemble disagreement", {"model.ld": "ensemble"}))
    gains = tuple(merged["k"])
    if not (algorithm.uses_model and stop == "ld") and len(gains) > 1:
        found.append((f"rule: {algo} does not use K, the first is kept", {"k": gains[:1]}))
    return found


def explain(
    preset: str, given: dict[str, tuple[object, str]], name: str
) -> list[tuple[str, object]]:
    """The layers of `resolution` that set the dotted field `name`, lowest first, with the
    value each gives it: the last one is the run's."""
    return [(layer, values[name]) for layer, values in resolution(preset, given) if name in values]


def _defaults() -> dict[str, object]:
    """Every field's dataclass default, by dotted name."""
    return {name: get_field(Config(), name) for name in fields()}


def _flat(overrides: dict) -> dict[str, object]:
    """`from_preset`'s overrides (agent and model as dicts) by dotted name."""
    flat = {}
    for name, value in overrides.items():
        if name in SECTIONS:
            flat |= {canonical(f"{name}.{sub}"): v for sub, v in dict(value).items()}
        else:
            flat[canonical(name)] = value
    return flat


@dataclass(frozen=True)
class FieldType:
    """What values one config field takes, read off its annotation."""

    base: type
    """float, int, str or bool; for a tuple field, the type of its items."""
    optional: bool = False
    """None is a value (`float | None`)."""
    sequence: bool = False
    """A tuple of `base` (`tuple[float, ...]`)."""

    def describe(self) -> str:
        text = f"{self.base.__name__}s, comma-separated" if self.sequence else self.base.__name__
        return text + (" or none" if self.optional else "")


CHOICES: dict[str, tuple[str, ...]] = {
    "algo": tuple(ALGORITHMS),
    "schedule": SCHEDULES,
    "backend": tuple(BACKEND_CHOICES),
    "agent.activation": ACTIVATIONS,
    "agent.init": INITS,
    "model.ld": LD_ESTIMATORS,
    "model.ld_reduce": LD_REDUCTIONS,
    "stop.rule": STOP_RULES,
    "model.action_encoding": ACTION_ENCODINGS,
    "imagine.mode": IMAGINE_MODES,
    "imagine.start": IMAGINE_STARTS,
    "imagine.std": IMAGINED_STD,
    "imagine.updates": IMAGINED_UPDATES,
    "model.imagined_step": IMAGINED_STEPS,
    "model.world": WORLDS,
    "imagine.termination": TERMINATIONS,
    "model.activation": ACTIVATIONS,
}
"""The fields that take one of a list of names, and the names (what `validate` accepts; the
docs' field table lists them, and a test checks each flag's help names them all)."""


def fields() -> dict[str, FieldType]:
    """Every setting of a run by its dotted name (`seeds`, `agent.actor_lr`, `fit.lr`), in
    declaration order, read off the dataclasses' annotations: the one table `--set`,
    `--config` and the CLI's own flags resolve names against. `preset` is not a setting
    (it names where the defaults came from)."""
    table = {}
    for name, hint in typing.get_type_hints(Config).items():
        if name in SECTIONS:
            for sub, sub_hint in typing.get_type_hints(SECTIONS[name]).items():
                table[f"{name}.{sub}"] = _field_type(sub_hint)
        elif name not in ("preset", "sweep"):
            table[name] = _field_type(hint)
    return table


def sweepable() -> tuple[str, ...]:
    """The fields a sweep can vary (`Config.sweep`): every float field the compiled program
    reads as a number. Not: K (`k` is its own axis), `threshold` (read by the host, after
    training), the initialisers' `init_std` and `log_std_init` (read where the parameters
    are made; `init_std` shapes the network modules), the branched imagination's
    `ratio` and `real_share` (they size its batches), the fit's `value_loss` (it
    decides whether the fit reads the critic) and `weight_decay` (whether the loss carries
    the penalty), and every int, bool or str field
    (sizes, counts, choices: they change the program's shapes or code, so they need separate
    runs)."""
    excluded = {
        "threshold",
        "agent.init_std",
        "model.init_std",
        "agent.log_std_init",
        "imagine.ratio",
        "imagine.real_share",
        "fit.value_loss",
        "fit.weight_decay",
    }
    return tuple(
        name
        for name, kind in fields().items()
        if kind.base is float and not kind.sequence and name not in excluded
    )


def with_values(config: Config, values: dict) -> Config:
    """`config` with the dotted fields `values` replaced, unvalidated (the values may be
    traced arrays inside a compiled sweep)."""
    top = {n: v for n, v in values.items() if "." not in n}
    parts = {}
    for section in SECTIONS:
        inner = {n.split(".", 1)[1]: v for n, v in values.items() if n.startswith(f"{section}.")}
        if inner:
            parts[section] = dataclasses.replace(getattr(config, section), **inner)
    return dataclasses.replace(config, **top, **parts)


def _field_type(hint) -> FieldType:
    args = typing.get_args(hint)
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        (inner,) = [a for a in args if a is not type(None)]
        return dataclasses.replace(_field_type(inner), optional=True)
    if typing.get_origin(hint) is tuple:
        return FieldType(args[0], sequence=True)
    if hint not in (float, int, str, bool):
        raise TypeError(f"config field of unsupported type {hint!r}")
    return FieldType(hint)


def get_field(config: Config, name: str):
    """The value of the dotted field `name` (`agent.actor_lr`) in `config`."""
    value = config
    for part in name.split("."):
        value = getattr(value, part)
    return value


def _continuous(env: str) -> bool:
    if env not in envs.names():
        return False  # `validate` reports the unknown name
    env_obj, params = envs.make(env)
    return not env_obj.action_spec(params).discrete


def validate(config: Config) -> Config:
    """Raise ValueError with a one-line message for the first impossible value."""
    if config.env not in envs.names():
        envs.make(config.env)  # raises the registry's one-line error
    if config.algo not in ALGORITHMS:
        raise ValueError(f"unknown algo {config.algo!r}; valid algos: {', '.join(ALGORITHMS)}")
    checks = [
        *_sac_checks(config),
        *_run_checks(config),
        *_agent_checks(config),
        *_model_checks(config),
        *_degree_checks(config),
        *_stop_checks(config),
        *_branch_checks(config),
        *_imagined_update_checks(config),
    ]
    for ok, message in checks:
        if not ok:
            raise ValueError(message)
    # Every check holds whatever the algorithm: a value no run could use is refused even where
    # this run would not read it (a2c has no model, yet model.hidden=-5 is an error).
    for name, kind in fields().items():
        value = get_field(config, name)
        not_a_float = kind.base is not float or kind.sequence or value is None
        if not (not_a_float or math.isfinite(value)):
            raise ValueError(f"{name} must be a finite number, got {value}")
    _validate_sweep(config)
    return config


def advisories(config: Config) -> list[str]:
    """What a valid config does that its user may not expect, one line each (the training
    command prints them as warnings)."""
    sac, notes = config.sac, []
    if ALGORITHMS[config.algo].learner == "sac" and config.schedule == "steps":
        most = config.iterations * config.workers * config.steps_per_iteration
        if most < sac.learning_starts:
            notes.append(
                f"{config.algo} makes no update: it plays at most {most:,} real steps, and its "
                "updates start once the replay memory holds sac.learning_starts "
                f"({sac.learning_starts:,}) rows (--set sac.learning_starts=N)"
            )
    return notes


def _run_checks(config: Config) -> list[tuple[bool, str]]:
    """The checks of the run as a whole: seeds, K, budget, schedule, engine."""
    return [
        (config.seeds >= 1, f"seeds must be >= 1, got {config.seeds}"),
        (config.first_seed >= 0, f"first_seed must be >= 0, got {config.first_seed}"),
        (
            config.preset != "fast" or not _continuous(config.env),
            "preset 'fast' is for CartPole (measured there); MuJoCo tasks have their own defaults",
        ),
        (len(config.k) >= 1, "k needs at least one value"),
        (
            all(k > 0 and math.isfinite(k) for k in config.k),
            f"every K must be > 0 and finite: {config.k}",
        ),
        (
            config.threshold is None or math.isfinite(config.threshold),
            f"threshold must be a finite number, got {config.threshold}",
        ),
        (
            config.solved_return is None or math.isfinite(config.solved_return),
            f"solved_return must be a finite number (or none), got {config.solved_return}",
        ),
        (len(set(config.k)) == len(config.k), f"K values must be distinct: {config.k}"),
        (config.episodes >= 1, f"episodes must be >= 1, got {config.episodes}"),
        (config.steps is None or config.steps >= 1, f"steps must be >= 1, got {config.steps}"),
        (config.workers >= 1, f"workers must be >= 1, got {config.workers}"),
        (
            config.max_steps is None or config.max_steps >= 1,
            f"max_steps must be >= 1 (or none: the env's), got {config.max_steps}",
        ),
        (
            config.schedule in SCHEDULES,
            f"unknown schedule {config.schedule!r}; valid: {', '.join(SCHEDULES)}",
        ),
        (
            config.iteration_steps is None
            or (
                config.iteration_steps >= config.agent.n_steps
                and config.iteration_steps % config.agent.n_steps == 0
            ),
            f"iteration_steps must be a positive multiple of n_steps ({config.agent.n_steps}), "
            f"got {config.iteration_steps}",
        ),
        (
            config.iteration_steps is None or config.schedule == "steps",
            "iteration_steps is schedule steps' (an iteration of schedule episodes is one "
            "episode per worker)",
        ),
        (
            config.backend in BACKEND_CHOICES,
            f"backend must be one of {', '.join(BACKEND_CHOICES)}",
        ),
        (0 < config.moving_decay < 1, "moving_decay must be in (0, 1)"),
        (config.eval_episodes >= 1, "eval_episodes must be >= 1"),
        (config.chunk_iterations >= 1, "chunk_iterations must be >= 1"),
    ]


def _agent_checks(config: Config) -> list[tuple[bool, str]]:
    """The checks of `AgentConfig`: the learner's nets and constants."""
    agent, ppo = config.agent, config.ppo
    return [
        (0 < config.agent.gamma <= 1, f"gamma must be in (0, 1], got {config.agent.gamma}"),
        (config.agent.n_steps >= 1, "n_steps must be >= 1"),
        (agent.actor_hidden >= 1, f"actor_hidden must be >= 1, got {agent.actor_hidden}"),
        (agent.critic_hidden >= 1, f"critic_hidden must be >= 1, got {agent.critic_hidden}"),
        (agent.hidden_layers >= 1, f"hidden_layers must be >= 1, got {agent.hidden_layers}"),
        (
            agent.log_std_init is None or _continuous(config.env),
            "log_std_init is for continuous actions (a Gaussian policy's std)",
        ),
        (
            agent.squash_mean or _continuous(config.env),
            "squash_mean is for continuous actions (a Gaussian policy's mean)",
        ),
        (agent.init_std > 0, f"agent init_std must be > 0, got {agent.init_std}"),
        (agent.min_std > 0, f"min_std must be > 0, got {agent.min_std}"),
        (agent.obs_clip > 0, f"obs_clip must be > 0, got {agent.obs_clip}"),
        (agent.entropy_beta >= 0, f"entropy_beta must be >= 0, got {agent.entropy_beta}"),
        (
            0 <= agent.rmsprop_decay < 1,
            f"rmsprop_decay must be in [0, 1), got {agent.rmsprop_decay}",
        ),
        (agent.rmsprop_eps > 0, f"rmsprop_eps must be > 0, got {agent.rmsprop_eps}"),
        (agent.adam_eps > 0, f"adam_eps must be > 0, got {agent.adam_eps}"),
        (ppo.value_coef >= 0, f"value_coef must be >= 0, got {ppo.value_coef}"),
        (
            config.agent.reward_scale > 0 and math.isfinite(config.agent.reward_scale),
            f"reward_scale must be > 0 and finite, got {config.agent.reward_scale}",
        ),
        (config.agent.actor_lr > 0 and config.agent.critic_lr > 0, "learning rates must be > 0"),
        (config.agent.activation in ACTIVATIONS, f"activation must be one of {ACTIVATIONS}"),
        (config.agent.init in INITS, f"init must be one of {', '.join(INITS)}"),
        (0 <= config.ppo.gae_lambda <= 1, "gae_lambda must be in [0, 1]"),
        (0 <= config.a2c.gae_lambda <= 1, "a2c gae_lambda must be in [0, 1]"),
        (config.a2c.value_coef >= 0, f"a2c value_coef must be >= 0, got {config.a2c.value_coef}"),
        (
            config.a2c.max_grad_norm is None or config.a2c.max_grad_norm > 0,
            "a2c max_grad_norm must be > 0 (or None: no clip)",
        ),
        (
            config.a2c.rmsprop in RMSPROPS,
            f"a2c rmsprop must be one of {', '.join(RMSPROPS)}, got {config.a2c.rmsprop!r}",
        ),
        (config.ppo.clip_eps > 0, "clip_eps must be > 0"),
        (
            config.ppo.value_clip is None or config.ppo.value_clip > 0,
            "value_clip must be > 0 (or None: no clip)",
        ),
        (config.ppo.epochs >= 1, "epochs must be >= 1"),
        (config.ppo.minibatches >= 1, "minibatches must be >= 1"),
        (config.ppo.max_grad_norm > 0, "max_grad_norm must be > 0"),
        (
            config.ppo.target_kl is None or config.ppo.target_kl > 0,
            f"target_kl must be > 0 (or None: no stop), got {config.ppo.target_kl}",
        ),
    ]


def _sac_checks(config: Config) -> list[tuple[bool, str]]:
    """The checks of `SACConfig`, and of what the `sac` learner needs of the run."""
    sac, learner = config.sac, ALGORITHMS[config.algo].learner
    return [
        (sac.hidden >= 1 and sac.layers >= 1, "sac hidden and layers must be >= 1"),
        (sac.lr > 0, f"sac lr must be > 0, got {sac.lr}"),
        (0 < sac.tau <= 1, f"sac tau must be in (0, 1], got {sac.tau}"),
        (sac.batch_size >= 1, f"sac batch_size must be >= 1, got {sac.batch_size}"),
        (sac.utd >= 1, f"sac utd (updates per real step) must be >= 1, got {sac.utd}"),
        (
            sac.learning_starts >= 0,
            f"sac learning_starts must be >= 0, got {sac.learning_starts}",
        ),
        (sac.random_steps >= 0, f"sac random_steps must be >= 0, got {sac.random_steps}"),
        (
            sac.buffer_capacity >= 1,
            f"sac buffer_capacity must be >= 1, got {sac.buffer_capacity}",
        ),
        (sac.init_alpha > 0, f"sac init_alpha must be > 0, got {sac.init_alpha}"),
        (
            sac.model_retain >= 1,
            "sac model_retain must be >= 1 (the model memory holds at least one iteration's "
            f"branches), got {sac.model_retain}",
        ),
        (
            learner != "sac" or not config.algorithm.uses_model or config.imagine.start == "real",
            f"{config.algo} branches from real states (MBPO): use --preset branched (or "
            "imagine.start real)",
        ),
        (
            learner != "sac" or _continuous(config.env),
            f"sac is for continuous actions, and {config.env}'s are discrete; use a2c or ppo",
        ),
        (
            learner != "sac" or config.schedule == "steps",
            "sac plays real steps into its replay memory: it needs schedule 'steps'",
        ),
    ]


def _model_checks(config: Config) -> list[tuple[bool, str]]:
    """The checks of the model's net and its fit (`ModelConfig`)."""
    model = config.model
    return [
        (model.hidden >= 1, f"model hidden must be >= 1, got {model.hidden}"),
        (model.init_std > 0, f"model init_std must be > 0, got {model.init_std}"),
        (config.model.activation in ACTIVATIONS, f"model activation must be one of {ACTIVATIONS}"),
        (config.fit.lr > 0, "fit lr must be > 0"),
        (config.fit.updates >= 0, "fit updates must be >= 0"),
        (
            config.fit.value_loss >= 0,
            f"fit value_loss must be >= 0, got {config.fit.value_loss}",
        ),
        (
            config.fit.weight_decay >= 0 and math.isfinite(config.fit.weight_decay),
            f"fit weight_decay must be >= 0 and finite, got {config.fit.weight_decay}",
        ),
        (config.fit.batch_size >= 1, "fit batch_size must be >= 1"),
        (
            not config.fit.early_stop or model.probabilistic,
            "fit.early_stop fits a probabilistic ensemble: it needs model.probabilistic",
        ),
        (config.model.buffer_capacity >= 1, "buffer_capacity must be >= 1"),
        (config.model.ensemble >= 2, f"ensemble size must be >= 2, got {config.model.ensemble}"),
        (model.hidden_layers >= 1, f"model hidden_layers must be >= 1, got {model.hidden_layers}"),
        (
            model.elites is None or 1 <= model.elites <= model.ensemble,
            f"elites must be in [1, ensemble size {model.ensemble}] (or none: all), got "
            f"{model.elites}",
        ),
        (
            model.imagined_step in IMAGINED_STEPS,
            f"unknown imagined_step {model.imagined_step!r}; valid: {', '.join(IMAGINED_STEPS)}",
        ),
        (
            model.imagined_step == "sample" or model.probabilistic,
            "imagined_step 'mean' is a probabilistic ensemble's: it needs model.probabilistic",
        ),
        (model.world in WORLDS, f"unknown world {model.world!r}; valid: {', '.join(WORLDS)}"),
        (
            model.world == "model" or _observes_state(config.env),
            f"world {model.world!r} steps the real env from imagined observations, and "
            f"{config.env}'s observation is not its whole state{OBSERVES_STATE}",
        ),
        (
            config.model.action_encoding in ACTION_ENCODINGS,
            f"unknown action_encoding {config.model.action_encoding!r}; valid: "
            + ", ".join(ACTION_ENCODINGS),
        ),
        (
            config.model.action_encoding == "one-hot" or not _continuous(config.env),
            "action_encoding is for discrete actions; continuous ones go to the model as "
            "the clipped vector",
        ),
    ]


def _degree_checks(config: Config) -> list[tuple[bool, str]]:
    """The checks of the learning degree's reading, the stopping rules' parameters, pessimism
    and the support box."""
    model, stop = config.model, config.stop
    return [
        (config.model.penalty >= 0, f"model penalty must be >= 0, got {config.model.penalty}"),
        (
            config.model.support is None
            or (config.model.support >= 0 and math.isfinite(config.model.support)),
            f"model support must be >= 0 and finite (or None: no box), got {config.model.support}",
        ),
        (
            config.model.ld_reduce in LD_REDUCTIONS,
            f"unknown ld_reduce {config.model.ld_reduce!r}; valid: {', '.join(LD_REDUCTIONS)}",
        ),
        (config.model.ld_window >= 1, f"ld_window must be >= 1, got {config.model.ld_window}"),
        (
            config.model.ld_scale > 0 and math.isfinite(config.model.ld_scale),
            f"ld_scale must be > 0 and finite, got {config.model.ld_scale}",
        ),
        (
            config.model.ld in LD_ESTIMATORS,
            f"unknown ld {config.model.ld!r}; valid: {', '.join(LD_ESTIMATORS)}",
        ),
        (stop.horizon >= 1, f"horizon must be >= 1, got {stop.horizon}"),
        (
            model.penalty == 0 or model.ld in ("ensemble", "variance"),
            "model penalty reads an ensemble's uncertainty (M1's deviation from M0 grows with "
            "what it has learned, not with what it does not know): set ld 'ensemble' or "
            "'variance'",
        ),
        (
            model.penalty == 0 or model.world == "model",
            f"model penalty is pessimism about the model's steps, and world {model.world!r} "
            "takes the real env's; use world 'model'",
        ),
        (
            1 <= stop.horizon_min <= stop.horizon_max,
            f"the horizon schedule needs 1 <= horizon_min <= horizon_max, got "
            f"{stop.horizon_min} and {stop.horizon_max}",
        ),
        (
            0 <= stop.horizon_from <= stop.horizon_to,
            f"the horizon schedule needs 0 <= horizon_from <= horizon_to, got "
            f"{stop.horizon_from} and {stop.horizon_to}",
        ),
        (
            0 < stop.macura_quantile <= 1,
            f"macura_quantile must be in (0, 1], got {stop.macura_quantile}",
        ),
        (stop.macura_scale > 0, f"macura_scale must be > 0, got {stop.macura_scale}"),
        (
            model.ld != "variance" or model.probabilistic,
            "ld 'variance' reads the members' predicted variance: it needs model.probabilistic",
        ),
        (0 < stop.m2ac_keep <= 1, f"m2ac_keep must be in (0, 1], got {stop.m2ac_keep}"),
        (stop.oracle_error > 0, f"oracle_error must be > 0, got {stop.oracle_error}"),
    ]


def _branch_checks(config: Config) -> list[tuple[bool, str]]:
    """The checks of where imagination starts and how much of it there is (branches)."""
    imagine = config.imagine
    return [
        (imagine.cut >= 1, f"cut must be >= 1, got {imagine.cut}"),
        (
            imagine.start in IMAGINE_STARTS,
            f"unknown imagine.start {imagine.start!r}; valid: {', '.join(IMAGINE_STARTS)}",
        ),
        (imagine.branches >= 1, f"branches must be >= 1, got {imagine.branches}"),
        (imagine.start_window >= 0, f"start_window must be >= 0, got {imagine.start_window}"),
        (
            imagine.start_window == 0 or imagine.start == "real",
            "imagine.start_window picks where branches start: it needs imagine.start 'real'",
        ),
        (
            imagine.start == "initial"
            or config.algo not in ALGORITHMS
            or config.algorithm.uses_model,
            f"imagine.start 'real' branches imagined rollouts, and {config.algo} imagines "
            "none; use a model-based algorithm (-model or -ldn)",
        ),
        (imagine.ratio > 0, f"imagine.ratio must be > 0, got {imagine.ratio}"),
        (0 <= imagine.real_share < 1, f"real_share must be in [0, 1), got {imagine.real_share}"),
        (
            imagine.termination in TERMINATIONS,
            f"unknown termination {imagine.termination!r}; valid: {', '.join(TERMINATIONS)}",
        ),
        (
            config.imagine.mode in IMAGINE_MODES,
            f"unknown imagine {config.imagine.mode!r}; valid: {', '.join(IMAGINE_MODES)}",
        ),
        (
            config.imagine.mode != "memory" or config.algorithm.learner == "ppo",
            "imagine.mode 'memory' needs the PPO learner (A2C learns on every n steps as it plays)",
        ),
    ]


def _imagined_update_checks(config: Config) -> list[tuple[bool, str]]:
    """The checks of what updates on branched imagination's rows may move."""
    imagine = config.imagine
    return [
        (
            imagine.std in IMAGINED_STD,
            f"unknown imagine.std {imagine.std!r}; valid: {', '.join(IMAGINED_STD)}",
        ),
        (
            imagine.std == "learn"
            or (imagine.start == "real" and config.agent.log_std_init is not None),
            "imagine.std 'real' needs branched imagination (imagine.start 'real') and a "
            "policy with a state-independent log std (agent.log_std_init)",
        ),
        (
            imagine.updates in IMAGINED_UPDATES,
            f"unknown imagine.updates {imagine.updates!r}; valid: {', '.join(IMAGINED_UPDATES)}",
        ),
        (
            imagine.updates == "all" or imagine.start == "real",
            "imagine.updates 'critic' needs branched imagination (imagine.start 'real')",
        ),
        (
            0 <= imagine.actor_step <= 1,
            f"imagine.actor_step must be in [0, 1], got {imagine.actor_step}",
        ),
        (
            imagine.actor_step == 1 or (imagine.start == "real" and imagine.updates == "all"),
            "imagine.actor_step scales the actor's steps on branched imagination's rows: it "
            "needs imagine.start 'real' and imagine.updates 'all'",
        ),
        (imagine.epochs >= 0, f"imagine.epochs must be >= 0, got {imagine.epochs}"),
        (
            imagine.epochs == 0 or imagine.start == "real",
            "imagine.epochs sets the epochs on branched imagination's rows: it needs "
            "imagine.start 'real'",
        ),
        (
            imagine.epochs == 0 or config.algorithm.learner == "ppo",
            f"imagine.epochs sets PPO's epochs; {config.algo} is of the A2C family, which "
            "makes one update per segment",
        ),
    ]


def _stop_checks(config: Config) -> list[tuple[bool, str]]:
    """The checks of `StopConfig.rule` and its parameters."""
    stop, model, imagine = config.stop.rule, config.model, config.imagine
    if stop is None:
        return []
    if stop not in STOP_RULES:
        return [(False, f"unknown stop {stop!r}; valid: {', '.join(STOP_RULES)}")]
    algorithm = ALGORITHMS.get(config.algo)
    learner = algorithm.learner if algorithm else "a2c"
    model_based = {
        "a2c": "a2c-model or ldn",
        "ppo": "ppo-model or ppo-ldn",
        "sac": "sac-model or sac-ldn",
    }[learner]
    return [
        (
            algorithm is None or algorithm.uses_model,
            f"stop {stop!r} ends imagined episodes, and {config.algo} imagines none; use "
            f"--algo {model_based}",
        ),
        (
            algorithm is None or not (algorithm.ld_stop and stop == "none"),
            f"{config.algo} with stop 'none' is {learner}-model; use --algo {learner}-model",
        ),
        (
            algorithm is None or algorithm.ld_stop or stop != "ld",
            f"{config.algo} with stop 'ld' is {_ldn(learner)}; use --algo {_ldn(learner)}",
        ),
        (
            stop not in ENSEMBLE_RULES or model.ld == "ensemble",
            f"stop {stop!r} reads the disagreement of an ensemble of models: it needs ld "
            "'ensemble' (its default)",
        ),
        (
            stop != "horizon" or imagine.start != "real",
            "stop 'horizon' cuts imagined episodes from initial states; a branch's cut is "
            "--cut (imagine.cut)",
        ),
        (
            stop != "macura" or imagine.start == "real",
            "stop 'macura' sets its threshold from the branches' start states: it needs "
            "imagine.start 'real' (the branched preset: --preset branched)",
        ),
        (
            stop != "oracle" or _observes_state(config.env),
            f"stop 'oracle' steps the real env from imagined observations, and {config.env}'s "
            f"observation is not its whole state{OBSERVES_STATE}",
        ),
    ]


def _ldn(learner: str) -> str:
    """The algorithm whose imagination the LD draw stops, for `learner`."""
    return "ldn" if learner == "a2c" else f"{learner}-ldn"


OBSERVES_STATE = " (CartPole's, inverted_pendulum's, halfcheetah's, hopper's and walker2d's are)"


def _observes_state(env: str) -> bool:
    """Whether the env can be stepped from an observation (`Env.from_observation`)."""
    if env not in envs.names():
        return True  # `validate` reports the unknown name
    env_obj, params = envs.make(env)
    if hasattr(env_obj, "observes_state"):
        return env_obj.observes_state(params)
    return hasattr(env_obj, "from_observation")


def _validate_sweep(config: Config) -> None:
    """A sweep names sweepable fields once each, with distinct finite values, and every
    point's config is valid."""
    names = [name for name, _ in config.sweep]
    allowed = sweepable()
    for name, values in config.sweep:
        if name == "k":
            raise ValueError("sweep k: K is its own axis; give the values with --k")
        if name not in fields():
            raise ValueError(f"sweep {name}: unknown config field")
        if name not in allowed:
            kind = fields()[name].describe()
            raise ValueError(
                f"sweep {name}: only float fields the compiled program reads can be swept "
                f"({name} is {kind}"
                + (", read after training" if name == "threshold" else "")
                + (", it shapes the networks" if name.endswith("init_std") else "")
                + "); it needs separate runs"
            )
        if names.count(name) > 1:
            raise ValueError(f"sweep {name}: given twice")
        if len(values) < 1 or len(set(values)) != len(values):
            raise ValueError(f"sweep {name}: needs distinct values, got {list(values)}")
        if not all(isinstance(v, float) and math.isfinite(v) for v in values):
            raise ValueError(f"sweep {name}: values must be finite numbers, got {list(values)}")
    if config.sweep:
        for index in range(len(config.points)):
            try:
                validate(config.at_point(index))
            except ValueError as error:
                raise ValueError(f"sweep point {config.point_name(index)}: {error}") from None
