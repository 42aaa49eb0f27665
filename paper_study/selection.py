"""The best eval γ, chosen on one set of episodes and reported on another. The maximum over γ of noisy
means is biased upward even when guidance does nothing, so the return the `best_gamma` table reports at
its chosen γ overstates what that γ gives. Here γ is chosen per group (env, configuration, checkpoint
step) on a selection sweep, and its return is reported on a fresh sweep of the same checkpoints with
other episode seeds, beside γ = 1 on those same fresh episodes.

Every statistic starts from the per-seed mean return over a cell's episodes, as in plot_results. The
selected γ maximises the mean over seeds of those on the selection episodes (ties go to the γ nearest
1, the least guidance). Its fresh gain is the mean over seeds of (fresh mean at the selected γ − fresh
mean at γ = 1), tested by a paired t test across seeds, Holm-corrected over the tested groups; its
selection bias is its mean on the selection episodes minus its mean on the fresh ones. Numpy and scipy;
no torch, no files."""

import math
from collections import defaultdict

import numpy as np
from scipy import stats

from paper_study.stats import correct_family
from pgg_utils import episodes
from pgg_utils.episodes import mean_ci95
from pgg_utils.files import InputError
from pgg_utils.identity import configuration

BASELINE_GAMMA = 1.0  # no guidance: what a selected γ has to beat
GROUP_FIELDS = ("env_id", "variant", "config", "train_guidance", "cond_dropout", "step")
GROUP_COLUMNS = [
    *GROUP_FIELDS, "status", "missing", "n_seeds", "candidates", "selected_gamma",
    "selection_mean", "selection_baseline", "selection_gain", "fresh_mean", "fresh_baseline",
    "fresh_gain", "fresh_gain_ci95", "t", "p", "p_holm", "significant", "selection_bias",
]  # fmt: skip
# A group's status: a selected γ other than 1 tested on fresh episodes; γ = 1 selected (fresh gain 0 by
# construction, no test); or the fresh sweep lacks what the comparison needs (`missing` says what).
TESTED, SELECTED_BASELINE, INCOMPLETE = "tested", "selected γ = 1", "incomplete"


def group_key(row: dict) -> tuple:
    """(env, variant, config, training guidance, dropout, step): the checkpoints of one configuration at
    one step, across seeds (identity.configuration, and the step)."""
    return (*configuration(row), int(row["step"]))


def by_gamma(rows: list[dict]) -> dict:
    """pgg_utils.episodes.seed_means by group and γ: {group: {γ: {seed: mean return over that cell's episodes}}} of
    one sweep's rows, which hold one run
    per configuration and seed (pgg_utils.episodes.read_episodes refuses pooled runs)."""
    cells = episodes.seed_means(rows, lambda row: (group_key(row), float(row["eval_guidance"])))
    out = defaultdict(dict)
    for (key, gamma), by_seed in cells.items():
        out[key][gamma] = by_seed
    return dict(out)


def check_same_checkpoints(selection: list[dict], fresh: list[dict]) -> None:
    """The fresh episodes must be of the selection's checkpoints (a group's seed is one run in both) and
    none of them an episode of the selection: episode seeds disjoint per run and step. An episode's seed
    fixes its reset and its action noise, so a shared seed is the same episode counted twice."""
    runs, episode_seeds = defaultdict(set), defaultdict(set)  # (sweep, group, seed) -> run names, episode seeds
    for sweep, rows in (("selection", selection), ("fresh", fresh)):
        for row in rows:
            if not row.get("episode_seed"):
                raise InputError(f"the {sweep} sweep records no episode_seed; sweep it again with eval_gamma_sweep.py")
            where = (sweep, group_key(row), int(row["seed"]))
            runs[where].add(row.get("run", ""))
            episode_seeds[where].add(int(row["episode_seed"]))
    for sweep, key, seed in list(runs):
        if sweep == "fresh" or ("fresh", key, seed) not in runs:
            continue
        chosen_on, reported_on = (", ".join(sorted(runs[(side, key, seed)])) for side in ("selection", "fresh"))
        if chosen_on != reported_on:
            raise InputError(f"seed {seed} of {key[2]} on {key[0]} at step {key[5]} is run {chosen_on} in the "
                             f"selection sweep and {reported_on} in the fresh one; sweep the same "
                             "checkpoints")  # fmt: skip
        shared = sorted(episode_seeds[("selection", key, seed)] & episode_seeds[("fresh", key, seed)])
        if shared:
            raise InputError(f"{len(shared)} episode seeds ({shared[0]}–{shared[-1]}) of run {chosen_on} at step "
                             f"{key[5]} are in both sweeps; sweep the fresh episodes with another --eval-seed "
                             "(e.g. 20000)")  # fmt: skip


