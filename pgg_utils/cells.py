"""The sweep's cache of evaluated cells: one CSV per (checkpoint, γ, settings, evaluation stack, evaluating
code), written atomically, each row with a checksum. A sweep reuses a cell only where the file is whole and
every checksum holds, so an interrupted sweep loses only the cells in flight and a damaged or foreign
file is evaluated again. A cell's identity holds the digest of every file of code that runs in its episodes
(evaluation_code), found for each checkpoint with its task (evaluation_of).

A cell holds the sweep's columns (EPISODE_COLUMNS) and, after them, whatever per-episode columns the sweep
that wrote it adds (a copy of the sweep that measures more: eval_gamma_sweep.py, "Changing the episodes")."""

import ast
import functools
import hashlib
import importlib.machinery
import importlib.util
import json
import os
import site
import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym

from pgg_utils import checkpoints, scripts, tasks
from pgg_utils.evaluation import action_error, first_line
from pgg_utils.files import InputError, read_csv, write_csv_atomic
from pgg_utils.identity import run_of
from pgg_utils.scripts import file_sha1

# The packages whose versions decide an episode's numbers (MuJoCo's physics, gymnasium's tasks and
# wrappers, numpy's and torch's rounding): recorded in every row, and part of every cell's identity.
STACK_COLUMNS = ["mujoco", "gymnasium", "numpy", "torch"]
EPISODE_COLUMNS = [
    "env_id", "variant", "config", "config_fields", "run", "seed", "train_guidance", "cond_dropout", "step", "global_step",
    "eval_guidance", "policy", "null_branch", "episode", "episode_seed", "return", "length",
    *STACK_COLUMNS, "action_space",
]  # fmt: skip
CHECKSUM = "checksum"  # a cell file's last column: each row proves that it is whole and whose it is
# This project's top-level modules (pyproject.toml's py-modules and packages): part of a cell's key wherever
# they lie, an installed copy's site-packages too, as no version in the key stands for them.
PROJECT_MODULES = frozenset({"pgg_utils", "paper_study", "ppo_pgg_discrete", "ppo_pgg_continuous", "eval_gamma_sweep",
                             "plot_results", "reproduce"})  # fmt: skip
INSTALLED_FOLDER_NAMES = {"site-packages", "dist-packages"}


def evaluation_stack() -> tuple[str, ...]:
    """This process's versions of the STACK_COLUMNS packages, in that order ("none" where one is not installed)."""
    versions = checkpoints.package_versions()
    return tuple(versions[package] or "none" for package in STACK_COLUMNS)


