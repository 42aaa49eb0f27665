"""Two sweeps of one grid, cell by cell: the same configurations trained on two software stacks
(MuJoCo versions, machines) or at two code revisions. It is the cross-stack check of the results:

    python -m paper_study.compare_sweeps results/continuous/episodes.csv \\
        results/continuous_device/episodes.csv --labels "MuJoCo 2.3.7 (table)" "MuJoCo 3.1.6" \\
        --output results/continuous_device/compare_table.md

A cell is (env, variant, checkpoint step, eval γ) with sampled actions and the learned null branch,
its statistic the mean over seeds of each seed's mean return, as everywhere in `plot_results.py` (paper_study.summary).
Each cell present in both sweeps gets Welch's t test on the two sets of seed means, Holm-corrected
over all the compared cells; per env and variant a sign test of first-above vs first-below. The
seeds are not paired: seed 1 on two stacks is two unrelated runs.
"""

import math
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tyro

from paper_study.agreement import compare_row, fmt, fmt_p, p_is, step_label
from paper_study.paper import paper_name, variant_rank
from paper_study.stats import ALPHA, correct_family, sign_test
from paper_study.summary import summarise, table_kinds
from pgg_utils.episodes import read_episodes, select_mode
from pgg_utils.files import InputError, one_line_errors, write_atomic


@dataclass
class Args:
    first: tyro.conf.Positional[str]
    """a sweep's episodes.csv (or its folder): the side whose differences are reported (first − second)"""
    second: tyro.conf.Positional[str]
    """the other sweep of the same grid"""
    labels: tuple[str, str] = ("first", "second")
    """names of the two sides in the report"""
    output: str | None = None
    """the Markdown report's path (printed to stdout if not given)"""


def cells(path: str) -> dict:
    """{(env, variant, step, eval γ): summary row} of one sweep; one configuration per env and variant
    (its config label and its exact training guidance and dropout)."""
    rows = summarise(select_mode(read_episodes([path], check=table_kinds), "sample", "learned"))
    configs = defaultdict(set)
    for r in rows:
        configs[(r["env_id"], r["variant"])].add((r["config"], r["train_guidance"], r["cond_dropout"]))
    for (env, variant), found in configs.items():
        if len(found) > 1:
            raise InputError(f"{path} has {len(found)} configurations of {variant} on {env}; compare one at a time")
    return {(r["env_id"], r["variant"], int(r["step"]), float(r["eval_guidance"])): r for r in rows}


def check_same_config(first: dict, second: dict) -> None:
    """The two sides of a cell must be one configuration, the stack (`mujoco=`) aside. A sweep from before
    configs were recorded has the variant alone, and is taken to be the variant's defaults."""
    for key in first.keys() & second.keys():
        fields = [{k: v for k, v in side[key]["config_fields"].items() if k != "mujoco"} for side in (first, second)]
        if fields[0] != fields[1]:
            raise InputError(f"{key[1]} on {key[0]} is '{first[key]['config']}' in one sweep and "
                             f"'{second[key]['config']}' in the other; compare one configuration")  # fmt: skip
        exact = [(side[key]["train_guidance"], side[key]["cond_dropout"]) for side in (first, second)]
        if exact[0] != exact[1]:  # the labels round both to 6 digits
            raise InputError(f"{key[1]} on {key[0]} trains with guidance, dropout {exact[0]} in one sweep and "
                             f"{exact[1]} in the other; compare one configuration")  # fmt: skip


def compare(first: dict, second: dict, second_label: str) -> list[dict]:
    """One row per cell of both sweeps, first against second (Welch), Holm over all of them."""
    shared = sorted(first.keys() & second.keys(), key=lambda k: (k[0], variant_rank(k[1]), k[1], k[2], k[3]))
    if not shared:
        raise InputError("the two sweeps have no cell (env, variant, step, eval γ) in common")
    check_same_config(first, second)
    out = []
    for key in shared:
        other = second[key]
        out.append(compare_row(first[key], second_label, float(other["mean"]), float(other["ci95"]),
                               float(other["sd"]), int(other["n_seeds"])))  # fmt: skip
    correct_family(out)
    return out


