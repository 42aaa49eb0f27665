"""Reproduce the paper end to end: train the grid, sweep γ on every checkpoint, write tables and figures.

    python reproduce.py --preset quick                   # minutes on a laptop
    python reproduce.py --preset discrete --workers 8     # CartPole + Acrobot, 5 seeds, 3 variants
    python reproduce.py --preset continuous --envs Hopper-v4 InvertedPendulum-v4 --variants ppo pgg_g1.1
    python reproduce.py --preset continuous --executor slurm --slurm-partition cpu   # a job array

The grid is environments × seeds × training variants:
  ppo          PPO, γ_train = 1 (the null embedding gets no gradient: CleanRL's PPO algorithm)
  pgg_g1.1     PGG, γ_train = 1.1, no dropout (the paper's main variant)
  pgg_drop0.1  PGG, γ_train = 1, conditioning dropout 0.1

Run directories are <root>/<env>__<variant>__s<seed>, logs <root>/logs/<run>.log. Every argument is
checked before anything is trained (one line, exit 2). Rerunning the same command skips every run whose
final checkpoint exists, resumes a half-finished run from its last checkpoint (bit for bit, see the
training scripts' --resume) and skips every finished sweep cell, so killing the launcher loses at most
the work since each run's last checkpoint: its local training children die with it, even when it is
SIGKILLed (Linux); SIGINT or SIGTERM also cancels submitit jobs. Preempted Slurm array tasks are
requeued and resume the same way. The sweep CSVs, tables and figures go to <results>, locked against
a second launcher or plot_results.py for as long as this one runs, as <root> is.
"""

from pgg_utils import startup  # noqa: F401  (first: a Ctrl-C during the imports below is one line, status 130)

# isort: split
import contextlib
import functools
import importlib.util
import os
import shutil
import signal
import subprocess
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Annotated, Literal

import tyro

import eval_gamma_sweep
import plot_results
from paper_study import paper
from paper_study.agents import export_agents
from pgg_utils import checkpoints, checks, processes, scripts
from pgg_utils.arguments import RUN_ONLY_ARGS, guidance_error
from pgg_utils.files import (
    RECORD,
    InputError,
    LockedError,
    check_writable,
    lock_directory,
    lock_holder,
    one_line_errors,
    write_atomic,
)
from pgg_utils.identity import GOAL_DIMS, VARIANT_ARGS, Configuration, format_arg, grid_run_name, variant_id
from pgg_utils.progress import Progress

ROOT = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Preset:
    envs: tuple[str, ...]
    seeds: int
    variants: tuple[str, ...]
    total_timesteps: int | None  # None: the training script's default (the paper's)
    checkpoint_interval: int | None
    gammas: tuple[float, ...] | None  # None: the sweep's default (the paper's)
    episodes: int


# The task the grid's variants are named on, with the continuous script: one with goal dimensions, so that
# every variant trains on it.
NAMING_ENV = next(iter(GOAL_DIMS))


@functools.cache
def variant_arguments(flags: tuple[str, ...], env_id: str, kind: str) -> dict:
    """The training arguments of a variant's flags (paper.VARIANTS, paper.BEYOND_VARIANTS) on `env_id`, parsed by
    the `kind` training script's own Args as its command line is. ValueError (`needs ...`, `has flags ...`) where
    it cannot run there."""
    module = scripts.original(kind)
    try:
        args = tyro.cli(module.Args, args=["--env-id", env_id, *paper.variant_flags(flags, env_id)],
                        console_outputs=False)  # fmt: skip
    except SystemExit:
        raise ValueError(f"has flags that {Path(module.__file__).name} refuses: {' '.join(flags)}") from None
    return asdict(args)


def variant_name(flags: tuple[str, ...], env_id: str, kind: str) -> str:
    """The id identity.variant_id gives a run of a variant's flags on `env_id` (variant_arguments): the one
    definition of a variant's name."""
    return variant_id(variant_arguments(flags, env_id, kind))


