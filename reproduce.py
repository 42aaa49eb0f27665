"""Reproduce the paper end to end: train the grid, sweep γ on every checkpoint, write tables and figures.

    python reproduce.py --preset quick                   # minutes on a laptop
    python reproduce.py --preset discrete --workers 8     # CartPole + Acrobot, 5 seeds, 3 variants
    python reproduce.py --preset continuous --envs Hopper-v4 InvertedPendulum-v4 --variants ppo pgg_g1.1
    python reproduce.py --preset continuous --executor slurm --slurm-partition cpu   # a job array

The grid is environments × seeds × training variants:
  ppo          PPO, γ_train = 1 (the null embedding gets no gradient: CleanRL's PPO algorithm)
  pgg_g1.1     PGG, γ_train = 1.1, no dropout (the paper's main variant)
  pgg_drop0.1  PGG, γ_train = 1, conditioning dropout 0.1
Run directories are <root>/<env>__<variant>__s<seed>, logs <root>/logs/<run>.log. Rerunning the same
command skips every run whose final checkpoint exists, resumes a half-finished run from its last
checkpoint (bit for bit, see the training scripts' --resume) and skips every finished sweep cell, so
killing the launcher loses at most the work since each run's last checkpoint: its local training
children die with it, even when it is SIGKILLed (Linux); SIGINT or SIGTERM also cancels submitit jobs.
Preempted Slurm array tasks are requeued and resume the same way. The sweep CSVs, tables and figures
go to <results>.
"""

import ctypes
import fcntl
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Annotated, Literal

import gymnasium as gym
import tyro

import eval_gamma_sweep
import plot_results
import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import runs

ROOT = Path(__file__).resolve().parent
VARIANTS = {"ppo": (1.0, 0.0), "pgg_g1.1": (1.1, 0.0), "pgg_drop0.1": (1.0, 0.1)}
CONTINUOUS_TASKS = ("HalfCheetah-v4", "Hopper-v4", "Humanoid-v4", "InvertedPendulum-v4", "Pusher-v4", "Walker2d-v4")


@dataclass(frozen=True)
class Preset:
    envs: tuple[str, ...]
    seeds: int
    variants: tuple[str, ...]
    total_timesteps: int | None  # None: the training script's default (the paper's)
    checkpoint_interval: int | None
    gammas: tuple[float, ...] | None  # None: the sweep's default (the paper's)
    episodes: int


PRESETS = {
    "quick": Preset(("CartPole-v1",), 2, tuple(VARIANTS), 50_000, 25_000, (1.0, 2.0, 5.0), 20),
    "discrete": Preset(("CartPole-v1", "Acrobot-v1"), 5, tuple(VARIANTS), None, None, None, 50),
    "continuous": Preset(CONTINUOUS_TASKS, 5, tuple(VARIANTS), None, None, None, 50),
}
RUNNING: set[subprocess.Popen] = set()  # training children, ended with the launcher
SUBMITTED: list = []  # submitit jobs (the same), cancelled by SIGINT / SIGTERM


@cache
def training_module(env_id: str):
    """The training script for this env's action space."""
    env = gym.make(env_id)
    discrete = isinstance(env.action_space, gym.spaces.Discrete)
    env.close()
    return ppo_pgg_discrete if discrete else ppo_pgg_continuous


# The help of a flag whose None means "take it from the preset" (tyro would print "(default: None)").
FROM_PRESET = tyro.conf.arg(help_behavior_hint="(default: the preset's)")
FROM_PRESET_OR_PAPER = tyro.conf.arg(help_behavior_hint="(default: the preset's, else the paper's)")


