"""What the learned null is: for each agent of a conditioned task, the command (or, on Reacher-v4, the goal)
whose conditional policy π(a|s, c) is closest to its unconditional one π(a|s, ∅) in KL on the task's states, for
"Beyond the paper" (beyond/condition_dropout.py, "Guidance on a condition, with the condition dropped in
training").

    python -m beyond.learned_null results/beyond/command/agents --steps 1000000 \\
        --output results/beyond/command/learned_null.csv

The states are the agent's own: --episodes episodes at γ = 1, each with the condition the task draws (a command
from the training range, a target in Reacher's disk), episode k reset with seed eval_seed + k and acted with the
sweep's action noise for episode k (pgg_utils.evaluation.episode_noise); every observation an action was taken on
is a state. On them, for each condition c of the task's grid (CONDITIONS), each state's condition is replaced by
c and the mean over states of KL(π(·|s, ∅) ‖ π(·|s, c)) computed from the agent's own branches: its
`acting_policy` at γ 0 (the null branch, exactly) and γ 1 (the conditional one), raw observations in, as the
agent acts. The pseudo-condition is the grid's minimiser; beside it the KL there, the KL to the states' own
condition (what the null differs by where it is used), and how far each state's own minimiser lies from the
pseudo-condition (median over states): a null that is the policy at one fixed condition has its minimisers
bunched there. A null on the whole state (PPO's, the paper's) is measured alike: π(a|∅) is then one action
distribution for every state. Each checkpoint is loaded by the code that trained it and its task checked
against the spaces it was trained on. One row per checkpoint: about 4 s each on the command task, 18 s on
Reacher-v4, on one core.
"""

import hashlib
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import tyro

from paper_study.cheetah_velocity import COMMAND_INDEX
from paper_study.cheetah_velocity import ENV_ID as COMMAND_ENV
from pgg_utils import evaluation, scripts, tasks
from pgg_utils.checkpoints import find_checkpoints
from pgg_utils.files import InputError, one_line_errors, write_csv_atomic
from pgg_utils.identity import variant_id

COLUMNS = ["env_id", "variant", "run", "seed", "step", "null_dims", "episodes", "states", "pseudo_command",
           "pseudo_goal_x", "pseudo_goal_y", "kl_at_pseudo", "kl_at_own", "per_state_spread", "at_grid_edge",
           "checkpoint_sha1"]  # fmt: skip


def set_command(obs: np.ndarray, command: np.ndarray) -> np.ndarray:
    out = obs.copy()
    out[:, COMMAND_INDEX] = command[0]
    return out