def unnamed_arguments(flags: tuple[str, ...]) -> dict:
    """The training arguments a variant's flags set away from the continuous script's defaults, on NAMING_ENV,
    besides those its variant id names (`{"learning_rate": 0.001}`)."""
    args, defaults = variant_arguments(flags, NAMING_ENV, "continuous"), variant_arguments((), NAMING_ENV, "continuous")
    unnamed = args.keys() - VARIANT_ARGS - RUN_ONLY_ARGS - {"env_id", "seed"}
    return {key: args[key] for key in sorted(unnamed) if args[key] != defaults[key]}


@functools.cache
def grid_variants() -> dict[str, tuple[str, ...]]:
    """{id: training flags} of the variants the grid can run: the paper's in its order, then those beyond it,
    each named by variant_name on NAMING_ENV with the continuous script, which takes every variant's flags. A
    variant whose runs would get the id of an earlier one, from which it differs in an argument the id does not
    name, has that id followed by the other arguments its flags set (`pgg_g1.1_learning_rate0.001`). ValueError
    (one line) for two variants that train the same runs."""
    named = {}
    for flags in (*paper.VARIANTS, *paper.BEYOND_VARIANTS):
        name = variant_name(flags, NAMING_ENV, "continuous")
        if name in named:
            name += "".join(f"_{key}{format_arg(value)}" for key, value in unnamed_arguments(flags).items())
        if name in named:
            raise ValueError(f"paper.py's variants {' '.join(named[name])} and {' '.join(flags)} train the same "
                             f"runs ({name}): remove one")  # fmt: skip
        named[name] = flags
    return named


try:
    VARIANT_IDS = tuple(grid_variants())
except ValueError as e:  # paper.py's variants, as edited: every command would stop here
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)
PAPER_VARIANT_IDS = VARIANT_IDS[: len(paper.VARIANTS)]
PRESETS = {
    "quick": Preset(("CartPole-v1",), 2, PAPER_VARIANT_IDS, 50_000, 25_000, (1.0, 2.0, 5.0), 20),
    "discrete": Preset(paper.PAPER_ENVS["discrete"], paper.PAPER_SEEDS, PAPER_VARIANT_IDS, None, None, None, 50),
    "continuous": Preset(paper.PAPER_ENVS["continuous"], paper.PAPER_SEEDS, PAPER_VARIANT_IDS, None, None, None, 50),
}
RUNNING: set[subprocess.Popen] = set()  # training children, ended with the launcher
SUBMITTED: list = []  # submitit jobs (the same), cancelled by SIGINT / SIGTERM

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
    variants: Annotated[tuple[Literal[VARIANT_IDS], ...] | None, FROM_PRESET] = None
    """training variants: the paper's three (every preset has them), or those beyond it (paper_study/paper.py's BEYOND_VARIANTS, named by their flags; a goal variant needs Reacher-v4 or Pusher-v4)"""
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
    agents: bool = True
    """export the agent of every swept checkpoint into <results>/agents (no optimizer or resume state), with a README listing them"""
    compile: bool = False
    """train with --compile (needs a C++ compiler): ~1.25x faster training, whose compile pays back after ~45k Hopper steps with inductor's cache warm, ~210k cold (benchmarks/README.md)"""


def settings(args: Args) -> Preset:
    """The grid's settings: each flag that was given, else the preset's (`is None`, so a given 0 stays 0
    and is refused rather than replaced)."""
    preset = PRESETS[args.preset]
    return Preset(**{f.name: getattr(preset, f.name) if getattr(args, f.name) is None else getattr(args, f.name)
                     for f in fields(Preset)})  # fmt: skip