@dataclass
class Args:
    preset: Literal["quick", "discrete", "continuous"] = "quick"
    """the grid to run; the flags below override its parts"""
    envs: Annotated[tuple[str, ...] | None, FROM_PRESET] = None
    """environments"""
    seeds: Annotated[int | None, FROM_PRESET] = None
    """number of seeds, 1..N"""
    variants: Annotated[tuple[Literal["ppo", "pgg_g1.1", "pgg_drop0.1"], ...] | None, FROM_PRESET] = None
    """training variants (every preset has all three)"""
    total_timesteps: Annotated[int | None, FROM_PRESET_OR_PAPER] = None
    """training steps per run"""
    checkpoint_interval: Annotated[int | None, FROM_PRESET_OR_PAPER] = None
    """steps between checkpoints"""
    gammas: Annotated[tuple[float, ...] | None, FROM_PRESET_OR_PAPER] = None
    """eval guidance values of the sweep"""
    episodes: Annotated[int | None, FROM_PRESET] = None
    """evaluation episodes per (checkpoint, γ) cell"""
    root: Annotated[str | None, tyro.conf.arg(help_behavior_hint="(default: runs/<preset>)")] = None
    """where the runs go"""
    results: Annotated[str | None, tyro.conf.arg(help_behavior_hint="(default: results/<preset>)")] = None
    """where sweep CSVs, tables and figures go"""
    executor: Literal["local", "submitit-local", "slurm"] = "local"
    """local: a process pool here; slurm: a submitit job array; submitit-local: submitit's local executor, the same code path as slurm without a cluster"""
    workers: int = os.cpu_count() or 1
    """concurrent training runs (local) and sweep processes"""
    slurm_partition: Annotated[str | None, tyro.conf.arg(help_behavior_hint="(default: the cluster's)")] = None
    """Slurm partition"""
    slurm_time_min: int = 180
    """Slurm time limit per run, minutes"""
    slurm_array_parallelism: int = 64
    """at most this many array tasks at once"""
    skip_training: bool = False
    """only sweep and plot what is already trained"""
    compile: bool = False
    """train with --compile (needs a C++ compiler): ~1.25x faster training, whose compile pays back after ~45k Hopper steps with inductor's cache warm, ~210k cold (benchmarks/README.md)"""


@dataclass(frozen=True)
class RunSpec:
    env_id: str
    variant: str
    seed: int
    root: str
    total_timesteps: int | None
    checkpoint_interval: int | None
    compile: bool = False

    @property
    def name(self) -> str:
        return f"{self.env_id}__{self.variant}__s{self.seed}"

    @property
    def final_checkpoint(self) -> Path:
        module = training_module(self.env_id)
        total = self.total_timesteps or module.Args().total_timesteps
        return runs.checkpoint_path(Path(self.root) / self.name, total)

    @property
    def log(self) -> Path:
        return Path(self.root) / "logs" / f"{self.name}.log"

    def command(self) -> list[str]:
        guidance, dropout = VARIANTS[self.variant]
        script = ROOT / f"{training_module(self.env_id).__name__}.py"
        cmd = [sys.executable, str(script), "--env-id", self.env_id, "--seed", str(self.seed),
               "--guidance", str(guidance), "--cond-dropout", str(dropout), "--output-dir", self.root,
               "--run-name", self.name, "--torch-threads", "1"]  # fmt: skip
        if self.total_timesteps:
            cmd += ["--total-timesteps", str(self.total_timesteps)]
        if self.checkpoint_interval:
            cmd += ["--checkpoint-interval", str(self.checkpoint_interval)]
        if self.compile:
            cmd.append("--compile")
        return cmd


LIBC = ctypes.CDLL(None, use_errno=True) if sys.platform == "linux" else None  # loaded here, not after fork


def die_with(parent: int):
    """For a child before exec (preexec_fn): the kernel kills it when the thread that started it ends,
    which a launcher killed by SIGKILL cannot arrange itself (Linux; elsewhere only SIGINT/SIGTERM
    do). If the launcher died before the signal was set, the child is already an orphan: it exits.
    Only an async-signal-safe system call and getppid run between fork and exec."""

    def set_death_signal() -> None:
        if LIBC is not None:
            LIBC.prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG
            if os.getppid() != parent:
                os._exit(1)

    return set_death_signal


