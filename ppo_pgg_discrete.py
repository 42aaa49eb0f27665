"""PPO with Policy Gradient Guidance (PGG) for discrete action spaces.

CleanRL's `ppo.py` plus one learnable *null embedding* that stands in for the observation and gives
the unconditional branch pi(a|null). Rollouts, the PPO ratio and the entropy bonus all use the guided
policy

    pi_hat(a|s) ∝ pi(a|null)^(1-guidance) · pi(a|s)^guidance,
    i.e. softmax((1-guidance)·logits_null + guidance·logits_s).

`guidance` is the PGG strength γ; the discount factor is `discount`. With --guidance 1 --cond-dropout 0
this is CleanRL's PPO with CleanRL's defaults; what differs: the README's "What differs from CleanRL".
Lines that differ from PPO are marked `# PGG`; run management is in pgg_utils.

    python ppo_pgg_discrete.py --env-id CartPole-v1 --guidance 1.1
    python ppo_pgg_discrete.py --env-id CartPole-v1 --guidance 1.1 --resume   # continue a stopped run
    python ppo_pgg_discrete.py --env-id CartPole-v1 --guidance 1.1 --guidance-schedule adaptive --guidance-kl-target 0.01
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
from pgg_utils.distributions import Categorical, guide, gumbel_noise  # PGG: guide, the mix of the branches' logits
from pgg_utils.fast import evaluation_network, flatten_parameters, numpy_network, standard_gumbel
from pgg_utils.guidance import GuidanceArgs, GuidanceSchedule, uses_null_branch  # PGG
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

ACTION_SPACE = "discrete"  # the checkpoints' kind; the sweep picks this script by it


@dataclass
class Args(GuidanceArgs, RunArgs):  # PGG: --guidance, its schedule and --cond-dropout (pgg_utils/guidance.py)
    env_id: str = "CartPole-v1"
    """the id of a gymnasium environment with a Discrete action space"""
    total_timesteps: int = 500_000
    """total environment steps; training runs whole iterations until at least this many"""
    learning_rate: float = 2.5e-4
    """the learning rate of the optimizer"""
    num_envs: int = 4
    """the number of parallel environments"""
    num_steps: int = 128
    """the number of steps per environment per rollout"""
    anneal_lr: bool = True
    """linearly anneal the learning rate to zero"""
    discount: float = 0.99
    """the discount factor (CleanRL's `gamma`; renamed so it cannot be confused with the guidance γ)"""
    gae_lambda: float = 0.95
    """the lambda of generalized advantage estimation"""
    num_minibatches: int = 4
    """the number of minibatches per epoch"""
    update_epochs: int = 4
    """the number of epochs over each rollout"""
    norm_adv: bool = True
    """normalize advantages per minibatch"""
    clip_coef: float = 0.2
    """the PPO surrogate clipping coefficient"""
    clip_vloss: bool = True
    """use a clipped value loss, as in the PPO paper"""
    ent_coef: float = 0.01
    """coefficient of the entropy bonus (of the guided policy)"""
    vf_coef: float = 0.5
    """coefficient of the value loss"""
    max_grad_norm: float = 0.5
    """the maximum norm for gradient clipping"""
    target_kl: float | None = None
    """stop the epochs early when the approximate KL (of the rows not dropped) exceeds this"""


def make_env(env_id: str, video_dir: Path | None = None, render_mode: str | None = None):
    """The task as the agent sees it, for training, the sweep and --video alike. A wrapper added to `env` here
    (reward shaping, a frame stack) shapes what the agent trains on, never the reported return: tasks.task_env
    records the task's own below it. With `video_dir`, RecordVideo records there; `render_mode` is gym.make's."""

    def thunk() -> gym.Env:
        env = tasks.task_env(env_id, video_dir, render_mode)
        return env

    return thunk


def layer_init(layer, std=np.sqrt(2), bias_const=0.0):
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
    """Change the networks here: the rollouts' numpy copy and the evaluation follow the modules
    (pgg_utils/fast.py); the action distribution is `guided_policy`'s. The methods the rest of the
    project calls: AGENT_METHODS."""

    def __init__(self, obs_dim: int, n_actions: int):
        super().__init__()
        self.critic = nn.Sequential(
            layer_init(nn.Linear(obs_dim, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 1), std=1.0),
        )
        self.actor = nn.Sequential(
            layer_init(nn.Linear(obs_dim, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, n_actions), std=0.01),
        )
        # The null embedding, an input that means "no state". Zeros (a neutral point) draw nothing from
        # the RNG: every other weight is initialised exactly as in PPO with the same seed.
        self.null_obs = nn.Parameter(torch.zeros(obs_dim))  # PGG
        self.obs_shape = (obs_dim,)  # what `act` takes

    def get_value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)

    def reset(self) -> None:
        """Begins an episode: a recurrent actor clears its state here (this one holds none)."""

    def unconditional_logits(self) -> torch.Tensor:  # PGG
        """Logits of pi(.|null), shape (n_actions,); one actor pass whatever the batch size."""
        return null_pass(self.actor, self.null_obs.unsqueeze(0))[0]  # PGG

    def branches(self, obs: torch.Tensor, drop_mask=None) -> tuple["Categorical", "Categorical"]:  # PGG
        """pi(.|s) and pi(.|null) for a batch `obs` (B, obs_dim); `drop_mask` (bool, (B,)) nulls those rows' pi(.|s)."""
        logits_cond, logits_null = branch_pass(self.actor, obs, self.null_obs.unsqueeze(0))  # PGG
        if drop_mask is not None:  # PGG
            logits_cond = torch.where(drop_mask.unsqueeze(-1), logits_null, logits_cond)  # PGG
        return Categorical(logits_cond), Categorical(logits_null)  # PGG

    def policy(self, obs: torch.Tensor, guidance: torch.Tensor | float | None, drop_mask=None) -> "Categorical":  # PGG
        """pi_hat(.|obs), the loss's. `guidance` None: PPO's own actor pass (the null embedding gets no gradient), still
        through guided_policy (at 1, exactly pi(.|s)), so that a changed distribution changes it too."""
        if guidance is None and drop_mask is None:  # PGG
            cond = Categorical(self.actor(obs))
            return guided_policy(cond, cond, 1.0)  # PGG
        return guided_policy(*self.branches(obs, drop_mask), 1.0 if guidance is None else guidance)  # PGG

    def acting_policy(self, obs: np.ndarray, guidance, logits_null=None):  # PGG
        """pi_hat for a float32 batch `obs`, in numpy (`act` samples from it), by FastPolicy."""
        return FastPolicy(self, acting=True, logits_null=logits_null).distribution(obs, guidance)  # PGG

    @torch.no_grad()
    def act(self, obs, guidance=1.0, deterministic: bool = False, noise=None, logits_null=None, seed=None) -> np.ndarray:  # PGG  # fmt: skip
        """Actions of pi_hat at `guidance` (a number, or one per row) for observations (one, or a batch), as the sweep
        acts: Gumbel-max samples with standard Gumbel `noise` (None: drawn, from a generator seeded by `seed` if
        given), or the mode if `deterministic` (pgg_utils.policy.guided_actions)."""
        obs, draw = np.asarray(obs, dtype=np.float32), lambda pi: gumbel_noise(*pi.logits.shape)
        return guided_actions(self, obs, guidance, deterministic, noise, logits_null, draw, seed)  # PGG

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = False, guidance=1.0):  # PGG
        """Stable-Baselines3's `model.predict`: (`act`'s actions, None); `state` and `episode_start` unused, as SB3's."""
        return self.act(obs, guidance, deterministic), None  # PGG


