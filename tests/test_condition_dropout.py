"""The section "Guidance on a condition, with the condition dropped in training" of "Beyond the paper"
(beyond/condition_dropout.py), on synthetic sets: the real ones are trained by
results/beyond/condition_dropout/run_all.sh. Every number is recomputed here from the synthetic rows by a route
of its own (per seed, then over seeds; scipy's tests; Holm written out), so a number or a verdict computed
wrongly fails."""

import csv
import re

import numpy as np
import pytest
from conftest import ROOT
from scipy import stats

from beyond import condition_dropout as cd
from beyond import dropout_sets, dropout_tests, figures
from beyond import report as beyond_report
from beyond import sets as beyond_sets
from beyond.command_tracking import COLUMNS
from beyond.goal_distance import COLUMNS as GOAL_COLUMNS
from beyond.learned_null import COLUMNS as NULL_COLUMNS
from paper_study.stats import detectable_gap
from pgg_utils.files import write_csv_atomic

CMD, REACHER = beyond_sets.COMMAND_ENV, beyond_sets.GOAL_ENV
DROP, NULL17, GOAL_DROP = beyond_sets.COMMAND_DROPOUT, beyond_sets.COMMAND_NULL, beyond_sets.GOAL_DROPOUT
COMMANDS = (-0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
BASE_GAMMAS, DROP_GAMMAS = (0.5, 1.0, 2.0, 3.0), (0.5, 0.8, 1.0, 2.0, 3.0)  # the dropout set has a γ more
GOAL_GAMMAS = (1.0, 1.1, 1.2, 1.5)
LEVEL, VS_ONE = dropout_tests.SECTION, f"{dropout_tests.SECTION} vs γ 1"


def achieved(variant: str, seed: int, gamma: float, command: float, episode: int) -> float:
    """Synthetic agents: with dropout γ raises the share of the command followed (0.6 at γ = 1); the command null
    acts at a pseudo-command of 0.75 that γ pushes away from (faster at high commands, slower at low ones); the
    others ignore γ. A seed's offset and a wobble give the seeds their spread."""
    wobble = 0.05 * seed + 0.01 * episode + 0.03 * np.sin(3 * seed + 2 * gamma + command)
    if variant == DROP:
        return (0.6 + 0.15 * (gamma - 1)) * command + wobble
    if variant == NULL17:
        return 0.75 + gamma * (0.6 * command - 0.75) + wobble
    return 0.6 * command + wobble


def tracking_rows(variants, gammas, seeds=range(1, 6), skip=()) -> list[dict]:
    rows = []
    for variant in variants:
        for seed in seeds:
            for gamma in gammas:
                for command in COMMANDS:
                    if (variant, seed, gamma, command) in skip:
                        continue
                    for episode in range(2):
                        v = achieved(variant, seed, gamma, command, episode)
                        rows.append({"env_id": CMD, "variant": variant, "run": f"r{seed}", "seed": seed,
                                     "step": 1_000_000, "eval_guidance": gamma, "command": command,
                                     "in_training_range": "yes" if 0 <= command <= 2 else "no", "episode": episode,
                                     "episode_seed": 30_000 + episode, "return": 1000 * (command - abs(v - command)),
                                     "length": 1000, "mean_velocity": v, "velocity_error": v - command,
                                     # the per-step error is larger than the mean velocity's, and moves with γ
                                     "tracking_error": abs(v - command) + 0.1 + 0.02 * seed * gamma,
                                     "checkpoint_sha1": "x", "task_sha1": "y"})  # fmt: skip
    return rows


def distance(variant: str, seed: int, gamma: float, episode: int) -> float:
    """Synthetic Reacher agents: with the goal dropped γ brings the fingertip closer, the goal null farther."""
    wobble = 0.002 * seed + 0.001 * episode**2 + 0.0005 * np.sin(seed + 5 * gamma)
    effect = {GOAL_DROP: -0.004, "pgg_g1.1_goal": 0.003, "pgg_g1.1": 0.01, "ppo": 0.0}[variant]
    return 0.02 + effect * (gamma - 1) + wobble


def goal_rows(variants, seeds=range(1, 6)) -> list[dict]:
    return [{"env_id": REACHER, "variant": variant, "run": f"r{seed}", "seed": seed, "step": 1_000_000,
             "eval_guidance": gamma, "episode": episode, "return": -5.0, "final_distance": distance(variant, seed, gamma, episode)}
            for variant in variants for seed in seeds for gamma in GOAL_GAMMAS for episode in range(3)]  # fmt: skip


def null_rows(env: str, variant: str, pseudo: list, seeds=None) -> list[dict]:
    rows = []
    for seed, value in zip(seeds or range(1, len(pseudo) + 1), pseudo):
        where = {"pseudo_command": value} if env == CMD else {"pseudo_goal_x": value[0], "pseudo_goal_y": value[1]}
        rows.append({"env_id": env, "variant": variant, "run": f"r{seed}", "seed": seed, "step": 1_000_000,
                     "null_dims": "17", "episodes": 5, "states": 5000, **where, "kl_at_pseudo": 0.001 * seed,
                     "kl_at_own": 10.0 + seed, "per_state_spread": 0.0, "at_grid_edge": "no", "checkpoint_sha1": "x"})  # fmt: skip
    return rows


def write_folder(tmp_path, drop_seeds=range(1, 6), drop_skip=(), goal=True, dropout=True, nulls=()):
    folder = tmp_path / "beyond"
    write_csv_atomic(folder / "command" / "tracking.csv", COLUMNS,
                     tracking_rows([NULL17, "pgg_g1.1", "ppo"], BASE_GAMMAS))  # fmt: skip
    write_csv_atomic(folder / "goal_distance.csv", GOAL_COLUMNS, goal_rows(["pgg_g1.1_goal", "pgg_g1.1", "ppo"]))
    if dropout:
        write_csv_atomic(folder / "condition_dropout" / "command" / "tracking.csv", COLUMNS,
                         tracking_rows([DROP], DROP_GAMMAS, drop_seeds, drop_skip))  # fmt: skip
    if dropout and goal:
        write_csv_atomic(folder / "condition_dropout" / "goal_distance.csv", GOAL_COLUMNS, goal_rows([GOAL_DROP]))
    for where, rows in nulls:
        write_csv_atomic(folder / where / "learned_null.csv", NULL_COLUMNS, rows)
    return folder


def section(folder) -> tuple[str, dict, dropout_sets.Sets]:
    values = []
    sets = dropout_sets.read(folder)
    text = "\n".join(cd.section(sets, values))
    return text, {(v["env_id"], v["variant"], v["baseline"], v["quantity"]): v["value"] for v in values}, sets


def per_seed(rows, variant, gamma, commands, value) -> dict:
    """{seed: the mean over `commands` of the mean over episodes of value(row)}, written out."""
    out = {}
    for seed in sorted({r["seed"] for r in rows if r["variant"] == variant}):
        means = []
        for command in commands:
            episodes = [value(r) for r in rows if (r["variant"], r["seed"], r["eval_guidance"], r["command"])
                        == (variant, seed, gamma, command)]  # fmt: skip
            means.append(np.mean(episodes))
        out[seed] = float(np.mean(means))
    return out


def holm_reference(p_values: list[float]) -> list[float]:
    """Holm's step-down adjustment, written out: the k-th smallest p times (m − k + 1), kept monotone, capped at 1."""
    order, out, running = np.argsort(p_values), [0.0] * len(p_values), 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(p_values) - rank) * p_values[i]))
        out[i] = running
    return out


