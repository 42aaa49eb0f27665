"""Pooling over seeds, once: the rule behind every statistic over seeds (within one configuration a seed
is one run, and each episode of a cell is counted once), the per-seed mean return every such statistic
starts from (seed_means), the statistic itself, the mean over seeds and its 95% confidence interval (mean_ci95), and
the two together per group of rows (summarise), which the sweep's summary.csv and the paper study's tables both
start from."""

import math
from collections import Counter, defaultdict

import numpy as np
from scipy import stats

from pgg_utils.files import InputError


def cell_of(row: dict) -> tuple:
    """(step, γ, evaluation mode) of a sweep's row: which cell of its run it belongs to."""
    return (row["step"], row["eval_guidance"], row["policy"], row["null_branch"])


def check_one_run_per_seed(rows, configuration, cell, source=lambda row: None) -> None:
    """InputError (one line) where two runs would count as the same seed of one configuration
    (`configuration(row)`: env, variant, config, ...), or one episode of a cell (`cell(row)`: step, γ,
    evaluation mode) appears twice. An episode is its reset seed where the row records one (`episode_seed`):
    two sweeps of one checkpoint with other --eval-seed values hold other episodes, pooled as one sweep's
    would be, while an episode index alone repeats in every sweep. `source(row)` names where a row was read
    from, for the message."""
    run_of, seen = {}, {}
    for row in rows:
        key, seed, run, where = configuration(row), str(row["seed"]), str(row.get("run", "")), source(row)
        first_run, first_where = run_of.setdefault((key, seed), (run, where))
        if first_run != run:
            runs = f"{first_run}{f' ({first_where})' if first_where else ''} and {run}{f' ({where})' if where else ''}"
            raise InputError(f"runs {runs} would both count as seed {seed} of {' '.join(map(str, key[:3]))}: a seed "
                             "must be one run (give them different configurations, or sweep and plot them apart)")  # fmt: skip
        if "episode" not in row:
            continue
        reset_seed = str(row.get("episode_seed") or "")
        episode = (key, seed, run, *cell(row), reset_seed or str(row["episode"]))
        if episode in seen:
            first = seen[episode]
            twice = (
                "twice" if first is None else f"in {first} twice" if first == where else f"in both {first} and {where}"
            )
            which = f"episode {row['episode']}" + (f" (reset seed {reset_seed})" if reset_seed else "")
            raise InputError(f"{which} of run {run} ({' '.join(map(str, cell(row)))}) appears {twice}: one episode "
                             "counted twice; pass each sweep once")  # fmt: skip
        seen[episode] = where


def mean_ci95(values, method: str = "t", bootstrap_samples: int = 10_000) -> tuple[float, float, float, float]:
    """(mean, half-width, low, high) of the 95% confidence interval of the mean of `values` (here:
    one mean return per training seed). "t": mean ± t_{0.975, n-1} · s / sqrt(n), s the sample standard
    deviation (ddof=1). "bootstrap": percentile interval of `bootstrap_samples` resampled means (fixed
    RNG seed), half-width = (high - low) / 2. With one value the interval is undefined (nan)."""
    values = np.asarray(values, dtype=np.float64)
    n, mean = len(values), float(np.mean(values))
    if n < 2:
        return mean, math.nan, math.nan, math.nan
    if method == "t":
        half = float(stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / math.sqrt(n))
        return mean, half, mean - half, mean + half
    resampled = np.random.default_rng(0).choice(values, size=(bootstrap_samples, n)).mean(1)
    low, high = np.percentile(resampled, [2.5, 97.5])
    return mean, float((high - low) / 2), float(low), float(high)


def seed_means(rows, key, value: str = "return") -> dict:
    """{key(row): {seed: mean return over that seed's episodes}}, seeds in numeric order: the per-seed
    mean that every statistic over seeds starts from (the sweep's summary, the tables, the paper study).
    The returns of a seed are summed in row order. `value`: the per-episode column averaged, the return unless
    a reader averages another (a goal distance's `final_distance`)."""
    returns = defaultdict(lambda: defaultdict(list))
    for row in rows:
        returns[key(row)][int(row["seed"])].append(float(row[value]))
    return {k: {seed: float(np.mean(v)) for seed, v in sorted(by_seed.items())} for k, by_seed in returns.items()}


def summarise(rows, key, order=None, method: str = "t", bootstrap_samples: int = 10_000) -> list[dict]:
    """Statistics over seeds of the per-seed mean return, one entry per group `key(row)`, sorted by `order(group)`:
    {"key": the group, "seeds": its seeds in numeric order, "seed_means": their mean returns (seed_means),
    "n_episodes": its rows, "mean", "ci95", "ci_low", "ci_high": mean_ci95 of the seed means (`method`)}, unrounded.
    The one summary over seeds: the sweep's summary.csv (pgg_utils.sweep.summary_rows) and the paper study's
    tables (paper_study.summary.summarise) add their columns to it."""
    per_seed, episodes = seed_means(rows, key), Counter(map(key, rows))
    out = []
    for group in sorted(per_seed, key=order):
        means = list(per_seed[group].values())
        mean, half, low, high = mean_ci95(means, method, bootstrap_samples)
        out.append({"key": group, "seeds": list(per_seed[group]), "seed_means": means, "n_episodes": episodes[group],
                    "mean": mean, "ci95": half, "ci_low": low, "ci_high": high})  # fmt: skip
    return out
