"""The condition-dropout section's Reacher-v4 part (the goal dropped in training) and "What the learned null is"
(learned_null.csv of each agent): each part's numbers computed once as tables (goal_tables, null_rows), its rows of
report_values.csv and its markdown written from them, its sentences templates (text.fill)."""

import numpy as np

from beyond.cells import record
from beyond.dropout_sets import LEARNED_NULL, Sets
from beyond.dropout_tests import (
    SECTION,
    against_gamma_one,
    against_others,
    cell,
    falls_and_rises,
    family,
    goal_gaps,
    named,
    record_family,
    record_welch,
    seeds_of,
)
from beyond.sets import (
    COMMAND_DROPOUT,
    COMMAND_ENV,
    COMMAND_NULL,
    COMMAND_SEEDS,
    COMMAND_SET,
    DROPOUT_FOLDER,
    GOAL_DROPOUT,
    GOAL_ENV,
    GOAL_SET,
)
from beyond.text import change_cell, fill, marks, name
from paper_study.agreement import fmt_p
from paper_study.paper import paper_name
from paper_study.stats import ALPHA

NOT_RUN = ("**Not run yet:** {where} holds no episode of {variant} (results/beyond/{folder}/run_all.sh trains, sweeps and "
           "scores the set): no numbers of Reacher-v4 with the goal dropped.")  # fmt: skip
NOT_COMPARABLE = "**Not comparable:** {where} does not exist: no baseline to compare with."
PARTIAL = ("**Partial set:** {gaps}. The tables below hold what there is; they are not the set's result, and a verdict "
           "waits for the whole set.")  # fmt: skip
DISTANCE = ("{marks}, the final distance to the goal (goal_distance.csv: the last observation's fingertip to target, the "
            "sweep's episodes), mean over seeds of the per-seed mean over episodes, and against γ = 1 its change, Holm p "
            "(over these {tests} tests) and the change one test detects: distance (change, p Holm; detectable); lower "
            "is closer.")  # fmt: skip
KNOB = ("The dropout set's per-seed change in distance from γ = 1 against each other variant's: Welch's t test, Holm over "
        "these {tests} tests; a negative difference comes closer with dropout.")  # fmt: skip
KNOB_HEAD = "| γ | against | dropout's change | its change | difference | p (Holm) | detectable |\n|---|---|---|---|---|---|---|"
VERDICT = ("**What these tests say, and no more.** With the goal dropped in training, {falls} of the {tests} tests of a γ "
           "above 1 against γ = 1 find a significant fall in the final distance after Holm{named_falls}, and {rises} a "
           "rise{named_rises}")  # fmt: skip
MOST = ("; its most negative change is {difference:+.4f} m at γ {gamma:g} (Holm p {p_holm:p}; one test detects "
        "{detectable:.4f})")  # fmt: skip
AGAINST = ". Against the other variants: {differing} of {tests} differences in change significant after Holm{named}."
AGAINST_ITEM = "; at γ {gamma:g} against {name} the dropout set's change {mean:+.4f} m against {baseline_mean:+.4f} (Holm p {p_holm:p})"
NULLS = ("For each agent at its last mark, the command (Reacher: the goal position) whose conditional policy π(a|s, c) is "
         "closest to π(a|s, ∅) in mean KL over the agent's own states at γ = 1 (`beyond/learned_null.py`: 5,000 states; "
         "a grid of commands from −1 to 4 m/s by 0.01, of goals on a 0.01 m lattice of [−0.25, 0.25]²). Beside it the "
         "KL there and the KL to the states' own condition (what guidance moves away from), and the median over states "
         "of how far each state's own closest condition lies from it: a null that is the policy at one fixed condition "
         "has a KL near 0 there and its states' closest conditions bunched on it; a condition-agnostic null does not.")  # fmt: skip
NULLS_HEAD = ("| task | variant (null) | seeds | closest condition, per seed | mean | KL there | KL to the own condition "
              "| per-state spread |\n|---|---|---|---|---|---|---|---|")  # fmt: skip
NULL_READING = ("{name}, {task}: KL {kl_low:.2g} to {kl_high:.2g} at its closest condition against {own_low:.2f} to "
                "{own_high:.2f} to the states' own")  # fmt: skip
NOT_MEASURED = ("Not measured yet: {missing} (`python -m beyond.learned_null <agents> --steps 1000000 --output "
                "<set>/{file}`).")  # fmt: skip
