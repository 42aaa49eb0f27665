"""The pilot of cloning while training (results/beyond/bc_train/pilot.sh): for each run's last checkpoint,
its return at each swept γ (mean over the sweep's episodes) and how near its unconditional branch lies to
the mean action of its own episodes (pgg_utils.bc_null.reach, in units of σ), the thing the term trains.

    python -m beyond.bc_train_pilot runs/bc_pilot runs/sweeps/bc_pilot/episodes.csv
"""

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import torch
import tyro

from pgg_utils import bc_null, checkpoints, scripts
from pgg_utils.episodes import read_episodes, seed_means, select_mode
from pgg_utils.files import one_line_errors


@dataclass
class Args:
    run_root: tyro.conf.Positional[Path]
    """the folder of the pilot's runs (one run directory each)"""
    episodes: tyro.conf.Positional[Path]
    """the sweep's episodes.csv of those runs"""


def main() -> None:
    args = tyro.cli(Args)
    run_root, episodes = args.run_root, args.episodes
    torch.set_num_threads(1)
    with one_line_errors():
        rows = select_mode(read_episodes([episodes]), "sample", "learned")
    last_step = defaultdict(int)
    for row in rows:
        last_step[row["run"]] = max(last_step[row["run"]], int(row["step"]))
    at_last = [row for row in rows if int(row["step"]) == last_step[row["run"]]]
    # one run is one seed: its per-seed mean is the run's mean return at that γ
    returns = {key: mean for key, by_seed in seed_means(at_last, lambda r: (r["run"], float(r["eval_guidance"]))).items()
               for mean in by_seed.values()}  # fmt: skip
    gammas = sorted({gamma for _, gamma in returns})
    print("| run | null_bc_coef | route | " + " | ".join(f"γ = {g:g}" for g in gammas) + " | reach (σ) |")
    print("|---|---|---|" + "---|" * (len(gammas) + 1))
    for run_dir in sorted(p for p in run_root.iterdir() if p.is_dir()):
        path = checkpoints.checkpoints_of(run_dir)[-1]
        ckpt = checkpoints.read_checkpoint_file(path)
        agent, module, _ = scripts.load_agent(ckpt, path)
        actions = bc_null.own_episodes(agent, ckpt, module.make_env(ckpt["env_id"]), 20, 30_000)
        reach = bc_null.reach(agent, ckpt["action_space"], agent.null_obs.detach(), actions)
        cells = " | ".join(f"{returns[(run_dir.name, g)]:.1f}" if (run_dir.name, g) in returns else "–" for g in gammas)
        print(
            f"| {run_dir.name} | {ckpt['args']['null_bc_coef']:g} | {ckpt['args']['null_bc_route']} | {cells} | {reach:.3f} |"
        )


if __name__ == "__main__":
    main()
