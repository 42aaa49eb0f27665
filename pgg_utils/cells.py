"""The sweep's cache of evaluated cells: one CSV per (checkpoint, γ, settings, evaluation stack, evaluating
code), written atomically, each row with a checksum. A sweep reuses a cell only where the file is whole and
every checksum holds, so an interrupted sweep loses only the cells in flight and a damaged or foreign
file is evaluated again.

A cell holds the sweep's columns (EPISODE_COLUMNS) and, after them, whatever per-episode columns the sweep
that wrote it adds (a copy of the sweep that measures more: eval_gamma_sweep.py, "Changing the episodes")."""

import ast
import hashlib
import json
from pathlib import Path

from pgg_utils import checkpoints
from pgg_utils.files import InputError, read_csv, write_csv_atomic
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
PACKAGE = Path(__file__).resolve().parent  # pgg_utils, wherever it is installed


def evaluation_stack() -> tuple[str, ...]:
    """This process's versions of the STACK_COLUMNS packages, in that order ("none" where one is not installed)."""
    versions = checkpoints.package_versions()
    return tuple(versions[package] or "none" for package in STACK_COLUMNS)


def imported_files(roots) -> list[Path]:
    """The files `roots` and every project module they import, transitively, as their import statements
    (each one, at the top of a file or inside a function) name them: the modules of this package and the
    modules beside the file that imports them (a fork's helper module, the original script a fork imports).
    Installed packages are not followed: their versions are the evaluation stack's (STACK_COLUMNS)."""
    todo, found = [Path(root).resolve() for root in roots], set()
    while todo:
        path = todo.pop()
        if path in found:
            continue
        found.add(path)
        for node in ast.walk(ast.parse(path.read_bytes(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):  # `from a import b`: b may be a module of a
                module = "." * node.level + (node.module or "")
                names = [module, *(module + ("." if node.module else "") + alias.name for alias in node.names)]
            else:
                continue
            todo.extend(file for name in names for file in module_files(name, path.parent))
    return sorted(found)


def module_files(name: str, folder: Path) -> list[Path]:
    """The project files that importing `name` from a file in `folder` runs: each package's __init__ on the
    way and the module itself, found beside the importing file or at the top of the repository (this
    package's folder); [] for a module of an installed package or of the standard library."""
    parts, level = name.lstrip(".").split("."), len(name) - len(name.lstrip("."))
    if level:  # relative: from `folder`, one folder up per dot after the first
        bases = [folder.parents[level - 2] if level > 1 else folder]
    else:
        bases = [PACKAGE.parent] if parts[0] == PACKAGE.name else [folder, PACKAGE.parent]
    for base in bases:
        files, here = [], base
        for part in filter(None, parts):
            here = here / part
            if (here / "__init__.py").is_file():
                files.append(here / "__init__.py")
            elif here.with_suffix(".py").is_file():
                files.append(here.with_suffix(".py"))
                break
            else:
                break
        if files:
            return files
    return []


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
