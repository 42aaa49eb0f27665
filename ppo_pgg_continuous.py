"""PPO with Policy Gradient Guidance (PGG) for continuous (Box) action spaces, e.g. MuJoCo.

CleanRL's `ppo_continuous_action.py` plus one learnable *null embedding* that stands in for the
(normalised) observation and gives the unconditional mean mu_null. The guided policy

    pi_hat(a|s) ∝ N(a; mu_null, σ)^(1-guidance) · N(a; mu_s, σ)^guidance
               = N(a; (1-guidance)·mu_null + guidance·mu_s, σ)          (shared σ, exactly)

drives rollouts, the PPO ratio and the entropy. `guidance` is the PGG strength γ; the discount factor
is `discount`. With --guidance 1 --cond-dropout 0 this is CleanRL's PPO with CleanRL's defaults, the
observation statistics inside the agent (CleanRL issue 425); what else differs: the README's "What
differs from CleanRL". Lines that differ from PPO are marked `# PGG`; run management is in pgg_utils.

    python ppo_pgg_continuous.py --env-id Hopper-v4 --guidance 1.1
    python ppo_pgg_continuous.py --env-id Hopper-v4 --guidance 1.1 --resume   # continue a stopped run
    python ppo_pgg_continuous.py --env-id Hopper-v4 --guidance 1 --guidance-schedule linear --guidance-final 1.2
    python ppo_pgg_continuous.py --env-id Reacher-v4 --guidance 1.1 --null-dims 4 5 8 9 10   # guidance on the goal
"""

from pgg_utils import startup  # noqa: F401  (first: a Ctrl-C during the imports below is one line, status 130)

# isort: split
import sys
from collections import defaultdict
from dataclasses import asdict, dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from pgg_utils import loading, runs, tasks, training_state
from pgg_utils.arguments import RunArgs
from pgg_utils.distributions import Gaussian, guide  # PGG: guide, the mix of the branches' parameters
from pgg_utils.fast import branch_scale, evaluation_network, flatten_parameters, numpy_network
from pgg_utils.guidance import GuidanceArgs, GuidanceSchedule, uses_null_branch  # PGG
from pgg_utils.normalisation import NormalizeClipReward, RunningObsNorm
from pgg_utils.policy import (
    PathError,
    branch_pass,
    first_ratio_error,
    frozen,
    guidance_diagnostics,  # PGG
    guided_actions,  # PGG
    null_pass,  # PGG
    numpy_policy,
    path_error,
    probe_observations,
    randomised,
    refuse,
    trained_parameters,
)
from pgg_utils.rollout import Rollout, flatten_rollout

ACTION_SPACE = "continuous"  # the checkpoints' kind; the sweep picks this script by it


@dataclass
class Args(GuidanceArgs, RunArgs):  # PGG: --guidance, its schedule and --cond-dropout (pgg_utils/guidance.py)
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
    """stop the epochs early when the approximate KL (of the rows not dropped) exceeds this"""
    obs_clip: float = 10.0
    """normalised observations are clipped to [-obs_clip, obs_clip]"""
    reward_clip: float = 10.0
    """normalised rewards are clipped to [-reward_clip, reward_clip]"""
    null_dims: tuple[int, ...] | None = None  # PGG
    """observation indices the null embedding replaces (e.g. a goal's: Reacher-v4 4 5 8 9 10, Pusher-v4 20 21 22); None: all, the paper's"""
    checkpoint_interval: int = 200_000
    """save a checkpoint at the first iteration boundary past each multiple of this many steps (at least one batch, num_envs * num_steps)"""


def make_env(env_id: str, video_dir: Path | None = None, render_mode: str | None = None):
    """The task as the agent sees it, for training, the sweep and --video alike. A wrapper added to `env` here
    (reward shaping, a frame stack) shapes what the agent trains on, never the reported return: tasks.task_env
    records the task's own below it. With `video_dir`, RecordVideo records there; `render_mode` is gym.make's."""

    def thunk() -> gym.Env:
        # FlattenObservation changes no reward: under the recorder, where the checkpoints' env state has always had it.
        env = tasks.task_env(env_id, video_dir, render_mode, below_record=(gym.wrappers.FlattenObservation,))
        return env

    return thunk


