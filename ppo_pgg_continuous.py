"""PPO with Policy Gradient Guidance (PGG) for continuous (Box) action spaces, e.g. MuJoCo.

CleanRL's `ppo_continuous_action.py` plus one learnable *null embedding* that stands in for the
(normalised) observation and gives the unconditional mean mu_null. The guided policy

    pi_hat(a|s) ∝ N(a; mu_null, σ)^(1-guidance) · N(a; mu_s, σ)^guidance
               = N(a; (1-guidance)·mu_null + guidance·mu_s, σ)          (shared σ, exactly)

drives rollouts, the PPO ratio and the entropy. `guidance` is the PGG strength γ of the paper; the
discount factor is `discount`, never "gamma". With --guidance 1 --cond-dropout 0 this script is exactly
CleanRL's PPO, with one fix: the observation-normalisation statistics live inside the agent, so every
checkpoint carries them and evaluates on the scale it was trained on (CleanRL issue 425).
Lines that PGG adds to PPO are marked `# PGG`.

    python ppo_pgg_continuous.py --env-id Hopper-v4 --guidance 1.1
"""

import json
import math
import os
import random
import shutil
import sys
import time
from collections import deque
from dataclasses import asdict, dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
import torch.nn as nn
import tyro
from torch.utils.tensorboard import SummaryWriter

CHECKPOINT_FORMAT_VERSION = 1
LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)


@dataclass
class Args:
    exp_name: str = "ppo_pgg"
    """the name of this experiment, part of the run directory's name"""
    seed: int = 1
    """seed of the experiment (torch, numpy, random and the environments)"""
    torch_deterministic: bool = True
    """if toggled, `torch.use_deterministic_algorithms(True)`"""
    torch_threads: int = 1
    """torch intra-op threads; one thread is fastest for these small networks"""
    compile: bool = False
    """compile the minibatch loss and its backward with torch.compile (needs a C++ compiler): updates
    ~1.6x faster after a one-off compile of ~20 s (~3 s from inductor's cache); the same algorithm,
    rounded differently (README, Performance)"""
    track: bool = False
    """if toggled, track the run with Weights and Biases (needs `pip install wandb`)"""
    wandb_project_name: str = "pgg"
    """the W&B project name"""
    wandb_entity: str | None = None
    """the W&B entity (team)"""
    output_dir: str = "runs"
    """directory under which the run directory is created"""
    run_name: str | None = None
    """run directory name; default `{env_id}__{exp_name}__g{guidance}__p{cond_dropout}__s{seed}`"""

    # Algorithm arguments (CleanRL's continuous PPO defaults)
    env_id: str = "Hopper-v4"
    """the id of a gymnasium environment with a Box action space"""
    total_timesteps: int = 1_000_000
    """total environment steps; training runs whole iterations until at least this many"""
    learning_rate: float = 3e-4
    """the learning rate of the optimizer"""
    num_envs: int = 1
    """the number of parallel environments"""
    num_steps: int = 2048
    """the number of steps per environment per rollout"""
    anneal_lr: bool = True
    """linearly anneal the learning rate to zero"""
    discount: float = 0.99
    """the discount factor (CleanRL's `gamma`; renamed so it cannot be confused with the guidance γ)"""
    gae_lambda: float = 0.95
    """the lambda of generalized advantage estimation"""
    num_minibatches: int = 32
    """the number of minibatches per epoch"""
    update_epochs: int = 10
    """the number of epochs over each rollout"""
    norm_adv: bool = True
    """normalize advantages per minibatch"""
    clip_coef: float = 0.2
    """the PPO surrogate clipping coefficient"""
    clip_vloss: bool = True
    """use a clipped value loss, as in the PPO paper"""
    ent_coef: float = 0.0
    """coefficient of the entropy bonus (of the guided policy)"""
    vf_coef: float = 0.5
    """coefficient of the value loss"""
    max_grad_norm: float = 0.5
    """the maximum norm for gradient clipping"""
    target_kl: float | None = None
    """stop the epochs early when the approximate KL exceeds this"""
    obs_clip: float = 10.0
    """normalised observations are clipped to [-obs_clip, obs_clip]"""
    reward_clip: float = 10.0
    """normalised rewards are clipped to [-reward_clip, reward_clip]"""

    # PGG arguments
    guidance: float = 1.0
    """PGG guidance strength γ used for rollouts and updates (1 = vanilla PPO; the paper trains with 1.1)"""
    cond_dropout: float = 0.0
    """probability that a sample's actor input is replaced by the null embedding during updates"""
    checkpoint_interval: int = 200_000
    """save a checkpoint at the first iteration boundary past each multiple of this many steps"""


