"""Question 3: a behaviour-cloned unconditional branch (the tables' agents with a fitted null) and cloning while
training, each against the agents' own null or the baselines, and what these tests say."""

import math
from pathlib import Path

import numpy as np

from beyond.cells import (
    cells_of,
    largest_vs_best,
    last_step,
    read_rows,
    record,
    response_at_last_step,
    seed_means,
    summary,
)
from beyond.sets import BASELINES, BC, BC_FOLDER, BC_TRAIN_FOLDER, CLONING_VARIANTS
from beyond.text import pct, points
from paper_study.agreement import fmt, fmt_p
from paper_study.paper import PAPER_ENVS, paper_name, variant_rank
from paper_study.stats import holm, median_relative_gap, paired_test, welch_of
from pgg_utils.files import read_csv
from pgg_utils.identity import config_fields


def read_bc(folder: Path, args) -> tuple[dict, dict, list[tuple[str, str]], dict]:
    """(means, fresh means, the (task, variant) of each fitted set, held-out rows) of the behaviour-cloned
    nulls: the fitted nulls' cells keyed `<variant> null=bc`, beside the same agents' cells with their own
    null (from the tables, at the fitted checkpoints' step) under the variant itself; on the sweep's episodes
    (seeds 10000+) and on the fresh ones (20000+: the fitted nulls' and the same agents' own, own_null_fresh.csv,
    every γ); held-out rows keyed so too."""
    if not (folder / BC_FOLDER / "episodes.csv").exists():
        return {}, {}, [], {}

    def both_nulls(fitted_csv: Path, tables: tuple[str, ...]) -> dict:
        fitted = read_rows(fitted_csv, "bc")
        step_of = {(r["env_id"], r["variant"]): r["step"] for r in fitted}
        own = [r for table in tables if Path(table).exists() for r in read_rows(Path(table))
               if step_of.get((r["env_id"], r["variant"])) == r["step"]]  # fmt: skip
        return seed_means(own + [{**r, "variant": r["variant"] + BC} for r in fitted]), step_of

    means, step_of = both_nulls(folder / BC_FOLDER / "episodes.csv", (args.table, args.discrete_table))
    fresh_csv, own_fresh = folder / BC_FOLDER / "heldout_fresh.csv", folder / BC_FOLDER / "own_null_fresh.csv"
    fresh = both_nulls(fresh_csv, (str(own_fresh),))[0] if fresh_csv.exists() else {}
    heldout = {}
    for table in (args.table_heldout, args.discrete_heldout, folder / BC_FOLDER / "heldout_gamma.csv"):
        if Path(table).exists():
            for r in read_csv(Path(table)):
                variant = r["variant"] + (BC if config_fields(r).get("null") == "bc" else "")
                if step_of.get((r["env_id"], r["variant"])) == r["step"]:
                    heldout[(r["env_id"], variant)] = r
    order = lambda key: (key[0] not in PAPER_ENVS["continuous"], key[0], variant_rank(key[1]))
    return means, fresh, sorted(step_of, key=order), heldout


def null_name(variant: str) -> str:
    """The null branch a set of agents is evaluated with: PPO's is never trained (all zeros)."""
    if variant.endswith(BC):
        return "behaviour-cloned"
    return "zero (untrained)" if variant == "ppo" else "learned"


def seeds_at(fresh: dict, env: str, key: str, gamma: float) -> dict:
    """{seed: mean return} of one side's fresh cell at the task's last step and γ ({} where unswept)."""
    return fresh.get((env, key, last_step(fresh, env), gamma), {}) if fresh else {}


