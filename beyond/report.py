"""The report of "Beyond the paper": each variant of the paper's future work (scheduled and adaptive
γ_train, guidance on a goal) against its baselines, from committed episode CSVs only.

    python -m beyond.report results/beyond --table results/continuous/episodes.csv

Reads every `results/beyond/<task>/episodes.csv` (the new variants, and for tasks outside the paper's
table their own PPO and γ_train 1.1 runs), the continuous table's episodes for the baselines of the
paper's tasks, `results/beyond/<task>/heldout_gamma.csv` where the held-out selection was run, and
`results/beyond/goal_distance.csv` (beyond/goal_distance.py) where it exists. Writes into the
folder, atomically:
  report.md    at a glance, a table per question (the γ-response at the last mark of the scheduled and
               adaptive variants and their baselines, with Welch tests of their per-seed fall from the best γ
               to the largest and of their return at the best γ against the baselines'; the final distance to
               the goal against γ, with a t test of each seed's change from γ = 1 to the largest); then per
               task: return at each mark at γ = 1 (mean ± 95% CI over seeds, seed sd, runs that fell),
               each new variant against each baseline (Welch + Holm over the report's γ = 1 tests, the gap
               one test can detect at 80% power, the cells above and below over both sweeps, the pooled
               median gap over every (step, γ) cell with its exact bootstrap interval), the held-out γ, the
               γ-response at the last step, and the final distance to the goal against γ
  report.csv   one row per (task, variant, baseline, step) at γ = 1: the tests' numbers
  report_values.csv   every other number the front page may quote, unrounded (the glance tables, the γ_train,
               γ-response and pooled counts): one row per (task, variant, baseline, quantity)
  gamma_response.png   return against eval γ at the last step, a panel per task
  guidance_trajectory.png   γ_train over training of the scheduled and adaptive runs
  goal_distance.png    the final distance to the goal against eval γ, a panel per goal task
With `--runs runs/beyond` it first rewrites `guidance_trajectory.csv` (γ_train and the KL of every
iteration of every run, from the runs' TensorBoard events, which are not committed); without it the
committed CSV is read. A run "fell" where its return at the last step is below half of its best mark's: at
γ = 1, and at its best eval γ of each mark.
"""

import csv
import math
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
import tyro
from scipy import optimize, stats

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from paper_study.agreement import fmt, fmt_p, step_label
from paper_study.figures import steps_formatter, variant_colour
from paper_study.paper import PAPER_ENVS, paper_name, variant_rank
from paper_study.stats import ALPHA, detectable_gap, holm, median_relative_gap, welch
from pgg_utils import pooling
from pgg_utils.episodes import read_episodes
from pgg_utils.files import InputError, one_line_errors, write_atomic, write_csv_atomic
from pgg_utils.identity import config_fields
from pgg_utils.pooling import mean_ci95

BASELINES = ("ppo", "pgg_g1.1")
# The behaviour-cloned nulls of the tables' agents (pgg_utils/bc_null.py, results/beyond/bc_null/run.sh): their
# folder, and the suffix that keys a fitted null's cells beside the same agents' own null in `means`.
BC_FOLDER, BC = "bc_null", " null=bc"
# The sets of the variant that clones the rollout's actions while it trains (results/beyond/bc_train/<task>).
BC_TRAIN_FOLDER = "bc_train"
# The ids of paper.BEYOND_VARIANTS by family (those with --null-bc-coef, {goal}, --guidance-schedule), as
# reproduce.grid_variants names them; tests/test_reproduce.py checks them against it.
CLONING_VARIANTS = {"pgg_g1.1_bc0.1"}
GOAL_VARIANTS = {"pgg_g1.1_goal"}
SCHEDULE_VARIANTS = {"pgg_g1to1.2", "pgg_adaptive1.1_kl0.04"}
# The command task's set (results/beyond/command/run_all.sh): its folder, its variants in the report's order with
# the null branch each is guided by, and its seeds. Its sweeps are read apart from the tasks' folders: its tests
# are a family of their own and never enter the other questions' Holm families.
COMMAND_FOLDER = "command"
COMMAND_VARIANTS = {"pgg_g1.1_null17": "command null", "pgg_g1.1": "state null", "ppo": "untrained null"}
COMMAND_NULL = "pgg_g1.1_null17"
COMMAND_SEEDS = 5
COMMAND_ENV = "paper_study.cheetah_velocity:HalfCheetahVelocity-v0"
# The sets that drop the condition (goal or command) in training, classifier-free guidance's recipe
# (results/beyond/condition_dropout/run_all.sh): their folder, and their variants with the set each is compared with.
DROPOUT_FOLDER = "condition_dropout"
DROPOUT_VARIANTS = {"pgg_drop0.1_goal": "Reacher-v4", "pgg_drop0.1_null17": "command"}
# Every variant of paper.BEYOND_VARIANTS: those the report compares with BASELINES.
BEYOND_VARIANT_IDS = SCHEDULE_VARIANTS | GOAL_VARIANTS | CLONING_VARIANTS | {COMMAND_NULL} | set(DROPOUT_VARIANTS)
SETS_APART = (BC_FOLDER, COMMAND_FOLDER, DROPOUT_FOLDER)  # folders of results/beyond that are not a task's
COLLAPSE_FRACTION = 0.5
REPORT_COLUMNS = ["env_id", "variant", "baseline", "step", "mean", "sd", "baseline_mean", "baseline_sd", "gap", "t",
                  "p", "p_holm", "detectable_gap", "n_seeds", "baseline_n_seeds"]  # fmt: skip
VALUE_COLUMNS = ["env_id", "variant", "baseline", "quantity", "value"]


@dataclass
class Args:
    folder: tyro.conf.Positional[str]
    """results/beyond: one folder per task, each with the episodes.csv of its sweep"""
    table: str = "results/continuous/episodes.csv"
    """the continuous table's episodes, for the baselines of the paper's tasks"""
    table_heldout: str = "results/continuous/heldout_gamma.csv"
    """the continuous table's held-out γ, for the baselines' rows of the held-out table"""
    discrete_table: str = "results/discrete/episodes.csv"
    """the discrete table's episodes, for the discrete agents whose null was behaviour-cloned"""
    discrete_heldout: str = "results/discrete/heldout_gamma.csv"
    """the discrete table's held-out γ, beside the fitted nulls'"""
    runs: str | None = None
    """the runs' folder, to rewrite guidance_trajectory.csv from their TensorBoard events; None: read the CSV"""


TRAJECTORY_COLUMNS = ["env_id", "variant", "seed", "step", "guidance", "kl"]


def write_trajectories(runs_folder: Path, output: Path) -> None:
    """γ_train and KL(π̂ ‖ π(·|s)) of every iteration of every scheduled or adaptive run under `runs_folder`."""
    import json

    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from pgg_utils.identity import variant_id

    rows = []
    for args_file in sorted(runs_folder.glob("*/args.json")):
        args = json.loads(args_file.read_text())
        if args.get("guidance_schedule", "constant") == "constant":
            continue
        events = EventAccumulator(str(args_file.parent), size_guidance={"scalars": 0})
        events.Reload()
        kls = {e.step: e.value for e in events.Scalars("pgg/kl_guided_vs_conditional")}
        rows += [{"env_id": args["env_id"], "variant": variant_id(args), "seed": args["seed"], "step": e.step,
                  "guidance": e.value, "kl": kls.get(e.step)} for e in events.Scalars("pgg/guidance")]  # fmt: skip
    write_csv_atomic(output, TRAJECTORY_COLUMNS, rows)


def read_trajectories(folder: Path) -> dict:
    """{(env, variant): {seed: [(step, γ_train, kl)]}} from guidance_trajectory.csv, where it exists."""
    path, out = folder / "guidance_trajectory.csv", defaultdict(lambda: defaultdict(list))
    if path.exists():
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                out[(r["env_id"], r["variant"])][int(r["seed"])].append(
                    (int(r["step"]), float(r["guidance"]), float(r["kl"]))
                )
    return out


def read_rows(path: Path, null_branch: str = "learned") -> list[dict]:
    """A sweep's sampled episodes of one null branch, read by the one reader (pgg_utils.episodes)."""
    return [r for r in read_episodes([path]) if r["policy"] == "sample" and r["null_branch"] == null_branch]


def seed_means(rows: list[dict]) -> dict:
    """{(env, variant, step, γ): {seed: mean return}} (pgg_utils.pooling.seed_means)."""
    return pooling.seed_means(rows, lambda r: (r["env_id"], r["variant"], int(r["step"]), float(r["eval_guidance"])))


def cells_of(means: dict, env: str, variant: str) -> dict:
    return {(step, gamma): seeds for (e, v, step, gamma), seeds in means.items() if e == env and v == variant}


def summary(seeds: dict) -> tuple[float, float, float]:
    values = list(seeds.values())
    mean, half, _, _ = mean_ci95(values)
    return mean, half, float(np.std(values, ddof=1)) if len(values) > 1 else math.nan


def collapsed(cells: dict, every_gamma: bool = False) -> list[int] | None:
    """Seeds whose return at the last step is below COLLAPSE_FRACTION of their best mark's: at γ = 1, or with
    `every_gamma` at their best eval γ of each mark. A schedule that ends at γ_train 1.2 trains the policy
    guided at 1.2, so its γ = 1 return can fall while its best γ holds. None where a seed's best is not
    positive (Pusher's and Reacher's returns are costs): half of it means nothing there."""
    by_step = defaultdict(lambda: defaultdict(lambda: -math.inf))
    for (step, gamma), seeds in cells.items():
        if every_gamma or gamma == 1.0:
            for seed, value in seeds.items():
                by_step[step][seed] = max(by_step[step][seed], value)
    if not by_step:
        return []
    last, out = max(by_step), []
    for seed, final in by_step[last].items():
        best = max(by_step[step][seed] for step in by_step)
        if best <= 0:
            return None
        if final < COLLAPSE_FRACTION * best:
            out.append(seed)
    return sorted(out)


