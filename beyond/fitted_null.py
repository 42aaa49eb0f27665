"""Question 3's first comparison: the tables' agents with a behaviour-cloned null (pgg_utils/bc_null.py,
results/beyond/bc_null) against the same agents with their own null, on the same episodes. read_bc reads the sets;
fitted_tables computes the section's tables once, fitted_values gives report_values.csv's rows and bc_section the
markdown, both from them; its sentences are templates (text.fill)."""

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
from beyond.sets import BC, BC_FOLDER
from beyond.text import fill, pct, points
from paper_study.agreement import fmt, fmt_p
from paper_study.paper import PAPER_ENVS, paper_name, variant_rank
from paper_study.stats import median_relative_gap, paired_test, set_holm
from pgg_utils.files import read_csv
from pgg_utils.identity import config_fields

INTRO = ("The null embedding of each of the tables' PPO and γ_train 1.1 agents at its last step, fitted by maximum "
         "likelihood to the actions of the agent's own episodes at γ = 1 with the rest of the network frozen "
         "(`pgg_utils/bc_null.py`; results/beyond/bc_null), swept on the tables' episodes. These comparisons "
         "isolate the unconditional branch: the same agents, the same episodes, another null. What is cloned: "
         "with σ shared by both branches and held, the maximum-likelihood π(a|∅) = N(μ_∅, σ²) of a continuous agent "
         "puts μ_∅ at the mean of the agent's own actions, a single mean action; a true clone of the agent's "
         "behaviour, the marginal over its states with variance σ² + Var μ(s), is not representable with the "
         "paper's shared σ (a discrete agent's clone is its action frequencies, which a softmax can represent, "
         "and the frozen actor approaches). At γ = 1 the null plays no part: in {identical} of the {sets} sets every "
         "seed's γ = 1 return equals the table's. The other comparison the question asks for, a variant that clones "
         "the rollout's actions while it trains against the constant γ_train 1.1, is the next section's, on the tasks "
         "trained so far.")  # fmt: skip
RESPONSE = ("γ-response at the agents' last mark (means over seeds; the best γ chosen on these episodes) and that γ "
            "scored on fresh episodes (seeds 20000+) against γ = 1 there, ± its 95% CI.")  # fmt: skip
RESPONSE_HEAD = ("| task | agents | null | γ = 1 | best γ: return | largest γ: return | largest vs best | held-out γ: "
                 "fresh gain |\n|---|---|---|---|---|---|---|---|")  # fmt: skip
RESPONSE_ROW = ("| {env} | {agents} | {null} | {at_one:.1f} | {best_gamma:g}: {best:.1f} | {largest_gamma:g}: "
                "{largest:.1f} | {drop:pct} | {chosen} |")  # fmt: skip
TESTS = ("Is γ more stable, or more useful, with the cloned null? Each side's best γ is chosen on the sweep above and "
         "scored on the fresh episodes, so that the test is not made on the episodes that chose it: each seed's fall "
         "there from that γ to the largest, and its return there at that γ, the cloned null's minus the agent's own, "
         "paired by seed (t test; Holm over the {falls} fall and {returns} return tests apart; the difference one test "
         "detects with 80% power at α = 0.05, before Holm; n/a where the seeds do not differ, e.g. at CartPole's "
         "ceiling). Then every γ ≠ 1 cell of the sweep: how many lie above and below the own null's, and the median "
         "relative gap with its exact bootstrap interval over seeds (the own null's means held fixed, so the interval "
         "is the cloned side's uncertainty only).")  # fmt: skip
TESTS_HEAD = ("| task | agents | best γ: cloned (own) | fresh fall difference | p (Holm) | detectable | fresh return "
              "difference at best γ | p (Holm) | detectable | cells above / below | median gap [95% CI] |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|")  # fmt: skip
# Each test's quantities in report_values.csv: (its difference, its detectable difference, their scale).
KINDS = {"fall": ("fall difference (pts)", "fall detectable (pts)", 100),
         "return": ("return difference at best γ", "return detectable", 1)}  # fmt: skip


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