# The methods of Agent that the rest of the project calls, and who calls each (checked when training starts).
AGENT_METHODS = {
    "get_value": "the loss",
    "policy": "the loss",
    "branches": "guidance_diagnostics",  # PGG
    "unconditional_logits": "the sweep",  # PGG
    "acting_policy": "act, pgg_utils/bc_null.py",  # PGG
    "act": "the sweep",
    "reset": "the sweep",
}


def make_agent(args: dict, shapes: dict) -> Agent:
    """The agent of a run from its training arguments and the task's shapes (tasks.checkpoint_shapes): the one
    constructor of training and of checkpoint loading, so an argument added to the network reaches both."""
    return Agent(shapes["obs_dim"], shapes["n_actions"])


def guided_policy(cond: "Categorical", null: "Categorical", guidance) -> "Categorical":  # PGG
    """pi_hat ∝ pi(.|null)^(1-γ) · pi(.|s)^γ, the one definition of the action distribution (the loss, the rollouts
    and `act` take it from here): the natural parameters, the logits, mix. Torch or numpy; a fork's distribution
    has Categorical's methods."""
    return Categorical(guide(cond.logits, null.logits, guidance))  # PGG


# --- the behaviour policy, in numpy: ~1.3x faster training than torch's per-call dispatch, same float32 arithmetic


