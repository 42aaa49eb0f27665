"""Learning curves of a training script as it is now against the same script at an earlier commit,
over several seeds: the check behind an optimisation that changes float rounding or the sampling
stream, where bit-for-bit equality cannot hold and statistical equivalence is what is claimed.

    python benchmarks/compare_learning_curves.py --rev 406cc87~1 --env-id CartPole-v1 --seeds 8
    python benchmarks/compare_learning_curves.py --rev 406cc87~1 --env-id Hopper-v4 --seeds 4 --total-timesteps 100000
    python benchmarks/compare_learning_curves.py --rev HEAD --compile --seeds 8   # --compile against eager

Each run trains at `--guidance`; its score is the mean episodic return over the whole run (the area
under the learning curve) and over the last tenth of its episodes. Prints both per revision, with
Welch's t-test between them. Not part of the test suite: it takes minutes.
"""

import importlib.util
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


def load_script(source: str, name: str):
    """The module defined by `source`, a training script's text."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp, f"{name}.py")
        path.write_text(source)
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    return module


def scores(module, args: Args, compile: bool = False) -> np.ndarray:
    """(seeds, 2): mean episodic return over each run, and over its last tenth of episodes."""
    rows = []
    for seed in range(1, args.seeds + 1):
        with tempfile.TemporaryDirectory() as tmp:
            run_args = module.Args(
                env_id=args.env_id, total_timesteps=args.total_timesteps, guidance=args.guidance, seed=seed,
                output_dir=tmp, checkpoint_interval=args.total_timesteps, **({"compile": True} if compile else {}),
            )  # fmt: skip
            run_dir = module.prepare_run_dir(run_args)
            module.train(run_args, run_dir)
            events = EventAccumulator(str(run_dir))
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
    shown = subprocess.run(["git", "show", f"{args.rev}:{script}"], cwd=ROOT, capture_output=True, text=True)
    if shown.returncode:
        sys.exit(f"error: cannot read {script} at {args.rev}: {shown.stderr.strip().splitlines()[-1]}")
    results = {
        args.rev: scores(load_script(shown.stdout, "reference_script"), args),
        "working tree" + (" --compile" if args.compile else ""): scores(
            load_script((ROOT / script).read_text(), "current_script"), args, args.compile
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
