"""PPO with Policy Gradient Guidance (PGG) for discrete action spaces.

CleanRL's `ppo.py` plus one learnable *null embedding* that stands in for the observation and gives
the unconditional branch pi(a|null). Rollouts, the PPO ratio and the entropy bonus all use the guided
policy

    pi_hat(a|s) ∝ pi(a|null)^(1-guidance) · pi(a|s)^guidance,
    i.e. softmax((1-guidance)·logits_null + guidance·logits_s).

`guidance` is the PGG strength γ of the paper; the discount factor is `discount`, never "gamma".
With --guidance 1 --cond-dropout 0 this script is exactly CleanRL's PPO (tests/test_discrete.py).
Lines that PGG adds to PPO are marked `# PGG`.

    python ppo_pgg_discrete.py --env-id CartPole-v1 --guidance 1.1
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

    # Algorithm arguments (CleanRL's discrete PPO defaults)
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
    """stop the epochs early when the approximate KL exceeds this"""

    # PGG arguments
    guidance: float = 1.0
    """PGG guidance strength γ used for rollouts and updates (1 = vanilla PPO; the paper trains with 1.1)"""
    cond_dropout: float = 0.0
    """probability that a sample's actor input is replaced by the null embedding during updates"""
    checkpoint_interval: int = 100_000
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
    except gym.error.Error as e:
        return f"cannot make environment {args.env_id!r}: {e}"
    action_space = env.action_space
    env.close()
    if not isinstance(action_space, gym.spaces.Discrete):
        return f"{args.env_id} has a {type(action_space).__name__} action space; this script needs Discrete (use ppo_pgg_continuous.py)"
    return None


def make_env(env_id: str):
    def thunk():
        return gym.make(env_id)

    return thunk


