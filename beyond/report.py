"""The report of "Beyond the paper": each variant of the paper's future work (scheduled and adaptive
γ_train, guidance on a goal) against its baselines, from committed episode CSVs only.

    python -m beyond.report results/beyond --table results/continuous/episodes.csv

Reads every `results/beyond/<task>/episodes.csv` (the new variants, and for tasks outside the paper's
table their own PPO and γ_train 1.1 runs), the continuous table's episodes for the baselines of the
paper's tasks, `results/beyond/<task>/heldout_gamma.csv` where the held-out selection was run, and
`results/beyond/goal_distance.csv` (beyond/goal_distance.py) where it exists. Writes into the
folder, atomically:
  report.md    at a glance, a table per question (the γ-response at the last mark of the scheduled and
               adaptive variants and their baselines, with Welch tests of their per-seed fall from the best γ
               to the largest and of their return at the best γ against the baselines'; the final distance to
               the goal against γ, with a t test of each seed's change from γ = 1 to the largest); then per
               task: return at each mark at γ = 1 (mean ± 95% CI over seeds, seed sd, runs that fell),
               each new variant against each baseline (Welch + Holm over the report's γ = 1 tests, the gap
               one test can detect at 80% power, the cells above and below over both sweeps, the pooled
               median gap over every (step, γ) cell with its exact bootstrap interval), the held-out γ, the
               γ-response at the last step, and the final distance to the goal against γ
  report.csv   one row per (task, variant, baseline, step) at γ = 1: the tests' numbers
  report_values.csv   every other number the front page may quote, unrounded (the glance tables, the γ_train,
               γ-response and pooled counts): one row per (task, variant, baseline, quantity)
  gamma_response.png   return against eval γ at the last step, a panel per task
  guidance_trajectory.png   γ_train over training of the scheduled and adaptive runs
  goal_distance.png    the final distance to the goal against eval γ, a panel per goal task
With `--runs runs/beyond` it first rewrites `guidance_trajectory.csv` (γ_train and the KL of every
iteration of every run, from the runs' TensorBoard events, which are not committed); without it the
committed CSV is read. A run "fell" where its return at the last step is below half of its best mark's: at
γ = 1, and at its best eval γ of each mark.
"""

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import tyro

from beyond import condition_dropout, dropout_sets
from beyond.cells import read_rows, seed_means
from beyond.cloning import cloning_fresh_tests, cloning_section
from beyond.command_text import command_section
from beyond.figures import (
    bc_figure,
    command_figure,
    distance_figure,
    dropout_figure,
    gamma_response_figure,
    trajectory_figure,
)
from beyond.fitted_null import bc_section, read_bc
from beyond.glance import glance_section
from beyond.goals import read_goal_distance
from beyond.question_3 import question_3_reading
from beyond.schedules import (
    fall_tests,
    gamma_one_tests,
    read_heldout,
    read_trajectories,
    write_trajectories,
)
from beyond.sets import (
    BASELINES,
    BC_TRAIN_FOLDER,
    CLONING_VARIANTS,
    COMMAND_FOLDER,
    SETS_APART,
)
from beyond.task import task_section
from paper_study.paper import variant_rank
from pgg_utils.files import InputError, one_line_errors, write_atomic, write_csv_atomic


@dataclass
class Args:
    folder: tyro.conf.Positional[str]
    """results/beyond: one folder per task, each with the episodes.csv of its sweep"""
    table: str = "results/continuous/episodes.csv"
    """the continuous table's episodes, for the baselines of the paper's tasks"""
    table_heldout: str = "results/continuous/heldout_gamma.csv"
    """the continuous table's held-out γ, for the baselines' rows of the held-out table"""
    discrete_table: str = "results/discrete/episodes.csv"
    """the discrete table's episodes, for the discrete agents whose null was behaviour-cloned"""
    discrete_heldout: str = "results/discrete/heldout_gamma.csv"
    """the discrete table's held-out γ, beside the fitted nulls'"""
    runs: str | None = None
    """the runs' folder, to rewrite guidance_trajectory.csv from their TensorBoard events; None: read the CSV"""


REPORT_COLUMNS = ["env_id", "variant", "baseline", "step", "mean", "sd", "baseline_mean", "baseline_sd", "gap", "t",
                  "p", "p_holm", "detectable_gap", "n_seeds", "baseline_n_seeds"]  # fmt: skip


VALUE_COLUMNS = ["env_id", "variant", "baseline", "quantity", "value"]


