"""The statistics every report uses, once: the confidence interval over seeds. Numpy and scipy; no torch."""

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
