"""Learning curves of a training script as it is now against the same script at an earlier commit,
over several seeds: the check behind an optimisation that changes float rounding or the sampling
stream, where bit-for-bit equality cannot hold and statistical equivalence is what is claimed.

    python -m benchmarks.compare_learning_curves --rev 406cc87~1 --env-id CartPole-v1 --seeds 8
    python -m benchmarks.compare_learning_curves --rev 406cc87~1 --env-id Hopper-v4 --seeds 4 --total-timesteps 100000
    python -m benchmarks.compare_learning_curves --rev HEAD --compile --seeds 8   # --compile against eager

Each run trains at `--guidance`; its score is the mean episodic return over the whole run (the area
under the learning curve) and over the last tenth of its episodes. Prints both per revision, with
Welch's t-test between them. Not part of the test suite: it takes minutes.
"""

import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tyro
from scipy import stats
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

ROOT = Path(__file__).resolve().parent.parent
from benchmarks.compare_revisions import CHILD_ENV, WORKTREE, export


@dataclass
class Args:
    rev: str
    """the earlier commit (anything `git show` takes) whose script is the reference"""
    env_id: str = "CartPole-v1"
    """a Discrete env runs ppo_pgg_discrete.py, a Box one ppo_pgg_continuous.py"""
    seeds: int = 8
    """seeds 1..N, the same for both revisions"""
    total_timesteps: int = 100_000
    """training steps per run"""
    guidance: float = 1.1
    """PGG guidance γ of every run"""
    compile: bool = False
    """train the working tree's runs with --compile (the reference's stay eager): the check behind it"""


def scores(tree: Path, script: str, args: Args, compile: bool = False) -> np.ndarray:
    """(seeds, 2): mean episodic return over each run, and over its last tenth of episodes. Each run
    is `script` of the checkout `tree`, run as a command (with that revision's own pgg_utils)."""
    rows = []
    for seed in range(1, args.seeds + 1):
        with tempfile.TemporaryDirectory() as tmp:
            command = [sys.executable, str(tree / script), "--env-id", args.env_id, "--total-timesteps",
                       str(args.total_timesteps), "--guidance", str(args.guidance), "--seed", str(seed),
                       "--output-dir", tmp, "--run-name", "run", "--checkpoint-interval", str(args.total_timesteps),
                       *(["--compile"] if compile else [])]  # fmt: skip
            done = subprocess.run(
                command, cwd=tree, env=dict(CHILD_ENV, PYTHONPATH=str(tree)), capture_output=True, text=True
            )
            if done.returncode:
                sys.exit(f"error: {script} at {tree.name} failed: {(done.stderr.strip().splitlines() or ['?'])[-1]}")
            events = EventAccumulator(str(Path(tmp, "run")))
            events.Reload()
            returns = np.array([e.value for e in events.Scalars("charts/episodic_return")])
        rows.append((returns.mean(), returns[-max(1, len(returns) // 10) :].mean()))
    return np.array(rows)


def main() -> None:
    args = tyro.cli(Args)
    import gymnasium as gym

    try:
        env = gym.make(args.env_id)
    except (gym.error.Error, ImportError) as e:
        sys.exit(f"error: cannot make environment {args.env_id!r}: {e}")
    discrete = isinstance(env.action_space, gym.spaces.Discrete)
    env.close()
    script = "ppo_pgg_discrete.py" if discrete else "ppo_pgg_continuous.py"
    with tempfile.TemporaryDirectory() as scratch:
        trees = {"reference": Path(scratch, "reference"), "working tree": Path(scratch, "worktree")}
        try:
            export(args.rev, trees["reference"])
            export(WORKTREE, trees["working tree"])
        except subprocess.CalledProcessError as e:
            sys.exit(
                f"error: cannot export {args.rev}: {e.stderr.decode().strip().splitlines()[-1] if e.stderr else e}"
            )
        results = {
            args.rev: scores(trees["reference"], script, args),
            "working tree" + (" --compile" if args.compile else ""): scores(
                trees["working tree"], script, args, args.compile
            ),
        }
    print(f"{script} on {args.env_id}, {args.seeds} seeds x {args.total_timesteps:,} steps, guidance {args.guidance:g}")
    for i, what in enumerate(("mean return over the run", "mean return, last tenth")):
        (ref_name, ref), (cur_name, cur) = ((name, values[:, i]) for name, values in results.items())
        p_value = stats.ttest_ind(ref, cur, equal_var=False).pvalue
        print(
            f"{what:26s} {ref_name}: {ref.mean():.1f} ± {ref.std(ddof=1):.1f}   "
            f"{cur_name}: {cur.mean():.1f} ± {cur.std(ddof=1):.1f}   Welch p = {p_value:.2f}"
        )


if __name__ == "__main__":
    main()