def check_args(args: Args) -> str | None:
    """Returns a one-line description of what is wrong with `args`, or None."""
    if not math.isfinite(args.guidance) or args.guidance < 0:
        return f"--guidance must be a finite number >= 0, got {args.guidance}"
    if not 0.0 <= args.cond_dropout <= 1.0:
        return f"--cond-dropout must lie in [0, 1], got {args.cond_dropout}"
    if args.compile and not any(shutil.which(cxx) for cxx in (os.environ.get("CXX", "g++"), "g++", "clang++")):
        return "--compile needs a C++ compiler (g++ or clang++ on PATH, or $CXX)"
    if args.checkpoint_interval <= 0:
        return f"--checkpoint-interval must be positive, got {args.checkpoint_interval}"
    if args.total_timesteps <= 0 or args.num_envs <= 0 or args.num_steps <= 0:
        return "--total-timesteps, --num-envs and --num-steps must be positive"
    if args.num_minibatches <= 0 or (args.num_envs * args.num_steps) % args.num_minibatches:
        return f"--num-minibatches must divide num_envs * num_steps = {args.num_envs * args.num_steps}"
    try:
        env = gym.make(args.env_id)
    except ImportError as e:
        if args.env_id == "Pusher-v4":
            return (
                "Pusher-v4 needs mujoco<3 (pip install mujoco==2.3.7, Python <= 3.11); "
                "with a newer mujoco use Pusher-v5"
            )
        return f"cannot make environment {args.env_id!r}: {e}"
    except gym.error.Error as e:
        return f"cannot make environment {args.env_id!r}: {e}"
    action_space = env.action_space
    env.close()
    if not isinstance(action_space, gym.spaces.Box):
        return f"{args.env_id} has a {type(action_space).__name__} action space; this script needs Box (use ppo_pgg_discrete.py)"
    return None


def make_env(env_id: str):
    def thunk():
        return gym.wrappers.FlattenObservation(gym.make(env_id))

    return thunk


def make_vector_env(env_id: str, num_envs: int, seed: int, discount: float, reward_clip: float) -> gym.vector.VectorEnv:
    """Vector env that resets a finished sub-env within the same step (the gym 0.29 convention GAE
    below relies on). Episode statistics are recorded on raw rewards, before normalisation.
    Observations come out raw: the agent normalises them itself (see RunningObsNorm).
    The wrappers sit on each sub-env, as in CleanRL (so do the reward statistics): gymnasium 1.4's
    vector versions of them cost ~40 µs more per step, a sixth of a Hopper env step."""

    def training_env():
        env = gym.wrappers.RecordEpisodeStatistics(make_env(env_id)())
        env = gym.wrappers.ClipAction(env)
        return NormalizeClipReward(env, discount, reward_clip)

    envs = gym.vector.SyncVectorEnv(
        [training_env for _ in range(num_envs)], autoreset_mode=gym.vector.AutoresetMode.SAME_STEP
    )
    envs.action_space.seed(seed)
    return envs


class NormalizeClipReward(gym.Wrapper):
    """gymnasium's NormalizeReward followed by ClipReward, the reward scaling CleanRL puts on each
    sub-env: rewards are divided by the running standard deviation of the discounted return (which
    a termination resets and a truncation does not), then clipped. The same float64 operations in
    the same order, on Python floats: the same bits (tests/test_continuous.py) for ~3 µs a step
    instead of ~27 (numpy's mean and var of a one-element batch), 7% of a Hopper training step."""

    def __init__(self, env: gym.Env, discount: float, clip: float, epsilon: float = 1e-8):
        super().__init__(env)
        self.discount, self.clip, self.epsilon = discount, clip, epsilon
        self.discounted_return, self.return_mean, self.return_var, self.return_count = 0.0, 0.0, 1.0, 1e-4

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.discounted_return = self.discounted_return * self.discount * (1 - terminated) + float(reward)
        # gymnasium's RunningMeanStd update with a batch of one (mean: the return, variance: 0)
        delta = self.discounted_return - self.return_mean
        total = self.return_count + 1
        self.return_mean += delta / total
        self.return_var = (self.return_var * self.return_count + delta * delta * self.return_count / total) / total
        self.return_count = total
        scaled = reward / math.sqrt(self.return_var + self.epsilon)
        return obs, min(max(scaled, -self.clip), self.clip), terminated, truncated, info


