"""Sweep the PGG guidance strength γ on saved checkpoints, without retraining.

    python eval_gamma_sweep.py runs/ --output sweeps/all
    python eval_gamma_sweep.py runs/discrete --gammas 1 2 5 --steps 100000 500000 --workers 2
    python eval_gamma_sweep.py RUN/checkpoints/step_000500000.pt --gammas 1 2 5 --video videos/   # watch the knob

Every checkpoint under the given run directories (or roots) is evaluated at each γ for `--episodes`
episodes. A (checkpoint, γ) cell is evaluated on its own: its episodes step together, one row each
in a batch of their own, with one policy forward per step; an episode that ends keeps its row
(padded) until the whole cell is done.

Reproducibility. Episode k of every cell starts from `env.reset(seed=eval_seed + k)` and draws its
action noise from its own stream, `np.random.default_rng([eval_seed + k, 1])`: the same episode seeds
and noise for every γ and every checkpoint (common random numbers). The default eval_seed, 10_000,
keeps evaluation seeds disjoint from the training scripts' (seed + env index, i.e. small integers).

Exactness. Every policy forward of a cell has cell_rows(episodes) = max(episodes, 8) rows, from its
first step to its last, and nothing of another cell enters its batch: on one machine and software
stack a cell's rows are bit-identical whether it is swept alone, beside other γ values, in a worker
or after a resume; across machines they are statistically equal, not identical (benchmarks/README.md,
"Exactness of the sweep").

Which code evaluates. A checkpoint is evaluated by the script that trained it, as CleanRL's evaluation
takes `Agent` from the file that trained it: the repository's file the checkpoint names (the two
scripts, or a fork copied beside them), or a file given with --script of that name (a fork kept
elsewhere, a copy). A checkpoint never makes the sweep run code from anywhere else: one whose script
cannot be found, or whose `Agent` cannot load its weights, is skipped with one line (skipped.csv).
evaluated_by.csv names the file that evaluated each checkpoint and whether it is the one that trained
it (same_script: yes, no, or unknown for checkpoints from before scripts recorded their own sha1).

Configurations. A cell's seeds must be distinct runs of one training configuration: the script and
every training argument (pgg_utils.identity.config_label). Every row carries `config`, its label: the
variant, the script where it is not the repository's own, and every training argument that differs
from the script's defaults, e.g. `pgg_g1.1 learning_rate=0.002` or `pgg_g1.1 script=ppo_pgg_relu.py`,
and `config_fields`, the same as a JSON object that readers compare without parsing the label;
summaries are grouped by it, and two checkpoints of one env, configuration, seed and step are an error
naming both. Checkpoints whose model holds a NaN or an infinity are skipped, never evaluated.

Outputs (in --output, locked against a second sweep while this one runs): cells/*.csv, one per
finished (checkpoint, γ) cell, written atomically and named by the bytes of the checkpoint that were
evaluated, the γ, the settings, the evaluation stack (the mujoco, gymnasium, numpy and torch versions,
recorded in every row) and every file of code that runs in its episodes: this sweep's file (or a copy
of it), the script that evaluates the checkpoint, a custom task's module, and each module these import,
read from their import statements, wherever it lies on the path (a fork's or a task's helper module, a
package's other modules), but for installed packages and the standard library, which the stack's versions
stand for (evaluation_code, cells.imported_files). A rerun reuses a cell only if it is whole
and every row's checksum holds, so an interrupted sweep (Ctrl-C: exit status 130) loses only the cells
in flight, a damaged cell is evaluated again, and so is every cell after an edit to any of that code.
Then episodes.csv (every episode of the requested cells, sorted), summary.csv (per env, variant,
config, step and γ: mean over seeds of the per-seed mean return, and its 95% confidence interval, see
`mean_ci95`), skipped.csv, evaluated_by.csv, and written.csv: episodes.csv, summary.csv and skipped.csv with their numbers of rows and sha256, by which
plot_results.py refuses an episodes.csv that is not whole.

Returns and faults. An episode's return is the task's own: the one that gymnasium's RecordEpisodeStatistics,
which the script's make_env puts directly on gym.make's env (pgg_utils.tasks.task_env), records at its end,
whatever make_env adds around it (a reward scale); for a script whose make_env has none, the sum of make_env's
rewards, the figure its training logged (records_episodes). A checkpoint is skipped, with one line in skipped.csv
and on stderr, and the sweep goes on, where its task's spaces are not those it was trained on (pgg_utils.spaces),
or where during its episodes the task raises, or returns an observation or a reward holding a NaN or an infinity.

Changing the episodes. Copy this file and edit `evaluate_cell`, the one episode loop of a cell: an
observation transform goes where the loop reads `obs`, and a per-episode metric is one more entry of the
dict it returns, one value per episode, written after the sweep's columns in every cell and in
episodes.csv (a name of the sweep's own columns, or not one value per episode, is refused in one line).
The copy's cells are its own: its file is part of every cell's identity, so the original's cells are
never reused by it, nor its cells by the original, even in one --output. Every episode is played by that
loop: the copy's --video films its cell's episode, with its return.
"""

