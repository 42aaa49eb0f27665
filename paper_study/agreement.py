"""The report against the paper and CleanRL: our cells beside the paper's published ones, each tested,
corrected over the cells of one of its tables, with effect sizes and what each criterion can show.
It works on plot_results' summary rows (one per cell: mean, CI and seed means over seeds, and the
cell's `kind`, the table it belongs to) and knows nothing of files but the paper's data."""

import csv
import math
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy import stats

from paper_study.paper import PAPER_SEEDS, paper_rows, with_series
from paper_study.stats import (
    ALPHA,
    POWER,
    bootstrap_coverage,
    correct_family,
    detectable_gap,
    hedges_g,
    median_relative_gap,
    null_rates,
    sd_from_ci,
    sign_test,
    welch,
)

PAPER_DATA = Path(__file__).resolve().parent / "data" / "paper_results.csv"
REFERENCE_MUJOCO = "2.3.7"  # the physics the v4 tasks were written for; cells from other versions are marked
# CleanRL's published PPO benchmark (docs.cleanrl.dev, rl-algorithms/ppo: ppo.py on classic control,
# ppo_continuous_action.py on MuJoCo v4, tag pr-424). Its protocol: per run the mean of the last 100
# *training* episodes' returns at the end of training (500k steps classic control, 1M MuJoCo), then
# mean ± standard deviation over 3 seeds (openrlbenchmark's rlops: numpy std, ddof = 0).
CLEANRL_PPO = {"CartPole-v1": (490.04, 6.12), "Acrobot-v1": (-86.36, 1.32), "Hopper-v4": (2382.86, 271.74),
               "HalfCheetah-v4": (1442.64, 46.03), "Walker2d-v4": (2287.95, 571.78),
               "InvertedPendulum-v4": (963.09, 22.20), "Humanoid-v4": (716.11, 49.08), "Pusher-v4": (-40.38, 7.15)}  # fmt: skip
CLEANRL_SEEDS = 3
CLEANRL_STEPS = {"discrete": 500_000, "continuous": 1_000_000}
BOOTSTRAP_RESAMPLES = 200_000  # of our seeds, where a task's bootstrap is too large to enumerate (RNG seed 0)


def step_label(step: int) -> str:
    """A checkpoint step as the paper writes it: 100k, 1M; a step that is no whole thousand exactly
    (512, 2,048), never rounded into another mark's label."""
    if step and step % 1_000_000 == 0:
        return f"{step // 1_000_000}M"
    return f"{step // 1000}k" if step and step % 1000 == 0 else f"{step:,}"


def series_id(variant: str, series: str) -> str:
    """A variant with the label of its configuration, where an env and variant hold several."""
    return with_series(variant, series)


def other_mujoco(row: dict | None) -> bool:
    """Whether a cell comes from a MuJoCo other than the tables' (it is marked † and named in titles)."""
    return bool(row and row.get("mujoco") and row["mujoco"] != REFERENCE_MUJOCO)


# --- the tests ------------------------------------------------------------------------------------


def our_sd(row: dict) -> float:
    seed_means = [float(x) for x in str(row["seed_means"]).split(";") if x]
    return float(np.std(seed_means, ddof=1)) if len(seed_means) > 1 else math.nan


def compare_row(ours: dict, reference: str, ref_mean: float, ref_ci: float, ref_sd: float, ref_n: int) -> dict:
    """One of our summary cells against a reference's summary of the same cell: Welch's t, Hedges' g,
    CI overlap. `p_holm` and `significant` are left for correct_family over the cell's family."""
    n = int(ours["n_seeds"])
    sd = our_sd(ours)
    mean, ci = float(ours["mean"]), float(ours["ci95"])
    t_value, df, p = welch(mean, sd, n, ref_mean, ref_sd, ref_n)
    diff = mean - ref_mean
    overlap = "n/a" if math.isnan(ci) else str(abs(diff) <= ci + ref_ci)
    return {"env_id": ours["env_id"], "variant": ours["variant"], "config": ours["config"], "series": ours["series"],
            "mujoco": ours.get("mujoco", ""), "step": int(ours["step"]), "eval_guidance": float(ours["eval_guidance"]),
            "reference": reference, "ref_mean": ref_mean, "ref_ci95": ref_ci, "ref_sd": ref_sd, "ref_n": ref_n,
            "our_mean": mean, "our_ci95": ci, "our_sd": sd, "our_n": n, "diff": diff,
            "diff_pct": 100 * diff / abs(ref_mean) if ref_mean else math.nan, "welch_t": t_value, "welch_df": df,
            "p": p, "p_holm": math.nan, "significant": "", "hedges_g": hedges_g(mean, sd, n, ref_mean, ref_sd, ref_n),
            "ci_overlap": overlap, "detectable_gap": math.nan, "detectable_gap_pct": math.nan}  # fmt: skip