def training_env(env: gym.Env, discount: float, reward_clip: float) -> gym.Env:
    """Training's own wrappers around make_env's task (the sweep acts without them): CleanRL's action clipping and
    reward normalisation."""
    return NormalizeClipReward(gym.wrappers.ClipAction(env), discount, reward_clip)


def layer_init(layer, std=np.sqrt(2), bias_const=0.0):
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
    """Actor and critic work on normalised observations (`obs_norm`). Change the networks here: the rollouts'
    numpy copy and the evaluation follow the modules (pgg_utils/fast.py); the action distribution is
    `guided_policy`'s. The methods the rest of the project calls: AGENT_METHODS."""

    def __init__(self, obs_dim: int, action_dim: int, obs_clip=10.0, null_dims=None, action_bounds=None):  # PGG
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
        # The null embedding, an input that means "no state". Zeros (the running mean observation) draw
        # nothing from the RNG: every other weight is initialised exactly as in PPO with the same seed.
        self.null_obs = nn.Parameter(torch.zeros(obs_dim))  # PGG
        # With null_dims the embedding replaces those dimensions only (a goal): pi(a|s, null) is then
        # a policy of the rest of the state, computed per row.
        self.null_mask = None if null_dims is None else torch.zeros(obs_dim, dtype=torch.bool)  # PGG
        if null_dims is not None:  # PGG
            self.null_mask[list(null_dims)] = True  # PGG
        self.action_bounds = action_bounds  # (low, high) that `act` clips to; not trained
        self.obs_shape = (obs_dim,)  # what `act` takes

    def get_value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)

    def reset(self) -> None:
        """Begins an episode: a recurrent actor clears its state here (this one holds none)."""

    def null_input(self, obs):  # PGG
        """The unconditional branch's input: one row (all nulled), or `obs` with the null_dims replaced (torch or numpy)."""
        if self.null_mask is None:  # PGG
            return self.null_obs.unsqueeze(0) if torch.is_tensor(obs) else self.null_obs.detach().numpy()[None]  # PGG
        if torch.is_tensor(obs):  # PGG
            return torch.where(self.null_mask, self.null_obs, obs)  # PGG
        return np.where(self.null_mask.numpy(), self.null_obs.detach().numpy(), obs)  # PGG

    def null_logstd(self) -> torch.Tensor:  # PGG
        """log σ of pi(.|null), (1, action_dim): the policy's own, one σ for both branches (the paper's)."""
        return self.actor_logstd  # PGG

    def unconditional_mean(self) -> torch.Tensor:  # PGG
        """Mean of pi(.|null), shape (action_dim,), with the whole observation nulled."""
        return null_pass(self.actor_mean, self.null_obs.unsqueeze(0))[0]  # PGG

    def branches(self, obs: torch.Tensor, drop_mask=None) -> tuple["Gaussian", "Gaussian"]:  # PGG
        """pi(.|s) and pi(.|null) for a batch `obs` (B, obs_dim); `drop_mask` (bool, (B,)) nulls those rows' pi(.|s)."""
        mean_cond, mean_null = branch_pass(self.actor_mean, obs, self.null_input(obs))  # PGG
        if drop_mask is not None:  # PGG
            mean_cond = torch.where(drop_mask.unsqueeze(-1), mean_null, mean_cond)  # PGG
        return Gaussian(mean_cond, self.actor_logstd), Gaussian(mean_null, self.null_logstd())  # PGG

    def policy(self, obs: torch.Tensor, guidance: torch.Tensor | float | None, drop_mask=None) -> "Gaussian":  # PGG
        """pi_hat(.|obs), the loss's. `guidance` None: PPO's own actor pass (the null embedding gets no gradient), still
        through guided_policy (at 1, exactly pi(.|s)), so that a changed distribution changes it too."""
        if guidance is None and drop_mask is None:  # PGG
            cond = Gaussian(self.actor_mean(obs), self.actor_logstd)
            return guided_policy(cond, cond, 1.0)  # PGG
        return guided_policy(*self.branches(obs, drop_mask), 1.0 if guidance is None else guidance)  # PGG

    def acting_policy(self, raw_obs: np.ndarray, guidance, mean_null=None):  # PGG
        """pi_hat for a batch of raw observations, in numpy (`act` samples from it), by FastPolicy."""
        fast = FastPolicy(self, acting=True, mean_null=mean_null)  # PGG
        return fast.distribution(self.obs_norm.normalise(raw_obs), guidance)  # PGG

    @torch.no_grad()
    def act(self, raw_obs, guidance=1.0, deterministic: bool = False, noise=None, mean_null=None, seed=None) -> np.ndarray:  # PGG  # fmt: skip
        """Actions of pi_hat at `guidance` (a number, or one per row) for raw observations (one, or a batch), as the
        sweep acts: sampled with standard normal `noise` (None: drawn, from a generator seeded by `seed` if given),
        or the mode if `deterministic`, clipped to the task's bounds (pgg_utils.policy.guided_actions)."""
        raw = np.asarray(raw_obs, dtype=np.float64)
        draw = lambda pi: torch.randn(pi.mode().shape).numpy()  # torch's generator, so torch.manual_seed repeats it
        return guided_actions(self, raw, guidance, deterministic, noise, mean_null, draw, seed)  # PGG

    def predict(self, raw_obs, state=None, episode_start=None, deterministic: bool = False, guidance=1.0):  # PGG
        """Stable-Baselines3's `model.predict`: (`act`'s actions, None); `state` and `episode_start` unused, as SB3's."""
        return self.act(raw_obs, guidance, deterministic), None  # PGG