from pgg_utils import startup  # first: a Ctrl-C during the imports below is one line, status 130

# isort: split
import hashlib
import inspect
import io
import sys
import time
from collections import Counter
from concurrent.futures import as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import gymnasium as gym
import numpy as np
import torch
import tyro

from pgg_utils import scripts, spaces
from pgg_utils.arguments import DEFAULT_GAMMAS, guidance_error
from pgg_utils.cells import (
    EPISODE_COLUMNS,
    STACK_COLUMNS,
    cell_path,
    code_digest,
    evaluation_stack,
    extra_columns,
    imported_files,
    read_cell,
    write_cell,
)
from pgg_utils.checkpoints import find_checkpoints, non_finite, read_checkpoint_file
from pgg_utils.checks import video_error
from pgg_utils.fast import MIN_FORWARD_ROWS, standard_gumbel
from pgg_utils.files import (
    InputError,
    LockedError,
    RuntimeFailure,
    check_writable,
    lock_directory,
    one_line_errors,
    write_csv_atomic,
    write_record,
)
from pgg_utils.identity import Configuration, configuration, configuration_fields, run_of
from pgg_utils.pooling import cell_of, check_one_run_per_seed, mean_ci95, seed_means
from pgg_utils.processes import how_workers_died, start_pool, stop_pool
from pgg_utils.progress import Progress, format_duration
from pgg_utils.tasks import TASK_EPISODE
from pgg_utils.video import labelled, write_video

SUMMARY_COLUMNS = [
    "env_id", "variant", "config", "train_guidance", "cond_dropout", "step", "eval_guidance", "policy", "null_branch",
    "n_seeds", "n_episodes", "mean", "ci95", "ci_low", "ci_high", "ci_method", "seed_means",
]  # fmt: skip


@dataclass
class Args:
    paths: tyro.conf.Positional[tuple[str, ...]]
    """run directories, roots to search for them, or checkpoint files"""
    output: str = "sweep"
    """output directory (cells/, episodes.csv, summary.csv); reusing it resumes a sweep"""
    gammas: tuple[float, ...] | None = None
    """eval guidance strengths; None: the paper's, discrete 1 1.5 2 5 10 20, continuous 1 1.05 ... 1.3 1.5"""
    episodes: int = 50
    """episodes per (checkpoint, γ) cell"""
    steps: tuple[int, ...] | None = None
    """only the checkpoints of these step marks (e.g. 100000 500000); None: all"""
    eval_seed: int = 10_000
    """episode k resets with seed eval_seed + k; keep it away from training seeds"""
    deterministic: bool = False
    """control: act with the argmax / mean of the guided policy instead of sampling it"""
    uniform_null: bool = False
    """control (discrete only): a uniform unconditional branch instead of the learned one, making guidance plain temperature scaling of the conditional policy"""
    workers: int = 1
    """processes that evaluate checkpoints in parallel"""
    ci: Literal["t", "bootstrap"] = "t"
    """confidence interval over per-seed means: Student t, or a percentile bootstrap"""
    bootstrap_samples: int = 10_000
    """resamples for --ci bootstrap"""
    video: str | None = None
    """instead of sweeping, record one episode of ONE checkpoint at each γ into this folder: gamma_<γ>.mp4 and side_by_side.mp4, each the sweep's cell episode --video-episode, played in its cell of --episodes episodes (needs the [video] extra); None: sweep"""
    script: tuple[str, ...] = ()
    """training scripts to evaluate with besides the repository's: a checkpoint is evaluated by the one of its training script's file name (a fork kept outside the repository, or a copy of a script); () : the repository's only"""
    video_episode: int = 0
    """with --video: the episode to record, k < --episodes: the sweep's cell episode k (its reset seed eval_seed + k, its noise, its return)"""


