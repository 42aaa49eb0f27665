"""Evaluation proper: a checkpoint read once and checked (read_checkpoint), its guided policy (GuidedPolicy), the
action noise of an episode (episode_noise), the task's faults (EpisodeFault), and evaluate_cell, the one loop that
plays evaluation episodes: the sweep's cells (pgg_utils.sweep), --video (pgg_utils.video), and, through its hooks,
beyond/goal_distance.py, beyond/command_tracking.py and pgg_utils/bc_null.py.

Reproducibility. Episode k of every cell starts from `env.reset(seed=eval_seed + k)` and draws its action noise
from its own stream, `np.random.default_rng([eval_seed + k, 1])`: the same episode seeds and noise for every γ and
every checkpoint (common random numbers).

Exactness. Every policy forward of a cell has cell_rows(episodes) = max(episodes, 8) rows, from its first step to
its last, and nothing of another cell enters its batch: on one machine and software stack a cell's rows are
bit-identical whether it is swept alone, beside other γ values, in a worker or after a resume (benchmarks/README.md,
"Exactness of the sweep")."""

import hashlib
import inspect
import io
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from pgg_utils import scripts, tasks
from pgg_utils.checkpoints import non_finite, read_checkpoint_file
from pgg_utils.fast import MIN_FORWARD_ROWS, standard_gumbel
from pgg_utils.tasks import TASK_EPISODE


def read_checkpoint(path: Path) -> tuple[str, dict]:
    """(sha1 of the file's bytes, checkpoint dict), both from one read of the file: what is evaluated
    is exactly what is hashed. ValueError with one line if it is not a checkpoint of either training
    script, or if its model holds a NaN or an infinity (a diverged run: its episodes would be NaN
    actions fed to the simulator, not results)."""
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise ValueError(f"unreadable checkpoint ({e.strerror or e})") from None
    ckpt = read_checkpoint_file(io.BytesIO(data))
    if ckpt.get("action_space") not in scripts.ORIGINALS:
        raise ValueError("not a PGG checkpoint (no known action_space field)")
    if bad := non_finite(ckpt["model"]):
        raise ValueError(f"non-finite weights or statistics ({', '.join(bad[:3])}); not evaluated")
    return hashlib.sha1(data).hexdigest(), ckpt


def load_any_checkpoint(path: Path, given: tuple[Path, ...] = ()):
    """(agent, checkpoint dict) from a checkpoint file, the agent built by the script that trained it
    (scripts.load_agent: the repository's, or the one of `given` of its name); ValueError if it is not
    a checkpoint of a training script, or that script cannot be found or load it."""
    _, ckpt = read_checkpoint(path)
    return scripts.load_agent(ckpt, path, given)[0], ckpt