def fitted_tables(means: dict, fresh: dict, sets: list[tuple[str, str]], heldout: dict) -> dict:
    """{"sets", "identical" (sets whose γ = 1 cells equal the table's), "response": a row per side with its γ-response
    and held-out row, "tests": per set, the fall and return tests on fresh episodes (Holm over each kind) and the
    sweep's γ ≠ 1 cells against the own null's}."""
    identical = sum(means.get((e, v + BC, last_step(means, e), 1.0)) == means.get((e, v, last_step(means, e), 1.0))
                    for e, v in sets)  # fmt: skip
    response, best_of = [], {}
    for env, variant in sets:
        for key in (variant, variant + BC):
            gammas, values = response_at_last_step(means, env, key)
            if any(math.isnan(v) for v in values):
                continue
            best, drop = largest_vs_best(values)
            best_of[(env, key)] = (gammas[best], gammas[-1])
            response.append({"env": env, "variant": variant, "key": key, "at_one": values[gammas.index(1.0)],
                             "best_gamma": gammas[best], "best": values[best], "largest_gamma": gammas[-1],
                             "largest": values[-1], "drop": drop, "held": heldout.get((env, key))})  # fmt: skip
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
    for kind in KINDS:
        set_holm([t[kind] for t in tests])
    return {"sets": len(sets), "identical": identical, "response": response, "tests": tests}


def fitted_values(t: dict) -> list[dict]:
    """The section's rows of report_values.csv, in the order of its tables."""
    out = []
    record(out, "", "", "question 3", "sets", t["sets"])
    record(out, "", "", "question 3", "γ = 1 cells equal", t["identical"])
    for r in t["response"]:
        for quantity, value in (("return at γ 1", r["at_one"]), ("best γ", r["best_gamma"]), ("return at best γ", r["best"]),
                                ("largest γ", r["largest_gamma"]), ("return at largest γ", r["largest"]),
                                ("largest γ vs best (%)", 100 * r["drop"])):  # fmt: skip
            record(out, r["env"], r["key"], "question 3", quantity, value)
    for r in t["tests"]:
        for kind, (difference, detectable, scale) in KINDS.items():
            if (test := r[kind]) is not None:
                for quantity, value in ((difference, scale * test["difference"]), (f"{kind} p", test["p"]),
                                        (f"{kind} p Holm", test["p_holm"]), (detectable, scale * test["detectable"])):  # fmt: skip
                    record(out, r["env_id"], r["variant"] + BC, r["variant"], quantity, value)
        for quantity, value in (("cells above", r["above"]), ("cells below", r["below"]), ("cells", r["cells"]),
                                ("median gap (%)", 100 * r["gap"][0]), ("median gap low (%)", 100 * r["gap"][1]),
                                ("median gap high (%)", 100 * r["gap"][2])):  # fmt: skip
            record(out, r["env_id"], r["variant"] + BC, r["variant"], quantity, value)
    return out


def bc_section(
    means: dict, fresh: dict, sets: list[tuple[str, str]], heldout: dict, values_out: list[dict]
) -> list[str]:
    """Question 3: does a behaviour-cloned unconditional branch make γ a more useful or a more stable knob?"""
    if not sets:
        return []
    t = fitted_tables(means, fresh, sets, heldout)
    values_out += fitted_values(t)
    lines = ["## Question 3: a behaviour-cloned unconditional branch", "", fill(INTRO, identical=t["identical"], sets=t["sets"]),
             "", RESPONSE, "", RESPONSE_HEAD]  # fmt: skip
    lines += [fill(RESPONSE_ROW, **r, agents=paper_name(r["variant"]), null=null_name(r["key"]), chosen=held_cell(r["held"]))
              for r in t["response"]]  # fmt: skip
    falls, returns = (sum(r[kind] is not None for r in t["tests"]) for kind in KINDS)
    lines += ["", fill(TESTS, falls=falls, returns=returns), "", TESTS_HEAD]
    for r in t["tests"]:
        cells = []
        for kind, shown in (("fall", points), ("return", lambda x, sign=True: fmt(x))):
            test = r[kind]
            cells += ["n/a"] * 3 if test is None else [shown(test["difference"]), f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})",
                                                       shown(test["detectable"], sign=False)]  # fmt: skip
        lines.append(f"| {r['env_id']} | {paper_name(r['variant'])} | {r['best_bc']:g} ({r['best']:g}) | " + " | ".join(cells)
                     + f" | {r['above']} / {r['below']} | {pct(r['gap'][0])} [{pct(r['gap'][1])}, {pct(r['gap'][2])}] |")  # fmt: skip
    return [*lines, ""]


def held_cell(held: dict | None) -> str:
    """A side's held-out γ and its fresh gain ± 95% CI (n/a where the CI is undefined); – where none was chosen."""
    if held is None:
        return "–"
    ci = "n/a" if held["fresh_gain_ci95"] in ("", "nan") else f"{float(held['fresh_gain_ci95']):.1f}"
    return f"{float(held['selected_gamma']):g}: {float(held['fresh_gain']):+.1f} ± {ci}"