def family(values: dict, env: str, baseline: str, pattern: str) -> dict:
    """{(variant, quantity): p} of the tests whose quantity matches `pattern` (a regex, the whole quantity)."""
    return {
        (k[1], k[3]): v for k, v in values.items() if k[0] == env and k[2] == baseline and re.fullmatch(pattern, k[3])
    }


IN_RANGE, ERROR = (0.0, 0.5, 1.0, 1.5, 2.0), (lambda r: abs(r["velocity_error"]))
ALL_ROWS = tracking_rows([DROP], DROP_GAMMAS) + tracking_rows([NULL17, "pgg_g1.1", "ppo"], BASE_GAMMAS)


def test_absent_dropout_sets_are_said_in_one_line_each_and_give_no_number(tmp_path):
    """Before the sets land: one line for each task, no table of either, no figure; the learned null of the set
    without dropout is shown and the ones not measured are named."""
    folder = write_folder(
        tmp_path, dropout=False, nulls=[("command", null_rows(CMD, NULL17, [0.7, 0.82, 0.68, 0.73, 0.87]))]
    )
    text, values, sets = section(folder)
    not_run = [line for line in text.splitlines() if line.startswith("**Not run yet:**")]
    assert len(not_run) == 2 and "condition_dropout/command/tracking.csv does not exist" in not_run[0]
    assert "condition_dropout/goal_distance.csv" in not_run[1]
    assert (
        "| variant (null) | seeds | γ |" not in text
        and "Partial set" not in text
        and "What these tests say" not in text
    )
    assert {k[2] for k in values} == {f"{dropout_tests.SECTION} learned null"}
    assert (
        "| command task | PGG, γ_train = 1.1, null on dims 17 (command null) | 5 | 0.70, 0.82, 0.68, 0.73, 0.87 | 0.76 m/s"
        in text
    )
    assert "Not measured yet: PGG, dropout 0.1, null on dims 17 (command task)" in text
    assert not figures.dropout_figure(sets, tmp_path / "fig.png") and not (tmp_path / "fig.png").exists()
    assert cd.FIGURE not in text