def add_detectable_gaps(family: list[dict]) -> None:
    """Sets each row's `detectable_gap`: the gap its Welch test detects with 80% power at Holm's first-step
    level α/m (m the family's tested cells), from the cell's two sds and seed counts, in return units
    and as % of the reference's mean. The level a lone true difference must reach to be flagged, so
    this is what the family's count of differing cells can see."""
    m = sum(1 for row in family if not math.isnan(row["p"]))
    if m == 0:
        return
    for row in family:
        gap = detectable_gap(row["our_sd"], row["our_n"], row["ref_sd"], row["ref_n"], ALPHA / m)
        row["detectable_gap"] = gap
        row["detectable_gap_pct"] = 100 * gap / abs(row["ref_mean"]) if row["ref_mean"] else math.nan


def kinds_of(summary: list[dict]) -> dict:
    """env -> the table it belongs to (discrete or continuous), as the summary's rows say."""
    return {r["env_id"]: r["kind"] for r in summary}


def compare_with_paper(summary: list[dict]) -> list[dict] | None:
    """Our cells beside the paper's, each tested (Welch, Holm over the cells of one of the paper's
    tables, i.e. per kind), and our final PPO cells beside CleanRL's published PPO (Holm over those).
    None, with one note, where none of the swept envs is the paper's."""
    with open(PAPER_DATA, newline="") as f:
        paper = list(csv.DictReader(f))
    paper_envs = {p["env_id"] for p in paper}
    swept = {r["env_id"] for r in summary}
    absent = sorted(swept - paper_envs)
    if len(absent) == len(swept):
        print(f"note: none of the swept envs ({', '.join(absent)}) is in the paper's tables: nothing to compare",
              file=sys.stderr)  # fmt: skip
        return None
    for env in absent:
        print(f"note: {env} is not in the paper's tables; left out of the comparison", file=sys.stderr)
    kinds = kinds_of(summary)
    paper_cells = {
        (p["env_id"], p["method"], p["train_guidance"], int(p["step"]), float(p["eval_guidance"])): p for p in paper
    }
    out = []
    for r in summary:
        if (rows_of := paper_rows(r["variant"])) is None:
            continue
        method, train_guidance = rows_of
        p = paper_cells.get((r["env_id"], method, train_guidance, int(r["step"]), float(r["eval_guidance"])))
        if p is not None:
            ci = float(p["ci95"])
            out.append(compare_row(r, "paper", float(p["mean"]), ci, sd_from_ci(ci, PAPER_SEEDS), PAPER_SEEDS))
    for kind in ("discrete", "continuous"):
        family = [row for row in out if kinds[row["env_id"]] == kind]
        correct_family(family)
        add_detectable_gaps(family)
    cleanrl = []
    for r in summary:
        env = r["env_id"]
        if (r["variant"] == "ppo" and env in CLEANRL_PPO and float(r["eval_guidance"]) == 1.0
                and int(r["step"]) == CLEANRL_STEPS[r["kind"]]):  # fmt: skip
            mean, sd_population = CLEANRL_PPO[env]
            sd = sd_population * math.sqrt(CLEANRL_SEEDS / (CLEANRL_SEEDS - 1))
            ci = float(stats.t.ppf(0.975, CLEANRL_SEEDS - 1)) * sd / math.sqrt(CLEANRL_SEEDS)
            cleanrl.append(compare_row(r, "cleanrl", mean, ci, sd, CLEANRL_SEEDS))
    correct_family(cleanrl)
    add_detectable_gaps(cleanrl)
    return out + cleanrl


