"""The report's "At a glance": one table per question, the numbers its verdicts rest on (each task's section has the
rest). Each table's rows are computed once (schedule_rows, schedules.fall_tests, goals.distance_tests); its rows of
report_values.csv and its markdown rows are both written from them, its sentences from templates (text.fill)."""

import math

from beyond.cells import cells_of, largest_vs_best, record, response_at_last_step
from beyond.goals import distance_tests
from beyond.schedules import collapsed, fall_tests, scheduled_tasks
from beyond.sets import CLONING_VARIANTS, GOAL_VARIANTS
from beyond.text import count_of, fill, pct, points
from paper_study.agreement import fmt, fmt_p
from paper_study.paper import paper_name

SCHEDULES = ("Did scheduling or adapting γ_train remove the fall past a modest γ? At the last mark, from the means over "
             "seeds: the return at γ = 1, the best eval γ, the largest γ swept and how far its mean lies below the "
             "best's; and the runs whose return fell below half their best mark's, at γ = 1 and at their best eval γ "
             "of each mark. The best γ is chosen on these same episodes, which makes every variant's fall a little "
             "larger than a fresh sweep would.")  # fmt: skip
SCHEDULES_HEAD = ("| task | variant | γ = 1 | best γ: return | largest γ: return | largest vs best | fell at γ = 1 | "
                  "fell at its best γ |\n|---|---|---|---|---|---|---|---|")  # fmt: skip
SCHEDULE_ROW = ("| {env} | {name} | {at_one:.1f} | {best_gamma:g}: {best:.1f} | {largest_gamma:g}: {largest:.1f} | "
                "{drop:pct} | {fell_at_one} | {fell_at_best} |")  # fmt: skip
FALLS = ("Is the fall smaller than the baselines'? Each seed's fall at the last mark from its variant's best γ (above) to "
         "the largest, relative to its return at the best γ, and the mean of these falls (not the ratio of means "
         "above); against each baseline's, Welch's t test (Holm over these {falls} tests alone, and over them with the "
         "report's {gamma_one} γ = 1 tests), and the difference in falls one test detects with 80% power at α = 0.05, "
         "before Holm. A negative difference is a larger fall than the baseline's. A variant whose best γ lies nearer "
         "the largest has less room to fall: the best γ of each side is shown.")  # fmt: skip
FALLS_HEAD = ("| task | variant | baseline | best γ (baseline's) | fall | baseline's fall | difference | p (Holm) | "
              "Holm with the γ = 1 tests | detectable difference |\n|---|---|---|---|---|---|---|---|---|---|")  # fmt: skip
RETURNS = ("Does a schedule cost return at its best γ? The same seeds' returns at each side's best γ (as above): Welch's "
           "t test, Holm over these tests alone, and the difference one test detects with 80% power at α = 0.05, "
           "before Holm.")  # fmt: skip
RETURNS_HEAD = ("| task | variant | baseline | best γ (baseline's) | return | baseline's return | difference | "
                "p (Holm) | detectable difference |\n|---|---|---|---|---|---|---|---|---|")  # fmt: skip
GOALS = ("Does guiding on the goal give a knob that state guidance lacks? The final distance to the goal (mean over "
         "seeds) at γ = 1, at the eval γ that brings it closest (chosen on these episodes), and at the largest γ swept; "
         "then, paired by seed, how many seeds end farther from the goal at the largest γ than at γ = 1, and a t test "
         "of the seeds' changes (Holm over these tests); intervals are in each task's section.")  # fmt: skip
GOALS_HEAD = ("| task | variant | γ = 1 | closest γ: distance | largest γ: distance | largest vs γ = 1 | seeds farther | "
              "p (Holm) |\n|---|---|---|---|---|---|---|---|")  # fmt: skip
GOAL_ROW = ("| {env_id} | {name} | {at_one:.4f} | {closest_gamma:g}: {closest:.4f} | {largest_gamma:g}: {largest:.4f} | "
            "{change:pct} | {farther} of {seeds} | {p:p} ({p_holm:p}) |")  # fmt: skip


def schedule_rows(means: dict, variants_of: dict) -> list[dict]:
    """Each variant of the schedules' tasks (not the goal's or the cloning's) swept at every γ of its task's last step:
    its return at γ = 1, at its best γ and at the largest, the relative fall, and its seeds that fell."""
    rows = []
    for env in scheduled_tasks(variants_of):
        for variant in (v for v in variants_of[env] if v not in GOAL_VARIANTS | CLONING_VARIANTS):
            gammas, values = response_at_last_step(means, env, variant)
            cells = cells_of(means, env, variant)
            if 1.0 not in gammas or any(math.isnan(v) for v in values):
                continue  # a variant not swept at every γ of the task's last step
            best, drop = largest_vs_best(values)
            rows.append({"env": env, "variant": variant, "at_one": values[gammas.index(1.0)], "best_gamma": gammas[best],
                         "best": values[best], "largest_gamma": gammas[-1], "largest": values[-1], "drop": drop,
                         "seeds": len(cells[(max(s for s, g in cells), 1.0)]),
                         "fell": [collapsed(cells), collapsed(cells, every_gamma=True)]})  # fmt: skip
    return rows