def bc_section(
    means: dict, fresh: dict, sets: list[tuple[str, str]], heldout: dict, values_out: list[dict]
) -> list[str]:
    """Question 3: does a behaviour-cloned unconditional branch make γ a more useful or a more stable knob?"""
    if not sets:
        return []
    identical = sum(means.get((e, v + BC, last_step(means, e), 1.0)) == means.get((e, v, last_step(means, e), 1.0))
                    for e, v in sets)  # fmt: skip
    record(values_out, "", "", "question 3", "sets", len(sets))
    record(values_out, "", "", "question 3", "γ = 1 cells equal", identical)
    lines = ["## Question 3: a behaviour-cloned unconditional branch", "",
             ("The null embedding of each of the tables' PPO and γ_train 1.1 agents at its last step, fitted by maximum "
              "likelihood to the actions of the agent's own episodes at γ = 1 with the rest of the network frozen "
              "(`pgg_utils/bc_null.py`; results/beyond/bc_null), swept on the tables' episodes. These comparisons "
              "isolate the unconditional branch: the same agents, the same episodes, another null. What is cloned: "
              "with σ shared by both branches and held, the maximum-likelihood π(a|∅) = N(μ_∅, σ²) of a continuous agent "
              "puts μ_∅ at the mean of the agent's own actions, a single mean action; a true clone of the agent's "
              "behaviour, the marginal over its states with variance σ² + Var μ(s), is not representable with the "
              "paper's shared σ (a discrete agent's clone is its action frequencies, which a softmax can represent, "
              "and the frozen actor approaches). At γ = 1 the null "
              f"plays no part: in {identical} of the {len(sets)} sets every seed's γ = 1 return equals the table's. "
              "The other comparison the question asks for, a variant that clones the rollout's actions while it "
              "trains against the constant γ_train 1.1, is the next section's, on the tasks trained so far."), "",
             ("γ-response at the agents' last mark (means over seeds; the best γ chosen on these episodes) and that γ "
              "scored on fresh episodes (seeds 20000+) against γ = 1 there, ± its 95% CI."), "",
             "| task | agents | null | γ = 1 | best γ: return | largest γ: return | largest vs best | held-out γ: fresh gain |",
             "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    best_of = {}
    for env, variant in sets:
        for key in (variant, variant + BC):
            gammas, values = response_at_last_step(means, env, key)
            if any(math.isnan(v) for v in values):
                continue
            (best, drop), at_one = largest_vs_best(values), values[gammas.index(1.0)]
            best_of[(env, key)] = (gammas[best], gammas[-1])
            held = heldout.get((env, key))
            ci = (
                "n/a"
                if held is None or held["fresh_gain_ci95"] in ("", "nan")
                else f"{float(held['fresh_gain_ci95']):.1f}"
            )
            chosen = (
                "–" if held is None else f"{float(held['selected_gamma']):g}: {float(held['fresh_gain']):+.1f} ± {ci}"
            )
            for quantity, value in (("return at γ 1", at_one), ("best γ", gammas[best]), ("return at best γ", values[best]),
                                    ("largest γ", gammas[-1]), ("return at largest γ", values[-1]),
                                    ("largest γ vs best (%)", 100 * drop)):  # fmt: skip
                record(values_out, env, key, "question 3", quantity, value)
            lines.append(f"| {env} | {paper_name(variant)} | {null_name(key)} | {at_one:.1f} | {gammas[best]:g}: "
                         f"{values[best]:.1f} | {gammas[-1]:g}: {values[-1]:.1f} | {pct(drop)} | {chosen} |")  # fmt: skip
    tests = []
    for env, variant in sets:
        if (env, variant) not in best_of or (env, variant + BC) not in best_of:
            continue
        sides = {}
        for key in (variant, variant + BC):  # each side at its best γ of the sweep, scored on the fresh episodes
            best, largest = best_of[(env, key)]
            at_best, at_largest = seeds_at(fresh, env, key, best), seeds_at(fresh, env, key, largest)
            sides[key] = (at_best, {seed: (at_largest[seed] - value) / abs(value) for seed, value in at_best.items()
                                    if seed in at_largest and value != 0})  # fmt: skip
        cells_own, cells_bc = cells_of(means, env, variant), cells_of(means, env, variant + BC)
        common = sorted(c for c in set(cells_own) & set(cells_bc) if c[1] != 1.0)
        seeds = sorted(set.intersection(*(set(cells_bc[c]) for c in common)))
        block = np.array([[cells_bc[c][seed] for seed in seeds] for c in common])
        references = np.array([summary(cells_own[c])[0] for c in common])
        differences = [summary(cells_bc[c])[0] - summary(cells_own[c])[0] for c in common]
        tests.append({"env_id": env, "variant": variant, "best": best_of[(env, variant)][0],
                      "best_bc": best_of[(env, variant + BC)][0],
                      "fall": paired_test(sides[variant + BC][1], sides[variant][1]),
                      "return": paired_test(sides[variant + BC][0], sides[variant][0]),
                      "above": sum(d > 0 for d in differences), "below": sum(d < 0 for d in differences),
                      "cells": len(common), "gap": median_relative_gap([(block, references)])})  # fmt: skip
    for kind in ("fall", "return"):
        tested = [t[kind] for t in tests if t[kind] is not None]
        for test, p_holm in zip(tested, holm([t["p"] for t in tested])):
            test["p_holm"] = p_holm
    family = {kind: sum(t[kind] is not None for t in tests) for kind in ("fall", "return")}
    lines += ["", ("Is γ more stable, or more useful, with the cloned null? Each side's best γ is chosen on the sweep above "
                   "and scored on the fresh episodes, so that the test is not made on the episodes that chose it: each "
                   "seed's fall there from that γ to the largest, and its return there at that γ, the cloned null's "
                   "minus the agent's own, paired by seed (t test; Holm over the "
                   f"{family['fall']} fall and {family['return']} return tests apart; the difference one test detects "
                   "with 80% power at α = 0.05, before Holm; n/a where the seeds do not differ, e.g. at CartPole's "
                   "ceiling). Then every γ ≠ 1 cell of the sweep: how many lie above and below the own null's, and the "
                   "median relative gap with its exact bootstrap interval over seeds (the own null's means held fixed, "
                   "so the interval is the cloned side's uncertainty only)."), "",
              ("| task | agents | best γ: cloned (own) | fresh fall difference | p (Holm) | detectable | fresh return "
               "difference at best γ | p (Holm) | detectable | cells above / below | median gap [95% CI] |"),
              "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for t in tests:
        cells = []
        for kind, unit in (("fall", "pts"), ("return", "")):
            test = t[kind]
            if test is None:
                cells += ["n/a", "n/a", "n/a"]
                continue
            scale = 100 if unit else 1
            names = {"fall": ("fall difference (pts)", "fall detectable (pts)"),
                     "return": ("return difference at best γ", "return detectable")}[kind]  # fmt: skip
            for quantity, value in ((names[0], scale * test["difference"]), (f"{kind} p", test["p"]),
                                    (f"{kind} p Holm", test["p_holm"]), (names[1], scale * test["detectable"])):  # fmt: skip
                record(values_out, t["env_id"], t["variant"] + BC, t["variant"], quantity, value)
            shown = points if unit else (lambda x, sign=True: fmt(x))
            cells += [shown(test["difference"]), f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})",
                      shown(test["detectable"], sign=False)]  # fmt: skip
        for quantity, value in (("cells above", t["above"]), ("cells below", t["below"]), ("cells", t["cells"]),
                                ("median gap (%)", 100 * t["gap"][0]), ("median gap low (%)", 100 * t["gap"][1]),
                                ("median gap high (%)", 100 * t["gap"][2])):  # fmt: skip
            record(values_out, t["env_id"], t["variant"] + BC, t["variant"], quantity, value)
        lines.append(f"| {t['env_id']} | {paper_name(t['variant'])} | {t['best_bc']:g} ({t['best']:g}) | "
                     + " | ".join(cells) + f" | {t['above']} / {t['below']} | "
                     f"{pct(t['gap'][0])} [{pct(t['gap'][1])}, {pct(t['gap'][2])}] |")  # fmt: skip
    return [*lines, ""]


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