def test_the_command_numbers_are_the_seeds_means_and_each_family_is_holm_corrected(tmp_path):
    """Over the training range: the tracking error (|velocity_error|), the per-step error (`tracking_error`, not the
    same), the gain (slope of achieved on commanded velocity) and the return are each seed's mean over its episodes
    and commands, then the mean over seeds; each γ is tested against γ = 1 paired by seed (scipy's ttest_rel), Holm
    over each measure's tests of the four variants, and the detectable change is where that test's power is 80%."""
    text, values, _ = section(write_folder(tmp_path))
    assert "Partial set" not in text and values[(CMD, DROP, LEVEL, "whole")] == 1.0
    measures = {"tracking error": ERROR, "per-step error": lambda r: r["tracking_error"],
                "return": lambda r: r["return"]}  # fmt: skip
    for quantity, value in measures.items():
        for variant in (DROP, NULL17, "pgg_g1.1", "ppo"):
            reference = per_seed(ALL_ROWS, variant, 1.0, IN_RANGE, value)
            for gamma in DROP_GAMMAS if variant == DROP else BASE_GAMMAS:
                at = per_seed(ALL_ROWS, variant, gamma, IN_RANGE, value)
                assert values[(CMD, variant, LEVEL, f"{quantity} at γ {gamma:g}")] == pytest.approx(
                    np.mean(list(at.values()))
                )
                if gamma == 1.0:
                    continue
                differences = np.array([at[s] - reference[s] for s in sorted(at)])

                def key(kind, variant=variant, quantity=quantity, gamma=gamma):
                    return (CMD, variant, VS_ONE, f"{quantity} {kind} at γ {gamma:g}")

                assert values[key("change")] == pytest.approx(differences.mean())
                assert values[key("p")] == pytest.approx(
                    stats.ttest_rel(list(at.values()), list(reference.values())).pvalue
                )
                sd, critical = differences.std(ddof=1), stats.t.ppf(0.975, 4)
                assert stats.nct.sf(critical, 4, values[key("detectable")] * np.sqrt(5) / sd) == pytest.approx(
                    0.8, abs=1e-6
                )
        tests = family(values, CMD, VS_ONE, rf"{quantity} p at γ [\d.]+")
        assert len(tests) == 4 + 3 * 3  # the dropout set's 0.5, 0.8, 2, 3; the others' 0.5, 2, 3
        for (variant, name), p_holm in zip(tests, holm_reference(list(tests.values()))):
            assert values[(CMD, variant, VS_ONE, name.replace(" p at", " p Holm at"))] == pytest.approx(p_holm)
    assert (
        values[(CMD, DROP, LEVEL, "per-step error at γ 2")] > values[(CMD, DROP, LEVEL, "tracking error at γ 2")] + 0.1
    )
    for variant, gamma in ((DROP, 2.0), (DROP, 3.0), (NULL17, 2.0), ("ppo", 3.0)):
        slopes = []
        for seed in range(1, 6):
            rows = [r for r in ALL_ROWS if (r["variant"], r["seed"], r["eval_guidance"]) == (variant, seed, gamma)
                    and r["command"] in IN_RANGE]  # fmt: skip
            by_command = {c: np.mean([r["mean_velocity"] for r in rows if r["command"] == c]) for c in IN_RANGE}
            slopes.append(stats.linregress(list(by_command), list(by_command.values())).slope)
        assert values[(CMD, variant, LEVEL, f"gain at γ {gamma:g}")] == pytest.approx(np.mean(slopes))
    assert values[(CMD, DROP, LEVEL, "gain at γ 3")] == pytest.approx(0.9, abs=0.03)  # 0.6 + 0.15·(3 − 1)
    assert values[(CMD, "ppo", LEVEL, "gain at γ 3")] == pytest.approx(0.6, abs=0.03)
    assert "| PGG, dropout 0.1, null on dims 17 (command dropped) | 5 | 0.8 |" in text
    assert "| PGG, γ_train = 1.1 (state null) | 5 | 0.8 |" not in text  # not tracked at 0.8: no row