def argument_error(args: Args) -> str | None:
    """The first bad argument as one line, or None: the training scripts' and the sweep's rules, checked
    here before anything is trained or written, so that no run of the grid fails on them hours later."""
    chosen = settings(args)
    for flag, values in (("--envs", chosen.envs), ("--variants", chosen.variants), ("--gammas", chosen.gammas)):
        if values is not None and not values:
            return f"{flag} needs at least one value"
        if values is not None and len(set(values)) < len(values):  # two runs would share a run directory
            return f"{flag} lists a value twice: {' '.join(map(str, values))}"
    for flag, value in (("--seeds", chosen.seeds), ("--total-timesteps", chosen.total_timesteps),
                        ("--checkpoint-interval", chosen.checkpoint_interval), ("--episodes", chosen.episodes),
                        ("--workers", args.workers), ("--slurm-time-min", args.slurm_time_min),
                        ("--slurm-array-parallelism", args.slurm_array_parallelism)):  # fmt: skip
        if value is not None and value <= 0:
            return f"{flag} must be positive, got {value}"
    if args.executor != "local" and importlib.util.find_spec("submitit") is None:
        return f"--executor {args.executor} needs submitit (pip install submitit)"
    if args.executor == "slurm" and not (shutil.which("srun") and shutil.which("sbatch")):
        return "--executor slurm needs Slurm (srun and sbatch on PATH); without a cluster use --executor local or submitit-local"
    for gamma in chosen.gammas or ():
        if error := guidance_error(gamma, "--gammas"):
            return error
    for env_id in chosen.envs:
        try:
            kind = paper.action_kind(env_id)
        except ValueError as e:
            return f"--envs: {e}"
        if error := checks.env_error(env_id, kind):
            return f"--envs: {error}"
        for variant in chosen.variants:
            try:
                name = variant_name(grid_variants()[variant], env_id, kind)
            except ValueError as e:
                return f"--variants: {variant} {e}"
            if name != variant_name(grid_variants()[variant], NAMING_ENV, "continuous"):  # named for another
                return f"--variants: {variant}'s flags give its runs on {env_id} the variant id {name}"
        defaults = scripts.original(kind).Args()
        batch = defaults.num_envs * defaults.num_steps
        if chosen.checkpoint_interval is not None and chosen.checkpoint_interval < batch:
            return (f"--checkpoint-interval must be at least one batch of {env_id}'s training script, "
                    f"num_envs * num_steps = {batch}, got {chosen.checkpoint_interval}")  # fmt: skip
    return None


@dataclass(frozen=True)
class RunSpec:
    env_id: str
    variant: str
    seed: int
    root: str
    total_timesteps: int | None  # None: the script's default
    checkpoint_interval: int | None
    compile: bool = False

    @property
    def name(self) -> str:
        return grid_run_name(self.env_id, self.variant, self.seed)

    @property
    def run_dir(self) -> Path:
        return Path(self.root) / self.name

    @property
    def final_checkpoint(self) -> Path:
        kind = paper.action_kind(self.env_id)
        total = scripts.original(kind).Args().total_timesteps if self.total_timesteps is None else self.total_timesteps
        return checkpoints.checkpoint_path(self.run_dir, total)

    @property
    def log(self) -> Path:
        return Path(self.root) / "logs" / f"{self.name}.log"

    def last_step(self) -> int | None:
        """The step of the run's last checkpoint; None where it has none (nothing to resume or sweep)."""
        latest = checkpoints.latest_checkpoint(self.run_dir)
        return None if latest is None else checkpoints.checkpoint_step(latest)

    def command(self) -> list[str]:
        cmd = [sys.executable, scripts.original(paper.action_kind(self.env_id)).__file__, "--env-id", self.env_id,
               "--seed", str(self.seed), *paper.variant_flags(grid_variants()[self.variant], self.env_id),
               "--output-dir", self.root, "--run-name", self.name, "--torch-threads", "1"]  # fmt: skip
        if self.total_timesteps is not None:
            cmd += ["--total-timesteps", str(self.total_timesteps)]
        if self.checkpoint_interval is not None:
            cmd += ["--checkpoint-interval", str(self.checkpoint_interval)]
        if self.compile:
            cmd.append("--compile")
        return cmd


