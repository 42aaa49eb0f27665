"""The sweep's cache of evaluated cells: one CSV per (checkpoint, γ, settings, evaluation stack),
written atomically, each row with a checksum. A sweep reuses a cell only where the file is whole and
every checksum holds, so an interrupted sweep loses only the cells in flight and a damaged or foreign
file is evaluated again."""

import hashlib
import json
from pathlib import Path

from pgg_utils import checkpoints
from pgg_utils.files import InputError, read_csv, write_csv_atomic

# Part of every cell's identity; raised when a fix changes what a cell evaluates to or holds, so that a
# rerun recomputes cells from before it. 2: continuous actions clipped to the env's bounds. 3: each cell
# in a batch of its own (its numbers no longer depend on the other cells), Gumbel noise in float64, and
# the config column. 4: the evaluation stack and the action space in every row and a checksum per row
# (cells of 3 have neither and could never be verified); returns and lengths are those of 3.
EVALUATOR_REVISION = 4
# The packages whose versions decide an episode's numbers (MuJoCo's physics, gymnasium's tasks and
# wrappers, numpy's and torch's rounding): recorded in every row, and part of every cell's identity.
STACK_COLUMNS = ["mujoco", "gymnasium", "numpy", "torch"]
EPISODE_COLUMNS = [
    "env_id", "variant", "config", "run", "seed", "train_guidance", "cond_dropout", "step", "global_step",
    "eval_guidance", "policy", "null_branch", "episode", "episode_seed", "return", "length",
    *STACK_COLUMNS, "action_space",
]  # fmt: skip
CELL_COLUMNS = [*EPISODE_COLUMNS, "checksum"]  # a cell file's: each row proves that it is whole and whose it is


def evaluation_stack() -> tuple[str, ...]:
    """This process's versions of the STACK_COLUMNS packages, in that order ("none" where one is not installed)."""
    versions = checkpoints.package_versions()
    return tuple(versions[package] or "none" for package in STACK_COLUMNS)


def cell_path(output: Path, checkpoint: Path, gamma: float, settings: tuple, digest: str, stack: tuple,
              evaluator: str) -> Path:  # fmt: skip
    """One file per (checkpoint, γ, settings, evaluation stack, evaluating code). The checkpoint's bytes
    (`digest`, their sha1), not its path or timestamp, are its identity: a retrained run is never
    mistaken for the one evaluated before, and a run directory copied to another machine or folder
    keeps its finished cells. The stack is part of it too: a cell computed under another MuJoCo,
    gymnasium, numpy or torch is never reused; and so is `evaluator`, the sha1 of the training script
    that evaluates it and of a custom task's code: a cell computed before either was edited is never reused."""
    key = f"{digest}|{gamma!r}|{settings!r}|{stack!r}|{evaluator}|{EVALUATOR_REVISION}"
    name = hashlib.sha1(key.encode()).hexdigest()[:16]
    return output / "cells" / f"{checkpoint.parent.parent.name}__{checkpoint.stem}__g{gamma:g}__{name}.csv"


def row_checksum(path: Path, row: dict) -> str:
    """sha1 of a row's values and of its cell's file name, which encodes the cell's identity (cell_path):
    a row that was edited, cut short or copied from another cell fails it."""
    return hashlib.sha1(json.dumps([path.name, *(row[column] for column in EPISODE_COLUMNS)]).encode()).hexdigest()


def write_cell(path: Path, rows: list[dict]) -> list[dict]:
    """Writes a cell atomically, each value as the text read_cell will read and each row with its
    checksum; returns the rows as written (str of a float is its repr, the digits csv writes)."""
    written = []
    for row in rows:
        text = {column: str(row[column]) for column in EPISODE_COLUMNS}
        written.append({**text, "checksum": row_checksum(path, text)})
    write_csv_atomic(path, CELL_COLUMNS, written)
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
        if list(row) != CELL_COLUMNS or None in row.values():
            raise ValueError(f"row {number} does not have the columns of a cell")
        if row["checksum"] != row_checksum(path, row):
            raise ValueError(f"row {number} does not match its checksum")
    if {row["episode"] for row in rows} != {str(k) for k in range(episodes)}:
        raise ValueError(f"its episodes are not 0..{episodes - 1} each once")
    return rows
