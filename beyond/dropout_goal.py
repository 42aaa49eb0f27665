"""The condition-dropout section's Reacher-v4 part (the goal dropped in training) and "What the learned null is"
(learned_null.csv of each agent)."""

import numpy as np

from beyond.cells import record
from beyond.dropout_sets import LEARNED_NULL, Sets
from beyond.dropout_tests import (
    SECTION,
    against_gamma_one,
    against_others,
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
from beyond.text import marks, name
from paper_study.agreement import fmt_p
from paper_study.paper import paper_name
from paper_study.stats import ALPHA


def goal_part(sets: Sets, values_out: list[dict]) -> list[str]:
    """Reacher-v4: does γ bring the agents trained with the goal dropped closer to the goal?"""
    if "goal" in sets.absent or not any(v == GOAL_DROPOUT for v, g in sets.goal):
        where = sets.absent.get("goal", f"{DROPOUT_FOLDER}/goal_distance.csv")
        return ["", (f"**Not run yet:** {where} holds no episode of {GOAL_DROPOUT} (results/beyond/{DROPOUT_FOLDER}/"
                     "run_all.sh trains, sweeps and scores the set): no numbers of Reacher-v4 with the goal dropped.")]  # fmt: skip
    if "goal baselines" in sets.absent:
        return ["", f"**Not comparable:** {sets.absent['goal baselines']} does not exist: no baseline to compare with."]
    env, goal = GOAL_ENV, sets.goal
    variants = [v for v in GOAL_SET if any(k[0] == v for k in goal)]
    gammas = sorted({g for (v, g) in goal})
    measure = lambda v, g: {s: d for s, (d, _) in goal.get((v, g), {}).items()}
    gaps = goal_gaps(goal, GOAL_DROPOUT, sorted({g for (v, g) in goal if v != GOAL_DROPOUT}))
    record(values_out, env, GOAL_DROPOUT, SECTION, "whole", float(not gaps))
    lines = ["", "### Reacher-v4, the goal dropped", ""]
    if gaps:
        lines += [(f"**Partial set:** {'; '.join(gaps)}. The tables below hold what there is; they are not the set's "
                   "result, and a verdict waits for the whole set."), ""]  # fmt: skip
    distance = family(against_gamma_one(variants, gammas, measure))
    record_family(values_out, env, distance, "final distance")
    for variant in variants:
        record(values_out, env, variant, SECTION, "seeds", seeds_of(distance, variant))
    lines += [(f"{marks(sets.goal_steps, variants)}, the final distance to the goal (goal_distance.csv: the last observation's "
               "fingertip to target, the sweep's episodes), mean over seeds of the per-seed mean over episodes, and "
               f"against γ = 1 its change, Holm p (over these {sum(r['test'] is not None for r in distance)} tests) and "
               "the change one test detects: distance (change, p Holm; detectable); lower is closer."), "",
              "| variant (null) | seeds | " + " | ".join(f"γ = {g:g}" for g in gammas) + " |",
              "|---|---|" + "---|" * len(gammas)]  # fmt: skip
    at = {(r["variant"], r["gamma"]): r for r in distance}
    for variant in variants:
        shown = []
        for gamma in gammas:
            r = at.get((variant, gamma))
            if r is None:
                shown.append("–")
                continue
            mean, test = float(np.mean(list(r["values"].values()))), r["test"]
            shown.append(f"{mean:.4f}" if test is None else
                         f"{mean:.4f} ({test['difference']:+.4f}, {fmt_p(test['p_holm'])}; {test['detectable']:.4f})")  # fmt: skip
        lines.append(f"| {name(variant, GOAL_SET)} | {seeds_of(distance, variant)} | " + " | ".join(shown) + " |")
    knob = against_others(variants, gammas, measure, GOAL_DROPOUT)
    record_welch(values_out, env, knob, GOAL_DROPOUT, "final distance")
    lines += ["", ("The dropout set's per-seed change in distance from γ = 1 against each other variant's: Welch's t "
                   f"test, Holm over these {len(knob)} tests; a negative difference comes closer with dropout."), "",
              "| γ | against | dropout's change | its change | difference | p (Holm) | detectable |",
              "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in knob:
        lines.append(f"| {r['gamma']:g} | {name(r['baseline'], GOAL_SET)} | {r['mean']:+.4f} | {r['baseline_mean']:+.4f} | "
                     f"{r['mean'] - r['baseline_mean']:+.4f} | {fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | "
                     f"{r['detectable']:.4f} |")  # fmt: skip
    if not gaps:
        above, falls, rises = falls_and_rises(distance, GOAL_DROPOUT)
        parts = [(f"**What these tests say, and no more.** With the goal dropped in training, {len(falls)} of the "
                  f"{len(above)} tests of a γ above 1 against γ = 1 find a significant fall in the final distance after "
                  f"Holm{named(falls, ' m', 4)}, and {len(rises)} a rise{named(rises, ' m', 4)}")]  # fmt: skip
        if above:
            best = min(above, key=lambda r: r["test"]["difference"])
            parts.append(f"; its most negative change is {best['test']['difference']:+.4f} m at γ {best['gamma']:g} (Holm p "
                         f"{fmt_p(best['test']['p_holm'])}; one test detects {best['test']['detectable']:.4f})")  # fmt: skip
        differing = [r for r in knob if r["p_holm"] < ALPHA]
        parts.append(f". Against the other variants: {len(differing)} of {len(knob)} differences in change significant "
                     "after Holm" + "".join(f"; at γ {r['gamma']:g} against {name(r['baseline'], GOAL_SET)} the dropout "
                                            f"set's change {r['mean']:+.4f} m against {r['baseline_mean']:+.4f} (Holm p "
                                            f"{fmt_p(r['p_holm'])})" for r in differing) + ".")  # fmt: skip
        lines += ["", "".join(parts)]
    return lines


def null_part(sets: Sets, values_out: list[dict]) -> list[str]:
    """What each condition null acts like: the command (goal) whose conditional policy is closest to it."""
    lines = ["", "### What the learned null is", "",
             ("For each agent at its last mark, the command (Reacher: the goal position) whose conditional policy "
              "π(a|s, c) is closest to π(a|s, ∅) in mean KL over the agent's own states at γ = 1 "
              "(`beyond/learned_null.py`: 5,000 states; a grid of commands from −1 to 4 m/s by 0.01, of goals on "
              "a 0.01 m lattice of [−0.25, 0.25]²). Beside it the KL there and the KL to the states' own condition "
              "(what guidance moves away from), and the median over states of how far each state's own closest "
              "condition lies from it: a null that is the policy at one fixed condition has a KL near 0 there and its "
              "states' closest conditions bunched on it; a condition-agnostic null does not.")]  # fmt: skip
    sets_of = ((COMMAND_ENV, "command task", COMMAND_SET, (COMMAND_DROPOUT, COMMAND_NULL), "m/s"),
               (GOAL_ENV, GOAL_ENV, GOAL_SET, (GOAL_DROPOUT, "pgg_g1.1_goal"), "m"))  # fmt: skip
    table = ["", ("| task | variant (null) | seeds | closest condition, per seed | mean | KL there | KL to the own "
                  "condition | per-state spread |"), "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    missing = []
    readings = []
    for env, task, nulls, variants, unit in sets_of:
        for variant in variants:
            rows = [r for r in sets.nulls if r["env_id"] == env and r["variant"] == variant]
            if not rows:
                missing.append(f"{paper_name(variant)} ({task})")
                continue
            last = max(int(r["step"]) for r in rows)
            rows = sorted((r for r in rows if int(r["step"]) == last), key=lambda r: int(r["seed"]))
            seeds = f"{len(rows)}" + ("" if len(rows) >= COMMAND_SEEDS else f" of {COMMAND_SEEDS} (partial)")
            if env == COMMAND_ENV:
                points = np.array([[float(r["pseudo_command"])] for r in rows])
                per_seed_text = ", ".join(f"{p[0]:.2f}" for p in points)
                mean_text = f"{points.mean():.2f} {unit}"
                for quantity, value in (("pseudo-command mean", points.mean()), ("pseudo-command min", points.min()),
                                        ("pseudo-command max", points.max())):  # fmt: skip
                    record(values_out, env, variant, f"{SECTION} learned null", quantity, value)
            else:
                points = np.array([[float(r["pseudo_goal_x"]), float(r["pseudo_goal_y"])] for r in rows])
                radius = np.linalg.norm(points, axis=1)
                per_seed_text = ", ".join(f"({x:.2f}, {y:.2f})" for x, y in points)
                mean_text = f"{radius.mean():.3f} {unit} from the centre"
                record(values_out, env, variant, f"{SECTION} learned null", "pseudo-goal radius mean", radius.mean())
            edges = sum(r["at_grid_edge"] == "yes" for r in rows)
            kl, own = (np.array([float(r[k]) for r in rows]) for k in ("kl_at_pseudo", "kl_at_own"))
            spread = np.array([float(r["per_state_spread"]) for r in rows])
            for quantity, value in (("KL at pseudo-condition mean", kl.mean()), ("KL to own condition mean", own.mean()),
                                    ("per-state spread mean", spread.mean()), ("seeds", len(rows))):  # fmt: skip
                record(values_out, env, variant, f"{SECTION} learned null", quantity, value)
            table.append(f"| {task} | {name(variant, nulls)} | {seeds} | {per_seed_text}"
                         + (f" ({edges} at the grid's edge)" if edges else "") + f" | {mean_text} | {kl.mean():.2g} | "
                         f"{own.mean():.2f} | {spread.mean():.3f} {unit} |")  # fmt: skip
            readings.append(f"{name(variant, nulls)}, {task}: KL {kl.min():.2g} to {kl.max():.2g} at its closest "
                            f"condition against {own.min():.2f} to {own.max():.2f} to the states' own")  # fmt: skip
    if readings:
        lines += [*table, "", f"Per seed, {'; '.join(readings)}."]
    if missing:
        lines += ["", (f"Not measured yet: {'; '.join(missing)} (`python -m beyond.learned_null <agents> --steps "
                       f"1000000 --output <set>/{LEARNED_NULL}`).")]  # fmt: skip
    return lines
