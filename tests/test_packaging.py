"""The project as a package and as a citation: a non-editable `pip install .` works from any folder and
leaves nothing git would show in the source tree; CITATION.cff holds to the Citation File Format 1.2.0
and cites the paper as the README does."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

NOT_PACKAGED = ("results/", "benchmarks/")  # the committed results and their tools: large, and no part of the wheel


def tracked_files() -> list[str]:
    if shutil.which("git") is None:
        pytest.skip("git is not installed: the packaging test copies the repository's tracked files")
    proc = subprocess.run(["git", "-C", str(ROOT), "ls-files"], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip("not a git checkout: the packaging test copies the repository's tracked files")
    return [path for path in proc.stdout.splitlines() if not path.startswith(NOT_PACKAGED)]


def build_backend_here() -> None:
    """`pip install --no-build-isolation` builds with this environment's setuptools, off the network;
    setuptools 70 is the first to build a wheel without the `wheel` package (the [dev] extra asks for it)."""
    try:
        from importlib.metadata import version

        major = int(version("setuptools").split(".")[0])
    except Exception:
        major = 0
    if major < 70:
        pytest.skip("needs setuptools>=70 (pip install -e '.[dev]') to build the wheel without the network")


def test_a_non_editable_install_finds_the_papers_data_from_any_folder(tmp_path):
    """`pip install .` (not -e) of a copy of the repository, then plot_results --compare-paper run as an
    installed module from a folder outside any source tree: it reads the paper's numbers from the
    installed package and tables the committed discrete sweep exactly as committed. Before the paper's
    CSVs were package data it stopped with `paper_study/data/paper_results.csv: No such file`; before
    build/ was ignored the install left it untracked in the tree."""
    build_backend_here()
    source, site, elsewhere = tmp_path / "source", tmp_path / "site", tmp_path / "elsewhere"
    for path in tracked_files():
        (source / path).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / path, source / path)
    git = ["git", "-c", "core.hooksPath=/dev/null", "-C", str(source)]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    pip = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index"]
    proc = subprocess.run([*pip, "--target", str(site), str(source)], capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr

    left = subprocess.run([*git, "status", "--porcelain", "--untracked-files=all"], capture_output=True, text=True)
    assert [line for line in left.stdout.splitlines() if line.startswith("??")] == []  # build/, pgg.egg-info/
    for name in ("paper_results.csv", "paper_dropout_figure.csv"):
        installed = site / "paper_study" / "data" / name
        assert installed.read_bytes() == (ROOT / "paper_study" / "data" / name).read_bytes()

    elsewhere.mkdir()
    env = {**os.environ, "PYTHONPATH": str(site), "OMP_NUM_THREADS": "1"}
    locate = "import plot_results, paper_study.agreement as a; print(plot_results.__file__); print(a.PAPER_DATA)"
    where = subprocess.run([sys.executable, "-c", locate], cwd=elsewhere, env=env, capture_output=True, text=True)
    assert where.returncode == 0, where.stderr
    assert all(Path(line).is_relative_to(site) for line in where.stdout.split()), where.stdout  # not the source tree
    out = tmp_path / "tables"
    plotted = subprocess.run([sys.executable, "-m", "plot_results", str(ROOT / "results" / "discrete"),
                              "--compare-paper", "--output", str(out)],
                             cwd=elsewhere, env=env, capture_output=True, text=True, timeout=300)  # fmt: skip
    assert plotted.returncode == 0, plotted.stderr
    for name in ("compare_paper.csv", "compare_paper_tasks.csv"):
        assert (out / name).read_bytes() == (ROOT / "results" / "discrete" / name).read_bytes(), name


def test_the_in_tree_build_folder_is_ignored():
    """`pip install .` in a clone writes build/ (setuptools' staging of the wheel) into it: ignored, never
    shown by `git status` as the user's own untracked work."""
    tracked_files()
    proc = subprocess.run(["git", "-C", str(ROOT), "check-ignore", "-q", "build/lib/plot_results.py"])
    assert proc.returncode == 0