def update_running_moments(mean: np.ndarray, var: np.ndarray, count: np.ndarray, batch: np.ndarray) -> None:
    """gymnasium's RunningMeanStd update, in place on float64 arrays (`count` 0-d), with the same
    operations in the same order, at half its cost: np.mean and np.var of a one-row batch cost ~9 µs."""
    batch_count = batch.shape[0]
    batch_mean = batch.sum(0) / batch_count
    batch_var = np.square(batch - batch_mean).sum(0) / batch_count
    delta = batch_mean - mean
    total = count + batch_count
    m2 = var * count + batch_var * batch_count + np.square(delta) * count * batch_count / total
    mean += delta * batch_count / total
    var[:] = m2 / total
    count[...] = total


def normalise_obs(raw_obs, mean: np.ndarray, var: np.ndarray, epsilon: float, clip: float) -> np.ndarray:
    """Normalised, clipped float32 observations from raw ones (array-like, (B, obs_dim))."""
    normalised = (np.asarray(raw_obs, dtype=np.float64) - mean) / np.sqrt(var + epsilon)
    return np.minimum(np.maximum(normalised, -clip), clip).astype(np.float32)  # np.clip costs twice as much


class RunningObsNorm(nn.Module):
    """Running mean/variance of observations, as gymnasium's NormalizeObservation computes them, kept
    as buffers so that they are saved in the state dict. Only training rollouts update them
    (`RolloutPolicy.observe`, on numpy views: a dozen torch ops on a few numbers cost more than a
    MuJoCo step); evaluation reads them frozen."""

    def __init__(self, obs_dim: int, clip: float, epsilon: float = 1e-8):
        super().__init__()
        self.clip, self.epsilon = clip, epsilon
        self.register_buffer("mean", torch.zeros(obs_dim, dtype=torch.float64))
        self.register_buffer("var", torch.ones(obs_dim, dtype=torch.float64))
        self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))

    def normalise(self, raw_obs) -> np.ndarray:
        return normalise_obs(raw_obs, self.mean.numpy(), self.var.numpy(), self.epsilon, self.clip)

    def forward(self, raw_obs) -> torch.Tensor:
        return torch.from_numpy(self.normalise(raw_obs))


def layer_init(layer, std=np.sqrt(2), bias_const=0.0):
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
    """Actor and critic work on normalised observations; `obs_norm(raw)` produces them."""

    def __init__(self, obs_dim: int, action_dim: int, obs_clip: float = 10.0):
        super().__init__()
        self.critic = nn.Sequential(
            layer_init(nn.Linear(obs_dim, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 1), std=1.0),
        )
        self.actor_mean = nn.Sequential(
            layer_init(nn.Linear(obs_dim, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, action_dim), std=0.01),
        )
        self.actor_logstd = nn.Parameter(torch.zeros(1, action_dim))
        self.obs_norm = RunningObsNorm(obs_dim, obs_clip)
        # PGG: the null embedding, a normalised-observation-shaped input that means "no state".
        # Initialised to zeros, the running mean observation: a neutral "average state" to start from,
        # and it draws nothing from the RNG, so every other weight is initialised exactly as in
        # vanilla PPO with the same seed.
        self.null_obs = nn.Parameter(torch.zeros(obs_dim))

    def get_value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)

    def unconditional_mean(self) -> torch.Tensor:
        """PGG: mean of pi(.|null), shape (action_dim,); one actor pass whatever the batch size."""
        return self.actor_mean(self.null_obs.unsqueeze(0))[0]

    def guided_mean(self, obs: torch.Tensor, guidance: float, drop_mask: torch.Tensor | None = None) -> torch.Tensor:
        """Mean of pi_hat(.|obs) for a batch `obs` (B, obs_dim) of normalised observations.
        `drop_mask` (bool, (B,)) replaces those rows' conditional mean by the unconditional one."""
        if guidance == 1.0 and drop_mask is None:
            # pi_hat = pi exactly, from PPO's own actor pass: an extra null row could change how the
            # product is blocked, hence its rounding. The null embedding gets no gradient (and train
            # leaves it out of the optimizer).
            return self.actor_mean(obs)
        # PGG: the null embedding rides along as one extra row of the same actor pass; a separate
        # one-row pass costs as much as the whole batch at this network size. (Its value can differ
        # from `unconditional_mean()`, a one-row product, in the last float bit.)
        mean_cond, mean_null = self.actor_mean(torch.cat([obs, self.null_obs.unsqueeze(0)])).split([len(obs), 1])
        if drop_mask is not None:  # PGG
            mean_cond = torch.where(drop_mask.unsqueeze(-1), mean_null, mean_cond)
        # PGG: guide() in one op, null + γ·(cond - null) (equal up to the last float bit): its three
        # ops and their backward had cost a tenth of the actor's forward and backward.
        return torch.lerp(mean_null, mean_cond, guidance)


