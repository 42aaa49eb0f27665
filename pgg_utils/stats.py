"""The statistics every report uses, once: the confidence interval over seeds, Welch's test from summary
statistics, effect sizes, Holm's correction and the sign test. Numpy and scipy; no torch."""

import math

import numpy as np
from scipy import stats


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
    for row, adjusted in zip(rows, holm([row["p"] for row in rows])):
        row["p_holm"] = adjusted
        row["significant"] = "n/a" if math.isnan(adjusted) else str(adjusted < ALPHA)


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