# The methods of Agent that the rest of the project calls, and who calls each (checked when training starts).
AGENT_METHODS = {
    "get_value": "the loss",
    "policy": "the loss",
    "branches": "guidance_diagnostics",  # PGG
    "null_logstd": "the rollouts",  # PGG
    "unconditional_mean": "the sweep",  # PGG
    "acting_policy": "act, pgg_utils/bc_null.py",  # PGG
    "act": "the sweep",
    "reset": "the sweep",
}


def make_agent(args: dict, shapes: dict) -> Agent:
    """The agent of a run from its training arguments and the task's shapes (tasks.checkpoint_shapes): the one
    constructor of training and of checkpoint loading, so an argument added to the network reaches both."""
    bounds = (np.asarray(shapes["action_low"], np.float32), np.asarray(shapes["action_high"], np.float32))
    return Agent(shapes["obs_dim"], shapes["action_dim"], args["obs_clip"], args.get("null_dims"), bounds)  # PGG


def guided_policy(cond: "Gaussian", null: "Gaussian", guidance) -> "Gaussian":  # PGG
    """pi_hat ∝ pi(.|null)^(1-γ) · pi(.|s)^γ, the one definition of the action distribution (the loss, the rollouts
    and `act` take it from here). The natural parameters mix; with one σ for both branches that is the mean mix
    `guide`, σ unchanged. Torch or numpy; a fork's distribution has Gaussian's methods."""
    return Gaussian(guide(cond.mean, null.mean, guidance), cond.logstd, cond.std)  # PGG


# --- the behaviour policy, in numpy: ~1.3x faster training than torch's per-call dispatch, same float32 arithmetic


