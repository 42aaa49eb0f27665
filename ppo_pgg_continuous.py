"""PPO with Policy Gradient Guidance (PGG) for continuous (Box) action spaces, e.g. MuJoCo.

CleanRL's `ppo_continuous_action.py` plus one learnable *null embedding* that stands in for the
(normalised) observation and gives the unconditional mean mu_null. The guided policy

    pi_hat(a|s) ∝ N(a; mu_null, σ)^(1-guidance) · N(a; mu_s, σ)^guidance
               = N(a; (1-guidance)·mu_null + guidance·mu_s, σ)          (shared σ, exactly)

drives rollouts, the PPO ratio and the entropy. `guidance` is the PGG strength γ of the paper; the
discount factor is `discount`, never "gamma". With --guidance 1 --cond-dropout 0 this script runs
CleanRL's PPO algorithm with CleanRL's defaults and one fix: the observation-normalisation statistics
live inside the agent, so every checkpoint carries them and evaluates on the scale it was trained on
(CleanRL issue 425). What else differs from CleanRL's `ppo_continuous_action.py` is listed, one line
each, in the README's "What differs from CleanRL"; `benchmarks/compare_cleanrl.py` compares the
learning curves with CleanRL's own script. Lines that PGG adds to PPO are marked `# PGG`.

    python ppo_pgg_continuous.py --env-id Hopper-v4 --guidance 1.1
    python ppo_pgg_continuous.py --env-id Hopper-v4 --guidance 1.1 --resume   # continue a stopped run
"""

import fcntl
import importlib.metadata
import importlib.util
import json
import math
import os
import platform
import random
import shutil
import sys
import time
import warnings
from collections import defaultdict, deque
from dataclasses import asdict, dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
import torch.nn as nn
import tyro
from torch.utils.tensorboard import SummaryWriter

# 2 added what resuming needs ("resume") and the package versions; format 1 still loads for evaluation.
CHECKPOINT_FORMAT_VERSION = 2
READABLE_FORMAT_VERSIONS = (1, 2)
MAX_GUIDANCE = 1000.0
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
    """compile the minibatch loss and its backward with torch.compile (needs a C++ compiler): updates ~1.6x faster after a one-off compile of ~20 s (~3 s from inductor's cache); the same algorithm, rounded differently (README, Performance)"""
    track: bool = False
    """if toggled, track the run with Weights and Biases (needs `pip install wandb`)"""
    wandb_project_name: str = "pgg"
    """the W&B project name"""
    wandb_entity: str | None = None
    """the W&B entity (team)"""
    output_dir: str = "runs"
    """directory under which the run directory is created"""
    run_name: str | None = None
    """run directory name; None: `{env_id}__{exp_name}__g{guidance}__p{cond_dropout}__s{seed}`"""
    resume: bool = False
    """continue the run in the run directory from its last checkpoint (start it if it has none)"""
    overwrite: bool = False
    """replace a run directory that holds checkpoints of a finished run or of other arguments"""
    capture_video: bool = False
    """record videos of the first sub-env's episodes into `{run_dir}/videos` (needs the [video] extra and, for MuJoCo, a GL backend: MUJOCO_GL=egl or osmesa)"""

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
    """save a checkpoint at the first iteration boundary past each multiple of this many steps (at least one batch, num_envs * num_steps)"""


# Arguments that change where and how a run is recorded or how fast it runs, never what it learns
# (--compile, the thread count and deterministic kernels change float rounding only). The sweep keys
# a training configuration on all the other arguments except the seed.
RUN_ONLY_ARGS = frozenset({
    "exp_name", "torch_deterministic", "torch_threads", "compile", "track", "wandb_project_name",
    "wandb_entity", "output_dir", "run_name", "resume", "overwrite", "capture_video", "checkpoint_interval",
})  # fmt: skip


def guidance_error(value: float, flag: str = "--guidance") -> str | None:
    """The one rule for a guidance strength, in training and in the sweep's --gammas."""
    if not (math.isfinite(value) and 0.0 <= value <= MAX_GUIDANCE):
        return f"{flag} must be a number in [0, {MAX_GUIDANCE:g}], got {value!r}"
    return None


