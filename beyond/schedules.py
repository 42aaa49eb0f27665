"""Questions 1 and 2 per task: scheduled and adaptive γ_train, and every new variant, against the baselines: the
γ_train trajectories, the γ = 1 tests per mark and the pooled cells, the held-out γ, the runs that fell, the fall
from the best γ to the largest against the baselines'; and each task's section."""

import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from beyond.cells import cells_of, last_step, response_at_last_step, summary
from beyond.sets import (
    BASELINES,
    BC_TRAIN_FOLDER,
    BEYOND_VARIANT_IDS,
    CLONING_VARIANTS,
    COLLAPSE_FRACTION,
    SCHEDULE_VARIANTS,
    SETS_APART,
)
from paper_study.stats import ALPHA, detectable_gap, holm, median_relative_gap, set_holm, welch, welch_of
from pgg_utils.files import read_csv, write_csv_atomic

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
        for r in read_csv(path):
            out[(r["env_id"], r["variant"])][int(r["seed"])].append(
                (int(r["step"]), float(r["guidance"]), float(r["kl"]))
            )
    return out


def read_heldout(folder: Path, table_heldout: Path) -> dict:
    """{(env, variant, step): heldout row} from each task's heldout_gamma.csv and the table's."""
    out = {}
    tasks = [
        *(path for path in sorted(folder.glob("*/heldout_gamma.csv")) if path.parent.name not in SETS_APART),
        *sorted(folder.glob(f"{BC_TRAIN_FOLDER}/*/heldout_gamma.csv")),
    ]
    for path in [*([table_heldout] if table_heldout.exists() else []), *tasks]:
        out.update({(r["env_id"], r["variant"], int(r["step"])): r for r in read_csv(path)})
    return out


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


def checkpoint_iteration(run: list[tuple], mark: int) -> tuple | None:
    """The logged (step, γ_train, kl) of the iteration a run saved its checkpoint of `mark` at: the first whose
    step reaches the mark (training saves right after it), None where the run has not reached it."""
    return min((t for t in run if t[0] >= mark), default=None)


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


def gamma_one_tests(means: dict, variants_of: dict) -> tuple[list[dict], dict]:
    """report.csv's rows: each new variant against each baseline of its task at γ = 1 per step (Holm over the
    schedules' and goal nulls' tests, and apart over the cloning variant's, Question 3's family), and the pooled
    cells of each pair {(env, variant, baseline): comparisons' pooled}."""
    rows, pooled = [], {}
    for env, variants in variants_of.items():
        for variant in (v for v in variants if v in BEYOND_VARIANT_IDS):
            for baseline in (b for b in BASELINES if b in variants):
                found, pooled[(env, variant, baseline)] = comparisons(means, env, variant, baseline)
                rows.extend(found)
    for cloning in (False, True):
        set_holm([r for r in rows if (r["variant"] in CLONING_VARIANTS) == cloning])
    return rows, pooled
