"""Question 3: a behaviour-cloned unconditional branch (the tables' agents with a fitted null) and cloning while
training, each against the agents' own null or the baselines, and what these tests say."""

import math
from pathlib import Path

import numpy as np

from beyond.cells import (
    last_step,
    read_rows,
    record,
    response_at_last_step,
    seed_means,
)
from beyond.sets import BASELINES, BC_FOLDER, BC_TRAIN_FOLDER, CLONING_VARIANTS
from beyond.text import pct, points
from paper_study.agreement import fmt, fmt_p
from paper_study.paper import paper_name
from paper_study.stats import holm, welch_of


def fresh_side(means: dict, fresh: dict, env: str, variant: str) -> tuple[float, list[float], list[float]] | None:
    """A variant's best eval γ at the last mark, chosen on the sweep (`means`), and each seed's fall from it to the
    largest γ and its return at it, both measured on the fresh episodes (`fresh`); None where those lack either γ."""
    gammas, values = response_at_last_step(means, env, variant)
    if all(math.isnan(v) for v in values):
        return None
    last, best = last_step(means, env), gammas[int(np.nanargmax(values))]
    at_best, at_largest = fresh.get((env, variant, last, best)), fresh.get((env, variant, last, gammas[-1]))
    if not at_best or not at_largest:
        return None
    seeds = sorted(s for s in at_best if s in at_largest)
    return best, [(at_largest[s] - at_best[s]) / abs(at_best[s]) for s in seeds], [at_best[s] for s in seeds]


def cloning_fresh_tests(means: dict, variants_of: dict, folder: Path) -> list[dict]:
    """The cloning variant against each baseline as in fall_tests, each side's best γ chosen on the sweep and its
    fall and return measured on fresh episodes (seeds 20000+): the cloning sets' heldout_fresh.csv and the baselines'
    own_null_fresh.csv (the tables' agents with their own null at every γ), so the γ that is tested was not chosen
    on the episodes it is tested on. Welch's t, Holm over each kind's tests."""
    files = [*sorted(folder.glob(f"{BC_TRAIN_FOLDER}/*/heldout_fresh.csv")), folder / BC_FOLDER / "own_null_fresh.csv"]
    fresh = seed_means([r for path in files if path.exists() for r in read_rows(path)])
    rows = []
    for env in sorted(e for e, vs in variants_of.items() if CLONING_VARIANTS & set(vs)):
        for variant in (v for v in variants_of[env] if v in CLONING_VARIANTS):
            ours = fresh_side(means, fresh, env, variant)
            for baseline in (b for b in BASELINES if b in variants_of[env]):
                theirs = fresh_side(means, fresh, env, baseline)
                if ours is None or theirs is None or len(ours[1]) < 2 or len(theirs[1]) < 2:
                    continue
                fall, at_best = welch_of(ours[1], theirs[1]), welch_of(ours[2], theirs[2])
                rows.append({"env_id": env, "variant": variant, "baseline": baseline, "best": ours[0],
                             "baseline_best": theirs[0], "fall": fall["mean"], "baseline_fall": fall["baseline_mean"],
                             "p": fall["p"], "detectable": fall["detectable"], "return": at_best["mean"],
                             "baseline_return": at_best["baseline_mean"], "return_p": at_best["p"]})  # fmt: skip
    for row, p_holm, return_holm in zip(rows, holm([r["p"] for r in rows]), holm([r["return_p"] for r in rows])):
        row["p_holm"], row["return_p_holm"] = p_holm, return_holm
    return rows


