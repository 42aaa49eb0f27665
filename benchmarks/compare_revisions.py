"""Runs a fixed set of tiny configurations at two revisions on this machine and compares them bit for bit.

    python -m benchmarks.compare_revisions 42843cd          # that commit against the working tree
    python -m benchmarks.compare_revisions 42843cd HEAD     # two commits

A refactor that should change no number is proven by it. Each revision is exported (`git archive`,
or the working tree as it is) into a scratch folder and runs, with this Python and one thread:
- training, to the final weights, optimizer and resume state: CartPole-v1 γ_train 1.1, Acrobot-v1
  dropout 0.1, Hopper-v4 γ_train 1.1, and a Humanoid-v4 run stopped after its first checkpoint and
  resumed (`--resume`) to the end;
- the sweep of one discrete and one continuous checkpoint (episodes.csv, summary.csv);
- the quick preset at fewer steps and episodes (`reproduce.py --preset quick ...`): its tables;
- the study's own episode tools on committed agents, each a subset of its committed output: goal
  distances (beyond/goal_distance.py), command tracking (beyond/command_tracking.py) and
  behaviour-cloned nulls (pgg_utils/bc_null.py), whose fitted checkpoints record the code that fitted them
  (`null_fit.code`: its sha1s differ wherever that code does).

Checkpoints are compared field by field (tensors with torch.equal, dtypes and shapes included), CSVs
row by row on the columns both have, tables and reports byte for byte. A field or column that only
the newer revision has (new metadata) is listed, not counted as a difference; a value that differs is.
Exit status 0 when everything both revisions have is identical, 1 otherwise.

With `--speed-pairs N` it then times training instead: CartPole-v1 and Hopper-v4 at γ_train 1.1, each
revision's script as a whole process, in turns (base, head, head, base, ...) N times, and prints the
median and range of the head/base wall-time ratio pair by pair (these machines drift; a ratio of two
runs made seconds apart is what holds).
"""

import csv
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from statistics import median

import torch
import tyro

ROOT = Path(__file__).resolve().parent.parent
WORKTREE = "worktree"
CHILD_ENV = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONHASHSEED="0")
# Short runs of the four training configurations; the Humanoid one is cut after its first checkpoint
# and resumed, to prove resume unchanged too.
TINY = ["--total-timesteps", "4096", "--checkpoint-interval", "2048"]
TRAINING = {
    "cartpole_g1.1": ["ppo_pgg_discrete.py", "--env-id", "CartPole-v1", "--guidance", "1.1", *TINY],
    "acrobot_drop0.1": ["ppo_pgg_discrete.py", "--env-id", "Acrobot-v1", "--cond-dropout", "0.1", *TINY],
    "hopper_g1.1": ["ppo_pgg_continuous.py", "--env-id", "Hopper-v4", "--guidance", "1.1", *TINY],
    "humanoid_resumed": ["ppo_pgg_continuous.py", "--env-id", "Humanoid-v4", "--guidance", "1.1", "--num-steps", "1024",
                         *TINY],
}  # fmt: skip
SWEEPS = {
    "sweep_discrete": ("cartpole_g1.1", ["--gammas", "1", "2", "5", "--episodes", "6"]),
    "sweep_continuous": ("hopper_g1.1", ["--gammas", "1", "1.1", "1.5", "--episodes", "4"]),
}
QUICK = ["reproduce.py", "--preset", "quick", "--total-timesteps", "8192", "--checkpoint-interval", "4096",
         "--episodes", "4", "--workers", "1"]  # fmt: skip
AGENTS = "results/beyond/{}/agents/{}"
BEYOND = {
    "goal_distance": ["beyond.goal_distance", AGENTS.format("Reacher-v4", "Reacher-v4__pgg_g1.1_goal__s1"),
                      "results/continuous/agents/Pusher-v4__pgg_g1.1__s1", "--steps", "1000000", "--gammas", "1", "1.3",
                      "--output", "out/goal_distance.csv"],
    "command_tracking": ["beyond.command_tracking",
                         AGENTS.format("command", "paper_study.cheetah_velocity-HalfCheetahVelocity-v0__pgg_g1.1__s1"),
                         "--steps", "1000000", "--gammas", "1.5", "--commands", "0", "2.5",
                         "--output", "out/tracking.csv"],
    "bc_null": ["pgg_utils.bc_null", "results/discrete/agents/CartPole-v1__ppo__s1",
                "results/continuous/agents/Hopper-v4__pgg_g1.1__s2", "--steps", "500000", "1000000",
                "--output", "out/bc_null"],
}  # fmt: skip
TEXT_OUTPUTS = (".md", ".tex", ".csv")
SPEED = {
    "CartPole-v1 γ_train 1.1, 40,960 steps": ["ppo_pgg_discrete.py", "--env-id", "CartPole-v1", "--guidance", "1.1",
                                               "--total-timesteps", "40960", "--checkpoint-interval", "40960"],
    "Hopper-v4 γ_train 1.1, 16,384 steps": ["ppo_pgg_continuous.py", "--env-id", "Hopper-v4", "--guidance", "1.1",
                                             "--total-timesteps", "16384", "--checkpoint-interval", "16384"],
}  # fmt: skip
# mjData arrays MuJoCo fills only on demand: between two runs of one revision they hold whatever the
# arena held (`compare_revisions.py HEAD HEAD` differs there and nowhere else), so only their shapes count.
MUJOCO_SCRATCH = (".mujoco.efc_AR", ".mujoco.efc_JT")