def read_tasks(args: Args) -> tuple[list[dict], list[str]]:
    """Every task's sampled episodes under the folder (and the bc_train sets'), with the continuous table's baselines
    of the tasks that do not hold their own; InputError where none, or where two configurations of one task and
    variant would pool as one."""
    folder = Path(args.folder)
    task_files = sorted([*(path for path in folder.glob("*/episodes.csv") if path.parent.name not in SETS_APART),
                         *folder.glob(f"{BC_TRAIN_FOLDER}/*/episodes.csv")])  # fmt: skip
    if not task_files:
        raise InputError(f"no <task>/episodes.csv under {folder}")
    beyond = [r for path in task_files for r in read_rows(path)]
    envs = sorted({r["env_id"] for r in beyond})
    own = {(r["env_id"], r["variant"]) for r in beyond}
    table_path = Path(args.table)
    table = [r for r in read_rows(table_path) if r["env_id"] in envs and r["variant"] in BASELINES
             and (r["env_id"], r["variant"]) not in own] if table_path.exists() else []  # fmt: skip
    configs = defaultdict(set)
    for r in beyond + table:
        configs[(r["env_id"], r["variant"])].add(r["config"])
    if mixed := [f"{e} {v}: {', '.join(sorted(c))}" for (e, v), c in configs.items() if len(c) > 1]:
        raise InputError(f"several configurations of one task and variant would pool as one: {'; '.join(mixed)}")
    return beyond + table, envs


def report(args: Args) -> list[Path]:
    folder = Path(args.folder)
    episodes, envs = read_tasks(args)
    means = seed_means(episodes)
    variants_of = {env: sorted({v for (e, v, s, g) in means if e == env}, key=lambda v: (variant_rank(v), v))
                   for env in envs}  # fmt: skip
    rows, pooled = gamma_one_tests(means, variants_of)
    others = [r["p"] for r in rows if r["variant"] not in CLONING_VARIANTS]
    if args.runs is not None:
        write_trajectories(Path(args.runs), folder / "guidance_trajectory.csv")
    values = []  # every number of the glance tables, the γ-response and γ_train tables and the pooled counts
    heldout, distance, trajectories = (
        read_heldout(folder, Path(args.table_heldout)),
        read_goal_distance(folder),
        read_trajectories(folder),
    )
    lines = ["# Beyond the paper: the report", "",
             (f"Generated by `python -m beyond.report {args.folder} --table {args.table}` from the committed "
             "episode CSVs. Baselines of the paper's tasks come from the continuous table's runs (the same code "
             "class: the same algorithm trained with --compile, MuJoCo 2.3.7, on another CPU); Reacher-v4's are "
             "trained here."), "", *glance_section(means, variants_of, distance, others, values)]  # fmt: skip
    for env in envs:
        lines += task_section(env, means, variants_of[env], rows, pooled, heldout, distance, trajectories, values)
    bc_means, bc_fresh, bc_sets, bc_heldout = read_bc(folder, args)
    lines += bc_section(bc_means, bc_fresh, bc_sets, bc_heldout, values)
    cloning_tests = fall_tests(means, variants_of, variants=CLONING_VARIANTS)
    lines += cloning_section(cloning_tests, cloning_fresh_tests(means, variants_of, folder), values)
    lines += question_3_reading(values)
    lines += command_section(folder, values)
    dropout = dropout_sets.read(folder)
    lines += condition_dropout.section(dropout, values)
    written = [folder / "report.md", folder / "report.csv", folder / "report_values.csv", folder / "gamma_response.png"]
    if command_figure(folder, folder / COMMAND_FOLDER / "command_tracking.png"):
        written.append(folder / COMMAND_FOLDER / "command_tracking.png")
    if dropout_figure(dropout, folder / condition_dropout.FIGURE):
        written.append(folder / condition_dropout.FIGURE)
    if trajectories:
        written.append(folder / "guidance_trajectory.png")
        trajectory_figure(trajectories, written[-1])
    if distance:
        written.append(folder / "goal_distance.png")
        distance_figure(distance, variants_of, written[-1])
    if bc_sets:
        written.append(folder / "bc_null_gamma_response.png")
        bc_figure(bc_means, bc_sets, written[-1])
    write_atomic(written[0], "\n".join(lines))
    write_csv_atomic(written[1], REPORT_COLUMNS, rows)
    write_csv_atomic(written[2], VALUE_COLUMNS, values)
    gamma_response_figure(means, envs, variants_of, written[3])
    return written


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with one_line_errors():
        for path in report(args):
            print(path)


if __name__ == "__main__":
    main()