def paper_ppo_span() -> dict[str, tuple[float, float]]:
    """env -> the paper's PPO mean (eval γ = 1) at the first and the last step of its table: fixed
    references for normalised scores, which adding a swept γ or a variant does not move."""
    with open(PAPER_DATA, newline="") as f:
        ppo = sorted((r for r in csv.DictReader(f) if r["method"] == "ppo" and float(r["eval_guidance"]) == 1.0),
                     key=lambda r: int(r["step"]))  # fmt: skip
    span = {}
    for r in ppo:
        first = span.get(r["env_id"], (float(r["mean"]),))[0]
        span[r["env_id"]] = (first, float(r["mean"]))
    return span


def cell_key(row: dict) -> tuple:
    """(env, variant, config, series, step, eval γ): one cell, in a summary row or a comparison row."""
    return (row["env_id"], row["variant"], row["config"], row["series"], int(row["step"]), float(row["eval_guidance"]))


def task_summaries(rows: list[dict], summary: list[dict]) -> list[dict]:
    """Per table and env, against the paper: the count of differing cells beside what the test could
    see (the median over cells of the gap detected 80% of the time), and the summary that has power,
    the median relative gap (ours − paper) / |paper| over the env's cells with a bootstrap 95% CI over
    our seeds (stats.median_relative_gap; the paper's means fixed). `summary`: the cells compared, whose
    per-seed means the bootstrap resamples."""
    seeds_of = {cell_key(r): (tuple(r["seeds"]), [float(x) for x in str(r["seed_means"]).split(";") if x])
                for r in summary}  # fmt: skip
    kinds = kinds_of(summary)
    out = []
    paper_rows = [r for r in rows if r["reference"] == "paper"]
    for kind in ("discrete", "continuous"):
        family = [r for r in paper_rows if kinds[r["env_id"]] == kind]
        tested = sum(1 for r in family if not math.isnan(r["p"]))
        for env in sorted({r["env_id"] for r in family}):
            cells = [r for r in family if r["env_id"] == env]
            above, below, ties, p_sign = sign_test([r["diff"] for r in cells])
            blocks = defaultdict(lambda: ([], []))  # cells of one run set: (seed means, paper's means)
            for r in cells:
                if not r["ref_mean"] or r["our_sd"] == r["ref_sd"] == 0:
                    continue  # no relative gap, or both sides at one value (the task's ceiling): no information
                seeds, seed_means = seeds_of[cell_key(r)]
                block = blocks[(r["variant"], r["config"], r["series"], seeds)]
                block[0].append(seed_means)
                block[1].append(r["ref_mean"])
            median, low, high = (median_relative_gap(list(blocks.values()), BOOTSTRAP_RESAMPLES) if blocks
                                 else (math.nan,) * 3)  # fmt: skip
            gaps = [r["detectable_gap"] for r in cells if not math.isnan(r["detectable_gap"])]
            gaps_pct = [r["detectable_gap_pct"] for r in cells if not math.isnan(r["detectable_gap_pct"])]
            out.append({"kind": kind, "env_id": env, "cells": len(cells),
                        "significant": sum(r["significant"] == "True" for r in cells),
                        "p_below_alpha": sum(1 for r in cells if not math.isnan(r["p"]) and r["p"] < ALPHA),
                        "holm_first_alpha": ALPHA / tested if tested else math.nan, "power": POWER,
                        "cells_with_spread": len(gaps),
                        "detectable_gap_median": float(np.median(gaps)) if gaps else math.nan,
                        "detectable_gap_pct_median": float(np.median(gaps_pct)) if gaps_pct else math.nan,
                        "detectable_gap_pct_min": min(gaps_pct) if gaps_pct else math.nan,
                        "detectable_gap_pct_max": max(gaps_pct) if gaps_pct else math.nan,
                        "rel_gap_median_pct": 100 * median, "rel_gap_ci_low_pct": 100 * low,
                        "rel_gap_ci_high_pct": 100 * high, "above": above, "below": below, "ties": ties,
                        "sign_p": p_sign})  # fmt: skip
    return out