# --- checkpoints ----------------------------------------------------------------------------------


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
    checkpoint's Discrete space, the size of its Box (spaces.recorded; action_error refuses a Box of
    more than one dimension)."""
    horizon = env.spec.max_episode_steps  # every swept task has one (evaluation_of)
    action = spaces.recorded(ckpt)["action"]
    size = (
        action["n"] if ckpt["action_space"] == "discrete" else int(np.prod(action.get("shape", [ckpt["action_dim"]])))
    )
    return horizon, size


def action_error(ckpt: dict, action_space: gym.Space) -> str | None:
    """One line where the sweep cannot act in the checkpoint's Box action space: one of more than one
    dimension, in training or now (the agent's actions are flat vectors; flatten the action in make_env to
    train on such a task). A size that changed since training is spaces.mismatch's."""
    if not isinstance(action_space, gym.spaces.Box) or ckpt["action_space"] != "continuous":
        return None
    trained = tuple(spaces.recorded(ckpt)["action"].get("shape", ()))
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
    of the sweep adds its own here: the module docstring's "Changing the episodes"). EpisodeFault
    where the task raises or returns a NaN or an infinity.

    The one loop that plays evaluation episodes: the sweep's cells, --video, and, through `hooks`,
    beyond/goal_distance.py, beyond/command_tracking.py and pgg_utils/bc_null.py (which acts with
    a policy of its own). An episode that ends keeps its row (holding its last observation) until the whole
    cell is done, so every policy forward of the cell has the same shape, cell_rows(episodes) rows, from the
    first step to the last: what a cell computes is a function of the checkpoint, γ and the settings alone
    (the module docstring's Exactness)."""
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


def evaluate_batched(policy: GuidedPolicy, ckpt, gammas, episodes, eval_seed, deterministic):
    """The cells of several γ values of one checkpoint, one after the other (evaluate_cell); returns
    (returns, lengths), each (len(gammas), episodes), and the number of environment steps taken."""
    cells = [evaluate_cell(policy, ckpt, gamma, episodes, eval_seed, deterministic) for gamma in gammas]
    returns = np.stack([cell["return"] for cell in cells]).reshape(len(gammas), episodes)
    lengths = np.stack([cell["length"] for cell in cells]).reshape(len(gammas), episodes)
    return returns, lengths, int(lengths.sum())


def evaluate_sequential(policy: GuidedPolicy, ckpt, gamma, episodes, eval_seed, deterministic):
    """Reference: one episode after another, one observation per forward (padded to cell_rows(1)), each a cell
    of its own whose episode 0 is this cell's episode k (reset seed and noise from eval_seed + k); used by the
    tests and the benchmark. It agrees with the cells to rounding, not necessarily to the bit (see the module
    docstring). Returns (returns, lengths), each (episodes,)."""
    cells = [evaluate_cell(policy, ckpt, gamma, 1, eval_seed + k, deterministic) for k in range(episodes)]
    return np.concatenate([cell["return"] for cell in cells]), np.concatenate([cell["length"] for cell in cells])


# --- cells, resumption, output ---------------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    checkpoint: Path
    gamma: float
    settings: tuple  # (episodes, eval_seed, deterministic, uniform_null)
    stack: tuple  # evaluation_stack() of the sweep
    evaluation: "Evaluation"  # the script that evaluates the checkpoint and the fingerprint of what computes the cell


@dataclass
class JobResult:
    job: Job
    digest: str | None  # sha1 of the checkpoint bytes that were evaluated
    rows: list[dict]
    env_steps: int
    error: str | None


def settings_of(args: Args) -> tuple:
    return (args.episodes, args.eval_seed, args.deterministic, args.uniform_null)


def run_job(job: Job) -> JobResult:
    """Evaluates one cell. The checkpoint is read once; the rows, and the digest that names their
    cell, come from those bytes."""
    torch.set_num_threads(1)
    episodes, eval_seed, deterministic, uniform_null = job.settings
    try:
        digest, ckpt = read_checkpoint(job.checkpoint)
        agent, module, _ = scripts.load_agent(ckpt, job.checkpoint, (job.evaluation.script,))
        fields = configuration_fields(ckpt)
    except Exception as e:
        return JobResult(job, None, [], 0, f"{job.checkpoint}: {e}")
    policy = GuidedPolicy(agent, ckpt, uniform_null, module)
    try:
        columns = evaluate_cell(policy, ckpt, job.gamma, episodes, eval_seed, deterministic)
    except EpisodeFault as e:  # the task's fault: none of the checkpoint's cells is tabled, the sweep goes on
        return JobResult(job, None, [], 0, f"{job.checkpoint}: {e}; none of its cells is tabled")
    except Exception as e:  # a fork's agent or make_env failing mid-episode: the same
        return JobResult(job, None, [], 0, f"{job.checkpoint}: at γ = {job.gamma:g}: {first_line(e)}; "
                                           "none of its cells is tabled")  # fmt: skip
    returns, lengths = columns.pop("return"), columns.pop("length")
    if error := added_columns_error(columns, episodes):
        return JobResult(job, None, [], 0, f"{job.checkpoint}: {error}")
    if not np.isfinite(returns).all():
        bad = np.flatnonzero(~np.isfinite(returns))
        return JobResult(job, None, [], 0, f"{job.checkpoint}: episode {bad[0]} at γ = {job.gamma:g} returned "
                                           f"{returns[bad[0]]} (a non-finite reward); none of its cells is tabled")  # fmt: skip
    common = {
        "env_id": ckpt["env_id"],
        "variant": fields["variant"],
        "config": fields["config"],
        "config_fields": fields["config_fields"],
        "run": run_of(ckpt, job.checkpoint),
        "seed": ckpt["args"]["seed"],
        "train_guidance": fields["train_guidance"],
        "cond_dropout": fields["cond_dropout"],
        "step": ckpt["step_mark"],
        "global_step": ckpt["global_step"],
        "eval_guidance": job.gamma,
        "policy": "deterministic" if deterministic else "sample",
        "null_branch": "uniform" if uniform_null else "bc" if ckpt.get("null_fit") else "learned",
        **dict(zip(STACK_COLUMNS, job.stack)),
        "action_space": ckpt["action_space"],
    }
    rows = [
        {**common, "episode": k, "episode_seed": eval_seed + k, "return": float(returns[k]), "length": int(lengths[k]),
         **{column: values[k] for column, values in columns.items()}}
        for k in range(episodes)
    ]  # fmt: skip
    return JobResult(job, digest, rows, int(lengths.sum()), None)


def added_columns_error(columns: dict, episodes: int) -> str | None:
    """One line where a per-episode column that evaluate_cell adds cannot be written: a name of the
    sweep's own columns, or not one value per episode."""
    for column, values in columns.items():
        if column in EPISODE_COLUMNS or column == "checksum" or not column.isidentifier():
            return (f"evaluate_cell's column {column!r} is refused: per-episode columns it adds need a name of "
                    "their own (letters, digits, underscores; none of the sweep's columns)")  # fmt: skip
        if np.shape(values) != (episodes,):
            return f"evaluate_cell's column {column!r} has shape {np.shape(values)}, not one value per episode ({episodes})"
    return None


GROUP_COLUMNS = SUMMARY_COLUMNS[:9]  # a summary row per (env, variant, config, ..., γ, policy, null branch)


def summarise(rows: list[dict], method: str = "t", bootstrap_samples: int = 10_000) -> list[dict]:
    """One row per (env, variant, config, step, γ, policy, null branch): statistics over seeds of the
    per-seed mean episodic return. A seed must be one run: InputError where two runs (the `run`
    column) give the same seed of one group, or one run gives the same episode twice."""
    check_one_run_per_seed(rows, configuration, cell_of)
    group_of = lambda row: tuple(configuration(row)[2] if c == "config" else str(row[c]) for c in GROUP_COLUMNS)
    per_seed, episodes = seed_means(rows, group_of), Counter(map(group_of, rows))
    out = []
    for key in sorted(per_seed, key=lambda k: (k[0], k[1], k[2], int(k[5]), float(k[6]), k[7], k[8])):
        means = list(per_seed[key].values())
        mean, half, low, high = mean_ci95(means, method, bootstrap_samples)
        out.append({
            **dict(zip(GROUP_COLUMNS, key)),
            "n_seeds": len(means), "n_episodes": episodes[key],
            "mean": round(mean, 4), "ci95": round(half, 4), "ci_low": round(low, 4), "ci_high": round(high, 4),
            "ci_method": method, "seed_means": ";".join(f"{m:.4f}" for m in means),
        })  # fmt: skip
    return out


def episode_sort_key(row: dict):
    return (row["env_id"], row["variant"], configuration(row)[2], row["run"], int(row["step"]), float(row["eval_guidance"]),
            row["policy"], row["null_branch"], int(row["episode"]))  # fmt: skip


def check_args(args: Args) -> None:
    """Every argument, before anything is read or written; InputError with one line."""
    if not args.paths:
        raise InputError("no run directories, roots or checkpoint files given (e.g. eval_gamma_sweep.py runs/)")
    if args.gammas is not None:
        if not args.gammas:
            raise InputError("--gammas needs at least one value (leave it out for the paper's)")
        for gamma in args.gammas:
            if error := guidance_error(gamma, "--gammas"):  # the training scripts' rule
                raise InputError(error)
    if args.steps is not None and not args.steps:
        raise InputError("--steps needs at least one value (leave it out for every checkpoint)")
    if args.episodes <= 0 or args.workers <= 0 or args.bootstrap_samples <= 0:
        raise InputError("--episodes, --workers and --bootstrap-samples must be positive")
    if args.eval_seed < 0 or args.video_episode < 0:
        raise InputError(f"--eval-seed and --video-episode must be >= 0, got {args.eval_seed} and {args.video_episode}")
    if args.video is not None and args.video_episode >= args.episodes:
        raise InputError(f"--video-episode {args.video_episode} is not an episode of a cell of --episodes "
                         f"{args.episodes} (0 to {args.episodes - 1}); raise --episodes to film it")  # fmt: skip
    if not args.output:
        raise InputError("--output must name a directory")
    if error := scripts.given_script_error(args.script):
        raise InputError(error)


# --- the sweep -----------------------------------------------------------------------------------------


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep; its message says how many of the sweep's cells are on disk."""


def claim_output(output: Path):
    """Creates the output directory, checks that it and cells/ are writable (os.replace needs that),
    and takes its lock (files.lock_directory: held until the returned file is closed or its holder
    dies). InputError with one line if it cannot be written or another sweep holds it."""
    try:
        check_writable(output, output / "cells")
        return lock_directory(output, "another sweep")
    except LockedError as e:
        raise InputError(f"{e}; wait for it to finish or choose another --output") from None
    except OSError as e:
        raise InputError(f"cannot write to {output}: {e.strerror or e}") from None


class WorkerDied(RuntimeFailure):
    """A worker ended while the sweep ran (the kernel's OOM killer sends SIGKILL); one line."""


EVALUATED_BY_COLUMNS = [
    "run",
    "step",
    "env_id",
    "config",
    "trained_by",
    "evaluated_by",
    "evaluated_by_sha1",
    "same_script",
]


@dataclass(frozen=True)
class Evaluation:
    """How a checkpoint is evaluated: by which script file, and the fingerprint of the code that computes
    its cells (part of each cell's identity), with the row evaluated_by.csv gets."""

    script: Path
    evaluator: str
    record: dict


@dataclass(frozen=True)
class Task:
    """A checkpoint's task as the script that evaluates it makes it: its spaces, and the digest of every file
    of code that runs in a cell's episodes (evaluation_code)."""

    observation_space: gym.Space
    action_space: gym.Space
    code: str


def evaluation_code(script: Path, task_files) -> str:
    """The digest of the code that runs in a cell's episodes: the file of this sweep (or of a copy of it,
    whichever runs), the script that evaluates the checkpoint, a custom task's module (scripts.task_sources;
    gymnasium's own tasks are named by its version in the stack), and every module that these import, wherever
    it lies, but installed packages and the standard library, which the stack's versions name (cells.imported_files).
    An edit to any of them, or another copy of the sweep, re-evaluates the cells."""
    return code_digest(imported_files([Path(__file__), script, *task_files]))


def task_of(module, script: Path, env_id: str) -> Task:
    """The task of `env_id` as `module` makes it. ValueError (one line) where it cannot be made or has no time limit."""
    try:
        env = module.make_env(env_id)()
    except Exception as e:  # a custom task's module gone, an id no longer registered: whatever make raises
        raise ValueError(f"cannot make environment {env_id!r} ({first_line(e)})") from None
    task = Task(env.observation_space, env.action_space, evaluation_code(script, scripts.task_sources(env_id, env)))
    bounded = env.spec is not None and env.spec.max_episode_steps
    env.close()
    if not bounded:
        raise ValueError(f"{env_id} has no time limit (max_episode_steps), so an episode may never end; "
                         "register it with one, e.g. gym.register(..., max_episode_steps=1000)")  # fmt: skip
    return task


def task_error(ckpt: dict, task: Task) -> str | None:
    """One line where the task's spaces are not those the checkpoint was trained on (spaces.mismatch), or
    its actions are not ones the sweep can act in (action_error)."""
    if error := action_error(ckpt, task.action_space):
        return error
    if error := spaces.mismatch(spaces.recorded(ckpt), task.observation_space, task.action_space):
        return f"its task {ckpt['env_id']} has changed since training: {error}; not evaluated"
    return None


def evaluation_of(checkpoint: Path, ckpt: dict, given: tuple[Path, ...], tasks: dict) -> Evaluation:
    """How a checkpoint is evaluated, by the script that trained it, and the fingerprint of the code that
    computes its cells (evaluation_code). `tasks` caches the task by (script, env). ValueError (one line)
    where the script cannot be found or load the checkpoint, or the task cannot be made or is not the one it
    was trained on (task_error)."""
    _, module, script = scripts.load_agent(ckpt, checkpoint, given)  # proves its Agent holds the weights, once
    key = (script, ckpt["env_id"])
    if key not in tasks:
        tasks[key] = task_of(module, script, ckpt["env_id"])
    if error := task_error(ckpt, tasks[key]):
        raise ValueError(error)
    script_sha1 = scripts.file_sha1(script)
    trained_sha1 = ckpt.get("code", {}).get("script_sha1")
    same = "unknown" if trained_sha1 is None else "yes" if trained_sha1 == script_sha1 else "no"
    evaluator = tasks[key].code
    record = {"run": run_of(ckpt, checkpoint), "step": ckpt["step_mark"], "env_id": ckpt["env_id"],
              "trained_by": scripts.script_name(ckpt), "evaluated_by": scripts.recorded_path(script),
              "evaluated_by_sha1": script_sha1, "same_script": same}  # fmt: skip
    return Evaluation(script, evaluator, record)


def plan(args: Args, checkpoints: list[Path], output: Path, stack: tuple, skipped: list[str]):
    """({(checkpoint, γ): cell path} of every cell the sweep asks for, {checkpoint: config label},
    {checkpoint: Evaluation}). Reads each checkpoint once; unreadable ones, those with non-finite models
    and those whose script cannot be found or load them go to `skipped`. InputError if two checkpoints
    are the same experiment, seed and step (two runs that would count as one seed)."""
    settings, cells, experiments, labels, evaluations = settings_of(args), {}, {}, {}, {}
    given, tasks = tuple(Path(path).resolve() for path in args.script), {}
    for checkpoint in checkpoints:
        try:
            digest, ckpt = read_checkpoint(checkpoint)
            evaluation = evaluation_of(checkpoint, ckpt, given, tasks)
            config = Configuration.of_checkpoint(ckpt)
            identity = (*config.key, ckpt["args"]["seed"], ckpt["step_mark"])  # its pooling key, seed and step
            kind = ckpt["action_space"]
        except ValueError as e:  # unreadable, not a checkpoint of these scripts, non-finite, no script or task
            skipped.append(f"{checkpoint}: {e}")
            continue
        except Exception as e:
            skipped.append(f"{checkpoint}: not a PGG checkpoint ({type(e).__name__}: {e})")
            continue
        if args.uniform_null and kind != "discrete":  # once per checkpoint, not once per cell
            skipped.append(f"{checkpoint}: --uniform-null applies to discrete checkpoints only")
            continue
        other = experiments.setdefault(identity, checkpoint)
        if other != checkpoint:
            raise InputError(
                f"{other} and {checkpoint} are two runs of one experiment ({ckpt['env_id']}, {config.label!r}, seed "
                f"{ckpt['args']['seed']}, step {ckpt['step_mark']}) and would count as one seed; sweep them separately "
                "or remove one"
            )
        labels[checkpoint], evaluations[checkpoint] = config.label, evaluation
        for gamma in dict.fromkeys(args.gammas if args.gammas is not None else DEFAULT_GAMMAS[kind]):
            cells[(checkpoint, gamma)] = cell_path(output, checkpoint, gamma, settings, digest, stack,
                                                   evaluation.evaluator)  # fmt: skip
    return cells, labels, evaluations


def sweep(args: Args) -> Path:
    """Runs (or resumes) the sweep; returns the output directory."""
    check_args(args)
    output, skipped = Path(args.output), []
    checkpoints = find_checkpoints(args.paths, args.steps, skipped)
    lock = claim_output(output)
    threads = torch.get_num_threads()
    try:
        return sweep_locked(args, output, checkpoints, skipped)
    finally:
        torch.set_num_threads(threads)  # run_job sets one thread per process
        lock.close()


def sweep_locked(args: Args, output: Path, checkpoints: list[Path], skipped: list[str]) -> Path:
    stack = evaluation_stack()
    cells, labels, evaluations = plan(args, checkpoints, output, stack, skipped)
    finished = {}  # (checkpoint, γ) -> its rows, as read back from its cell file or written to it
    try:
        for cell, path in cells.items():
            if path.exists():
                try:
                    finished[cell] = read_cell(path, args.episodes)
                except ValueError as e:
                    print(f"re-evaluating {path}: {e}", file=sys.stderr)
        print(f"{len(checkpoints)} checkpoints, {len(cells)} cells, {len(finished)} already done", file=sys.stderr)
        withheld = evaluate_missing(args, output, stack, cells, finished, skipped, evaluations)
        rows, added = [], {}
        for (checkpoint, _), cell_rows in finished.items():
            if checkpoint not in withheld:
                added.setdefault(tuple(extra_columns(cell_rows[0])), checkpoint)
                # The label of today's rule: a cell written before the rule changed keeps its numbers but
                # must not split its run from the cells written after.
                rows.extend({**row, "config": labels[checkpoint]} for row in cell_rows)
        if len(added) > 1:
            raise InputError(f"the cells carry different added columns ({' and '.join(map(str, added))}); "
                             "evaluate_cell must add the same per-episode columns to every cell")  # fmt: skip
        columns = [*EPISODE_COLUMNS, *next(iter(added), ())]
        rows = [{column: row[column] for column in columns} for row in rows]
        rows.sort(key=episode_sort_key)
        summary = summarise(rows, args.ci, args.bootstrap_samples)
        write_csv_atomic(output / "episodes.csv", columns, rows)
        write_csv_atomic(output / "summary.csv", SUMMARY_COLUMNS, summary)
        write_csv_atomic(output / "skipped.csv", ["reason"], [{"reason": s} for s in skipped])
        evaluated = [evaluations[c].record | {"config": labels[c]} for c in sorted(evaluations) if c not in withheld]
        write_csv_atomic(output / "evaluated_by.csv", EVALUATED_BY_COLUMNS, evaluated)
        # What the sweep wrote, by rows and digest: the tables refuse an episodes.csv that is not (plot_results).
        write_record(output, {"episodes.csv": len(rows), "summary.csv": len(summary), "skipped.csv": len(skipped)},
                     "eval_gamma_sweep.py")  # fmt: skip
    except KeyboardInterrupt:
        raise SweepInterrupted(
            f"{len(finished)} of the sweep's {len(cells)} cells are finished in {output / 'cells'}; "
            "rerun the same command to evaluate the rest"
        ) from None
    except WorkerDied as e:
        raise WorkerDied(f"{e}; {len(finished)} of the sweep's {len(cells)} cells are finished in {output / 'cells'}: "
                         "rerun the same command to evaluate the rest") from None  # fmt: skip
    for reason in skipped:
        print(f"skipped {reason}", file=sys.stderr)
    for run, script in sorted({(r["run"], r["evaluated_by"]) for r in evaluated if r["same_script"] == "no"}):
        print(f"note: {run} was evaluated by {script}, which differs from the file that trained it "
              f"({output / 'evaluated_by.csv'})", file=sys.stderr)  # fmt: skip
    listed = f"; skipped {len(skipped)} checkpoint(s), listed in {output / 'skipped.csv'}" if skipped else ""
    wrote = f"{output / 'episodes.csv'} ({len(rows)} episodes), {output / 'summary.csv'} ({len(summary)} rows)"
    print(f"wrote {wrote}{listed}")
    if not rows:
        raise InputError("no checkpoint could be evaluated")
    return output


def evaluate_missing(args: Args, output: Path, stack: tuple, cells: dict, finished: dict, skipped: list[str],
                     evaluations: dict) -> set[Path]:  # fmt: skip
    """Evaluates the cells not in `finished`, writing each as it finishes and adding its rows to
    `finished`; returns the checkpoints none of whose cells may be reported, each said in `skipped`: those
    of a cell that failed, and those whose bytes changed since `cells` was planned."""
    settings = settings_of(args)
    missing = [cell for cell in cells if cell not in finished]
    jobs = [Job(checkpoint, gamma, settings, stack, evaluations[checkpoint]) for checkpoint, gamma in missing]
    if not jobs:
        return set()
    progress = Progress(label="sweep", total=len(jobs), unit="cells", interval=0, stream=sys.stderr)
    handled, env_steps, start, failed, changed, pool, broken = 0, 0, time.time(), {}, set(), None, False
    try:
        if args.workers > 1 and len(jobs) > 1:
            pool, futures, processes = start_pool(min(args.workers, len(jobs)), run_job, jobs)
            results = (f.result() for f in as_completed(futures) if not isinstance(f.exception(), BrokenProcessPool))
        else:
            results = map(run_job, jobs)
        for result in results:
            job, handled = result.job, handled + 1
            if result.error:  # none of the checkpoint's cells is reported: its rows would be partial
                failed.setdefault(job.checkpoint, result.error)
            else:
                # Named by the bytes that were evaluated. A checkpoint rewritten since the plan keeps its new
                # cell for a later sweep; this sweep reports none of its cells (they could mix two files).
                path = cell_path(
                    output, job.checkpoint, job.gamma, settings, result.digest, stack, job.evaluation.evaluator
                )
                rows = write_cell(path, result.rows)
                if path == cells[(job.checkpoint, job.gamma)]:
                    finished[(job.checkpoint, job.gamma)] = rows
                else:
                    changed.add(job.checkpoint)
                env_steps += result.env_steps
            elapsed = time.time() - start
            rate = env_steps / max(elapsed, 1e-9)
            progress.update(handled, f"{rate:,.0f} env steps/s  elapsed {format_duration(elapsed)}")
        broken = pool is not None and handled < len(jobs)  # the failed futures: BrokenProcessPool, all of them
    finally:
        progress.close()
        if pool:
            stop_pool(pool, processes)
    if broken:
        raise WorkerDied(f"a sweep worker died ({how_workers_died(processes)}) and the cells in flight with it")
    skipped.extend(failed.values())
    rewritten = sorted(changed - failed.keys())
    skipped.extend(f"{c}: rewritten during the sweep; rerun the sweep to evaluate its new contents" for c in rewritten)
    return failed.keys() | changed


# --- watching the knob: videos of one checkpoint at several γ ----------------------------------------


class Filming(EpisodeHooks):
    """Films one episode of a cell: its env, made by the script's make_env, renders, after the reset and after
    each of its steps."""

    def __init__(self, episode: int):
        self.episode, self.env, self.frames = episode, None, []

    def make_env(self, policy, episode: int):
        if episode != self.episode:
            return policy.make_env()
        self.env = policy.make_env(render_mode="rgb_array")
        return self.env

    def after_reset(self, obs: np.ndarray) -> None:
        self.frames.append(self.env.render())

    def after_step(self, episode: int, t: int, obs: np.ndarray, reward: float, done: bool, info: dict) -> None:
        if episode == self.episode:
            self.frames.append(self.env.render())


def record_episode(policy: GuidedPolicy, ckpt: dict, gamma: float, episodes: int, eval_seed: int, episode: int,
                   deterministic: bool):  # fmt: skip
    """Episode `episode` of the sweep's cell of `episodes` episodes at `gamma`, filmed as the cell plays it
    (evaluate_cell); returns (its frames, its return, the cell's returns)."""
    filming = Filming(episode)
    returns = evaluate_cell(policy, ckpt, gamma, episodes, eval_seed, deterministic, filming)["return"]
    return filming.frames, float(returns[episode]), returns


def record_videos(args: Args) -> list[Path]:
    """--video: one video per γ of one checkpoint, each the sweep's cell episode --video-episode (record_episode:
    the same reset seed and noise at every γ, and the return the cell gives it), and all of them side by side
    with γ and the return written on each panel (shorter episodes hold their last frame). Returns the files
    written."""
    checkpoints = find_checkpoints(args.paths, args.steps)
    if len(checkpoints) != 1:
        raise InputError(f"--video records one checkpoint; {len(checkpoints)} found "
                         "(name a checkpoint file, or narrow with --steps)")  # fmt: skip
    try:
        _, ckpt = read_checkpoint(checkpoints[0])
        agent, module, _ = scripts.load_agent(ckpt, checkpoints[0], tuple(Path(path).resolve() for path in args.script))
    except ValueError as e:
        raise InputError(f"{checkpoints[0]}: {e}") from None
    policy = GuidedPolicy(agent, ckpt, args.uniform_null, module)
    try:
        probe = policy.make_env(render_mode="rgb_array")
    except Exception as e:
        raise InputError(f"cannot make environment {ckpt['env_id']!r} ({first_line(e)})") from None
    changed = task_error(ckpt, Task(probe.observation_space, probe.action_space, ""))
    error = None if changed else video_error(probe)  # the training scripts' check: moviepy, a renderer
    fps = probe.metadata.get("render_fps") or 30
    probe.close()
    if changed:
        raise InputError(f"{checkpoints[0]}: {changed}")
    if error:
        raise InputError(error.replace("--capture-video", "--video"))
    output = Path(args.video)
    output.mkdir(parents=True, exist_ok=True)
    gammas = args.gammas if args.gammas is not None else DEFAULT_GAMMAS[ckpt["action_space"]]
    written, panels = [], []
    for gamma in gammas:
        try:
            frames, total, returns = record_episode(policy, ckpt, gamma, args.episodes, args.eval_seed,
                                                    args.video_episode, args.deterministic)  # fmt: skip
        except EpisodeFault as e:
            raise InputError(f"{checkpoints[0]}: {e}") from None
        write_video(output / f"gamma_{gamma:g}.mp4", frames, fps)
        written.append(output / f"gamma_{gamma:g}.mp4")
        panels.append([labelled(frame, f"γ = {gamma:g}   return {total:.1f}") for frame in frames])
        print(f"γ = {gamma:g}: episode {args.video_episode}, return {total!r} over {len(frames) - 1} steps (its cell "
              f"of {args.episodes} episodes: mean return {returns.mean():.1f}) -> {written[-1]}", file=sys.stderr)  # fmt: skip
    longest = max(len(frames) for frames in panels)
    side_by_side = [
        np.concatenate([frames[min(t, len(frames) - 1)] for frames in panels], axis=1) for t in range(longest)
    ]
    write_video(output / "side_by_side.mp4", side_by_side, fps)
    return [*written, output / "side_by_side.mp4"]


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with one_line_errors():
        try:
            startup.ctrl_c_handled()
            if args.video is not None:
                check_args(args)
                for path in record_videos(args):
                    print(path)
                return
            sweep(args)
        except KeyboardInterrupt as e:
            print(f"interrupted: {e}" if isinstance(e, SweepInterrupted) else "interrupted before any cell was evaluated",
                  file=sys.stderr)  # fmt: skip
            sys.exit(130)


if __name__ == "__main__":
    main()