def train_one(spec: RunSpec) -> None:
    """Trains (or resumes) one run in a child process pinned to one thread; raises on failure. The
    function every executor runs, so local and cluster runs share one code path. The child is started
    and waited for in this thread, which its death signal is tied to; if the wait is cut short (a
    preempted submitit job exits, Ctrl-C), the child is killed and reaped first, so that the run's lock
    is free for the requeued job that resumes it."""
    spec.log.parent.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    with open(spec.log, "a") as log:
        child = subprocess.Popen(
            [*spec.command(), "--resume"],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
            preexec_fn=processes.child_of(os.getpid()),
        )
        RUNNING.add(child)
        try:
            code = child.wait()
        finally:
            child.kill()
            child.wait()
            RUNNING.discard(child)
    if code != 0:
        raise RuntimeError(f"{spec.name}: training exited with status {code}")
    if not spec.final_checkpoint.exists():
        raise RuntimeError(f"{spec.name}: training ended without its final checkpoint {spec.final_checkpoint.name}")


class TrainingTask:
    """train_one as a submitit callable. Submitit calls `checkpoint` when Slurm preempts an array task
    or its time runs out; the task is requeued and, as train_one passes --resume, continues from the
    run's last checkpoint. Jobs unpickle it as `reproduce.TrainingTask` (see importable_by_jobs)."""

    def __call__(self, spec: RunSpec) -> None:
        train_one(spec)

    def checkpoint(self, spec: RunSpec):
        import submitit

        return submitit.helpers.DelayedSubmission(self, spec)


def grid(args: Args) -> list[RunSpec]:
    chosen = settings(args)
    root = args.root or f"runs/{args.preset}"
    return [RunSpec(env, variant, seed, root, chosen.total_timesteps, chosen.checkpoint_interval, args.compile)
            for env in chosen.envs for seed in range(1, chosen.seeds + 1) for variant in chosen.variants]  # fmt: skip


def grid_state(specs: list[RunSpec]) -> str:
    """What this launch skips, resumes and starts: `6 runs in the grid: 1 trained, 1 half done (name at
    step 4,096), 4 not started`."""
    trained = [s for s in specs if s.final_checkpoint.exists()]
    half_done = [(s.name, step) for s in specs if s not in trained and (step := s.last_step()) is not None]
    at = f" ({', '.join(f'{name} at step {step:,}' for name, step in half_done)})" if half_done else ""
    return (f"{len(specs)} runs in the grid: {len(trained)} trained, {len(half_done)} half done{at}, "
            f"{len(specs) - len(trained) - len(half_done)} not started")  # fmt: skip


class Tally:
    """The grid's runs as they end, on pgg_utils' progress display (its ETA at this launch's rate)."""

    def __init__(self, total: int, trained: int):
        self.done, self.failed = trained, []  # failed: (spec, the log that says why, None where none was written)
        self.progress = Progress("runs", total, trained, unit="ended", interval=0, stream=sys.stderr)

    def show(self, details: str) -> None:
        self.progress.update(self.done + len(self.failed), f"{details}, {len(self.failed)} failed")

    def record(self, spec: RunSpec, error: BaseException | str | None = None, log: Path | None = None) -> None:
        if error is None:
            self.done += 1
        else:
            self.failed.append((spec, log))
            print(f"FAILED {spec.name}: {error}{f'; log: {log}' if log else ''}", file=sys.stderr, flush=True)


def run_local(todo: list[RunSpec], tally: Tally, workers: int) -> None:
    with ThreadPoolExecutor(workers) as pool:
        started = {pool.submit(train_one, spec): spec for spec in todo}
        pending = set(started)
        tally.show(f"{min(workers, len(pending))} running")
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                spec = started[future]
                tally.record(spec, future.exception(), spec.log if spec.log.exists() else None)
            tally.show(f"{min(workers, len(pending))} running")