def test_the_bands_split_the_range_in_thirds_and_show_the_changes_the_pooled_error_hides(tmp_path):
    """The bands are the thirds of [0, 2] (0 and 0.5; 1; 1.5 and 2) and the commands outside it; under the command
    null γ 2 raises the error at low commands and lowers it at high ones, which the pooled error averages away.
    Holm is over the bands inside the range as one family, and apart over the two outside it; every test there
    has its detectable change."""
    text, values, _ = section(write_folder(tmp_path))
    assert "the bands: low 0, 0.5; middle 1; high 1.5, 2; below -0.5; above 2.5, 3 m/s" in text
    for band, commands in (("low", (0.0, 0.5)), ("high", (1.5, 2.0)), ("above", (2.5, 3.0))):
        at = per_seed(ALL_ROWS, NULL17, 2.0, commands, ERROR)
        assert values[(CMD, NULL17, LEVEL, f"tracking error {band} at γ 2")] == pytest.approx(
            np.mean(list(at.values()))
        )
    assert values[(CMD, NULL17, VS_ONE, "tracking error low change at γ 2")] > 0.3
    assert values[(CMD, NULL17, VS_ONE, "tracking error high change at γ 2")] < -0.1
    for names, size in ((("low", "middle", "high"), 3 * 13), (("below", "above"), 2 * 13)):
        tests = family(values, CMD, VS_ONE, rf"tracking error ({'|'.join(names)}) p at γ [\d.]+")
        assert len(tests) == size
        for (variant, name), p_holm in zip(tests, holm_reference(list(tests.values()))):
            assert values[(CMD, variant, VS_ONE, name.replace(" p at", " p Holm at"))] == pytest.approx(p_holm)
        for variant, name in tests:
            assert values[(CMD, variant, VS_ONE, name.replace(" p at", " detectable at"))] > 0
    row = next(
        line for line in text.splitlines() if line.startswith("| PGG, γ_train = 1.1 (state null) | low (0, 0.5) |")
    )
    assert row.split(" | ")[3] == "–"  # γ 0.8: not tracked for the state null