def check_args(args: Args) -> str | None:
    """Returns a one-line description of what is wrong with `args`, or None. Touches no file."""
    rules = {  # NaN fails every comparison
        "learning_rate": (lambda v: 0 < v < math.inf, "a finite number > 0"),
        "discount": (lambda v: 0 <= v <= 1, "in [0, 1]"),
        "gae_lambda": (lambda v: 0 <= v <= 1, "in [0, 1]"),
        "clip_coef": (lambda v: 0 < v < math.inf, "a finite number > 0"),
        "ent_coef": (lambda v: 0 <= v < math.inf, "a finite number >= 0"),
        "vf_coef": (lambda v: 0 <= v < math.inf, "a finite number >= 0"),
        "max_grad_norm": (lambda v: 0 < v < math.inf, "a finite number > 0"),
        "target_kl": (lambda v: v is None or 0 < v < math.inf, "a finite number > 0"),
        "cond_dropout": (lambda v: 0 <= v <= 1, "in [0, 1]"),
        "total_timesteps": (lambda v: v > 0, "positive"),
        "num_envs": (lambda v: v > 0, "positive"),
        "num_steps": (lambda v: v > 0, "positive"),
        "update_epochs": (lambda v: v > 0, "positive"),
        "torch_threads": (lambda v: v > 0, "positive"),
        "obs_clip": (lambda v: 0 < v <= math.inf, "> 0"),
        "reward_clip": (lambda v: 0 < v <= math.inf, "> 0"),
    }
    for name, (holds, requirement) in rules.items():
        if not holds(getattr(args, name)):
            return f"--{name.replace('_', '-')} must be {requirement}, got {getattr(args, name)!r}"
    if error := guidance_error(args.guidance):
        return error
    batch_size = args.num_envs * args.num_steps
    if args.num_minibatches <= 0 or batch_size % args.num_minibatches:
        return f"--num-minibatches must divide num_envs * num_steps = {batch_size}"
    if args.checkpoint_interval < batch_size:
        return f"--checkpoint-interval must be at least one batch, num_envs * num_steps = {batch_size}"
    if args.resume and args.overwrite:
        return "--resume and --overwrite exclude each other"
    if args.compile and not any(shutil.which(cxx) for cxx in (os.environ.get("CXX", "g++"), "g++", "clang++")):
        return "--compile needs a C++ compiler (g++ or clang++ on PATH, or $CXX)"
    if args.track and importlib.util.find_spec("wandb") is None:
        return "--track needs Weights and Biases: pip install wandb"
    try:
        env = gym.make(args.env_id, render_mode="rgb_array" if args.capture_video else None)
    except ImportError as e:
        if args.env_id == "Pusher-v4":
            return (
                "Pusher-v4 needs mujoco<3 (pip install mujoco==2.3.7, Python <= 3.11); "
                "with a newer mujoco use Pusher-v5"
            )
        return f"cannot make environment {args.env_id!r}: {e}"
    except Exception as e:  # unknown ids, missing dependencies, a bad MUJOCO_GL: whatever the env's import raises
        return f"cannot make environment {args.env_id!r}: {e}"
    action_space = env.action_space
    error = video_error(env) if args.capture_video else None
    env.close()
    if not isinstance(action_space, gym.spaces.Box):
        return f"{args.env_id} has a {type(action_space).__name__} action space; this script needs Box (use ppo_pgg_discrete.py)"
    return error


def video_error(env: gym.Env) -> str | None:
    """Why this env cannot be recorded here (a missing package or rendering backend), or None."""
    try:
        import moviepy  # noqa: F401  (gymnasium's RecordVideo writes with it)

        env.reset(seed=0)
        with warnings.catch_warnings():  # a failing GL backend warns before it raises
            warnings.simplefilter("ignore")
            if env.render() is None:
                return f"{env.spec.id} renders no frames"
    except ImportError as e:
        return f"--capture-video needs the [video] extra (pip install -e '.[video]'): {e}"
    except Exception as e:  # rendering backends fail with anything from OpenGL, pygame or MuJoCo
        hint = "; headless MuJoCo needs MUJOCO_GL=egl or osmesa (apt-get install libosmesa6)" if "mujoco" in type(env.unwrapped).__module__ else ""
        return f"--capture-video cannot render {env.spec.id} here ({type(e).__name__}: {e}){hint}"
    return None


