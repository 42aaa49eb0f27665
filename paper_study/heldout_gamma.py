"""The best eval γ, chosen on one sweep's episodes and reported on another's. `best_gamma` (plot_results)
picks the γ with the highest mean and reports that same mean; over 6–8 γ values and 5 seeds that maximum
is biased upward even where γ changes nothing. Here the choice and the report use disjoint episodes of
the same checkpoints (paper_study.selection):

    python eval_gamma_sweep.py RUNS --eval-seed 20000 --output runs/sweeps/fresh   # needs the checkpoints
    python -m paper_study.heldout_gamma results/discrete/episodes.csv runs/sweeps/fresh/episodes.csv \\
        --output runs/heldout/discrete

The first sweep selects γ per (env, configuration, step); the second, swept from the same run
directories with the same --gammas (it needs γ = 1 and each group's selected γ) and another --eval-seed
(episode k resets with eval_seed + k: the default 10000 and 20000 stay apart up to 10000 episodes),
reports it beside γ = 1 on its own episodes, with a paired t test across seeds (Holm over the tested
groups) and the selection bias (the selected γ's mean on the selection episodes minus on the fresh
ones). Sweeps whose episode seeds overlap are refused; a group the fresh sweep lacks is reported, not
dropped. That a seed is the same checkpoint in both is checked by its run name only: the episodes
record no checkpoint digest, so sweep both from the same, unchanged run directories.

Writes into --output, atomically, and prints each path:
  heldout_gamma.csv   one row per group (paper_study.selection.GROUP_COLUMNS)
  heldout_gamma.md    per env and variant the counts and medians, then the per-group table
"""

import math
from dataclasses import dataclass
from pathlib import Path

import tyro

from paper_study.agreement import fmt, fmt_p, step_label
from paper_study.paper import paper_name, variant_rank
from paper_study.selection import BASELINE_GAMMA, GROUP_COLUMNS, INCOMPLETE, TESTED, held_out, summary_by_env
from paper_study.stats import ALPHA
from pgg_utils.episodes import read_episodes, select_mode
from pgg_utils.files import one_line_errors, write_atomic, write_csv_atomic


@dataclass
class Args:
    selection: tyro.conf.Positional[str]
    """the episodes.csv (or its folder) of the sweep that selects γ"""
    fresh: tyro.conf.Positional[str]
    """the episodes.csv (or its folder) of a sweep of the same checkpoints with another --eval-seed"""
    output: str
    """the folder to write heldout_gamma.csv and heldout_gamma.md into"""
    policy: str = "sample"
    """the evaluation mode to compare: sampled actions (or `deterministic`, of a --deterministic sweep)"""
    null_branch: str = "learned"
    """the evaluation mode to compare: the learned null branch (or `uniform`, of a --uniform-null sweep, or `bc`, of fitted nulls)"""


def episodes(path: str, args: Args) -> list[dict]:
    return select_mode(read_episodes([path]), args.policy, args.null_branch)


def seed_range(rows: list[dict]) -> str:
    seeds = {int(r["episode_seed"]) for r in rows}
    return f"episode seeds {min(seeds)}–{max(seeds)}"


def gamma_text(gamma: float) -> str:
    return fmt(gamma) if math.isnan(gamma) else f"{gamma:g}"


def configuration_name(row: dict) -> str:
    """The paper's name of the variant, with the configuration label where it says more than the variant."""
    name = paper_name(row["variant"])
    return name if row["config"] == row["variant"] else f"{name} [{row['config']}]"