def guide(cond, null, guidance: float):
    """PGG: (1-γ)·null + γ·cond, for torch tensors or numpy arrays; exactly `cond` at γ=1."""
    return (1.0 - guidance) * null + guidance * cond


def gaussian_log_prob(action, mean, logstd):
    """log N(action; mean, exp(logstd)) summed over action dimensions."""
    return (-0.5 * ((action - mean) * torch.exp(-logstd)).square() - logstd - LOG_SQRT_2PI).sum(-1)


def gaussian_entropy(logstd):
    return (0.5 + LOG_SQRT_2PI + logstd).sum(-1)


def numpy_layers(mlp: nn.Sequential) -> list[tuple[np.ndarray, np.ndarray]]:
    """(weight transposed, bias) of each Linear layer, as numpy views of the parameters."""
    return [(layer.weight.detach().numpy().T, layer.bias.detach().numpy()) for layer in mlp if isinstance(layer, nn.Linear)]


def numpy_forward(layers, x: np.ndarray) -> np.ndarray:
    """The Agent's Linear-Tanh-...-Linear networks, in numpy."""
    for weight, bias in layers[:-1]:
        x = np.tanh(x @ weight + bias)
    weight, bias = layers[-1]
    return x @ weight + bias


class RolloutPolicy:
    """pi_hat and the critic for acting during one rollout, in numpy, on views of the agent's weights
    and observation statistics (the weights are fixed until the update). On one observation every
    torch call pays microseconds of dispatch, an nn.Sequential pass ~35 µs, and these made up most of
    a rollout step's own time; the same float32 arithmetic in numpy made training ~1.3x faster (README,
    Performance). The values agree with the Agent's to float rounding (tests/test_equivalence.py).
    It caches pi(.|null) and σ: build one per rollout."""

    def __init__(self, agent: Agent, guidance: float):
        self.actor, self.critic = numpy_layers(agent.actor_mean), numpy_layers(agent.critic)
        norm = agent.obs_norm
        self.obs_mean, self.obs_var, self.obs_count = norm.mean.numpy(), norm.var.numpy(), norm.count.numpy()
        self.obs_epsilon, self.obs_clip = norm.epsilon, norm.clip
        self.guidance = guidance
        self.logstd = agent.actor_logstd.detach().numpy()[0].copy()  # cached like σ, not a live view
        self.std = np.exp(self.logstd)
        with torch.no_grad():
            self.mean_null = agent.unconditional_mean().numpy()  # PGG: pi(.|null) is fixed here too

    def observe(self, raw_obs: np.ndarray) -> np.ndarray:
        """Updates the agent's observation statistics with `raw_obs` and returns it normalised by them."""
        update_running_moments(self.obs_mean, self.obs_var, self.obs_count, raw_obs)
        return normalise_obs(raw_obs, self.obs_mean, self.obs_var, self.obs_epsilon, self.obs_clip)

    def act(self, obs: np.ndarray, noise: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(actions, log pi_hat(action|obs), values) for a batch `obs` of normalised observations;
        `noise` is standard normal, shaped like the actions."""
        mean = guide(numpy_forward(self.actor, obs), self.mean_null, self.guidance)  # PGG: act with pi_hat
        # log N(mean + std·noise; mean, std) per dimension is -noise²/2 - log std - log √(2π).
        log_probs = (-0.5 * np.square(noise) - self.logstd - LOG_SQRT_2PI).sum(-1)
        return mean + self.std * noise, log_probs, self.value(obs)

    def value(self, obs: np.ndarray) -> np.ndarray:
        return numpy_forward(self.critic, obs)[:, 0]


@dataclass
class Rollout:
    obs: torch.Tensor  # (num_steps, num_envs, obs_dim), normalised with the statistics of that moment
    actions: torch.Tensor  # (num_steps, num_envs, action_dim), before clipping to the action space
    logprobs: torch.Tensor  # (num_steps, num_envs), log pi_hat(a|s) at collection time
    rewards: torch.Tensor  # (num_steps, num_envs), normalised and clipped
    dones: torch.Tensor  # (num_steps, num_envs): 1 where obs[t] is the first observation of an episode
    values: torch.Tensor  # (num_steps, num_envs)

    @classmethod
    def empty(cls, num_steps: int, num_envs: int, obs_dim: int, action_dim: int) -> "Rollout":
        zeros = lambda *shape: torch.zeros(shape)  # noqa: E731
        return cls(
            obs=zeros(num_steps, num_envs, obs_dim),
            actions=zeros(num_steps, num_envs, action_dim),
            logprobs=zeros(num_steps, num_envs),
            rewards=zeros(num_steps, num_envs),
            dones=zeros(num_steps, num_envs),
            values=zeros(num_steps, num_envs),
        )


def collect_rollout(policy: RolloutPolicy, envs, raw_obs, next_done, buf: Rollout, on_episode):
    """Fills `buf` with num_steps transitions from the guided policy, updating the observation
    statistics as it goes, and returns the (raw obs, done) numpy arrays to start the next rollout
    from. `on_episode(return, length)` is called per finished episode with raw (unnormalised) returns."""
    # Numpy views of the buffers: a write costs a fraction of a torch indexing call.
    obs_buf, dones_buf, actions_buf, logprobs_buf, values_buf, rewards_buf = (
        t.numpy() for t in (buf.obs, buf.dones, buf.actions, buf.logprobs, buf.values, buf.rewards)
    )
    noise = torch.randn(buf.actions.shape).numpy()  # the whole rollout's, in one draw
    for step in range(buf.obs.shape[0]):
        obs_buf[step] = policy.observe(raw_obs)
        dones_buf[step] = next_done
        actions_buf[step], logprobs_buf[step], values_buf[step] = policy.act(obs_buf[step], noise[step])

        raw_obs, reward, terminations, truncations, infos = envs.step(actions_buf[step])
        # Truncation ends the episode without bootstrapping, as in CleanRL's PPO.
        next_done = np.logical_or(terminations, truncations).astype(np.float32)
        rewards_buf[step] = reward
        if "final_info" in infos:  # a sub-env ended an episode; its last step's info is kept here
            ended = infos["final_info"]
            for i in np.flatnonzero(ended["_episode"]):
                on_episode(float(ended["episode"]["r"][i]), int(ended["episode"]["l"][i]))
    return raw_obs, next_done


def compute_gae(buf: Rollout, next_value: np.ndarray, next_done: np.ndarray, discount: float, gae_lambda: float):
    """Generalized advantage estimation; returns (advantages, returns) as tensors, each (num_steps,
    num_envs). The loop over time runs in numpy: a handful of operations on num_envs numbers per step,
    the same float32 arithmetic as torch's at a fraction of its per-call cost."""
    rewards, values, dones = buf.rewards.numpy(), buf.values.numpy(), buf.dones.numpy()
    num_steps = rewards.shape[0]
    advantages = np.zeros_like(rewards)
    lastgaelam = np.zeros_like(next_value)
    for t in reversed(range(num_steps)):
        if t == num_steps - 1:
            nextnonterminal, nextvalues = 1.0 - next_done, next_value
        else:
            nextnonterminal, nextvalues = 1.0 - dones[t + 1], values[t + 1]
        delta = rewards[t] + discount * nextvalues * nextnonterminal - values[t]
        lastgaelam = delta + discount * gae_lambda * nextnonterminal * lastgaelam
        advantages[t] = lastgaelam
    return torch.from_numpy(advantages), torch.from_numpy(advantages + values)


def flatten_parameters(params: list[nn.Parameter]) -> nn.Parameter:
    """Moves `params` into one flat buffer and their gradients into another, and returns a Parameter
    over the two for the optimizer and gradient clipping. On the CPU, Adam and clip_grad_norm_ loop
    over their tensors in Python: for this agent's 14 small ones that was ~300 µs per minibatch, about a
    tenth of the update; on one tensor it is ~40 µs. The parameters become views of the buffers: the forward
    pass, autograd and the state dict are unchanged, and backward accumulates into the flat gradient
    (zero it in place, never set it to None)."""
    flat = nn.Parameter(torch.cat([p.detach().reshape(-1) for p in params]))
    flat.grad = torch.zeros_like(flat)
    offset = 0
    for p in params:
        p.data = flat.data[offset : offset + p.numel()].view_as(p)
        p.grad = flat.grad[offset : offset + p.numel()].view_as(p)
        offset += p.numel()
    return flat


def minibatch_loss(agent: Agent, batch: dict[str, torch.Tensor], mb_inds, drop_mask, args: Args):
    """PPO's clipped objective on the rows `mb_inds` of `batch` (the flattened rollout), with pi_hat in
    place of pi. Returns (loss, stats); the stats are detached tensors, not floats, so that the
    compiled version (--compile) runs without a break back to Python."""
    mb_obs = batch["obs"][mb_inds]
    mean = agent.guided_mean(mb_obs, args.guidance, drop_mask)  # PGG
    newlogprob = gaussian_log_prob(batch["actions"][mb_inds], mean, agent.actor_logstd)
    entropy = gaussian_entropy(agent.actor_logstd)
    newvalue = agent.get_value(mb_obs)
    logratio = newlogprob - batch["logprobs"][mb_inds]
    ratio = logratio.exp()

    with torch.no_grad():
        # http://joschu.net/blog/kl-approx.html
        old_approx_kl = (-logratio).mean()
        approx_kl = ((ratio - 1) - logratio).mean()
        clipfrac = ((ratio - 1.0).abs() > args.clip_coef).float().mean()

    mb_advantages = batch["advantages"][mb_inds]
    if args.norm_adv:
        mb_advantages = (mb_advantages - mb_advantages.mean()) / (mb_advantages.std() + 1e-8)

    pg_loss1 = -mb_advantages * ratio
    pg_loss2 = -mb_advantages * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)
    pg_loss = torch.max(pg_loss1, pg_loss2).mean()

    mb_returns = batch["returns"][mb_inds]
    if args.clip_vloss:
        mb_values = batch["values"][mb_inds]
        v_loss_unclipped = (newvalue - mb_returns) ** 2
        v_clipped = mb_values + torch.clamp(newvalue - mb_values, -args.clip_coef, args.clip_coef)
        v_loss_clipped = (v_clipped - mb_returns) ** 2
        v_loss = 0.5 * torch.max(v_loss_unclipped, v_loss_clipped).mean()
    else:
        v_loss = 0.5 * ((newvalue - mb_returns) ** 2).mean()

    entropy_loss = entropy.mean()
    loss = pg_loss - args.ent_coef * entropy_loss + v_loss * args.vf_coef
    return loss, {
        "losses/value_loss": v_loss.detach(),
        "losses/policy_loss": pg_loss.detach(),
        "losses/entropy": entropy_loss.detach(),
        "losses/old_approx_kl": old_approx_kl,
        "losses/approx_kl": approx_kl,
        "losses/clipfrac": clipfrac,
    }


