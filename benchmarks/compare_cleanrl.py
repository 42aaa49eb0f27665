"""Our PPO (`--guidance 1 --cond-dropout 0`: CleanRL's algorithm and defaults) against CleanRL's own `ppo.py` or
`ppo_continuous_action.py`, each run in its own environment, over several seeds.

    python -m benchmarks.compare_cleanrl --env-id CartPole-v1 --seeds 8 --total-timesteps 500000 \\
        --cleanrl-dir ~/cleanrl/cleanrl --cleanrl-python ~/cleanrl-venv/bin/python --workers 2
    python -m benchmarks.compare_cleanrl --env-id CartPole-v1 --analyse-only     # the saved runs again

Both implementations run as child processes through their command lines, so nothing here depends on
either's internals: one thread each, at the lowest priority, `--workers` at a time, the two runs of a
seed one after the other in the queue so that they train side by side under the same load. A finished
run's episodes (the global step at which each ended, its return) go to <output>/<env_id>/<impl>_s<seed>.csv
and its wall time and software stack to the .json beside it. A rerun skips the runs already saved, so an
interrupted comparison loses only the runs in flight. A failed run leaves its log in <output>/<env_id>/logs/.

The analysis compares the two on the steps both trained: CleanRL floors the number of iterations and
our scripts round it up (500k CartPole steps are 499,712 steps for CleanRL and 500,224 for us). A run's
two scores are its mean episodic return over the episodes ending in that common range, and over those
ending in its last tenth; Welch's t-test compares each across seeds. It writes <output>/<env_id>.png
(learning curves, mean and 95% CI over seeds) and <output>/<env_id>_summary.md.
"""

import functools
import hashlib
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from datetime import datetime, timezone
from operator import itemgetter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import tyro
from scipy import stats
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

ROOT = Path(__file__).resolve().parent.parent
from paper_study.paper import action_kind
from paper_study.stats import ALPHA, welch
from pgg_utils.files import write_atomic
from pgg_utils.processes import die_with_parent

IMPLS = ("ours", "cleanrl")
BINS = 50  # learning-curve bins over the common step range
SCORES = ("mean return over the common range", "mean return over its last tenth")
# CleanRL's published end-of-training returns (docs.cleanrl.dev, ppo.py and ppo_continuous_action.py):
# context for the summary, from other machines, seeds and library versions.
PUBLISHED = {
    "CartPole-v1": (490.04, 6.12),
    "Acrobot-v1": (-86.36, 1.32),
    "Hopper-v4": (2382.86, 271.74),
    "HalfCheetah-v4": (1442.64, 46.03),
    "Walker2d-v4": (2287.95, 571.78),
    "InvertedPendulum-v4": (963.09, 22.20),
    "Humanoid-v4": (716.11, 49.08),
    "Pusher-v4": (-40.38, 7.15),
}
# What a training script needs, imported by each implementation's interpreter before any run: a broken
# environment fails here, once, and the versions it reports are the ones that trained.
STACK_QUERY = """
import importlib.metadata, json, platform
import gymnasium, numpy, tensorboard, torch, tyro
try:
    mujoco = importlib.metadata.version("mujoco")
except importlib.metadata.PackageNotFoundError:
    mujoco = None
print(json.dumps({"python": platform.python_version(), "torch": torch.__version__, "numpy": numpy.__version__,
                  "gymnasium": gymnasium.__version__, "mujoco": mujoco}))
"""
# One thread per run, as in the README's measurements; unbuffered, so that a failed run's log is complete.
CHILD_ENV = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONUNBUFFERED="1")
# The children in flight, and the flag that stops new ones once the comparison is interrupted.
RUNNING: set[subprocess.Popen] = set()
STOPPING = threading.Event()
LAUNCH = threading.Lock()