# --- the report -----------------------------------------------------------------------------------


def fmt(value: float, digits: int = 1) -> str:
    if isinstance(value, str):
        return value
    if math.isnan(value):
        return "–"
    if math.isinf(value):
        return "∞" if value > 0 else "−∞"
    return f"{value:.{digits}f}"


def fmt_p(p: float) -> str:
    if math.isnan(p):
        return "–"
    return "<0.001" if p < 0.001 else f"{p:.3f}"


def p_is(p: float) -> str:
    """ "p = 0.012" or "p < 0.001"."""
    return "p < 0.001" if fmt_p(p).startswith("<") else f"p = {fmt_p(p)}"


def cell_name(r: dict) -> str:
    name = "PPO" if r["variant"] == "ppo" else f"γ_train 1.1 γ={r['eval_guidance']:g}"
    return f"{step_label(r['step'])} {with_series(name, r['series'])}"


def env_headline(env: str, rows: list[dict]) -> str:
    above, below, ties, p_sign = sign_test([r["diff"] for r in rows])
    significant = [r for r in rows if r["significant"] == "True"]
    raw = sum(1 for r in rows if not math.isnan(r["p"]) and r["p"] < ALPHA)
    overlap = sum(r["ci_overlap"] == "True" for r in rows)
    pct = [abs(r["diff_pct"]) for r in rows if not math.isnan(r["diff_pct"])]
    ratio = [r["ref_sd"] / r["our_sd"] for r in rows if r["our_sd"] and not math.isnan(r["our_sd"]) and r["ref_sd"]]
    versions = sorted({r["mujoco"] for r in rows if r["mujoco"]})
    stack = f" (MuJoCo {', '.join(versions)})" if versions else ""
    text = (f"**{env}**{stack}: {len(rows)} cells; "
            f"**{len(significant)} differ significantly after Holm**")  # fmt: skip
    if significant:
        text += " (" + "; ".join(f"{cell_name(r)}: {fmt(r['our_mean'])} vs {fmt(r['ref_mean'])}, {r['diff_pct']:+.0f}%, "
                                 f"g = {fmt(r['hedges_g'])}" for r in significant) + ")"  # fmt: skip
    text += (f"; {raw} at p < 0.05 before correction. Ours above the paper in {above}, below in {below}"
             f"{f', tied in {ties}' if ties else ''} (sign test {p_is(p_sign)}). "
             f"|difference| {min(pct):.0f}–{max(pct):.0f}% of the paper's mean (median {np.median(pct):.0f}%). "
             f"CIs overlap in {overlap} of {len(rows)}.") if pct else "."  # fmt: skip
    if ratio:
        text += f" The paper's seed spread is {np.median(ratio):.1f}× ours (median over cells)."
    return text


def pct(value: float) -> str:
    """A relative gap in %, signed, one decimal: "−27.6%"."""
    return "–" if math.isnan(value) else f"{value:+.1f}%".replace("-", "−")


def relative_gap(task: dict) -> str:
    """ "−27.6% [−31.0, −21.5]": a task's median relative gap and its bootstrap 95% CI."""
    low, high = (pct(task[k]).rstrip("%") for k in ("rel_gap_ci_low_pct", "rel_gap_ci_high_pct"))
    return f"{pct(task['rel_gap_median_pct'])} [{low}, {high}]"


def gap_verdict(tasks: list[dict]) -> str:
    """The headline's sentence from the per-task relative gaps: where the CI lies below 0, above it, or
    holds it (then how far from 0 it reaches, the gap the data leave possible)."""
    below = [t for t in tasks if t["rel_gap_ci_high_pct"] < 0]
    above = [t for t in tasks if t["rel_gap_ci_low_pct"] > 0]
    level = [t for t in tasks if t not in below and t not in above and not math.isnan(t["rel_gap_median_pct"])]
    parts = []
    for tasks_of, where in ((below, "below the paper's means on"), (above, "above them on")):
        if tasks_of:
            parts.append(f"{where} " + ", ".join(f"{t['env_id']} {relative_gap(t)}" for t in tasks_of))
    if level:
        reach = max(max(abs(t["rel_gap_ci_low_pct"]), abs(t["rel_gap_ci_high_pct"])) for t in level)
        parts.append("level with them (the interval holds 0) on "
                     + ", ".join(f"{t['env_id']} {relative_gap(t)}" for t in level)
                     + f", the intervals reaching no further than {reach:.1f}% from 0")  # fmt: skip
    return "ours lies " + "; ".join(parts) + "."