def mean_over_seeds(by_seed: dict, seeds: list[int]) -> float:
    """The mean of the per-seed means, summed in seed order: equal cells tie exactly, whatever the row order."""
    return float(np.mean([by_seed[s] for s in seeds]))


def select_gamma(cells: dict, seeds: list[int]) -> float:
    """The γ with the highest mean over seeds; ties go to the γ nearest 1, then to the smaller."""
    return max(sorted(cells), key=lambda gamma: (mean_over_seeds(cells[gamma], seeds), -abs(gamma - BASELINE_GAMMA)))


def paired_t(differences: np.ndarray) -> tuple[float, float]:
    """(t, two-sided p) of the paired t test that the mean difference is 0, on n − 1 degrees of freedom.
    With no spread the difference is certain: p = 1 if it is 0, else 0 (as paper_study.stats.welch)."""
    n = len(differences)
    if n < 2:
        return math.nan, math.nan
    mean, sd = float(np.mean(differences)), float(np.std(differences, ddof=1))
    if sd == 0:
        return (0.0 if mean == 0 else math.copysign(math.inf, mean)), (1.0 if mean == 0 else 0.0)
    t_value = mean / (sd / math.sqrt(n))
    return t_value, float(2 * stats.t.sf(abs(t_value), n - 1))


def what_is_missing(fresh_cells: dict | None, seeds: list[int], gammas: tuple[float, ...]) -> str:
    """'' where the fresh sweep has every seed at each of `gammas`, else a phrase saying what it lacks."""
    if fresh_cells is None:
        return "the fresh sweep has no episodes of this group"
    lacking = []
    for gamma in gammas:
        absent = [s for s in seeds if s not in fresh_cells.get(gamma, {})]
        if absent:
            lacking.append(f"γ {gamma:g} for seed{'s' * (len(absent) > 1)} {', '.join(map(str, absent))}")
    return f"the fresh sweep lacks {'; '.join(lacking)}" if lacking else ""


