"""Guidance on a goal: the final distance to the goal against γ (goal_distance.csv), each seed's change from γ = 1
to the largest γ."""

import math
from pathlib import Path

import numpy as np
from scipy import stats

from paper_study.stats import set_holm
from pgg_utils.episodes import seed_means
from pgg_utils.files import read_csv


def read_goal_distance(folder: Path) -> dict:
    """{(env, variant, γ): {seed: final distance, mean over its episodes}} from goal_distance.csv."""
    path = folder / "goal_distance.csv"
    if not path.exists():
        return {}
    key = lambda r: (r["env_id"], r["variant"], float(r["eval_guidance"]))
    return seed_means(read_csv(path), key, value="final_distance")


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
    set_holm(rows)
    return rows