def test_the_dropout_sets_change_is_tested_against_each_other_variants_by_welch(tmp_path):
    """Each seed's change from γ = 1 (error and gain), the dropout set's against each other variant's at each γ both
    were tracked at: scipy's Welch test, Holm over each measure's 9 tests, the detectable difference of Welch's test."""
    _, values, _ = section(write_folder(tmp_path))

    def change(variant, gamma):
        reference = per_seed(ALL_ROWS, variant, 1.0, IN_RANGE, ERROR)
        return [x - reference[s] for s, x in per_seed(ALL_ROWS, variant, gamma, IN_RANGE, ERROR).items()]

    for baseline in (NULL17, "pgg_g1.1", "ppo"):
        for gamma in (0.5, 2.0, 3.0):
            ours, theirs = change(DROP, gamma), change(baseline, gamma)

            def key(kind, baseline=baseline, gamma=gamma):
                return (CMD, DROP, f"{dropout_tests.SECTION} vs {baseline}", f"tracking error {kind} at γ {gamma:g}")

            assert values[key("difference")] == pytest.approx(np.mean(ours) - np.mean(theirs))
            assert values[key("p")] == pytest.approx(stats.ttest_ind(ours, theirs, equal_var=False).pvalue)
            assert values[key("detectable")] == pytest.approx(
                detectable_gap(np.std(ours, ddof=1), 5, np.std(theirs, ddof=1), 5, 0.05)
            )
    for measure in ("tracking error", "gain"):
        against = {f"{dropout_tests.SECTION} vs {b}" for b in (NULL17, "pgg_g1.1", "ppo")}
        tests = {k: v for k, v in values.items() if k[2] in against and re.fullmatch(rf"{measure} p at γ [\d.]+", k[3])}
        assert len(tests) == 9
        for key, p_holm in zip(tests, holm_reference(list(tests.values()))):
            assert values[(*key[:3], key[3].replace(" p at", " p Holm at"))] == pytest.approx(p_holm)


def test_the_verdict_counts_what_the_tests_found(tmp_path):
    """The verdict of the dropout set counts its γ > 1 tests whose error falls (or rises) after Holm, names them,
    counts the per-step, gain and band tests and the differences from the other variants, all as the recorded
    values give them, and states the detectable changes outside the range."""
    text, values, _ = section(write_folder(tmp_path))
    verdict = next(
        line for line in text.splitlines() if line.startswith("**What these tests say, and no more.** With the command")
    )

    def significant(pattern, sign):
        found = family(values, CMD, VS_ONE, pattern)
        return [k for k in found if values[(CMD, k[0], VS_ONE, k[1].replace(" p Holm at", " change at"))] * sign > 0
                and found[k] < 0.05 and k[0] == DROP]  # fmt: skip

    falls, rises = (
        significant(r"tracking error p Holm at γ (2|3)", -1),
        significant(r"tracking error p Holm at γ (2|3)", 1),
    )
    assert len(falls) == 2 and not rises  # the synthetic knob works
    assert f"{len(falls)} of the 2 tests of a γ above 1 against γ = 1 find a significant fall" in verdict
    change = values[(CMD, DROP, VS_ONE, "tracking error change at γ 3")]
    gain_rises = significant(r"gain p Holm at γ (2|3)", 1)
    assert f"of the 2 tests above 1, {len(gain_rises)} find it rise" in verdict
    band_falls = significant(r"tracking error (low|middle|high) p Holm at γ (2|3)", -1)
    band_rises = significant(r"tracking error (low|middle|high) p Holm at γ (2|3)", 1)
    assert (
        f"Per band inside the range: {len(band_falls)} falls" in verdict and f"and {len(band_rises)} rises" in verdict
    )
    welch = [k for k, v in values.items() if k[1] == DROP and k[2] in {f"{dropout_tests.SECTION} vs {b}" for b in (NULL17, "pgg_g1.1", "ppo")}
             and re.fullmatch(r"tracking error p Holm at γ (2|3)", k[3]) and v < 0.05]  # fmt: skip
    assert f"in error: {len(welch)} of 6 differences significant after Holm" in verdict
    outside = [v for k, v in values.items() if k[1] == DROP and k[2] == VS_ONE
               and re.fullmatch(r"tracking error (below|above) detectable at γ [\d.]+", k[3])]  # fmt: skip
    assert f"one test detects {min(outside):.3f} to {max(outside):.3f} m/s before Holm" in verdict
    found = [k for k, p in family(values, CMD, VS_ONE, r"tracking error (below|above) p Holm at γ [\d.]+").items()
             if k[0] == DROP and p < 0.05]  # fmt: skip
    assert f"Outside the training range, {len(found)} of its 8 tests find a change after Holm" in verdict
    assert f"γ 3 {change:+.3f} m/s, Holm p" in verdict  # the largest fall is named


