"""The aggregate of plot_results.py's tables: per task, scores normalised by fixed references (0 and 1 = PPO at its
first and last step: the paper's, or the sweep's own on a task the paper did not run), their interquartile mean
over tasks and seeds with a stratified-bootstrap CI, and rliable's performance profile of the same scores."""

import math
from collections import defaultdict

import numpy as np
from scipy import stats

from paper_study.agreement import paper_ppo_span, series_id
from paper_study.stats import performance_profile


def iqm(scores: np.ndarray) -> float:
    return float(stats.trim_mean(scores, 0.25))


def iqm_along(*samples, axis=-1):
    """The IQM of the concatenated samples along `axis`, batched (what scipy.stats.trim_mean(·, 0.25)
    computes, on many resamples at once)."""
    x = np.sort(np.concatenate(samples, axis=axis), axis=axis)
    n = x.shape[axis]
    cut = int(0.25 * n)
    return np.take(x, np.arange(cut, n - cut), axis=axis).mean(axis=axis)


PAPER_REFERENCE, OWN_REFERENCE = "the paper's PPO", "this sweep's PPO at γ = 1"


def normalisation_references(summary) -> tuple[dict, dict]:
    """({env: (first, last, whose)}, {env: why it has none}): the two fixed references of an env's normalised
    scores, 0 and 1, PPO's mean return (eval γ = 1) at its first and at its last step: the paper's
    (agreement.paper_ppo_span) where the paper has a row, else this sweep's own PPO (its one PPO configuration,
    swept at two steps or more, whose returns differ between them)."""
    span = paper_ppo_span()
    references, missing = {}, {}
    for env in sorted({r["env_id"] for r in summary}):
        if env in span:
            references[env] = (*span[env], PAPER_REFERENCE)
            continue
        ppo = sorted((r for r in summary if r["env_id"] == env and r["variant"] == "ppo"
                      and float(r["eval_guidance"]) == 1.0), key=lambda r: int(r["step"]))  # fmt: skip
        if not ppo:
            why = "the sweep holds no PPO at eval γ = 1"
        elif len(configurations := {r["series"] for r in ppo}) > 1:
            why = f"the sweep holds {len(configurations)} PPO configurations"
        elif int(ppo[0]["step"]) == int(ppo[-1]["step"]):
            why = "the sweep's PPO (eval γ = 1) was swept at one step"
        elif float(ppo[0]["mean"]) == float(ppo[-1]["mean"]):
            why = "the sweep's PPO (eval γ = 1) returns the same at its first and last step"
        else:
            references[env] = (float(ppo[0]["mean"]), float(ppo[-1]["mean"]), OWN_REFERENCE)
            continue
        missing[env] = f"the paper has no row for it and {why}"
    return references, missing


def reference_text(references: dict, envs) -> str:
    """What 0 and 1 of the normalised scores of `envs` are, in words: the paper's PPO or this sweep's, per task."""
    whose = defaultdict(list)
    for env in sorted(envs):
        whose[references[env][2]].append(env)
    if len(whose) == 1:
        return f"0 = {next(iter(whose))} at its first step, 1 = at its last"
    return ("0 = PPO at its first step, 1 = at its last: "
            + "; ".join(f"{reference} for {', '.join(tasks)}" for reference, tasks in sorted(whose.items())))  # fmt: skip


def normalised_scores(summary) -> dict:
    """{(variant, step, eval γ): [per env, its per-seed mean returns normalised]}: per env by fixed
    references, PPO at the first and the last step (0 and 1; normalisation_references: the paper's where
    it has a row, else this sweep's own), so that adding a γ or a variant moves no score; a task with
    neither is left out. The scores of the aggregate IQM and of the performance profile."""
    references = normalisation_references(summary)[0]
    groups = defaultdict(list)
    for r in summary:
        if r["env_id"] not in references:
            continue
        lo, hi, _ = references[r["env_id"]]
        seed_means = np.array([float(x) for x in r["seed_means"].split(";")])
        groups[(series_id(r["variant"], r["series"]), int(r["step"]), float(r["eval_guidance"]))].append(
            (seed_means - lo) / ((hi - lo) or 1.0)
        )
    return groups


def aggregate_iqm(summary) -> list[dict]:
    """Per (variant, step, eval γ): IQM over (env, seed) of the normalised scores (normalised_scores).
    95% CI by a stratified percentile bootstrap: seeds are resampled within each env
    (scipy.stats.bootstrap, one sample per env)."""
    out = []
    for (variant, step, gamma), per_env in sorted(normalised_scores(summary).items()):
        point = iqm(np.concatenate(per_env))
        low = high = math.nan
        if all(len(s) >= 2 for s in per_env):
            result = stats.bootstrap(tuple(per_env), iqm_along, vectorized=True, n_resamples=2000,
                                     method="percentile", random_state=0)  # fmt: skip
            low, high = result.confidence_interval
        out.append({"variant": variant, "step": step, "eval_guidance": gamma, "n_envs": len(per_env),
                    "iqm": round(point, 4), "ci_low": round(float(low), 4), "ci_high": round(float(high), 4)})  # fmt: skip
    return out


def performance_profiles(summary, points: int = 201) -> tuple[dict, int, int]:
    """({(variant, eval γ): (τ, profile, low, high)}, step, envs): rliable's performance profile
    (paper_study.stats.performance_profile) of each variant and eval γ at the last step, from the
    aggregate IQM's normalised scores, on one grid of τ from the lowest score to the highest, as rliable's own
    plots span the scores (the references, 0 and 1, need not lie inside)."""
    scores = normalised_scores(summary)
    step = max(s for _, s, _ in scores)
    at_step = {(variant, gamma): per_env for (variant, s, gamma), per_env in scores.items() if s == step}
    every = np.concatenate([np.concatenate(per_env) for per_env in at_step.values()])
    low, high = (every.min(), every.max()) if every.max() > every.min() else (every.min() - 0.5, every.max() + 0.5)
    taus = np.linspace(low, high, points)
    envs = max(len(per_env) for per_env in at_step.values())
    return {key: (taus, *performance_profile(per_env, taus)) for key, per_env in at_step.items()}, step, envs