@dataclass
class Args:
    env_id: str = "CartPole-v1"
    """a Discrete env runs ppo_pgg_discrete.py against CleanRL's ppo.py, a Box one ppo_pgg_continuous.py against ppo_continuous_action.py"""
    seeds: int = 8
    """seeds 1..N, the same for both implementations"""
    total_timesteps: int | None = None
    """--total-timesteps of every run (default: the scripts' own, 500k discrete and 1M continuous; with --analyse-only, that of the saved runs)"""
    cleanrl_dir: str | None = None
    """the folder holding CleanRL's ppo.py and ppo_continuous_action.py (cleanrl/ in its repository)"""
    cleanrl_python: str | None = None
    """the interpreter of CleanRL's own environment (gymnasium 0.29; README, Performance)"""
    workers: int = os.cpu_count() or 1
    """runs at a time, one thread each"""
    output: str = str(ROOT / "benchmarks" / "results" / "cleanrl_parity")
    """<output>/<env_id>/ holds the saved runs; <output>/<env_id>.png and <env_id>_summary.md the analysis"""
    analyse_only: bool = False
    """analyse the runs saved in <output>/<env_id>/ and train none"""


class CompareError(Exception):
    """A bad argument, unusable saved runs or a failed run: one line on stderr, exit 2."""


@dataclass(frozen=True)
class Run:
    impl: str
    seed: int
    folder: Path  # <output>/<env_id>

    @property
    def name(self) -> str:
        return f"{self.impl}_s{self.seed}"

    @property
    def csv(self) -> Path:
        return self.folder / f"{self.name}.csv"

    @property
    def meta(self) -> Path:
        return self.folder / f"{self.name}.json"

    @property
    def log(self) -> Path:
        return self.folder / "logs" / f"{self.name}.log"


@dataclass(frozen=True)
class Plan:
    """What one comparison trains, checked before any run starts."""

    env_id: str
    total_timesteps: int
    folder: Path
    scripts: dict[str, tuple[str, Path]]  # impl -> (interpreter, training script)
    stacks: dict[str, dict]  # impl -> versions reported by its interpreter


def is_discrete(env_id: str) -> bool:
    try:
        return action_kind(env_id) == "discrete"
    except ValueError as e:  # an unknown id, or an action space the scripts do not take
        raise CompareError(str(e)) from None


def saved_total(folder: Path) -> int | None:
    """The --total-timesteps of the runs saved in `folder` (None if there are none)."""
    totals = {json.loads(path.read_text())["total_timesteps"] for path in folder.glob("*_s*.json")}
    if len(totals) > 1:
        raise CompareError(f"{folder} holds runs of several lengths ({sorted(totals)}): keep one per folder")
    return totals.pop() if totals else None


def stack_of(python: str, what: str) -> dict:
    out = subprocess.run([python, "-c", STACK_QUERY], capture_output=True, text=True, env=CHILD_ENV)
    if out.returncode:
        reason = (out.stderr.strip().splitlines() or [f"exit {out.returncode}"])[-1]
        raise CompareError(f"{what} {python} cannot run a training script: {reason}")
    return json.loads(out.stdout)


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def make_plan(args: Args, folder: Path, total_saved: int | None) -> Plan:
    discrete = is_discrete(args.env_id)
    total = args.total_timesteps or (500_000 if discrete else 1_000_000)
    if total_saved not in (None, total):
        raise CompareError(
            f"{folder} holds runs of {total_saved:,} steps, not {total:,}: pass another --output or remove them"
        )
    if not (args.cleanrl_dir and args.cleanrl_python):
        raise CompareError("training needs --cleanrl-dir and --cleanrl-python (or pass --analyse-only)")
    cleanrl_python = shutil.which(os.path.expanduser(args.cleanrl_python))
    if cleanrl_python is None:
        raise CompareError(f"--cleanrl-python {args.cleanrl_python} is not an executable")
    # Absolute paths, not resolved ones: the runs start in temporary folders, and a venv's python is a link.
    cleanrl_script = Path(args.cleanrl_dir).expanduser().absolute() / (
        "ppo.py" if discrete else "ppo_continuous_action.py"
    )
    if not cleanrl_script.is_file():
        raise CompareError(f"--cleanrl-dir {args.cleanrl_dir} has no {cleanrl_script.name}")
    scripts = {
        "ours": (sys.executable, ROOT / ("ppo_pgg_discrete.py" if discrete else "ppo_pgg_continuous.py")),
        "cleanrl": (os.path.abspath(cleanrl_python), cleanrl_script),
    }
    whats = {"ours": "this interpreter", "cleanrl": "--cleanrl-python"}
    stacks = {impl: stack_of(python, whats[impl]) for impl, (python, _) in scripts.items()}
    return Plan(args.env_id, total, folder, scripts, stacks)