def train_one(spec: RunSpec) -> None:
    """Trains (or resumes) one run in a child process pinned to one thread; raises with the log's path
    on failure. The function every executor runs, so local and cluster runs share one code path. The
    child is started and waited for in this thread, which its death signal is tied to."""
    spec.log.parent.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    with open(spec.log, "a") as log:
        child = subprocess.Popen(
            [*spec.command(), "--resume"], stdout=log, stderr=subprocess.STDOUT, env=env, preexec_fn=die_with(os.getpid())
        )
        RUNNING.add(child)
        code = child.wait()
        RUNNING.discard(child)
    if code != 0 or not spec.final_checkpoint.exists():
        raise RuntimeError(f"{spec.name} failed (exit {code}); log: {spec.log}")


def grid(args: Args) -> list[RunSpec]:
    preset = PRESETS[args.preset]
    root = args.root or f"runs/{args.preset}"
    return [
        RunSpec(env, variant, seed, root, args.total_timesteps or preset.total_timesteps,
                args.checkpoint_interval or preset.checkpoint_interval, args.compile)  # fmt: skip
        for env in (args.envs or preset.envs)
        for seed in range(1, (args.seeds or preset.seeds) + 1)
        for variant in (args.variants or preset.variants)
    ]


class Progress:
    def __init__(self, total: int, already_done: int):
        self.total, self.done, self.failed, self.running = total, already_done, [], 0
        self.durations: list[float] = []
        self.workers = 1

    def line(self) -> str:
        remaining = self.total - self.done - len(self.failed)
        if self.durations and remaining:
            eta = eval_gamma_sweep.format_duration(sum(self.durations) / len(self.durations) * remaining / self.workers)
        else:
            eta = "unknown" if remaining else "0m00s"
        return f"runs: {self.done}/{self.total} done, {self.running} running, {len(self.failed)} failed, ETA {eta}"

    def show(self) -> None:
        print(self.line(), file=sys.stderr, flush=True)


class TrainingTask:
    """train_one, timed: returns the run's wall time. Submitit calls `checkpoint` when Slurm preempts
    an array task or its time runs out; the task is requeued and, as train_one passes --resume,
    continues from the run's last checkpoint."""

    def __call__(self, spec: RunSpec) -> float:
        start = time.time()
        train_one(spec)
        return time.time() - start

    def checkpoint(self, spec: RunSpec):
        import submitit

        return submitit.helpers.DelayedSubmission(self, spec)


def run_local(todo: list[RunSpec], progress: Progress, workers: int) -> None:
    progress.workers = workers
    with ThreadPoolExecutor(workers) as pool:
        started = {pool.submit(TrainingTask(), spec): spec for spec in todo}
        progress.running = min(workers, len(todo))
        progress.show()
        pending = set(started)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                error = future.exception()
                record(progress, started[future], error, 0.0 if error else future.result())
            progress.running = min(workers, len(pending))
            progress.show()


def record(progress: Progress, spec: RunSpec, error: BaseException | None, seconds: float) -> None:
    if error is None:
        progress.done += 1
        progress.durations.append(seconds)
    else:
        progress.failed.append(spec)
        print(f"FAILED {spec.name}: {error}", file=sys.stderr, flush=True)


def run_submitit(todo: list[RunSpec], progress: Progress, args: Args) -> None:
    import submitit

    folder = Path(todo[0].root) / "submitit"
    if args.executor == "slurm":
        executor = submitit.AutoExecutor(folder=folder, cluster="slurm")
        executor.update_parameters(timeout_min=args.slurm_time_min, cpus_per_task=1, slurm_partition=args.slurm_partition,
                                   slurm_array_parallelism=args.slurm_array_parallelism)  # fmt: skip
        progress.workers = args.slurm_array_parallelism
    else:
        executor = submitit.LocalExecutor(folder=folder)
        executor.update_parameters(timeout_min=args.slurm_time_min)
        progress.workers = len(todo)
    jobs = executor.map_array(TrainingTask(), todo)
    SUBMITTED.extend(jobs)
    pending = dict(zip(jobs, todo))
    while pending:
        progress.running = len(pending)
        progress.show()
        time.sleep(1.0)
        for job in [j for j in pending if j.done()]:
            spec = pending.pop(job)
            try:
                record(progress, spec, None, job.result())
            except Exception as e:  # submitit wraps the child's exception in its own type
                record(progress, spec, RuntimeError(f"{e}".strip().splitlines()[-1] + f"; log: {spec.log}"), 0)
    progress.running = 0
    progress.show()