def cloning_section(tests: list[dict], fresh_tests: list[dict], values_out: list[dict]) -> list[str]:
    """Question 3's other comparison: the variant that clones the rollout's actions while it trains against the
    constant γ_train 1.1, which isolates the cloning (the same γ_train), and against PPO; each side at its own
    best eval γ at the last mark (Welch's t over seeds, distinct runs; Holm over these tests alone)."""
    if not tests:
        return []
    lines = ["### Cloning while training", "",
             ("The variant that clones the rollout's actions by the null branch while it trains (γ_train 1.1, "
              "coefficient 0.1, the null embedding alone; results/beyond/bc_train) against the constant γ_train 1.1, "
              "which isolates the cloning, and against PPO: each side at its own best eval γ at the last mark (chosen "
              "on these episodes), each seed's fall from it to the largest γ and its return at it; Welch's t test "
              f"(distinct runs), Holm over these {len(tests)} tests of each kind, the difference one test detects "
              "with 80% power at α = 0.05, before Holm. Sets trained so far: "
              f"{', '.join(sorted({t['env_id'] for t in tests}))}; its held-out γ is in the task's section."), "",
             ("| task | baseline | best γ (baseline's) | fall | baseline's fall | difference | p (Holm) | detectable | "
              "return | baseline's return | p (Holm) |"), "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    lines += cloning_rows(tests, SWEEP_QUANTITIES, values_out)
    if fresh_tests:
        lines += ["", ("The best γ above is chosen on the episodes its fall is measured on, which inflates each side's "
                       "return there and so its fall, not by the same amount on both sides. The same tests with the choice and "
                       "the measurement apart: each side's best γ chosen on the sweep above, its fall and its return "
                       "measured on fresh episodes (seeds 20000+: the cloning sets' heldout_fresh.csv, the baselines' "
                       "bc_null/own_null_fresh.csv); Welch's t test, Holm over these "
                       f"{len(fresh_tests)} tests of each kind. These are the tests the verdict rests on."), "",
                  ("| task | baseline | best γ (baseline's) | fresh fall | baseline's | difference | p (Holm) | "
                   "detectable | fresh return | baseline's | p (Holm) |"), "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
        lines += cloning_rows(fresh_tests, FRESH_QUANTITIES, values_out)
    return [*lines, ""]


# The quantities of a cloning test recorded in report_values.csv, in the order of cloning_rows' values.
SWEEP_QUANTITIES = ("fall (%)", "baseline's fall (%)", "fall difference (pts)", "fall p", "fall p Holm",
                    "fall detectable (pts)", "return at best γ", "baseline's return at its best γ",
                    "return at best γ p", "return at best γ p Holm")  # fmt: skip


FRESH_QUANTITIES = ("fresh fall (%)", "baseline's fresh fall (%)", "fresh fall difference (pts)", "fresh fall p",
                    "fresh fall p Holm", "fresh fall detectable (pts)", "fresh return at best γ",
                    "baseline's fresh return at its best γ", "fresh return p", "fresh return p Holm")  # fmt: skip


def cloning_rows(tests: list[dict], quantities: tuple[str, ...], values_out: list) -> list[str]:
    """A table row per cloning test, its unrounded values recorded under `quantities`."""
    rows = []
    for t in tests:
        values = (100 * t["fall"], 100 * t["baseline_fall"], 100 * (t["fall"] - t["baseline_fall"]), t["p"],
                  t["p_holm"], 100 * t["detectable"], t["return"], t["baseline_return"], t["return_p"],
                  t["return_p_holm"])  # fmt: skip
        for quantity, value in zip(quantities, values, strict=True):
            record(values_out, t["env_id"], t["variant"], t["baseline"], quantity, value)
        rows.append(f"| {t['env_id']} | {paper_name(t['baseline'])} | {t['best']:g} ({t['baseline_best']:g}) | "
                    f"{pct(t['fall'])} | {pct(t['baseline_fall'])} | {points(t['fall'] - t['baseline_fall'])} | "
                    f"{fmt_p(t['p'])} ({fmt_p(t['p_holm'])}) | {points(t['detectable'], sign=False)} | "
                    f"{fmt(t['return'])} | {fmt(t['baseline_return'])} | {fmt_p(t['return_p'])} "
                    f"({fmt_p(t['return_p_holm'])}) |")  # fmt: skip
    return rows