def make_env(env_id: str, video_dir: Path | None = None):
    def thunk():
        if video_dir is None:
            return gym.wrappers.FlattenObservation(gym.make(env_id))
        env = gym.wrappers.RecordVideo(gym.make(env_id, render_mode="rgb_array"), str(video_dir), disable_logger=True)
        return gym.wrappers.FlattenObservation(env)

    return thunk


def make_vector_env(
    env_id: str, num_envs: int, seed: int, discount: float, reward_clip: float, video_dir: Path | None = None
) -> gym.vector.VectorEnv:
    """Vector env that resets a finished sub-env within the same step (the gym 0.29 convention GAE
    below relies on). Episode statistics are recorded on raw rewards, before normalisation.
    Observations come out raw: the agent normalises them itself (see RunningObsNorm).
    The wrappers sit on each sub-env, as in CleanRL (so do the reward statistics): gymnasium 1.4's
    vector versions of them cost ~40 µs more per step, a sixth of a Hopper env step. With
    `video_dir`, the first sub-env's episodes are recorded there (CleanRL's schedule: episodes 0, 1,
    8, 27, ..., 1000, 2000, ...)."""

    def training_env(video_dir: Path | None):
        env = gym.wrappers.RecordEpisodeStatistics(make_env(env_id, video_dir)())
        env = gym.wrappers.ClipAction(env)
        return NormalizeClipReward(env, discount, reward_clip)

    envs = gym.vector.SyncVectorEnv(
        [lambda i=i: training_env(video_dir if i == 0 else None) for i in range(num_envs)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )
    envs.action_space.seed(seed)
    return envs


# What a sub-env carries from one step to the next, besides its RNG and a MuJoCo task's simulation
# state: wrapper counters (time limit, episode statistics, reward scaling) and a classic-control task's
# physical state. Saved with a checkpoint so that a resumed run continues the very episodes it was in.
ENV_STATE_ATTRIBUTES = (
    "_elapsed_steps", "_has_reset", "episode_returns", "episode_lengths", "state", "steps_beyond_terminated",
    "discounted_return", "return_mean", "return_var", "return_count",
)  # fmt: skip


def wrapper_chain(env: gym.Env):
    while True:
        yield env
        if not isinstance(env, gym.Wrapper):
            return
        env = env.env


def pickle_free(value):
    """`value` as a checkpoint can hold it: arrays as tensors, numpy scalars as Python numbers."""
    if isinstance(value, np.ndarray):
        return torch.from_numpy(value.copy())
    return value.item() if isinstance(value, np.generic) else value


def env_state(envs) -> list[dict]:
    """The state of every sub-env as plain values and tensors (pickle-free): its wrappers' counters and
    statistics, its RNG and, where it is a classic-control or MuJoCo task, the task's own state
    ("complete"; for other tasks a resumed run starts fresh episodes)."""
    states = []
    for env in envs.envs:
        task = env.unwrapped
        layers = [
            {name: pickle_free(value) for name, value in vars(layer).items() if name in ENV_STATE_ATTRIBUTES}
            for layer in wrapper_chain(env)
        ]
        complete = hasattr(task, "state") or hasattr(task, "data")
        states.append({"layers": layers, "rng": task.np_random.bit_generator.state, "complete": complete})
        if hasattr(task, "data"):
            # MuJoCo: every array of mjData, not only the integration state. Quantities derived from
            # the state (body positions, contact forces) lag it by one step after mj_step, and some
            # tasks read them (Humanoid's reward and observation): mj_forward would not restore them.
            data = task.data
            arrays = {name: getattr(data, name) for name in dir(data) if not name.startswith("_")}
            states[-1]["mujoco"] = {name: torch.from_numpy(a.copy()) for name, a in arrays.items() if isinstance(a, np.ndarray)}
            states[-1]["mujoco_time"] = float(data.time)
    return states


def restore_env_state(envs, states: list[dict]) -> None:
    for env, state in zip(envs.envs, states):
        for layer, saved in zip(wrapper_chain(env), state["layers"]):
            for name, value in saved.items():
                setattr(layer, name, value.numpy().copy() if isinstance(value, torch.Tensor) else value)
        env.unwrapped.np_random.bit_generator.state = state["rng"]
        if "mujoco" in state:
            data = env.unwrapped.data
            for name, saved in state["mujoco"].items():
                target = getattr(data, name)
                # Arrays sized by the contacts of the moment may differ in shape; the next step recomputes them.
                if target.flags.writeable and target.shape == tuple(saved.shape):
                    target[...] = saved.numpy()
            data.time = state["mujoco_time"]


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
    as buffers so that they are saved in the state dict. Only training rollouts update them, with the
    observations CleanRL's per-sub-env NormalizeObservation sees, in its order: every observation that
    a reset or a step returns, an episode's last one included (`collect_rollout`; on numpy views, as
    a dozen torch ops on a few numbers cost more than a MuJoCo step). Evaluation reads them frozen.
    With several sub-envs the statistics are pooled over them (CleanRL keeps one set per sub-env,
    which no single checkpoint could carry)."""

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

    def update_statistics(self, raw_obs: np.ndarray) -> None:
        """Adds the rows of `raw_obs` to the agent's observation statistics."""
        update_running_moments(self.obs_mean, self.obs_var, self.obs_count, raw_obs)

    def observe(self, raw_obs: np.ndarray) -> np.ndarray:
        """Adds `raw_obs` to the agent's observation statistics and returns it normalised by them."""
        self.update_statistics(raw_obs)
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