def set_goal(obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Reacher-v4's observation with the target at `goal` (dims 4, 5) and fingertip − target (dims 8, 9) moved
    with it, the fingertip where it is (gymnasium's documentation of the v4 observation)."""
    out = obs.copy()
    out[:, 8:10] = obs[:, 8:10] + obs[:, 4:6] - goal
    out[:, 4:6] = goal
    return out


@dataclass(frozen=True)
class Condition:
    grid: np.ndarray
    """(points, dims) the conditions tried"""
    put: callable
    """(raw observations, one condition) -> the observations with that condition"""
    own: callable
    """raw observations -> (states, dims) each state's own condition"""
    columns: tuple[str, ...]
    """the CSV columns of the pseudo-condition, one per dimension"""


# The grid of each task: commands beyond the training range [0, 2] on both sides, by 0.01 m/s; target positions
# by 0.01 m over a square beyond Reacher's disk of targets (radius 0.2) and the arm's reach (0.21).
_lattice = np.round(np.arange(-25, 26) * 0.01, 2)
CONDITIONS = {
    COMMAND_ENV: Condition(np.round(np.arange(-100, 401) * 0.01, 2)[:, None], set_command,
                           lambda obs: obs[:, [COMMAND_INDEX]], ("pseudo_command",)),
    "Reacher-v4": Condition(np.stack(np.meshgrid(_lattice, _lattice, indexing="ij"), -1).reshape(-1, 2), set_goal,
                            lambda obs: obs[:, 4:6], ("pseudo_goal_x", "pseudo_goal_y")),
}  # fmt: skip
DEFAULT_EPISODES = {COMMAND_ENV: 5, "Reacher-v4": 100}  # 5,000 states each


@dataclass
class Args:
    paths: tyro.conf.Positional[tuple[str, ...]]
    """agents folders, run directories or checkpoint files of the command task or Reacher-v4"""
    output: str
    """the CSV to write"""
    steps: tuple[int, ...] | None = None
    """only these step marks; None: all"""
    episodes: int | None = None
    """episodes at γ = 1 whose states are measured; None: the task's DEFAULT_EPISODES"""
    eval_seed: int = 40_000
    """episode k resets with seed eval_seed + k (40000+: apart from the sweeps' and the tracking's)"""


def own_states(agent, make_env, episodes: int, eval_seed: int) -> np.ndarray:
    """The raw observations an agent acts on at γ = 1 over `episodes` episodes played together, in order."""
    envs = [make_env() for _ in range(episodes)]
    horizon, action_size = envs[0].spec.max_episode_steps, envs[0].action_space.shape[0]
    noise = np.stack([evaluation.episode_noise("continuous", eval_seed, k, horizon, action_size) for k in range(episodes)],
                     axis=1)  # fmt: skip
    obs = np.stack([env.reset(seed=eval_seed + k)[0] for k, env in enumerate(envs)])
    running, states, t = np.ones(episodes, dtype=bool), [], 0
    while running.any():
        states.append(obs[running])
        actions = agent.act(obs, guidance=np.ones(episodes), noise=noise[t])
        for i in np.flatnonzero(running):
            obs[i], _, terminated, truncated, _ = envs[i].step(actions[i])
            running[i] = not (terminated or truncated)
        t += 1
    for env in envs:
        env.close()
    return np.concatenate(states)


def gaussian_kl(p, q) -> np.ndarray:
    """KL(p ‖ q) per row of two diagonal Gaussians (mean, logstd), in float64."""
    mean_p, mean_q = (np.asarray(d.mean, dtype=np.float64) for d in (p, q))
    logstd_p, logstd_q = (np.broadcast_to(np.asarray(d.logstd, dtype=np.float64), mean_p.shape) for d in (p, q))
    ratio = np.exp(2 * (logstd_p - logstd_q))
    return (logstd_q - logstd_p + 0.5 * (ratio + (mean_p - mean_q) ** 2 * np.exp(-2 * logstd_q)) - 0.5).sum(-1)


def nearest_condition(agent, states: np.ndarray, condition: Condition) -> dict:
    """The grid's condition whose π(·|s, c) is closest to π(·|s, ∅) in mean KL over `states`, and the rest of a row."""
    null = agent.acting_policy(states, 0.0)
    own = float(gaussian_kl(null, agent.acting_policy(states, 1.0)).mean())
    mean_kl = np.empty(len(condition.grid))
    best_kl, best_at = np.full(len(states), np.inf), np.zeros(len(states), dtype=np.int64)
    for i, c in enumerate(condition.grid):
        kl = gaussian_kl(null, agent.acting_policy(condition.put(states, c), 1.0))
        mean_kl[i] = kl.mean()
        closer = kl < best_kl
        best_kl[closer], best_at[closer] = kl[closer], i
    best = int(np.argmin(mean_kl))
    pseudo = condition.grid[best]
    spread = float(np.median(np.linalg.norm(condition.grid[best_at] - pseudo, axis=1)))
    edge = bool(np.any((pseudo == condition.grid.min(0)) | (pseudo == condition.grid.max(0))))
    return {**dict(zip(condition.columns, pseudo.tolist())), "kl_at_pseudo": float(mean_kl[best]), "kl_at_own": own,
            "per_state_spread": spread, "at_grid_edge": "yes" if edge else "no"}  # fmt: skip


def measure_checkpoint(path: Path, args: Args) -> tuple[dict | None, str | None]:
    """(row, None) of one checkpoint, or (None, why it was skipped) in one line."""
    torch.set_num_threads(1)
    try:
        agent, ckpt = scripts.load_checkpoint(path)
    except ValueError as e:  # unreadable, non-finite, its script not found
        return None, f"{path}: {e}"
    if ckpt["env_id"] not in CONDITIONS:
        return None, f"{path}: {ckpt['env_id']} has no condition here (only {', '.join(CONDITIONS)})"
    make_env = scripts.training_module(ckpt)[0].make_env(ckpt["env_id"])
    probe = make_env()
    error = tasks.mismatch(tasks.recorded(ckpt), probe.observation_space, probe.action_space)
    probe.close()
    if error:
        return None, f"{path}: its task changed since training ({error})"
    episodes = args.episodes or DEFAULT_EPISODES[ckpt["env_id"]]
    states = own_states(agent, make_env, episodes, args.eval_seed)
    null_dims = ckpt["args"].get("null_dims")
    row = {"env_id": ckpt["env_id"], "variant": variant_id({"env_id": ckpt["env_id"], **ckpt["args"]}),
           "run": path.parent.parent.name, "seed": ckpt["args"]["seed"], "step": ckpt["step_mark"],
           "null_dims": "all" if null_dims is None else " ".join(map(str, null_dims)), "episodes": episodes,
           "states": len(states), "checkpoint_sha1": hashlib.sha1(path.read_bytes()).hexdigest(),
           **nearest_condition(agent, states, CONDITIONS[ckpt["env_id"]])}  # fmt: skip
    return row, None


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with one_line_errors():
        if args.episodes is not None and args.episodes <= 0:
            raise InputError(f"--episodes must be positive, got {args.episodes}")
        if args.eval_seed < 0:
            raise InputError(f"--eval-seed must be non-negative, got {args.eval_seed}")
        rows = []
        for path in find_checkpoints(args.paths, args.steps):
            row, skipped = measure_checkpoint(path, args)
            if skipped:
                print(f"skipped {skipped}", file=sys.stderr)
                continue
            rows.append(row)
            print(f"{path}: pseudo-condition {' '.join(str(row[c]) for c in COLUMNS if c.startswith('pseudo_') and c in row)}",
                  file=sys.stderr)  # fmt: skip
        if not rows:
            raise InputError(f"no checkpoint of {' or '.join(CONDITIONS)} under {', '.join(args.paths)}")
        rows.sort(key=lambda r: (r["env_id"], r["variant"], int(r["seed"]), int(r["step"])))
        write_csv_atomic(Path(args.output), COLUMNS, rows)
        print(f"wrote {args.output} ({len(rows)} checkpoints)")


if __name__ == "__main__":
    main()