@dataclass
class Args:
    base: tyro.conf.Positional[str]
    """the older revision (a commit, tag or branch)"""
    head: tyro.conf.Positional[str] = WORKTREE
    """the newer revision; `worktree`: the working tree as it is, uncommitted changes included"""
    keep: str | None = None
    """keep both revisions' outputs in this folder (default: a temporary one, removed)"""
    skip_quick: bool = False
    """leave out the quick preset (the slowest part, about a minute a revision)"""
    skip_beyond: bool = False
    """leave out the paper study's episode tools on committed agents (about a minute a revision)"""
    speed_pairs: int = 0
    """time training instead of comparing outputs: this many (base, head) pairs per configuration"""


def export(revision: str, destination: Path) -> None:
    """The files of `revision` (or of the working tree, untracked ones git does not ignore included)."""
    destination.mkdir(parents=True)
    if revision == WORKTREE:
        listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                                check=True, capture_output=True).stdout.decode().split("\0")  # fmt: skip
        for name in filter(None, listed):
            source = ROOT / name
            if source.is_file():
                (destination / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(source, destination / name)
        return
    archive = subprocess.run(["git", "archive", revision], cwd=ROOT, check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(destination)], input=archive, check=True)


def run(tree: Path, command: list[str], log) -> None:
    log.write(f"$ {' '.join(command)}\n")
    log.flush()
    done = subprocess.run([sys.executable, *command], cwd=tree, env=dict(CHILD_ENV, PYTHONPATH=str(tree)),
                          stdout=log, stderr=subprocess.STDOUT)  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"{tree.name}: `{' '.join(command)}` exited {done.returncode} (log: {log.name})")


def run_all(tree: Path, skip_quick: bool, skip_beyond: bool) -> None:
    """Every configuration of this module's docstring, in `tree`, outputs under tree/out."""
    with open(tree / "compare.log", "w") as log:
        for name, command in TRAINING.items():
            run(tree, [*command, "--output-dir", "out/runs", "--run-name", name], log)
        humanoid = tree / "out/runs/humanoid_resumed/checkpoints"
        final = max(humanoid.glob("step_*.pt"))
        final.unlink()
        run(
            tree,
            [*TRAINING["humanoid_resumed"], "--output-dir", "out/runs", "--run-name", "humanoid_resumed", "--resume"],
            log,
        )
        for name, (trained, options) in SWEEPS.items():
            checkpoint = max((tree / f"out/runs/{trained}/checkpoints").glob("step_*.pt"))
            run(
                tree,
                ["eval_gamma_sweep.py", str(checkpoint.relative_to(tree)), *options, "--output", f"out/{name}"],
                log,
            )
        if not skip_quick:
            run(tree, [*QUICK, "--root", "out/quick_runs", "--results", "out/quick_results"], log)
        if not skip_beyond:
            for module, *options in BEYOND.values():
                run(tree, [*beyond_entry(tree, module), *options], log)


def beyond_entry(tree: Path, module: str) -> list[str]:
    """How `tree` runs a study module: as a module, or, in revisions before beyond/ (the study's tools lay in
    paper_study/ and ran as scripts), by its old path."""
    if (tree / (module.replace(".", "/") + ".py")).exists():
        return ["-m", module]
    return [module.replace("beyond.", "paper_study/") + ".py"]


def timed_run(tree: Path, command: list[str]) -> float:
    """Wall seconds of one training run of `tree`, as a command, one thread."""
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        run(tree, [*command, "--output-dir", out, "--run-name", "timed"], open(os.devnull, "w"))
        return time.perf_counter() - start


def compare_speed(trees: dict[str, Path], pairs: int) -> None:
    for name, command in SPEED.items():
        ratios, seconds = [], {"base": [], "head": []}
        for i in range(pairs):
            order = ("base", "head") if i % 2 == 0 else ("head", "base")
            times = {label: timed_run(trees[label], command) for label in order}
            for label, wall in times.items():
                seconds[label].append(wall)
            ratios.append(times["head"] / times["base"])
        print(f"{name}: base {median(seconds['base']):.1f} s, head {median(seconds['head']):.1f} s (medians); "
              f"head/base {median(ratios):.3f} (range {min(ratios):.3f} to {max(ratios):.3f}, {pairs} pairs)", flush=True)  # fmt: skip


