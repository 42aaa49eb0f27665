"""A cell's key covers the code that runs in its episodes wherever it lies (a helper module on PYTHONPATH, a
custom task's package), and no file of an installed package or the standard library: an installed copy of the
project reads its own files and none of the thousands beside it."""

import os
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import gymnasium as gym
import pytest
from conftest import ROOT, train
from test_fault_sweep import tiny_discrete_args
from test_sweep_code import LOOP_LINE, sweep_args, sweep_copy

import eval_gamma_sweep as sweep
import ppo_pgg_discrete
from pgg_utils import cells, files


def returns(output: Path) -> list[float]:
    return [float(row["return"]) for row in files.read_csv(output / "episodes.csv")]


def test_an_edited_helper_module_on_the_path_evaluates_the_cells_again(tmp_path, monkeypatch, capsys):
    """Issue 56, silent 5: a copy of the sweep whose loop imports a helper module from a folder on PYTHONPATH;
    the helper edited, the next sweep into the same --output evaluates its cells again (it said "2 already
    done" and kept the old returns)."""
    lib = tmp_path / "lib"
    lib.mkdir()
    (lib / "observation_helpers.py").write_text("SIGN = 1\n")
    monkeypatch.syspath_prepend(str(lib))
    transformed = "import observation_helpers\n            " + LOOP_LINE.replace(
        "policy.act(obs,", "policy.act(observation_helpers.SIGN * obs,"
    )
    copy = sweep_copy(tmp_path, "helped_sweep", LOOP_LINE, transformed)
    args = sweep_args(tmp_path / "out")
    before = returns(copy.sweep(args))
    (lib / "observation_helpers.py").write_text("SIGN = -1\n")
    monkeypatch.delitem(sys.modules, "observation_helpers")  # as the next sweep's new process imports it
    capsys.readouterr()
    after = returns(copy.sweep(args))
    assert "2 cells, 0 already done" in capsys.readouterr().err and after != before


TASKS = """
import gymnasium as gym
import numpy as np
{helper_import}


class Grid(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(2, np.float32), {{}}

    def step(self, action):
        return np.full(2, float(action), np.float32), SCALE * (1.0 + float(action)), False, False, {{}}


gym.register("pk/Grid-v0", entry_point=Grid, max_episode_steps=10)
"""
HELPER_IMPORTS = {"absolute": "from pk.helpers import SCALE", "relative": "from .helpers import SCALE",
                  "namespace package": "from pk.helpers import SCALE"}  # fmt: skip


def write_task_package(root: Path, style: str, scale: float) -> None:
    """The package pk: pk/tasks.py registers the task, whose reward scale comes from pk/helpers.py; a namespace
    package has no __init__.py."""
    (root / "pk").mkdir(parents=True, exist_ok=True)
    (root / "pk" / "tasks.py").write_text(TASKS.format(helper_import=HELPER_IMPORTS[style]))
    (root / "pk" / "helpers.py").write_text(f"SCALE = {scale}\n")
    init = root / "pk" / "__init__.py"
    if style == "namespace package":
        init.unlink(missing_ok=True)
    else:
        init.write_text("")
    for name in ("pk", "pk.tasks", "pk.helpers"):  # as the next command's new process starts
        sys.modules.pop(name, None)
    gym.registry.pop("pk/Grid-v0", None)


@pytest.mark.slow
def test_an_edited_module_of_a_tasks_package_evaluates_the_cells_again(tmp_path, monkeypatch, capsys):
    """Issue 56, silent 5: a custom task kept in a package (`--env-id pk.tasks:pk/Grid-v0`) whose reward scale
    comes from pk/helpers.py; the helper edited (x100), the next sweep into the same --output evaluates the cell
    again and gives 100 times the returns (it said "1 already done"). Imported absolutely, relatively, or from a
    namespace package (no __init__.py)."""
    root = tmp_path / "tasks"
    monkeypatch.syspath_prepend(str(root))
    try:
        write_task_package(root, "absolute", 1.0)
        run_dir = train(ppo_pgg_discrete, tiny_discrete_args(tmp_path, "pk.tasks:pk/Grid-v0"))
        for style in HELPER_IMPORTS:
            write_task_package(root, style, 1.0)
            args = sweep.Args(paths=(str(run_dir),), output=str(tmp_path / style), gammas=(1.0,), episodes=3)
            before = returns(sweep.sweep(args))
            write_task_package(root, style, 100.0)
            capsys.readouterr()
            after = returns(sweep.sweep(args))
            assert "1 cells, 0 already done" in capsys.readouterr().err, style
            assert after == [100 * value for value in before] and min(before) >= 10, style
    finally:
        write_task_package(tmp_path / "gone", "absolute", 1.0)  # this process forgets the package and its task