def ppo_update(agent, optimizer, buf: Rollout, advantages, returns, args: Args, loss_fn=minibatch_loss) -> dict[str, float]:
    """PPO's epochs over one rollout; `loss_fn` is `minibatch_loss` or its compiled version."""
    batch = {
        "obs": buf.obs.reshape(-1, buf.obs.shape[-1]),
        "actions": buf.actions.reshape(-1, buf.actions.shape[-1]),
        "logprobs": buf.logprobs.reshape(-1),
        "advantages": advantages.reshape(-1),
        "returns": returns.reshape(-1),
        "values": buf.values.reshape(-1),
    }
    batch_size = len(batch["obs"])
    minibatch_size = batch_size // args.num_minibatches

    clipfracs = []
    for _ in range(args.update_epochs):
        b_inds = torch.randperm(batch_size)
        for start in range(0, batch_size, minibatch_size):
            drop_mask = None
            if args.cond_dropout > 0:  # PGG: conditioning dropout
                drop_mask = torch.rand(minibatch_size) < args.cond_dropout
            loss, stats = loss_fn(agent, batch, b_inds[start : start + minibatch_size], drop_mask, args)
            clipfracs.append(stats["losses/clipfrac"])

            optimizer.zero_grad(set_to_none=False)  # in place: see flatten_parameters
            loss.backward()
            nn.utils.clip_grad_norm_(optimizer.param_groups[0]["params"], args.max_grad_norm)
            optimizer.step()

        if args.target_kl is not None and stats["losses/approx_kl"] > args.target_kl:
            break

    y_pred, y_true = batch["values"].numpy(), batch["returns"].numpy()
    var_y = np.var(y_true)
    stats = {key: value.item() for key, value in stats.items()}
    stats["losses/clipfrac"] = torch.stack(clipfracs).mean().item()
    stats["losses/explained_variance"] = float("nan") if var_y == 0 else float(1 - np.var(y_true - y_pred) / var_y)
    return stats