def compare_values(a, b, where: str, differences: list[str], added: list[str]) -> None:
    if isinstance(a, torch.Tensor) or isinstance(b, torch.Tensor):
        same = isinstance(a, torch.Tensor) and isinstance(b, torch.Tensor) and a.dtype == b.dtype \
            and a.shape == b.shape and torch.equal(a, b)  # fmt: skip
        if (
            any(name in where for name in MUJOCO_SCRATCH)
            and isinstance(a, torch.Tensor)
            and isinstance(b, torch.Tensor)
        ):
            same = a.shape == b.shape
        if not same:
            differences.append(f"{where}: tensors differ")
    elif isinstance(a, dict) and isinstance(b, dict):
        for key in a.keys() - b.keys():
            differences.append(f"{where}.{key}: only in the base")
        for key in b.keys() - a.keys():
            added.append(f"{where}.{key}")
        for key in a.keys() & b.keys():
            compare_values(a[key], b[key], f"{where}.{key}", differences, added)
    elif isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            compare_values(x, y, f"{where}[{i}]", differences, added)
    elif a != b and not (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)):
        differences.append(f"{where}: {a!r} != {b!r}")


def compare_csv(a: Path, b: Path, where: str, differences: list[str], added: list[str]) -> None:
    with open(a, newline="") as fa, open(b, newline="") as fb:
        rows_a, rows_b = list(csv.DictReader(fa)), list(csv.DictReader(fb))
    columns_a = list(rows_a[0]) if rows_a else []
    columns_b = list(rows_b[0]) if rows_b else []
    added.extend(f"{where}: column {c}" for c in columns_b if c not in columns_a)
    differences.extend(f"{where}: column {c} only in the base" for c in columns_a if c not in columns_b)
    if len(rows_a) != len(rows_b):
        differences.append(f"{where}: {len(rows_a)} rows vs {len(rows_b)}")
        return
    common = [c for c in columns_a if c in columns_b]
    bad = [i for i, (x, y) in enumerate(zip(rows_a, rows_b)) if any(x[c] != y[c] for c in common)]
    if bad:
        differences.append(f"{where}: {len(bad)} of {len(rows_a)} rows differ (first: row {bad[0] + 1})")


def compare_trees(base: Path, head: Path) -> tuple[list[str], list[str], int]:
    """(differences, fields or columns only the head has, number of files compared)."""
    differences, added, compared = [], [], 0
    base_files = {p.relative_to(base) for p in base.rglob("*") if p.is_file()}
    head_files = {p.relative_to(head) for p in head.rglob("*") if p.is_file()}
    for name in sorted(base_files):
        kind = name.suffix
        if kind not in (".pt", *TEXT_OUTPUTS) or "cells" in name.parts:
            continue  # figures carry no numbers of their own; cells are named by their identity
        if name not in head_files:
            differences.append(f"{name}: only in the base")
            continue
        compared += 1
        if kind == ".pt":
            load = lambda p: torch.load(p, map_location="cpu", weights_only=True)
            compare_values(load(base / name), load(head / name), str(name), differences, added)
        elif kind == ".csv":
            compare_csv(base / name, head / name, str(name), differences, added)
        elif (base / name).read_bytes() != (head / name).read_bytes():
            differences.append(f"{name}: the text differs")
    return differences, sorted(set(added)), compared


def main() -> None:
    args = tyro.cli(Args)
    scratch = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="compare_revisions_"))
    trees = {"base": scratch / "base", "head": scratch / "head"}
    try:
        for label, revision in (("base", args.base), ("head", args.head)):
            if trees[label].exists():
                shutil.rmtree(trees[label])
            export(revision, trees[label])
        if args.speed_pairs:
            compare_speed(trees, args.speed_pairs)
            return
        with ThreadPoolExecutor(2) as pool:  # one process per revision at a time, one thread each
            for future in [pool.submit(run_all, tree, args.skip_quick, args.skip_beyond) for tree in trees.values()]:
                future.result()
        differences, added, compared = compare_trees(trees["base"] / "out", trees["head"] / "out")
    except (RuntimeError, subprocess.CalledProcessError) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    finally:
        if not args.keep:
            shutil.rmtree(scratch, ignore_errors=True)
    print(f"{args.base} vs {args.head}: {compared} files compared (checkpoints, CSVs, tables)")
    for name in added:
        print(f"  new in {args.head}: {name}")
    for difference in differences:
        print(f"  DIFFERS {difference}")
    print("identical" if not differences else f"{len(differences)} difference(s)")
    sys.exit(1 if differences else 0)


if __name__ == "__main__":
    main()
