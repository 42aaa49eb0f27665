"""The statistics the paper study's reports use, once: Welch's test from summary statistics, effect sizes,
Holm's correction and the sign test; the power of Welch's test and the gap it detects; a bootstrap over
seeds of a pooled relative gap. The confidence interval over seeds is the sweep's (pgg_utils.episodes).
Numpy and scipy; no torch."""

import functools
import itertools
import math

import numpy as np
from scipy import optimize, stats

ALPHA = 0.05  # the significance level of every test in the reports, family-wise after Holm


def sd_from_ci(ci95: float, n: int) -> float:
    """The sample standard deviation behind a Student-t 95% CI half-width over n values: how a
    published mean ± CI becomes the spread a test needs."""
    return ci95 * math.sqrt(n) / float(stats.t.ppf(0.975, n - 1))


def welch(mean1: float, sd1: float, n1: int, mean2: float, sd2: float, n2: int) -> tuple[float, float, float]:
    """(t, degrees of freedom, two-sided p) of Welch's t test from summary statistics, as a paper gives
    them. With no spread on either side the difference is certain: p = 1 if the means are equal, else 0."""
    if n1 < 2 or n2 < 2 or math.isnan(sd1) or math.isnan(sd2):
        return math.nan, math.nan, math.nan
    v1, v2 = sd1**2 / n1, sd2**2 / n2
    diff = mean1 - mean2
    if v1 + v2 == 0:
        return (0.0 if diff == 0 else math.copysign(math.inf, diff)), math.nan, (1.0 if diff == 0 else 0.0)
    t_value = diff / math.sqrt(v1 + v2)
    df = (v1 + v2) ** 2 / (v1**2 / (n1 - 1) + v2**2 / (n2 - 1))
    return t_value, df, float(2 * stats.t.sf(abs(t_value), df))


def hedges_g(mean1: float, sd1: float, n1: int, mean2: float, sd2: float, n2: int) -> float:
    """Standardised difference (mean1 − mean2) / pooled sd, with Hedges' small-sample correction: how
    large a difference is, whatever its p-value."""
    if n1 < 2 or n2 < 2 or math.isnan(sd1) or math.isnan(sd2):
        return math.nan
    pooled = math.sqrt(((n1 - 1) * sd1**2 + (n2 - 1) * sd2**2) / (n1 + n2 - 2))
    diff = mean1 - mean2
    if pooled == 0:
        return 0.0 if diff == 0 else math.copysign(math.inf, diff)
    return (1 - 3 / (4 * (n1 + n2) - 9)) * diff / pooled


def holm(p_values: list[float]) -> list[float]:
    """Holm's step-down adjusted p-values (family-wise error, valid under any dependence between the
    tests), NaNs left out of the family and kept."""
    indexed = sorted((p, i) for i, p in enumerate(p_values) if not math.isnan(p))
    m = len(indexed)
    adjusted = [math.nan] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(indexed):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[i] = running
    return adjusted


def correct_family(rows: list[dict]) -> None:
    """Sets each row's `p_holm` and `significant` ("True", "False", or "n/a" where untested) from Holm's
    correction over these rows' `p`: one family, one correction, in every report."""
    set_holm(rows)
    for row in rows:
        row["significant"] = "n/a" if math.isnan(row["p_holm"]) else str(row["p_holm"] < ALPHA)


def sign_test(differences) -> tuple[int, int, int, float]:
    """(above, below, ties, two-sided exact binomial p) of the signs of the differences: whether one side
    lies above the other as often as below."""
    above = sum(d > 0 for d in differences)
    below = sum(d < 0 for d in differences)
    ties = len(differences) - above - below
    p = float(stats.binomtest(above, above + below, 0.5).pvalue) if above + below else math.nan
    return above, below, ties, p


def null_rates(n: int, draws: int = 200_000, shifts=(0.0, 1.0, 2.0), seed: int = 0) -> list[dict]:
    """Simulated, for two samples of n normal values whose means differ by `shift` standard deviations:
    how often their t 95% CIs overlap, and how often Welch's test rejects at ALPHA. What each criterion
    of agreement can show at this n."""
    rng = np.random.default_rng(seed)
    t_crit = float(stats.t.ppf(0.975, n - 1))
    out = []
    for shift in shifts:
        a = rng.standard_normal((draws, n))
        b = rng.standard_normal((draws, n)) + shift
        ma, mb, sa, sb = a.mean(1), b.mean(1), a.std(1, ddof=1), b.std(1, ddof=1)
        overlap = np.abs(ma - mb) <= t_crit * (sa + sb) / math.sqrt(n)
        va, vb = sa**2 / n, sb**2 / n
        t_value = (ma - mb) / np.sqrt(va + vb)
        df = (va + vb) ** 2 / (va**2 / (n - 1) + vb**2 / (n - 1))
        p = 2 * stats.t.sf(np.abs(t_value), df)
        out.append({"shift_sd": shift, "overlap": float(overlap.mean()), "welch_reject": float((p < ALPHA).mean())})
    return out


