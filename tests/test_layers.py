"""The three layers (docs/layout.md): the algorithm (the training scripts), the engine (pgg_utils/) and the
study (paper_study/, the paper's tables; beyond/, the experiments past it). A layer imports only the layers
below it, read from every module's own import statements, so an import added anywhere, at the top of a file
or inside a function, is seen before anything runs."""

import ast
import functools
import importlib
import os
from pathlib import Path

import pytest
from conftest import ROOT, run_main

TRAINING = ("ppo_pgg_discrete", "ppo_pgg_continuous")
# Each top-level name of the project, with the layer it belongs to (lower numbers lie lower).
LAYER_OF = {
    "pgg_utils": 0,
    **dict.fromkeys(TRAINING, 1),
    "eval_gamma_sweep": 1,
    "paper_study": 2,
    "plot_results": 2,
    "reproduce": 2,
    "beyond": 3,
    "benchmarks": 4,
}
# Only the experiments beyond the paper, the benchmarks and the tests may import beyond/; paper_study's part
# that the wheel ships (plot_results --compare-paper, reproduce) must load without it.
LEFT_OUT = {"tests", "build", "runs", "venv", "pgg.egg-info"}
LAYER_NAMES = {0: "the engine", 1: "the algorithm and the sweep", 2: "the paper study", 3: "beyond/", 4: "benchmarks/"}


@functools.cache
def modules() -> dict[str, Path]:
    """{dotted module name: file} of every Python file of the project outside tests/ (and outside the folders
    git ignores that a checkout may hold: virtual environments, build/, runs/)."""
    found = {}
    for folder, subfolders, names in os.walk(ROOT):
        subfolders[:] = [sub for sub in subfolders if not sub.startswith((".", "__")) and sub not in LEFT_OUT]
        for name in names:
            if name.endswith(".py"):
                relative = (Path(folder) / name).relative_to(ROOT)
                found[".".join(relative.with_suffix("").parts).removesuffix(".__init__")] = ROOT / relative
    return dict(sorted(found.items()))


def imported_names(path: Path) -> set[str]:
    """The dotted names a file imports, absolute, wherever in the file the statement stands."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def layer(name: str) -> int | None:
    return LAYER_OF.get(name.split(".")[0])


def test_every_project_module_has_a_layer():
    assert {name for name in modules() if layer(name) is None} == set()


@pytest.mark.parametrize("name", sorted(modules()))
def test_no_module_imports_a_layer_above_its_own(name):
    path = modules()[name]
    above = sorted(imported for imported in imported_names(path) if (layer(imported) or 0) > layer(name))
    assert above == [], f"{name} ({LAYER_NAMES[layer(name)]}) imports {above}"


def test_the_training_scripts_and_the_sweep_import_only_the_engine():
    for name in (*TRAINING, "eval_gamma_sweep"):
        project = {
            imported.split(".")[0] for imported in imported_names(modules()[name]) if layer(imported) is not None
        }
        assert project <= {"pgg_utils"}, name


def test_the_check_sees_an_import_of_the_study_inside_a_function(tmp_path):
    """What the test above would miss if it read only top-level imports."""
    engine = tmp_path / "engine.py"
    engine.write_text("def report():\n    from paper_study import stats\n    return stats\n")
    assert "paper_study" in imported_names(engine) and layer("paper_study.stats") > layer("pgg_utils.files")


def test_no_module_outside_tests_edits_sys_path():
    """Scripts run as modules (`python -m beyond.report`) or from the installed package, never by making their
    own folder importable."""
    assert [name for name, path in modules().items() if "sys.path.insert" in path.read_text()] == []


def test_no_import_circle_between_the_projects_modules():
    graph = {name: set() for name in modules()}
    for name, path in modules().items():
        for imported in imported_names(path):
            while imported and imported not in graph:
                imported = imported.rpartition(".")[0]
            if imported and imported != name and not name.startswith(imported + "."):
                graph[name].add(imported)
    done, on_path = set(), []

    def visit(name):
        if name in on_path:
            raise AssertionError(f"import circle: {' -> '.join([*on_path[on_path.index(name) :], name])}")
        if name in done:
            return
        on_path.append(name)
        for imported in sorted(graph[name]):
            visit(imported)
        on_path.pop()
        done.add(name)

    for name in sorted(graph):
        visit(name)


def tools() -> list[str]:
    """The modules of the packages that run as `python -m package.tool`: those with an entry point."""
    return sorted(
        name for name, path in modules().items() if "." in name and '__name__ == "__main__"' in path.read_text()
    )


@pytest.mark.parametrize("name", tools())
def test_every_tool_run_as_a_module_answers_help_with_its_usage(name):
    """`python -m <tool> --help` prints the tool's usage and exits 0: a tool that reads sys.argv by hand (its file
    names taken for --help) or runs at import, with no main(), fails here."""
    module = importlib.import_module(name)
    assert callable(getattr(module, "main", None)), f"{name} has no main()"
    done = run_main(module, "--help")
    assert done.returncode == 0 and "usage" in done.stdout.lower(), (name, done.stderr[-500:])
