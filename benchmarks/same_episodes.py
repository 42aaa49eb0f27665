"""Are a sweep's episodes the table's own? Each episode of the sweep is looked up in the table by run,
checkpoint step, eval γ, policy, null branch and episode seed, and every field that both record is
compared as text, so a return equal to the last bit is equal:

    python -m benchmarks.same_episodes results/continuous/episodes.csv runs/sweeps/check/episodes.csv

This is how a retrained run is shown to be the table's run bit for bit: identical weights give identical
episodes in every cell, and weights that differ anywhere change the sampled actions of nearly every
episode (benchmarks/README.md, "Exactness of the sweep"). A field that one side leaves empty (the stack
columns of sweeps older than them) is named and not compared. Exit status 0 when every episode of the
sweeps is in the table, identical; 1 when one is missing or differs; 2 for unreadable input.
"""

import sys
from dataclasses import dataclass
from pathlib import Path

import tyro

from pgg_utils.files import InputError, one_line_errors, read_csv

KEY = ("run", "step", "eval_guidance", "policy", "null_branch", "episode_seed")
SHOWN = 5  # differences printed in full; the rest are counted


@dataclass
class Args:
    table: tyro.conf.Positional[str]
    """the table's episodes.csv"""
    sweeps: tyro.conf.Positional[tuple[str, ...]]
    """one or more sweeps' episodes.csv, every episode of which should be the table's"""


def key(row: dict) -> tuple:
    return (row["run"], int(row["step"]), float(row["eval_guidance"]), row["policy"], row["null_branch"],
            int(row["episode_seed"]))  # fmt: skip


def read(path: str) -> list[dict]:
    try:
        rows = read_csv(Path(path))
    except OSError as e:
        raise InputError(f"{path}: {e.strerror}") from None
    if not rows:
        raise InputError(f"{path} holds no episodes")
    if missing := [c for c in KEY if c not in rows[0]]:
        raise InputError(f"{path} is no sweep's episodes.csv: it lacks {', '.join(missing)}")
    return rows


def compare(table: list[dict], sweep: list[dict]) -> tuple[list[str], set[str], int]:
    """(one line per sweep episode missing from the table or differing from it, the fields left empty on
    one side, the episodes found identical)."""
    by_key = {key(row): row for row in table}
    problems, unrecorded, identical = [], set(), 0
    for row in sweep:
        theirs = by_key.get(key(row))
        if theirs is None:
            problems.append(f"not in the table: {dict(zip(KEY, key(row), strict=True))}")
            continue
        differ = []
        for field in row.keys() & theirs.keys():
            if row[field] == "" or theirs[field] == "":
                if row[field] != theirs[field]:
                    unrecorded.add(field)
            elif row[field] != theirs[field]:
                differ.append(f"{field} {theirs[field]} in the table, {row[field]} here")
        if differ:
            problems.append(f"{row['run']} step {row['step']} γ {row['eval_guidance']} episode seed "
                            f"{row['episode_seed']}: {'; '.join(sorted(differ))}")  # fmt: skip
        else:
            identical += 1
    return problems, unrecorded, identical


def main() -> None:
    args = tyro.cli(Args)
    with one_line_errors():
        table = read(args.table)
        same = True
        for path in args.sweeps:
            sweep = read(path)
            problems, unrecorded, identical = compare(table, sweep)
            skipped = f"; empty on one side, not compared: {', '.join(sorted(unrecorded))}" if unrecorded else ""
            print(f"{path}: {identical:,} of {len(sweep):,} episodes identical to the table's in every field"
                  f"{skipped}")  # fmt: skip
            for problem in problems[:SHOWN]:
                print(f"  {problem}")
            if len(problems) > SHOWN:
                print(f"  … and {len(problems) - SHOWN:,} more")
            same &= not problems
    sys.exit(0 if same else 1)


if __name__ == "__main__":
    main()