# --- what a test can see, and a summary that has power --------------------------------------------

POWER = 0.8  # the power at which a report states the gap its test would detect
QUADRATURE_NODES = 64  # per sample variance; the power agrees with 200 nodes to 1e-6


@functools.cache
def _variance_quadrature(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes and weights over the probabilities of s² / σ² for n normal values
    (a χ²_{n-1} / (n - 1) law): the expectation of a function of one sample variance as a weighted sum."""
    x, w = np.polynomial.legendre.leggauss(QUADRATURE_NODES)
    return stats.chi2.ppf((x + 1) / 2, n - 1) / (n - 1), w / 2


def _welch_thresholds(sd1: float, n1: int, sd2: float, n2: int, alpha: float):
    """(c·√V per pair of sample variances, the pairs' weights, sd of the mean difference): given the two
    sample variances, Welch's test rejects when |mean difference| > c·√V, c = t_{1-α/2} at their df."""
    q1, w1 = _variance_quadrature(n1)
    q2, w2 = _variance_quadrature(n2)
    v1, v2 = (sd1**2 / n1 * q1)[:, None], (sd2**2 / n2 * q2)[None, :]
    v = v1 + v2
    df = v**2 / (v1**2 / (n1 - 1) + v2**2 / (n2 - 1))
    return stats.t.ppf(1 - alpha / 2, df) * np.sqrt(v), w1[:, None] * w2[None, :], math.sqrt(sd1**2 / n1 + sd2**2 / n2)


def _power_from(gap: float, bounds, weights, se: float) -> float:
    return float((weights * (stats.norm.cdf((gap - bounds) / se) + stats.norm.cdf((-gap - bounds) / se))).sum())


def welch_power(gap: float, sd1: float, n1: int, sd2: float, n2: int, alpha: float) -> float:
    """The chance that Welch's two-sided test at level `alpha` rejects when the true means differ by
    `gap`, for normal samples of n1 and n2 values with true sds sd1 and sd2. Exact, not the noncentral-t
    approximation: given the two sample variances the test's threshold is fixed and the mean difference
    is normal, so the power is a normal probability averaged over the two variances' laws (quadrature).
    The approximation with the df of the true sds overstates the power at n = 5 and small α (63%
    instead of 80% at α = 0.05/270 with equal sds), where the df of the sample sds is often far lower."""
    if n1 < 2 or n2 < 2 or math.isnan(sd1) or math.isnan(sd2) or sd1 == sd2 == 0:
        return math.nan
    return _power_from(abs(gap), *_welch_thresholds(sd1, n1, sd2, n2, alpha))


def detectable_gap(sd1: float, n1: int, sd2: float, n2: int, alpha: float, power: float = POWER) -> float:
    """The true difference of means that Welch's test at level `alpha` detects with probability `power`
    (welch_power), taking a cell's two sds as the true ones: what a non-significant cell can rule out.
    nan where neither side has a spread (the test is then degenerate) or either has one value."""
    if n1 < 2 or n2 < 2 or math.isnan(sd1) or math.isnan(sd2) or sd1 == sd2 == 0:
        return math.nan
    bounds, weights, se = _welch_thresholds(sd1, n1, sd2, n2, alpha)
    high = se
    while _power_from(high, bounds, weights, se) < power:
        high *= 2
    return float(optimize.brentq(lambda gap: _power_from(gap, bounds, weights, se) - power, 0.0, high, xtol=1e-9 * se))


EXACT_BOOTSTRAP_LIMIT = 200_000  # joint resamples enumerated at most; past it, Monte Carlo


def seed_resamples(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every distinct bootstrap resample of n seeds, as counts per seed (rows), and its probability
    (the multinomial n! / Π countᵢ! / nⁿ): with n = 5, 126 resamples stand for all 3,125 draws."""
    counts = np.array([np.bincount(c, minlength=n) for c in itertools.combinations_with_replacement(range(n), n)])
    log_p = math.lgamma(n + 1) - np.array([sum(math.lgamma(k + 1) for k in row) for row in counts]) - n * math.log(n)
    return counts, np.exp(log_p)


def median_relative_gap(blocks, resamples: int = 10_000, seed: int = 0, exact_limit: int = EXACT_BOOTSTRAP_LIMIT):
    """(median, 2.5th and 97.5th percentile) over cells of (ours − reference) / |reference|, the interval
    a percentile bootstrap over our seeds: one gap that pools a task's cells, so it has the power no
    single cell has. `blocks`: (seed means, references) per set of cells that share their runs, seed
    means as cells × seeds, columns the same seed in every cell (a run's checkpoints and eval γ share
    its seed); each resample draws one set of seeds per block, so that cells of one run move together.
    The references (the paper's means) are held fixed: the interval is our seeds' uncertainty only.
    With few seeds the bootstrap distribution is a few thousand weighted atoms, and a Monte Carlo
    percentile jumps between them from draw to draw (by a point or more at 5 seeds and 200,000
    resamples): up to `exact_limit` joint resamples it is enumerated and its percentiles are exact (the
    smallest atom whose cumulative weight reaches 2.5% or 97.5%); past that, `resamples` Monte Carlo
    draws (RNG `seed`)."""
    blocks = [(np.asarray(m, dtype=np.float64), np.asarray(r, dtype=np.float64)) for m, r in blocks]
    observed = np.concatenate([(m.mean(1) - r) / np.abs(r) for m, r in blocks])
    if math.prod(math.comb(2 * m.shape[1] - 1, m.shape[1]) for m, _ in blocks) <= exact_limit:
        gaps, weights = np.zeros((1, 0)), np.ones(1)
        for seed_means, references in blocks:
            counts, p = seed_resamples(seed_means.shape[1])
            block = (counts @ seed_means.T / seed_means.shape[1] - references) / np.abs(references)
            gaps = np.concatenate([np.repeat(gaps, len(p), axis=0), np.tile(block, (len(weights), 1))], axis=1)
            weights = np.outer(weights, p).ravel()
        medians = np.median(gaps, axis=1)
        order = np.argsort(medians, kind="stable")
        cumulative = np.cumsum(weights[order])
        low, high = (medians[order][min(np.searchsorted(cumulative, q * cumulative[-1] - 1e-12), len(order) - 1)]
                     for q in (0.025, 0.975))  # fmt: skip
        return float(np.median(observed)), float(low), float(high)
    rng = np.random.default_rng(seed)
    resampled = []
    for seed_means, references in blocks:
        scale = np.abs(references)[:, None]
        draws = rng.integers(0, seed_means.shape[1], size=(resamples, seed_means.shape[1]))
        resampled.append((seed_means[:, draws].mean(-1) - references[:, None]) / scale)
    low, high = np.percentile(np.median(np.concatenate(resampled), axis=0), [2.5, 97.5])
    return float(np.median(observed)), float(low), float(high)


def bootstrap_coverage(n: int, samples: int = 4000, resamples: int = 1000, seed: int = 0) -> float:
    """Simulated: how often the 95% percentile bootstrap interval of the mean of n normal values holds
    the true mean. With few seeds it is well under 95% (the resamples never show a wider spread than
    the sample's), which a report must say beside such an interval."""
    rng = np.random.default_rng(seed)
    values = rng.standard_normal((samples, n))
    means = values[:, rng.integers(0, n, size=(resamples, n))].mean(-1)
    low, high = np.percentile(means, [2.5, 97.5], axis=1)
    return float(((low <= 0) & (high >= 0)).mean())


def performance_profile(per_task: list[np.ndarray], taus: np.ndarray, resamples: int = 2000, seed: int = 0):
    """(profile, low, high), each of len(taus): rliable's performance profile (its score distribution,
    `create_performance_profile` with `use_score_distribution=True`), the fraction of all (task, run)
    scores above each threshold τ, with a stratified percentile bootstrap 95% interval: each task's runs
    are resampled with replacement, `resamples` times (RNG `seed`). `per_task`: one array of run scores
    per task, as the aggregate IQM pools them (a task with fewer runs weighs less, as in the IQM)."""
    taus = np.asarray(taus, dtype=np.float64)
    profile = (np.concatenate(per_task)[:, None] > taus).mean(axis=0)
    rng = np.random.default_rng(seed)
    drawn = np.concatenate([s[rng.integers(0, len(s), size=(resamples, len(s)))] for s in per_task], axis=1)
    profiles = (drawn[:, :, None] > taus).mean(axis=1)  # (resamples, taus)
    low, high = np.percentile(profiles, [2.5, 97.5], axis=0)
    return profile, low, high


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


def welch_of(ours: list[float], theirs: list[float]) -> dict:
    """Welch's test of two samples: their means, p and the difference one test detects with 80% power."""
    (m1, s1, n1), (m2, s2, n2) = ((float(np.mean(x)), float(np.std(x, ddof=1)), len(x)) for x in (ours, theirs))
    return {"mean": m1, "baseline_mean": m2, "p": welch(m1, s1, n1, m2, s2, n2)[2],
            "detectable": detectable_gap(s1, n1, s2, n2, ALPHA)}  # fmt: skip


def set_holm(tests: list[dict | None]) -> None:
    """Each test's `p_holm`, Holm over one family: the tests that were made (None where a side had too few seeds)."""
    made = [t for t in tests if t is not None]
    for test, p_holm in zip(made, holm([t["p"] for t in made])):
        test["p_holm"] = p_holm
