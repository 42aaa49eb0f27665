"""Does this CPU train as the one that trained a shipped agent did? Retrains the agent's run from its
recorded arguments, as reproduce.py trains it, and compares the weights at every step mark bit for bit:

    python -m benchmarks.same_training_cpu results/discrete/agents/CartPole-v1__ppo__s1

(CartPole-v1 PPO seed 1, 500k steps with --compile: about 2 min on 2 cores.) The same code and
software stack train different weights on different CPUs while their sweeps of one checkpoint agree
(benchmarks/README.md, "Exactness of the sweep"), so where this says no, retraining a table's runs here
gives statistically equal runs, not the table's rows. Exit status 0 when every mark is bit-identical,
1 when one is not.
"""

import sys
from dataclasses import dataclass
from pathlib import Path

import torch
import tyro

import reproduce
from pgg_utils import checkpoints
from pgg_utils.files import InputError, one_line_errors
from pgg_utils.identity import variant_id


@dataclass
class Args:
    agent: tyro.conf.Positional[str]
    """a shipped agent's run folder (<agents>/<run>/checkpoints/step_*.pt)"""
    root: str = "runs/same_training_cpu"
    """where the retrained run and its log go; a finished one there is compared again, not retrained"""


def read(checkpoint: Path) -> dict:
    try:
        return checkpoints.read_checkpoint_file(checkpoint)
    except ValueError as e:
        raise InputError(f"{checkpoint}: {e}") from None


def compare_weights(first: Path, second: Path) -> tuple[int, int, float]:
    """(tensors bit-identical, tensors in all, largest absolute difference) of two checkpoints' weights."""
    a, b = read(first)["model"], read(second)["model"]
    if a.keys() != b.keys() or any(a[k].shape != b[k].shape for k in a):
        raise InputError(f"{first} and {second} hold different networks")
    equal = sum(torch.equal(a[k], b[k]) for k in a)
    return equal, len(a), max(float((a[k].double() - b[k].double()).abs().max()) for k in a)


def retrain(agent: Path, root: Path) -> Path:
    """Trains the agent's run again under `root`; returns the new run's directory."""
    shipped = checkpoints.checkpoints_of(agent)
    if not shipped:
        raise InputError(f"{agent} holds no checkpoints/step_*.pt")
    args = read(shipped[-1])["args"]
    variant = variant_id(args)
    spec = reproduce.RunSpec(args["env_id"], variant, args["seed"], str(root), args["total_timesteps"],
                             args["checkpoint_interval"], args["compile"])  # fmt: skip
    try:
        reproduce.train_one(spec)
    except RuntimeError as e:
        raise InputError(f"{e}; its log: {spec.log}") from None
    return spec.run_dir


def main() -> None:
    args = tyro.cli(Args)
    agent = Path(args.agent)
    with one_line_errors():
        retrained = retrain(agent, Path(args.root))
        print(f"this CPU: {checkpoints.machine()}")
        same = True
        for checkpoint in checkpoints.checkpoints_of(agent):
            equal, total, largest = compare_weights(checkpoint, retrained / "checkpoints" / checkpoint.name)
            same &= equal == total
            print(f"{checkpoint.name}: {equal} of {total} tensors bit-identical, largest |difference| {largest:.3g}")
        print("this CPU trains as the agent's did" if same else "this CPU does not train as the agent's did")
    sys.exit(0 if same else 1)


if __name__ == "__main__":
    main()
