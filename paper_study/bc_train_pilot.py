"""The pilot of cloning while training (results/beyond/bc_train/pilot.sh): for each run's last checkpoint,
its return at each swept γ (mean over the sweep's episodes) and how near its unconditional branch lies to
the mean action of its own episodes (pgg_utils.bc_null.reach, in units of σ), the thing the term trains.

    python paper_study/bc_train_pilot.py runs/bc_pilot runs/sweeps/bc_pilot/episodes.csv
"""

import csv
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from pgg_utils import bc_null, checkpoints, scripts


def main() -> None:
    run_root, episodes = Path(sys.argv[1]), Path(sys.argv[2])
    torch.set_num_threads(1)
    returns = defaultdict(list)
    with open(episodes, newline="") as f:
        for row in csv.DictReader(f):
            returns[(row["run"], float(row["eval_guidance"]))].append(float(row["return"]))
    gammas = sorted({gamma for _, gamma in returns})
    print("| run | null_bc_coef | route | " + " | ".join(f"γ = {g:g}" for g in gammas) + " | reach (σ) |")
    print("|---|---|---|" + "---|" * (len(gammas) + 1))
    for run_dir in sorted(p for p in run_root.iterdir() if p.is_dir()):
        path = checkpoints.checkpoints_of(run_dir)[-1]
        ckpt = checkpoints.read_checkpoint_file(path)
        agent, module, _ = scripts.load_agent(ckpt, path)
        actions = bc_null.own_episodes(agent, ckpt, module.make_env(ckpt["env_id"]), 20, 30_000)
        reach = bc_null.reach(agent, ckpt["action_space"], agent.null_obs.detach(), actions)
        cells = " | ".join(f"{np.mean(returns[(run_dir.name, g)]):.1f}" for g in gammas)
        print(
            f"| {run_dir.name} | {ckpt['args']['null_bc_coef']:g} | {ckpt['args']['null_bc_route']} | {cells} | {reach:.3f} |"
        )


if __name__ == "__main__":
    main()
