"""How close guidance brings the fingertip (Reacher-v4) or the object (Pusher-v4) to its goal: the final
distance of every episode against the eval γ, for "Beyond the paper" (beyond/report.py).

    python -m beyond.goal_distance results/beyond/Reacher-v4/agents results/beyond/Pusher-v4/agents \\
        results/continuous/agents --envs Reacher-v4 Pusher-v4 --steps 1000000 --output results/beyond/goal_distance.csv

Each (checkpoint, γ) is a sweep cell, played by the sweep's own loop (pgg_utils.evaluation.evaluate_cell: reset
seed eval_seed + k and the sweep's action noise for episode k, the episodes stepping together through the
agent's `act`), and each episode's distance is read from its last observation: Reacher's fingertip to target (dims 8-10), Pusher's object (17-19) to goal (20-22), from
gymnasium's documentation of the v4 observations. The tasks' own `reward_dist` is measured before the
step's action, one step early. One row per episode.
"""

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tyro

from paper_study.paper import PAPER_GAMMAS
from pgg_utils import checkpoints, evaluation
from pgg_utils.files import InputError, one_line_errors, write_csv_atomic
from pgg_utils.identity import variant_id

FINAL_DISTANCE = {
    "Reacher-v4": lambda obs: float(np.linalg.norm(obs[8:11])),
    "Pusher-v4": lambda obs: float(np.linalg.norm(obs[17:20] - obs[20:23])),
}
COLUMNS = ["env_id", "variant", "run", "seed", "step", "eval_guidance", "episode", "return", "final_distance"]


@dataclass
class Args:
    paths: tyro.conf.Positional[tuple[str, ...]]
    """agents folders, run directories or checkpoint files"""
    output: str
    """the CSV to write"""
    envs: tuple[str, ...] = tuple(FINAL_DISTANCE)
    """only checkpoints of these tasks (each needs its FINAL_DISTANCE)"""
    steps: tuple[int, ...] | None = None
    """only these step marks; None: all"""
    gammas: tuple[float, ...] = PAPER_GAMMAS["continuous"]
    """eval guidance values"""
    episodes: int = 50
    """episodes per (checkpoint, γ)"""
    eval_seed: int = 10_000
    """episode k resets with seed eval_seed + k, as in the sweep"""


class FinalDistance(evaluation.EpisodeHooks):
    """The distance to the goal in each episode's last observation."""

    def __init__(self, env_id: str, episodes: int):
        self.distance_of, self.distances = FINAL_DISTANCE[env_id], [None] * episodes

    def after_step(self, episode: int, t: int, obs: np.ndarray, reward: float, done: bool, info: dict) -> None:
        if done:
            self.distances[episode] = self.distance_of(obs)


def final_distances(policy, ckpt: dict, gamma: float, episodes: int, eval_seed: int) -> list[tuple[float, float]]:
    """(return, final distance) of each episode of one cell."""
    measured = FinalDistance(ckpt["env_id"], episodes)
    returns = evaluation.evaluate_cell(policy, ckpt, gamma, episodes, eval_seed, False, measured)["return"]
    return [(float(total), distance) for total, distance in zip(returns, measured.distances)]


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with one_line_errors():
        rows, present = [], [p for p in args.paths if Path(p).exists()]
        for missing in sorted(set(args.paths) - set(present)):  # a goal set not trained yet
            print(f"note: {missing} does not exist; left out", file=sys.stderr)
        if not present:
            raise InputError(f"none of {', '.join(args.paths)} exists")
        for path in checkpoints.find_checkpoints(present, args.steps):
            try:
                agent, ckpt = evaluation.load_any_checkpoint(path)
            except ValueError as e:  # unreadable, non-finite, or its script not found: one line, the rest measured
                print(f"skipped {path}: {e}", file=sys.stderr)
                continue
            if ckpt["env_id"] not in args.envs:
                continue
            variant, policy = variant_id(ckpt["args"]), evaluation.GuidedPolicy(agent, ckpt)
            for gamma in args.gammas:
                for k, (total, distance) in enumerate(final_distances(policy, ckpt, gamma, args.episodes,
                                                                      args.eval_seed)):  # fmt: skip
                    rows.append({"env_id": ckpt["env_id"], "variant": variant, "run": path.parent.parent.name,
                                 "seed": ckpt["args"]["seed"], "step": ckpt["step_mark"], "eval_guidance": gamma,
                                 "episode": k, "return": total, "final_distance": distance})  # fmt: skip
            print(f"{path}: {len(args.gammas)} γ values", file=sys.stderr)
        if not rows:
            raise InputError(f"no checkpoint of {', '.join(args.envs)} under {', '.join(args.paths)}")
        write_csv_atomic(Path(args.output), COLUMNS, rows)
        print(f"wrote {args.output} ({len(rows)} episodes)")


if __name__ == "__main__":
    main()