def make_vector_env(env_id: str, num_envs: int, seed: int) -> gym.vector.VectorEnv:
    """Vector env that resets a finished sub-env within the same step (the gym 0.29 convention GAE
    below relies on): the observation returned with done=True is the next episode's first one.
    Episode statistics are recorded per sub-env, as in CleanRL: gymnasium 1.4's vector wrapper for
    them cost ~1.5 µs more per env step, about 2% of training here."""
    envs = gym.vector.SyncVectorEnv(
        [lambda: gym.wrappers.RecordEpisodeStatistics(make_env(env_id)()) for _ in range(num_envs)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )
    envs.action_space.seed(seed)
    return envs


def layer_init(layer, std=np.sqrt(2), bias_const=0.0):
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
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
        # PGG: the null embedding, an observation-shaped input that means "no state". Initialised to
        # zeros: that draws nothing from the RNG, so with the same seed every other weight is
        # initialised exactly as in vanilla PPO; and 0 is a neutral point of the input space.
        self.null_obs = nn.Parameter(torch.zeros(obs_dim))

    def get_value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)

    def unconditional_logits(self) -> torch.Tensor:
        """PGG: logits of pi(.|null), shape (n_actions,); one actor pass whatever the batch size."""
        return self.actor(self.null_obs.unsqueeze(0))[0]

    def guided_logits(
        self, obs: torch.Tensor, guidance: float, drop_mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Logits of pi_hat(.|obs) for a batch `obs` of shape (B, obs_dim). `drop_mask` (bool, (B,))
        replaces those rows' conditional branch by the unconditional one (conditioning dropout)."""
        if guidance == 1.0 and drop_mask is None:
            # pi_hat = pi exactly, from PPO's own actor pass: an extra null row could change how the
            # product is blocked, hence its rounding. The null embedding gets no gradient (and train
            # leaves it out of the optimizer).
            return self.actor(obs)
        # PGG: the null embedding rides along as one extra row of the same actor pass; a separate
        # one-row pass costs as much as the whole batch at this network size. (Its value can differ
        # from `unconditional_logits()`, a one-row product, in the last float bit.)
        logits_cond, logits_null = self.actor(torch.cat([obs, self.null_obs.unsqueeze(0)])).split([len(obs), 1])
        if drop_mask is not None:  # PGG
            logits_cond = torch.where(drop_mask.unsqueeze(-1), logits_null, logits_cond)
        # PGG: guide() in one op, null + γ·(cond - null) (equal up to the last float bit): its three
        # ops and their backward had cost a tenth of the actor's forward and backward.
        return torch.lerp(logits_null, logits_cond, guidance)


def guide(cond, null, guidance: float):
    """PGG: (1-γ)·null + γ·cond, for torch tensors or numpy arrays; exactly `cond` at γ=1."""
    return (1.0 - guidance) * null + guidance * cond


def numpy_layers(mlp: nn.Sequential) -> list[tuple[np.ndarray, np.ndarray]]:
    """(weight transposed, bias) of each Linear layer, as numpy views of the parameters."""
    return [(layer.weight.detach().numpy().T, layer.bias.detach().numpy()) for layer in mlp if isinstance(layer, nn.Linear)]


def numpy_forward(layers, x: np.ndarray) -> np.ndarray:
    """The Agent's Linear-Tanh-...-Linear networks, in numpy."""
    for weight, bias in layers[:-1]:
        x = np.tanh(x @ weight + bias)
    weight, bias = layers[-1]
    return x @ weight + bias


def gumbel_noise(*shape: int) -> np.ndarray:
    """Standard Gumbel noise from torch's generator: argmax(logits + noise) is an exact categorical
    sample (the Gumbel-max trick), far cheaper than torch.distributions."""
    uniform = torch.rand(*shape).clamp_min_(np.finfo(np.float32).tiny)
    return -np.log(-np.log(uniform.numpy()))


class RolloutPolicy:
    """pi_hat and the critic for acting during one rollout, in numpy, on views of the agent's weights
    (they are fixed until the update). On a batch of a few observations every torch call pays
    microseconds of dispatch, an nn.Sequential pass ~35 µs, and these made up most of a rollout step;
    the same float32 arithmetic in numpy made training ~1.3x faster (README, Performance). The values
    agree with the Agent's to float rounding (tests/test_equivalence.py). It caches pi(.|null):
    build one per rollout."""

    def __init__(self, agent: Agent, guidance: float):
        self.actor, self.critic = numpy_layers(agent.actor), numpy_layers(agent.critic)
        self.guidance = guidance
        with torch.no_grad():
            self.logits_null = agent.unconditional_logits().numpy()  # PGG: pi(.|null) is fixed here too

    def act(self, obs: np.ndarray, gumbel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(actions, log pi_hat(action|obs), values) for a batch `obs`. Actions are sampled by the
        Gumbel-max trick with `gumbel`, standard Gumbel noise shaped like the logits."""
        logits = guide(numpy_forward(self.actor, obs), self.logits_null, self.guidance)  # PGG: act with pi_hat
        actions = (logits + gumbel).argmax(-1)
        shifted = logits - logits.max(-1, keepdims=True)
        # The log-softmax of the sampled actions only: a third of the cost of the full one.
        log_probs = shifted[np.arange(len(actions)), actions] - np.log(np.exp(shifted).sum(-1))
        return actions, log_probs, self.value(obs)

    def value(self, obs: np.ndarray) -> np.ndarray:
        return numpy_forward(self.critic, obs)[:, 0]


@dataclass
class Rollout:
    obs: torch.Tensor  # (num_steps, num_envs, obs_dim)
    actions: torch.Tensor  # (num_steps, num_envs), int64
    logprobs: torch.Tensor  # (num_steps, num_envs), log pi_hat(a|s) at collection time
    rewards: torch.Tensor  # (num_steps, num_envs)
    dones: torch.Tensor  # (num_steps, num_envs): 1 where obs[t] is the first observation of an episode
    values: torch.Tensor  # (num_steps, num_envs)

    @classmethod
    def empty(cls, num_steps: int, num_envs: int, obs_dim: int) -> "Rollout":
        zeros = lambda *shape: torch.zeros(shape)  # noqa: E731
        return cls(
            obs=zeros(num_steps, num_envs, obs_dim),
            actions=torch.zeros((num_steps, num_envs), dtype=torch.long),
            logprobs=zeros(num_steps, num_envs),
            rewards=zeros(num_steps, num_envs),
            dones=zeros(num_steps, num_envs),
            values=zeros(num_steps, num_envs),
        )


def collect_rollout(policy: RolloutPolicy, envs, next_obs, next_done, buf: Rollout, on_episode):
    """Fills `buf` with num_steps transitions from the guided policy and returns the (obs, done)
    numpy arrays to start the next rollout from. `on_episode(return, length)` is called per
    finished episode."""
    # Numpy views of the buffers: a write costs a fraction of a torch indexing call.
    obs_buf, dones_buf, actions_buf, logprobs_buf, values_buf, rewards_buf = (
        t.numpy() for t in (buf.obs, buf.dones, buf.actions, buf.logprobs, buf.values, buf.rewards)
    )
    gumbel = gumbel_noise(*buf.obs.shape[:2], len(policy.logits_null))  # the whole rollout's, in one draw
    for step in range(buf.obs.shape[0]):
        obs_buf[step] = next_obs
        dones_buf[step] = next_done
        actions_buf[step], logprobs_buf[step], values_buf[step] = policy.act(next_obs, gumbel[step])

        obs, reward, terminations, truncations, infos = envs.step(actions_buf[step])
        # Truncation ends the episode without bootstrapping, as in CleanRL's ppo.py.
        next_done = np.logical_or(terminations, truncations).astype(np.float32)
        next_obs = obs.astype(np.float32, copy=False)
        rewards_buf[step] = reward
        if "final_info" in infos:  # a sub-env ended an episode; its last step's info is kept here
            ended = infos["final_info"]
            for i in np.flatnonzero(ended["_episode"]):
                on_episode(float(ended["episode"]["r"][i]), int(ended["episode"]["l"][i]))
    return next_obs, next_done


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
    over their tensors in Python: for this agent's 13 small ones that was ~300 µs per minibatch, about a
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
    logp_all = agent.guided_logits(mb_obs, args.guidance, drop_mask).log_softmax(-1)  # PGG
    newlogprob = logp_all.gather(-1, batch["actions"][mb_inds].unsqueeze(-1)).squeeze(-1)
    entropy = -(logp_all.exp() * logp_all).sum(-1)
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
        "actions": buf.actions.reshape(-1),
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
    """PGG: how far guidance moves the policy, and what the unconditional branch has learned."""
    logp_guided = agent.guided_logits(obs, guidance).log_softmax(-1)
    logp_cond = agent.actor(obs).log_softmax(-1)
    logp_null = agent.unconditional_logits().log_softmax(-1)
    return {
        "pgg/kl_guided_vs_conditional": (logp_guided.exp() * (logp_guided - logp_cond)).sum(-1).mean().item(),
        "pgg/entropy_unconditional": -(logp_null.exp() * logp_null).sum().item(),
        "pgg/null_embedding_norm": agent.null_obs.norm().item(),
    }


def checkpoint_marks(total_timesteps: int, interval: int) -> list[int]:
    """Nominal steps that get a checkpoint: every multiple of `interval` below the total, and the total."""
    return list(range(interval, total_timesteps, interval)) + [total_timesteps]


def checkpoint_path(run_dir: Path, mark: int) -> Path:
    return run_dir / "checkpoints" / f"step_{mark:09d}.pt"


def save_checkpoint(path: Path, agent: Agent, args: Args, global_step: int, mark: int, envs) -> None:
    """Self-contained, pickle-free checkpoint (loads with weights_only=True), written atomically."""
    payload = {
        "format_version": CHECKPOINT_FORMAT_VERSION,
        "script": "ppo_pgg_discrete",
        "action_space": "discrete",
        "env_id": args.env_id,
        "obs_dim": int(envs.single_observation_space.shape[0]),
        "n_actions": int(envs.single_action_space.n),
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
    """Rebuilds the agent from a checkpoint file; returns (agent in eval mode, the checkpoint dict)."""
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    return agent_from_checkpoint(ckpt, path), ckpt


def agent_from_checkpoint(ckpt: dict, source: str | Path = "checkpoint") -> Agent:
    """The agent, in eval mode, of an already loaded checkpoint dict."""
    if ckpt.get("format_version") != CHECKPOINT_FORMAT_VERSION or ckpt.get("action_space") != "discrete":
        raise ValueError(f"{source} is not a discrete PGG checkpoint of format {CHECKPOINT_FORMAT_VERSION}")
    agent = Agent(ckpt["obs_dim"], ckpt["n_actions"])
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

    envs = make_vector_env(args.env_id, args.num_envs, args.seed)
    obs_dim = envs.single_observation_space.shape[0]
    agent = Agent(obs_dim, envs.single_action_space.n)
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
    buf = Rollout.empty(args.num_steps, args.num_envs, obs_dim)
    recent_returns = deque(maxlen=20)
    global_step = 0

    def on_episode(episodic_return: float, episodic_length: int):
        recent_returns.append(episodic_return)
        writer.add_scalar("charts/episodic_return", episodic_return, global_step)
        writer.add_scalar("charts/episodic_length", episodic_length, global_step)

    start_time = time.time()
    obs, _ = envs.reset(seed=args.seed)
    next_obs = obs.astype(np.float32)
    next_done = np.zeros(args.num_envs, dtype=np.float32)

    for iteration in range(1, num_iterations + 1):
        if args.anneal_lr:
            optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / num_iterations) * args.learning_rate

        policy = RolloutPolicy(agent, args.guidance)
        next_obs, next_done = collect_rollout(policy, envs, next_obs, next_done, buf, on_episode)
        global_step += batch_size
        next_value = policy.value(next_obs)
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
