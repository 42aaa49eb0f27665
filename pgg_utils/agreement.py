"""The report against the paper and CleanRL: our cells beside the paper's published ones, each tested,
corrected over the cells of one of its tables, with effect sizes and what each criterion can show.
It works on plot_results' summary rows (one per cell: mean, CI and seed means over seeds, and the
cell's `kind`, the table it belongs to) and knows nothing of files but the paper's data."""

import csv
import math
import sys
from pathlib import Path

import numpy as np
from scipy import stats

from pgg_utils.files import InputError
from pgg_utils.paper import PAPER_SEEDS
from pgg_utils.stats import ALPHA, correct_family, hedges_g, null_rates, sd_from_ci, sign_test, welch

PAPER_DATA = Path(__file__).resolve().parent.parent / "data" / "paper_results.csv"
# Our variant -> the paper's (method, training guidance) in data/paper_results.csv.
PAPER_METHOD_OF_VARIANT = {"ppo": ("ppo", ""), "pgg_g1.1": ("pgg", "1.1")}
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


def step_label(step: int) -> str:
    """A checkpoint step as the paper writes it: 100k, 1M."""
    return f"{step // 1_000_000}M" if step % 1_000_000 == 0 else f"{step // 1000}k"


def series_id(variant: str, series: str) -> str:
    """A variant with the label of its configuration, where an env and variant hold several."""
    return variant + (f" [{series}]" if series else "")


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
            "ci_overlap": overlap}  # fmt: skip


def kinds_of(summary: list[dict]) -> dict:
    """env -> the table it belongs to (discrete or continuous), as the summary's rows say."""
    return {r["env_id"]: r["kind"] for r in summary}


def compare_with_paper(summary: list[dict]) -> list[dict]:
    """Our cells beside the paper's, each tested (Welch, Holm over the cells of one of the paper's
    tables, i.e. per kind), and our final PPO cells beside CleanRL's published PPO (Holm over those)."""
    with open(PAPER_DATA, newline="") as f:
        paper = list(csv.DictReader(f))
    paper_envs = {p["env_id"] for p in paper}
    swept = {r["env_id"] for r in summary}
    absent = sorted(swept - paper_envs)
    for env in absent:
        print(f"note: {env} is not in the paper's tables; left out of the comparison", file=sys.stderr)
    if len(absent) == len(swept):
        raise InputError(f"none of the swept envs ({', '.join(absent)}) is in the paper's tables")
    kinds = kinds_of(summary)
    paper_cells = {(p["env_id"], p["method"], p["train_guidance"], int(p["step"]), float(p["eval_guidance"])): p for p in paper}
    out = []
    for r in summary:
        if r["variant"] not in PAPER_METHOD_OF_VARIANT:
            continue
        method, train_guidance = PAPER_METHOD_OF_VARIANT[r["variant"]]
        p = paper_cells.get((r["env_id"], method, train_guidance, int(r["step"]), float(r["eval_guidance"])))
        if p is not None:
            ci = float(p["ci95"])
            out.append(compare_row(r, "paper", float(p["mean"]), ci, sd_from_ci(ci, PAPER_SEEDS), PAPER_SEEDS))
    for kind in ("discrete", "continuous"):
        correct_family([row for row in out if kinds[row["env_id"]] == kind])
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
    return out + cleanrl


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
    """"p = 0.012" or "p < 0.001"."""
    return "p < 0.001" if fmt_p(p).startswith("<") else f"p = {fmt_p(p)}"


def cell_name(r: dict) -> str:
    name = "PPO" if r["variant"] == "ppo" else f"γ_train 1.1 γ={r['eval_guidance']:g}"
    if r["series"]:
        name += f" [{r['series']}]"
    return f"{step_label(r['step'])} {name}"


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


def comparison_markdown(rows: list[dict], summary: list[dict]) -> str:
    """compare_paper.md: the headline per table and env, what each criterion can show, every cell, and
    CleanRL's PPO as a second reference. `summary`: the cells the rows were compared from."""
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
        lines.append(f"{len(family)} cells of the paper's {kind} table compared; **{n_sig} differ significantly** "
                     f"(Welch's t, Holm-corrected over these {len(family)} cells, family-wise α = {ALPHA}).")  # fmt: skip
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
        variant = series_id(r["variant"], r["series"]) + ("†" if r["mujoco"] and r["mujoco"] != REFERENCE_MUJOCO else "")
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
                   "final weights), so the test is indicative. sd in units: ours − CleanRL over CleanRL's sd "
                   "(ddof 1)."),
                  "",
                  "| env | CleanRL (mean ± sd, 3 seeds) | paper PPO, same step | ours PPO | diff % | in CleanRL sds | Welch p | Holm p |",
                  "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        paper_ppo = {(r["env_id"], r["step"], r["series"]): r for r in paper_rows if r["variant"] == "ppo" and r["eval_guidance"] == 1.0}
        for r in cleanrl_rows:
            p = paper_ppo.get((r["env_id"], r["step"], r["series"]))
            sd_pop = CLEANRL_PPO[r["env_id"]][1]
            paper_cell = f"{fmt(p['ref_mean'])} ± {fmt(p['ref_ci95'])}" if p else "–"
            lines.append(f"| {r['env_id']} | {fmt(r['ref_mean'], 2)} ± {sd_pop:.2f} | "
                         f"{paper_cell} | {fmt(r['our_mean'])} ± {fmt(r['our_ci95'])} | "
                         f"{r['diff_pct']:+.1f} | {r['diff'] / r['ref_sd']:+.2f} | {fmt_p(r['p'])} | {fmt_p(r['p_holm'])} |")  # fmt: skip
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
               "survive. A non-significant cell is *not* evidence of equality (5 seeds give little power), "
               "only the absence of evidence of a difference; an equivalence test would need a margin the paper "
               "does not give. Holm is valid whatever the dependence between cells."),
              ("- **The sign test** per env asks whether ours lies above the paper's as often as below. Its cells are "
               "not independent (the same 5 checkpoints are evaluated at every eval γ, and checkpoints of one run "
               "share its history), so its p-value overstates the evidence; read it as a description of a "
               "systematic offset, not a test."),
              ("- **The effect size** (Hedges' g, difference as % of the paper's mean) says how large a difference "
               "is, whatever its p-value."), ""]  # fmt: skip
    return lines