def imported_files(roots) -> list[Path]:
    """The files `roots` and every module they import, transitively, as their import statements (each one, at
    the top of a file or inside a function) name them, wherever the module lies: this project's own modules, a
    fork's helper module beside it, a module on PYTHONPATH, a task package's other modules. Found as Python finds
    them (the module this process imported under that name, else the import path, else beside the importing
    file), never imported. Not followed: installed packages and the standard library (`installed`), whose
    versions stand for them in a cell's key (STACK_COLUMNS): their thousands of files are never read."""
    importlib.invalidate_caches()  # a module written since the finders listed its folder is found
    todo, found, resolved = [Path(root).resolve() for root in roots], set(), {}
    while todo:
        path = todo.pop()
        if path in found:
            continue
        found.add(path)
        if path.suffix != ".py":  # compiled code: its bytes are its identity, it names no imports we can read
            continue
        for node in import_statements(ast.parse(path.read_bytes(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:  # `from a import b`: b may be a module of a
                module = "." * node.level + (node.module or "")
                names = [module, *(module + ("." if node.module else "") + alias.name for alias in node.names)]
            for name in names:
                if (name, path.parent) not in resolved:
                    resolved[name, path.parent] = module_files(name, path.parent)
                todo.extend(resolved[name, path.parent])
    return sorted(found)


def import_statements(tree: ast.Module):
    """Every import statement of a module, at its top or nested in any block (a function, a class, a try):
    statements lie only in blocks, so no expression is visited."""
    todo = [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        for block in ("body", "orelse", "finalbody", "handlers", "cases"):
            todo.extend(getattr(node, block, ()))


def module_files(name: str, folder: Path) -> list[Path]:
    """The files of code that importing `name` from a file in `folder` runs, each package's __init__ on the way
    and the module itself; [] for a module of an installed package or of the standard library (`installed`),
    but for this project's own (PROJECT_MODULES), which no version in a cell's key stands for."""
    level = len(name) - len(name.lstrip("."))
    parts = name[level:].split(".") if name[level:] else []
    if level:  # relative: from the importing file's package, one folder up per dot after the first
        if level - 2 >= len(folder.parents):  # above the file system's root: the import itself fails
            return []
        package = folder.parents[level - 2] if level > 1 else folder
        spec = importlib.machinery.PathFinder.find_spec(package.name, [str(package.parent)])
        parts = [package.name, *parts]
    else:
        spec = top_level_spec(parts[0], folder)
    files = []
    for depth in range(1, len(parts) + 1):
        if spec is None:
            break
        origin = Path(spec.origin) if spec.has_location and spec.origin else None
        locations = list(spec.submodule_search_locations or [])
        if depth == 1 and not level and parts[0] not in PROJECT_MODULES:
            where = [origin] if origin else [Path(location) for location in locations]
            if not where or any(map(installed, where)):
                return []
        if origin is not None and origin.is_file():
            files.append(origin.resolve())
        if depth == len(parts) or not locations:
            break
        spec = submodule_spec(".".join(parts[: depth + 1]), locations)
    return files


def top_level_spec(name: str, folder: Path):
    """How Python finds the top-level module `name`: the one this process imported, else on the import path
    (sys.meta_path's finders, an editable install's among them), else a file beside the importer (a fork loaded
    from its path, whose folder is not on the path)."""
    if (spec := getattr(sys.modules.get(name), "__spec__", None)) is not None:
        return spec
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):  # a finder that refuses the name
        spec = None
    return spec or importlib.machinery.PathFinder.find_spec(name, [str(folder)])


def submodule_spec(name: str, locations: list[str]):
    """The spec of the submodule `name` (dotted) of a package found in `locations`, as imported or as it would be."""
    if (spec := getattr(sys.modules.get(name), "__spec__", None)) is not None:
        return spec
    return importlib.machinery.PathFinder.find_spec(name, locations)


@functools.cache
def installed_folders() -> tuple[Path, ...]:
    """Where this interpreter's standard library and installed packages lie."""
    paths = sysconfig.get_paths()
    folders = [paths[key] for key in ("stdlib", "platstdlib", "purelib", "platlib")]
    folders += [*site.getsitepackages(), site.getusersitepackages()]
    return tuple(dict.fromkeys(Path(folder).resolve() for folder in folders))


def installed(path: Path) -> bool:
    """Whether `path` belongs to the standard library or an installed package: under one of this interpreter's
    folders for them, or in any folder named site-packages or dist-packages (another environment's)."""
    for where in dict.fromkeys((Path(os.path.abspath(path)), Path(path).resolve())):
        if INSTALLED_FOLDER_NAMES & set(where.parts) or any(where.is_relative_to(f) for f in installed_folders()):
            return True
    return False


def code_digest(files) -> str:
    """The sha1 of the contents of `files`, in no order of theirs: where the files lie or are named does
    not enter it, so a copied repository keeps its cells."""
    return hashlib.sha1("|".join(sorted(file_sha1(path) for path in files)).encode()).hexdigest()


def cell_path(output: Path, checkpoint: Path, gamma: float, settings: tuple, digest: str, stack: tuple,
              evaluator: str) -> Path:  # fmt: skip
    """One file per (checkpoint, γ, settings, evaluation stack, evaluating code). The checkpoint's bytes
    (`digest`, their sha1), not its path or timestamp, are its identity: a retrained run is never
    mistaken for the one evaluated before, and a run directory copied to another machine or folder
    keeps its finished cells. The stack is part of it too: a cell computed under another MuJoCo,
    gymnasium, numpy or torch is never reused; and so is `evaluator`, the digest of every file of code
    that runs in its episodes (the sweep's evaluation_code): a cell computed before any of them was
    edited, or by another copy of the sweep, is never reused."""
    key = f"{digest}|{gamma!r}|{settings!r}|{stack!r}|{evaluator}"
    name = hashlib.sha1(key.encode()).hexdigest()[:16]
    return output / "cells" / f"{checkpoint.parent.parent.name}__{checkpoint.stem}__g{gamma:g}__{name}.csv"


def extra_columns(row: dict) -> list[str]:
    """The columns of a row after the sweep's own: the per-episode columns a copy of the sweep adds."""
    return [column for column in row if column not in EPISODE_COLUMNS and column != CHECKSUM]


def row_checksum(path: Path, row: dict) -> str:
    """sha1 of a row's values (and of the names of its added columns) and of its cell's file name, which
    encodes the cell's identity (cell_path): a row that was edited, cut short or copied from another cell fails it."""
    added = [[column, row[column]] for column in extra_columns(row)]
    return hashlib.sha1(
        json.dumps([path.name, *(row[column] for column in EPISODE_COLUMNS), *added]).encode()
    ).hexdigest()


def write_cell(path: Path, rows: list[dict]) -> list[dict]:
    """Writes a cell atomically, each value as the text read_cell will read and each row with its
    checksum; returns the rows as written (str of a float is its repr, the digits csv writes). Its
    columns are EPISODE_COLUMNS, then the rows' added ones (the same in every row)."""
    columns = [*EPISODE_COLUMNS, *extra_columns(rows[0])]
    written = []
    for row in rows:
        if set(row) - {CHECKSUM} != set(columns):  # a row read back from a cell holds its old checksum
            raise ValueError(f"its rows do not all have the columns {columns}")
        text = {column: str(row[column]) for column in columns}
        written.append({**text, CHECKSUM: row_checksum(path, text)})
    write_csv_atomic(path, [*columns, CHECKSUM], written)
    return written


def read_cell(path: Path, episodes: int) -> list[dict]:
    """The rows of a finished cell of `episodes` episodes. ValueError, saying why, for a file that
    cannot be trusted: unreadable, another row count, a row cut short or whose checksum fails (an
    edited value, a row of another cell), or episodes other than 0..episodes-1 each once."""
    try:
        rows = read_csv(path)
    except InputError:  # random bytes, a NUL: not CSV text (read_csv says so)
        raise ValueError("unreadable (not CSV text)") from None
    except OSError as e:  # a directory in its place
        raise ValueError(f"unreadable ({type(e).__name__})") from None
    if len(rows) != episodes:
        raise ValueError(f"{len(rows)} rows, not {episodes}")
    for number, row in enumerate(rows, start=1):
        columns = list(row)
        if columns[: len(EPISODE_COLUMNS)] != EPISODE_COLUMNS or columns[-1] != CHECKSUM or None in row.values():
            raise ValueError(f"row {number} does not have the columns of a cell")
        if row[CHECKSUM] != row_checksum(path, row):
            raise ValueError(f"row {number} does not match its checksum")
    if {row["episode"] for row in rows} != {str(k) for k in range(episodes)}:
        raise ValueError(f"its episodes are not 0..{episodes - 1} each once")
    return rows


# --- what evaluates a checkpoint: its script, its task, the digest of their code ---------------------------


EVALUATED_BY_COLUMNS = [
    "run",
    "step",
    "env_id",
    "config",
    "trained_by",
    "evaluated_by",
    "evaluated_by_sha1",
    "same_script",
]


@dataclass(frozen=True)
class Evaluation:
    """How a checkpoint is evaluated: by which script file, and the fingerprint of the code that computes
    its cells (part of each cell's identity), with the row evaluated_by.csv gets."""

    script: Path
    evaluator: str
    record: dict


@dataclass(frozen=True)
class Task:
    """A checkpoint's task as the script that evaluates it makes it: its spaces, and the digest of every file
    of code that runs in a cell's episodes (evaluation_code)."""

    observation_space: gym.Space
    action_space: gym.Space
    code: str


def evaluation_code(sweeper: Path, script: Path, task_files) -> str:
    """The digest of the code that runs in a cell's episodes: the file of the sweep (`sweeper`: eval_gamma_sweep.py
    or a copy of it, whichever runs, and through its imports this engine), the script that evaluates the checkpoint, a custom task's module (scripts.task_sources;
    gymnasium's own tasks are named by its version in the stack), and every module that these import, wherever
    it lies, but installed packages and the standard library, which the stack's versions name (cells.imported_files).
    An edit to any of them, or another copy of the sweep, re-evaluates the cells."""
    return code_digest(imported_files([sweeper, script, *task_files]))


def task_of(module, sweeper: Path, script: Path, env_id: str) -> Task:
    """The task of `env_id` as `module` makes it. ValueError (one line) where it cannot be made or has no time limit."""
    try:
        env = module.make_env(env_id)()
    except Exception as e:  # a custom task's module gone, an id no longer registered: whatever make raises
        raise ValueError(f"cannot make environment {env_id!r} ({first_line(e)})") from None
    task = Task(
        env.observation_space, env.action_space, evaluation_code(sweeper, script, scripts.task_sources(env_id, env))
    )
    bounded = env.spec is not None and env.spec.max_episode_steps
    env.close()
    if not bounded:
        raise ValueError(f"{env_id} has no time limit (max_episode_steps), so an episode may never end; "
                         "register it with one, e.g. gym.register(..., max_episode_steps=1000)")  # fmt: skip
    return task


def task_error(ckpt: dict, task: Task) -> str | None:
    """One line where the task's spaces are not those the checkpoint was trained on (tasks.mismatch), or
    its actions are not ones the sweep can act in (action_error)."""
    if error := action_error(ckpt, task.action_space):
        return error
    if error := tasks.mismatch(tasks.recorded(ckpt), task.observation_space, task.action_space):
        return f"its task {ckpt['env_id']} has changed since training: {error}; not evaluated"
    return None


def evaluation_of(checkpoint: Path, ckpt: dict, given: tuple[Path, ...], tasks: dict, sweeper: Path) -> Evaluation:
    """How a checkpoint is evaluated, by the script that trained it, and the fingerprint of the code that
    computes its cells (evaluation_code, with `sweeper`, the sweep's file). `tasks` caches the task by (script, env). ValueError (one line)
    where the script cannot be found or load the checkpoint, or the task cannot be made or is not the one it
    was trained on (task_error)."""
    _, module, script = scripts.load_agent(ckpt, checkpoint, given)  # proves its Agent holds the weights, once
    key = (script, ckpt["env_id"])
    if key not in tasks:
        tasks[key] = task_of(module, sweeper, script, ckpt["env_id"])
    if error := task_error(ckpt, tasks[key]):
        raise ValueError(error)
    script_sha1 = scripts.file_sha1(script)
    trained_sha1 = ckpt.get("code", {}).get("script_sha1")
    same = "unknown" if trained_sha1 is None else "yes" if trained_sha1 == script_sha1 else "no"
    evaluator = tasks[key].code
    record = {"run": run_of(ckpt, checkpoint), "step": ckpt["step_mark"], "env_id": ckpt["env_id"],
              "trained_by": scripts.script_name(ckpt), "evaluated_by": scripts.recorded_path(script),
              "evaluated_by_sha1": script_sha1, "same_script": same}  # fmt: skip
    return Evaluation(script, evaluator, record)
