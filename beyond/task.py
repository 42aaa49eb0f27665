"""A task's section of the report: γ_train at each mark of the scheduled runs, the return at γ = 1 and the runs that
fell, each new variant against each baseline (the γ = 1 tests and the pooled cells), the held-out γ, the γ-response at
the last step and the final distance to the goal. Its numbers are computed once as tables (task_tables), its rows of
report_values.csv (task_values) and its markdown (task_lines) written from them; its sentences are templates."""

import math

import numpy as np

from beyond.cells import cells_of, largest_vs_best, record, response_at_last_step, summary
from beyond.schedules import checkpoint_iteration, collapsed
from beyond.sets import CLONING_VARIANTS
from beyond.text import fill, pct, seed_list
from paper_study.agreement import fmt, fmt_p, step_label
from paper_study.paper import paper_name
from pgg_utils.episodes import mean_ci95

TRAJECTORY = ("γ_train of each checkpoint's own iteration, the first whose step reaches the mark (mean over seeds, "
              "min–max over seeds): where the schedule had taken the guidance.")  # fmt: skip
RETURN = ("Return at γ = 1, mean ± 95% CI over seeds (seed sd); runs whose return at the last step fell below half their "
          "best mark's, named by seed: at γ = 1, and at their best eval γ of each mark (n/a where returns are costs).")  # fmt: skip
AGAINST = ("Each new variant against each baseline at γ = 1 (Welch's t test, Holm over the report's {tests} such tests of "
           "the schedules and goal nulls, and apart over the {cloning} of the cloning variant; beside it the gap one "
           "test detects with 80% power at α = 0.05, before Holm, so a non-significant row rules out less than it "
           "shows). γ = 1 is not the policy a schedule ending at γ_train 1.2 was trained toward: the held-out and "
           "γ-response tables below compare at other γ. Then, over every (step, eval γ) cell both sweeps hold: how many "
           "cells lie above and below the baseline (no p value: the cells of one run share its seeds), and the median "
           "relative gap (ours − baseline) / |baseline| with its exact bootstrap interval over our seeds, which "
           "resamples whole runs but holds the baseline's means fixed; a percentile bootstrap over 5 seeds "
           "under-covers, so the interval is narrower than the truth.")  # fmt: skip
AGAINST_HEAD = ("| variant | baseline | step | gap | p (Holm) | detectable gap | cells above / below | median gap [95% CI] |\n"
                "|---|---|---|---|---|---|---|---|")  # fmt: skip
HELDOUT = ("Held-out γ at {mark}: chosen on the sweep above, scored on a fresh sweep (episode seeds 20000+) against γ = 1 "
           "on the same fresh episodes; Holm over the groups of the sweep each row comes from (the continuous table's "
           "for its runs, this task's for those trained here).")  # fmt: skip
HELDOUT_HEAD = (
    "| variant | chosen γ | fresh return | fresh at γ = 1 | gain ± 95% CI | p (Holm) |\n|---|---|---|---|---|---|"
)
RESPONSE = ("γ-response at {mark}: mean return over seeds at each eval γ, and how far the largest γ ({largest:g}) falls "
            "below the best: the deterioration past a modest γ the paper reports.")  # fmt: skip
DISTANCE = ("Final distance to the goal at {mark} (in the last observation; lower is closer), mean ± 95% CI over seeds "
            "of the per-seed mean over episodes.")  # fmt: skip


def task_tables(env: str, means: dict, variants: list[str], rows: list[dict], pooled: dict, heldout: dict,
                distance: dict, trajectories: dict) -> dict:  # fmt: skip
    """The task's tables: {"steps", "trajectory": {variant: {step: γ_train of each seed}}, "returns": {variant:
    {step: (mean, half-width, sd)}}, "fell": {variant: (at γ = 1, at the best γ)}, "against": [the γ = 1 rows, each
    with the pooled cells at its last step], "heldout": [(variant, row)], "gammas", "response": {variant: (values,
    fall)}, "goal_gammas", "distance": {variant: {γ: per-seed distances}}}."""
    steps = sorted({s for (e, v, s, g) in means if e == env})
    trajectory = {}
    for variant in (v for v in variants if trajectories.get((env, v))):
        at = {step: [t[1] for t in (checkpoint_iteration(runs, step) for runs in trajectories[(env, variant)].values())
                     if t is not None] for step in steps}  # fmt: skip
        trajectory[variant] = at
    cells = {variant: cells_of(means, env, variant) for variant in variants}
    against = []
    for r in (r for r in rows if r["env_id"] == env):
        key = (env, r["variant"], r["baseline"])
        last = r["step"] == max(x["step"] for x in rows if (x["env_id"], x["variant"], x["baseline"]) == key)
        against.append({**r, "pooled": pooled[key] if last and key in pooled else None})
    response = {}
    for variant in variants:
        _, values = response_at_last_step(means, env, variant)
        response[variant] = (values, largest_vs_best(values)[1])
    goal_gammas = sorted({g for (e, v, g) in distance if e == env})
    return {"env": env, "steps": steps, "variants": variants, "trajectory": trajectory,
            "returns": {v: {s: summary(cells[v][(s, 1.0)]) for s in steps if (s, 1.0) in cells[v]} for v in variants},
            "fell": {v: (collapsed(cells[v]), collapsed(cells[v], True)) for v in variants},
            "tests": len(rows), "cloning": sum(r["variant"] in CLONING_VARIANTS for r in rows), "against": against,
            "heldout": [(v, heldout.get((env, v, steps[-1]))) for v in variants],
            "gammas": sorted({g for (e, v, s, g) in means if e == env and s == steps[-1]}), "response": response,
            "goal_gammas": goal_gammas,
            "distance": {v: {g: list(distance.get((env, v, g), {}).values()) for g in goal_gammas} for v in variants}}  # fmt: skip