@contextlib.contextmanager
def importable_by_jobs():
    """Jobs unpickle reproduce.TrainingTask and reproduce.RunSpec, so `import reproduce` must work in them
    wherever the launcher was started: ROOT leads PYTHONPATH while they are submitted, in the environment
    that submitit's local controller copies and sbatch exports (its default, --export=ALL)."""
    before = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT), *([before] if before else [])])
    try:
        yield
    finally:
        if before is None:
            del os.environ["PYTHONPATH"]
        else:
            os.environ["PYTHONPATH"] = before


def run_submitit(todo: list[RunSpec], tally: Tally, args: Args) -> None:
    import submitit

    folder = Path(todo[0].root) / "submitit"
    if args.executor == "slurm":
        executor = submitit.AutoExecutor(folder=folder, cluster="slurm")
        executor.update_parameters(timeout_min=args.slurm_time_min, cpus_per_task=1, slurm_partition=args.slurm_partition,
                                   slurm_array_parallelism=args.slurm_array_parallelism)  # fmt: skip
    else:
        executor = submitit.LocalExecutor(folder=folder)
        executor.update_parameters(timeout_min=args.slurm_time_min)
    with importable_by_jobs():
        jobs = executor.map_array(TrainingTask(), todo)
    SUBMITTED.extend(jobs)
    pending = dict(zip(jobs, todo, strict=True))
    tally.show(f"{len(pending)} in progress")
    while pending:
        time.sleep(1.0)
        finished = [job for job in pending if job.done()]
        for job in finished:
            spec = pending.pop(job)
            try:
                job.result()
                tally.record(spec)
            except Exception as e:
                # The run's log, unless the job failed before train_one opened it: then submitit's own.
                tally.record(spec, str(e).strip().splitlines()[-1], spec.log if spec.log.exists() else job.paths.stderr)
        if finished:
            tally.show(f"{len(pending)} in progress")


def other_arguments(spec: RunSpec) -> str | None:
    """`name (total_timesteps 10 -> 2048)` where the run's last checkpoint holds other training arguments
    than this grid gives it (a run of another grid, which its training script refuses to continue, and
    which the sweep must not take for this grid's); None otherwise, or where it has none to read."""
    latest = checkpoints.latest_checkpoint(spec.run_dir)
    if latest is None:
        return None
    try:
        recorded = Configuration.of_checkpoint(checkpoints.read_checkpoint_file(latest))
    except ValueError:  # the sweep lists it in skipped.csv
        return None
    kind = paper.action_kind(spec.env_id)
    module = scripts.original(kind)
    wanted = tyro.cli(module.Args, args=spec.command()[2:])  # the arguments the run's command gives it
    differing = recorded.differing(Configuration.of_run(module.__file__, kind, wanted), asdict(module.Args()))
    return f"{spec.name} ({', '.join(differing)})" if differing else None


def unfinished_note(spec: RunSpec) -> str:
    """`name (last checkpoint's step)`, and who is training it now where its run directory is locked."""
    holder = lock_holder(spec.run_dir)
    return f"{spec.name} ({spec.last_step():,}{f', being trained now by pid {holder}' if holder else ''})"


def reproduce(args: Args) -> int:
    """Returns the number of failed runs; InputError (one line) for bad arguments, before anything is written."""
    if error := argument_error(args):
        raise InputError(error)
    specs = grid(args)
    results = Path(args.results or f"results/{args.preset}")
    plot_results.check_writable(results)  # before hours of training, not after
    root = Path(specs[0].root)
    lock = claim_root(root)
    try:
        # A second launcher into the same results would mix its tables with this one's agents.
        results_lock = None if results.resolve() == root.resolve() else plot_results.claim_output(results, "--results")
        try:
            return reproduce_locked(args, specs, results)
        finally:
            if results_lock is not None:
                results_lock.close()
    finally:
        lock.close()


