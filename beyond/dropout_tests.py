"""The condition-dropout section's tests, as Holm families: each variant at each γ against γ = 1 paired by seed,
the dropout set's change from γ = 1 against each other variant's (Welch), and how they enter report_values.csv
and the tables; what a set lacks to be whole."""

import numpy as np

from beyond.cells import record
from beyond.sets import COMMAND_SEEDS
from paper_study.agreement import fmt_p
from paper_study.paper import paper_name
from paper_study.stats import ALPHA, paired_test, set_holm, welch_of

SECTION = "condition dropout"  # report_values.csv's `baseline` of this section's rows, apart from the others'


def against_gamma_one(variants, gammas, measure, **labels) -> list[dict]:
    """Each variant's {seed: value} at each γ it was measured at (measure(variant, γ)), each γ ≠ 1 tested against
    γ = 1 paired by seed; `labels` added to every row. The caller sets Holm over the family (`set_holm`)."""
    rows = []
    for variant in variants:
        reference = measure(variant, 1.0)
        for gamma in gammas:
            if values := measure(variant, gamma):
                rows.append({"variant": variant, "gamma": gamma, "values": values, **labels,
                             "test": None if gamma == 1.0 else paired_test(values, reference)})  # fmt: skip
    return rows


def family(rows: list[dict]) -> list[dict]:
    """`rows` (against_gamma_one's) as one Holm family."""
    set_holm([r["test"] for r in rows])
    return rows


def against_others(variants, gammas, measure, ours: str) -> list[dict]:
    """A family: `ours`'s per-seed change from γ = 1 against each other variant's at each γ ≠ 1 both were measured
    at, Welch's t test (distinct runs); Holm over the family."""
    reference = {variant: measure(variant, 1.0) for variant in variants}
    change = lambda variant, gamma: {s: v - reference[variant][s] for s, v in measure(variant, gamma).items()
                                     if s in reference[variant]}  # fmt: skip
    rows = []
    for gamma in (g for g in gammas if g != 1.0):
        mine = change(ours, gamma)
        for baseline in (v for v in variants if v != ours):
            theirs = change(baseline, gamma)
            if len(mine) >= 2 and len(theirs) >= 2:
                rows.append({"gamma": gamma, "baseline": baseline,
                             **welch_of(list(mine.values()), list(theirs.values()))})  # fmt: skip
    set_holm(rows)
    return rows


def test_cells(test: dict | None, digits: int) -> list[str]:
    """A paired test's change, p (Holm) and detectable difference, as the tables show them."""
    if test is None:
        return ["–", "–", "–"]
    return [f"{test['difference']:+.{digits}f}", f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})",
            f"{test['detectable']:.{digits}f}"]  # fmt: skip


def record_family(values_out: list, env: str, rows: list[dict], quantity: str) -> None:
    """A family's values and tests into report_values.csv: the mean over seeds at each γ, and against γ = 1 its
    change, p, Holm p and detectable difference (a band's rows name their band after `quantity`)."""
    for r in rows:
        measured = f"{quantity} {r['band']}" if "band" in r else quantity
        record(values_out, env, r["variant"], SECTION, f"{measured} at γ {r['gamma']:g}",
               np.mean(list(r["values"].values())))  # fmt: skip
        if (test := r["test"]) is not None:
            for kind, key in (("change", "difference"), ("p", "p"), ("p Holm", "p_holm"), ("detectable", "detectable")):
                record(values_out, env, r["variant"], f"{SECTION} vs γ 1", f"{measured} {kind} at γ {r['gamma']:g}",
                       test[key])  # fmt: skip


def record_welch(values_out: list, env: str, rows: list[dict], ours: str, quantity: str) -> None:
    for r in rows:
        for name, value in (("change", r["mean"]), ("baseline's change", r["baseline_mean"]),
                            ("difference", r["mean"] - r["baseline_mean"]), ("p", r["p"]), ("p Holm", r["p_holm"]),
                            ("detectable", r["detectable"])):  # fmt: skip
            record(values_out, env, ours, f"{SECTION} vs {r['baseline']}", f"{quantity} {name} at γ {r['gamma']:g}",
                   value)  # fmt: skip


def gaps_of(cells: dict, variant: str) -> list[str]:
    """What a variant's set lacks to be whole: COMMAND_SEEDS seeds, each at every (γ, command) any seed has, with as
    many episodes as the fullest cell; [] where it is whole."""
    mine = {k: v for k, v in cells.items() if k[0] == variant}
    grid = {(g, c) for (v, s, g, c) in mine}
    episodes = max((cell["episodes"] for cell in mine.values()), default=0)
    seeds = sorted({s for (v, s, g, c) in mine})
    gaps = [f"{paper_name(variant)}: {len(seeds)} of {COMMAND_SEEDS} seeds"] if len(seeds) < COMMAND_SEEDS else []
    short = sorted({s for s in seeds for g, c in grid if mine.get((variant, s, g, c), {"episodes": 0})["episodes"]
                    < episodes})  # fmt: skip
    if short:
        gaps.append(f"{paper_name(variant)}: cells missing or short of {episodes} episodes "
                    f"({', '.join(f'seed {s}' for s in short)})")  # fmt: skip
    return gaps


def goal_gaps(goal: dict, variant: str, gammas: list[float]) -> list[str]:
    """What Reacher's dropout set lacks to be whole: COMMAND_SEEDS seeds at every γ the other sets were scored at,
    each with as many episodes as the fullest cell."""
    seeds = sorted({s for (v, g), by_seed in goal.items() if v == variant for s in by_seed})
    episodes = max((n for (v, g), by_seed in goal.items() if v == variant for _, n in by_seed.values()), default=0)
    gaps = [f"{paper_name(variant)}: {len(seeds)} of {COMMAND_SEEDS} seeds"] if len(seeds) < COMMAND_SEEDS else []
    short = sorted({s for s in seeds for g in gammas if goal.get((variant, g), {}).get(s, (0, 0))[1] < episodes})
    if short:
        gaps.append(f"{paper_name(variant)}: γ cells missing or short of {episodes} episodes "
                    f"({', '.join(f'seed {s}' for s in short)})")  # fmt: skip
    return gaps


def seeds_of(values: list[dict], variant: str) -> int:
    return max((len(r["values"]) for r in values if r["variant"] == variant), default=0)


def falls_and_rises(rows: list[dict], variant: str) -> tuple[list[dict], list[dict], list[dict]]:
    """A variant's tests of a γ above 1 in a family, and those of them that fall and rise significantly after Holm."""
    above = [r for r in rows if r["variant"] == variant and r["gamma"] > 1 and r["test"] is not None]
    significant = [r for r in above if r["test"]["p_holm"] < ALPHA]
    return above, [r for r in significant if r["test"]["difference"] < 0], [r for r in significant
                                                                           if r["test"]["difference"] > 0]  # fmt: skip


def named(rows: list[dict], unit: str = " m/s", digits: int = 3) -> str:
    """The tests of `rows`, in parentheses: γ (band), change, Holm p; nothing for none."""
    tests = [f"γ {r['gamma']:g}{' ' + r['band'] if 'band' in r else ''} {r['test']['difference']:+.{digits}f}{unit}, "
             f"Holm p {fmt_p(r['test']['p_holm'])}" for r in rows]  # fmt: skip
    return f" ({'; '.join(tests)})" if tests else ""


def cell(row: dict | None) -> tuple[dict | None, dict | None]:
    """(values, test) of a family's row, for text.change_cell; (None, None) where the variant has no row at that γ."""
    return (None, None) if row is None else (row["values"], row["test"])