def task_values(t: dict) -> list[dict]:
    """The task's rows of report_values.csv: γ_train at each mark, the pooled cells, the γ-response."""
    out, env, mark = [], t["env"], step_label(t["steps"][-1])
    for variant, at in t["trajectory"].items():
        for step, values in ((s, v) for s, v in at.items() if v):
            for name, value in (("mean", float(np.mean(values))), ("min", min(values)), ("max", max(values))):
                record(out, env, variant, "", f"γ_train {name} at {step_label(step)}", value)
    for r in (r for r in t["against"] if r["pooled"]):
        for quantity in ("above", "below", ""):
            record(out, env, r["variant"], r["baseline"], f"cells {quantity}".strip(), r["pooled"][quantity or "cells"])
    for variant, (values, drop) in t["response"].items():
        for g, v in zip(t["gammas"], values):
            record(out, env, variant, "", f"return at γ {g:g} at {mark}", v)
        record(out, env, variant, "", f"largest γ vs best at {mark} (%)", 100 * drop)
    return out


def task_lines(t: dict) -> list[str]:
    steps, mark = t["steps"], step_label(t["steps"][-1])
    lines = [f"## {t['env']}", ""]
    if t["trajectory"]:
        lines += [
            TRAJECTORY,
            "",
            "| variant | " + " | ".join(step_label(s) for s in steps) + " |",
            "|---|" + "---|" * len(steps),
        ]
        for variant, at in t["trajectory"].items():
            shown = [f"{np.mean(v):.3f} ({min(v):.3f}–{max(v):.3f})" if v else "–" for v in at.values()]
            lines.append(f"| {paper_name(variant)} | " + " | ".join(shown) + " |")
        lines.append("")
    lines += [RETURN, "", "| variant | " + " | ".join(step_label(s) for s in steps) + " | fell at γ = 1 | fell at its best γ |",
              "|---|" + "---|" * (len(steps) + 2)]  # fmt: skip
    for variant in t["variants"]:
        at = t["returns"][variant]
        shown = [f"{at[s][0]:.1f} ± {at[s][1]:.1f} ({at[s][2]:.0f})" if s in at else "–" for s in steps]
        fell = [seed_list(seeds) for seeds in t["fell"][variant]]
        lines.append(f"| {paper_name(variant)} | " + " | ".join(shown) + f" | {fell[0]} | {fell[1]} |")
    lines += ["", fill(AGAINST, tests=t["tests"] - t["cloning"], cloning=t["cloning"]), "", AGAINST_HEAD]
    for r in t["against"]:
        tail = "| |"
        if pooled := r["pooled"]:
            gap = pooled.get("median_gap")
            tail = f"| {pooled['above']} / {pooled['below']} | " + (
                f"{pct(gap[0], 2)} [{pct(gap[1], 2)}, {pct(gap[2], 2)}] |" if gap else "– |"
            )
        lines.append(f"| {paper_name(r['variant'])} | {paper_name(r['baseline'])} | {step_label(r['step'])} | "
                     f"{fmt(r['gap'])} | {fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | {fmt(r['detectable_gap'])} {tail}")  # fmt: skip
    if any(h for _, h in t["heldout"]):
        lines += ["", fill(HELDOUT, mark=mark), "", HELDOUT_HEAD]
        lines += [heldout_row(variant, h) for variant, h in t["heldout"] if h]
    gammas = t["gammas"]
    lines += ["", fill(RESPONSE, mark=mark, largest=gammas[-1]), "",
              "| variant | " + " | ".join(f"γ = {g:g}" for g in gammas) + f" | γ = {gammas[-1]:g} vs best |",
              "|---|" + "---|" * (len(gammas) + 1)]  # fmt: skip
    for variant, (values, drop) in t["response"].items():
        lines.append(f"| {paper_name(variant)} | " + " | ".join("–" if math.isnan(v) else f"{v:.1f}" for v in values)
                     + f" | {pct(drop)} |")  # fmt: skip
    if t["goal_gammas"]:
        lines += ["", fill(DISTANCE, mark=mark), "", "| variant | " + " | ".join(f"γ = {g:g}" for g in t["goal_gammas"]) + " |",
                  "|---|" + "---|" * len(t["goal_gammas"])]  # fmt: skip
        for variant, by_gamma in t["distance"].items():
            shown = [f"{mean_ci95(v)[0]:.4f} ± {mean_ci95(v)[1]:.4f}" if v else "–" for v in by_gamma.values()]
            lines.append(f"| {paper_name(variant)} | " + " | ".join(shown) + " |")
    return [*lines, ""]


def heldout_row(variant: str, h: dict) -> str:
    if h["status"] != "tested":
        return f"| {paper_name(variant)} | {float(h['selected_gamma']):g} | – | – | γ = 1 chosen | – |"
    return (f"| {paper_name(variant)} | {float(h['selected_gamma']):g} | {fmt(float(h['fresh_mean']))} | "
            f"{fmt(float(h['fresh_baseline']))} | {fmt(float(h['fresh_gain']))} ± {fmt(float(h['fresh_gain_ci95']))} | "
            f"{fmt_p(float(h['p']))} ({fmt_p(float(h['p_holm']))}) |")  # fmt: skip


def task_section(env: str, means: dict, variants: list[str], rows: list[dict], pooled: dict, heldout: dict,
                 distance: dict, trajectories: dict, values_out: list[dict]) -> list[str]:  # fmt: skip
    t = task_tables(env, means, variants, rows, pooled, heldout, distance, trajectories)
    values_out += task_values(t)
    return task_lines(t)
