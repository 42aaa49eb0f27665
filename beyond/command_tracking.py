"""How closely agents of the command task follow their command, against the eval γ: per episode the commanded
and achieved mean forward velocity, the tracking error and the return, for "Beyond the paper"
(beyond/report.py, "Guidance on a command").

    python -m beyond.command_tracking results/beyond/command/agents --steps 1000000 \\
        --gammas 0.5 1 1.25 1.5 2 3 --commands -0.5 0 0.5 1 1.5 2 2.5 3 --output results/beyond/command/tracking.csv

Each checkpoint is loaded by the code that trained it (pgg_utils.scripts.load_checkpoint), its task made by that
script's make_env and checked against the spaces it was trained on. Each (checkpoint, γ, command) cell is a sweep
cell of --episodes episodes, played by the sweep's own loop (pgg_utils.evaluation.evaluate_cell: the episodes step
together through the agent's `act`, one row each): episode k resets with seed eval_seed + k and
`options={"command": v}` and draws the sweep's action noise for episode k, so every γ and command of a
checkpoint starts from the same states with the same noise. A row holds the
command, whether it lies in the task's training range, the mean forward velocity over the episode (its
displacement over its duration), the error of that mean (achieved − commanded), the mean per-step tracking
error |v_t − v_cmd| (the reward's tracking term), the return and the length.

Resumable: each checkpoint's cells are written, whole, to <output>.parts/<checkpoint sha1>_<settings>.csv and
reused by a rerun with the same settings; the CSV is written from the parts at the end, atomically.
"""

import hashlib
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import tyro

from paper_study.cheetah_velocity import HalfCheetahVelocity
from pgg_utils import evaluation, scripts, tasks
from pgg_utils.checkpoints import find_checkpoints
from pgg_utils.files import InputError, one_line_errors, read_csv, write_csv_atomic
from pgg_utils.identity import variant_id

COLUMNS = ["env_id", "variant", "run", "seed", "step", "eval_guidance", "command", "in_training_range",
           "episode", "episode_seed", "return", "length", "mean_velocity", "velocity_error", "tracking_error",
           "checkpoint_sha1", "task_sha1"]  # fmt: skip