def collect_rollout(policy: RolloutPolicy, envs, next_obs, next_done, buf: Rollout, on_episode, global_step: int):
    """Fills `buf` with num_steps transitions from the guided policy, updating the observation
    statistics as it goes, and returns the (normalised obs, done) numpy arrays to start the next
    rollout from. `on_episode(return, length, step)` is called per finished episode with its raw
    (unnormalised) return and the global step at which it ended (CleanRL's logging step);
    `global_step` is the step count before this rollout."""
    # Numpy views of the buffers: a write costs a fraction of a torch indexing call.
    obs_buf, dones_buf, actions_buf, logprobs_buf, values_buf, rewards_buf = (
        t.numpy() for t in (buf.obs, buf.dones, buf.actions, buf.logprobs, buf.values, buf.rewards)
    )
    noise = torch.randn(buf.actions.shape).numpy()  # the whole rollout's, in one draw
    for step in range(buf.obs.shape[0]):
        obs_buf[step] = next_obs
        dones_buf[step] = next_done
        actions_buf[step], logprobs_buf[step], values_buf[step] = policy.act(next_obs, noise[step])

        raw_obs, reward, terminations, truncations, infos = envs.step(actions_buf[step])
        # Truncation ends the episode without bootstrapping, as in CleanRL's PPO.
        next_done = np.logical_or(terminations, truncations).astype(np.float32)
        rewards_buf[step] = reward
        if "final_info" in infos:  # a sub-env ended an episode; its last step's info and obs are kept here
            # The statistics count the episode's last observation before the next one's first, as
            # CleanRL's NormalizeObservation does (step, then the reset inside it).
            policy.update_statistics(np.stack(infos["final_obs"][infos["_final_obs"]]))
            ended = infos["final_info"]
            for i in np.flatnonzero(ended["_episode"]):
                on_episode(float(ended["episode"]["r"][i]), int(ended["episode"]["l"][i]), global_step + (step + 1) * len(raw_obs))
        # Normalised on arrival, with statistics that include it, as CleanRL's wrapper returns it.
        next_obs = policy.observe(raw_obs)
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
        # PGG: a dropped row compares pi(a|null) with the pi_hat(a|s) that acted, so its ratio does not
        # start at 1; the KL estimates and the clip fraction describe the policy's own change, i.e. the
        # kept rows. Masked means, not boolean indexing: the compiled loss keeps static shapes.
        kept = torch.ones_like(ratio) if drop_mask is None else (~drop_mask).float()
        kept_mean = lambda x: (kept * x).sum() / kept.sum().clamp_min(1.0)  # noqa: E731
        # http://joschu.net/blog/kl-approx.html
        old_approx_kl = kept_mean(-logratio)
        approx_kl = kept_mean((ratio - 1) - logratio)
        clipped = ((ratio - 1.0).abs() > args.clip_coef).float()
        clipfrac = kept_mean(clipped)
        dropped_stats = {}
        if drop_mask is not None:  # PGG
            dropped = 1.0 - kept
            dropped_mean = lambda x: (dropped * x).sum() / dropped.sum().clamp_min(1.0)  # noqa: E731
            dropped_stats = {
                "pgg/dropped_fraction": dropped.mean(),
                "pgg/dropped_ratio_mean": dropped_mean(ratio),
                "pgg/dropped_abs_logratio": dropped_mean(logratio.abs()),
                "pgg/dropped_clipfrac": dropped_mean(clipped),
            }

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
        **dropped_stats,
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

    per_minibatch = defaultdict(list)  # averaged over every minibatch, as CleanRL does the clip fraction
    for _ in range(args.update_epochs):
        b_inds = torch.randperm(batch_size)
        for start in range(0, batch_size, minibatch_size):
            drop_mask = None
            if args.cond_dropout > 0:  # PGG: conditioning dropout
                drop_mask = torch.rand(minibatch_size) < args.cond_dropout
            loss, stats = loss_fn(agent, batch, b_inds[start : start + minibatch_size], drop_mask, args)
            for key in ("losses/clipfrac", *(key for key in stats if key.startswith("pgg/"))):
                per_minibatch[key].append(stats[key])

            optimizer.zero_grad(set_to_none=False)  # in place: see flatten_parameters
            loss.backward()
            nn.utils.clip_grad_norm_(optimizer.param_groups[0]["params"], args.max_grad_norm)
            optimizer.step()

        if args.target_kl is not None and stats["losses/approx_kl"] > args.target_kl:
            break

    y_pred, y_true = batch["values"].numpy(), batch["returns"].numpy()
    var_y = np.var(y_true)
    stats = {key: value.item() for key, value in stats.items()}
    stats.update({key: torch.stack(values).mean().item() for key, values in per_minibatch.items()})
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