def test_a_partial_dropout_set_is_marked_and_gets_no_verdict(tmp_path):
    """4 of 5 seeds, or a cell missing, is said before any table, the seeds are counted in the table, `whole` is 0,
    and no verdict is drawn."""
    text, values, _ = section(write_folder(tmp_path, drop_seeds=range(1, 5)))
    assert "**Partial set:** PGG, dropout 0.1, null on dims 17: 4 of 5 seeds" in text
    assert text.index("Partial set") < text.index("| variant (null) | seeds | γ |")
    assert "| PGG, dropout 0.1, null on dims 17 (command dropped) | 4 | 2 |" in text
    assert values[(CMD, DROP, LEVEL, "whole")] == 0.0 and "With the command dropped in training" not in text
    text, values, _ = section(write_folder(tmp_path, drop_skip={(DROP, 3, 2.0, 3.0)}))
    assert "cells missing or short of 2 episodes (seed 3)" in text and values[(CMD, DROP, LEVEL, "whole")] == 0.0


def test_reacher_distance_is_tested_against_gamma_one_and_against_the_goal_null(tmp_path):
    """Each variant's final distance at each γ is its seeds' mean distance, tested against γ = 1 paired by seed (Holm
    over the four variants' 12 tests); the dropout set's change against each other variant's by Welch (Holm over 9);
    the verdict counts the falls; 4 seeds are marked partial."""
    text, values, _ = section(write_folder(tmp_path))
    rows = goal_rows([GOAL_DROP, "pgg_g1.1_goal", "pgg_g1.1", "ppo"])
    seeds = lambda v, g: {s: np.mean([r["final_distance"] for r in rows if (r["variant"], r["seed"], r["eval_guidance"])
                                      == (v, s, g)]) for s in range(1, 6)}  # fmt: skip
    for variant in (GOAL_DROP, "pgg_g1.1_goal"):
        for gamma in GOAL_GAMMAS[1:]:
            at, reference = seeds(variant, gamma), seeds(variant, 1.0)
            assert values[(REACHER, variant, LEVEL, f"final distance at γ {gamma:g}")] == pytest.approx(
                np.mean(list(at.values()))
            )
            assert values[(REACHER, variant, VS_ONE, f"final distance p at γ {gamma:g}")] == pytest.approx(
                stats.ttest_rel(list(at.values()), list(reference.values())).pvalue
            )
    tests = family(values, REACHER, VS_ONE, r"final distance p at γ [\d.]+")
    assert len(tests) == 12
    for (variant, name), p_holm in zip(tests, holm_reference(list(tests.values()))):
        assert values[(REACHER, variant, VS_ONE, name.replace(" p at", " p Holm at"))] == pytest.approx(p_holm)
    ours = [seeds(GOAL_DROP, 1.5)[s] - seeds(GOAL_DROP, 1.0)[s] for s in range(1, 6)]
    theirs = [seeds("pgg_g1.1_goal", 1.5)[s] - seeds("pgg_g1.1_goal", 1.0)[s] for s in range(1, 6)]
    assert values[
        (REACHER, GOAL_DROP, f"{dropout_tests.SECTION} vs pgg_g1.1_goal", "final distance p at γ 1.5")
    ] == pytest.approx(stats.ttest_ind(ours, theirs, equal_var=False).pvalue)
    falls = [k for k, p in family(values, REACHER, VS_ONE, r"final distance p Holm at γ [\d.]+").items()
             if k[0] == GOAL_DROP and p < 0.05]  # fmt: skip
    assert f"With the goal dropped in training, {len(falls)} of the 3 tests" in text and falls
    assert values[(REACHER, GOAL_DROP, LEVEL, "whole")] == 1.0
    write_csv_atomic(tmp_path / "beyond" / "condition_dropout" / "goal_distance.csv", GOAL_COLUMNS,
                     goal_rows([GOAL_DROP], seeds=range(1, 5)))  # fmt: skip
    text, values, _ = section(tmp_path / "beyond")
    assert "**Partial set:** PGG, dropout 0.1, goal null: 4 of 5 seeds" in text
    assert values[(REACHER, GOAL_DROP, LEVEL, "whole")] == 0.0 and "With the goal dropped in training" not in text