def headline_table(tasks: list[dict]) -> list[str]:
    lines = [(f"| env | cells | differ after Holm | gap detected {100 * POWER:.0f}% of the time (median) | "
              "as % of the paper's mean: median (range) | median relative gap (95% bootstrap CI) | above / below "
              "(sign test) |"), "|---|---|---|---|---|---|---|"]  # fmt: skip
    for t in tasks:
        spread = "" if t["cells_with_spread"] == t["cells"] else f" ({t['cells_with_spread']} with a spread)"
        ties = f", {t['ties']} tied" if t["ties"] else ""
        share = ("–" if math.isnan(t["detectable_gap_pct_median"]) else f"{t['detectable_gap_pct_median']:.0f}% "
                 f"({t['detectable_gap_pct_min']:.0f}–{t['detectable_gap_pct_max']:.0f}%)")  # fmt: skip
        sign = f"{t['above']} / {t['below']}{ties} ({p_is(t['sign_p'])})"
        lines.append(f"| {t['env_id']} | {t['cells']}{spread} | {t['significant']} | "
                     f"{fmt(t['detectable_gap_median'])} | {share} | {relative_gap(t)} | {sign} |")  # fmt: skip
    return lines


def comparison_markdown(rows: list[dict], summary: list[dict], tasks: list[dict]) -> str:
    """compare_paper.md: the headline per table and env (what the cell-by-cell test can see, and the
    per-task relative gap that has power), what each criterion can show, every cell, and CleanRL's PPO
    as a second reference. `summary`: the cells the rows were compared from; `tasks`: task_summaries."""
    paper_rows = [r for r in rows if r["reference"] == "paper"]
    cleanrl_rows = [r for r in rows if r["reference"] == "cleanrl"]
    kinds = kinds_of(summary)
    lines = ["# Agreement with the paper", ""]
    families = {kind: [r for r in paper_rows if kinds[r["env_id"]] == kind] for kind in ("discrete", "continuous")}
    lines.append("## Headline")
    lines.append("")
    for kind, family in families.items():
        if not family:
            continue
        n_sig = sum(r["significant"] == "True" for r in family)
        of_kind = [t for t in tasks if t["kind"] == kind]
        alpha = of_kind[0]["holm_first_alpha"]
        lines.append(f"Per task, over the {len(family)} cells of the paper's {kind} table we swept, the median "
                     "relative gap (ours − paper) / |paper| with a 95% bootstrap interval over our seeds: "
                     f"{gap_verdict(of_kind)}")  # fmt: skip
        lines.append("")
        ours_n = "–".join(str(n) for n in sorted({min(r["our_n"] for r in family), max(r["our_n"] for r in family)}))
        tested = sum(1 for r in family if not math.isnan(r["p"]))
        if tested:
            lines.append(f"Cell by cell, **{n_sig} of {len(family)} differ significantly** (Welch's t, Holm-corrected "
                         f"over these {tested} cells, family-wise α = {ALPHA}). What that count can see: at Holm's "
                         f"first step (α/{tested} = {alpha:.2g}), with {PAPER_SEEDS} seeds on the paper's side and "
                         f"{ours_n} on ours, a cell's test detects a gap {100 * POWER:.0f}% of the time only at the "
                         "size below (per cell from its two seed sds; the median over a task's cells).")  # fmt: skip
        elif max(r["our_n"] for r in family) < 2:
            lines.append("Cell by cell, **no cell is tested**: Welch's t needs two seeds on each side, and ours hold "
                         "one (the relative gap's interval above is then a point).")  # fmt: skip
        else:
            lines.append("Cell by cell, **no cell is tested**: no cell has a spread on either side to test.")
        lines += ["", *headline_table(of_kind), ""]
        lines.append(f"The gap detected {100 * POWER:.0f}% of the time: the exact power of Welch's test for normal "
                     "samples, the cell's two sds taken as the true ones (`paper_study.stats.detectable_gap`). Cells "
                     "with no spread on either side (both at the task's ceiling), where the test is degenerate and "
                     "no gap is possible, are left out of both columns. The relative gap: per cell "
                     "(ours − paper) / |paper|, the median over the task's cells; its interval resamples our "
                     "seeds (every resample enumerated and weighted, so its endpoints are exact, not a Monte Carlo "
                     f"draw; {BOOTSTRAP_RESAMPLES:,} draws, RNG seed 0, where there are too many: "
                     "`paper_study.stats.median_relative_gap`), one draw of seeds per run set so that a "
                     "run's checkpoints and eval γ move together, and **holds the paper's means fixed**: it is our "
                     "seeds' uncertainty, not the paper's, and says how far ours lies from the published numbers, "
                     "not from the distribution they were drawn from. With 5 seeds a percentile bootstrap is narrow: "
                     "for one cell's mean its 95% interval holds the true mean "
                     f"{100 * bootstrap_coverage(PAPER_SEEDS):.0f}% of the time (simulated, seeded).")  # fmt: skip
        lines.append("")
        for env in sorted({r["env_id"] for r in family}):
            lines.append("- " + env_headline(env, [r for r in family if r["env_id"] == env]))
        lines.append("")
    if not paper_rows:
        lines += ["No cell of the paper's tables was swept (its steps are 100k–500k discrete, 200k–1M continuous).", ""]
    configs = sorted({(r["env_id"], r["variant"], r["series"]) for r in paper_rows if r["series"]})
    if configs:
        lines += ["Several configurations of one env and variant are compared with the paper separately: "
                  + "; ".join(f"{e} {v} [{s}]" for e, v, s in configs) + ".", ""]  # fmt: skip
    if cleanrl_rows:
        lines.append("CleanRL's published PPO, a second reference (its own protocol): " + "; ".join(
            f"{r['env_id']} ours {fmt(r['our_mean'])} vs {fmt(r['ref_mean'])} ({r['diff_pct']:+.0f}%, Holm {p_is(r['p_holm'])})"
            for r in cleanrl_rows) + ".")  # fmt: skip
        lines.append("")
    short = sorted({r["env_id"] for r in summary if r["env_id"] in CLEANRL_PPO and r["variant"] == "ppo"}
                   - {r["env_id"] for r in cleanrl_rows})  # fmt: skip
    if short:
        lines += [(f"No PPO cell at CleanRL's final step (500k classic control, 1M MuJoCo) for {', '.join(short)}; "
                   "not compared with CleanRL."), ""]  # fmt: skip
    lines += criteria_section()
    lines += ["## Cells", "",
              ("Our side: the per-seed mean returns (sd over seeds, ddof 1). The paper's: sd recovered from its "
               f"mean ± 95% CI with n = {PAPER_SEEDS} (sd = CI·√5 / t₀.₉₇₅,₄). diff = ours − paper; "
               "g = Hedges' g (positive: ours higher). Holm: over the cells of the same table (discrete or "
               "continuous). † MuJoCo other than 2.3.7."), "",
              "| env | variant | step | eval γ | paper | ours | seeds | diff | diff % | Welch p | Holm p | g | CIs overlap |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in paper_rows:
        mark = " ✗" if r["significant"] == "True" else ""
        variant = series_id(r["variant"], r["series"]) + ("†" if other_mujoco(r) else "")
        lines.append(f"| {r['env_id']} | {variant} | {step_label(r['step'])} | {r['eval_guidance']:g} | "
                     f"{fmt(r['ref_mean'])} ± {fmt(r['ref_ci95'])} | {fmt(r['our_mean'])} ± {fmt(r['our_ci95'])} | "
                     f"{r['our_n']} | {r['diff']:+.1f} | {fmt(r['diff_pct'])} | {fmt_p(r['p'])} | {fmt_p(r['p_holm'])}{mark} | "
                     f"{fmt(r['hedges_g'], 2)} | {'yes' if r['ci_overlap'] == 'True' else 'no' if r['ci_overlap'] == 'False' else '?'} |")  # fmt: skip
    if cleanrl_rows:
        lines += ["", "## Second reference: CleanRL's PPO", "",
                  ("CleanRL's published end-of-training PPO returns (docs.cleanrl.dev, `ppo.py` on classic control at "
                   "500k steps, `ppo_continuous_action.py` on MuJoCo v4 at 1M): per run the mean return of the last "
                   "100 *training* episodes, then **mean ± standard deviation** over 3 seeds (numpy std, ddof 0; "
                   "not a CI). Ours: vanilla PPO's final checkpoint evaluated over 50 fresh episodes per seed at "
                   "γ = 1. The protocols differ (training episodes under the running policy vs evaluation of the "
                   "final weights), so the test is indicative. In CleanRL sds: ours − CleanRL over CleanRL's "
                   "published sd, the one shown (ddof 0); the test uses it rescaled to ddof 1."),
                  "",
                  "| env | CleanRL (mean ± sd, 3 seeds) | paper PPO, same step | ours PPO | diff % | in CleanRL sds | Welch p | Holm p |",
                  "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        paper_ppo = {
            (r["env_id"], r["step"], r["series"]): r
            for r in paper_rows
            if r["variant"] == "ppo" and r["eval_guidance"] == 1.0
        }
        for r in cleanrl_rows:
            p = paper_ppo.get((r["env_id"], r["step"], r["series"]))
            sd_pop = CLEANRL_PPO[r["env_id"]][1]
            paper_cell = f"{fmt(p['ref_mean'])} ± {fmt(p['ref_ci95'])}" if p else "–"
            lines.append(f"| {r['env_id']} | {fmt(r['ref_mean'], 2)} ± {sd_pop:.2f} | "
                         f"{paper_cell} | {fmt(r['our_mean'])} ± {fmt(r['our_ci95'])} | "
                         f"{r['diff_pct']:+.1f} | {r['diff'] / sd_pop:+.2f} | {fmt_p(r['p'])} | "
                         f"{fmt_p(r['p_holm'])} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def criteria_section() -> list[str]:
    rates = null_rates(PAPER_SEEDS)
    by_shift = {r["shift_sd"]: r for r in rates}
    null = by_shift[0.0]
    lines = ["## What each criterion can and cannot show", "",
             (f"Simulated (seeded, {200_000:,} pairs): two samples of {PAPER_SEEDS} normal values, means "
              "`shift` standard deviations apart."), "",
             "| true difference | 95% CIs overlap | Welch p < 0.05 |", "|---|---|---|"]  # fmt: skip
    for r in rates:
        lines.append(f"| {r['shift_sd']:g} sd | {100 * r['overlap']:.1f}% | {100 * r['welch_reject']:.1f}% |")
    lines += ["",
              (f"- **CI overlap** happens {100 * null['overlap']:.1f}% of the time when both samples come from one "
               "distribution, and still most of the time for a true difference of one standard deviation: it almost "
               "never fails, so a cell that 'agrees' this way says little. Where one side's interval is wide (the "
               "paper's HalfCheetah), it says nothing."),
              (f"- **Welch's t test** per cell rejects a true null {100 * null['welch_reject']:.1f}% of the time at "
               "p < 0.05; after Holm's correction over a table of hundreds of cells, only large, clear differences "
               "survive (the headline's table says how large, per task). A non-significant cell is *not* evidence "
               "of equality (5 seeds give little power), only the absence of evidence of a difference. Holm is "
               "valid whatever the dependence between cells."),
              ("- **The median relative gap** per task pools its cells into one number, so its bootstrap interval "
               "is narrow where the cells' tests are blind; it describes our distance from the paper's published "
               "means (held fixed), with the bootstrap's small-sample optimism (the headline's note)."),
              ("- **The sign test** per env asks whether ours lies above the paper's as often as below. Its cells are "
               "not independent (the same 5 checkpoints are evaluated at every eval γ, and checkpoints of one run "
               "share its history), so its p-value overstates the evidence; read it as a description of a "
               "systematic offset, not a test."),
              ("- **The effect size** (Hedges' g, difference as % of the paper's mean) says how large a difference "
               "is, whatever its p-value."), ""]  # fmt: skip
    return lines