@torch.no_grad()
def guidance_diagnostics(agent: Agent, obs: torch.Tensor, guidance: float) -> dict[str, float]:
    """PGG: how far guidance moves the policy, and what the unconditional branch has learned.
    With a shared σ, KL(pi_hat || pi_s) = ½ Σ ((mu_hat - mu_s)/σ)²."""
    mean_guided = agent.guided_mean(obs, guidance)
    mean_cond = agent.actor_mean(obs)
    inv_std = torch.exp(-agent.actor_logstd)
    return {
        "pgg/kl_guided_vs_conditional": (0.5 * ((mean_guided - mean_cond) * inv_std).square().sum(-1)).mean().item(),
        "pgg/unconditional_mean_norm": agent.unconditional_mean().norm().item(),
        "pgg/null_embedding_norm": agent.null_obs.norm().item(),
        "charts/action_std_mean": agent.actor_logstd.exp().mean().item(),
    }


def checkpoint_marks(total_timesteps: int, interval: int) -> list[int]:
    """Nominal steps that get a checkpoint: every multiple of `interval` below the total, and the total."""
    return list(range(interval, total_timesteps, interval)) + [total_timesteps]


def checkpoint_path(run_dir: Path, mark: int) -> Path:
    return run_dir / "checkpoints" / f"step_{mark:09d}.pt"