def glance_values(
    schedules: list[dict], falls: list[dict] | None, gamma_one_p: list[float], goals: list[dict]
) -> list[dict]:
    """The glance tables' rows of report_values.csv, unrounded (`falls` None where no task has a schedule)."""
    out = []
    for r in schedules:
        for quantity, value in (("return at γ 1", r["at_one"]), ("best γ", r["best_gamma"]), ("return at best γ", r["best"]),
                                ("largest γ", r["largest_gamma"]), ("return at largest γ", r["largest"]),
                                ("largest γ vs best (%)", 100 * r["drop"]), ("seeds", r["seeds"]),
                                *((f"fell at {at}", len(f)) for at, f in zip(("γ 1", "best γ"), r["fell"]) if f is not None)):  # fmt: skip
            record(out, r["env"], r["variant"], "", quantity, value)
    if falls is not None:
        record(out, "", "", "", "fall tests", len(falls))
        record(out, "", "", "", "γ = 1 tests", len(gamma_one_p))
    for r in falls or []:
        for quantity, value in (("fall (%)", 100 * r["fall"]), ("baseline's fall (%)", 100 * r["baseline_fall"]),
                                ("fall difference (pts)", 100 * (r["fall"] - r["baseline_fall"])), ("fall p", r["p"]),
                                ("fall p Holm", r["p_holm"]), ("fall p Holm with the γ = 1 tests", r["p_holm_with_gamma_one"]),
                                ("fall detectable (pts)", 100 * r["detectable"]), ("return at best γ", r["return"]),
                                ("baseline's return at its best γ", r["baseline_return"]),
                                ("return difference at best γ", r["return"] - r["baseline_return"]),
                                ("return at best γ p", r["return_p"]), ("return at best γ p Holm", r["return_p_holm"]),
                                ("return at best γ detectable", r["return_detectable"])):  # fmt: skip
            record(out, r["env_id"], r["variant"], r["baseline"], quantity, value)
    for r in goals:
        for quantity, value in (("distance at γ 1", r["at_one"]), ("closest γ", r["closest_gamma"]),
                                ("distance at closest γ", r["closest"]), ("largest γ", r["largest_gamma"]),
                                ("distance at largest γ", r["largest"]), ("distance largest vs γ 1 (%)", 100 * r["change"]),
                                ("seeds farther", r["farther"]), ("seeds", r["seeds"]), ("distance p", r["p"]),
                                ("distance p Holm", r["p_holm"])):  # fmt: skip
            record(out, r["env_id"], r["variant"], "", quantity, value)
    return out


def glance_section(means: dict, variants_of: dict, distance: dict, gamma_one_p: list[float],
                   values_out: list[dict]) -> list[str]:  # fmt: skip
    """One table per question, the numbers the verdicts rest on; each task's section below has the rest."""
    scheduled = bool(scheduled_tasks(variants_of))
    schedules = schedule_rows(means, variants_of) if scheduled else []
    falls = fall_tests(means, variants_of, gamma_one_p) if scheduled else None
    goals = [{**r, "change": (r["largest"] - r["at_one"]) / r["at_one"]} for r in distance_tests(distance, variants_of)]
    values_out += glance_values(schedules, falls, gamma_one_p, goals)
    lines = ["## At a glance", ""]
    if scheduled:
        lines += [SCHEDULES, "", SCHEDULES_HEAD]
        lines += [fill(SCHEDULE_ROW, **r, name=paper_name(r["variant"]), fell_at_one=count_of(r["fell"][0], r["seeds"]),
                       fell_at_best=count_of(r["fell"][1], r["seeds"])) for r in schedules]  # fmt: skip
        lines += ["", fill(FALLS, falls=len(falls), gamma_one=len(gamma_one_p)), "", FALLS_HEAD]
        lines += [f"| {r['env_id']} | {paper_name(r['variant'])} | {paper_name(r['baseline'])} | {r['best']:g} "
                  f"({r['baseline_best']:g}) | {pct(r['fall'])} | {pct(r['baseline_fall'])} | "
                  f"{points(r['fall'] - r['baseline_fall'])} | {fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | "
                  f"{fmt_p(r['p_holm_with_gamma_one'])} | {points(r['detectable'], sign=False)} |" for r in falls]  # fmt: skip
        lines += ["", RETURNS, "", RETURNS_HEAD]
        lines += [f"| {r['env_id']} | {paper_name(r['variant'])} | {paper_name(r['baseline'])} | {r['best']:g} "
                  f"({r['baseline_best']:g}) | {fmt(r['return'])} | {fmt(r['baseline_return'])} | "
                  f"{fmt(r['return'] - r['baseline_return'])} | {fmt_p(r['return_p'])} "
                  f"({fmt_p(r['return_p_holm'])}) | {fmt(r['return_detectable'])} |" for r in falls]  # fmt: skip
        lines.append("")
    if goals:
        lines += [GOALS, "", GOALS_HEAD]
        lines += [fill(GOAL_ROW, **r, name=paper_name(r["variant"])) for r in goals]
        lines.append("")
    return lines