def reproduce(args: Args) -> int:
    """Returns the number of failed runs."""
    specs = grid(args)
    results = Path(args.results or f"results/{args.preset}")
    plot_results.check_writable(results)  # before hours of training, not after
    todo = [s for s in specs if not s.final_checkpoint.exists()]
    progress = Progress(len(specs), len(specs) - len(todo))
    print(f"{len(specs)} runs in the grid, {len(specs) - len(todo)} already trained", file=sys.stderr)
    if todo and not args.skip_training:
        if args.executor == "local":
            run_local(todo, progress, args.workers)
        else:
            run_submitit(todo, progress, args)

    preset = PRESETS[args.preset]
    root = Path(specs[0].root)
    trained = sorted({str(root / s.name) for s in specs if s.final_checkpoint.parent.exists()})
    if not trained:
        raise eval_gamma_sweep.InputError("no run has any checkpoint to sweep")
    unfinished = [unfinished_note(s) for s in specs if s.final_checkpoint.parent.exists() and not s.final_checkpoint.exists()]
    if unfinished:
        print(f"note: unfinished, so swept up to the last checkpoint: {'; '.join(unfinished)}", file=sys.stderr)
    sweep_args = eval_gamma_sweep.Args(
        paths=tuple(trained), output=str(root / "sweep"), gammas=args.gammas or preset.gammas,
        episodes=args.episodes or preset.episodes, workers=args.workers,
    )  # fmt: skip
    sweep_dir = eval_gamma_sweep.sweep(sweep_args)
    results.mkdir(parents=True, exist_ok=True)
    for name in ("episodes.csv", "summary.csv"):
        copy_atomic(sweep_dir / name, results / name)
    written = plot_results.generate(
        plot_results.Args(sweeps=(str(results),), output=str(results), runs=tuple(trained), compare_paper=True)
    )
    print(f"results in {results}: {len(written)} files", file=sys.stderr)
    for spec in progress.failed:
        print(f"failed: {spec.name}, log {spec.log}", file=sys.stderr)
    return len(progress.failed)


def unfinished_note(spec: RunSpec) -> str:
    """`name (last checkpoint's step)`, and who is training it now where its run directory is locked."""
    run_dir = Path(spec.root) / spec.name
    latest = runs.latest_checkpoint(run_dir)
    note = f"{spec.name} ({int(latest.stem.split('_')[1]):,}" if latest else f"{spec.name} (no checkpoint"
    lock = run_dir / ".lock"
    if lock.exists():
        with open(lock) as handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                note += f", being trained now by pid {handle.read().strip() or 'unknown'}"
    return note + ")"


def copy_atomic(source: Path, destination: Path) -> None:
    tmp = destination.with_name(destination.name + ".tmp")
    tmp.write_bytes(source.read_bytes())
    os.replace(tmp, destination)


def main() -> None:
    args = tyro.cli(Args)

    def stop(signum, _frame):
        # End the training children with us, so that none writes into a run directory after we are gone
        # (a SIGKILLed launcher's local children die by their death signal; submitit jobs cannot).
        for child in list(RUNNING):
            child.kill()
        for job in SUBMITTED:
            try:
                job.cancel(check=False)
            except Exception:  # a job that already ended, or a scheduler that is gone
                pass
        os._exit(128 + signum)

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        failed = reproduce(args)
    except (eval_gamma_sweep.InputError, plot_results.InputError) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except OSError as e:  # e.g. a full disk while writing results; finished runs and cells stay
        print(f"error: {e}", file=sys.stderr)
        sys.exit(1)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