def save_checkpoint(path: Path, agent: Agent, args: Args, global_step: int, mark: int, envs) -> None:
    """Self-contained, pickle-free checkpoint (loads with weights_only=True), written atomically.
    The model's state dict includes the observation-normalisation statistics."""
    action_space = envs.unwrapped.envs[0].unwrapped.action_space  # the env's own bounds, not ClipAction's ±inf
    payload = {
        "format_version": CHECKPOINT_FORMAT_VERSION,
        "script": "ppo_pgg_continuous",
        "action_space": "continuous",
        "env_id": args.env_id,
        "obs_dim": int(envs.single_observation_space.shape[0]),
        "action_dim": int(action_space.shape[0]),
        "action_low": action_space.low.tolist(),
        "action_high": action_space.high.tolist(),
        "global_step": int(global_step),
        "step_mark": int(mark),
        "args": asdict(args),
        "model": agent.state_dict(),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)


def load_checkpoint(path) -> tuple[Agent, dict]:
    """Rebuilds the agent, normalisation statistics included, from a checkpoint file; returns
    (agent in eval mode, the checkpoint dict)."""
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    return agent_from_checkpoint(ckpt, path), ckpt


def agent_from_checkpoint(ckpt: dict, source: str | Path = "checkpoint") -> Agent:
    """The agent, in eval mode, of an already loaded checkpoint dict."""
    if ckpt.get("format_version") != CHECKPOINT_FORMAT_VERSION or ckpt.get("action_space") != "continuous":
        raise ValueError(f"{source} is not a continuous PGG checkpoint of format {CHECKPOINT_FORMAT_VERSION}")
    agent = Agent(ckpt["obs_dim"], ckpt["action_dim"], ckpt["args"]["obs_clip"])
    agent.load_state_dict(ckpt["model"])
    return agent.eval()


def default_run_name(args: Args) -> str:
    return f"{args.env_id}__{args.exp_name}__g{args.guidance:g}__p{args.cond_dropout:g}__s{args.seed}"


def prepare_run_dir(args: Args) -> Path:
    """Creates the run directory, clearing what an earlier run of the same name left (a rerun starts
    cleanly), and writes args.json. Raises OSError if it is not writable."""
    run_dir = Path(args.output_dir) / (args.run_name or default_run_name(args))
    run_dir.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(run_dir / "checkpoints", ignore_errors=True)
    for stale in run_dir.glob("events.out.tfevents.*"):
        stale.unlink()
    tmp = run_dir / "args.json.tmp"
    tmp.write_text(json.dumps(asdict(args), indent=2))
    os.replace(tmp, run_dir / "args.json")
    return run_dir