class FastPolicy:
    """pi_hat and the critic in numpy, derived from the agent's modules and guided_policy. For a rollout: numpy
    copies on views of the weights, pi(.|null) cached, one per rollout. For `act` (`acting=True`): the modules' own
    forward, rounded independently of the batch's other rows (pgg_utils/fast.py)."""

    def __init__(self, agent: Agent, guidance=None, acting: bool = False, logits_null=None):  # PGG
        network = evaluation_network if acting else numpy_network
        self.actor, self.critic = network(agent.actor), network(agent.critic)
        self.guidance = guidance  # PGG
        if logits_null is None:  # PGG
            with torch.no_grad():  # PGG
                logits_null = agent.unconditional_logits().numpy()  # PGG
        self.logits_null = logits_null  # PGG
        self.n_actions = len(self.logits_null)  # PGG

    def distribution(self, obs: np.ndarray, guidance) -> "Categorical":  # PGG
        """pi_hat for a batch `obs` at `guidance` (a number, or one per row)."""
        cond, null = Categorical(self.actor(obs)), Categorical(self.logits_null)  # PGG
        return numpy_policy(guided_policy, cond, null, guidance)  # PGG

    def act(self, obs: np.ndarray, gumbel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(actions, log pi_hat(action|obs), values) for a batch `obs`. Actions are sampled by the
        Gumbel-max trick with `gumbel`, standard Gumbel noise shaped like the logits."""
        actions, log_probs = self.distribution(obs, self.guidance).sample_log_prob(gumbel)  # PGG
        return actions, log_probs, self.value(obs)

    def value(self, obs: np.ndarray) -> np.ndarray:
        return self.critic(obs)[:, 0]


# --- rollout, GAE, loss, update ------------------------------------------------------------------


def collect_rollout(policy: FastPolicy, envs, next_obs, next_done, buf: Rollout, on_episode, global_step: int):
    """Fills `buf` (a pgg_utils.rollout.Rollout) with num_steps transitions from the guided policy and returns the
    (obs, done) to start the next rollout from. `on_episode(return, length, step)` is called per finished episode,
    at the global step it ended (CleanRL's logging step)."""
    # Numpy views of the buffers: a write costs a fraction of a torch indexing call.
    obs_buf, dones_buf, actions_buf, logprobs_buf, values_buf, rewards_buf = (
        t.numpy() for t in (buf.obs, buf.dones, buf.actions, buf.logprobs, buf.values, buf.rewards)
    )
    gumbel = gumbel_noise(*buf.obs.shape[:2], policy.n_actions)  # one draw per rollout: cheaper than one per step
    for step in range(buf.obs.shape[0]):
        obs_buf[step] = next_obs
        dones_buf[step] = next_done
        actions_buf[step], logprobs_buf[step], values_buf[step] = policy.act(next_obs, gumbel[step])

        obs, reward, terminations, truncations, infos = envs.step(actions_buf[step])
        # Truncation ends the episode without bootstrapping, as in CleanRL's ppo.py.
        next_done = np.logical_or(terminations, truncations).astype(np.float32)
        next_obs = obs.astype(np.float32, copy=False)
        rewards_buf[step] = reward
        for episodic_return, episodic_length in tasks.ended_episodes(infos):  # the task's own (tasks.task_env)
            on_episode(episodic_return, episodic_length, global_step + (step + 1) * len(next_obs))
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


def null_bc_loss(agent: Agent, actions: torch.Tensor, route: str) -> torch.Tensor:  # PGG
    """Mean -log pi(a|null) of the rollout's actions: behaviour cloning by the unconditional branch. Route
    "null": the actor's weights are held for this term, so it trains the null embedding alone; "actor": it
    trains the shared actor as well. In eval mode: a BatchNorm takes the one row and keeps its statistics."""
    with frozen(agent.actor):  # PGG
        if route == "null":  # PGG
            held = {name: weight.detach() for name, weight in agent.actor.named_parameters()}  # PGG
            logits_null = torch.func.functional_call(agent.actor, held, (agent.null_obs.unsqueeze(0),))  # PGG
        else:  # PGG
            logits_null = agent.actor(agent.null_obs.unsqueeze(0))  # PGG
    return nn.functional.cross_entropy(logits_null.expand(len(actions), -1), actions)  # PGG


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
        loss = loss + args.null_bc_coef * null_bc_loss(agent, batch["actions"][mb_inds], args.null_bc_route)  # PGG
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

    envs = tasks.make_vector_env(make_env, args.env_id, args.num_envs, args.seed, run.video_dir(resumed))
    shapes, error = tasks.trained_task(script, args.env_id, envs)  # make_env's task, as swept
    if error:
        refuse(error, envs)
    if (start := int(envs.single_action_space.start)) != 0:
        refuse(f"{args.env_id}'s actions start at {start}; this script acts with 0..n-1: shift them in make_env "
               "(gymnasium.wrappers.TransformAction) or start the space at 0", envs)  # fmt: skip
    obs_dim = envs.single_observation_space.shape[0]
    agent = make_agent(asdict(args), shapes)
    # Before anything is written: the rollouts, `act` and the loss must compute guided_policy's distribution, on an
    # agent whose every parameter is drawn at random (a fresh one's zeros would hide a path's difference).
    probe = probe_observations(envs.single_observation_space)
    gumbel = standard_gumbel(np.random.default_rng(1).random((len(probe), envs.single_action_space.n), np.float32))
    as_input = lambda raw: raw.astype(np.float32)
    if error := path_error(script, randomised(agent), args, probe, as_input, gumbel):
        refuse(error, envs)
    writer = run.open_writer(resumed)
    guided = uses_null_branch(args)  # PGG
    # The null embedding trains only where the objective reads it: PPO's loss on an empty rollout probes that.
    null_probe = flatten_rollout(Rollout.empty(2, 1, obs_dim), torch.zeros(2), torch.zeros(2))  # PGG
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
    buf = Rollout.empty(args.num_steps, args.num_envs, obs_dim)

    # A resumed run continues the checkpoint's sub-envs mid-episode; a fresh one resets them.
    first_iteration, global_step, next_obs, next_done = run.start_or_resume(resumed, envs, as_input, agent, optimizer)
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
            stats["charts/learning_rate"] = optimizer.param_groups[0]["lr"]
            stats["charts/SPS"] = run.report(global_step, iteration, stats, optimizer.param_groups[0]["params"][0])
            for key, value in stats.items():
                writer.add_scalar(key, value, global_step)

            while marks and global_step >= marks[0]:
                # The trained weights, before they are saved: `act` (the sweep's) and the rollouts still act as the loss.
                if error := path_error(script, agent, args, probe, as_input, gumbel):
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
