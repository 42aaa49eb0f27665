"""The numbers every question of the report starts from: a sweep's sampled episodes (pgg_utils.episodes), their
per-seed means (pgg_utils.episodes), a variant's cells and their summary over seeds, the γ-response at a task's
last step; and `record`, which puts one number into report_values.csv's rows."""

import math
from pathlib import Path

import numpy as np

from pgg_utils import episodes
from pgg_utils.episodes import mean_ci95, read_episodes


def read_rows(path: Path, null_branch: str = "learned") -> list[dict]:
    """A sweep's sampled episodes of one null branch, read by the one reader (pgg_utils.episodes)."""
    return [r for r in read_episodes([path]) if r["policy"] == "sample" and r["null_branch"] == null_branch]


def seed_means(rows: list[dict]) -> dict:
    """{(env, variant, step, γ): {seed: mean return}} (pgg_utils.episodes.seed_means)."""
    return episodes.seed_means(rows, lambda r: (r["env_id"], r["variant"], int(r["step"]), float(r["eval_guidance"])))


def cells_of(means: dict, env: str, variant: str) -> dict:
    return {(step, gamma): seeds for (e, v, step, gamma), seeds in means.items() if e == env and v == variant}


def summary(seeds: dict) -> tuple[float, float, float]:
    values = list(seeds.values())
    mean, half, _, _ = mean_ci95(values)
    return mean, half, float(np.std(values, ddof=1)) if len(values) > 1 else math.nan


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


def record(values_out: list[dict], env: str, variant: str, baseline: str, quantity: str, value: float) -> None:
    """One number of the report, unrounded, as report.md prints it (percentages in percent): report_values.csv
    is what the front page's numbers are checked against, so that a number rounded twice is caught."""
    values_out.append({"env_id": env, "variant": variant, "baseline": baseline, "quantity": quantity,
                       "value": float(value)})  # fmt: skip