def claim_root(root: Path):
    """Locks the grid's root for this launcher (files.lock_directory). InputError with one line where
    it is not a writable directory or another launcher holds it: two launchers would each train, and
    report as failed, the runs the other is training, and sweep them half-trained."""
    if root.exists() and not root.is_dir():
        raise InputError(f"--root {root} exists and is not a directory")
    check_writable(root)
    try:
        return lock_directory(root, "another reproduce.py")
    except LockedError as e:
        raise InputError(f"{e}; wait for it to finish or choose another --root") from None


def reproduce_locked(args: Args, specs: list[RunSpec], results: Path) -> int:
    todo = [s for s in specs if not s.final_checkpoint.exists()]
    print(grid_state(specs), file=sys.stderr)
    tally = Tally(len(specs), len(specs) - len(todo))
    if todo and not args.skip_training:
        if args.executor == "local":
            run_local(todo, tally, args.workers)
        else:
            run_submitit(todo, tally, args)
        tally.progress.close()

    stale = {s: note for s in specs if (note := other_arguments(s))}
    if stale:
        print(f"note: not swept, trained with other arguments than this grid's: {'; '.join(stale.values())} "
              "(choose another --root, or delete them)", file=sys.stderr)  # fmt: skip
    swept = [s for s in specs if s not in stale and s.last_step() is not None]
    if not swept:
        raise InputError("no run has any checkpoint to sweep")
    unfinished = [unfinished_note(s) for s in swept if not s.final_checkpoint.exists()]
    if unfinished:
        print(f"note: unfinished, so swept up to the last checkpoint: {'; '.join(unfinished)}", file=sys.stderr)
    chosen = settings(args)
    sweep_args = eval_gamma_sweep.Args(paths=tuple(str(s.run_dir) for s in swept), output=str(Path(specs[0].root) / "sweep"),
                                       gammas=chosen.gammas, episodes=chosen.episodes, workers=args.workers)  # fmt: skip
    sweep_dir = eval_gamma_sweep.sweep(sweep_args)
    for name in ("episodes.csv", "summary.csv", RECORD):  # with the sweep's record, by which the tables check it
        write_atomic(results / name, (sweep_dir / name).read_bytes())
    plot_args = plot_results.Args(sweeps=(str(results),), output=str(results), runs=sweep_args.paths,
                                  compare_paper=True)  # fmt: skip
    plot_results.validate(plot_args)
    written = plot_results.generate_locked(plot_args)  # reproduce holds the lock of <results>
    if args.agents:
        written.append(export_agents(swept, results / "agents"))
    print(f"results in {results}: {len(written)} files", file=sys.stderr)
    for spec, log in tally.failed:
        print(f"failed: {spec.name}{f', log {log}' if log else ''}", file=sys.stderr)
    return len(tally.failed)


def main() -> None:
    args = tyro.cli(Args, description=__doc__)

    def stop(signum, _frame):
        # End the training children with us, so that none writes into a run directory after we are gone
        # (a SIGKILLed launcher's local children die by their death signal; submitit jobs cannot).
        for child in list(RUNNING):
            child.kill()
        for job in SUBMITTED:
            try:
                job.cancel(check=False)
            except Exception:  # noqa: S110  a job that already ended, or a scheduler that is gone
                pass
        print(f"interrupted ({signal.Signals(signum).name}): finished runs, checkpoints and sweep cells are kept; "
              "rerun the same command to continue", file=sys.stderr, flush=True)  # fmt: skip
        os._exit(128 + signum)

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    with one_line_errors():  # files.exit_status's rule; finished runs and cells stay
        failed = reproduce(args)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    # Run as the module `reproduce`, not `__main__`: submitit pickles TrainingTask and RunSpec by their
    # module's name, and a job can import `reproduce` but has no `__main__` of ours.
    import reproduce

    reproduce.main()