def checkpoint_marks(total_timesteps: int, interval: int, batch_size: int) -> list[int]:
    """Nominal steps that get a checkpoint: every multiple of `interval` below the total, and the total;
    one per iteration (interval >= batch_size), so a multiple that the last iteration passes is left
    to the total's checkpoint."""
    last_iteration = -(-total_timesteps // batch_size)
    return [m for m in range(interval, total_timesteps, interval) if -(-m // batch_size) < last_iteration] + [total_timesteps]


def checkpoint_path(run_dir: Path, mark: int) -> Path:
    return run_dir / "checkpoints" / f"step_{mark:09d}.pt"


def package_versions() -> dict[str, str | None]:
    """The software stack a checkpoint was trained on (the sweep keeps MuJoCo versions apart)."""

    def version(package: str) -> str | None:
        try:
            return importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {"python": platform.python_version(), **{p: version(p) for p in ("torch", "numpy", "gymnasium", "mujoco")}}


def rng_state() -> dict:
    """torch's, numpy's and Python's global generators, pickle-free."""
    numpy_state = np.random.get_state(legacy=False)
    numpy_state["state"]["key"] = torch.from_numpy(numpy_state["state"]["key"].astype(np.int64))
    return {"torch": torch.get_rng_state(), "numpy": numpy_state, "python": random.getstate()}


def set_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    numpy_state = state["numpy"]
    numpy_state["state"]["key"] = numpy_state["state"]["key"].numpy().astype(np.uint32)
    np.random.set_state(numpy_state)
    random.setstate(state["python"])


def save_checkpoint(path: Path, agent: Agent, args: Args, global_step: int, mark: int, envs, resume: dict) -> None:
    """Self-contained, pickle-free checkpoint (loads with weights_only=True), written atomically.
    The model's state dict includes the observation-normalisation statistics; `resume` holds what
    continuing the run needs besides the model (see `train`)."""
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
        "versions": package_versions(),
        "model": agent.state_dict(),
        "resume": resume,
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
    """The agent, in eval mode, of an already loaded checkpoint dict (of any readable format)."""
    if ckpt.get("format_version") not in READABLE_FORMAT_VERSIONS or ckpt.get("action_space") != "continuous":
        raise ValueError(f"{source} is not a continuous PGG checkpoint of format {READABLE_FORMAT_VERSIONS}")
    agent = Agent(ckpt["obs_dim"], ckpt["action_dim"], ckpt["args"]["obs_clip"])
    agent.load_state_dict(ckpt["model"])
    return agent.eval()


def default_run_name(args: Args) -> str:
    return f"{args.env_id}__{args.exp_name}__g{args.guidance:g}__p{args.cond_dropout:g}__s{args.seed}"


class RunDirError(Exception):
    """A run directory this run must not write to; the message is one line that says what to do."""


HELD_LOCKS: dict[Path, object] = {}  # run directory -> its open lock file, while this process trains there


def lock_directory(directory: Path):
    """An exclusive lock on `directory` for as long as the returned file stays open. The kernel drops
    it when its holder dies, however it dies, so no stale lock outlives a killed run."""
    handle = open(directory / ".lock", "a+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip() or "unknown"
        handle.close()
        raise RunDirError(f"{directory} is in use by another process (pid {holder}); wait for it or stop it") from None
    handle.truncate(0)
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    return handle


def latest_checkpoint(run_dir: Path) -> Path | None:
    found = sorted((run_dir / "checkpoints").glob("step_*.pt"))
    return found[-1] if found else None


def training_arguments(values: dict) -> dict:
    """The arguments that decide what a run learns, those an older checkpoint lacks at their defaults."""
    defaults = asdict(Args())
    return {name: values.get(name, default) for name, default in defaults.items() if name not in RUN_ONLY_ARGS}


def check_continuable(run_dir: Path, latest: Path, args: Args) -> None:
    """Raises RunDirError unless this run may continue the one whose last checkpoint is `latest`."""
    try:
        ckpt = torch.load(latest, map_location="cpu", weights_only=True)
    except Exception as e:  # a truncated or foreign file raises anything from pickle/zip internals
        raise RunDirError(f"cannot read {latest} ({type(e).__name__}); pass --overwrite to start over") from None
    recorded, wanted = training_arguments(ckpt.get("args", {})), training_arguments(asdict(args))
    differing = [f"{name} {recorded[name]!r} -> {wanted[name]!r}" for name in wanted if recorded[name] != wanted[name]]
    if differing:
        raise RunDirError(
            f"{run_dir} holds a run with other arguments ({', '.join(differing)}): "
            "choose another --run-name, or pass --overwrite to replace it"
        )
    if not args.resume:
        finished = checkpoint_path(run_dir, args.total_timesteps).exists()
        state = "a finished run" if finished else f"an unfinished run (last checkpoint {latest.name})"
        how = "" if finished else "pass --resume to continue it, or "
        raise RunDirError(f"{run_dir} holds {state}: {how}pass --overwrite to train it again from scratch")
    if "resume" not in ckpt:
        raise RunDirError(f"{latest} predates resumable checkpoints: pass --overwrite to start over")


def prepare_run_dir(args: Args) -> Path:
    """Creates and locks the run directory and writes args.json. A directory that holds checkpoints is
    only continued (--resume, same training arguments) or replaced (--overwrite), and every check runs
    before anything is deleted. Raises RunDirError (one line) or OSError (not writable)."""
    run_dir = Path(args.output_dir) / (args.run_name or default_run_name(args))
    run_dir.mkdir(parents=True, exist_ok=True)
    if run_dir.resolve() not in HELD_LOCKS:
        HELD_LOCKS[run_dir.resolve()] = lock_directory(run_dir)
    latest = latest_checkpoint(run_dir)
    if latest is not None and not args.overwrite:
        try:
            check_continuable(run_dir, latest, args)
        except RunDirError:
            HELD_LOCKS.pop(run_dir.resolve()).close()
            raise
    if not (args.resume and latest is not None):
        for stale in ("checkpoints", "videos"):
            shutil.rmtree(run_dir / stale, ignore_errors=True)
        for stale in run_dir.glob("events.out.tfevents.*"):
            stale.unlink()
    tmp = run_dir / "args.json.tmp"
    tmp.write_text(json.dumps(asdict(args), indent=2))
    os.replace(tmp, run_dir / "args.json")
    return run_dir


class ProgressReport:
    """Steps done, SPS, recent mean return and ETA: a live bar (rich) when stdout is a terminal, else
    a plain line every `interval` seconds, for the logs of the launcher and of Slurm."""

    def __init__(self, total_steps: int, first_step: int, interval: float = 30.0):
        self.total, self.first_step, self.interval = total_steps, first_step, interval
        self.start = self.last_line = time.time()
        self.bar = None
        if sys.stdout.isatty():
            from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn

            self.bar = Progress(TextColumn("training"), BarColumn(), TaskProgressColumn(), TextColumn("{task.fields[line]}"))
            self.task = self.bar.add_task("", total=total_steps, completed=first_step, line="")
            self.bar.start()

    def update(self, global_step: int, recent_returns) -> int:
        """Reports `global_step`; returns the SPS of this process so far."""
        now = time.time()
        sps = int((global_step - self.first_step) / max(now - self.start, 1e-9))
        mean_return = f"{np.mean(recent_returns):.1f}" if recent_returns else "-"
        eta = (self.total - global_step) / max(sps, 1)
        line = f"{global_step:,}/{self.total:,} steps  {sps:,} SPS  return(last 20) {mean_return}  ETA {eta / 60:.0f}m{eta % 60:02.0f}s"
        if self.bar is not None:
            self.bar.update(self.task, completed=global_step, line=line)
        elif now - self.last_line >= self.interval:
            self.last_line = now
            print(line, flush=True)
        return sps

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def train(args: Args, run_dir: Path) -> None:
    """Trains one agent, writing TensorBoard events and checkpoints into `run_dir` (prepared by
    `prepare_run_dir`). With --resume it continues from the last checkpoint bit for bit: the checkpoint
    holds the optimizer, the sub-envs mid-episode, the next observation and every RNG state."""
    try:
        _train(args, run_dir, latest_checkpoint(run_dir) if args.resume else None)
    finally:
        lock = HELD_LOCKS.pop(run_dir.resolve(), None)
        if lock is not None:
            lock.close()


def _train(args: Args, run_dir: Path, resume_from: Path | None) -> None:
    resumed = torch.load(resume_from, map_location="cpu", weights_only=True) if resume_from else None
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
    # Events written after the checkpoint by the run that stopped are dropped by TensorBoard's readers.
    writer = SummaryWriter(str(run_dir), purge_step=resumed["global_step"] + 1 if resumed else None)
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

    # A resumed run records into a folder of its own: RecordVideo numbers episodes from 0 again.
    video_dir = run_dir / "videos" / (f"from_step_{resumed['global_step']}" if resumed else "")
    video_dir = video_dir if args.capture_video else None
    envs = make_vector_env(args.env_id, args.num_envs, args.seed, args.discount, args.reward_clip, video_dir)
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
    buf = Rollout.empty(args.num_steps, args.num_envs, obs_dim, action_dim)
    recent_returns = deque(maxlen=20)

    def on_episode(episodic_return: float, episodic_length: int, step: int):
        recent_returns.append(episodic_return)
        writer.add_scalar("charts/episodic_return", episodic_return, step)
        writer.add_scalar("charts/episodic_length", episodic_length, step)

    raw_obs, _ = envs.reset(seed=args.seed)
    next_obs = RolloutPolicy(agent, args.guidance).observe(raw_obs)  # the statistics count the first observation too
    next_done = np.zeros(args.num_envs, dtype=np.float32)
    first_iteration, global_step = 1, 0
    if resumed is not None:
        state = resumed["resume"]
        agent.load_state_dict(resumed["model"])  # in place, into the optimizer's flat buffer
        optimizer.load_state_dict(state["optimizer"])
        restore_env_state(envs, state["envs"])
        if all(sub_env["complete"] for sub_env in state["envs"]):
            next_obs, next_done = state["next_obs"].numpy().copy(), state["next_done"].numpy().copy()
        else:  # a task whose own state a checkpoint cannot hold: fresh episodes, a statistically equal run
            raw_obs, _ = envs.reset(seed=args.seed + state["iteration"])
            next_obs = RolloutPolicy(agent, args.guidance).observe(raw_obs)
        set_rng_state(state["rng"])
        first_iteration, global_step = state["iteration"] + 1, resumed["global_step"]
        print(f"resuming from {resume_from} at global_step={global_step}", flush=True)
    marks = deque(m for m in checkpoint_marks(args.total_timesteps, args.checkpoint_interval, batch_size) if m > global_step)
    progress = ProgressReport(num_iterations * batch_size, global_step)

    try:
        for iteration in range(first_iteration, num_iterations + 1):
            if args.anneal_lr:
                optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / num_iterations) * args.learning_rate

            policy = RolloutPolicy(agent, args.guidance)
            next_obs, next_done = collect_rollout(policy, envs, next_obs, next_done, buf, on_episode, global_step)
            global_step += batch_size
            next_value = policy.value(next_obs)
            advantages, returns = compute_gae(buf, next_value, next_done, args.discount, args.gae_lambda)

            stats = ppo_update(agent, optimizer, buf, advantages, returns, args, loss_fn)
            stats.update(guidance_diagnostics(agent, buf.obs.reshape(-1, obs_dim), args.guidance))
            stats["charts/learning_rate"] = optimizer.param_groups[0]["lr"]
            stats["charts/SPS"] = sps = progress.update(global_step, recent_returns)
            for key, value in stats.items():
                writer.add_scalar(key, value, global_step)

            while marks and global_step >= marks[0]:
                mark = marks.popleft()
                resume = {
                    "iteration": iteration,
                    "optimizer": optimizer.state_dict(),
                    "envs": env_state(envs),
                    "next_obs": torch.from_numpy(next_obs.copy()),
                    "next_done": torch.from_numpy(next_done.copy()),
                    "rng": rng_state(),
                }
                save_checkpoint(checkpoint_path(run_dir, mark), agent, args, global_step, mark, envs, resume)
                mean_return = np.mean(recent_returns) if recent_returns else float("nan")
                print(f"global_step={global_step} mark={mark} mean_return(last 20)={mean_return:.1f} SPS={sps}", flush=True)
    finally:
        progress.close()
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
        except RunDirError as e:
            error = str(e)
        except OSError as e:
            error = f"cannot write the run directory under {args.output_dir!r}: {e.strerror or e}"
    if error is not None:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
    print(f"run directory: {run_dir}")
    try:
        train(args, run_dir)
    except (KeyboardInterrupt, OSError) as e:  # Ctrl-C, or e.g. a full disk while saving a checkpoint
        latest = latest_checkpoint(run_dir)
        kept = f"checkpoints up to {latest.name} are kept: continue with --resume" if latest else "no checkpoint yet"
        what = "interrupted" if isinstance(e, KeyboardInterrupt) else f"error: {e.strerror or e}"
        print(f"{what}; {run_dir}: {kept}", file=sys.stderr)
        sys.exit(130 if isinstance(e, KeyboardInterrupt) else 1)


if __name__ == "__main__":
    main()