def comparisons(means: dict, env: str, variant: str, baseline: str) -> tuple[list[dict], dict]:
    """Rows at γ = 1 per step, and the pooled tests over every common (step, γ) cell."""
    ours, theirs = cells_of(means, env, variant), cells_of(means, env, baseline)
    rows = []
    for step, gamma in sorted(ours):
        if gamma != 1.0 or (step, gamma) not in theirs:
            continue
        (m1, _, s1), (m2, _, s2) = summary(ours[(step, gamma)]), summary(theirs[(step, gamma)])
        n1, n2 = len(ours[(step, gamma)]), len(theirs[(step, gamma)])
        t, _, p = welch(m1, s1, n1, m2, s2, n2)
        rows.append({"env_id": env, "variant": variant, "baseline": baseline, "step": step, "mean": m1, "sd": s1,
                     "baseline_mean": m2, "baseline_sd": s2, "gap": m1 - m2, "t": t, "p": p,
                     "detectable_gap": detectable_gap(s1, n1, s2, n2, ALPHA), "n_seeds": n1,
                     "baseline_n_seeds": n2})  # fmt: skip
    common = sorted(set(ours) & set(theirs))
    pooled = {}
    if common:
        differences = [summary(ours[c])[0] - summary(theirs[c])[0] for c in common]
        pooled["above"], pooled["below"] = sum(d > 0 for d in differences), sum(d < 0 for d in differences)
        seeds = sorted(set.intersection(*(set(ours[c]) for c in common)))
        if len(seeds) >= 2:
            block = np.array([[ours[c][s] for s in seeds] for c in common])
            references = np.array([summary(theirs[c])[0] for c in common])
            if np.all(references != 0):
                pooled["median_gap"] = median_relative_gap([(block, references)])
        pooled["cells"] = len(common)
    return rows, pooled


def read_heldout(folder: Path, table_heldout: Path) -> dict:
    """{(env, variant, step): heldout row} from each task's heldout_gamma.csv and the table's."""
    out = {}
    tasks = [
        *(path for path in sorted(folder.glob("*/heldout_gamma.csv")) if path.parent.name not in SETS_APART),
        *sorted(folder.glob(f"{BC_TRAIN_FOLDER}/*/heldout_gamma.csv")),
    ]
    for path in [*([table_heldout] if table_heldout.exists() else []), *tasks]:
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                out[(r["env_id"], r["variant"], int(r["step"]))] = r
    return out


def read_goal_distance(folder: Path) -> dict:
    """{(env, variant, γ): {seed: final distance, mean over its episodes}} from goal_distance.csv."""
    path = folder / "goal_distance.csv"
    if not path.exists():
        return {}
    per_seed = defaultdict(lambda: defaultdict(list))
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            per_seed[(r["env_id"], r["variant"], float(r["eval_guidance"]))][int(r["seed"])].append(
                float(r["final_distance"])
            )
    return {key: {seed: float(np.mean(v)) for seed, v in sorted(s.items())} for key, s in per_seed.items()}


def pct(x: float, decimals: int = 1) -> str:
    return "–" if math.isnan(x) else f"{100 * x:+.{decimals}f}%"


def seed_list(seeds: list[int] | None) -> str:
    return "n/a" if seeds is None else ", ".join(map(str, seeds)) or "none"


def points(x: float, sign: bool = True) -> str:
    """A difference of two percentages, in percentage points."""
    return "–" if math.isnan(x) else f"{100 * x:{'+' if sign else ''}.1f} pts"


def checkpoint_iteration(run: list[tuple], mark: int) -> tuple | None:
    """The logged (step, γ_train, kl) of the iteration a run saved its checkpoint of `mark` at: the first whose
    step reaches the mark (training saves right after it), None where the run has not reached it."""
    return min((t for t in run if t[0] >= mark), default=None)


def record(values_out: list[dict], env: str, variant: str, baseline: str, quantity: str, value: float) -> None:
    """One number of the report, unrounded, as report.md prints it (percentages in percent): report_values.csv
    is what the front page's numbers are checked against, so that a number rounded twice is caught."""
    values_out.append({"env_id": env, "variant": variant, "baseline": baseline, "quantity": quantity,
                       "value": float(value)})  # fmt: skip