def in_child(parent_pid: int) -> None:
    """Runs in each child between fork and exec. The lowest priority keeps the comparison from slowing
    other work on the machine (it slows both implementations alike), and the parent-death signal kills
    the child if the harness dies, so that no orphan trains on. It fires when the thread that started
    the child ends, which is why a run is started and waited for in the same thread."""
    os.nice(19)
    die_with_parent(parent_pid)


def read_events(run_dir: Path) -> tuple[np.ndarray, int, float] | None:
    """Each episode's (global step at its end, return), the number of steps trained, and the SPS the
    script reported at its end (timed from its own start, so without the interpreter's start-up).
    None if the run logged no episode or no iteration."""
    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})  # 0: every scalar, not a sample
    events.Reload()
    if not {"charts/episodic_return", "charts/SPS"} <= set(events.Tags()["scalars"]):
        return None
    episodes = np.array([(e.step, e.value) for e in events.Scalars("charts/episodic_return")]).reshape(-1, 2)
    # Both implementations log charts/SPS at the end of every iteration.
    last = events.Scalars("charts/SPS")[-1]
    return episodes, last.step, last.value


def train_one(plan: Plan, run: Run, scratch: Path) -> str | None:
    """Trains one run in its own temporary folder and saves its episodes; returns a progress line, or
    None if the comparison was interrupted. Raises CompareError naming the kept log if the run fails."""
    python, script = plan.scripts[run.impl]
    workdir = Path(tempfile.mkdtemp(prefix=f"{run.name}_", dir=scratch))
    command = [python, str(script), "--env-id", plan.env_id, "--seed", str(run.seed),
               "--total-timesteps", str(plan.total_timesteps)]  # fmt: skip
    if run.impl == "ours":
        # One checkpoint, at the end, which the temporary folder takes away with it.
        command += ["--guidance", "1", "--cond-dropout", "0", "--checkpoint-interval", str(plan.total_timesteps),
                    "--output-dir", str(workdir), "--run-name", run.name]  # fmt: skip
    else:
        command.append("--no-cuda")  # CleanRL writes runs/<name>/ into its working directory
    # Hashed before the run: a script edited while it trains is recorded as it was when it started.
    script_sha256 = hashlib.sha256(script.read_bytes()).hexdigest()
    log = workdir / "train.log"
    start = time.monotonic()
    with open(log, "w") as out:
        with LAUNCH:  # no child starts after an interrupt has killed those running
            if STOPPING.is_set():
                return None
            child = subprocess.Popen(command, cwd=workdir, stdout=out, stderr=subprocess.STDOUT, env=CHILD_ENV,
                                     preexec_fn=functools.partial(in_child, os.getpid()), start_new_session=True)  # fmt: skip
            RUNNING.add(child)
        code = child.wait()
        RUNNING.discard(child)
    seconds = time.monotonic() - start
    if STOPPING.is_set():
        return None
    events = list(workdir.rglob("events.out.tfevents.*"))
    found = read_events(events[0].parent) if code == 0 and len(events) == 1 else None
    if found is None:
        run.log.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(log, run.log)
        raise CompareError(f"{plan.env_id} {run.name} failed (exit {code}); log: {run.log}")
    episodes, steps, sps = found
    meta = {
        "env_id": plan.env_id, "impl": run.impl, "seed": run.seed, "total_timesteps": plan.total_timesteps,
        "steps_trained": steps, "episodes": len(episodes), "wall_time_s": round(seconds, 1), "sps_reported": sps,
        "script": script.name, "script_sha256": script_sha256,
        "arguments": [a.replace(str(workdir), "<tmp>") for a in command[2:]],
        "stack": plan.stacks[run.impl], "cpu": cpu_model(),
        "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }  # fmt: skip
    run.folder.mkdir(parents=True, exist_ok=True)
    write_atomic(run.meta, json.dumps(meta, indent=2) + "\n")
    # The CSV last: its presence is what marks the run done. 9 digits: float32 round-trips.
    write_atomic(run.csv, "step,return\n" + "".join(f"{int(s)},{r:.9g}\n" for s, r in episodes))
    run.log.unlink(missing_ok=True)  # a failed earlier attempt's log
    shutil.rmtree(workdir)
    return (
        f"{run.name}: {steps:,} steps in {seconds:.0f} s (the script reports {sps:,.0f} SPS), "
        f"{len(episodes)} episodes, mean return {episodes[:, 1].mean():.1f}"
    )


def train_missing(plan: Plan, seeds: int, workers: int) -> None:
    """Trains the runs not saved yet. After a failure no new run starts, those in flight finish and are
    saved, then the failure is raised. On Ctrl-C the children are killed at once."""
    runs = [Run(impl, seed, plan.folder) for seed in range(1, seeds + 1) for impl in IMPLS]
    todo = [run for run in runs if not run.csv.exists()]
    print(f"{plan.env_id}: {len(runs)} runs, {len(runs) - len(todo)} already saved in {plan.folder}",
          file=sys.stderr, flush=True)  # fmt: skip
    failures = []
    with tempfile.TemporaryDirectory(prefix="compare_cleanrl_") as scratch, ThreadPoolExecutor(workers) as pool:
        futures = [pool.submit(train_one, plan, run, Path(scratch)) for run in todo]
        try:
            for done, future in enumerate(as_completed(futures), 1):
                if future.cancelled():
                    continue
                try:
                    print(f"[{done}/{len(todo)}] {future.result()}", file=sys.stderr, flush=True)
                except CompareError as e:
                    failures.append(str(e))
                    for other in futures:
                        other.cancel()
        except KeyboardInterrupt:
            with LAUNCH:
                STOPPING.set()
                for child in list(RUNNING):
                    child.kill()
            for other in futures:
                other.cancel()
            raise
    if failures:
        raise CompareError("; ".join(failures))


@dataclass
class Saved:
    seed: int
    episodes: np.ndarray  # (episodes, 2): global step at the episode's end, return
    meta: dict


def load_saved(folder: Path) -> dict[str, list[Saved]]:
    saved = {impl: [] for impl in IMPLS}
    for csv in folder.glob("*_s*.csv"):
        impl, seed = csv.stem.rsplit("_s", 1)
        episodes = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2).reshape(-1, 2)
        saved[impl].append(Saved(int(seed), episodes, json.loads(csv.with_suffix(".json").read_text())))
    for runs in saved.values():
        runs.sort(key=lambda run: run.seed)
    return saved


