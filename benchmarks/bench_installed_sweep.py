"""An installed copy's sweep against the clone's, on the same checkpoints: wall time of the whole command, in turns.

    python -m benchmarks.bench_installed_sweep                 # the working tree
    python -m benchmarks.bench_installed_sweep --revision b37a440 --rounds 1

The revision's files (results/ and benchmarks/ left out) are exported into a scratch folder: that export is the
clone, run as `python <clone>/eval_gamma_sweep.py`. It is also installed, non-editable (`pip install --no-deps
--target`), into a fresh virtual environment beside every package of this one (each linked into the new
site-packages, the same torch), and run as `python -m eval_gamma_sweep` from a folder outside both. Each round
runs both, in alternating order, into fresh output folders, and the installed/clone ratio is taken round by round
(these machines drift), after one untimed run of each. The two must write the same episodes and the same cell names (the cells' keys: the
installed copy keys its cells by the same files as the clone). Prints each round, the medians and the ratio.
"""

import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from statistics import median

import tyro

ROOT = Path(__file__).resolve().parent.parent
WORKTREE = "worktree"
LEFT_OUT = ("results/", "benchmarks/")  # the committed results and their tools: no part of the package
PROJECT_FILES = ("pgg", "__editable__")  # this environment's own install of the project, left out of the new one
CHILD_ENV = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"} | {"OMP_NUM_THREADS": "1"}


@dataclass
class Args:
    revision: str = WORKTREE
    """the revision to install and run (a commit, tag or branch); `worktree`: the working tree as it is"""
    checkpoints: tuple[str, ...] = (
        "results/discrete/agents/CartPole-v1__pgg_g1.1__s1/checkpoints/step_000500000.pt",
        "results/continuous/agents/Hopper-v4__pgg_g1.1__s1/checkpoints/step_001000000.pt",
    )
    """checkpoint files (relative to the repository, or absolute)"""
    gammas: tuple[float, ...] = (1.0, 2.0, 5.0)
    """the sweep's γ values"""
    episodes: int = 4
    """episodes per cell"""
    rounds: int = 3
    """(installed, clone) pairs"""
    keep: str | None = None
    """keep the scratch folder (the export, the environment, the outputs) here; default: a temporary one, removed"""


def export(revision: str, destination: Path) -> None:
    """The revision's files, but results/ and benchmarks/ (the working tree's: untracked files git does not ignore
    included)."""
    destination.mkdir(parents=True)
    if revision == WORKTREE:
        listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                                check=True, capture_output=True).stdout.decode().split("\0")  # fmt: skip
        for name in filter(None, listed):
            if not name.startswith(LEFT_OUT) and (ROOT / name).is_file():
                (destination / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(ROOT / name, destination / name)
        return
    names = subprocess.run(["git", "ls-tree", "--name-only", revision], cwd=ROOT, check=True, capture_output=True,
                           text=True).stdout.split()  # fmt: skip
    kept = [name for name in names if f"{name}/" not in LEFT_OUT]
    archive = subprocess.run(["git", "archive", revision, *kept], cwd=ROOT, check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(destination)], input=archive, check=True)


def installed_environment(source: Path, venv: Path) -> Path:
    """A fresh virtual environment holding this environment's packages (linked) and `source` installed, not
    editable; returns its python."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    site_packages = Path(sysconfig.get_path("purelib", vars={"base": str(venv), "platbase": str(venv)}))
    for entry in Path(sysconfig.get_path("purelib")).iterdir():
        if not entry.name.startswith(PROJECT_FILES) and entry.name.split(".")[0] not in project_modules(source):
            (site_packages / entry.name).symlink_to(entry)
    pip = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index"]
    subprocess.run([*pip, "--target", str(site_packages), str(source)], check=True, capture_output=True)
    return venv / "bin" / "python"


def project_modules(source: Path) -> set[str]:
    import tomllib

    setuptools = tomllib.loads((source / "pyproject.toml").read_text())["tool"]["setuptools"]
    return {*setuptools["py-modules"], *setuptools["packages"]}


def timed(command: list[str], cwd: Path) -> float:
    start = time.perf_counter()
    done = subprocess.run(command, cwd=cwd, env=CHILD_ENV, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"error: `{' '.join(command)}` exited {done.returncode}: {done.stderr.strip()[-2000:]}")
    return seconds


def main() -> None:
    args = tyro.cli(Args)
    checkpoints = [str((ROOT / path).resolve()) for path in args.checkpoints]
    scratch = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_installed_sweep_"))
    try:
        export(args.revision, scratch / "clone")
        python = installed_environment(scratch / "clone", scratch / "venv")
        elsewhere = scratch / "elsewhere"
        elsewhere.mkdir()
        settings = [*checkpoints, "--gammas", *map(str, args.gammas), "--episodes", str(args.episodes)]
        commands = {"installed": [str(python), "-m", "eval_gamma_sweep", *settings],
                    "clone": [sys.executable, str(scratch / "clone" / "eval_gamma_sweep.py"), *settings]}  # fmt: skip
        for name, command in commands.items():  # untimed: each writes its bytecode caches, the disk warms
            timed([*command, "--output", f"{name}_warmup"], elsewhere)
        seconds, ratios = {"installed": [], "clone": []}, []
        for i in range(args.rounds):
            order = ("installed", "clone") if i % 2 == 0 else ("clone", "installed")
            wall = {name: timed([*commands[name], "--output", f"{name}_{i}"], elsewhere) for name in order}
            for name, value in wall.items():
                seconds[name].append(value)
            ratios.append(wall["installed"] / wall["clone"])
            print(f"round {i + 1}: installed {wall['installed']:.1f} s, clone {wall['clone']:.1f} s", flush=True)
        outputs = {name: elsewhere / f"{name}_0" for name in commands}
        same_episodes = len({(path / "episodes.csv").read_bytes() for path in outputs.values()}) == 1
        same_cells = len({tuple(sorted(p.name for p in (path / "cells").iterdir())) for path in outputs.values()}) == 1
        cells = len(list((outputs["clone"] / "cells").iterdir()))
        print(f"{args.revision}, {cells} cells ({len(checkpoints)} checkpoints x {len(args.gammas)} γ, {args.episodes} "
              f"episodes each): installed {median(seconds['installed']):.1f} s, clone {median(seconds['clone']):.1f} s "
              f"(medians); installed/clone {median(ratios):.2f} (range {min(ratios):.2f} to {max(ratios):.2f}, "
              f"{args.rounds} rounds); same episodes: {same_episodes}, same cell names: {same_cells}")  # fmt: skip
    finally:
        if not args.keep:
            shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