def task_section(env: str, means: dict, variants: list[str], rows: list[dict], pooled: dict, heldout: dict,
                 distance: dict, trajectories: dict, values_out: list[dict]) -> list[str]:  # fmt: skip
    lines = [f"## {env}", ""]
    steps = sorted({s for (e, v, s, g) in means if e == env})
    scheduled = [v for v in variants if trajectories.get((env, v))]
    if scheduled:
        lines += [("γ_train of each checkpoint's own iteration, the first whose step reaches the mark (mean over seeds, "
                  "min–max over seeds): where the schedule had taken the guidance."), "",
                  "| variant | " + " | ".join(step_label(s) for s in steps) + " |", "|---|" + "---|" * len(steps)]  # fmt: skip
        for variant in scheduled:
            cells = []
            for step in steps:
                values = [t[1] for t in (checkpoint_iteration(runs, step) for runs in
                                          trajectories[(env, variant)].values()) if t is not None]  # fmt: skip
                if values:
                    summary_of = {"mean": float(np.mean(values)), "min": min(values), "max": max(values)}
                    for name, value in summary_of.items():
                        record(values_out, env, variant, "", f"γ_train {name} at {step_label(step)}", value)
                    cells.append(f"{summary_of['mean']:.3f} ({min(values):.3f}–{max(values):.3f})")
                else:
                    cells.append("–")
            lines.append(f"| {paper_name(variant)} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += [("Return at γ = 1, mean ± 95% CI over seeds (seed sd); runs whose return at the last step fell below "
              "half their best mark's, named by seed: at γ = 1, and at their best eval γ of each mark (n/a where "
              "returns are costs)."), "",
              "| variant | " + " | ".join(step_label(s) for s in steps) + " | fell at γ = 1 | fell at its best γ |",
              "|---|" + "---|" * (len(steps) + 2)]  # fmt: skip
    for variant in variants:
        cells = cells_of(means, env, variant)
        out = []
        for step in steps:
            if (step, 1.0) in cells:
                m, h, s = summary(cells[(step, 1.0)])
                out.append(f"{m:.1f} ± {h:.1f} ({s:.0f})")
            else:
                out.append("–")
        fell = [seed_list(collapsed(cells, every)) for every in (False, True)]
        lines.append(f"| {paper_name(variant)} | " + " | ".join(out) + f" | {fell[0]} | {fell[1]} |")
    cloning = sum(r["variant"] in CLONING_VARIANTS for r in rows)
    lines += ["", (f"Each new variant against each baseline at γ = 1 (Welch's t test, Holm over the report's {len(rows) - cloning} "
              f"such tests of the schedules and goal nulls, and apart over the {cloning} of the cloning variant; beside it the gap one test detects with 80% power at α = 0.05, before Holm, so a "
              "non-significant row rules out less than it shows). γ = 1 is not the policy a schedule ending at "
              "γ_train 1.2 was trained toward: the held-out and γ-response tables below compare at other γ. Then, "
              "over every (step, eval γ) cell both sweeps hold: how many cells lie above and below the baseline "
              "(no p value: the cells of one run share its seeds), and the median relative gap (ours − baseline) / "
              "|baseline| with its exact bootstrap interval over our seeds, which resamples whole runs but holds "
              "the baseline's means fixed; a percentile bootstrap over 5 seeds under-covers, so the interval is "
              "narrower than the truth."), "",
              ("| variant | baseline | step | gap | p (Holm) | detectable gap | cells above / below | "
              "median gap [95% CI] |"), "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        if r["env_id"] != env:
            continue
        key = (env, r["variant"], r["baseline"])
        last = r["step"] == max(x["step"] for x in rows if (x["env_id"], x["variant"], x["baseline"]) == key)
        tail = "| |"
        if last and key in pooled:
            above, below = pooled[key]["above"], pooled[key]["below"]
            gap = pooled[key].get("median_gap")
            for quantity, value in (("cells above", above), ("cells below", below), ("cells", pooled[key]["cells"])):
                record(values_out, *key, quantity, value)
            tail = f"| {above} / {below} | " + (
                f"{pct(gap[0], 2)} [{pct(gap[1], 2)}, {pct(gap[2], 2)}] |" if gap else "– |"
            )
        lines.append(f"| {paper_name(r['variant'])} | {paper_name(r['baseline'])} | {step_label(r['step'])} | "
                     f"{fmt(r['gap'])} | {fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | {fmt(r['detectable_gap'])} {tail}")  # fmt: skip
    held = [(v, heldout.get((env, v, steps[-1]))) for v in variants]
    if any(h for _, h in held):
        lines += ["", (f"Held-out γ at {step_label(steps[-1])}: chosen on the sweep above, scored on a fresh sweep "
                  "(episode seeds 20000+) against γ = 1 on the same fresh episodes; Holm over the groups of the sweep each row comes "
                   "from (the continuous table's for its runs, this task's for those trained here)."), "",
                  "| variant | chosen γ | fresh return | fresh at γ = 1 | gain ± 95% CI | p (Holm) |",
                  "|---|---|---|---|---|---|"]  # fmt: skip
        for variant, h in held:
            if h and h["status"] == "tested":
                lines.append(f"| {paper_name(variant)} | {float(h['selected_gamma']):g} | {fmt(float(h['fresh_mean']))} | "
                             f"{fmt(float(h['fresh_baseline']))} | {fmt(float(h['fresh_gain']))} ± "
                             f"{fmt(float(h['fresh_gain_ci95']))} | {fmt_p(float(h['p']))} ({fmt_p(float(h['p_holm']))}) |")  # fmt: skip
            elif h:
                lines.append(f"| {paper_name(variant)} | {float(h['selected_gamma']):g} | – | – | γ = 1 chosen | – |")
    gammas = sorted({g for (e, v, s, g) in means if e == env and s == steps[-1]})
    lines += ["", (f"γ-response at {step_label(steps[-1])}: mean return over seeds at each eval γ, and how far the "
                   f"largest γ ({gammas[-1]:g}) falls below the best: the deterioration past a modest γ the paper "
                   "reports."), "",
              "| variant | " + " | ".join(f"γ = {g:g}" for g in gammas) + f" | γ = {gammas[-1]:g} vs best |",
              "|---|" + "---|" * (len(gammas) + 1)]  # fmt: skip
    for variant in variants:
        _, values = response_at_last_step(means, env, variant)
        _, drop = largest_vs_best(values)
        for g, v in zip(gammas, values):
            record(values_out, env, variant, "", f"return at γ {g:g} at {step_label(steps[-1])}", v)
        record(values_out, env, variant, "", f"largest γ vs best at {step_label(steps[-1])} (%)", 100 * drop)
        lines.append(f"| {paper_name(variant)} | " + " | ".join("–" if math.isnan(v) else f"{v:.1f}" for v in values)
                     + f" | {pct(drop)} |")  # fmt: skip
    goal_gammas = sorted({g for (e, v, g) in distance if e == env})
    if goal_gammas:
        lines += ["", (f"Final distance to the goal at {step_label(steps[-1])} (in the last observation; "
                  "lower is closer), mean ± 95% CI over seeds of the per-seed mean over episodes."), "",
                  "| variant | " + " | ".join(f"γ = {g:g}" for g in goal_gammas) + " |",
                  "|---|" + "---|" * len(goal_gammas)]  # fmt: skip
        for variant in variants:
            out = []
            for g in goal_gammas:
                values = list(distance.get((env, variant, g), {}).values())
                out.append(f"{mean_ci95(values)[0]:.4f} ± {mean_ci95(values)[1]:.4f}" if values else "–")
            lines.append(f"| {paper_name(variant)} | " + " | ".join(out) + " |")
    return [*lines, ""]


def last_step(means: dict, env: str) -> int:
    return max(s for (e, v, s, g) in means if e == env)


def response_at_last_step(means: dict, env: str, variant: str) -> tuple[list[float], list[float]]:
    """The eval γ list at the task's last step and the variant's mean return over seeds at each (nan where unswept)."""
    last = last_step(means, env)
    gammas = sorted({g for (e, v, s, g) in means if e == env and s == last})
    cells = cells_of(means, env, variant)
    return gammas, [summary(cells[(last, g)])[0] if (last, g) in cells else math.nan for g in gammas]


def largest_vs_best(values: list[float]) -> tuple[int, float]:
    """The index of the best of a γ-response (nan where unswept) and how far its last value lies below it, relative."""
    best = int(np.nanargmax(values))
    return best, (values[-1] - values[best]) / abs(values[best])


def scheduled_tasks(variants_of: dict) -> list[str]:
    """The tasks with a scheduled or adaptive γ_train variant, sorted."""
    return sorted(e for e, vs in variants_of.items() if SCHEDULE_VARIANTS & set(vs))


def seed_falls(means: dict, env: str, variant: str) -> tuple[float, list[float], list[float]]:
    """The variant's best eval γ at the last step (best on the mean over seeds), each seed's relative fall from
    it to the largest γ, and each seed's return at it; no falls where either γ is unswept."""
    gammas, values = response_at_last_step(means, env, variant)
    if all(math.isnan(v) for v in values):
        return math.nan, [], []
    last, best = last_step(means, env), gammas[int(np.nanargmax(values))]
    cells = cells_of(means, env, variant)
    at_best, at_largest = cells.get((last, best), {}), cells.get((last, gammas[-1]), {})
    falls = [(at_largest[seed] - at_best[seed]) / abs(at_best[seed]) for seed in sorted(at_best) if seed in at_largest]
    return best, falls, [at_best[seed] for seed in sorted(at_best)]


def welch_of(ours: list[float], theirs: list[float]) -> dict:
    """Welch's test of two samples: their means, p and the difference one test detects with 80% power."""
    (m1, s1, n1), (m2, s2, n2) = ((float(np.mean(x)), float(np.std(x, ddof=1)), len(x)) for x in (ours, theirs))
    return {"mean": m1, "baseline_mean": m2, "p": welch(m1, s1, n1, m2, s2, n2)[2],
            "detectable": detectable_gap(s1, n1, s2, n2, ALPHA)}  # fmt: skip


def fall_tests(means: dict, variants_of: dict, gamma_one_p: list[float] = (), variants=SCHEDULE_VARIANTS) -> list[dict]:
    """Each of `variants` (the schedules) against each baseline, each side at its own best eval γ: the per-seed
    fall from it to the largest γ, and the per-seed return at it; Welch's t, Holm over each kind's tests alone,
    and for the falls also Holm over them with the report's γ = 1 tests (`gamma_one_p`), the family the verdict
    was drawn from."""
    rows = []
    for env in sorted(e for e, vs in variants_of.items() if set(variants) & set(vs)):
        for variant in (v for v in variants_of[env] if v in variants):
            best, ours, our_returns = seed_falls(means, env, variant)
            for baseline in (b for b in BASELINES if b in variants_of[env]):
                baseline_best, theirs, their_returns = seed_falls(means, env, baseline)
                if len(ours) < 2 or len(theirs) < 2:
                    continue
                fall, at_best = welch_of(ours, theirs), welch_of(our_returns, their_returns)
                rows.append({"env_id": env, "variant": variant, "baseline": baseline, "best": best,
                             "baseline_best": baseline_best, "fall": fall["mean"], "baseline_fall": fall["baseline_mean"],
                             "p": fall["p"], "detectable": fall["detectable"], "return": at_best["mean"],
                             "baseline_return": at_best["baseline_mean"], "return_p": at_best["p"],
                             "return_detectable": at_best["detectable"]})  # fmt: skip
    falls = [r["p"] for r in rows]
    for row, p_holm, p_joint, return_holm in zip(rows, holm(falls), holm([*falls, *gamma_one_p]),
                                                 holm([r["return_p"] for r in rows])):  # fmt: skip
        row["p_holm"], row["p_holm_with_gamma_one"], row["return_p_holm"] = p_holm, p_joint, return_holm
    return rows


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


def count_of(seeds: list[int] | None, of: int) -> str:
    return "n/a" if seeds is None else f"{len(seeds)} of {of}"


def distance_tests(distance: dict, variants_of: dict) -> list[dict]:
    """Each goal task's variants: the final distance to the goal (mean over seeds) at γ = 1, at the closest γ and at
    the largest, and each seed's change from γ = 1 to the largest, paired by seed (a one-sample t test of the
    changes; Holm over these tests)."""
    rows = []
    for env in sorted({e for (e, v, g) in distance if e in variants_of}):
        for variant in (v for v in variants_of[env] if (env, v, 1.0) in distance):
            gammas = sorted(g for (e, v, g) in distance if e == env and v == variant)
            at_one, at_largest = distance[(env, variant, 1.0)], distance[(env, variant, gammas[-1])]
            changes = [at_largest[seed] - at_one[seed] for seed in sorted(at_one) if seed in at_largest]
            values = [float(np.mean(list(distance[(env, variant, g)].values()))) for g in gammas]
            closest = int(np.argmin(values))
            rows.append({"env_id": env, "variant": variant, "at_one": values[gammas.index(1.0)],
                         "closest_gamma": gammas[closest], "closest": values[closest], "largest_gamma": gammas[-1],
                         "largest": values[-1], "farther": sum(c > 0 for c in changes), "seeds": len(changes),
                         "p": float(stats.ttest_1samp(changes, 0.0).pvalue) if len(changes) > 1 else math.nan})  # fmt: skip
    for row, p_holm in zip(rows, holm([r["p"] for r in rows])):
        row["p_holm"] = p_holm
    return rows


def glance_section(means: dict, variants_of: dict, distance: dict, gamma_one_p: list[float],
                   values_out: list[dict]) -> list[str]:  # fmt: skip
    """One table per question, the numbers the verdicts rest on; each task's section below has the rest."""
    lines = ["## At a glance", ""]
    scheduled = scheduled_tasks(variants_of)
    if scheduled:
        lines += [("Did scheduling or adapting γ_train remove the fall past a modest γ? At the last mark, from the "
                  "means over seeds: the return at γ = 1, the best eval γ, the largest γ swept and how far its mean "
                  "lies below the best's; and the runs whose return fell below half their best mark's, at γ = 1 and "
                  "at their best eval γ of each mark. The best γ is chosen on these same episodes, which makes "
                  "every variant's fall a little larger than a fresh sweep would."), "",
                  ("| task | variant | γ = 1 | best γ: return | largest γ: return | largest vs best | fell at γ = 1 | "
                  "fell at its best γ |"), "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for env in scheduled:
            for variant in (v for v in variants_of[env] if v not in GOAL_VARIANTS | CLONING_VARIANTS):
                gammas, values = response_at_last_step(means, env, variant)
                cells = cells_of(means, env, variant)
                if 1.0 not in gammas or any(math.isnan(v) for v in values):
                    continue  # a variant not swept at every γ of the task's last step
                (best, drop), at_one = largest_vs_best(values), values[gammas.index(1.0)]
                seeds = len(cells[(max(s for s, g in cells), 1.0)])
                fell = [collapsed(cells), collapsed(cells, every_gamma=True)]
                for quantity, value in (("return at γ 1", at_one), ("best γ", gammas[best]),
                                        ("return at best γ", values[best]), ("largest γ", gammas[-1]),
                                        ("return at largest γ", values[-1]), ("largest γ vs best (%)", 100 * drop),
                                        ("seeds", seeds), *((f"fell at {at}", len(f)) for at, f in
                                                            zip(("γ 1", "best γ"), fell) if f is not None)):  # fmt: skip
                    record(values_out, env, variant, "", quantity, value)
                lines.append(f"| {env} | {paper_name(variant)} | {at_one:.1f} | {gammas[best]:g}: {values[best]:.1f} | "
                             f"{gammas[-1]:g}: {values[-1]:.1f} | {pct(drop)} | {count_of(fell[0], seeds)} | "
                             f"{count_of(fell[1], seeds)} |")  # fmt: skip
        falls = fall_tests(means, variants_of, gamma_one_p)
        lines += ["", ("Is the fall smaller than the baselines'? Each seed's fall at the last mark from its variant's best "
                  "γ (above) to the largest, relative to its return at the best γ, and the mean of these falls (not "
                  f"the ratio of means above); against each baseline's, Welch's t test (Holm over these {len(falls)} "
                  f"tests alone, and over them with the report's {len(gamma_one_p)} γ = 1 tests), and the difference "
                  "in falls one test detects with 80% power at α = 0.05, before Holm. A negative difference is a "
                  "larger fall than the baseline's. A variant whose best γ lies nearer the largest has less room to "
                  "fall: the best γ of each side is shown."), "",
                  ("| task | variant | baseline | best γ (baseline's) | fall | baseline's fall | difference | p (Holm) | "
                  "Holm with the γ = 1 tests | detectable difference |"), "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
        record(values_out, "", "", "", "fall tests", len(falls))
        record(values_out, "", "", "", "γ = 1 tests", len(gamma_one_p))
        for r in falls:
            for quantity, value in (("fall (%)", 100 * r["fall"]), ("baseline's fall (%)", 100 * r["baseline_fall"]),
                                    ("fall difference (pts)", 100 * (r["fall"] - r["baseline_fall"])),
                                    ("fall p", r["p"]), ("fall p Holm", r["p_holm"]),
                                    ("fall p Holm with the γ = 1 tests", r["p_holm_with_gamma_one"]),
                                    ("fall detectable (pts)", 100 * r["detectable"]), ("return at best γ", r["return"]),
                                    ("baseline's return at its best γ", r["baseline_return"]),
                                    ("return difference at best γ", r["return"] - r["baseline_return"]),
                                    ("return at best γ p", r["return_p"]), ("return at best γ p Holm", r["return_p_holm"]),
                                    ("return at best γ detectable", r["return_detectable"])):  # fmt: skip
                record(values_out, r["env_id"], r["variant"], r["baseline"], quantity, value)
            lines.append(f"| {r['env_id']} | {paper_name(r['variant'])} | {paper_name(r['baseline'])} | {r['best']:g} "
                         f"({r['baseline_best']:g}) | {pct(r['fall'])} | {pct(r['baseline_fall'])} | "
                         f"{points(r['fall'] - r['baseline_fall'])} | {fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | "
                         f"{fmt_p(r['p_holm_with_gamma_one'])} | {points(r['detectable'], sign=False)} |")  # fmt: skip
        lines += ["", ("Does a schedule cost return at its best γ? The same seeds' returns at each side's best γ (as "
                  "above): Welch's t test, Holm over these tests alone, and the difference one test detects with 80% "
                  "power at α = 0.05, before Holm."), "",
                  ("| task | variant | baseline | best γ (baseline's) | return | baseline's return | difference | "
                  "p (Holm) | detectable difference |"), "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for r in falls:
            lines.append(f"| {r['env_id']} | {paper_name(r['variant'])} | {paper_name(r['baseline'])} | {r['best']:g} "
                         f"({r['baseline_best']:g}) | {fmt(r['return'])} | {fmt(r['baseline_return'])} | "
                         f"{fmt(r['return'] - r['baseline_return'])} | {fmt_p(r['return_p'])} "
                         f"({fmt_p(r['return_p_holm'])}) | {fmt(r['return_detectable'])} |")  # fmt: skip
        lines.append("")
    goal = distance_tests(distance, variants_of)
    if goal:
        lines += [("Does guiding on the goal give a knob that state guidance lacks? The final distance to the goal "
                  "(mean over seeds) at γ = 1, at the eval γ that brings it closest (chosen on these episodes), and "
                  "at the largest γ swept; then, paired by seed, how many seeds end farther from the goal at the "
                  "largest γ than at γ = 1, and a t test of the seeds' changes (Holm over these tests); intervals are "
                  "in each task's section."), "",
                  ("| task | variant | γ = 1 | closest γ: distance | largest γ: distance | largest vs γ = 1 | "
                  "seeds farther | p (Holm) |"), "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for r in goal:
            change = (r["largest"] - r["at_one"]) / r["at_one"]
            for quantity, value in (("distance at γ 1", r["at_one"]), ("closest γ", r["closest_gamma"]),
                                    ("distance at closest γ", r["closest"]), ("largest γ", r["largest_gamma"]),
                                    ("distance at largest γ", r["largest"]), ("distance largest vs γ 1 (%)", 100 * change),
                                    ("seeds farther", r["farther"]), ("seeds", r["seeds"]), ("distance p", r["p"]),
                                    ("distance p Holm", r["p_holm"])):  # fmt: skip
                record(values_out, r["env_id"], r["variant"], "", quantity, value)
            lines.append(f"| {r['env_id']} | {paper_name(r['variant'])} | {r['at_one']:.4f} | {r['closest_gamma']:g}: "
                         f"{r['closest']:.4f} | {r['largest_gamma']:g}: {r['largest']:.4f} | {pct(change)} | "
                         f"{r['farther']} of {r['seeds']} | {fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) |")  # fmt: skip
        lines.append("")
    return lines


def paired_test(ours: dict, theirs: dict) -> dict | None:
    """A paired t test of two {seed: value} (the same agents, the same episodes) on their shared seeds: the
    mean difference, p, and the difference one test detects with 80% power at α = 0.05 (the noncentral t);
    None with fewer than 3 shared seeds or no spread in the differences, where no test means anything."""
    seeds = sorted(ours.keys() & theirs.keys())
    differences = np.array([ours[seed] - theirs[seed] for seed in seeds])
    if len(seeds) < 3 or not np.std(differences) > 0:
        return None
    n, sd = len(seeds), float(np.std(differences, ddof=1))
    critical = stats.t.ppf(1 - ALPHA / 2, n - 1)
    # The lower tail is below 1e-10 where the power nears 0.8, and scipy's noncentral t returns NaN far out in it.
    power = lambda gap: stats.nct.sf(critical, n - 1, gap * math.sqrt(n) / sd)
    high = sd
    while power(high) < 0.8:
        high *= 2
    return {"difference": float(differences.mean()), "n": n, "p": float(stats.ttest_1samp(differences, 0.0).pvalue),
            "detectable": float(optimize.brentq(lambda gap: power(gap) - 0.8, 0.0, high))}  # fmt: skip


def read_bc(folder: Path, args: Args) -> tuple[dict, dict, list[tuple[str, str]], dict]:
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
            with open(table, newline="") as f:
                for r in csv.DictReader(f):
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


def question_3_reading(values_out: list[dict]) -> list[str]:
    """Question 3's verdicts, each no more than its test, written from the numbers the section's tables recorded:
    the fitted null's fall and return tests, its cells' gap (no test), and cloning while training on fresh episodes."""
    value = {(r["env_id"], r["variant"], r["baseline"], r["quantity"]): r["value"] for r in values_out}
    envs = list(dict.fromkeys(r["env_id"] for r in values_out if r["variant"] == "ppo" + BC))

    def tested(env, variant, baseline, kind):
        return (env, variant, baseline, f"{kind} p Holm") in value

    def sig(env, variant, baseline, kind):
        return value[(env, variant, baseline, f"{kind} p Holm")] < ALPHA

    def p_text(env, variant, baseline, kind):
        return (f"p {fmt_p(value[(env, variant, baseline, kind + ' p')])}, "
                f"Holm {fmt_p(value[(env, variant, baseline, kind + ' p Holm')])}")  # fmt: skip

    lines = []
    ppo_bc = "ppo" + BC
    falls = [e for e in envs if tested(e, ppo_bc, "ppo", "fall")]
    smaller = [
        e for e in falls if sig(e, ppo_bc, "ppo", "fall") and value[(e, ppo_bc, "ppo", "fall difference (pts)")] > 0
    ]
    others = [e for e in falls if e not in smaller]
    if falls:

        def fall_of(e):
            return (f"{e} {value[(e, ppo_bc, 'ppo', 'fall difference (pts)')]:+.1f} points, "
                    f"{p_text(e, ppo_bc, 'ppo', 'fall')}")  # fmt: skip

        unused = [e for e in smaller if value.get((e, ppo_bc, "question 3", "best γ")) == 1.0]
        lines.append(f"- **The fitted null and PPO's knob.** Scored on fresh episodes, γ falls less from its best value "
                     f"to the largest with the cloned null than with PPO's untrained one on {len(smaller)} of "
                     f"{len(falls)} tasks ({'; '.join(fall_of(e) for e in smaller) or 'none'}); not on the others "
                     f"({'; '.join(fall_of(e) for e in others)}), where a negative difference is a larger fall."
                     + (f" On {', '.join(unused)} the cloned null's best γ is 1 (no guidance): its smaller fall is "
                        "from γ = 1, not from a γ at which guidance helped." if unused else ""))  # fmt: skip
    returns = [e for e in envs if tested(e, ppo_bc, "ppo", "return")]
    if returns:

        def return_of(e):
            return (
                f"{e} {value[(e, ppo_bc, 'ppo', 'return difference at best γ')]:+.1f}, "
                f"{p_text(e, ppo_bc, 'ppo', 'return')}, detectable {value[(e, ppo_bc, 'ppo', 'return detectable')]:.0f}"
            )

        gaps = [e for e in envs if (e, ppo_bc, "ppo", "median gap (%)") in value
                and value[(e, ppo_bc, "ppo", "median gap low (%)")] > 0]  # fmt: skip
        gap_text = "; ".join(f"{e} {value[(e, ppo_bc, 'ppo', 'median gap (%)')]:+.1f}% "
                             f"[{value[(e, ppo_bc, 'ppo', 'median gap low (%)')]:+.1f}, "
                             f"{value[(e, ppo_bc, 'ppo', 'median gap high (%)')]:+.1f}]" for e in gaps)  # fmt: skip
        lines.append("- **Return, PPO's agents.** Tested at each side's best γ only, on fresh episodes: "
                     f"{sum(sig(e, ppo_bc, 'ppo', 'return') for e in returns)} of {len(returns)} tests survive Holm "
                     f"({'; '.join(return_of(e) for e in returns)}), so a "
                     "difference below the detectable one is not ruled out. Over the sweep's γ ≠ 1 cells the cloned "
                     f"null's returns lie above the untrained null's on {', '.join(gaps) or 'no task'} (median gap "
                     f"{gap_text or '–'}), a gap with no test of its own: the cells share their seeds.")  # fmt: skip
    own = "pgg_g1.1"
    trained = [e for e in envs if tested(e, own + BC, own, "return")]
    if trained:
        costs = [e for e in trained if sig(e, own + BC, own, "return")]
        lines.append(f"- **In place of a trained null.** For the γ_train 1.1 agents, {len(costs)} of {len(trained)} "
                     "return tests at the best γ survive Holm: "
                     + ("; ".join(f"{e} {value[(e, own + BC, own, 'return difference at best γ')]:+.1f} "
                                  f"({p_text(e, own + BC, own, 'return')})" for e in costs) or "none")
                     + ". That is the evidence that the cloned null does not replace a trained one, on those tasks "
                     "alone.")  # fmt: skip
    cloning = [(e, b) for (e, v, b, q) in value if v in CLONING_VARIANTS and q == "fresh fall p Holm"]
    if cloning:

        def fresh_fall(e, b):
            v = next(iter(CLONING_VARIANTS))
            return (
                f"{e} {value[(e, v, b, 'fresh fall difference (pts)')]:+.1f} points, "
                f"{p_text(e, v, b, 'fresh fall')}, detectable {value[(e, v, b, 'fresh fall detectable (pts)')]:.1f}"
            )

        variant = next(iter(CLONING_VARIANTS))
        parts = []
        for baseline in BASELINES:
            sided = [(e, b) for e, b in cloning if b == baseline]
            significant = [(e, b) for e, b in sided if value[(e, variant, b, "fresh fall p Holm")] < ALPHA]
            parts.append(f"than {paper_name(baseline)} on {len(significant)} of {len(sided)} tasks "
                         f"({'; '.join(fresh_fall(e, b) for e, b in sided)})")  # fmt: skip
        lines.append("- **Cloning while training.** On fresh episodes, with each side's best γ chosen on the sweep, "
                     f"the cloning variant's fall is smaller {parts[0]}; and {parts[1]}, the comparison that isolates "
                     "the cloning (the same γ_train). Where no test survives Holm, 5 seeds detect only differences "
                     "of the size shown.")  # fmt: skip
    return ["### Question 3: what these tests say, and no more", "", *lines, ""] if lines else []


def bc_figure(means: dict, sets: list[tuple[str, str]], path: Path) -> None:
    """A panel per task: each set of agents' γ-response with its own null (solid) and the cloned one (dashed)."""
    envs = list(dict.fromkeys(env for env, _ in sets))
    fig, axes = panels(len(envs), 3.4)
    for ax, env in zip(axes, envs):
        for variant in (v for e, v in sets if e == env):
            for key, style in ((variant, "-"), (variant + BC, "--")):
                cells, last = cells_of(means, env, key), last_step(means, env)
                gammas = sorted(g for (s, g) in cells if s == last)
                band(ax, gammas, [list(cells[(last, g)].values()) for g in gammas], variant,
                     f"{paper_name(variant)}, {null_name(key)} null", style)  # fmt: skip
        ax.set(title=f"{env}, {step_label(last_step(means, env))}", xlabel="eval guidance γ", ylabel="return")
        ax.set_xscale("log" if max(g for (e, v, s, g) in means if e == env) > 2 else "linear")
    save(fig, axes, path)


def band(ax, xs, per_x_values, variant: str, label: str | None = None, linestyle: str = "-") -> None:
    """A variant's mean over seeds against x, with its 95% CI as a band."""
    stats = [mean_ci95(values) for values in per_x_values]
    mean, half = np.array([s[0] for s in stats]), np.array([s[1] for s in stats])
    color = variant_colour(variant)
    ax.plot(xs, mean, marker="o", ms=3, color=color, label=label or paper_name(variant), linestyle=linestyle)
    ax.fill_between(xs, mean - half, mean + half, color=color, alpha=0.15)


def panels(count: int, height: float, columns: int = 3):
    """`count` panels, `columns` to a row; the unused ones of the last row are hidden."""
    rows, columns = -(-count // columns), min(count, columns)
    fig, grid = plt.subplots(rows, columns, figsize=(4.3 * columns, height * rows), squeeze=False)
    axes = list(grid.flat)
    for ax in axes[count:]:
        ax.set_visible(False)
    return fig, axes[:count]


def save(fig, axes, path: Path) -> None:
    for ax in axes:  # each panel names its own variants: tasks differ in which were run
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def gamma_response_figure(means: dict, envs: list[str], variants_of: dict, path: Path) -> None:
    """A panel per task: the tasks of the schedules first (a row of their own for the paper's three), then the goal's."""
    envs = [*scheduled_tasks(variants_of), *(e for e in envs if e not in scheduled_tasks(variants_of))]
    fig, axes = panels(len(envs), 3.4)
    for ax, env in zip(axes, envs):
        last = last_step(means, env)
        for variant in variants_of[env]:
            cells = cells_of(means, env, variant)
            gammas = sorted(g for (s, g) in cells if s == last)
            band(ax, gammas, [list(cells[(last, g)].values()) for g in gammas], variant)
        ax.set(title=f"{env}, {step_label(last)}", xlabel="eval guidance γ", ylabel="return")
    save(fig, axes, path)


def trajectory_figure(trajectories: dict, path: Path) -> None:
    keys = sorted(trajectories)
    fig, axes = panels(len(keys), 3.2, columns=len({v for e, v in keys}))  # a row per task
    for ax, (env, variant) in zip(axes, keys):
        for seed, points in sorted(trajectories[(env, variant)].items()):
            steps, gammas, _ = zip(*sorted(points))
            ax.plot(steps, gammas, color=variant_colour(variant), alpha=0.7, lw=1, label=f"seed {seed}")
        ax.set_title(f"{env}\n{paper_name(variant)}", fontsize=9)
        ax.set(xlabel="training steps", ylabel="γ_train")
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(steps_formatter))
    save(fig, axes, path)


def distance_figure(distance: dict, variants_of: dict, path: Path) -> None:
    """A panel per goal task, of the variants the report's tables hold (goal_distance.csv may hold more)."""
    envs = sorted({e for (e, v, g) in distance if e in variants_of})
    fig, axes = panels(len(envs), 3.4)
    for ax, env in zip(axes, envs):
        for variant in (v for v in variants_of[env] if (env, v, 1.0) in distance):
            gammas = sorted(g for (e, v, g) in distance if e == env and v == variant)
            band(ax, gammas, [list(distance[(env, variant, g)].values()) for g in gammas], variant)
        ax.set_title(f"{env}: final distance to the goal", fontsize=10)
        ax.set(xlabel="eval guidance γ", ylabel="distance (lower is closer)")
    save(fig, axes, path)


def read_tracking(path: Path) -> tuple[dict, dict, int]:
    """({(variant, seed, γ, command): (mean |achieved − commanded| velocity, mean achieved velocity, mean return,
    episodes)} over the episodes of tracking.csv at its last step, {command: inside the training range}, that step)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return {}, {}, 0
    last = max(int(r["step"]) for r in rows)
    cells = defaultdict(list)
    for r in rows:
        if int(r["step"]) == last:
            cells[(r["variant"], int(r["seed"]), float(r["eval_guidance"]), float(r["command"]))].append(
                (abs(float(r["velocity_error"])), float(r["mean_velocity"]), float(r["return"]))
            )
    inside = {float(r["command"]): r["in_training_range"] == "yes" for r in rows}
    out = {key: (*np.mean(values, axis=0).tolist(), len(values)) for key, values in cells.items()}
    return out, inside, last


def tracking_gaps(cells: dict) -> list[str]:
    """What the set lacks to be whole: COMMAND_SEEDS seeds of every variant, each at every (γ, command) that any
    seed has, with as many episodes as the fullest cell; [] where it is whole."""
    grid = {(g, c) for (v, s, g, c) in cells}
    episodes = max((n for *_, n in cells.values()), default=0)
    gaps = []
    for variant in COMMAND_VARIANTS:
        seeds = sorted({s for (v, s, g, c) in cells if v == variant})
        if len(seeds) < COMMAND_SEEDS:
            gaps.append(f"{paper_name(variant)}: {len(seeds)} of {COMMAND_SEEDS} seeds")
        short = sorted(f"seed {s}" for s in seeds for g, c in grid
                       if cells.get((variant, s, g, c), (0, 0, 0, 0))[3] < episodes)  # fmt: skip
        if short:
            gaps.append(
                f"{paper_name(variant)}: cells missing or short of {episodes} episodes ({', '.join(sorted(set(short)))})"
            )
    return gaps


def per_seed(cells: dict, variant: str, gamma: float, commands: list[float], field: int) -> dict:
    """{seed: mean over `commands` of one field of the cells (0 error, 1 velocity, 2 return)} for the seeds that
    hold every one of those cells."""
    seeds = {s for (v, s, g, c) in cells if v == variant}
    return {s: float(np.mean([cells[(variant, s, gamma, c)][field] for c in commands])) for s in sorted(seeds)
            if all((variant, s, gamma, c) in cells for c in commands)}  # fmt: skip


def change_of(at: dict, reference: dict) -> dict:
    return {seed: at[seed] - reference[seed] for seed in at if seed in reference}


def command_gain(cells: dict, variant: str, gamma: float, commands: list[float]) -> dict:
    """{seed: the slope of achieved on commanded velocity over `commands`}: 1 follows every change of command."""
    out = {}
    for seed in sorted({s for (v, s, g, c) in cells if v == variant}):
        if all((variant, seed, gamma, c) in cells for c in commands) and len(commands) > 1:
            out[seed] = float(np.polyfit(commands, [cells[(variant, seed, gamma, c)][1] for c in commands], 1)[0])
    return out


def seeds_cell(values: dict, digits: int = 2) -> str:
    if not values:
        return "–"
    mean, half, _, _ = mean_ci95(list(values.values()))
    return f"{mean:.{digits}f} ± {half:.{digits}f}" if len(values) > 1 else f"{mean:.{digits}f}"


def command_name(variant: str) -> str:
    """A variant of the command set as its tables name it: the paper's name and the null it is guided by."""
    return f"{paper_name(variant)} ({COMMAND_VARIANTS[variant]})"


def command_section(folder: Path, values_out: list[dict]) -> list[str]:
    """The command task: does γ set how closely an agent follows its command, and with which null?"""
    base = folder / COMMAND_FOLDER
    lines = ["## Guidance on a command", "",
             ("HalfCheetah told each episode how fast to run (`paper_study/cheetah_velocity/`: a commanded forward "
              "velocity drawn from the training range, appended to the observation; reward v_cmd − |v − v_cmd| − "
              "0.1·Σa²), trained with the null on the command (`--null-dims 17`: π(a|s, ∅) cannot read the command, but "
              "trained without dropping the command it acts as the policy at one fixed pseudo-command, so γ > 1 pushes "
              "behaviour away from that command rather than amplifying what the command adds: \"What the learned null "
              "is\", in the next section), with the paper's whole-state null, and as PPO, whose "
              "null is never trained (results/beyond/command, `run_all.sh`). Each agent at its last mark is given "
              "commands inside and outside the training range at each eval γ "
              "(`beyond/command_tracking.py`: per episode the mean forward velocity over its 1000 steps; the "
              "tracking error is |achieved − commanded|, the absolute value of tracking.csv's `velocity_error`, not its "
              "`tracking_error`, the reward's mean per-step |v_t − v_cmd|). A velocity command rather than a preference vector over "
              "objectives: a command has a target that an episode misses by a measured amount (how closely it "
              "follows, the analogue of a sample's fidelity to its prompt), a scalar command can be asked outside "
              "its trained range, and it is the meta-RL literature's velocity task, with three differences: there the "
              "velocity is hidden and inferred from reward, the control cost is 0.05·Σa² and some code uses 200-step "
              "episodes; here the command is observed, episodes last 1000 steps and the control cost is gymnasium's "
              "0.1·Σa². A preference has no target of its own, only a point of a Pareto front to be estimated first "
              "(results/beyond/README.md).")]  # fmt: skip
    tracking_csv = base / "tracking.csv"
    if not tracking_csv.exists():
        return [*lines, "", (f"**Not run yet:** {COMMAND_FOLDER}/tracking.csv does not exist (results/beyond/command/run_all.sh "
                             "trains, sweeps and tracks the set): no numbers here."), ""]  # fmt: skip
    cells, inside, last = read_tracking(tracking_csv)
    if not cells:
        return [*lines, "", f"**Not run yet:** {COMMAND_FOLDER}/tracking.csv holds no episode: no numbers here.", ""]
    env = COMMAND_ENV
    gammas = sorted({g for (v, s, g, c) in cells})
    commands = sorted({c for (v, s, g, c) in cells})
    in_range = [c for c in commands if inside[c]]
    low, high = (min(in_range), max(in_range)) if in_range else (math.nan, math.nan)
    above, below = (
        [c for c in commands if not inside[c] and c > high],
        [c for c in commands if not inside[c] and c < low],
    )
    variants = [v for v in COMMAND_VARIANTS if any(k[0] == v for k in cells)]
    gaps = tracking_gaps(cells)
    record(values_out, env, "", "command", "whole", float(not gaps))
    if gaps:
        lines += ["", (f"**Partial set:** {'; '.join(gaps)}. The tables below hold what there is, at {step_label(last)}; "
                       "they are not the set's result, and a verdict waits for the whole set.")]  # fmt: skip
    if 1.0 not in gammas or not in_range:
        return [*lines, "", "No γ = 1 cell or no command inside the training range: nothing to compare.", ""]
    seeds = len({s for (v, s, g, c) in cells})
    lines += ["", (f"At {step_label(last)}: {len(variants)} variants, seeds up to {seeds}, eval γ "
                   f"{', '.join(f'{g:g}' for g in gammas)}; commands inside the training range "
                   f"{', '.join(f'{c:g}' for c in in_range)}, above it {', '.join(f'{c:g}' for c in above) or 'none'}, "
                   f"below it {', '.join(f'{c:g}' for c in below) or 'none'} (m/s); each seed's value is the mean over "
                   "its episodes and the commands named, then mean ± 95% CI over seeds.")]  # fmt: skip
    lines += top_of_range_lines(cells, variants, high, env, values_out)

    # Question 1: tracking error and return against γ, each γ against γ = 1 on the same seeds and episodes.
    tests = []
    for variant in variants:
        reference_error = per_seed(cells, variant, 1.0, in_range, 0)
        reference_return = per_seed(cells, variant, 1.0, in_range, 2)
        for gamma in gammas:
            error, ret = per_seed(cells, variant, gamma, in_range, 0), per_seed(cells, variant, gamma, in_range, 2)
            tests.append({"variant": variant, "gamma": gamma, "error": error, "return": ret,
                          "error_test": None if gamma == 1.0 else paired_test(error, reference_error),
                          "return_test": None if gamma == 1.0 else paired_test(ret, reference_return)})  # fmt: skip
    for kind in ("error_test", "return_test"):
        tested = [t[kind] for t in tests if t[kind] is not None]
        for test, p_holm in zip(tested, holm([t["p"] for t in tested])):
            test["p_holm"] = p_holm
    family = sum(t["error_test"] is not None for t in tests)
    lines += ["", ("**Does γ > 1 make an agent follow its command more closely, and at what cost in return?** The "
                   "tracking error and the return over the commands inside the training range at each eval γ, and "
                   "each γ against γ = 1: the same seeds and episodes, paired by seed (t test; Holm over the "
                   f"{family} error tests and apart over the {family} return tests; the difference one test detects "
                   "with 80% power at α = 0.05, before Holm). A negative error difference follows the command more "
                   "closely."), "",
              ("| variant (null) | γ | tracking error (m/s) | vs γ = 1 | p (Holm) | detectable | return | vs γ = 1 | "
               "p (Holm) |"), "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for t in tests:
        name = command_name(t["variant"])
        error_cells, return_cells = ["–", "–", "–"], ["–", "–"]
        if t["error"]:
            record(
                values_out,
                env,
                t["variant"],
                "",
                f"tracking error at γ {t['gamma']:g}",
                np.mean(list(t["error"].values())),
            )
            record(
                values_out, env, t["variant"], "", f"return at γ {t['gamma']:g}", np.mean(list(t["return"].values()))
            )
        if (test := t["error_test"]) is not None:
            error_cells = [f"{test['difference']:+.3f}", f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})",
                           f"{test['detectable']:.3f}"]  # fmt: skip
            for quantity, value in (("tracking error change", test["difference"]), ("tracking error p", test["p"]),
                                    ("tracking error p Holm", test["p_holm"]),
                                    ("tracking error detectable", test["detectable"])):  # fmt: skip
                record(values_out, env, t["variant"], "γ 1", f"{quantity} at γ {t['gamma']:g}", value)
        if (test := t["return_test"]) is not None:
            return_cells = [f"{test['difference']:+.1f}", f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})"]
            for quantity, value in (("return change", test["difference"]), ("return p", test["p"]),
                                    ("return p Holm", test["p_holm"])):  # fmt: skip
                record(values_out, env, t["variant"], "γ 1", f"{quantity} at γ {t['gamma']:g}", value)
        lines.append(f"| {name} | {t['gamma']:g} | {seeds_cell(t['error'], 3)} | " + " | ".join(error_cells)
                     + f" | {seeds_cell(t['return'], 1)} | " + " | ".join(return_cells) + " |")  # fmt: skip

    # Question 2: the command null's change in error from γ = 1 against the other nulls' (distinct runs: Welch).
    knob = []
    reference = {v: per_seed(cells, v, 1.0, in_range, 0) for v in variants}
    for gamma in (g for g in gammas if g != 1.0):
        ours = change_of(per_seed(cells, COMMAND_NULL, gamma, in_range, 0), reference.get(COMMAND_NULL, {}))
        for baseline in (v for v in variants if v != COMMAND_NULL):
            theirs = change_of(per_seed(cells, baseline, gamma, in_range, 0), reference[baseline])
            if len(ours) >= 2 and len(theirs) >= 2:
                knob.append(
                    {"gamma": gamma, "baseline": baseline, **welch_of(list(ours.values()), list(theirs.values()))}
                )
    for row, p_holm in zip(knob, holm([r["p"] for r in knob])):
        row["p_holm"] = p_holm
    lines += ["", ("**Does the command null give a knob that the state null and PPO's untrained null lack?** Each "
                   "seed's change in tracking error (inside the training range) from γ = 1 to each γ, the command "
                   "null's against each other null's: Welch's t test (distinct runs), Holm over these "
                   f"{len(knob)} tests, the difference one test detects with 80% power at α = 0.05, before Holm; a "
                   "negative difference is a larger fall in error under the command null. Beside it, the gain: the "
                   "slope of achieved on commanded velocity over those commands (1 follows every change of command, "
                   "0 ignores it), mean ± 95% CI over seeds."), "",
              "| γ | baseline | command null's change | baseline's change | difference | p (Holm) | detectable |",
              "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in knob:
        for quantity, value in (("knob change", r["mean"]), ("baseline's knob change", r["baseline_mean"]),
                                ("knob difference", r["mean"] - r["baseline_mean"]), ("knob p", r["p"]),
                                ("knob p Holm", r["p_holm"]), ("knob detectable", r["detectable"])):  # fmt: skip
            record(values_out, env, COMMAND_NULL, r["baseline"], f"{quantity} at γ {r['gamma']:g}", value)
        lines.append(f"| {r['gamma']:g} | {command_name(r['baseline'])} | "
                     f"{r['mean']:+.3f} | {r['baseline_mean']:+.3f} | {r['mean'] - r['baseline_mean']:+.3f} | "
                     f"{fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | {r['detectable']:.3f} |")  # fmt: skip
    lines += ["", "| variant (null) | " + " | ".join(f"gain at γ = {g:g}" for g in gammas) + " |",
              "|---|" + "---|" * len(gammas)]  # fmt: skip
    gains = {v: {g: command_gain(cells, v, g, in_range) for g in gammas} for v in variants}
    for variant in variants:
        for gamma, gain in gains[variant].items():
            if gain:
                record(values_out, env, variant, "", f"gain at γ {gamma:g}", np.mean(list(gain.values())))
        lines.append(f"| {command_name(variant)} | "
                     + " | ".join(seeds_cell(g) for g in gains[variant].values()) + " |")  # fmt: skip

    # Question 3: outside the training range, each γ against γ = 1, paired by seed.
    outside = [(side, chosen) for side, chosen in (("above", above), ("below", below)) if chosen]
    far = []
    for variant in variants:
        for side, chosen in outside:
            reference_error = per_seed(cells, variant, 1.0, chosen, 0)
            for gamma in gammas:
                error = per_seed(cells, variant, gamma, chosen, 0)
                far.append({"variant": variant, "side": side, "gamma": gamma, "error": error,
                            "test": None if gamma == 1.0 else paired_test(error, reference_error)})  # fmt: skip
    tested = [r["test"] for r in far if r["test"] is not None]
    for test, p_holm in zip(tested, holm([t["p"] for t in tested])):
        test["p_holm"] = p_holm
    if outside:
        lines += ["", ("**Does guidance extend the range of commands an agent can follow outside the training range?** "
                       "The tracking error over the commands above and below the training range at each eval γ, and "
                       "its change from γ = 1, paired by seed (t test, Holm over these "
                       f"{len(tested)} tests), and the change one test detects with 80% power at α = 0.05, before "
                       "Holm: error (change, p Holm; detectable)."), "",
                  "| variant (null) | commands | " + " | ".join(f"γ = {g:g}" for g in gammas) + " |",
                  "|---|---|" + "---|" * len(gammas)]  # fmt: skip
        for variant in variants:
            for side, chosen in outside:
                row = [r for r in far if r["variant"] == variant and r["side"] == side]
                shown = []
                for r in row:
                    if not r["error"]:
                        shown.append("–")
                        continue
                    mean = float(np.mean(list(r["error"].values())))
                    record(values_out, env, variant, "", f"tracking error {side} the range at γ {r['gamma']:g}", mean)
                    if r["test"] is None:
                        shown.append(f"{mean:.3f}")
                        continue
                    for quantity, value in (("change", r["test"]["difference"]), ("p", r["test"]["p"]),
                                            ("p Holm", r["test"]["p_holm"]), ("detectable", r["test"]["detectable"])):  # fmt: skip
                        record(values_out, env, variant, "γ 1", f"tracking error {side} the range {quantity} at "
                               f"γ {r['gamma']:g}", value)  # fmt: skip
                    shown.append(f"{mean:.3f} ({r['test']['difference']:+.3f}, {fmt_p(r['test']['p_holm'])}; "
                                 f"{r['test']['detectable']:.3f})")  # fmt: skip
                lines.append(f"| {command_name(variant)} | {side} "
                             f"({', '.join(f'{c:g}' for c in chosen)}) | " + " | ".join(shown) + " |")  # fmt: skip
    lines += command_verdict(tests, knob, tested, gains, gaps)
    lines += ["", ("Commanded against achieved velocity, one line per eval γ, a panel per variant (mean over seeds, "
                   "95% CI band; the dashed diagonal follows the command exactly, the grey band is the training "
                   "range):"), "",
              f"![Commanded against achieved velocity, one line per eval γ]({COMMAND_FOLDER}/command_tracking.png)"]  # fmt: skip
    lines += command_sweep_lines(base, env)
    return [*lines, ""]


def top_of_range_lines(cells: dict, variants: list[str], top: float, env: str, values_out: list[dict]) -> list[str]:
    """How fast the agents run at γ = 1 when commanded the top of the training range: whether they cover it, which
    the tests outside the range presume."""
    speeds = {v: per_seed(cells, v, 1.0, [top], 1) for v in variants}
    every = [speed for v in variants for speed in speeds[v].values()]
    if not every:
        return []
    means = {v: float(np.mean(list(seeds.values()))) for v, seeds in speeds.items() if seeds}
    for variant, baseline, value in (("", "command", np.mean(every)), *((v, "", m) for v, m in means.items())):
        record(values_out, env, variant, baseline, f"velocity at command {top:g} at γ 1", value)
    return ["", (f"At γ = 1 the agents commanded the top of the range ({top:g} m/s) run at {np.mean(every):.2f} m/s on "
                 f"average ({min(every):.2f} to {max(every):.2f} over the {len(every)} agents; "
                 + "; ".join(f"{command_name(v)} {m:.2f}" for v, m in means.items())
                 + "): they do not cover the training range, so the tests above it are made on agents that do not "
                 "reach its top.")]  # fmt: skip


def command_verdict(
    tests: list[dict], knob: list[dict], outside: list[dict], gains: dict, gaps: list[str]
) -> list[str]:
    """What the command section's tests say, from their results alone: the falls in tracking error that γ > 1
    gives, its cost in return at the largest γ, where the command null's change differs from the other
    nulls' (below and above γ = 1), and the tests outside the training range; none for a partial set."""
    if gaps:
        return []
    above_one = [t for t in tests if t["gamma"] > 1 and t["error_test"] is not None]
    found = lambda sign: [
        t for t in above_one if sign * t["error_test"]["difference"] > 0 and t["error_test"]["p_holm"] < ALPHA
    ]
    falls, rises = found(-1), found(+1)
    best = min(above_one, key=lambda t: t["error_test"]["difference"], default=None)
    top = max((t["gamma"] for t in above_one), default=None)
    costs = [t for t in tests if t["gamma"] == top and t["return_test"] is not None]
    parts = [(f"**What these tests say, and no more.** Following more closely: {len(falls)} of the {len(above_one)} "
              "tests of a γ above 1 against γ = 1 find a significant fall in tracking error after Holm")]  # fmt: skip
    if best is not None and best["error_test"]["difference"] < 0:
        test = best["error_test"]
        parts.append(f"; the largest fall is {-test['difference']:.3f} m/s ({command_name(best['variant'])} at γ {best['gamma']:g}, "
                     f"p {fmt_p(test['p'])}, Holm {fmt_p(test['p_holm'])}; one test detects {test['detectable']:.3f} before Holm)")  # fmt: skip
    parts.append(f"; {len(rises)} find a significant rise" + "".join(
        f" ({command_name(t['variant'])} at γ {t['gamma']:g}, {t['error_test']['difference']:+.3f} m/s, Holm p "
        f"{fmt_p(t['error_test']['p_holm'])})" for t in rises))  # fmt: skip
    if costs:
        parts.append(f". The cost at γ {top:g}: " + "; ".join(
            f"{command_name(t['variant'])} {t['return_test']['difference']:+.1f} return (Holm p {fmt_p(t['return_test']['p_holm'])})"
            for t in costs))  # fmt: skip
    for side, rows in (("below", [r for r in knob if r["gamma"] < 1]), ("above", [r for r in knob if r["gamma"] > 1])):
        differing = [r for r in rows if r["p_holm"] < ALPHA]
        parts.append(f". The command null's change against the other nulls' {side} γ = 1: {len(differing)} of {len(rows)} "
                     "differences significant after Holm" + "".join(
                         f"; at γ {r['gamma']:g} against {command_name(r['baseline'])} {r['mean']:+.3f} m/s against "
                         f"{r['baseline_mean']:+.3f} (Holm p {fmt_p(r['p_holm'])})" for r in differing))  # fmt: skip
    lowest = min((g for v in gains for g in gains[v]), default=None)
    if lowest is not None and lowest < 1:
        parts.append(f". The gain (slope of achieved on commanded velocity) from γ = 1 to γ {lowest:g}: " + "; ".join(
            f"{command_name(v)} {np.mean(list(gains[v][1.0].values())):.2f} to {np.mean(list(gains[v][lowest].values())):.2f}"
            for v in gains if gains[v].get(1.0) and gains[v].get(lowest)))  # fmt: skip
    significant = [r for r in outside if r["p_holm"] < ALPHA]
    parts.append(f". Outside the training range, {len(significant)} of the {len(outside)} tests of a γ against γ = 1 "
                 "find a significant change in tracking error after Holm")  # fmt: skip
    if outside:
        detectable = [t["detectable"] for t in outside]
        parts.append(f"; one test there detects {min(detectable):.3f} to {max(detectable):.3f} m/s before "
                     "Holm, so changes of the sizes seen (up to "
                     f"{max(t['difference'] for t in outside):+.3f} m/s) can go unfound")  # fmt: skip
    parts.append(f". What they cannot say: a change smaller than one test detects with {COMMAND_SEEDS} seeds (the "
                 "detectable columns and figures, before Holm: after it, more is needed), anything of another task, or "
                 "of a command of more than one dimension.")  # fmt: skip
    return ["", "".join(parts)]


def command_sweep_lines(base: Path, env: str) -> list[str]:
    """The set's sweep on the training distribution of commands (episodes.csv) and its held-out γ, where they exist."""
    if not (base / "episodes.csv").exists():
        return ["", f"The set's return sweep ({COMMAND_FOLDER}/episodes.csv) is not there yet."]
    means = seed_means(read_rows(base / "episodes.csv"))
    variants = [v for v in COMMAND_VARIANTS if any(k[0] == env and k[1] == v for k in means)]
    if not variants:
        return ["", f"{COMMAND_FOLDER}/episodes.csv holds no episode of the command task's variants."]
    last = last_step(means, env)
    gammas = sorted({g for (e, v, s, g) in means if e == env and s == last})
    lines = ["", (f"Return at {step_label(last)} on commands drawn from the training range (the sweep, episode seeds "
                  "10000+), mean ± 95% CI over seeds, with each variant's seeds counted; and the held-out γ: chosen "
                  "on that sweep, scored on fresh episodes (seeds 20000+) against γ = 1 there."), "",
             "| variant (null) | seeds | " + " | ".join(f"γ = {g:g}" for g in gammas) + " | held-out γ: fresh gain |",
             "|---|---|" + "---|" * (len(gammas) + 1)]  # fmt: skip
    heldout = {}
    if (base / "heldout_gamma.csv").exists():
        with open(base / "heldout_gamma.csv", newline="") as f:
            heldout = {(r["variant"], int(r["step"])): r for r in csv.DictReader(f) if r["env_id"] == env}
    for variant in variants:
        cells = cells_of(means, env, variant)
        shown = [seeds_cell(cells[(last, g)], 1) if (last, g) in cells else "–" for g in gammas]
        seeds = max((len(cells[(last, g)]) for g in gammas if (last, g) in cells), default=0)
        held = heldout.get((variant, last))
        chosen = "–"
        if held and held["status"] == "tested":
            chosen = (f"{float(held['selected_gamma']):g}: {float(held['fresh_gain']):+.1f} ± "
                      f"{float(held['fresh_gain_ci95']):.1f} (p {fmt_p(float(held['p']))}, Holm "
                      f"{fmt_p(float(held['p_holm']))})")  # fmt: skip
        elif held:
            chosen = f"{float(held['selected_gamma']):g}: {held['status']}"
        lines.append(f"| {command_name(variant)} | {seeds} | " + " | ".join(shown)
                     + f" | {chosen} |")  # fmt: skip
    return lines


def command_figure(folder: Path, path: Path) -> bool:
    """Commanded against achieved velocity, one line per eval γ, a panel per variant; False where no tracking."""
    tracking_csv = folder / COMMAND_FOLDER / "tracking.csv"
    if not tracking_csv.exists():
        return False
    cells, inside, last = read_tracking(tracking_csv)
    if not cells:
        return False
    variants = [v for v in COMMAND_VARIANTS if any(k[0] == v for k in cells)]
    gammas, commands = sorted({g for (v, s, g, c) in cells}), sorted({c for (v, s, g, c) in cells})
    in_range = [c for c in commands if inside[c]]
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(gammas)))
    fig, axes = panels(len(variants), 3.6)
    for ax, variant in zip(axes, variants):
        if in_range:
            ax.axvspan(min(in_range), max(in_range), color="0.9", zorder=0)
        ax.plot(commands, commands, color="0.4", linestyle="--", lw=1)
        for gamma, colour in zip(gammas, colours):
            shown = [c for c in commands if per_seed(cells, variant, gamma, [c], 1)]
            stats = [mean_ci95(list(per_seed(cells, variant, gamma, [c], 1).values())) for c in shown]
            mean, half = np.array([s[0] for s in stats]), np.array([s[1] for s in stats])
            ax.plot(shown, mean, marker="o", ms=3, color=colour, label=f"γ = {gamma:g}")
            ax.fill_between(shown, mean - half, mean + half, color=colour, alpha=0.12)
        ax.set(title=f"{paper_name(variant)}\n({COMMAND_VARIANTS[variant]}), {step_label(last)}",
               xlabel="commanded velocity (m/s)", ylabel="achieved mean velocity (m/s)")  # fmt: skip
        ax.title.set_fontsize(9)
    save(fig, axes, path)
    return True


def report(args: Args) -> list[Path]:
    folder = Path(args.folder)
    task_files = sorted([*(path for path in folder.glob("*/episodes.csv") if path.parent.name not in SETS_APART),
                         *folder.glob(f"{BC_TRAIN_FOLDER}/*/episodes.csv")])  # fmt: skip
    if not task_files:
        raise InputError(f"no <task>/episodes.csv under {folder}")
    beyond = [r for path in task_files for r in read_rows(path)]
    envs = sorted({r["env_id"] for r in beyond})
    own = {(r["env_id"], r["variant"]) for r in beyond}
    table_path = Path(args.table)
    table = [r for r in read_rows(table_path) if r["env_id"] in envs and r["variant"] in BASELINES
             and (r["env_id"], r["variant"]) not in own] if table_path.exists() else []  # fmt: skip
    configs = defaultdict(set)
    for r in beyond + table:
        configs[(r["env_id"], r["variant"])].add(r["config"])
    if mixed := [f"{e} {v}: {', '.join(sorted(c))}" for (e, v), c in configs.items() if len(c) > 1]:
        raise InputError(f"several configurations of one task and variant would pool as one: {'; '.join(mixed)}")
    means = seed_means(beyond + table)
    variants_of = {env: sorted({v for (e, v, s, g) in means if e == env}, key=lambda v: (variant_rank(v), v))
                   for env in envs}  # fmt: skip
    rows, pooled = [], {}
    for env in envs:
        for variant in (v for v in variants_of[env] if v in BEYOND_VARIANT_IDS):
            for baseline in (b for b in BASELINES if b in variants_of[env]):
                found, pooled[(env, variant, baseline)] = comparisons(means, env, variant, baseline)
                rows.extend(found)
    cloning = [r for r in rows if r["variant"] in CLONING_VARIANTS]  # Question 3's family, apart from the others'
    others = [r for r in rows if r["variant"] not in CLONING_VARIANTS]
    for family in (others, cloning):
        for r, p in zip(family, holm([r["p"] for r in family])):
            r["p_holm"] = p
    if args.runs is not None:
        write_trajectories(Path(args.runs), folder / "guidance_trajectory.csv")
    values = []  # every number of the glance tables, the γ-response and γ_train tables and the pooled counts
    heldout, distance, trajectories = (
        read_heldout(folder, Path(args.table_heldout)),
        read_goal_distance(folder),
        read_trajectories(folder),
    )
    lines = ["# Beyond the paper: the report", "",
             (f"Generated by `python -m beyond.report {args.folder} --table {args.table}` from the committed "
             "episode CSVs. Baselines of the paper's tasks come from the continuous table's runs (the same code "
             "class: the same algorithm trained with --compile, MuJoCo 2.3.7, on another CPU); Reacher-v4's are "
             "trained here."), "", *glance_section(means, variants_of, distance, [r["p"] for r in others], values)]  # fmt: skip
    for env in envs:
        lines += task_section(env, means, variants_of[env], rows, pooled, heldout, distance, trajectories, values)
    bc_means, bc_fresh, bc_sets, bc_heldout = read_bc(folder, args)
    lines += bc_section(bc_means, bc_fresh, bc_sets, bc_heldout, values)
    cloning_tests = fall_tests(means, variants_of, variants=CLONING_VARIANTS)
    lines += cloning_section(cloning_tests, cloning_fresh_tests(means, variants_of, folder), values)
    lines += question_3_reading(values)
    lines += command_section(folder, values)
    # Imported here: the section's module builds on this one's readers and tests.
    from beyond import condition_dropout

    dropout = condition_dropout.read(folder)
    lines += condition_dropout.section(dropout, values)
    written = [folder / "report.md", folder / "report.csv", folder / "report_values.csv", folder / "gamma_response.png"]
    if command_figure(folder, folder / COMMAND_FOLDER / "command_tracking.png"):
        written.append(folder / COMMAND_FOLDER / "command_tracking.png")
    if condition_dropout.figure(dropout, folder / condition_dropout.FIGURE):
        written.append(folder / condition_dropout.FIGURE)
    if trajectories:
        written.append(folder / "guidance_trajectory.png")
        trajectory_figure(trajectories, written[-1])
    if distance:
        written.append(folder / "goal_distance.png")
        distance_figure(distance, variants_of, written[-1])
    if bc_sets:
        written.append(folder / "bc_null_gamma_response.png")
        bc_figure(bc_means, bc_sets, written[-1])
    write_atomic(written[0], "\n".join(lines))
    write_csv_atomic(written[1], REPORT_COLUMNS, rows)
    write_csv_atomic(written[2], VALUE_COLUMNS, values)
    gamma_response_figure(means, envs, variants_of, written[3])
    return written


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with one_line_errors():
        for path in report(args):
            print(path)


if __name__ == "__main__":
    main()