def run_scores(episodes: np.ndarray, end: int) -> tuple[float, float]:
    """Mean return of the episodes ending in (0, end], and of those ending in its last tenth."""
    steps, returns = episodes.T
    whole = returns[steps <= end]
    last = returns[(steps > 0.9 * end) & (steps <= end)]
    return (whole.mean() if len(whole) else np.nan), (last.mean() if len(last) else np.nan)


def binned_curve(episodes: np.ndarray, end: int, bins: int = BINS) -> np.ndarray:
    """Mean return of the episodes ending in each of `bins` equal bins (e_i, e_i+1] of (0, end]. An empty
    bin carries the previous bin's value: a long episode leaves no gap in the curve. NaN before the first."""
    steps, returns = episodes[(episodes[:, 0] > 0) & (episodes[:, 0] <= end)].T
    index = np.searchsorted(np.linspace(0, end, bins + 1), steps, side="left") - 1
    sums = np.bincount(index, returns, minlength=bins)
    counts = np.bincount(index, minlength=bins)
    curve, value = np.full(bins, np.nan), np.nan
    for i in range(bins):
        if counts[i]:
            value = sums[i] / counts[i]
        curve[i] = value
    return curve


def mean_ci(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean over axis 0 and the half-width of its 95% t interval, over the non-NaN values (NaN with one)."""
    n = np.sum(~np.isnan(values), axis=0)
    with warnings.catch_warnings():  # a column with fewer than two values is NaN, as it should be
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(values, axis=0)
        half = stats.t.ppf(0.975, n - 1) * np.nanstd(values, axis=0, ddof=1) / np.sqrt(n)
    return mean, half


def welch_p(ours: np.ndarray, cleanrl: np.ndarray) -> float:
    """Welch's t-test p-value over seeds (paper_study.stats.welch: 1 or 0 where neither side varies, e.g.
    every CartPole seed at 500 at the end); NaN with fewer than two seeds on a side."""
    if min(len(ours), len(cleanrl)) < 2:
        return np.nan
    return welch(ours.mean(), ours.std(ddof=1), len(ours), cleanrl.mean(), cleanrl.std(ddof=1), len(cleanrl))[2]


def verdict(scores: dict[str, np.ndarray], p_values: list[float]) -> str:
    if any(np.isnan(p_values)):
        return "not tested (fewer than two seeds on a side, or a run without episodes in the range)"
    differ = [
        f"{name} (ours {'higher' if scores['ours'][:, i].mean() > scores['cleanrl'][:, i].mean() else 'lower'}, "
        f"p = {p:.3g})"
        for i, (name, p) in enumerate(zip(SCORES, p_values))
        if p < ALPHA
    ]
    if differ:
        return f"significant difference at α={ALPHA} in " + "; ".join(differ)
    return f"no significant difference at α={ALPHA}"


@dataclass
class Analysis:
    env_id: str
    total_timesteps: int
    trained: dict[str, int]  # impl -> steps its runs trained
    end: int  # the common step range is (0, end]
    saved: dict[str, list[Saved]]
    scores: dict[str, np.ndarray]  # impl -> (seeds, 2), the two scores of each run
    p_values: list[float]  # Welch's, one per score
    labels: dict[str, str]

    @property
    def seeds_text(self) -> str:
        n = [len(self.saved[impl]) for impl in IMPLS]
        return f"{n[0]} seed{'s' * (n[0] > 1)}" if n[0] == n[1] else f"{n[0]} / {n[1]} seeds"

    def per_impl(self, what) -> list[str]:
        """The distinct values of what(meta) over each implementation's runs, one cell each."""
        return ["; ".join(dict.fromkeys(str(what(run.meta)) for run in self.saved[impl])) for impl in IMPLS]

    def mean_per_impl(self, what) -> list[float]:
        return [float(np.mean([what(run.meta) for run in self.saved[impl]])) for impl in IMPLS]