def report(rows: list[dict], labels: tuple[str, str], sources: tuple[str, str], unmatched: tuple[int, int]) -> str:
    """`unmatched`: how many cells of each sweep have no counterpart in the other (left out)."""
    first, second = labels
    n_sig = sum(r["significant"] == "True" for r in rows)
    lines = [f"# {first} against {second}, cell by cell", "",
             f"- {first}: `{sources[0]}` ({unmatched[0]} of its cells not in the other, left out)",
             f"- {second}: `{sources[1]}` ({unmatched[1]} of its cells not in the other, left out)", "",
             (f"{len(rows)} cells in both; **{n_sig} differ significantly** (Welch's t on the per-seed means, "
             f"Holm-corrected over the {len(rows)} cells, family-wise α = {ALPHA}). Sign test: {first} above "
             f"vs below {second} over a group's cells, ties left out; the cells of a group share their runs, so "
             "read its p-value as a description. diff = first − second."), "",
             (f"| env | variant | cells | differ after Holm | p < 0.05 uncorrected | {first} above / below (sign test) "
             f"| mean diff % (range) | {first} − {second}, final step, eval γ 1 |"),
             "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    groups = defaultdict(list)
    for r in rows:
        groups[(r["env_id"], r["variant"])].append(r)
    for (env, variant), group in groups.items():
        above, below, ties, p_sign = sign_test([r["diff"] for r in group])
        pct = [r["diff_pct"] for r in group if not math.isnan(r["diff_pct"])]
        raw = sum(1 for r in group if not math.isnan(r["p"]) and r["p"] < ALPHA)
        last_step = max(r["step"] for r in group)
        final = [r for r in group if r["step"] == last_step and r["eval_guidance"] == 1.0]
        final_text = "–"
        if final:
            f = final[0]
            final_text = (f"{step_label(f['step'])}: {fmt(f['our_mean'])} ± {fmt(f['our_ci95'])} vs "
                          f"{fmt(f['ref_mean'])} ± {fmt(f['ref_ci95'])} ({p_is(f['p'])})")  # fmt: skip
        spread = f"{np.mean(pct):+.1f}% ({min(pct):+.0f} to {max(pct):+.0f})" if pct else "–"
        lines.append(f"| {env} | {paper_name(variant)} | {len(group)} | "
                     f"{sum(r['significant'] == 'True' for r in group)} | {raw} | "
                     f"{above} / {below}{f', {ties} tied' if ties else ''}"
                     f"{f' ({p_is(p_sign)})' if above + below else ''} | {spread} | "
                     f"{final_text} |")  # fmt: skip
    lines += ["", "## Cells", "",
              f"| env | variant | step | eval γ | {first} | {second} | diff | diff % | Welch p | Holm p | g |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        mark = " ✗" if r["significant"] == "True" else ""
        lines.append(f"| {r['env_id']} | {paper_name(r['variant'])} | {step_label(r['step'])} | {r['eval_guidance']:g} | "
                     f"{fmt(r['our_mean'])} ± {fmt(r['our_ci95'])} | "
                     f"{fmt(r['ref_mean'])} ± {fmt(r['ref_ci95'])} | {r['diff']:+.1f} | "
                     f"{fmt(r['diff_pct'])} | {fmt_p(r['p'])} | {fmt_p(r['p_holm'])}{mark} | "
                     f"{fmt(r['hedges_g'], 2)} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    args = tyro.cli(Args)
    with one_line_errors():
        first, second = cells(args.first), cells(args.second)
        rows = compare(first, second, args.labels[1])
        unmatched = (len(first.keys() - second.keys()), len(second.keys() - first.keys()))
        text = report(rows, args.labels, (args.first, args.second), unmatched)
        if args.output:
            write_atomic(Path(args.output), text)
        else:
            print(text, end="")


if __name__ == "__main__":
    main()