class GuidedPolicy:
    """The guided policy of one checkpoint for the sweep: its agent's own `act`, the path every user of
    a trained agent takes, with the unconditional branch computed once (or, for the discrete
    uniform-null control, zeros). Where the null embedding replaces chosen dimensions only, the
    unconditional branch depends on the observation and `act` computes it per row."""

    def __init__(self, agent, ckpt: dict, uniform_null: bool = False, module=None):
        self.agent, self.kind, self.env_id = agent, ckpt["action_space"], ckpt["env_id"]
        self.module = module or inspect.getmodule(type(agent))  # the script that evaluates: it makes the env
        with torch.no_grad():
            if self.kind == "discrete":
                learned = agent.unconditional_logits().numpy()
                self.null = {"logits_null": np.zeros_like(learned) if uniform_null else learned}
            else:
                self.null = {"mean_null": agent.unconditional_mean().numpy()}

    def reset(self) -> None:
        """Begins the episodes of a cell, or one episode: a recurrent actor starts from a fresh state."""
        if callable(reset := getattr(self.agent, "reset", None)):  # agents before Agent.reset have no state
            reset()

    def act(self, raw_obs: np.ndarray, guidance: np.ndarray, noise: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions for a batch, one guidance strength per row; `noise` holds one row of episode_noise
        per observation, used unless deterministic."""
        return self.agent.act(raw_obs, guidance, deterministic, noise, **self.null)

    def noise(self, eval_seed: int, episode: int, horizon: int, action_size: int) -> np.ndarray:
        """The action noise of episode `episode` of a cell (episode_noise)."""
        return episode_noise(self.kind, eval_seed, episode, horizon, action_size)

    def make_env(self, render_mode: str | None = None):
        """An evaluation env of the checkpoint's task, made by the `make_env` of the script that evaluates
        the agent; with `render_mode`, one that renders (--video). A script whose make_env takes no
        render_mode (written before it did) renders gymnasium's env wrapped as the original scripts did."""
        if render_mode is None:
            return self.module.make_env(self.env_id)()
        if "render_mode" in inspect.signature(self.module.make_env).parameters:
            return self.module.make_env(self.env_id, render_mode=render_mode)()
        env = gym.make(self.env_id, render_mode=render_mode)
        return gym.wrappers.FlattenObservation(env) if self.kind == "continuous" else env


def episode_noise(kind: str, eval_seed: int, episode: int, horizon: int, action_size: int) -> np.ndarray:
    """The action noise of one evaluation episode, (horizon, action_size) float32; the same for every
    γ and computed per episode, so its bits never depend on which episodes are evaluated with it.
    Discrete: standard Gumbel noise (argmax of logits + noise samples the categorical); continuous:
    standard normal."""
    rng = np.random.default_rng([eval_seed + episode, 1])
    if kind == "discrete":
        uniform = rng.uniform(np.finfo(np.float32).tiny, 1.0, size=(horizon, action_size))
        return standard_gumbel(uniform).astype(np.float32)
    return rng.standard_normal(size=(horizon, action_size)).astype(np.float32)


def horizon_and_action_size(env, ckpt) -> tuple[int, int]:
    """The task's time limit, and the size of one step's action noise: the number of actions of the
    checkpoint's Discrete space, the size of its Box (tasks.recorded; action_error refuses a Box of
    more than one dimension)."""
    horizon = env.spec.max_episode_steps  # every swept task has one (evaluation_of)
    action = tasks.recorded(ckpt)["action"]
    size = (
        action["n"] if ckpt["action_space"] == "discrete" else int(np.prod(action.get("shape", [ckpt["action_dim"]])))
    )
    return horizon, size


def action_error(ckpt: dict, action_space: gym.Space) -> str | None:
    """One line where the sweep cannot act in the checkpoint's Box action space: one of more than one
    dimension, in training or now (the agent's actions are flat vectors; flatten the action in make_env to
    train on such a task). A size that changed since training is tasks.mismatch's."""
    if not isinstance(action_space, gym.spaces.Box) or ckpt["action_space"] != "continuous":
        return None
    trained = tuple(tasks.recorded(ckpt)["action"].get("shape", ()))
    shape = next((s for s in (action_space.shape, trained) if len(s) > 1), None)
    if shape is not None:
        return (f"its task's actions are a Box of shape {shape}; the agent acts with flat vectors of "
                f"{ckpt['action_dim']}: flatten the action in make_env (and train on that) to sweep it")  # fmt: skip
    return None


class EpisodeFault(Exception):
    """The task failed during an episode: it raised, or returned a non-finite observation; one line."""


def first_line(error: BaseException) -> str:
    return f"{type(error).__name__}: {str(error).splitlines()[0]}" if str(error) else type(error).__name__


def reset_task(env, seed: int, episode: int, gamma: float, options: dict | None = None):
    """env.reset(seed=seed, options=options)'s observation; EpisodeFault where the task raises or returns a NaN
    or an infinity."""
    try:
        obs, _ = env.reset(seed=seed, options=options)
    except Exception as e:
        raise EpisodeFault(
            f"episode {episode} at γ = {gamma:g}: the task raised {first_line(e)} at its reset"
        ) from None
    if not np.isfinite(obs).all():
        raise EpisodeFault(f"episode {episode} at γ = {gamma:g}: the task's reset returned a non-finite observation")
    return obs


def step_task(env, action, episode: int, gamma: float, t: int):
    """env.step(action); EpisodeFault, naming the episode and the step, where the task raises."""
    try:
        return env.step(action)
    except Exception as e:
        raise EpisodeFault(
            f"episode {episode} at γ = {gamma:g}: the task raised {first_line(e)} at step {t + 1}"
        ) from None


def records_episodes(env) -> bool:
    """Whether the script's make_env puts gymnasium's RecordEpisodeStatistics on the task (pgg_utils.tasks.task_env
    does): then an episode's return is the one recorded at the episode's end (recorded_return), the task's own
    whatever make_env adds around it (a reward scale). A make_env without one (a script written before
    it held one) had its training returns recorded outside it, on make_env's rewards: the sweep sums
    those, which is the same figure training logged."""
    while isinstance(env, gym.Wrapper):
        if isinstance(env, gym.wrappers.RecordEpisodeStatistics):
            return True
        env = env.env
    return False


def recorded_return(info: dict, episode: int, gamma: float) -> float:
    """The return an episode's last info reports: pgg_utils.tasks.task_env's, recorded below every wrapper of
    make_env, or, for a make_env from before it, that of its RecordEpisodeStatistics on the task."""
    for key in (TASK_EPISODE, "episode"):
        if key in info:
            return info[key]["r"]
    raise EpisodeFault(f"episode {episode} at γ = {gamma:g}: make_env's RecordEpisodeStatistics reported no "
                       f"return at the episode's end (info['{TASK_EPISODE}'])")  # fmt: skip


def cell_rows(episodes: int) -> int:
    """The row count of every policy forward of a cell of `episodes` episodes (fast.evaluation_forward)."""
    return max(episodes, MIN_FORWARD_ROWS)


class EpisodeHooks:
    """What a caller adds to the episodes of a cell (evaluate_cell), each a no-op here: the env of an episode
    (--video films one), its reset options (a command), and a look at each step (a metric, a frame, the
    actions to clone). Hooks watch the episodes; the cell's numbers are the same with or without them."""

    def make_env(self, policy, episode: int):
        return policy.make_env()

    def reset_options(self, episode: int) -> dict | None:
        return None

    def after_reset(self, obs: np.ndarray) -> None:
        """The cell's first observations, one row per episode."""

    def after_step(self, episode: int, t: int, obs: np.ndarray, reward: float, done: bool, info: dict) -> None:
        """Episode `episode` took its step t (from 0): what the task returned, `done` where the episode ended."""


NO_HOOKS = EpisodeHooks()


def evaluate_cell(policy: GuidedPolicy, ckpt, gamma: float, episodes: int, eval_seed: int, deterministic: bool,
                  hooks: EpisodeHooks = NO_HOOKS):  # fmt: skip
    """One (checkpoint, γ) cell: its episodes step together, one row each, in a batch of their own.
    Returns its per-episode columns, {"return": ..., "length": ...}, each of shape (episodes,) (a copy
    of the sweep adds its own in its copy of this function: eval_gamma_sweep.py, "Changing the episodes"). EpisodeFault
    where the task raises or returns a NaN or an infinity.

    The one loop that plays evaluation episodes: the sweep's cells, --video, and, through `hooks`,
    beyond/goal_distance.py, beyond/command_tracking.py and pgg_utils/bc_null.py (which acts with
    a policy of its own). An episode that ends keeps its row (holding its last observation) until the whole
    cell is done, so every policy forward of the cell has the same shape, cell_rows(episodes) rows, from the
    first step to the last: what a cell computes is a function of the checkpoint, γ and the settings alone
    (this module's docstring, Exactness)."""
    envs = [hooks.make_env(policy, k) for k in range(episodes)]
    try:
        horizon, action_size = horizon_and_action_size(envs[0], ckpt)
        # (horizon, episodes, action_size): the noise of time step t is one contiguous block.
        noise = np.stack([policy.noise(eval_seed, k, horizon, action_size) for k in range(episodes)], 1)
        guidance = np.full(episodes, float(gamma))
        obs = np.stack([reset_task(env, eval_seed + k, k, gamma, hooks.reset_options(k)) for k, env in enumerate(envs)])
        hooks.after_reset(obs)
        policy.reset()
        recorded = records_episodes(envs[0])
        returns, lengths = np.zeros(episodes), np.zeros(episodes, dtype=np.int64)
        running = np.ones(episodes, dtype=bool)
        t = 0
        while running.any():
            actions = policy.act(obs, guidance, noise[t], deterministic)
            for i in np.flatnonzero(running):
                obs[i], reward, terminated, truncated, info = step_task(envs[i], actions[i], i, gamma, t)
                lengths[i] += 1
                if not recorded:
                    returns[i] += reward
                if terminated or truncated:
                    running[i] = False
                    if recorded:
                        returns[i] = recorded_return(info, i, gamma)
                hooks.after_step(i, t, obs[i], reward, not running[i], info)
            if not np.isfinite(obs).all():
                episode = int(np.flatnonzero(~np.isfinite(obs).reshape(episodes, -1).all(1))[0])
                raise EpisodeFault(f"episode {episode} at γ = {gamma:g}: the task returned a non-finite observation "
                                   f"at step {t + 1}")  # fmt: skip
            t += 1
    finally:
        for env in envs:
            env.close()
    return {"return": returns, "length": lengths}