def compute(env_id: str, folder: Path) -> Analysis:
    saved = load_saved(folder)
    missing = [impl for impl in IMPLS if not saved[impl]]
    if missing:
        raise CompareError(f"no saved {' or '.join(missing)} runs in {folder}")
    # Like with like: only the seeds that both implementations have finished (a comparison still running).
    both = set.intersection(*({run.seed for run in runs} for runs in saved.values()))
    if not both:
        raise CompareError(f"no seed in {folder} has finished runs of both implementations yet")
    saved = {impl: [run for run in runs if run.seed in both] for impl, runs in saved.items()}
    trained = {impl: min(run.meta["steps_trained"] for run in runs) for impl, runs in saved.items()}
    end = min(trained.values())
    scores = {impl: np.array([run_scores(run.episodes, end) for run in runs]) for impl, runs in saved.items()}
    p_values = [welch_p(scores["ours"][:, i], scores["cleanrl"][:, i]) for i in range(len(SCORES))]
    labels = {"ours": "ours (--guidance 1)", "cleanrl": f"CleanRL {saved['cleanrl'][0].meta['script']}"}
    return Analysis(env_id, saved_total(folder), trained, end, saved, scores, p_values, labels)


def plot(a: Analysis, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4.5))
    x = (np.arange(BINS) + 0.5) * a.end / BINS
    for impl, color in zip(IMPLS, ("C0", "C1")):
        mean, half = mean_ci(np.array([binned_curve(run.episodes, a.end) for run in a.saved[impl]]))
        ax.plot(x, mean, color=color, label=a.labels[impl])
        ax.fill_between(x, mean - half, mean + half, color=color, alpha=0.2, linewidth=0)
    ax.set(xlabel="environment steps", ylabel="episodic return (mean over seeds, 95% CI)",
           title=f"{a.env_id}: {a.seeds_text}, {a.end:,} steps")  # fmt: skip
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def summary(a: Analysis, figure: str) -> str:
    def mean_sd(values: np.ndarray) -> str:
        return f"{values.mean():.1f} ± {values.std(ddof=1):.1f}" if len(values) > 1 else f"{values.mean():.1f}"

    def row(*cells) -> str:
        return "| " + " | ".join(cells) + " |"

    lines = [
        f"# Our PPO against CleanRL's: {a.env_id}",
        "",
        (
            f"{a.seeds_text}, `--total-timesteps {a.total_timesteps}`. CleanRL trained {a.trained['cleanrl']:,} "
            f"steps, ours {a.trained['ours']:,} (CleanRL floors the number of iterations, we round it up), so both "
            f"are scored on the episodes ending in the first {a.end:,} steps, and on those ending in the last "
            f"tenth of them ({0.9 * a.end:,.0f} to {a.end:,}). Mean ± sd over seeds; Welch's t-test."
        ),
        "",
        row("score", a.labels["ours"], a.labels["cleanrl"], "Welch p"),
        "|---|---|---|---|",
    ]
    for i, name in enumerate(SCORES):
        p = "n/a" if np.isnan(a.p_values[i]) else f"{a.p_values[i]:.3g}"
        lines.append(row(name, mean_sd(a.scores["ours"][:, i]), mean_sd(a.scores["cleanrl"][:, i]), p))
    lines += ["", f"**Verdict: {verdict(a.scores, a.p_values)}.**", ""]
    if a.env_id in PUBLISHED:
        mean, sd = PUBLISHED[a.env_id]
        lines += [
            (
                f"For context, CleanRL's published end-of-training return on {a.env_id} is {mean:.2f} ± {sd:.2f} "
                "(its documentation: other machines, seeds and library versions)."
            ),
            "",
        ]
    lines += [
        row("seed", "ours, whole range", "ours, last tenth", "CleanRL, whole range", "CleanRL, last tenth"),
        "|---|---|---|---|---|",
    ]
    by_seed = {impl: {run.seed: a.scores[impl][k] for k, run in enumerate(a.saved[impl])} for impl in IMPLS}
    for seed in sorted(set(by_seed["ours"]) | set(by_seed["cleanrl"])):
        lines.append(row(str(seed), *(f"{v:.1f}" for impl in IMPLS for v in by_seed[impl].get(seed, (np.nan,) * 2))))
    lines += ["", row("", a.labels["ours"], a.labels["cleanrl"]), "|---|---|---|"]
    for name in ("python", "torch", "numpy", "gymnasium", "mujoco"):
        lines.append(row(name, *a.per_impl(lambda meta, name=name: meta["stack"][name])))
    lines += [
        row("training script, sha256", *a.per_impl(lambda meta: f"{meta['script']}, {meta['script_sha256'][:12]}")),
        row("CPU", *a.per_impl(itemgetter("cpu"))),
        row("wall time per run, mean", *(f"{t:,.0f} s" for t in a.mean_per_impl(itemgetter("wall_time_s")))),
        row(
            "steps per second, start-up included, mean",
            *(f"{v:,.0f}" for v in a.mean_per_impl(lambda meta: meta["steps_trained"] / meta["wall_time_s"])),
        ),
        row(
            "SPS the script reports at its end, mean",
            *(f"{v:,.0f}" for v in a.mean_per_impl(itemgetter("sps_reported"))),
        ),
        "",
        f"One thread and the lowest CPU priority per run. Learning curves: [{figure}]({figure}).",
    ]
    return "\n".join(lines) + "\n"


def analyse(env_id: str, output: Path) -> str:
    """Writes <output>/<env_id>.png and <env_id>_summary.md from the saved runs; returns the summary."""
    a = compute(env_id, output / env_id)
    plot(a, output / f"{env_id}.png")
    text = summary(a, f"{env_id}.png")
    write_atomic(output / f"{env_id}_summary.md", text)
    return text


def main() -> None:
    args = tyro.cli(Args)
    output = Path(args.output)
    folder = output / args.env_id
    try:
        total_saved = saved_total(folder)
        if args.analyse_only:
            if args.total_timesteps and total_saved and args.total_timesteps != total_saved:
                raise CompareError(f"{folder} holds runs of {total_saved:,} steps, not {args.total_timesteps:,}")
        else:
            plan = make_plan(args, folder, total_saved)
            train_missing(plan, args.seeds, args.workers)
        summary = analyse(args.env_id, output)
    except CompareError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print(f"interrupted: {len(list(folder.glob('*_s*.csv')))} finished runs kept in {folder}", file=sys.stderr)
        sys.exit(130)
    print(summary, end="")
    print(f"wrote {output / args.env_id}.png and {output / args.env_id}_summary.md")


if __name__ == "__main__":
    main()