class FastPolicy:
    """pi_hat and the critic in numpy, derived from the agent's modules and guided_policy. For a rollout: numpy
    copies on views of the weights, pi(.|null) cached, one per rollout. For `act` (`acting=True`): the modules' own
    forward, rounded independently of the batch's other rows (pgg_utils/fast.py)."""

    def __init__(self, agent: Agent, guidance=None, acting: bool = False, mean_null=None):  # PGG
        network = evaluation_network if acting else numpy_network
        self.actor, self.critic = network(agent.actor_mean), network(agent.critic)
        self.obs_norm = agent.obs_norm  # the agent's own normaliser: the rollout's observations update it in place
        self.guidance = guidance  # PGG
        self.logstd, self.std = branch_scale(agent.actor_logstd, acting)
        self.logstd_null, self.std_null = branch_scale(agent.null_logstd(), acting)  # PGG
        self.null_input = None if agent.null_mask is None else agent.null_input  # PGG: per-row null inputs
        if mean_null is None and self.null_input is None:  # PGG
            with torch.no_grad():  # PGG
                mean_null = agent.unconditional_mean().numpy()  # PGG
        self.mean_null = mean_null  # PGG

    def distribution(self, obs: np.ndarray, guidance) -> "Gaussian":  # PGG
        """pi_hat for a batch `obs` of normalised observations at `guidance` (a number, or one per row)."""
        mean_null = self.mean_null if self.null_input is None else self.actor(self.null_input(obs))  # PGG
        cond = Gaussian(self.actor(obs), self.logstd, self.std)
        null = Gaussian(mean_null, self.logstd_null, self.std_null)  # PGG
        return numpy_policy(guided_policy, cond, null, guidance)  # PGG

    def act(self, obs: np.ndarray, noise: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(actions, log pi_hat(action|obs), values) for a batch `obs` of normalised observations;
        `noise` is standard normal, shaped like the actions."""
        actions, log_probs = self.distribution(obs, self.guidance).sample_log_prob(noise)  # PGG
        return actions, log_probs, self.value(obs)

    def value(self, obs: np.ndarray) -> np.ndarray:
        return self.critic(obs)[:, 0]


# --- rollout, GAE, loss, update ------------------------------------------------------------------


def collect_rollout(policy: FastPolicy, envs, next_obs, next_done, buf: Rollout, on_episode, global_step: int):
    """Fills `buf` (a pgg_utils.rollout.Rollout) with num_steps transitions from the guided policy, updating the
    observation statistics, and returns the (normalised obs, done) to start the next rollout from. `on_episode(return,
    length, step)` is called per finished episode, at the global step it ended (CleanRL's logging step)."""
    # Numpy views of the buffers: a write costs a fraction of a torch indexing call.
    obs_buf, dones_buf, actions_buf, logprobs_buf, values_buf, rewards_buf = (
        t.numpy() for t in (buf.obs, buf.dones, buf.actions, buf.logprobs, buf.values, buf.rewards)
    )
    noise = torch.randn(buf.actions.shape).numpy()  # one draw per rollout: cheaper than one per step
    for step in range(buf.obs.shape[0]):
        obs_buf[step] = next_obs
        dones_buf[step] = next_done
        actions_buf[step], logprobs_buf[step], values_buf[step] = policy.act(next_obs, noise[step])

        raw_obs, reward, terminations, truncations, infos = envs.step(actions_buf[step])
        # Truncation ends the episode without bootstrapping, as in CleanRL's PPO.
        next_done = np.logical_or(terminations, truncations).astype(np.float32)
        rewards_buf[step] = reward
        if "final_info" in infos:  # same-step autoreset: the ended episode's last obs is only here
            # The statistics count the episode's last observation before the next one's first, as
            # CleanRL's NormalizeObservation does (step, then the reset inside it).
            policy.obs_norm.update(np.stack(infos["final_obs"][infos["_final_obs"]]))
            for episodic_return, episodic_length in tasks.ended_episodes(infos):  # the task's own (tasks.task_env)
                on_episode(episodic_return, episodic_length, global_step + (step + 1) * len(raw_obs))
        # Normalised on arrival, with statistics that include it, as CleanRL's wrapper returns it.
        next_obs = policy.obs_norm.observe(raw_obs)
    return next_obs, next_done


def compute_gae(buf: Rollout, next_value: np.ndarray, next_done: np.ndarray, discount: float, gae_lambda: float):
    """Generalized advantage estimation: (advantages, returns), each (num_steps, num_envs). In numpy: torch's
    float32 arithmetic at a fraction of its per-call cost."""
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


def null_bc_loss(agent: Agent, obs: torch.Tensor, actions: torch.Tensor, route: str) -> torch.Tensor:  # PGG
    """Mean -log pi(a|null) of the rollout's actions: behaviour cloning by the unconditional branch, with the
    policy's σ held (it is the conditional policy's too). Route "null": the actor's weights are held for this
    term, so it trains the null embedding alone; "actor": it trains the shared actor as well."""
    null_in = agent.null_input(obs)  # PGG
    with frozen(agent.actor_mean):  # PGG: a BatchNorm's statistics stay where they are
        if route == "null":  # PGG
            held = {name: weight.detach() for name, weight in agent.actor_mean.named_parameters()}  # PGG
            mean_null = torch.func.functional_call(agent.actor_mean, held, (null_in,))  # PGG
        else:  # PGG
            mean_null = agent.actor_mean(null_in)  # PGG
    return -Gaussian(mean_null, agent.null_logstd().detach()).log_prob(actions).mean()  # PGG


def minibatch_loss(agent: Agent, batch: dict[str, torch.Tensor], mb_inds, drop_mask, guidance, args: Args):  # PGG
    """PPO's clipped objective on the rows `mb_inds` of `batch` (flatten_rollout's), with pi_hat in place of pi.
    `guidance`: γ_train (under --compile a 0-d tensor: a new value compiles nothing), or None without guidance.
    Returns (loss, stats), the stats detached tensors: --compile's graph has no break back to Python."""
    mb_obs = batch["obs"][mb_inds]
    pi = agent.policy(mb_obs, guidance, drop_mask)  # PGG
    newlogprob = pi.log_prob(batch["actions"][mb_inds])
    entropy = pi.entropy()
    newvalue = agent.get_value(mb_obs)
    logratio = newlogprob - batch["logprobs"][mb_inds]
    ratio = logratio.exp()

    with torch.no_grad():
        # A dropped row compares pi(a|null) with the pi_hat(a|s) that acted, so its ratio does not
        # start at 1: the KL estimates and the clip fraction describe the kept rows, the policy's own
        # change. Masked means, not boolean indexing: the compiled loss keeps static shapes.
        kept = torch.ones_like(ratio) if drop_mask is None else (~drop_mask).float()  # PGG
        kept_mean = lambda x: (kept * x).sum() / kept.sum().clamp_min(1.0)  # PGG
        # http://joschu.net/blog/kl-approx.html
        old_approx_kl = kept_mean(-logratio)  # PGG
        approx_kl = kept_mean((ratio - 1) - logratio)  # PGG
        clipped = ((ratio - 1.0).abs() > args.clip_coef).float()
        clipfrac = kept_mean(clipped)  # PGG
        dropped_stats = {}  # PGG
        if drop_mask is not None:  # PGG
            dropped = 1.0 - kept  # PGG
            dropped_mean = lambda x: (dropped * x).sum() / dropped.sum().clamp_min(1.0)  # PGG
            dropped_stats = {  # PGG
                "pgg/dropped_fraction": dropped.mean(),  # PGG
                "pgg/dropped_ratio_mean": dropped_mean(ratio),  # PGG
                "pgg/dropped_abs_logratio": dropped_mean(logratio.abs()),  # PGG
                "pgg/dropped_clipfrac": dropped_mean(clipped),  # PGG
            }  # PGG

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
    if args.null_bc_coef:  # PGG: the unconditional branch clones the rollout's actions
        cloning = null_bc_loss(agent, mb_obs, batch["actions"][mb_inds], args.null_bc_route)  # PGG
        loss = loss + args.null_bc_coef * cloning  # PGG
    return loss, {
        "losses/value_loss": v_loss.detach(),
        "losses/policy_loss": pg_loss.detach(),
        "losses/entropy": entropy_loss.detach(),
        "losses/old_approx_kl": old_approx_kl,
        "losses/approx_kl": approx_kl,
        "losses/clipfrac": clipfrac,
        **dropped_stats,  # PGG
    }


def ppo_update(agent, optimizer, buf, advantages, returns, args, guidance, loss_fn=minibatch_loss):  # PGG
    """PPO's epochs over one rollout (a Rollout); `loss_fn` is `minibatch_loss` or its compiled version. Returns the
    last minibatch's statistics, the clip fraction and PGG's averaged over every minibatch, as floats."""
    batch = flatten_rollout(buf, advantages, returns)
    batch_size = len(batch["obs"])
    minibatch_size = batch_size // args.num_minibatches

    per_minibatch = defaultdict(list)  # averaged over every minibatch, as CleanRL does the clip fraction
    first_approx_kl = None  # the first minibatch's, before any step: on the parameters that acted, every ratio is 1
    for _ in range(args.update_epochs):
        b_inds = torch.randperm(batch_size)
        for start in range(0, batch_size, minibatch_size):
            drop_mask = None  # PGG
            if args.cond_dropout > 0:  # PGG
                drop_mask = torch.rand(minibatch_size) < args.cond_dropout  # PGG
            mb_inds = b_inds[start : start + minibatch_size]
            loss, stats = loss_fn(agent, batch, mb_inds, drop_mask, guidance, args)  # PGG
            first_approx_kl = stats["losses/approx_kl"] if first_approx_kl is None else first_approx_kl
            for key in ("losses/clipfrac", *(key for key in stats if key.startswith("pgg/"))):  # PGG
                per_minibatch[key].append(stats[key])

            optimizer.zero_grad(set_to_none=False)  # in place: see flatten_parameters
            loss.backward()
            nn.utils.clip_grad_norm_(optimizer.param_groups[0]["params"], args.max_grad_norm)
            optimizer.step()

        if args.target_kl is not None and stats["losses/approx_kl"] > args.target_kl:  # the kept rows' KL
            break

    y_pred, y_true = batch["values"].numpy(), batch["returns"].numpy()
    var_y = np.var(y_true)
    stats = {key: value.item() for key, value in stats.items()}
    stats["losses/first_approx_kl"] = first_approx_kl.item()
    stats.update({key: torch.stack(values).mean().item() for key, values in per_minibatch.items()})
    stats["losses/explained_variance"] = float("nan") if var_y == 0 else float(1 - np.var(y_true - y_pred) / var_y)
    return stats


def train(args: Args, run: runs.Run) -> None:
    """Trains one agent, writing TensorBoard events and checkpoints into `run.dir`. With --resume it
    continues from the last checkpoint bit for bit: the checkpoint holds the optimizer, the sub-envs
    mid-episode, the next observation and every RNG state."""
    script = sys.modules[__name__]  # this file's module: a fork's checks read the fork's own code
    resumed = run.checkpoint_to_resume()
    training_state.seed_everything(args)

    wrap = lambda env: training_env(env, args.discount, args.reward_clip)
    envs = tasks.make_vector_env(make_env, args.env_id, args.num_envs, args.seed, run.video_dir(resumed), wrap)
    shapes, error = tasks.trained_task(script, args.env_id, envs)  # make_env's task, as swept
    if error:
        refuse(error, envs)
    if len(envs.single_action_space.shape) != 1:
        refuse(f"{args.env_id}'s actions have shape {envs.single_action_space.shape}; this script acts with a "
               "vector (a 1-D Box): reshape them in make_env", envs)  # fmt: skip
    obs_dim, action_dim = envs.single_observation_space.shape[0], envs.single_action_space.shape[0]
    agent = make_agent(asdict(args), shapes)
    # Before anything is written: the rollouts, `act` and the loss must compute guided_policy's distribution, on an
    # agent whose every parameter is drawn at random (a fresh one's zeros and ones would hide a path's difference).
    probe = probe_observations(envs.single_observation_space)
    noise = np.random.default_rng(1).standard_normal((len(probe), action_dim)).astype(np.float32)
    probed = randomised(agent)
    if error := path_error(script, probed, args, probe, probed.obs_norm.normalise, noise):
        refuse(error, envs)
    writer = run.open_writer(resumed)
    guided = uses_null_branch(args)  # PGG
    # The null embedding trains only where the objective reads it: PPO's loss on an empty rollout probes that.
    null_probe = flatten_rollout(Rollout.empty(2, 1, obs_dim, action_dim), torch.zeros(2), torch.zeros(2))  # PGG
    null_probe_loss = lambda: minibatch_loss(agent, null_probe, torch.arange(2), None, None, args)[0]  # PGG
    trained = trained_parameters(agent, guided, null_probe_loss)  # PGG
    # Fused Adam on one flat tensor: CleanRL's per-tensor Adam costs more than our forward pass.
    optimizer = torch.optim.Adam([flatten_parameters(trained)], lr=args.learning_rate, eps=1e-5, fused=True)
    # One fused kernel for the loss and one for its backward, in place of ~200 small ops.
    loss_fn = torch.compile(minibatch_loss) if args.compile else minibatch_loss

    batch_size = args.num_envs * args.num_steps
    # Ceil, not CleanRL's floor, so that the final checkpoint lies at or past total_timesteps.
    num_iterations = -(-args.total_timesteps // batch_size)
    schedule = GuidanceSchedule(args, num_iterations)  # PGG: γ_train of each iteration, from one owner
    buf = Rollout.empty(args.num_steps, args.num_envs, obs_dim, action_dim)

    # A resumed run continues the checkpoint's sub-envs mid-episode; a fresh one resets them, its first observation counted.
    start = run.start_or_resume(resumed, envs, agent.obs_norm.observe, agent, optimizer)
    first_iteration, global_step, next_obs, next_done = start
    schedule.load_state_dict(resumed["resume"].get("guidance") if resumed else None)  # PGG: an adaptive γ_train's
    marks = run.start_progress(global_step, batch_size, num_iterations)

    try:
        for iteration in range(first_iteration, num_iterations + 1):
            if args.anneal_lr:
                optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / num_iterations) * args.learning_rate

            guidance = schedule.value(iteration)  # PGG
            policy = FastPolicy(agent, guidance)  # PGG
            next_obs, next_done = collect_rollout(policy, envs, next_obs, next_done, buf, run.on_episode, global_step)
            global_step += batch_size
            next_value = policy.value(next_obs)
            advantages, returns = compute_gae(buf, next_value, next_done, args.discount, args.gae_lambda)

            # A schedule under --compile feeds γ_train as a tensor, so that a new value compiles no new graph.
            # Otherwise it stays a float: lerp's backward rounds (1 - γ) in double for a float, in float32 for
            # a tensor, and the float is what trained the tables' runs.
            scheduled = args.compile and args.guidance_schedule != "constant"  # PGG
            loss_guidance = (torch.tensor(guidance) if scheduled else guidance) if guided else None  # PGG
            stats = ppo_update(agent, optimizer, buf, advantages, returns, args, loss_guidance, loss_fn)  # PGG
            first_ratio_error(agent, stats)  # the loss, before its first step, gave the rollout's log-probs
            stats.update(guidance_diagnostics(script, agent, buf.obs.reshape(-1, obs_dim), guidance))  # PGG
            schedule.observe(stats)  # PGG: the adaptive rule's step
            stats["charts/action_std_mean"] = agent.actor_logstd.exp().mean().item()
            stats["charts/learning_rate"] = optimizer.param_groups[0]["lr"]
            stats["charts/SPS"] = run.report(global_step, iteration, stats, optimizer.param_groups[0]["params"][0])
            for key, value in stats.items():
                writer.add_scalar(key, value, global_step)

            while marks and global_step >= marks[0]:
                # The trained weights, before they are saved: `act` (the sweep's) and the rollouts still act as the loss.
                if error := path_error(script, agent, args, probe, agent.obs_norm.normalise, noise):
                    raise PathError(f"at step {global_step:,}: {error}")
                resume = training_state.resume_state(iteration, optimizer, envs, next_obs, next_done, schedule)  # PGG
                run.save(marks.popleft(), global_step, agent.state_dict(), shapes, resume)
    finally:
        envs.close()


# agent, ckpt = load_checkpoint(path): this script's checkpoints, loaded by its own make_agent (a fork's by the fork's).
agent_from_checkpoint, load_checkpoint = loading.script_loaders(sys.modules[__name__])


def main() -> None:
    runs.launch_from_command_line(Args, __doc__, ACTION_SPACE, __file__, train)


if __name__ == "__main__":
    main()