def held_out_row(key: tuple, cells: dict, fresh_cells: dict | None) -> dict:
    """One group: the γ selected on `cells` ({γ: {seed: mean}}, the selection sweep), reported on
    `fresh_cells` (the same of the fresh sweep, None where it lacks the group)."""
    seeds = sorted(set().union(*cells.values()))
    for gamma, by_seed in sorted(cells.items()):
        if sorted(by_seed) != seeds:
            absent = ", ".join(str(s) for s in seeds if s not in by_seed)
            raise InputError(f"the selection sweep lacks seeds {absent} at γ {gamma:g} of {key[2]} on {key[0]} at "
                             f"step {key[5]}; a selection compares every γ on the same seeds")  # fmt: skip
    row = dict(zip(GROUP_FIELDS, key)) | {column: math.nan for column in GROUP_COLUMNS[len(GROUP_FIELDS) :]}
    row |= {"n_seeds": len(seeds), "candidates": ";".join(f"{g:g}" for g in sorted(cells)), "missing": ""}
    if BASELINE_GAMMA not in cells:
        return row | {"status": INCOMPLETE, "missing": f"the selection sweep has no γ {BASELINE_GAMMA:g}"}
    selected = select_gamma(cells, seeds)
    row["selected_gamma"] = selected
    row["selection_mean"] = mean_over_seeds(cells[selected], seeds)
    row["selection_baseline"] = mean_over_seeds(cells[BASELINE_GAMMA], seeds)
    row["selection_gain"] = row["selection_mean"] - row["selection_baseline"]
    missing = what_is_missing(fresh_cells, seeds, tuple(sorted({BASELINE_GAMMA, selected})))
    if missing:
        return row | {"status": INCOMPLETE, "missing": missing}
    chosen = np.array([fresh_cells[selected][s] for s in seeds])
    baseline = np.array([fresh_cells[BASELINE_GAMMA][s] for s in seeds])
    gain, gain_ci95, _, _ = mean_ci95(chosen - baseline)
    row |= {"fresh_mean": float(chosen.mean()), "fresh_baseline": float(baseline.mean()), "fresh_gain": gain,
            "fresh_gain_ci95": gain_ci95, "selection_bias": row["selection_mean"] - float(chosen.mean())}  # fmt: skip
    if selected == BASELINE_GAMMA:
        return row | {"status": SELECTED_BASELINE, "fresh_gain_ci95": math.nan}
    row["t"], row["p"] = paired_t(chosen - baseline)
    return row | {"status": TESTED}


def held_out(selection: list[dict], fresh: list[dict]) -> tuple[list[dict], list[tuple]]:
    """(one row per group of the selection sweep, the groups of the fresh sweep that the selection lacks).
    The rows of both hold one evaluation mode (policy, null branch) and one run per configuration and seed.
    Rows are in group order; a group that cannot be answered (no γ = 1 in the selection, a cell the fresh
    sweep lacks) is a row with status `incomplete` saying what is missing."""
    if not selection:
        raise InputError("the selection sweep has no episodes")
    if not fresh:
        raise InputError("the fresh sweep has no episodes")
    check_same_checkpoints(selection, fresh)
    selected, held = by_gamma(selection), by_gamma(fresh)
    if not selected.keys() & held.keys():
        raise InputError("the two sweeps have no group (env, configuration, step) in common; sweep the fresh episodes "
                         "from the selection's run directories")  # fmt: skip
    rows = [held_out_row(key, selected[key], held.get(key)) for key in sorted(selected)]
    correct_family(rows)
    return rows, sorted(held.keys() - selected.keys())


def summary_by_env(rows: list[dict]) -> list[dict]:
    """Per env and variant, over its groups (configurations and steps): how often the selected γ is 1,
    how often another γ still beats γ = 1 on fresh episodes (at all, and significantly after Holm), the median fresh
    and in-sample gains of those selections, and the median selection bias of every answered group."""
    by_env = defaultdict(list)
    for row in rows:
        by_env[(row["env_id"], row["variant"])].append(row)
    out = []
    for (env, variant), group in by_env.items():
        tested = [r for r in group if r["status"] == TESTED]
        answered = [r for r in group if r["status"] != INCOMPLETE]
        out.append({
            "env_id": env, "variant": variant, "groups": len(group),
            "incomplete": sum(r["status"] == INCOMPLETE for r in group),
            "selected_baseline": sum(r["status"] == SELECTED_BASELINE for r in group),
            "selected_other": len(tested), "fresh_above": sum(r["fresh_gain"] > 0 for r in tested),
            "fresh_above_significant": sum(r["significant"] == "True" and r["fresh_gain"] > 0 for r in tested),
            "median_fresh_gain": median([r["fresh_gain"] for r in tested]),
            "median_selection_gain": median([r["selection_gain"] for r in tested]),
            "median_selection_bias": median([r["selection_bias"] for r in answered]),
        })  # fmt: skip
    return out


def median(values: list[float]) -> float:
    return float(np.median(values)) if values else math.nan