# Each task's learned nulls: (env, its name, its variants' nulls, the variants measured, the unit of a condition).
NULL_SETS = ((COMMAND_ENV, "command task", COMMAND_SET, (COMMAND_DROPOUT, COMMAND_NULL), "m/s"),
             (GOAL_ENV, GOAL_ENV, GOAL_SET, (GOAL_DROPOUT, "pgg_g1.1_goal"), "m"))  # fmt: skip


def goal_tables(sets: Sets) -> dict:
    """Reacher's tables: each variant's final distance at each γ against γ = 1 (a Holm family), and the dropout set's
    change from γ = 1 against each other variant's (Welch, a family)."""
    goal = sets.goal
    variants = [v for v in GOAL_SET if any(k[0] == v for k in goal)]
    gammas = sorted({g for (v, g) in goal})
    measure = lambda v, g: {s: d for s, (d, _) in goal.get((v, g), {}).items()}
    distance = family(against_gamma_one(variants, gammas, measure))
    return {"variants": variants, "gammas": gammas, "distance": distance,
            "gaps": goal_gaps(goal, GOAL_DROPOUT, sorted({g for (v, g) in goal if v != GOAL_DROPOUT})),
            "at": {(r["variant"], r["gamma"]): r for r in distance},
            "knob": against_others(variants, gammas, measure, GOAL_DROPOUT)}  # fmt: skip


def goal_values(t: dict) -> list[dict]:
    out = []
    record(out, GOAL_ENV, GOAL_DROPOUT, SECTION, "whole", float(not t["gaps"]))
    record_family(out, GOAL_ENV, t["distance"], "final distance")
    for variant in t["variants"]:
        record(out, GOAL_ENV, variant, SECTION, "seeds", seeds_of(t["distance"], variant))
    record_welch(out, GOAL_ENV, t["knob"], GOAL_DROPOUT, "final distance")
    return out


def goal_part(sets: Sets, values_out: list[dict]) -> list[str]:
    """Reacher-v4: does γ bring the agents trained with the goal dropped closer to the goal?"""
    if "goal" in sets.absent or not any(v == GOAL_DROPOUT for v, g in sets.goal):
        where = sets.absent.get("goal", f"{DROPOUT_FOLDER}/goal_distance.csv")
        return ["", fill(NOT_RUN, where=where, variant=GOAL_DROPOUT, folder=DROPOUT_FOLDER)]
    if "goal baselines" in sets.absent:
        return ["", fill(NOT_COMPARABLE, where=sets.absent["goal baselines"])]
    t = goal_tables(sets)
    values_out += goal_values(t)
    variants, gammas, distance, knob = t["variants"], t["gammas"], t["distance"], t["knob"]
    lines = ["", "### Reacher-v4, the goal dropped", ""]
    if t["gaps"]:
        lines += [fill(PARTIAL, gaps="; ".join(t["gaps"])), ""]
    lines += [fill(DISTANCE, marks=marks(sets.goal_steps, variants), tests=sum(r["test"] is not None for r in distance)), "",
              "| variant (null) | seeds | " + " | ".join(f"γ = {g:g}" for g in gammas) + " |", "|---|---|" + "---|" * len(gammas)]  # fmt: skip
    for variant in variants:
        shown = [change_cell(*cell(t["at"].get((variant, gamma))), 4) for gamma in gammas]
        lines.append(f"| {name(variant, GOAL_SET)} | {seeds_of(distance, variant)} | " + " | ".join(shown) + " |")
    lines += ["", fill(KNOB, tests=len(knob)), "", KNOB_HEAD]
    lines += [f"| {r['gamma']:g} | {name(r['baseline'], GOAL_SET)} | {r['mean']:+.4f} | {r['baseline_mean']:+.4f} | "
              f"{r['mean'] - r['baseline_mean']:+.4f} | {fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | {r['detectable']:.4f} |"
              for r in knob]  # fmt: skip
    if not t["gaps"]:
        above, falls, rises = falls_and_rises(distance, GOAL_DROPOUT)
        parts = [fill(VERDICT, falls=len(falls), tests=len(above), named_falls=named(falls, " m", 4), rises=len(rises),
                      named_rises=named(rises, " m", 4))]  # fmt: skip
        if above:
            best = min(above, key=lambda r: r["test"]["difference"])
            parts.append(fill(MOST, gamma=best["gamma"], **best["test"]))
        differing = [r for r in knob if r["p_holm"] < ALPHA]
        parts.append(fill(AGAINST, differing=len(differing), tests=len(knob), named="".join(
            fill(AGAINST_ITEM, **{**r, "name": name(r["baseline"], GOAL_SET)}) for r in differing)))  # fmt: skip
        lines += ["", "".join(parts)]
    return lines