def train(args: Args, run_dir: Path) -> None:
    """Trains one agent, writing TensorBoard events and checkpoints into `run_dir`."""
    if args.track:
        import wandb

        wandb.init(
            project=args.wandb_project_name,
            entity=args.wandb_entity,
            sync_tensorboard=True,
            config=asdict(args),
            name=run_dir.name,
            save_code=True,
        )
    writer = SummaryWriter(str(run_dir))
    writer.add_text(
        "hyperparameters",
        "|param|value|\n|-|-|\n%s" % "\n".join(f"|{key}|{value}|" for key, value in asdict(args).items()),
    )

    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.backends.cudnn.deterministic = args.torch_deterministic
    torch.use_deterministic_algorithms(args.torch_deterministic)
    torch.set_num_threads(args.torch_threads)

    envs = make_vector_env(args.env_id, args.num_envs, args.seed, args.discount, args.reward_clip)
    obs_dim, action_dim = envs.single_observation_space.shape[0], envs.single_action_space.shape[0]
    agent = Agent(obs_dim, action_dim, args.obs_clip)
    # fused Adam on one flat tensor: CleanRL's per-tensor Adam costs more than our forward pass.
    # PGG: at γ = 1 without dropout the null embedding is outside the objective. Its all-zero gradient
    # in the flat buffer would still change the clipping norm's rounding; without it the run is
    # bit-for-bit PPO.
    vanilla = args.guidance == 1.0 and args.cond_dropout == 0
    trained = [p for name, p in agent.named_parameters() if not (vanilla and name == "null_obs")]
    optimizer = torch.optim.Adam([flatten_parameters(trained)], lr=args.learning_rate, eps=1e-5, fused=True)
    # One fused kernel for the loss and one for its backward, in place of ~200 small ops whose
    # per-call dispatch dominates an update of this size on the CPU.
    loss_fn = torch.compile(minibatch_loss) if args.compile else minibatch_loss

    batch_size = args.num_envs * args.num_steps
    # Ceil, not CleanRL's floor, so that the final checkpoint lies at or past total_timesteps.
    num_iterations = -(-args.total_timesteps // batch_size)
    marks = deque(checkpoint_marks(args.total_timesteps, args.checkpoint_interval))
    buf = Rollout.empty(args.num_steps, args.num_envs, obs_dim, action_dim)
    recent_returns = deque(maxlen=20)
    global_step = 0

    def on_episode(episodic_return: float, episodic_length: int):
        recent_returns.append(episodic_return)
        writer.add_scalar("charts/episodic_return", episodic_return, global_step)
        writer.add_scalar("charts/episodic_length", episodic_length, global_step)

    start_time = time.time()
    raw_obs, _ = envs.reset(seed=args.seed)
    next_done = np.zeros(args.num_envs, dtype=np.float32)

    for iteration in range(1, num_iterations + 1):
        if args.anneal_lr:
            optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / num_iterations) * args.learning_rate

        policy = RolloutPolicy(agent, args.guidance)
        raw_obs, next_done = collect_rollout(policy, envs, raw_obs, next_done, buf, on_episode)
        global_step += batch_size
        # Bootstrap from the next observation normalised like the ones it follows; the next
        # rollout's first step updates the statistics with it.
        next_value = policy.value(agent.obs_norm.normalise(raw_obs))
        advantages, returns = compute_gae(buf, next_value, next_done, args.discount, args.gae_lambda)

        stats = ppo_update(agent, optimizer, buf, advantages, returns, args, loss_fn)
        stats.update(guidance_diagnostics(agent, buf.obs.reshape(-1, obs_dim), args.guidance))
        stats["charts/learning_rate"] = optimizer.param_groups[0]["lr"]
        sps = int(global_step / (time.time() - start_time))
        stats["charts/SPS"] = sps
        for key, value in stats.items():
            writer.add_scalar(key, value, global_step)

        while marks and global_step >= marks[0]:
            mark = marks.popleft()
            save_checkpoint(checkpoint_path(run_dir, mark), agent, args, global_step, mark, envs)
            mean_return = np.mean(recent_returns) if recent_returns else float("nan")
            print(f"global_step={global_step} mark={mark} mean_return(last 20)={mean_return:.1f} SPS={sps}", flush=True)

    envs.close()
    writer.close()
    if args.track:
        wandb.finish()


def main() -> None:
    args = tyro.cli(Args)
    error = check_args(args)
    if error is None:
        try:
            run_dir = prepare_run_dir(args)
        except OSError as e:
            error = f"cannot write the run directory under {args.output_dir!r}: {e.strerror or e}"
    if error is None and args.track:
        try:
            import wandb  # noqa: F401
        except ImportError:
            error = "--track needs Weights and Biases: pip install wandb"
    if error is not None:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
    print(f"run directory: {run_dir}")
    train(args, run_dir)


if __name__ == "__main__":
    main()