def report(rows: list[dict], unmatched: list[tuple], args: Args, ranges: tuple[str, str]) -> str:
    tested = sum(r["status"] == TESTED for r in rows)
    lines = [
        "# Best γ, chosen on one set of episodes and reported on another", "",
        f"- selection: `{args.selection}` ({ranges[0]})",
        f"- fresh: `{args.fresh}` ({ranges[1]})",
        f"- evaluation mode: policy {args.policy}, null branch {args.null_branch}", "",
        ("Per group (env, configuration, checkpoint step) the selected γ is the one with the highest mean over "
         "seeds of the per-seed mean return on the selection episodes (ties to the γ nearest 1). *In-sample gain*: "
         "its mean minus γ = 1's on those same episodes, what `best_gamma` implies. *Fresh gain*: the mean over "
         "seeds of its per-seed fresh mean minus γ = 1's, with a paired t test across seeds, Holm-corrected over "
         f"the {tested} groups where a γ other than 1 was selected (family-wise α = {ALPHA}). *Selection bias*: "
         "the selected γ's mean on the selection episodes minus on the fresh ones. Where γ = 1 is selected the "
         "fresh gain is 0 by construction; those groups are counted apart and left out of the gain medians."), "",
        ("| env | variant | groups | γ = 1 selected | other γ selected | of those, above γ = 1 on fresh | "
         "of those, significantly (Holm) | median in-sample gain | median fresh gain | median selection bias "
         "| incomplete |"),
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    for s in summary_by_env(rows):
        lines.append(f"| {s['env_id']} | {paper_name(s['variant'])} | {s['groups']} | {s['selected_baseline']} | "
                     f"{s['selected_other']} | {s['fresh_above']} | {s['fresh_above_significant']} | "
                     f"{fmt(s['median_selection_gain'], 2)} | {fmt(s['median_fresh_gain'], 2)} | "
                     f"{fmt(s['median_selection_bias'], 2)} | {s['incomplete']} |")  # fmt: skip
    incomplete = [r for r in rows if r["status"] == INCOMPLETE]
    if incomplete:
        lines += ["", f"**Groups that cannot be answered ({len(incomplete)})**, left out of counts and medians:", ""]
        for r in incomplete:
            lines.append(f"- {r['env_id']}, {configuration_name(r)}, {step_label(r['step'])}: {r['missing']}")
    if unmatched:
        lines += ["", f"Groups of the fresh sweep that the selection sweep lacks ({len(unmatched)}), left out:", ""]
        lines += [f"- {env}, {config}, {step_label(step)}" for env, _, config, _, _, step in unmatched]
    lines += ["", "## Groups", "",
              (f"| env | variant | step | seeds | selected γ (of) | selection: selected / γ = {BASELINE_GAMMA:g} | "
               f"fresh: selected / γ = {BASELINE_GAMMA:g} | fresh gain ± 95% CI | paired t p | Holm p | "
               "selection bias | status |"),
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        mark = " ✓" if r["significant"] == "True" else ""
        lines.append(f"| {r['env_id']} | {configuration_name(r)} | {step_label(r['step'])} | {r['n_seeds']} | "
                     f"{gamma_text(r['selected_gamma'])} ({r['candidates'].replace(';', ', ')}) | "
                     f"{fmt(r['selection_mean'])} / {fmt(r['selection_baseline'])} | "
                     f"{fmt(r['fresh_mean'])} / {fmt(r['fresh_baseline'])} | "
                     f"{fmt(r['fresh_gain'])} ± {fmt(r['fresh_gain_ci95'])} | {fmt_p(r['p'])} | "
                     f"{fmt_p(r['p_holm'])}{mark} | {fmt(r['selection_bias'])} | {r['status']} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    args = tyro.cli(Args)
    with one_line_errors():
        selection, fresh = episodes(args.selection, args), episodes(args.fresh, args)
        rows, unmatched = held_out(selection, fresh)
        rows.sort(key=lambda r: (r["env_id"], variant_rank(r["variant"]), r["variant"], r["config"], r["step"]))
        text = report(rows, unmatched, args, (seed_range(selection), seed_range(fresh)))
        output = Path(args.output)
        write_csv_atomic(output / "heldout_gamma.csv", GROUP_COLUMNS, rows)
        write_atomic(output / "heldout_gamma.md", text)
    for name in ("heldout_gamma.csv", "heldout_gamma.md"):
        print(output / name)


if __name__ == "__main__":
    main()