def test_the_learned_nulls_are_tabled_with_and_without_dropout(tmp_path):
    """Each set's pseudo-condition per seed and its mean (the command in m/s, Reacher's goal as a position and its mean
    distance from the centre), a set of fewer than 5 agents marked partial, a set not measured named."""
    nulls = [("command", null_rows(CMD, NULL17, [0.7, 0.82, 0.68, 0.73, 0.87])),
             ("condition_dropout/command", null_rows(CMD, DROP, [1.01, 0.95, 1.2])),
             ("Reacher-v4", null_rows(REACHER, "pgg_g1.1_goal", [(0.03, -0.04), (0.0, 0.1)]))]  # fmt: skip
    text, values, _ = section(write_folder(tmp_path, nulls=nulls))
    learned = f"{dropout_tests.SECTION} learned null"
    assert values[(CMD, DROP, learned, "pseudo-command mean")] == pytest.approx(np.mean([1.01, 0.95, 1.2]))
    assert values[(CMD, NULL17, learned, "pseudo-command min")] == 0.68
    assert values[(CMD, NULL17, learned, "KL to own condition mean")] == pytest.approx(13.0)
    assert values[(REACHER, "pgg_g1.1_goal", learned, "pseudo-goal radius mean")] == pytest.approx((0.05 + 0.1) / 2)
    assert (
        "| command task | PGG, dropout 0.1, null on dims 17 (command dropped) | 3 of 5 (partial) | 1.01, 0.95, 1.20 |"
        in text
    )
    assert (
        "| Reacher-v4 | PGG, γ_train = 1.1, goal null (goal null) | 2 of 5 (partial) | (0.03, -0.04), (0.00, 0.10) |"
        in text
    )
    assert "Not measured yet: PGG, dropout 0.1, goal null (Reacher-v4)" in text
    assert "| 0.075 m from the centre |" in text  # no bar of a norm inside a table's cell


@pytest.mark.slow
def test_the_figure_draws_four_variants_per_band_and_on_reacher(tmp_path, monkeypatch):
    """A panel per band (5) and Reacher's, each with its four variants; the section links it."""
    drawn = []
    real_band = figures.band
    monkeypatch.setattr(figures, "band", lambda ax, xs, values, variant, label: drawn.append((id(ax), variant))
                        or real_band(ax, xs, values, variant, label))  # fmt: skip
    text, _, sets = section(write_folder(tmp_path))
    path = tmp_path / "fig.png"
    assert figures.dropout_figure(sets, path) and path.stat().st_size > 0 and f"]({cd.FIGURE})" in text
    panels = {}
    for ax, variant in drawn:
        panels.setdefault(ax, []).append(variant)
    assert len(panels) == 6
    assert max(map(tuple, panels.values())) in {
        (DROP, NULL17, "pgg_g1.1", "ppo"),
        (GOAL_DROP, "pgg_g1.1_goal", "pgg_g1.1", "ppo"),
    }
    assert all(len(v) == 4 for v in panels.values())


@pytest.mark.slow
def test_the_report_writes_the_section_and_its_figure_from_the_folder(tmp_path):
    """beyond_report.report reads the dropout sets from the folder it is given: the section follows the command
    task's, the figure is written and listed, report_values.csv holds the section's numbers."""
    folder = write_folder(tmp_path)
    (folder / "Reacher-v4").mkdir()
    with open(ROOT / "results" / "beyond" / "Reacher-v4" / "episodes.csv", newline="") as f:
        head = [next(f) for _ in range(2)]
    (folder / "Reacher-v4" / "episodes.csv").write_text("".join(head))
    written = beyond_report.report(beyond_report.Args(folder=str(folder), table=str(tmp_path / "none.csv"),
                                                      table_heldout=str(tmp_path / "none.csv")))  # fmt: skip
    report = (folder / "report.md").read_text()
    assert report.index("## Guidance on a command") < report.index(
        "## Guidance on a condition, with the condition dropped"
    )
    assert folder / cd.FIGURE in written and (folder / cd.FIGURE).stat().st_size > 0
    with open(folder / "report_values.csv", newline="") as f:
        assert any(
            r["baseline"] == dropout_tests.SECTION and r["quantity"] == "tracking error at γ 0.8"
            for r in csv.DictReader(f)
        )