@dataclass
class Args:
    paths: tyro.conf.Positional[tuple[str, ...]]
    """agents folders, run directories or checkpoint files of the command task"""
    output: str
    """the CSV to write"""
    commands: tuple[float, ...] = (-0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
    """commanded forward velocities (m/s), inside and outside the training range"""
    gammas: tuple[float, ...] = (0.5, 1.0, 1.25, 1.5, 2.0, 3.0)
    """eval guidance values"""
    steps: tuple[int, ...] | None = None
    """only these step marks; None: all"""
    episodes: int = 50
    """episodes per (checkpoint, γ, command)"""
    eval_seed: int = 30_000
    """episode k resets with seed eval_seed + k (30000+: apart from the sweep's 10000+ and 20000+)"""
    workers: int = 1
    """checkpoints evaluated at once, one process each"""


def settings_key(args: Args) -> str:
    """A digest of the settings a checkpoint's part depends on."""
    settings = [list(args.commands), list(args.gammas), args.episodes, args.eval_seed]
    return hashlib.sha1(json.dumps(settings).encode()).hexdigest()[:12]


class Tracking(evaluation.EpisodeHooks):
    """Commands every episode of a cell to `command` and sums its forward velocity and its tracking error."""

    def __init__(self, command: float, episodes: int):
        self.command = command
        self.velocity_sum, self.error_sum = np.zeros(episodes), np.zeros(episodes)

    def reset_options(self, episode: int) -> dict:
        return {"command": self.command}

    def after_step(self, episode: int, t: int, obs: np.ndarray, reward: float, done: bool, info: dict) -> None:
        self.velocity_sum[episode] += info["x_velocity"]
        self.error_sum[episode] += abs(info["x_velocity"] - self.command)


def play_cell(policy, ckpt: dict, gamma: float, command: float, episodes: int, eval_seed: int) -> list[dict]:
    """The rows of one (γ, command) cell of `policy` (pgg_utils.evaluation.GuidedPolicy)."""
    tracking = Tracking(command, episodes)
    cell = evaluation.evaluate_cell(policy, ckpt, gamma, episodes, eval_seed, False, tracking)
    returns, lengths = cell["return"], cell["length"]
    mean_velocity = tracking.velocity_sum / lengths
    return [{"eval_guidance": gamma, "command": command, "episode": k, "episode_seed": eval_seed + k,
             "return": returns[k], "length": int(lengths[k]), "mean_velocity": mean_velocity[k],
             "velocity_error": mean_velocity[k] - command, "tracking_error": tracking.error_sum[k] / lengths[k]}
            for k in range(episodes)]  # fmt: skip


def evaluate_checkpoint(path: Path, args: Args) -> tuple[list[dict], str | None]:
    """(rows, None) of every cell of one checkpoint, or ([], why it was skipped) in one line."""
    # One thread a worker process, so that --workers processes never oversubscribe the cores.
    torch.set_num_threads(1)
    digest = hashlib.sha1(path.read_bytes()).hexdigest()
    part = Path(f"{args.output}.parts") / f"{digest}_{settings_key(args)}.csv"
    if part.is_file():
        return read_csv(part), None
    try:
        agent, ckpt = scripts.load_checkpoint(path)
    except ValueError as e:  # unreadable, non-finite, its script not found: one line, the rest evaluated
        return [], f"{path}: {e}"
    module = scripts.training_module(ckpt)[0]
    make_env = module.make_env(ckpt["env_id"])
    probe = make_env()
    if not isinstance(probe.unwrapped, HalfCheetahVelocity):
        return [], f"{path}: {ckpt['env_id']} is not the command task"
    if error := tasks.mismatch(tasks.recorded(ckpt), probe.observation_space, probe.action_space):
        return [], f"{path}: its task changed since training ({error})"
    low, high = probe.unwrapped.command_range
    task_sha1 = ";".join(scripts.task_sources(ckpt["env_id"], probe).values())
    probe.close()
    header = {"env_id": ckpt["env_id"], "variant": variant_id({"env_id": ckpt["env_id"], **ckpt["args"]}),
              "run": path.parent.parent.name, "seed": ckpt["args"]["seed"], "step": ckpt["step_mark"],
              "checkpoint_sha1": digest, "task_sha1": task_sha1}  # fmt: skip
    policy, rows = evaluation.GuidedPolicy(agent, ckpt, module=module), []
    for gamma in args.gammas:
        for command in args.commands:
            try:
                cell = play_cell(policy, ckpt, gamma, command, args.episodes, args.eval_seed)
            except evaluation.EpisodeFault as e:
                return [], f"{path}: {e}"
            for row in cell:
                rows.append({**header, **row, "in_training_range": "yes" if low <= command <= high else "no"})
    part.parent.mkdir(parents=True, exist_ok=True)
    write_csv_atomic(part, COLUMNS, rows)
    return rows, None


def check_args(args: Args) -> None:
    for flag, values in (("--commands", args.commands), ("--gammas", args.gammas)):
        if not values or len(set(values)) < len(values) or not all(np.isfinite(values)):
            raise InputError(f"{flag} needs distinct finite values, got {' '.join(map(str, values)) or 'none'}")
    if min(args.gammas) < 0:
        raise InputError(f"--gammas must be non-negative, got {min(args.gammas)}")
    for flag, value in (("--episodes", args.episodes), ("--workers", args.workers)):
        if value <= 0:
            raise InputError(f"{flag} must be positive, got {value}")
    if args.eval_seed < 0:
        raise InputError(f"--eval-seed must be non-negative, got {args.eval_seed}")


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with one_line_errors():
        check_args(args)
        checkpoints = find_checkpoints(args.paths, args.steps)
        with ProcessPoolExecutor(args.workers) as pool:
            results = list(pool.map(evaluate_checkpoint, checkpoints, [args] * len(checkpoints)))
        rows = [row for found, _ in results for row in found]
        for _, skipped in results:
            if skipped:
                print(f"skipped {skipped}", file=sys.stderr)
        if not rows:
            raise InputError(f"no checkpoint of the command task under {', '.join(args.paths)}")
        rows.sort(key=lambda r: (r["variant"], int(r["seed"]), int(r["step"]), float(r["eval_guidance"]),
                                 float(r["command"]), int(r["episode"])))  # fmt: skip
        write_csv_atomic(Path(args.output), COLUMNS, rows)
        print(f"wrote {args.output} ({len(rows)} episodes of {len(checkpoints) - sum(bool(s) for _, s in results)} "
              "checkpoints)")  # fmt: skip


if __name__ == "__main__":
    main()