def null_rows(sets: Sets) -> tuple[list[dict], list[str]]:
    """A row per measured agent set at its last mark (its seeds' closest conditions, KLs and spreads), and the sets not
    measured yet."""
    rows, missing = [], []
    for env, task, nulls, variants, unit in NULL_SETS:
        for variant in variants:
            found = [r for r in sets.nulls if r["env_id"] == env and r["variant"] == variant]
            if not found:
                missing.append(f"{paper_name(variant)} ({task})")
                continue
            last = max(int(r["step"]) for r in found)
            found = sorted((r for r in found if int(r["step"]) == last), key=lambda r: int(r["seed"]))
            if env == COMMAND_ENV:
                points = np.array([[float(r["pseudo_command"])] for r in found])
            else:
                points = np.array([[float(r["pseudo_goal_x"]), float(r["pseudo_goal_y"])] for r in found])
            rows.append({"env": env, "task": task, "variant": variant, "name": name(variant, nulls), "unit": unit,
                         "seeds": len(found), "points": points, "edges": sum(r["at_grid_edge"] == "yes" for r in found),
                         **{key: np.array([float(r[column]) for r in found]) for key, column in
                            (("kl", "kl_at_pseudo"), ("own", "kl_at_own"), ("spread", "per_state_spread"))}})  # fmt: skip
    return rows, missing


def null_values(rows: list[dict]) -> list[dict]:
    out = []
    for r in rows:
        where, points = (r["env"], r["variant"], f"{SECTION} learned null"), r["points"]
        if r["env"] == COMMAND_ENV:
            for quantity, value in (("pseudo-command mean", points.mean()), ("pseudo-command min", points.min()),
                                    ("pseudo-command max", points.max())):  # fmt: skip
                record(out, *where, quantity, value)
        else:
            record(out, *where, "pseudo-goal radius mean", np.linalg.norm(points, axis=1).mean())
        for quantity, value in (("KL at pseudo-condition mean", r["kl"].mean()), ("KL to own condition mean", r["own"].mean()),
                                ("per-state spread mean", r["spread"].mean()), ("seeds", r["seeds"])):  # fmt: skip
            record(out, *where, quantity, value)
    return out


def null_part(sets: Sets, values_out: list[dict]) -> list[str]:
    """What each condition null acts like: the command (goal) whose conditional policy is closest to it."""
    rows, missing = null_rows(sets)
    values_out += null_values(rows)
    lines = ["", "### What the learned null is", "", NULLS]
    if rows:
        lines += ["", NULLS_HEAD, *(null_row(r) for r in rows), ""]
        readings = [fill(NULL_READING, name=r["name"], task=r["task"], kl_low=r["kl"].min(), kl_high=r["kl"].max(),
                         own_low=r["own"].min(), own_high=r["own"].max()) for r in rows]  # fmt: skip
        lines.append(f"Per seed, {'; '.join(readings)}.")
    if missing:
        lines += ["", fill(NOT_MEASURED, missing="; ".join(missing), file=LEARNED_NULL)]
    return lines


def null_row(r: dict) -> str:
    points, unit = r["points"], r["unit"]
    if r["env"] == COMMAND_ENV:
        per_seed, mean = ", ".join(f"{p[0]:.2f}" for p in points), f"{points.mean():.2f} {unit}"
    else:
        per_seed = ", ".join(f"({x:.2f}, {y:.2f})" for x, y in points)
        mean = f"{np.linalg.norm(points, axis=1).mean():.3f} {unit} from the centre"
    seeds = f"{r['seeds']}" + ("" if r["seeds"] >= COMMAND_SEEDS else f" of {COMMAND_SEEDS} (partial)")
    return (f"| {r['task']} | {r['name']} | {seeds} | {per_seed}" + (f" ({r['edges']} at the grid's edge)" if r["edges"] else "")
            + f" | {mean} | {r['kl'].mean():.2g} | {r['own'].mean():.2f} | {r['spread'].mean():.3f} {unit} |")  # fmt: skip
