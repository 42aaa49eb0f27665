"""Pilot of the behaviour-cloned null (pgg_utils/bc_null.py): how many of an agent's own episodes fix the
fitted unconditional branch, and whether the frozen actor reaches the maximum-likelihood target.

    python -m beyond.bc_null_pilot CHECKPOINT [CHECKPOINT ...] > results/beyond/bc_null/pilot.txt

For each checkpoint and n in 1, 2, 5, 10, 20, 40 episodes (seeds 30000+): the fit's distance to the
target (continuous: the mean action, in units of the agent's σ; discrete: the action frequencies) and to
the fit on 40 episodes.
"""

from dataclasses import dataclass

import numpy as np
import torch
import tyro

from pgg_utils import bc_null, checkpoints, scripts


@dataclass
class Args:
    checkpoints: tyro.conf.Positional[tuple[str, ...]]
    """the agents' checkpoint files"""


def main() -> None:
    torch.set_num_threads(1)
    for path in tyro.cli(Args).checkpoints:
        ckpt = checkpoints.read_checkpoint_file(path)
        agent, module, _ = scripts.load_agent(ckpt, path)
        print(path)
        fits = {}
        for n in (1, 2, 5, 10, 20, 40):
            actions = bc_null.own_episodes(agent, ckpt, module.make_env(ckpt["env_id"]), n, 30_000)
            fresh, _, _ = scripts.load_agent(ckpt, path)  # the fit starts from the checkpoint's own weights each time
            null, nll = bc_null.fit_null(
                fresh, ckpt["action_space"], actions, bc_null.Args.fit_steps, bc_null.Args.learning_rate
            )
            with torch.no_grad():
                if ckpt["action_space"] == "continuous":
                    fit = fresh.actor_mean(null[None])[0].numpy() / fresh.actor_logstd.exp()[0].numpy()
                else:
                    fit = torch.softmax(fresh.actor(null[None])[0], -1).numpy()
            gap = bc_null.reach(fresh, ckpt["action_space"], null, actions)
            fits[n] = fit
            print(f"  n={n:2d} actions={len(actions):6d} NLL {nll:.4f}  max |fit - target| = {gap:.3f}")
        for n in (1, 2, 5, 10, 20):
            print(f"  n={n:2d}: max |fit(n) - fit(40)| = {np.abs(fits[n] - fits[40]).max():.3f}")


if __name__ == "__main__":
    main()