def installed_folders() -> list[Path]:
    """Where this interpreter's standard library and installed packages lie, as sysconfig and site say."""
    paths = sysconfig.get_paths()
    folders = [paths[key] for key in ("stdlib", "platstdlib", "purelib", "platlib")] + site.getsitepackages()
    return [Path(folder).resolve() for folder in folders]


def test_a_sweeps_code_lists_no_installed_or_standard_library_file(tmp_path, monkeypatch):
    """The files a real sweep keys its cells by: the sweep, the script, this package, and nothing of torch,
    numpy, gymnasium, tyro or the standard library."""
    listed = []
    real_digest = cells.code_digest
    monkeypatch.setattr(cells, "code_digest", lambda found: listed.extend(found) or real_digest(found))
    sweep.sweep(sweep_args(tmp_path / "out", gammas=(1.0,), episodes=1))
    assert {ROOT / "eval_gamma_sweep.py", ROOT / "ppo_pgg_discrete.py", ROOT / "pgg_utils" / "fast.py"} <= set(listed)
    assert all(ROOT in path.parents for path in listed), listed
    assert not [path for path in listed if any(path.is_relative_to(folder) for folder in installed_folders())]


@pytest.mark.slow
def test_an_installed_copy_reads_its_own_files_and_none_of_the_packages_beside_it(tmp_path):
    """Issue 59, silent 1: the project installed in a site-packages folder, an installed package (tyro) beside it
    as in any environment. Its sweep's code is the copy's own files, the same ones as the clone's (so the same
    digest, the same cells), and nothing of tyro: it followed `import tyro` beside the sweep into every file of
    the packages there (4,204 files for torch's, a sweep ten times slower)."""
    installed = tmp_path / "venv" / "lib" / "site-packages"
    installed.mkdir(parents=True)
    for name in ("eval_gamma_sweep.py", "ppo_pgg_discrete.py"):
        (installed / name).write_bytes((ROOT / name).read_bytes())
    (installed / "pgg_utils").mkdir()
    for path in (ROOT / "pgg_utils").glob("*.py"):
        (installed / "pgg_utils" / path.name).write_bytes(path.read_bytes())
    import tyro

    (installed / "tyro").symlink_to(Path(tyro.__file__).parent)
    listing = "import sys; from pgg_utils import cells; print(*cells.imported_files(sys.argv[1:]), sep='\\n')"
    roots = [str(installed / "eval_gamma_sweep.py"), str(installed / "ppo_pgg_discrete.py")]
    environment = {**os.environ, "PYTHONPATH": str(installed)}
    proc = subprocess.run([sys.executable, "-c", listing, *roots], cwd=tmp_path, env=environment, capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    listed = [Path(line) for line in proc.stdout.splitlines()]
    assert all(installed in path.parents and "tyro" not in path.parts for path in listed), listed
    clone = cells.imported_files([ROOT / "eval_gamma_sweep.py", ROOT / "ppo_pgg_discrete.py"])
    assert sorted(path.relative_to(installed) for path in listed) == sorted(path.relative_to(ROOT) for path in clone)


def test_the_project_modules_are_the_packaged_ones():
    """cells.PROJECT_MODULES, followed even where they lie among installed packages, are what pyproject.toml
    packages: a module added to the package and not here would be left out of an installed copy's cell keys."""
    tomllib = pytest.importorskip("tomllib", reason="Python 3.11's TOML reader")
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert cells.PROJECT_MODULES == {*setuptools["py-modules"], *setuptools["packages"]}
